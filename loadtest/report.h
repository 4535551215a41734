// The load test's report: a table on stdout, JSON (per step: the ghz-style summary users know —
// count, rps, average/fastest/slowest, latencyDistribution, statusCodeDistribution — plus the
// soft cache's verdicts, the server's own counters before and after, and a per-second timeline)
// and CSV in perf_analyzer's manner (one row per step, latencies in microseconds).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "loadtest/runner.h"
#include "loadtest/workload.h"

namespace animspace::loadtest {

struct RunReport {
  std::vector<std::string> servers;
  const Workload* workload = nullptr;
  std::vector<StepResult> steps;
};

nlohmann::json report_json(const RunReport& report);
std::string report_csv(const RunReport& report);
void print_table(const RunReport& report);

}  // namespace animspace::loadtest
