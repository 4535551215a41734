// animspace-loadtest: replays real sequences against one or several animspaced servers and
// reports throughput, latency percentiles, errors by status code and the soft cache's hit /
// blend / miss rates per step — closed-loop concurrency sweeps or open-loop target rates (constant
// steps or linear ramps), every step bounded by time and by request count. It only ever talks to
// the addresses given on its command line.
#include <sys/wait.h>
#include <unistd.h>

#include <climits>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/common/atomic_file.h"
#include "loadtest/report.h"

namespace {

using namespace animspace::loadtest;

int fail(const std::string& message) {
  std::fprintf(stderr, "animspace-loadtest: %s\n", message.c_str());
  return 2;
}

// Comma-separated positive numbers ("1,2,4,8"); empty on a bad entry (named in `error`).
std::vector<double> parse_list(const std::string& text, const char* flag, std::string* error) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || !(v > 0)) {
      *error = std::string(flag) + ": expected positive numbers separated by commas, got '" + item + "'";
      return {};
    }
    out.push_back(v);
  }
  return out;
}

std::filesystem::path plot_script() {
  char self[PATH_MAX] = {};
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  if (n > 0) return std::filesystem::path(std::string(self, static_cast<size_t>(n))).parent_path() / "animspace-loadtest-plot.py";
  return "animspace-loadtest-plot.py";
}

// Runs a program with arguments (no shell), waiting for it; true when it exits 0.
bool run_process(const std::vector<std::string>& args) {
  const pid_t pid = fork();
  if (pid < 0) return false;
  if (pid == 0) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) return false;
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> servers;
  WorkloadArgs workload_args;
  std::string rpc = "evaluate";
  std::string concurrency = "1,2,4,8";
  std::string rate;
  std::string ramp = "step";
  double rate_end = 0;
  uint32_t workers = 64;
  uint32_t window = 1;
  double duration_s = 10;
  uint64_t max_requests = 1000000;
  bool with_points = false;
  std::string json_path, csv_path, plot_path, token_file;

  CLI::App app{"animspace-loadtest — replay real sequences against animspaced: closed-loop concurrency sweeps or "
               "open-loop target rates, bounded in time and requests; throughput, latency p50/p90/p99/p99.9, errors "
               "by status code, hit/blend/miss rates and the servers' own counters; JSON, CSV and a PNG plot"};
  app.add_option("--server", servers,
                 "Server address; repeat for several replicas (IP:port each), balanced round-robin by the client. One "
                 "DNS name resolving to every replica (dns:///name:port) is balanced too")
      ->required();
  app.add_option("--model", workload_args.model, "Model to load")->required();
  app.add_option("--version", workload_args.version, "Model version (default: the served one, pinned for the run)");
  app.add_option("--rpc", rpc,
                 "evaluate: EvaluateKeyPoints; stream: StreamKeyPoints (closed loop only); skinning: "
                 "EvaluateSkeletonPose with --pose-file")
      ->check(CLI::IsMember({"evaluate", "stream", "skinning"}))
      ->capture_default_str();
  app.add_option("--sequence", workload_args.sequence,
                 "Frames whose key points are replayed: a folder (reference.obj + frames.pc2, or OBJ frames), a mesh "
                 "with --pc2, or a model.anim's stored frames");
  app.add_option("--pc2", workload_args.pc2, "Point cache when --sequence is a mesh file");
  app.add_option("--select", workload_args.select, "Frames as a slice start:stop:step (1::2: the odd frames)")
      ->capture_default_str();
  app.add_option("--pose-file", workload_args.pose_file,
                 "--rpc skinning: skeleton poses, 12 numbers per bone (rows 0–2 of each matrix), pose after pose");
  app.add_option("--pose-space", workload_args.pose_space, "The pose file's matrices: global G_j or local L_j")
      ->check(CLI::IsMember({"global", "local"}))
      ->capture_default_str();
  app.add_option("--batch", workload_args.batch, "Poses per unary call")->check(CLI::Range(1u, 1024u))->capture_default_str();
  app.add_flag("--with-points", with_points, "Ask for the reconstructed points too (default: verdicts only)");
  app.add_flag("--log-misses", workload_args.log_misses,
               "Let the load's blends and misses into the model's miss log (default: kept out, as test traffic "
               "that must not reach retraining)");
  app.add_flag("--coordinates", workload_args.coordinates,
               "Ask for the answers as subspace coordinates (M values each, reconstructed by clients; issue #36)");
  app.add_option("--concurrency", concurrency, "Closed loop: callers per step, e.g. 1,2,4,8,16,32")
      ->capture_default_str();
  app.add_option("--rate", rate, "Open loop: target requests/s per step, e.g. 50,100,200 (replaces --concurrency)");
  app.add_option("--ramp", ramp, "Open loop: step (constant within each step) or linear (from --rate to --rate-end)")
      ->check(CLI::IsMember({"step", "linear"}))
      ->capture_default_str();
  app.add_option("--rate-end", rate_end, "Open loop, linear ramp: requests/s at the end of the run");
  app.add_option("--workers", workers, "Open loop: most requests in flight at once")
      ->check(CLI::Range(1u, 4096u))
      ->capture_default_str();
  app.add_option("--window", window, "--rpc stream: frames in flight per stream")
      ->check(CLI::Range(1u, 1024u))
      ->capture_default_str();
  app.add_option("--duration-s", duration_s, "Length of each step")->check(CLI::Range(0.1, 86400.0))->capture_default_str();
  app.add_option("--max-requests", max_requests, "Most requests per step")
      ->check(CLI::Range(uint64_t{1}, uint64_t{1} << 40))
      ->capture_default_str();
  app.add_option("--json", json_path, "Write the report as JSON");
  app.add_option("--csv", csv_path, "Write one CSV row per step (perf_analyzer style, microseconds)");
  app.add_option("--plot", plot_path,
                 "Write a PNG: latency against throughput per step, and the hit rate over time (python3-matplotlib)");
  app.add_option("--token-file", token_file, "Bearer token for servers started with --auth-token-file");
  CLI11_PARSE(app, argc, argv);

  auto parsed_rpc = parse_rpc(rpc);
  if (!parsed_rpc) return fail(parsed_rpc.error().message);
  workload_args.rpc = *parsed_rpc;
  workload_args.omit_points = !with_points;
  const bool open_loop = !rate.empty();
  if (open_loop && workload_args.rpc == Rpc::kStream) {
    return fail("--rate: a stream paces itself (closed loop); use --concurrency with --rpc stream");
  }
  std::string error;
  std::vector<StepPlan> plans;
  if (open_loop) {
    const auto rates = parse_list(rate, "--rate", &error);
    if (rates.empty()) return fail(error);
    if (ramp == "linear") {
      if (!(rate_end > 0)) return fail("--ramp linear: give --rate-end, the requests/s to ramp to");
      if (rates.size() != 1) return fail("--ramp linear: give one starting --rate, got " + std::to_string(rates.size()));
      plans.push_back({true, workers, rates[0], rate_end, duration_s, max_requests, window});
    } else {
      for (double r : rates) plans.push_back({true, workers, r, r, duration_s, max_requests, window});
    }
  } else {
    const auto levels = parse_list(concurrency, "--concurrency", &error);
    if (levels.empty()) return fail(error);
    for (double c : levels) {
      if (c != static_cast<double>(static_cast<uint32_t>(c)) || c > 4096) {
        return fail("--concurrency: expected whole numbers of callers up to 4096, got " + std::to_string(c));
      }
      plans.push_back({false, static_cast<uint32_t>(c), 0, 0, duration_s, max_requests, window});
    }
  }

  animspace::ClientOptions options;
  if (const char* token = std::getenv("ANIMSPACE_TOKEN"); token != nullptr) options.token = token;
  if (!token_file.empty()) {
    auto text = animspace::read_whole_file(token_file);
    if (!text) return fail("--token-file: " + text.error().message);
    options.token = *text;
    while (!options.token.empty() && std::isspace(static_cast<unsigned char>(options.token.back()))) options.token.pop_back();
  }
  auto targets = connect_targets(servers, options);
  if (!targets) return fail(targets.error().message);

  try {
    auto workload = make_workload(*targets->load, workload_args);
    if (!workload) return fail(workload.error().message);
    RunReport report;
    report.servers = servers;
    report.workload = &*workload;
    const auto run_start = std::chrono::steady_clock::now();
    for (const StepPlan& plan : plans) report.steps.push_back(run_step(*workload, *targets, plan, run_start));
    print_table(report);

    const nlohmann::json document = report_json(report);
    std::string json_out = json_path;
    if (json_out.empty() && !plot_path.empty()) json_out = plot_path + ".json";
    if (!json_out.empty()) {
      if (auto written = animspace::write_file_atomically(json_out, document.dump(2) + "\n"); !written.ok()) {
        return fail(written.error().message);
      }
    }
    if (!csv_path.empty()) {
      if (auto written = animspace::write_file_atomically(csv_path, report_csv(report)); !written.ok()) {
        return fail(written.error().message);
      }
    }
    if (!plot_path.empty()) {
      const std::vector<std::string> command{"/usr/bin/python3", plot_script().string(), json_out, plot_path};
      if (!run_process(command)) return fail("--plot: /usr/bin/python3 " + command[1] + " failed (python3-matplotlib?)");
    }
    uint64_t errors = 0;
    for (const StepResult& s : report.steps) errors += s.error_count();
    return errors == 0 ? 0 : 1;
  } catch (const animspace::RpcError& rpc_error) {
    return fail(rpc_error.what());
  }
}
