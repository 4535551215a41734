// The loadtest suite (issue #9): what `animspace-loadtest` measures against one real animspaced
// replica serving crane interleaved — a PMSC model trained on crane's even frames (Meyer &
// Anderson 2007 §2, the pmsc suite's settings) while the odd frames' key points are replayed —
// set against the same work done in process in the same run.
//
//   in_process   pmsc::evaluate_cached over the odd frames in this process, one thread: poses/s,
//                µs per pose, and the hit / blend / miss fractions the soft cache gives them
//   sweep        animspace-loadtest closed loop, EvaluateKeyPoints with the points returned (what
//                an animation tool asks for), 1, 2, 4, 8, 16, 32 callers: poses/s, p50/p90/p99/
//                p99.9 per call, errors, and the hit / blend / miss rates the server reported
//
// Every odd frame is replayed in turn, so a step's served rates must equal the in-process
// fractions up to the partial last pass over the frames: the suite prints the largest difference.
// Client and daemon share this machine's cores, so past 2 callers the sweep measures how the
// server queues, not how it scales.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/child_process.h"
#include "bench/crane_split.h"
#include "bench/serving.h"
#include "bench/suites.h"
#include "clients/cpp/client.h"
#include "core/pmsc/pmsc_model.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"

namespace animspace::bench {
namespace {

constexpr const char* kSweep = "1,2,4,8,16,32";
constexpr double kStepSeconds = 4;

struct InProcess {
  double us_per_pose = 0;  // median pass over the odd frames, divided by their count
  double hit = 0, blend = 0, miss = 0;
};

InProcess measure_in_process(const CraneSplit& split, int passes) {
  const FrameMatrix& all = split.sequence.frames.samples;
  std::vector<Eigen::VectorXf> keys;
  for (int f : split.odd) keys.push_back(pmsc::gather_key_values(split.model, all.row(f).transpose()));
  InProcess out;
  pmsc::CachedPose cached;
  for (const auto& k : keys) {
    pmsc::evaluate_cached(split.model, k, nullptr, cached);
    (cached.status == pmsc::CacheStatus::kHit     ? out.hit
     : cached.status == pmsc::CacheStatus::kBlend ? out.blend
                                                  : out.miss) += 1.0 / static_cast<double>(keys.size());
  }
  out.us_per_pose = 1e6 *
                    median_seconds(passes,
                                   [&] {
                                     for (const auto& k : keys) {
                                       pmsc::evaluate_cached(split.model, k, nullptr, cached);
                                       do_not_optimize(cached.points.data());
                                     }
                                   }) /
                    static_cast<double>(keys.size());
  return out;
}

}  // namespace

nlohmann::json run_loadtest_suite(const SuiteOptions& options) {
  nlohmann::json results = nlohmann::json::array();
  auto split = train_crane_even(options, "loadtest");
  if (!split) return results;
  const InProcess in_process = measure_in_process(*split, std::max(3, options.repetitions / 3));
  const double in_process_poses_per_second = 1e6 / in_process.us_per_pose;
  std::printf("loadtest: crane trained on %zu even frames (N = %d, M = %d, K = %d); replaying the %zu odd frames\n",
              split->even.size(), split->model.point_count, split->model.basis_size(),
              split->model.key_point_count(), split->odd.size());

  ScratchDirectory scratch("loadtest");
  const auto repository = scratch.path() / "repository";
  if (!write_crane_repository(*split, repository, "loadtest")) return results;
  const auto daemon_dir = scratch.path() / "daemon";
  std::filesystem::create_directories(daemon_dir);
  std::unique_ptr<harness::DaemonProcess> daemon;
  try {
    daemon = std::make_unique<harness::DaemonProcess>(
        std::vector<std::string>{"--model-repository", repository.string(), "--miss-log-dir", daemon_dir.string(),
                                 "--log-level", "warn", "--miss-log-fsync", "never", "--renderer", "none"},
        daemon_dir);
  } catch (const std::exception& e) {
    std::printf("loadtest: the daemon did not start: %s\n", e.what());
    return results;
  }
  if (!wait_until_serving(daemon->address())) {
    std::printf("loadtest: the daemon never answered SERVING\n%s\n", daemon->log().c_str());
    return results;
  }

  const auto report_path = scratch.path() / "report.json";
  const auto log_path = scratch.path() / "loadtest.txt";
  const int status = run_program({harness::program_path("animspace-loadtest").string(), "--server", daemon->address(), "--model", kCraneModelName,
                                  "--sequence", (*options.data / "crane").string(), "--select", "1::2",
                                  "--with-points", "--concurrency", kSweep, "--duration-s",
                                  std::to_string(kStepSeconds), "--json", report_path.string()},
                                 log_path)
                           .exit_status;
  if (status != 0) {
    std::printf("loadtest: animspace-loadtest exited with %d:\n%s\n", status, read_text(log_path).c_str());
    return results;
  }
  const nlohmann::json report = nlohmann::json::parse(read_text(report_path));

  std::printf("\n%-12s %5s %9s %8s %9s %9s %9s %9s %6s %6s %6s %6s %7s %7s\n", "row", "conc", "poses/s", "×conc1",
              "×in-proc", "p50 us", "p90 us", "p99 us", "p99.9", "errors", "hit", "blend", "miss", "|Δhit|");
  std::printf("%-12s %5d %9.0f %8s %9.2f %9.1f %9s %9s %6s %6s %6.3f %6.3f %7.3f %7s\n", "in_process", 1,
              in_process_poses_per_second, "-", 1.0, in_process.us_per_pose, "-", "-", "-", "-", in_process.hit,
              in_process.blend, in_process.miss, "-");
  results.push_back({{"row", "in_process"},
                     {"concurrency", 1},
                     {"poses_per_second", in_process_poses_per_second},
                     {"us_per_pose", in_process.us_per_pose},
                     {"hit_rate", in_process.hit},
                     {"blend_rate", in_process.blend},
                     {"miss_rate", in_process.miss}});
  double first_step = 0;
  for (const auto& step : report["steps"]) {
    const double poses_per_second = step["poses_per_second"].get<double>();
    if (first_step == 0) first_step = poses_per_second;
    const double hit = step["hit_rate"].get<double>();
    const double hit_difference = std::abs(hit - in_process.hit);
    std::printf("%-12s %5d %9.0f %8.2f %9.2f %9.0f %9.0f %9.0f %6.0f %6llu %6.3f %6.3f %7.3f %7.4f\n", "sweep",
                step["concurrency"].get<int>(), poses_per_second, poses_per_second / first_step,
                poses_per_second / in_process_poses_per_second, step["p50_us"].get<double>(),
                step["p90_us"].get<double>(), step["p99_us"].get<double>(), step["p99_9_us"].get<double>(),
                static_cast<unsigned long long>(step["errors"].get<uint64_t>()), hit, step["blend_rate"].get<double>(),
                step["miss_rate"].get<double>(), hit_difference);
    results.push_back({{"row", "sweep"},
                       {"concurrency", step["concurrency"]},
                       {"poses_per_second", poses_per_second},
                       {"p50_us", step["p50_us"]},
                       {"p90_us", step["p90_us"]},
                       {"p99_us", step["p99_us"]},
                       {"p99_9_us", step["p99_9_us"]},
                       {"errors", step["errors"]},
                       {"hit_rate", hit},
                       {"blend_rate", step["blend_rate"]},
                       {"miss_rate", step["miss_rate"]},
                       {"in_process_hit_rate", in_process.hit},
                       {"server_delta", step["server_delta"]}});
  }
  std::printf(
      "\nconc: closed-loop callers (EvaluateKeyPoints, one pose per call, points returned, %.0f s a step). ×conc1: "
      "poses/s over the 1-caller step; ×in-proc: over in-process evaluate_cached on one thread (no RPC). "
      "hit/blend/miss: fractions of poses; in_process: of the odd frames once; sweep: as the server answered. "
      "|Δhit|: served hit rate − in-process (nonzero only from the partial last pass over the frames).\n",
      kStepSeconds);
  return results;
}

}  // namespace animspace::bench
