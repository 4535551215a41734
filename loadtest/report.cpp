#include "loadtest/report.h"

#include <cstdio>
#include <sstream>

namespace animspace::loadtest {
namespace {

constexpr double kQuantiles[] = {0.5, 0.75, 0.9, 0.95, 0.99, 0.999};

double per_second(uint64_t count, double seconds) { return seconds > 0 ? static_cast<double>(count) / seconds : 0.0; }
double ratio(uint64_t part, uint64_t whole) { return whole ? static_cast<double>(part) / static_cast<double>(whole) : 0.0; }
double us(int64_t ns) { return static_cast<double>(ns) / 1e3; }

std::string step_label(const StepPlan& p) {
  if (!p.open_loop) return "closed c=" + std::to_string(p.concurrency);
  std::ostringstream s;
  s << "open " << p.rate_start << "/s";
  if (p.rate_end != p.rate_start) s << "→" << p.rate_end << "/s";
  return s.str();
}

nlohmann::json counters_json(const ServerCounters& c) {
  return {{"requests", c.requests}, {"poses", c.poses},   {"hits", c.hits},
          {"blends", c.blends},     {"misses", c.misses}, {"errors", c.errors}};
}

nlohmann::json step_json(const StepResult& s) {
  nlohmann::json distribution = nlohmann::json::array();
  for (double q : kQuantiles) distribution.push_back({{"percentage", 100 * q}, {"latency_us", us(s.latency.quantile(q))}});
  nlohmann::json codes = {{"OK", s.ok}};
  for (const auto& [code, count] : s.errors) codes[code] = count;
  nlohmann::json timeline = nlohmann::json::array();
  for (size_t i = 0; i < s.timeline.size(); ++i) {
    const Second& t = s.timeline[i];
    timeline.push_back({{"t_s", s.start_s + static_cast<double>(i)},
                        {"ok", t.ok},
                        {"errors", t.errors},
                        {"poses", t.poses},
                        {"hits", t.hits},
                        {"blends", t.blends},
                        {"misses", t.misses}});
  }
  const ServerCounters& a = s.server_after;
  const ServerCounters& b = s.server_before;
  return {{"label", step_label(s.plan)},
          {"mode", s.plan.open_loop ? "open" : "closed"},
          {"concurrency", s.plan.concurrency},
          {"target_rate", s.plan.open_loop ? nlohmann::json(s.plan.rate_start) : nlohmann::json()},
          {"target_rate_end", s.plan.open_loop ? nlohmann::json(s.plan.rate_end) : nlohmann::json()},
          {"start_s", s.start_s},
          {"seconds", s.seconds},
          {"requests", s.requests},
          {"count", s.requests},
          {"ok", s.ok},
          {"errors", s.error_count()},
          {"unsent", s.unsent},
          {"rps", per_second(s.ok, s.seconds)},
          {"poses_per_second", per_second(s.poses, s.seconds)},
          {"average_us", s.latency.mean() / 1e3},
          {"fastest_us", us(s.latency.min())},
          {"slowest_us", us(s.latency.max())},
          {"p50_us", us(s.latency.quantile(0.5))},
          {"p90_us", us(s.latency.quantile(0.9))},
          {"p99_us", us(s.latency.quantile(0.99))},
          {"p99_9_us", us(s.latency.quantile(0.999))},
          {"latencyDistribution", distribution},
          {"statusCodeDistribution", codes},
          {"poses", s.poses},
          {"hits", s.hits},
          {"blends", s.blends},
          {"misses", s.misses},
          {"hit_rate", ratio(s.hits, s.poses)},
          {"blend_rate", ratio(s.blends, s.poses)},
          {"miss_rate", ratio(s.misses, s.poses)},
          {"server_before", counters_json(b)},
          {"server_after", counters_json(a)},
          {"server_delta", counters_json({a.requests - b.requests, a.poses - b.poses, a.hits - b.hits,
                                          a.blends - b.blends, a.misses - b.misses, a.errors - b.errors})},
          {"timeline", timeline}};
}

}  // namespace

nlohmann::json report_json(const RunReport& r) {
  nlohmann::json steps = nlohmann::json::array();
  for (const StepResult& s : r.steps) steps.push_back(step_json(s));
  const Workload& w = *r.workload;
  return {{"tool", "animspace-loadtest"},
          {"servers", r.servers},
          {"model", w.model},
          {"version", w.version},
          {"rpc", rpc_name(w.rpc)},
          {"batch", w.batch},
          {"frames", w.frame_count()},
          {"steps", steps}};
}

std::string report_csv(const RunReport& r) {
  std::ostringstream out;
  out << "Step,Mode,Concurrency,Target Rate,Requests/Second,Poses/Second,Requests,OK,Errors,Unsent,"
         "Avg latency,p50 latency,p90 latency,p95 latency,p99 latency,p99.9 latency,Hits,Blends,Misses,Hit Rate\n";
  for (size_t i = 0; i < r.steps.size(); ++i) {
    const StepResult& s = r.steps[i];
    out << i << ',' << (s.plan.open_loop ? "open" : "closed") << ',' << s.plan.concurrency << ','
        << (s.plan.open_loop ? s.plan.rate_start : 0.0) << ',' << per_second(s.ok, s.seconds) << ','
        << per_second(s.poses, s.seconds) << ',' << s.requests << ',' << s.ok << ',' << s.error_count() << ','
        << s.unsent << ',' << s.latency.mean() / 1e3 << ',' << us(s.latency.quantile(0.5)) << ','
        << us(s.latency.quantile(0.9)) << ',' << us(s.latency.quantile(0.95)) << ',' << us(s.latency.quantile(0.99))
        << ',' << us(s.latency.quantile(0.999)) << ',' << s.hits << ',' << s.blends << ',' << s.misses << ','
        << ratio(s.hits, s.poses) << '\n';
  }
  return out.str();
}

void print_table(const RunReport& r) {
  const Workload& w = *r.workload;
  std::printf("%s version %llu, %s, %u pose%s per call, %zu frames, %zu server%s\n", w.model.c_str(),
              static_cast<unsigned long long>(w.version), rpc_name(w.rpc), w.batch, w.batch == 1 ? "" : "s",
              w.frame_count(), r.servers.size(), r.servers.size() == 1 ? "" : "s");
  std::printf("%-22s %9s %10s %9s %9s %9s %9s %8s %7s %7s %7s\n", "step", "requests", "req/s", "p50 ms", "p90 ms",
              "p99 ms", "p99.9 ms", "errors", "hit%", "blend%", "miss%");
  for (const StepResult& s : r.steps) {
    std::printf("%-22s %9llu %10.1f %9.3f %9.3f %9.3f %9.3f %8llu %6.1f%% %6.1f%% %6.1f%%\n", step_label(s.plan).c_str(),
                static_cast<unsigned long long>(s.requests), per_second(s.ok, s.seconds),
                s.latency.quantile(0.5) / 1e6, s.latency.quantile(0.9) / 1e6, s.latency.quantile(0.99) / 1e6,
                s.latency.quantile(0.999) / 1e6, static_cast<unsigned long long>(s.error_count()),
                100 * ratio(s.hits, s.poses), 100 * ratio(s.blends, s.poses), 100 * ratio(s.misses, s.poses));
    for (const auto& [code, count] : s.errors) {
      std::printf("%-22s   %s: %llu\n", "", code.c_str(), static_cast<unsigned long long>(count));
    }
    if (s.unsent > 0) {
      std::printf("%-22s   %llu scheduled requests were still waiting for a worker at the end\n", "",
                  static_cast<unsigned long long>(s.unsent));
    }
  }
}

}  // namespace animspace::loadtest
