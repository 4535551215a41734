// Fuzz target: mesh_io::parse_pc2 (Point Cache 2, binary). The format has no slack — a fixed
// header, then exactly the samples it announces — so anything it accepts must be rewritten by
// serialize_pc2 byte for byte.
#include <cmath>

#include "core/mesh_io/pc2.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  const std::string_view bytes = fuzz::as_bytes(data, size);
  const auto cache = mesh_io::parse_pc2(bytes, "fuzz.pc2");
  if (!cache) {
    fuzz::check_refusal(cache.error(), "fuzz.pc2");
    return 0;
  }
  FUZZ_CHECK(cache->num_points > 0 && cache->num_frames() > 0);
  FUZZ_CHECK(cache->samples.cols() == 3 * Eigen::Index{cache->num_points});
  FUZZ_CHECK(cache->samples.allFinite());
  FUZZ_CHECK(std::isfinite(cache->start_frame) && std::isfinite(cache->sample_rate) && cache->sample_rate > 0);
  FUZZ_CHECK(mesh_io::serialize_pc2(*cache) == bytes);
  return 0;
}
