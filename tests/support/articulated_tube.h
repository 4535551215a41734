// A generated articulated tube with known segments, joints and motions: the ground truth of the
// segmentation and skinning-decomposition tests (no shared data).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/common/types.h"

namespace animspace::testing {

using Eigen::Vector3d;

// A tube along x made of `segment_count` segments of `rings_per_segment` rings each, bent like
// a finger: segment s turns about its joint (on the axis, half-way between its first ring and the
// previous segment's last) by a known rotation per frame, on top of its parent's motion, so the
// true joints, hierarchy and transforms are known.
//
// `blend_rings` = 0: each segment is exactly rigid. > 0: the skin is linear blend skinned — a
// vertex within `blend_rings` ring spacings of a joint blends the two segments' motions with a
// weight ramping linearly across the joint (`weights`, #V × segment_count, rows summing to 1), the
// smooth skin a skinning decomposition should recover.
struct ArticulatedTube {
  static constexpr int kAround = 12;
  static constexpr double kRingSpacing = 0.1;
  static constexpr double kRadius = 0.15;

  PointMatrix rest;
  FaceMatrix faces;
  FrameMatrix frames;
  std::vector<int> segment;                                         // #V: true part
  std::vector<std::vector<Eigen::Matrix4d>> motions;                // [frame][segment]: rest → frame
  std::vector<Vector3d, Eigen::aligned_allocator<Vector3d>> joint;  // [segment], joint[0] unused
  Eigen::MatrixXd weights;                                          // #V × segments (see above)
};

inline ArticulatedTube make_tube(int segment_count, int rings_per_segment, int frame_count, uint32_t seed,
                                 double blend_rings = 0) {
  ArticulatedTube tube;
  const int rings = segment_count * rings_per_segment;
  const int around = ArticulatedTube::kAround;
  tube.rest.resize(rings * around, 3);
  for (int r = 0; r < rings; ++r) {
    for (int a = 0; a < around; ++a) {
      // Alternate rings are twisted by half a step so that the mesh is not symmetric under
      // swapping rings (every diagonal goes the same way).
      const double angle = 2 * M_PI * (a + 0.5 * (r % 2)) / around;
      tube.rest.row(r * around + a) << static_cast<float>(r * ArticulatedTube::kRingSpacing),
          static_cast<float>(ArticulatedTube::kRadius * std::cos(angle)),
          static_cast<float>(ArticulatedTube::kRadius * std::sin(angle));
      tube.segment.push_back(r / rings_per_segment);
    }
  }
  tube.faces.resize(2 * (rings - 1) * around, 3);
  int f = 0;
  for (int r = 0; r + 1 < rings; ++r) {
    for (int a = 0; a < around; ++a) {
      const int v00 = r * around + a, v01 = r * around + (a + 1) % around;
      const int v10 = (r + 1) * around + a, v11 = (r + 1) * around + (a + 1) % around;
      tube.faces.row(f++) << v00, v10, v11;
      tube.faces.row(f++) << v00, v11, v01;
    }
  }
  tube.joint.assign(static_cast<size_t>(segment_count), Vector3d::Zero());
  for (int s = 1; s < segment_count; ++s) {
    tube.joint[static_cast<size_t>(s)] = Vector3d((s * rings_per_segment - 0.5) * ArticulatedTube::kRingSpacing, 0, 0);
  }
  // Weights: the own segment, blended across each joint within blend_rings ring spacings.
  tube.weights = Eigen::MatrixXd::Zero(tube.rest.rows(), segment_count);
  for (Eigen::Index i = 0; i < tube.rest.rows(); ++i) {
    const int own = tube.segment[static_cast<size_t>(i)];
    tube.weights(i, own) = 1;
    if (blend_rings <= 0) continue;
    const double x = tube.rest(i, 0);
    for (int s = 1; s < segment_count; ++s) {
      const double d = (x - tube.joint[static_cast<size_t>(s)].x()) / (blend_rings * ArticulatedTube::kRingSpacing);
      if (std::abs(d) >= 1) continue;
      // Across joint s: segment s − 1 below, s above; the child's share ramps from 0 to 1.
      const double child = 0.5 * (1 + d);
      tube.weights.row(i).setZero();
      tube.weights(i, s - 1) = 1 - child;
      tube.weights(i, s) = child;
    }
  }
  std::mt19937 engine(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  tube.frames.resize(frame_count, 3 * tube.rest.rows());
  tube.motions.resize(static_cast<size_t>(frame_count));
  for (int k = 0; k < frame_count; ++k) {
    std::vector<Eigen::Matrix4d>& G = tube.motions[static_cast<size_t>(k)];
    // Segment 0 moves as a whole (a free root); each later one turns about its joint by up to
    // ~70° about a random axis.
    Eigen::Affine3d root = Eigen::Translation3d(0.3 * unit(engine), 0.3 * unit(engine), 0.3 * unit(engine)) *
                           Eigen::AngleAxisd(0.5 * unit(engine), Vector3d(unit(engine), unit(engine), 1).normalized());
    G.push_back(root.matrix());
    for (int s = 1; s < segment_count; ++s) {
      const Vector3d axis = Vector3d(unit(engine), unit(engine), unit(engine) + 2.0).normalized();
      const Vector3d& u = tube.joint[static_cast<size_t>(s)];
      const Eigen::Affine3d turn =
          Eigen::Translation3d(u) * Eigen::AngleAxisd(1.2 * unit(engine), axis) * Eigen::Translation3d(-u);
      G.push_back(G.back() * turn.matrix());
    }
    for (Eigen::Index i = 0; i < tube.rest.rows(); ++i) {
      Vector3d v = Vector3d::Zero();
      for (int s = 0; s < segment_count; ++s) {
        const double w = tube.weights(i, s);
        if (w != 0) v += w * (G[static_cast<size_t>(s)] * tube.rest.row(i).cast<double>().transpose().homogeneous()).head<3>();
      }
      tube.frames.block<1, 3>(k, 3 * i) = v.cast<float>().transpose();
    }
  }
  return tube;
}

}  // namespace animspace::testing
