#include "core/animspace/segmentation.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <queue>
#include <random>
#include <set>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "core/mesh_io/sequence_io.h"
#include "tests/support/articulated_tube.h"
#include "tests/support/test_support.h"

namespace animspace::animation_space {
namespace {

using testing::ArticulatedTube;
using testing::make_tube;

using Eigen::Matrix3d;
using Eigen::Vector3d;

// Bone → true segment, by majority of the bone's vertices; -1 for bone 0.
std::vector<int> bone_to_segment(const RigidSegmentation& result, const std::vector<int>& segment, int segment_count) {
  std::vector<std::vector<int>> votes(static_cast<size_t>(result.bone_count()),
                                      std::vector<int>(static_cast<size_t>(segment_count), 0));
  for (size_t i = 0; i < segment.size(); ++i)
    ++votes[static_cast<size_t>(result.labels[i])][static_cast<size_t>(segment[i])];
  std::vector<int> mapping(static_cast<size_t>(result.bone_count()), -1);
  for (size_t j = 1; j < votes.size(); ++j) {
    mapping[j] = static_cast<int>(std::max_element(votes[j].begin(), votes[j].end()) - votes[j].begin());
  }
  return mapping;
}

// Number of connected components of each bone's vertices over mesh edges (index 0 unused).
std::vector<int> part_components(const RigidSegmentation& result, const FaceMatrix& faces) {
  const size_t V = result.labels.size();
  std::vector<std::vector<int>> neighbours(V);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      neighbours[static_cast<size_t>(faces(f, c))].push_back(faces(f, (c + 1) % 3));
      neighbours[static_cast<size_t>(faces(f, (c + 1) % 3))].push_back(faces(f, c));
    }
  }
  std::vector<int> components(static_cast<size_t>(result.bone_count()), 0);
  std::vector<char> seen(V, 0);
  for (size_t start = 0; start < V; ++start) {
    if (seen[start]) continue;
    const int label = result.labels[start];
    ++components[static_cast<size_t>(label)];
    std::queue<size_t> queue;
    queue.push(start);
    seen[start] = 1;
    while (!queue.empty()) {
      const size_t i = queue.front();
      queue.pop();
      for (int j : neighbours[i]) {
        if (!seen[static_cast<size_t>(j)] && result.labels[static_cast<size_t>(j)] == label) {
          seen[static_cast<size_t>(j)] = 1;
          queue.push(static_cast<size_t>(j));
        }
      }
    }
  }
  return components;
}

// RMS of ‖M_label(i)^k v̂_i − v_i^k‖ over vertices and frames, from the returned transforms.
double rigid_reconstruction_rms(const RigidSegmentation& result, const PointMatrix& rest, const FrameMatrix& frames) {
  double sum = 0.0;
  for (Eigen::Index k = 0; k < frames.rows(); ++k) {
    for (Eigen::Index i = 0; i < rest.rows(); ++i) {
      const Eigen::Matrix4d& M =
          result.transforms[static_cast<size_t>(k)][static_cast<size_t>(result.labels[static_cast<size_t>(i)])];
      const Vector3d v = (M * rest.row(i).cast<double>().transpose().homogeneous()).head<3>();
      sum += (v - frames.block<1, 3>(k, 3 * i).cast<double>().transpose()).squaredNorm();
    }
  }
  return std::sqrt(sum / static_cast<double>(rest.rows() * frames.rows()));
}

void expect_valid_skeleton(const RigidSegmentation& result, int B, size_t V, size_t F) {
  ASSERT_EQ(result.bone_count(), B + 1);
  EXPECT_EQ(result.parents[0], -1);
  for (int j = 1; j <= B; ++j) {
    EXPECT_GE(result.parents[static_cast<size_t>(j)], 0) << j;
    EXPECT_LT(result.parents[static_cast<size_t>(j)], j) << j;
  }
  ASSERT_EQ(result.labels.size(), V);
  std::vector<int> size(static_cast<size_t>(B) + 1, 0);
  for (int label : result.labels) {
    ASSERT_GE(label, 1);
    ASSERT_LE(label, B);
    ++size[static_cast<size_t>(label)];
  }
  for (int j = 1; j <= B; ++j) EXPECT_GT(size[static_cast<size_t>(j)], 0) << "bone " << j << " owns no vertex";
  ASSERT_EQ(result.transforms.size(), F);
  for (const TransformList& pose : result.transforms) {
    ASSERT_EQ(pose.size(), static_cast<size_t>(B) + 1);
    EXPECT_TRUE(pose[0].isIdentity(0.0));
    for (const Eigen::Matrix4d& M : pose) {
      const Matrix3d R = M.topLeftCorner<3, 3>();
      EXPECT_TRUE((R.transpose() * R).isIdentity(1e-9));
      EXPECT_NEAR(R.determinant(), 1.0, 1e-9);
    }
  }
  ASSERT_EQ(result.core_vertices.size(), static_cast<size_t>(B) + 1);
  EXPECT_TRUE(result.core_vertices[0].empty());
  for (int j = 1; j <= B; ++j) {
    for (int i : result.core_vertices[static_cast<size_t>(j)]) EXPECT_EQ(result.labels[static_cast<size_t>(i)], j) << i;
  }
  ASSERT_EQ(result.joint_positions.rows(), B + 1);
  EXPECT_TRUE(result.joint_positions.row(0).isZero(0.0));
}

// Labels equal the true segments up to renaming, and each bone's transforms the known motions.
void expect_tube_segmented_exactly(uint32_t seed) {
  constexpr int kSegments = 4, kFrames = 10;
  const ArticulatedTube tube = make_tube(kSegments, 8, kFrames, seed);
  SegmentationOptions options;
  options.bone_count = kSegments;
  const Result<RigidSegmentation> result = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, kSegments, tube.segment.size(), kFrames);

  // Labels agree with the true segments up to renaming (a bijection bone ↔ segment).
  const std::vector<int> mapping = bone_to_segment(*result, tube.segment, kSegments);
  EXPECT_EQ(std::set<int>(mapping.begin() + 1, mapping.end()).size(), static_cast<size_t>(kSegments));
  size_t agree = 0;
  for (size_t i = 0; i < tube.segment.size(); ++i)
    agree += mapping[static_cast<size_t>(result->labels[i])] == tube.segment[i];
  EXPECT_GE(static_cast<double>(agree), 0.99 * static_cast<double>(tube.segment.size()));
  EXPECT_EQ(agree, tube.segment.size());

  // Each bone's transforms are the known motions of its segment (float input: ~1e-6).
  for (int k = 0; k < kFrames; ++k) {
    for (int j = 1; j <= kSegments; ++j) {
      const Eigen::Matrix4d& expected =
          tube.motions[static_cast<size_t>(k)][static_cast<size_t>(mapping[static_cast<size_t>(j)])];
      EXPECT_LT((result->transforms[static_cast<size_t>(k)][static_cast<size_t>(j)] - expected).cwiseAbs().maxCoeff(),
                1e-5)
          << "frame " << k << " bone " << j;
    }
  }
  EXPECT_LT(result->rms_error, 1e-5);
  EXPECT_LT(result->fit_error.maxCoeff(), 1e-5);
}

// Forty random motions of the tube: a local optimum of the clustering (two segments in one part,
// one segment in two) would show up in a few of them.
TEST(SegmentationTest, ArticulatedTubeIsSplitIntoItsSegments) {
  for (uint32_t seed = 1; seed <= 40; ++seed) {
    SCOPED_TRACE("motion seed " + std::to_string(seed));
    expect_tube_segmented_exactly(seed);
  }
}

TEST(SegmentationTest, ArticulatedTubeHierarchyJointsAndCoresFollowTheChain) {
  constexpr int kSegments = 4;
  const ArticulatedTube tube = make_tube(kSegments, 8, 10, 12);
  SegmentationOptions options;
  options.bone_count = kSegments;
  options.core_erosion_rings = 2;
  const Result<RigidSegmentation> result = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, kSegments, tube.segment.size(), 10);
  const std::vector<int> mapping = bone_to_segment(*result, tube.segment, kSegments);

  // The tree, as undirected segment pairs, is the chain 0–1–2–3, hanging from bone 0 once.
  std::set<std::pair<int, int>> edges;
  int roots = 0;
  for (int j = 1; j <= kSegments; ++j) {
    const int parent = result->parents[static_cast<size_t>(j)];
    if (parent == 0) {
      ++roots;
      continue;
    }
    const int a = mapping[static_cast<size_t>(j)], b = mapping[static_cast<size_t>(parent)];
    edges.insert({std::min(a, b), std::max(a, b)});
  }
  EXPECT_EQ(roots, 1);
  EXPECT_EQ(edges, (std::set<std::pair<int, int>>{{0, 1}, {1, 2}, {2, 3}}));
  // Median root of a chain of four equal parts: one of the two middle segments.
  const int root_bone = 1;
  ASSERT_EQ(result->parents[1], 0);
  EXPECT_TRUE(mapping[root_bone] == 1 || mapping[root_bone] == 2) << mapping[root_bone];

  for (int j = 1; j <= kSegments; ++j) {
    const int s = mapping[static_cast<size_t>(j)];
    const int parent = result->parents[static_cast<size_t>(j)];
    const Vector3d u = result->joint_positions.row(j).transpose();
    if (parent == 0) {
      // Centroid of the root part: on the axis, in the middle of its segment.
      const double middle = (s * 8 + 3.5) * ArticulatedTube::kRingSpacing;
      EXPECT_LT((u - Vector3d(middle, 0, 0)).norm(), 1e-5) << "bone " << j << ": " << u.transpose();
    } else {
      // The joint between the segment and its parent: the later segment's joint.
      const int later = std::max(s, mapping[static_cast<size_t>(parent)]);
      EXPECT_LT((u - tube.joint[static_cast<size_t>(later)]).norm(), 1e-5) << "bone " << j << ": " << u.transpose();
    }
    // Core vertices: inside the true segment, at least 2 rings away from its ends, not collinear.
    const std::vector<int32_t>& core = result->core_vertices[static_cast<size_t>(j)];
    ASSERT_GE(core.size(), 3u) << j;
    for (int32_t i : core) {
      EXPECT_EQ(tube.segment[static_cast<size_t>(i)], s) << "core vertex " << i << " of bone " << j;
      const int ring_in_segment = (i / ArticulatedTube::kAround) % 8;
      const bool first = s == 0, last = s == kSegments - 1;
      if (!first) {
        EXPECT_GE(ring_in_segment, 2) << i;
      }
      if (!last) {
        EXPECT_LE(ring_in_segment, 5) << i;
      }
    }
  }
}

// Scaling the data, or moving it far from the origin, must give the same parts: every threshold
// is relative.
TEST(SegmentationTest, LabelsAreInvariantToScaleAndPlacement) {
  const ArticulatedTube tube = make_tube(3, 6, 8, 13);
  SegmentationOptions options;
  options.bone_count = 3;
  const Result<RigidSegmentation> reference = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  ASSERT_TRUE(reference.ok()) << reference.error().message;
  for (const double scale : {1e-4, 1e4}) {
    for (const float offset : {0.0f, 1000.0f}) {
      const PointMatrix rest =
          (tube.rest.array() * static_cast<float>(scale) + offset * static_cast<float>(scale)).matrix();
      const FrameMatrix frames =
          (tube.frames.array() * static_cast<float>(scale) + offset * static_cast<float>(scale)).matrix();
      const Result<RigidSegmentation> result = segment_rigid_parts(rest, tube.faces, frames, options);
      ASSERT_TRUE(result.ok()) << result.error().message;
      EXPECT_EQ(result->labels, reference->labels) << "scale " << scale << " offset " << offset;
      EXPECT_EQ(result->parents, reference->parents) << "scale " << scale << " offset " << offset;
      // float resolves ~6e-8 of the coordinates' magnitude.
      EXPECT_LT(result->rms_error, 1e-5 * scale * (1.0 + offset)) << "scale " << scale << " offset " << offset;
    }
  }
}

TEST(SegmentationTest, SingleBoneIsOneRigidFitOfEverything) {
  const ArticulatedTube tube = make_tube(1, 6, 5, 14);
  SegmentationOptions options;
  options.bone_count = 1;
  const Result<RigidSegmentation> result = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, 1, tube.segment.size(), 5);
  EXPECT_EQ(result->parents, (std::vector<int32_t>{-1, 0}));
  for (int k = 0; k < 5; ++k) {
    EXPECT_LT(
        (result->transforms[static_cast<size_t>(k)][1] - tube.motions[static_cast<size_t>(k)][0]).cwiseAbs().maxCoeff(),
        1e-5);
  }
}

// With more bones than rigid segments every bone must still own vertices, each part connected.
TEST(SegmentationTest, MoreBonesThanSegmentsStillGivesConnectedNonEmptyParts) {
  const ArticulatedTube tube = make_tube(2, 6, 6, 15);
  for (const int B : {7, 60, static_cast<int>(tube.rest.rows())}) {
    SegmentationOptions options;
    options.bone_count = B;
    const Result<RigidSegmentation> result = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
    ASSERT_TRUE(result.ok()) << result.error().message;
    expect_valid_skeleton(*result, B, tube.segment.size(), 6);
    const std::vector<int> components = part_components(*result, tube.faces);
    for (int j = 1; j <= B; ++j) EXPECT_EQ(components[static_cast<size_t>(j)], 1) << "B " << B << " bone " << j;
    EXPECT_LT(rigid_reconstruction_rms(*result, tube.rest, tube.frames), 1e-5) << B;
  }
}

// Two separate tubes (a mesh in two pieces): both pieces are covered, each part connected, and
// the forest hangs from bone 0 by one root per piece.
TEST(SegmentationTest, MeshInTwoPiecesGivesOneTreePerPiece) {
  const ArticulatedTube a = make_tube(2, 6, 6, 16), b = make_tube(2, 6, 6, 17);
  const Eigen::Index Va = a.rest.rows();
  PointMatrix rest(2 * Va, 3);
  rest << a.rest, (b.rest.rowwise() + Eigen::RowVector3f(0, 5, 0));
  FaceMatrix faces(2 * a.faces.rows(), 3);
  faces << a.faces, (a.faces.array() + static_cast<int32_t>(Va)).matrix();
  FrameMatrix frames(6, 6 * Va);
  for (int k = 0; k < 6; ++k) {
    frames.block(k, 0, 1, 3 * Va) = a.frames.row(k);
    for (Eigen::Index i = 0; i < Va; ++i) {
      frames.block<1, 3>(k, 3 * (Va + i)) = b.frames.block<1, 3>(k, 3 * i) + Eigen::RowVector3f(0, 5, 0);
    }
  }
  SegmentationOptions options;
  options.bone_count = 4;
  const Result<RigidSegmentation> result = segment_rigid_parts(rest, faces, frames, options);
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, 4, static_cast<size_t>(2 * Va), 6);
  const std::vector<int> components = part_components(*result, faces);
  for (int j = 1; j <= 4; ++j) EXPECT_EQ(components[static_cast<size_t>(j)], 1) << j;
  EXPECT_EQ(std::count(result->parents.begin(), result->parents.end(), 0), 2);
  EXPECT_LT(rigid_reconstruction_rms(*result, rest, frames), 1e-4);
}

// Without faces there is no adjacency: parts are clusters of rigid motion only, each bone hangs
// from bone 0 at its centroid, and the rigid segments are still recovered.
TEST(SegmentationTest, PointSetWithoutFacesIsClusteredByMotion) {
  const ArticulatedTube tube = make_tube(3, 6, 8, 20);
  SegmentationOptions options;
  options.bone_count = 3;
  const Result<RigidSegmentation> result = segment_rigid_parts(tube.rest, FaceMatrix(0, 3), tube.frames, options);
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, 3, tube.segment.size(), 8);
  EXPECT_EQ(result->parents, (std::vector<int32_t>{-1, 0, 0, 0}));
  EXPECT_LT(rigid_reconstruction_rms(*result, tube.rest, tube.frames), 1e-5);
  for (int j = 1; j <= 3; ++j) {
    Vector3d centroid = Vector3d::Zero();
    int count = 0;
    for (size_t i = 0; i < result->labels.size(); ++i) {
      if (result->labels[i] != j) continue;
      centroid += tube.rest.row(static_cast<Eigen::Index>(i)).cast<double>().transpose();
      ++count;
    }
    EXPECT_LT((result->joint_positions.row(j).transpose() - centroid / count).norm(), 1e-9) << j;
  }
}

TEST(SegmentationTest, SameInputGivesSameResult) {
  const ArticulatedTube tube = make_tube(4, 5, 6, 18);
  SegmentationOptions options;
  options.bone_count = 9;
  const Result<RigidSegmentation> first = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  const Result<RigidSegmentation> second = segment_rigid_parts(tube.rest, tube.faces, tube.frames, options);
  ASSERT_TRUE(first.ok() && second.ok());
  EXPECT_EQ(first->labels, second->labels);
  EXPECT_EQ(first->parents, second->parents);
  EXPECT_EQ(first->core_vertices, second->core_vertices);
}

struct InvalidCase {
  const char* name;
  std::function<void(PointMatrix&, FaceMatrix&, FrameMatrix&, SegmentationOptions&)> corrupt;
  std::vector<std::string> expected_in_message;
};

TEST(SegmentationTest, InvalidInputIsRejectedWithAPreciseMessage) {
  const ArticulatedTube tube = make_tube(2, 3, 3, 19);
  const int V = static_cast<int>(tube.rest.rows());
  const std::vector<InvalidCase> cases = {
      {"no bones",
       [](auto&, auto&, auto&, auto& o) { o.bone_count = 0; },
       {"options.bone_count", "[1, #V = 72]", "got 0"}},
      {"more bones than vertices",
       [&](auto&, auto&, auto&, auto& o) { o.bone_count = V + 1; },
       {"options.bone_count", "got 73"}},
      {"frames too narrow",
       [&](auto&, auto&, auto& f, auto&) { f.conservativeResize(Eigen::NoChange, 3 * V - 3); },
       {"frames", "3·#V = 216 columns", "got 3 × 213"}},
      {"no frames",
       [&](auto&, auto&, auto& f, auto&) { f.resize(0, 3 * V); },
       {"frames", "at least 1 frame", "got 0 × 216"}},
      {"face index too large",
       [&](auto&, auto& F, auto&, auto&) { F(5, 2) = V; },
       {"faces(5, 2) = 72", "[0, #V = 72)"}},
      {"negative face index", [](auto&, auto& F, auto&, auto&) { F(0, 0) = -1; }, {"faces(0, 0) = -1"}},
      {"NaN in rest", [](auto& r, auto&, auto&, auto&) { r(7, 1) = NAN; }, {"rest vertex 7", "not finite"}},
      {"infinity in frames",
       [](auto&, auto&, auto& f, auto&) { f(2, 31) = INFINITY; },
       {"frames(2, 31)", "frame 2, vertex 10", "not finite"}},
      {"negative iterations",
       [](auto&, auto&, auto&, auto& o) { o.iterations = -1; },
       {"options.iterations", "got -1"}},
      {"negative erosion",
       [](auto&, auto&, auto&, auto& o) { o.core_erosion_rings = -2; },
       {"options.core_erosion_rings", "got -2"}},
      {"zero error factor",
       [](auto&, auto&, auto&, auto& o) { o.core_error_factor = 0.0; },
       {"options.core_error_factor"}},
  };
  for (const InvalidCase& c : cases) {
    PointMatrix rest = tube.rest;
    FaceMatrix faces = tube.faces;
    FrameMatrix frames = tube.frames;
    SegmentationOptions options;
    options.bone_count = 2;
    c.corrupt(rest, faces, frames, options);
    const Result<RigidSegmentation> result = segment_rigid_parts(rest, faces, frames, options);
    ASSERT_FALSE(result.ok()) << c.name;
    EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument) << c.name;
    for (const std::string& fragment : c.expected_in_message) {
      EXPECT_NE(result.error().message.find(fragment), std::string::npos)
          << c.name << ": '" << fragment << "' not in: " << result.error().message;
    }
  }
}

// Real data (Sumner & Popović 2004 horse gallop, 8431 vertices × 48 frames): 20 parts must
// explain the motion far better than one rigid body, within a few % of the model's size, with
// every part a single connected piece of mesh.
TEST(SegmentationTest, HorseGallopPartsAreRigidAndConnected) {
  const auto data = testing::shared_data_dir();
  if (!data) GTEST_SKIP() << "reference data folder ../shared/data is absent";
  const Result<mesh_io::LoadedSequence> sequence = mesh_io::load_sequence(*data / "horse-gallop");
  ASSERT_TRUE(sequence.ok()) << sequence.error().message;
  const PointMatrix rest = sequence->frames.frame(0);
  const FaceMatrix& faces = sequence->reference.F;
  const FrameMatrix& frames = sequence->frames.samples;
  const double diagonal = (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).cast<double>().norm();

  SegmentationOptions single;
  single.bone_count = 1;
  const Result<RigidSegmentation> one = segment_rigid_parts(rest, faces, frames, single);
  ASSERT_TRUE(one.ok()) << one.error().message;

  SegmentationOptions options;
  options.bone_count = 20;
  const auto start = std::chrono::steady_clock::now();
  const Result<RigidSegmentation> result = segment_rigid_parts(rest, faces, frames, options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(result.ok()) << result.error().message;
  expect_valid_skeleton(*result, 20, static_cast<size_t>(rest.rows()), static_cast<size_t>(frames.rows()));

  const double rms_one = rigid_reconstruction_rms(*one, rest, frames);
  const double rms = rigid_reconstruction_rms(*result, rest, frames);
  std::printf(
      "horse-gallop: B = 20 in %.2f s (%d refinement iterations); rigid-part RMS %.4f%% of the diagonal, "
      "one rigid body %.4f%%\n",
      seconds, result->iterations, 100 * rms / diagonal, 100 * rms_one / diagonal);
  EXPECT_NEAR(result->rms_error, rms, 1e-6 * diagonal);
  EXPECT_LT(rms, 0.02 * diagonal);
  EXPECT_LT(rms, 0.25 * rms_one);

  const std::vector<int> components = part_components(*result, faces);
  for (int j = 1; j <= 20; ++j) EXPECT_EQ(components[static_cast<size_t>(j)], 1) << "bone " << j;
  for (int j = 1; j <= 20; ++j) EXPECT_GE(result->core_vertices[static_cast<size_t>(j)].size(), 3u) << j;
}

}  // namespace
}  // namespace animspace::animation_space
