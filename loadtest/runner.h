// Running one step of load: a closed loop (N callers, each sending its next request as soon as
// the previous one answers) or an open loop (requests scheduled at a target rate, constant or
// ramping linearly, whatever the answers do). Every step is bounded by a duration and a request
// count. Open-loop latency is measured from each request's scheduled time, not from when a free
// worker got to it, so a server that falls behind shows its queueing delay instead of hiding it
// ("coordinated omission").
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "clients/cpp/client.h"
#include "loadtest/histogram.h"
#include "loadtest/workload.h"

namespace animspace::loadtest {

// The servers under load: one channel balancing calls round-robin across them (the client-side
// load balancing a Kubernetes headless Service is made for), and one client per server for its
// own statistics.
struct Targets {
  std::vector<std::string> servers;
  std::unique_ptr<Client> load;                      // round_robin over every server
  std::vector<std::unique_ptr<Client>> per_server;  // GetStats of each server
};

// One address is used as given (a DNS name resolving to several replicas is balanced too, e.g.
// dns:///animspaced-headless:50051); several must be IP literals (host:port with an IPv4 address
// or [IPv6]:port, not mixed), joined into one ipv4:/ipv6: target. Errors name the address.
Result<Targets> connect_targets(const std::vector<std::string>& servers, const ClientOptions& options);

// Counters of one model summed over every server's GetStats.
struct ServerCounters {
  uint64_t requests = 0;
  uint64_t poses = 0;
  uint64_t hits = 0;
  uint64_t blends = 0;
  uint64_t misses = 0;
  uint64_t errors = 0;
};
ServerCounters read_server_counters(Targets& targets, const std::string& model);

struct StepPlan {
  bool open_loop = false;
  uint32_t concurrency = 1;   // closed loop: callers; open loop: workers that may be in flight at once
  double rate_start = 0;      // open loop: requests/s at the start of the step
  double rate_end = 0;        // … and at its end (= rate_start for a constant rate)
  double duration_s = 10;
  uint64_t max_requests = 1000000;
  uint32_t stream_window = 1;  // kStream: frames in flight per stream
};

// One second of a step: what completed in it.
struct Second {
  uint64_t ok = 0;
  uint64_t errors = 0;
  uint64_t poses = 0;
  uint64_t hits = 0;
  uint64_t blends = 0;
  uint64_t misses = 0;
};

struct StepResult {
  StepPlan plan;
  double start_s = 0;  // since the run began
  double seconds = 0;  // wall time of the step
  uint64_t requests = 0;  // calls sent (kStream: frames written)
  uint64_t ok = 0;        // answered successfully
  std::map<std::string, uint64_t> errors;  // by status code name; CLIENT for a broken answer
  uint64_t unsent = 0;    // open loop: scheduled but not yet started when the step ended
  uint64_t poses = 0;     // poses in successful answers
  uint64_t hits = 0;
  uint64_t blends = 0;
  uint64_t misses = 0;
  LatencyHistogram latency;    // per successful call (kStream: per frame)
  std::vector<Second> timeline;
  ServerCounters server_before;
  ServerCounters server_after;

  uint64_t error_count() const;
};

// Runs one step of `workload` against `targets`. `run_start` anchors start_s and the timeline.
StepResult run_step(const Workload& workload, Targets& targets, const StepPlan& plan,
                    std::chrono::steady_clock::time_point run_start);

// Open loop: the time (seconds from the step's start) at which request k (0-based) is due, for a
// rate ramping linearly from r0 to r1 over T seconds: the k-th solution of ∫₀ᵗ r = k.
double scheduled_time(uint64_t k, double r0, double r1, double T);

}  // namespace animspace::loadtest
