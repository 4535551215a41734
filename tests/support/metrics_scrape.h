// Reading a daemon's Prometheus page (--metrics-listen) from the integration tests: the state the
// server counts (calls in flight, calls by status code) is what a test waits on. Compiled apart
// (metrics_scrape.cpp) because httplib's <resolv.h> defines a `_res` macro that breaks Eigen
// headers included after it.
#pragma once

#include <optional>
#include <string>

namespace animspace::testing {

// The page served at http://127.0.0.1:<port>/metrics, or nullopt when nothing answers.
std::optional<std::string> scrape_metrics(int port);

// The value of one sample on `page`: `series` is the metric name with its labels exactly as the
// page prints them ("animspace_calls_in_flight", "animspace_requests_total{rpc=\"…\",…}");
// nullopt when the page has no such line.
std::optional<double> metric_value(const std::string& page, const std::string& series);

}  // namespace animspace::testing
