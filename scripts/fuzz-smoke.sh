#!/usr/bin/env bash
# Bounded fuzzing of every target in fuzz/ (built by `cmake --build --preset fuzz`): each one
# first replays its seeds (fuzz/corpus/<name>) and past crashes (fuzz/regressions/<name>), then
# fuzzes for FUZZ_SECONDS (default 20) from them. Exits non-zero when any target crashed, naming
# the target and the saved input; new corpus entries and crash inputs go under
# $FUZZ_BUILD/fuzz-smoke, never into the committed corpus. FUZZ_JOBS (default 1) targets run at
# once, each a single libFuzzer process on its own core; every target gets its FUZZ_SECONDS
# whatever the count, and the reports come out in the targets' order.
#
#   scripts/fuzz-smoke.sh                  # every target
#   scripts/fuzz-smoke.sh obj pc2          # some
#   FUZZ_SECONDS=300 scripts/fuzz-smoke.sh model_container
#   FUZZ_JOBS=2 scripts/fuzz-smoke.sh      # two at a time (make fuzz-smoke uses one per core)
#
# A crash found here becomes a fix, its input under fuzz/regressions/<name>/ and a unit test
# (see fuzz/regressions/README.md).
set -uo pipefail

cd "$(dirname "$0")/.."
seconds=${FUZZ_SECONDS:-20}
jobs=${FUZZ_JOBS:-1}
if ! [[ $jobs =~ ^[1-9][0-9]*$ ]]; then
  echo "fuzz-smoke: FUZZ_JOBS is '$jobs'; expected a count of at least 1" >&2
  exit 2
fi
build=${FUZZ_BUILD:-build-fuzz}
out="$build/fuzz-smoke"
# -rss_limit_mb also caps a single allocation (malloc_limit_mb defaults to it), so a parser that
# trusts a size field crashes here instead of passing on a big machine.
limits=(-rss_limit_mb=2048 -timeout=10)

if [ $# -gt 0 ]; then
  targets=("$@")
else
  targets=()
  for source in fuzz/*_fuzzer.cpp; do
    name=$(basename "$source" _fuzzer.cpp)
    targets+=("$name")
  done
fi

for name in "${targets[@]}"; do
  if [ ! -x "$build/bin/${name}_fuzzer" ]; then
    echo "fuzz-smoke: $build/bin/${name}_fuzzer is missing; build it with: cmake --preset fuzz && cmake --build --preset fuzz" >&2
    exit 2
  fi
done

# fuzz_one NAME: replays, then fuzzes one target; prints its report line, and on a crash the
# target, the saved input and the sanitizer's summary on stderr. Exits 1 when it crashed.
fuzz_one() {
  local name=$1
  local binary="$build/bin/${name}_fuzzer"
  local seeds=(fuzz/corpus/"$name" fuzz/regressions/"$name")
  local work="$out/$name"
  local log="$work/fuzz.log"

  # Replay: every seed and regression input once, nothing mutated.
  if ! "$binary" "${limits[@]}" -runs=0 -artifact_prefix="$work/crashes/" "${seeds[@]}" >"$work/replay.log" 2>&1; then
    log="$work/replay.log"
  # Fuzz: new inputs go to the scratch corpus (the first directory), crashes to crashes/.
  elif "$binary" "${limits[@]}" -max_total_time="$seconds" -print_final_stats=1 \
      -artifact_prefix="$work/crashes/" "$work/corpus" "${seeds[@]}" >"$log" 2>&1; then
    local stats rate runs
    stats=$(grep -E '^#[0-9]+[[:space:]]+DONE' "$log" | tail -1 | grep -oE 'cov: [0-9]+ ft: [0-9]+')
    rate=$(grep -oE 'stat::average_exec_per_sec: *[0-9]+' "$log" | grep -oE '[0-9]+$')
    runs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$')
    printf 'fuzz-smoke: %-20s ok   %9s runs  %6s exec/s  %s\n' "$name" "$runs" "$rate" "$stats"
    return 0
  fi
  local crash
  crash=$(grep -oE 'Test unit written to [^ ]+' "$log" | tail -1 | sed 's/Test unit written to //')
  echo "fuzz-smoke: $name CRASHED; input: ${crash:-(none saved)}; log: $log" >&2
  grep -E '^(==[0-9]+==ERROR|SUMMARY|.*invariant violated|.*runtime error)' "$log" | head -5 >&2
  return 1
}

# At most $jobs targets at once; each one's report waits in its folder until all are done.
running=0
for name in "${targets[@]}"; do
  for dir in fuzz/corpus/"$name" fuzz/regressions/"$name"; do mkdir -p "$dir"; done
  work="$out/$name"
  rm -rf "$work" && mkdir -p "$work/corpus" "$work/crashes"
  if [ "$running" -ge "$jobs" ]; then
    wait -n
    running=$((running - 1))
  fi
  { fuzz_one "$name" >"$work/report.out" 2>"$work/report.err"; echo $? >"$work/status"; } &
  running=$((running + 1))
done
wait

failed=()
for name in "${targets[@]}"; do
  work="$out/$name"
  cat "$work/report.out"
  cat "$work/report.err" >&2
  [ "$(cat "$work/status" 2>/dev/null)" = 0 ] || failed+=("$name")
done

# The plain closing line CI reads: targets that ran clean, targets that crashed.
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz-smoke: ${#failed[@]} target(s) crashed: ${failed[*]}" >&2
  echo "fuzz-smoke: $((${#targets[@]} - ${#failed[@]})) passed, ${#failed[@]} failed"
  exit 1
fi
echo "fuzz-smoke: ${#targets[@]} passed, 0 failed"
