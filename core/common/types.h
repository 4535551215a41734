// Array types shared by every core module.
//
// Points are stored row-major in float32 because that is how they travel (proto `bytes`
// fields, PC2 files) and how a renderer consumes them; algorithms that need more precision
// (least squares, PCA) promote to double internally and say so.
#pragma once

#include <cstdint>

#include <Eigen/Core>

namespace animspace {

// #V by 3 positions, row-major so that `data()` is x0 y0 z0 x1 y1 z1 … (the wire layout).
using PointMatrix = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
// #F by 3 zero-based vertex indices, counter-clockwise seen from outside.
using FaceMatrix = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
// A dense float32 row-major matrix: frames × (points · channels) for sequences.
using FrameMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A triangle mesh: vertices and faces. Normals, if present in a file, are not kept: the
// algorithms derive them (Merry 2007 §3.5).
struct TriangleMesh {
  PointMatrix V;  // #V by 3
  FaceMatrix F;   // #F by 3
};

}  // namespace animspace
