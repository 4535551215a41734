// Point multiplication on the client (issue #36): a pose answered as its subspace coordinates p
// (Meyer & Anderson 2007 eq. 1, f̂ = mean + A p) instead of its N·D points, reconstructed by
// whoever holds the basis. The server's one-pose reconstruction and a client's are this one
// function, so that the two differ by nothing but the kernel a build links.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <span>
#include <string>

#include <Eigen/Core>

#include "core/common/result.h"

#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

// Names a subspace exactly: crc32 (zlib's) of the mean's float32 bytes in the high 32 bits, of
// the basis's (column by column) in the low 32. A client checks a cached basis with it.
uint64_t basis_checksum(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis);
// The same subspace named so that it cannot be forged (issue #54 item 8): SHA-256 of the mean's
// float32 bytes followed by the basis's, exactly the values GetBasis streams (32 raw bytes).
std::string basis_sha256(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis);

// The subspace as GetBasis sends it in float16 (issue #53): every mean and basis value rounded to
// the nearest binary16 (core/common/point_codec.h), in the order of basis_sha256.
struct Float16Basis {
  std::string sha256;    // SHA-256 of the binary16 values' bytes (32 raw bytes)
  float max_error = 0;   // the largest |binary16 − float32| over the values
};
// kOutOfRange naming the first value beyond ±65504, which binary16 cannot hold.
Result<Float16Basis> float16_basis(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis);
// The same for any run of values as sent, given in parts (the skinned layout, skinned_basis.h),
// naming value i of the run.
Result<Float16Basis> float16_values(std::initializer_list<std::span<const float>> parts);

// The alignment of one pose as it travels: R and t in float32 (what reconstruct applies).
struct FloatAlignment {
  Eigen::Matrix3f rotation = Eigen::Matrix3f::Identity();
  Eigen::Vector3f translation = Eigen::Vector3f::Zero();
};
FloatAlignment float_alignment(const geometry::RigidTransform& alignment);

// Moves `point_count` 3-D points (point-major floats) from the aligned frame to the world,
// x ← R x + t in float32: every reconstruction, alone or batched, ends with it.
void to_world(const FloatAlignment& alignment, long point_count, float* points);

// f̂ = R (mean + A p) + t for one pose, into `out` (mean.size() floats): the mean copied, one
// matrix–vector product through the active kernel (core/common/kernels.h), then, when `alignment`
// is given (aligned models: 3 channels), every point moved to the world. `p` holds M values.
void reconstruct_coordinates(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis, const float* p,
                             const FloatAlignment* alignment, float* out);

// How far two float32 reconstructions of the same p (different kernels, or one pose alone and in
// a batch) may differ in value i: both are within γ_{M+2} of the exact sum, so at most
//   coordinates_rounding_bound(M) · (|mean_i| + Σ_j |A_ij p_j|)
// before alignment. An aligned model's rotation keeps that error's size (the point's whole error
// moves into each coordinate, at most its norm) and adds, per coordinate c of a point x with
// answer f̂, both sides' roundings of R x (γ_3‖x‖ each) and of the final + t (2⁻²⁴|f̂_c| each):
//   aligned_rounding_bound() · ‖x‖ + translation_rounding_bound() · |f̂_c|.
inline double coordinates_rounding_bound(long basis_size) { return reconstruction_rounding_bound(basis_size); }
inline double aligned_rounding_bound() {
  const double gamma3 = 3 * 0x1p-24 / (1 - 3 * 0x1p-24);
  return 2 * gamma3;
}
inline double translation_rounding_bound() { return 2 * 0x1p-24; }

}  // namespace animspace::pmsc
