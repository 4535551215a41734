// A level cut into blocks of bytes: the blocks tile the level, decode (by plain memcpy, the
// layout level_blocks.h documents) to the level's own arrays or to its pose computed here as
// v = Σ_j G_j p_j, a geomorph's blocks reach the coarser level at t = 1, and every block but a
// lone vertex fits the byte budget while one more vertex would not.
#include "core/lod/level_blocks.h"

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/lod/simplify.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;
using testing::arm_lod_case;
using testing::LodCase;

LodLevels arm_levels(const LodCase& c) {
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  EXPECT_TRUE(pm.ok());
  return make_levels(*pm);
}

template <typename T>
std::vector<T> decode(const std::string& bytes) {
  EXPECT_EQ(bytes.size() % sizeof(T), 0u);
  std::vector<T> out(bytes.size() / sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

// One vertex block's arrays, decoded, appended to whole-level arrays.
struct Decoded {
  std::vector<int32_t> offsets{0};
  std::vector<int32_t> bones;
  std::vector<float> positions;  // 4 per influence
  std::vector<float> delta;      // 4 per influence, with a geomorph
};

void append(const InfluenceBlock& block, uint32_t count, bool geomorph, Decoded& out) {
  const auto offsets = decode<uint32_t>(block.influence_offsets);
  ASSERT_EQ(offsets.size(), count + 1);
  EXPECT_EQ(offsets[0], 0u);
  const int32_t base = out.offsets.back();
  for (uint32_t v = 1; v <= count; ++v) out.offsets.push_back(base + static_cast<int32_t>(offsets[v]));
  for (uint32_t b : decode<uint32_t>(block.bone_indices)) out.bones.push_back(static_cast<int32_t>(b));
  for (float p : decode<float>(block.animation_positions)) out.positions.push_back(p);
  for (float d : decode<float>(block.geomorph_delta)) out.delta.push_back(d);
  EXPECT_EQ(block.geomorph_delta.empty(), !geomorph || offsets.back() == 0);
}

// Bytes of vertices [first, first + count) of `sets` in an animation-space block, counted here.
int64_t block_bytes(const as::InfluenceSets& sets, uint32_t first, uint32_t count, bool geomorph) {
  int64_t bytes = 4;
  for (uint32_t v = first; v < first + count; ++v) {
    const int n = sets.end(static_cast<int>(v)) - sets.begin(static_cast<int>(v));
    bytes += 4 + n * (4 + 16 + (geomorph ? 16 : 0));
  }
  return bytes;
}

// Σ_j G_j p_j of vertex v, from decoded arrays (eq. 3.1), in double.
Eigen::Vector3d pose_vertex(const Decoded& d, int v, const as::TransformList& G, bool with_delta) {
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (int k = d.offsets[static_cast<size_t>(v)]; k < d.offsets[static_cast<size_t>(v) + 1]; ++k) {
    Eigen::Vector4d p;
    for (int r = 0; r < 4; ++r) {
      const auto i = static_cast<size_t>(4 * k + r);
      p[r] = d.positions[i] + (with_delta ? d.delta[i] : 0.0f);
    }
    sum += G[static_cast<size_t>(d.bones[static_cast<size_t>(k)])] * p;
  }
  return sum.head<3>();
}

Eigen::Vector3d pose_vertex(const as::AnimationSpaceModel& model, int v, const as::TransformList& G) {
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (int k = model.influences.begin(v); k < model.influences.end(v); ++k) {
    sum += G[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] * model.positions.col(k);
  }
  return sum.head<3>();
}

class LevelBlocksTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    arm_ = new LodCase(arm_lod_case());
    lods_ = new LodLevels(arm_levels(*arm_));
  }
  static void TearDownTestSuite() {
    delete lods_;
    delete arm_;
  }
  static LodCase* arm_;
  static LodLevels* lods_;
};
LodCase* LevelBlocksTest::arm_ = nullptr;
LodLevels* LevelBlocksTest::lods_ = nullptr;

TEST_F(LevelBlocksTest, AnimationSpaceBlocksTileTheLevelWithinTheByteBudget) {
  ASSERT_GE(lods_->count(), 3);
  for (int l = 0; l < lods_->count(); ++l) {
    const as::AnimationSpaceModel& model = lods_->levels[static_cast<size_t>(l)].model;
    LevelBlockOptions options;
    options.max_block_vertices = 7;
    options.max_block_bytes = 160;  // a few arm vertices (1–2 influences: 24–44 bytes each)
    const LevelBlocks blocks(*lods_, l, options);
    ASSERT_EQ(blocks.vertex_count(), static_cast<uint32_t>(model.vertex_count()));
    EXPECT_EQ(blocks.influence_count(), static_cast<uint32_t>(model.influences.influence_count()));
    Decoded d;
    for (uint32_t first = 0; first < blocks.vertex_count();) {
      const uint32_t count = blocks.block_vertex_count(first);
      ASSERT_GE(count, 1u);
      ASSERT_LE(count, std::min(7u, blocks.vertex_count() - first));
      const int64_t bytes = block_bytes(model.influences, first, count, false);
      if (count > 1) {
        EXPECT_LE(bytes, 160) << "level " << l << " from " << first;
      }
      // Maximal: one more vertex would break the budget (or there is none, or the count cap).
      if (count < 7 && first + count < blocks.vertex_count()) {
        EXPECT_GT(block_bytes(model.influences, first, count + 1, false), 160) << "level " << l << " from " << first;
      }
      const InfluenceBlock block = blocks.influence_block(first, count);
      EXPECT_EQ(static_cast<int64_t>(block.influence_offsets.size() + block.bone_indices.size() +
                                     block.animation_positions.size()),
                bytes);
      append(block, count, false, d);
      first += count;
    }
    EXPECT_EQ(d.offsets, model.influences.offsets) << "level " << l;
    EXPECT_EQ(d.bones, model.influences.bones) << "level " << l;
    ASSERT_EQ(d.positions.size(), static_cast<size_t>(4 * model.positions.cols()));
    for (Eigen::Index k = 0; k < model.positions.cols(); ++k) {
      for (int r = 0; r < 4; ++r) {
        EXPECT_EQ(d.positions[static_cast<size_t>(4 * k + r)], static_cast<float>(model.positions(r, k)));
      }
    }
  }
}

TEST_F(LevelBlocksTest, GeomorphBlocksReachTheCoarserLevelAtTOne) {
  const as::TransformList& G = arm_->poses[arm_->poses.size() / 2];  // a bent elbow
  for (int l = 0; l < lods_->count(); ++l) {
    const LodLevel& fine = lods_->levels[static_cast<size_t>(l)];
    LevelBlockOptions options;
    options.geomorph = true;
    options.max_block_bytes = 300;
    const LevelBlocks blocks(*lods_, l, options);
    Decoded d;
    for (uint32_t first = 0; first < blocks.vertex_count();) {
      const uint32_t count = blocks.block_vertex_count(first);
      const InfluenceBlock block = blocks.influence_block(first, count);
      const size_t bytes = block.influence_offsets.size() + block.bone_indices.size() +
                           block.animation_positions.size() + block.geomorph_delta.size();
      if (count > 1) {
        EXPECT_LE(bytes, 300u) << "level " << l << " from " << first;
      }
      append(block, count, true, d);
      first += count;
    }
    ASSERT_EQ(d.delta.size(), d.positions.size()) << "level " << l;
    EXPECT_EQ(blocks.influence_count(), d.bones.size());
    const bool coarsest = l + 1 == lods_->count();
    if (coarsest) {
      // Nothing coarser: the level's own influences, Δp = 0.
      EXPECT_EQ(d.bones, fine.model.influences.bones);
      EXPECT_TRUE(std::all_of(d.delta.begin(), d.delta.end(), [](float x) { return x == 0; }));
    }
    PointMatrix coarser;
    if (!coarsest) as::evaluate(lods_->levels[static_cast<size_t>(l + 1)].model, G, coarser);
    for (int v = 0; v < fine.model.vertex_count(); ++v) {
      // t = 0 is the level itself; t = 1 the coarser vertex it collapses into (eq. 7.1).
      EXPECT_LT((pose_vertex(d, v, G, false) - pose_vertex(fine.model, v, G)).norm(), 1e-5) << l << " " << v;
      if (!coarsest) {
        const int c = fine.coarser_vertex[static_cast<size_t>(v)];
        EXPECT_LT((pose_vertex(d, v, G, true) - coarser.row(c).transpose().cast<double>()).norm(), 1e-5)
            << l << " " << v;
      }
    }
  }
}

TEST_F(LevelBlocksTest, PosedBlocksAreTheLevelAtThePose) {
  const int l = 1;
  const as::AnimationSpaceModel& model = lods_->levels[l].model;
  const as::TransformList& G = arm_->poses.back();
  LevelBlockOptions options;
  options.form = LevelForm::kPosed;
  options.pose = &G;
  options.max_block_vertices = 1000;
  options.max_block_bytes = 12 * 5 + 11;  // five posed vertices
  const LevelBlocks posed(*lods_, l, options);
  EXPECT_EQ(posed.influence_count(), 0u);
  ASSERT_EQ(posed.posed().rows(), model.vertex_count());
  for (int v = 0; v < model.vertex_count(); ++v) {
    EXPECT_LT((posed.posed().row(v).transpose().cast<double>() - pose_vertex(model, v, G)).norm(), 1e-5) << v;
  }
  EXPECT_EQ(posed.block_vertex_count(0), 5u);
  EXPECT_EQ(posed.block_vertex_count(posed.vertex_count() - 2), 2u);  // the vertices left

  // No pose: the rest pose Ĝ_j.
  options.pose = nullptr;
  const LevelBlocks rest(*lods_, l, options);
  for (int v = 0; v < model.vertex_count(); ++v) {
    EXPECT_LT((rest.posed().row(v).transpose().cast<double>() - pose_vertex(model, v, model.skeleton.rest)).norm(),
              1e-5)
        << v;
  }
  // A budget below one vertex still sends one.
  options.max_block_bytes = 1;
  EXPECT_EQ(LevelBlocks(*lods_, l, options).block_vertex_count(0), 1u);
}

TEST_F(LevelBlocksTest, FaceBlocksAreTheFacesInOrder) {
  const as::AnimationSpaceModel& model = lods_->levels[0].model;
  LevelBlockOptions options;
  options.max_block_vertices = 1000;
  options.max_block_bytes = 12 * 9 + 5;
  const LevelBlocks blocks(*lods_, 0, options);
  ASSERT_EQ(blocks.face_count(), static_cast<uint32_t>(model.faces.rows()));
  EXPECT_EQ(blocks.faces_per_block(), 9u);
  std::vector<uint32_t> all;
  for (uint32_t first = 0; first < blocks.face_count(); first += blocks.faces_per_block()) {
    const uint32_t count = std::min(blocks.faces_per_block(), blocks.face_count() - first);
    const std::string bytes = blocks.face_block(first, count);
    EXPECT_EQ(bytes.size(), size_t{count} * 12);
    for (uint32_t i : decode<uint32_t>(bytes)) all.push_back(i);
  }
  ASSERT_EQ(all.size(), static_cast<size_t>(3 * model.faces.rows()));
  for (Eigen::Index f = 0; f < model.faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(all[static_cast<size_t>(3 * f + c)], static_cast<uint32_t>(model.faces(f, c)));
    }
  }
  // Capped by the vertex count per block, and never 0.
  options.max_block_vertices = 4;
  EXPECT_EQ(LevelBlocks(*lods_, 0, options).faces_per_block(), 4u);
  options.max_block_bytes = 1;
  EXPECT_EQ(LevelBlocks(*lods_, 0, options).faces_per_block(), 1u);
}

// Per-corner UVs (a texture atlas): 24 more bytes per face, so fewer faces per block, and each
// block the corners' (u, v) rounded to float32, in the faces' order.
TEST_F(LevelBlocksTest, CornerUvBlocksAreTheUvsInFaceOrder) {
  const Eigen::Index F = lods_->levels[0].model.faces.rows();
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> uvs(3 * F, 2);
  for (Eigen::Index r = 0; r < 3 * F; ++r) uvs.row(r) << 1.0 / static_cast<double>(r + 3), 0.1 + 1e-9 * static_cast<double>(r);
  LevelBlockOptions options;
  options.max_block_vertices = 1000;
  options.max_block_bytes = 36 * 9 + 35;
  EXPECT_FALSE(LevelBlocks(*lods_, 0, options).has_corner_uvs());
  options.corner_uvs = &uvs;
  const LevelBlocks blocks(*lods_, 0, options);
  EXPECT_TRUE(blocks.has_corner_uvs());
  EXPECT_EQ(blocks.faces_per_block(), 9u);
  std::vector<float> all;
  for (uint32_t first = 0; first < blocks.face_count(); first += blocks.faces_per_block()) {
    const uint32_t count = std::min(blocks.faces_per_block(), blocks.face_count() - first);
    const std::string bytes = blocks.face_uv_block(first, count);
    EXPECT_EQ(bytes.size(), size_t{count} * 24);
    for (float x : decode<float>(bytes)) all.push_back(x);
  }
  ASSERT_EQ(all.size(), static_cast<size_t>(6 * F));
  for (Eigen::Index r = 0; r < 3 * F; ++r) {
    EXPECT_EQ(all[static_cast<size_t>(2 * r)], static_cast<float>(uvs(r, 0)));
    EXPECT_EQ(all[static_cast<size_t>(2 * r + 1)], static_cast<float>(uvs(r, 1)));
  }
}

TEST_F(LevelBlocksTest, RestTransformsAreTheTopThreeRowsRowMajor) {
  const as::Skeleton& skeleton = lods_->levels[0].model.skeleton;
  const auto values = decode<float>(pack_rest_transforms(skeleton));
  ASSERT_EQ(values.size(), skeleton.rest.size() * 12);
  for (size_t j = 0; j < skeleton.rest.size(); ++j) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        EXPECT_EQ(values[12 * j + static_cast<size_t>(4 * r + c)], static_cast<float>(skeleton.rest[j](r, c)));
      }
    }
  }
}

}  // namespace
}  // namespace animspace::lod
