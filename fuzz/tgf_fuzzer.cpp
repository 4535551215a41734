// Fuzz target: mesh_io::parse_tgf (libigl's TGF skeleton text).
#include "core/mesh_io/libigl_rig.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  const auto skeleton = mesh_io::parse_tgf(fuzz::as_bytes(data, size), "fuzz.tgf");
  if (!skeleton) {
    fuzz::check_refusal(skeleton.error(), "fuzz.tgf");
    return 0;
  }
  // What write_tgf accepts: joints, all finite, and bones joining two different joints.
  const Eigen::Index joints = skeleton->joints.rows();
  FUZZ_CHECK(joints > 0);
  FUZZ_CHECK(skeleton->joints.allFinite());
  for (Eigen::Index b = 0; b < skeleton->bones.rows(); ++b) {
    const int parent = skeleton->bones(b, 0);
    const int child = skeleton->bones(b, 1);
    FUZZ_CHECK(parent >= 0 && parent < joints && child >= 0 && child < joints && parent != child);
  }
  return 0;
}
