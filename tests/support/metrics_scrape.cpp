#include "tests/support/metrics_scrape.h"

#include <cstdlib>

#include <httplib.h>

namespace animspace::testing {

std::optional<std::string> scrape_metrics(int port) {
  httplib::Client http("127.0.0.1", port);
  const auto scraped = http.Get("/metrics");
  if (!scraped || scraped->status != 200) return std::nullopt;
  return scraped->body;
}

std::optional<double> metric_value(const std::string& page, const std::string& series) {
  // A sample line is "<series> <value>" at the start of a line.
  const std::string key = series + " ";
  for (size_t at = page.find(key); at != std::string::npos; at = page.find(key, at + 1)) {
    if (at != 0 && page[at - 1] != '\n') continue;
    return std::strtod(page.c_str() + at + key.size(), nullptr);
  }
  return std::nullopt;
}

}  // namespace animspace::testing
