// Fuzz target: animation_space::read_gltf_rig (glTF 2.0 skins, .gltf JSON or .glb binary, through
// tinygltf), then what `animspace import-rig --gltf` does with an accepted rig
// (clients/cpp/cli/fit.cpp): from_linear_blend, tangent planes from the file's normals (or
// area-weighted ones), and one evaluation in the file's pose.
//
// The importer's own arithmetic on untrusted numbers is the target: accessor byteOffset, count and
// the buffer view's byteStride against the buffer's length (accessor_view), JOINTS indices against
// the skin, indices against the primitive, the node graph's parents. Seeds (fuzz/corpus/gltf,
// fuzz/make_seed_corpus.cpp) are a tiny skinned strip as .glb and as .gltf with a base64 data URI
// buffer, so that mutations reach those checks rather than stopping in the JSON or GLB framing.
//
// read_gltf_rig reads a path, not bytes (tinygltf resolves buffer URIs relative to the file), so
// each input is written to one file in a private directory: a relative "uri" then finds nothing.
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/animspace/import.h"
#include "core/animspace/model.h"
#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"
#include "fuzz/fuzz_support.h"

namespace animspace::fuzz {
namespace {

namespace as = animation_space;

const std::filesystem::path& input_path() {
  static const std::filesystem::path path = [] {
    std::string dir = (std::filesystem::temp_directory_path() / "gltf_fuzzer.XXXXXX").string();
    FUZZ_CHECK(::mkdtemp(dir.data()) != nullptr);
    // The extension does not choose the parser (the "glTF" magic does), so one name serves both.
    return std::filesystem::path(dir) / "fuzz.gltf";
  }();
  return path;
}

void check_rig(const as::GltfRig& gltf) {
  const as::ImportedRig& rig = gltf.rig;
  // The importer validates what it returns; restated so that a path that skips it is caught.
  FUZZ_CHECK(as::validate(rig.model).ok());
  const int bones = rig.model.skeleton.bone_count();
  const int vertices = rig.model.vertex_count();
  FUZZ_CHECK(bones >= 2);  // the super-root and at least one skin joint
  FUZZ_CHECK(static_cast<int>(gltf.pose.size()) == bones);
  for (const int32_t bone : rig.bone_of_source) FUZZ_CHECK(bone >= 1 && bone < bones);
  FUZZ_CHECK(gltf.rest_normals.rows() == 0 || gltf.rest_normals.rows() == vertices);
  for (Eigen::Index f = 0; f < rig.model.faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) FUZZ_CHECK(rig.model.faces(f, c) >= 0 && rig.model.faces(f, c) < vertices);
  }

  // import-rig's next steps.
  const as::AnimationSpaceModel model = as::from_linear_blend(rig.model);
  FUZZ_CHECK(model.vertex_count() == vertices);
  Eigen::MatrixX3d normals = gltf.rest_normals;
  if (normals.rows() == 0) normals = geometry::area_weighted_normals(rig.model.rest_points.transpose(), model.faces);
  const auto planes = as::tangent_planes_from_normals(model, normals);
  if (!planes) FUZZ_CHECK(planes.error().code == ErrorCode::kInvalidArgument);
  PointMatrix posed;
  as::evaluate(model, gltf.pose, posed);
  FUZZ_CHECK(posed.rows() == vertices);
}

}  // namespace
}  // namespace animspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  const std::filesystem::path& path = fuzz::input_path();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    FUZZ_CHECK(out.good());
  }
  const auto gltf = animation_space::read_gltf_rig(path);
  if (!gltf) {
    fuzz::check_refusal(gltf.error(), path.string());
    return 0;
  }
  fuzz::check_rig(*gltf);
  return 0;
}
