// The io suite: parsing the formats the daemon reads, against a memcpy of the same bytes.
#include "bench/suites.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/bench_support.h"
#include "core/common/atomic_file.h"
#include "core/container/model_container.h"
#include "core/mesh_io/pc2.h"

namespace animspace::bench {
namespace {

struct Row {
  std::string name;
  std::string baseline;
  double seconds = 0;           // median over repetitions
  double baseline_seconds = 0;  // median over repetitions
  double bytes = 0;
};

// A synthetic point cache of the horse-gallop's size, for machines without ../shared/data.
animspace::mesh_io::PointCache synthetic_cache(int frames, int points) {
  animspace::mesh_io::PointCache cache;
  cache.num_points = points;
  cache.samples.resize(frames, 3 * points);
  for (int f = 0; f < frames; ++f) {
    for (int i = 0; i < 3 * points; ++i) cache.samples(f, i) = static_cast<float>(f) * 1e-3f + static_cast<float>(i % 97);
  }
  return cache;
}

std::vector<Row> io_suite(const std::optional<std::filesystem::path>& data, int repetitions) {
  std::vector<Row> rows;
  std::string pc2_bytes;
  std::string source = "synthetic 48×8431";
  if (data && std::filesystem::exists(*data / "horse-gallop/frames.pc2")) {
    auto bytes = animspace::read_whole_file(*data / "horse-gallop/frames.pc2");
    if (bytes) {
      pc2_bytes = std::move(*bytes);
      source = "horse-gallop/frames.pc2";
    }
  }
  if (pc2_bytes.empty()) pc2_bytes = animspace::mesh_io::serialize_pc2(synthetic_cache(48, 8431));

  std::vector<char> sink(pc2_bytes.size());
  const auto memcpy_baseline = [&] { std::memcpy(sink.data(), pc2_bytes.data(), pc2_bytes.size()); };

  Row pc2{"parse_pc2 (" + source + ")", "memcpy of the same bytes"};
  pc2.bytes = static_cast<double>(pc2_bytes.size());
  pc2.seconds = median_seconds(repetitions, [&] {
    auto parsed = animspace::mesh_io::parse_pc2(pc2_bytes, source);
    if (!parsed) std::fprintf(stderr, "parse_pc2 failed: %s\n", parsed.error().message.c_str());
  });
  pc2.baseline_seconds = median_seconds(repetitions, memcpy_baseline);
  rows.push_back(pc2);

  // The same frames as a model container section: parse includes CRC-32 verification.
  auto cache = animspace::mesh_io::parse_pc2(pc2_bytes, source);
  animspace::container::ModelContainer container;
  container.set_matrix("sequence.frames", cache->samples);
  const std::string container_bytes = animspace::container::serialize(container);
  std::vector<char> sink2(container_bytes.size());
  Row anim{"container parse (checksummed)", "memcpy of the same bytes"};
  anim.bytes = static_cast<double>(container_bytes.size());
  anim.seconds = median_seconds(repetitions, [&] {
    auto parsed = animspace::container::parse(container_bytes, "bench");
    if (!parsed) std::fprintf(stderr, "container parse failed: %s\n", parsed.error().message.c_str());
  });
  anim.baseline_seconds = median_seconds(
      repetitions, [&] { std::memcpy(sink2.data(), container_bytes.data(), container_bytes.size()); });
  rows.push_back(anim);
  return rows;
}

}  // namespace

nlohmann::json run_io_suite(const SuiteOptions& options) {
  const std::vector<Row> rows = io_suite(options.data, options.repetitions);
  std::printf("%-44s %12s %12s %10s %12s  %s\n", "benchmark", "median ms", "GB/s", "baseline", "× baseline",
              "baseline is");
  nlohmann::json results = nlohmann::json::array();
  for (const auto& r : rows) {
    std::printf("%-44s %12.3f %12.2f %10.3f %12.1f  %s\n", r.name.c_str(), 1e3 * r.seconds, r.bytes / r.seconds / 1e9,
                1e3 * r.baseline_seconds, r.seconds / r.baseline_seconds, r.baseline.c_str());
    results.push_back({{"name", r.name}, {"seconds", r.seconds}, {"baseline", r.baseline},
                       {"baseline_seconds", r.baseline_seconds}, {"bytes", r.bytes}});
  }
  return results;
}

}  // namespace animspace::bench
