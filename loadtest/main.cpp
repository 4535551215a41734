// animspace-loadtest: bounded closed-loop load against one or several animspaced servers.
//
// This first version drives the registry RPCs (ListModels, DescribeModel, health) so that the
// serving path, its concurrency and its latency can be measured today; replay of key points from
// real sequences joins when pose evaluation lands (issue #9). Every run is bounded by both a
// duration and a request count, and targets only the addresses given on the command line.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "clients/cpp/client.h"

namespace {

struct Outcome {
  std::vector<double> latencies_s;  // successful calls
  std::map<std::string, uint64_t> errors;
};

double percentile(std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0;
  const size_t index = std::min(sorted.size() - 1, static_cast<size_t>(q * static_cast<double>(sorted.size())));
  return sorted[index];
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> servers{"127.0.0.1:50051"};
  std::string rpc = "describe";
  std::string model = "arm";
  int concurrency = 4;
  double duration_s = 5;
  uint64_t max_requests = 100000;
  std::string json_path;

  CLI::App app{"animspace-loadtest — bounded closed-loop load against animspaced"};
  app.add_option("--server", servers, "Server address(es); several are used round-robin")->capture_default_str();
  app.add_option("--rpc", rpc, "Call to drive")->check(CLI::IsMember({"list", "describe", "health"}))->capture_default_str();
  app.add_option("--model", model, "Model for describe")->capture_default_str();
  app.add_option("--concurrency", concurrency, "Concurrent callers")->check(CLI::Range(1, 1024))->capture_default_str();
  app.add_option("--duration-s", duration_s, "Stop after this long")->check(CLI::Range(0.1, 3600.0))->capture_default_str();
  app.add_option("--max-requests", max_requests, "Stop after this many calls")->check(CLI::Range(uint64_t{1}, uint64_t{100000000}))->capture_default_str();
  app.add_option("--json", json_path, "Write the report as JSON to this file");
  CLI11_PARSE(app, argc, argv);

  std::vector<std::unique_ptr<animspace::Client>> clients;
  for (const auto& s : servers) clients.push_back(std::make_unique<animspace::Client>(s));

  std::atomic<uint64_t> issued{0};
  const auto start = std::chrono::steady_clock::now();
  const auto stop_at = start + std::chrono::duration<double>(duration_s);
  std::vector<Outcome> outcomes(static_cast<size_t>(concurrency));
  std::vector<std::thread> workers;
  for (int w = 0; w < concurrency; ++w) {
    workers.emplace_back([&, w] {
      Outcome& out = outcomes[static_cast<size_t>(w)];
      while (std::chrono::steady_clock::now() < stop_at) {
        const uint64_t n = issued.fetch_add(1);
        if (n >= max_requests) break;
        auto& client = *clients[n % clients.size()];
        const auto t0 = std::chrono::steady_clock::now();
        try {
          if (rpc == "list") {
            (void)client.list_models();
          } else if (rpc == "describe") {
            (void)client.describe_model(model);
          } else {
            (void)client.health();
          }
          out.latencies_s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        } catch (const animspace::RpcError& e) {
          ++out.errors[animspace::status_code_name(e.code())];
        }
      }
    });
  }
  for (auto& t : workers) t.join();
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::vector<double> all;
  std::map<std::string, uint64_t> errors;
  for (auto& o : outcomes) {
    all.insert(all.end(), o.latencies_s.begin(), o.latencies_s.end());
    for (const auto& [code, count] : o.errors) errors[code] += count;
  }
  std::sort(all.begin(), all.end());
  uint64_t error_count = 0;
  for (const auto& [code, count] : errors) error_count += count;
  const double throughput = static_cast<double>(all.size()) / elapsed;

  std::printf("%-10s %6s %10s %10s %10s %10s %10s %10s %8s\n", "rpc", "conc", "calls", "req/s", "p50 ms", "p90 ms",
              "p99 ms", "p99.9 ms", "errors");
  std::printf("%-10s %6d %10zu %10.1f %10.3f %10.3f %10.3f %10.3f %8llu\n", rpc.c_str(), concurrency, all.size(),
              throughput, 1e3 * percentile(all, 0.5), 1e3 * percentile(all, 0.9), 1e3 * percentile(all, 0.99),
              1e3 * percentile(all, 0.999), static_cast<unsigned long long>(error_count));
  for (const auto& [code, count] : errors) std::printf("  %s: %llu\n", code.c_str(), static_cast<unsigned long long>(count));

  if (!json_path.empty()) {
    std::ofstream json(json_path);
    json << "{\"rpc\": \"" << rpc << "\", \"concurrency\": " << concurrency << ", \"elapsed_s\": " << elapsed
         << ", \"successful\": " << all.size() << ", \"errors\": " << error_count
         << ", \"throughput_per_s\": " << throughput << ", \"latency_s\": {\"p50\": " << percentile(all, 0.5)
         << ", \"p90\": " << percentile(all, 0.9) << ", \"p99\": " << percentile(all, 0.99)
         << ", \"p99_9\": " << percentile(all, 0.999) << "}}\n";
  }
  return error_count == 0 ? 0 : 1;
}
