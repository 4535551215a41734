// Inputs that once crashed a fuzz target (fuzz/, scripts/fuzz-smoke.sh), replayed in the normal
// suite so that the fixes hold in builds without clang or libFuzzer. Every file under
// fuzz/regressions/<target>/ is fed to the parser that target fuzzes and must come back as a
// value or an error; a test per bug states which, and why.
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/animspace/import.h"
#include "core/animspace/model.h"
#include "core/container/model_container.h"
#include "core/mesh_io/libigl_rig.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "core/model/model_info.h"
#include "core/model/servable.h"
#include "core/pmsc/pmsc_io.h"
#include "harness/build_tree.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace fs = std::filesystem;

// fuzz/regressions/ of this source tree (the test binary is built from it);
// tests/CMakeLists.txt defines it as an absolute path: __FILE__ is relative to the build
// directory when ccache rewrites paths (Makefile: CCACHE_BASEDIR).
fs::path regressions_dir() { return harness::source_dir() / "fuzz" / "regressions"; }

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Whether `parse` returned (a value or an error): the call itself is the test.
template <typename T>
bool returned(const Result<T>&) {
  return true;
}

// What the daemon's registry runs on a model file (server/model_registry.cpp, load_version).
bool load_like_the_registry(std::string_view bytes) {
  const std::string source = "regression.anim";
  const auto container = container::parse(bytes, source);
  return !container || returned(model::load_servable(*container, source));
}

// What gltf_fuzzer runs: read_gltf_rig takes a path (tinygltf resolves buffer URIs next to the
// file), so the bytes go to a file of their own first.
bool import_gltf(std::string_view bytes) {
  const testing::TempDir dir;
  const fs::path path = dir / "regression.gltf";
  std::ofstream(path, std::ios::binary) << bytes;
  return returned(animation_space::read_gltf_rig(path));
}

// Each fuzz target's parser, for the replay of its directory.
const std::map<std::string, std::function<bool(std::string_view)>>& parsers() {
  static const std::map<std::string, std::function<bool(std::string_view)>> table = {
      {"obj", [](std::string_view b) { return returned(mesh_io::parse_obj(b, "regression.obj")); }},
      {"ply", [](std::string_view b) { return returned(mesh_io::parse_ply(b, "regression.ply")); }},
      {"off", [](std::string_view b) { return returned(mesh_io::parse_off(b, "regression.off")); }},
      {"pc2", [](std::string_view b) { return returned(mesh_io::parse_pc2(b, "regression.pc2")); }},
      {"tgf", [](std::string_view b) { return returned(mesh_io::parse_tgf(b, "regression.tgf")); }},
      {"dmat", [](std::string_view b) { return returned(mesh_io::parse_dmat(b, "regression.dmat")); }},
      {"tmat", [](std::string_view b) { return returned(mesh_io::parse_tmat(b, "regression.tmat")); }},
      {"model_container", [](std::string_view b) { return load_like_the_registry(b); }},
      {"gltf", [](std::string_view b) { return import_gltf(b); }},
  };
  return table;
}

TEST(FuzzRegression, EverySavedInputReturns) {
  const fs::path root = regressions_dir();
  ASSERT_TRUE(fs::is_directory(root)) << root;
  int replayed = 0;
  for (const auto& [target, parse] : parsers()) {
    if (!fs::is_directory(root / target)) continue;
    for (const auto& entry : fs::directory_iterator(root / target)) {
      if (!entry.is_regular_file() || entry.path().filename().string().starts_with(".")) continue;
      SCOPED_TRACE(entry.path().string());
      EXPECT_TRUE(parse(read_bytes(entry.path())));
      ++replayed;
    }
  }
  RecordProperty("replayed", replayed);
}

// dmat_fuzzer: a binary DMAT header for an empty matrix (`0 0`, then `3 0`) copied its empty
// payload with memcpy into the matrix's null storage, which UBSan reports (memcpy's pointers
// must not be null even for 0 bytes). The saved input also had a stray token after `3 0`, which
// the binary header accepted although the text header refuses it.
TEST(FuzzRegression, BinaryDmatOfAnEmptyMatrix) {
  const auto empty = mesh_io::parse_dmat(std::string_view("0 0\n3 0\n"), "empty.dmat");
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  EXPECT_EQ(empty->rows(), 0);
  EXPECT_EQ(empty->cols(), 3);

  const std::string saved = read_bytes(regressions_dir() / "dmat" / "binary_empty_matrix_header_with_extra_token.dmat");
  ASSERT_FALSE(saved.empty());
  const auto refused = mesh_io::parse_dmat(saved, "saved.dmat");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(refused.error().message, "saved.dmat:2: expected end of line after `cols rows`, got '02z'");
}

// dmat_fuzzer (timeout): the 12-byte text DMAT `2020202022 0` is an empty matrix of two billion
// columns; the parser walked the columns one by one to read zero values (seconds of CPU per
// request), and so did the finiteness check of the binary variant. Both now count values.
TEST(FuzzRegression, EmptyDmatWithTwoBillionColumns) {
  const std::string saved = read_bytes(regressions_dir() / "dmat" / "empty_matrix_of_two_billion_columns.dmat");
  ASSERT_EQ(saved, "2020202022 0");
  const auto text = mesh_io::parse_dmat(saved, "saved.dmat");
  ASSERT_TRUE(text.ok()) << text.error().message;
  EXPECT_EQ(text->rows(), 0);
  EXPECT_EQ(text->cols(), 2020202022);
  const auto binary = mesh_io::parse_dmat(std::string_view("0 0\n2020202022 0\n"), "binary.dmat");
  ASSERT_TRUE(binary.ok()) << binary.error().message;
  EXPECT_EQ(binary->cols(), 2020202022);
}

// ply_fuzzer (timeout): a header declaring an element of 128 812 929 instances and no properties;
// the reader walked the instances one by one to read nothing (35 s per file under the fuzzer). An
// element without properties holds nothing in any encoding and is now skipped whole; the mesh
// around such an element reads as before.
TEST(FuzzRegression, PlyElementOfManyInstancesWithoutProperties) {
  const std::string saved =
      read_bytes(regressions_dir() / "ply" / "element_of_128_million_instances_without_properties.ply");
  ASSERT_FALSE(saved.empty());
  EXPECT_FALSE(mesh_io::parse_ply(saved, "saved.ply").ok());  // no vertex element: refused, at once
  const std::string_view tidy =
      "ply\nformat ascii 1.0\nelement nothing 2000000000\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
      "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const auto mesh = mesh_io::parse_ply(tidy, "tidy.ply");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->V.rows(), 3);
  EXPECT_EQ(mesh->F.rows(), 1);
  EXPECT_EQ(mesh->V(1, 0), 1.0);
  EXPECT_EQ(mesh->F(0, 2), 2);
}

// model_container_fuzzer: a PMSC container (checksums intact) whose pmsc.key_mean holds 2e307,
// finite but far beyond the float32 frames training computes it from, loaded; the first pose
// served then had e_key = Inf, which the soft cache asserts against. pmsc::load now refuses it.
TEST(FuzzRegression, PmscKeyMeanBeyondFloatRangeIsRefusedAtLoad) {
  const std::string saved = read_bytes(regressions_dir() / "model_container" / "pmsc_key_mean_beyond_float_range.anim");
  const auto container = container::parse(saved, "saved.anim");
  ASSERT_TRUE(container.ok()) << container.error().message;
  const auto info = model::describe(*container, "saved.anim");
  ASSERT_TRUE(info.ok()) << info.error().message;
  ASSERT_EQ(info->kind, container::ModelKind::kPmsc);
  const auto loaded = pmsc::load(*container, "saved.anim");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(loaded.error().message.find("key_mean or key_basis holds a value beyond float32 range"), std::string::npos)
      << loaded.error().message;
}

// model_container_fuzzer: a PMSC container with a posing engine whose animspace.influence_offsets
// has a middle entry (vertex 9's end) of 268435469 while only the last is compared with the 14
// influences: validate() then read animspace.influence_bones far past its end (ASan:
// heap-buffer-overflow) while loading the file.
TEST(FuzzRegression, InfluenceOffsetPastTheInfluencesIsRefused) {
  const std::string saved =
      read_bytes(regressions_dir() / "model_container" / "influence_offset_past_the_influences.anim");
  const auto container = container::parse(saved, "saved.anim");
  ASSERT_TRUE(container.ok()) << container.error().message;
  const auto engine = animation_space::load(*container, "saved.anim");
  ASSERT_FALSE(engine.ok());
  EXPECT_EQ(engine.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(engine.error().message, "saved.anim: vertex 9: influence offset 268435469 is past the 14 influences");

  animation_space::InfluenceSets sets;
  sets.offsets = {0, 5, 2};
  sets.bones = {0, 1};
  EXPECT_FALSE(animation_space::validate(sets, 2).ok());
}

// model_container_fuzzer, inputs written by hand after reading model::describe and fed to the
// fuzz target: a pmsc.epsilon section with no rows was read at (0, 0) — out of bounds, a crash of
// the daemon while loading the file — and pmsc.channels = 10^9 made N·D overflow int in the
// message about pmsc.mean's width.
TEST(FuzzRegression, PmscEpsilonWithoutRowsIsRefused) {
  const std::string saved = read_bytes(regressions_dir() / "model_container" / "pmsc_epsilon_without_rows.anim");
  const auto container = container::parse(saved, "saved.anim");
  ASSERT_TRUE(container.ok()) << container.error().message;
  const auto info = model::describe(*container, "saved.anim");
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(info.error().message, "saved.anim: section 'pmsc.epsilon' should be 1×2, got 0×2");
}

TEST(FuzzRegression, PmscChannelCountTooLargeForNTimesDInInt) {
  const std::string saved = read_bytes(regressions_dir() / "model_container" / "pmsc_channels_overflow_n_times_d.anim");
  const auto container = container::parse(saved, "saved.anim");
  ASSERT_TRUE(container.ok()) << container.error().message;
  ASSERT_EQ(container->metadata_value("pmsc.channels"), "1000000000");
  const auto info = model::describe(*container, "saved.anim");
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.error().code, ErrorCode::kInvalidArgument);
  // The seed's 11 points × 10^9 channels (the width its sequence.frames should have), in 64 bits.
  EXPECT_NE(info.error().message.find("'sequence.frames' should be F×11000000000,"), std::string::npos)
      << info.error().message;
}

}  // namespace
}  // namespace animspace
