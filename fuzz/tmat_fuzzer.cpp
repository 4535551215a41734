// Fuzz target: mesh_io::parse_tmat (libigl-style per-bone 4×3 transforms, text).
#include "core/mesh_io/libigl_rig.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  const auto transforms = mesh_io::parse_tmat(fuzz::as_bytes(data, size), "fuzz.tmat");
  if (!transforms) {
    fuzz::check_refusal(transforms.error(), "fuzz.tmat");
    return 0;
  }
  // What write_tmat accepts: at least one transform, every entry finite.
  FUZZ_CHECK(!transforms->empty());
  for (const auto& transform : *transforms) FUZZ_CHECK(transform.allFinite());
  return 0;
}
