#!/usr/bin/env bash
# Runs a test command with sanitizer reports going to files under REPORT_DIR (the *_OPTIONS
# variables name it with log_path), then prints every report written. Fails when the command
# fails or when any report exists: a race or leak found inside a daemon that a test started
# (and killed) is a failure even though that test passed.
#
#   scripts/with-sanitizer-reports.sh REPORT_DIR COMMAND [ARGS...]
set -uo pipefail
report_dir=$1
shift
mkdir -p "$report_dir"
"$@"
status=$?
shopt -s nullglob
reports=("$report_dir"/*)
if [ ${#reports[@]} -gt 0 ]; then
  for r in "${reports[@]}"; do
    echo "=== sanitizer report: $r"
    cat "$r"
  done
  echo "with-sanitizer-reports: ${#reports[@]} report(s) under $report_dir" >&2
  [ "$status" -eq 0 ] && status=1
fi
exit "$status"
