#include "core/pmsc/coordinates.h"

#include <algorithm>
#include <cassert>
#include <span>

#include "core/common/kernels.h"
#include "core/common/sha256.h"
#include "core/container/crc32.h"

namespace animspace::pmsc {
namespace {

uint32_t crc_of(const float* values, long count) {
  return container::crc32_update(
      0, std::span<const std::byte>(reinterpret_cast<const std::byte*>(values), static_cast<size_t>(count) * sizeof(float)));
}

}  // namespace

uint64_t basis_checksum(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis) {
  return (uint64_t{crc_of(mean.data(), mean.size())} << 32) | crc_of(basis.data(), basis.size());
}

std::string basis_sha256(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis) {
  Sha256 digest;
  digest.update(std::as_bytes(std::span<const float>(mean.data(), static_cast<size_t>(mean.size()))));
  digest.update(std::as_bytes(std::span<const float>(basis.data(), static_cast<size_t>(basis.size()))));
  return digest.digest();
}

FloatAlignment float_alignment(const geometry::RigidTransform& alignment) {
  return {alignment.rotation.cast<float>(), alignment.translation.cast<float>()};
}

void to_world(const FloatAlignment& alignment, long point_count, float* points) {
  Eigen::Map<Eigen::Matrix3Xf> world(points, 3, point_count);
  world = (alignment.rotation * world).colwise() + alignment.translation;
}

void reconstruct_coordinates(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis, const float* p,
                             const FloatAlignment* alignment, float* out) {
  const long rows = mean.size();
  assert(basis.rows() == rows);
  std::copy(mean.data(), mean.data() + rows, out);
  if (basis.cols() > 0) gemm(rows, basis.cols(), 1, basis.data(), rows, p, basis.cols(), 1.0f, out, rows);
  if (alignment != nullptr) to_world(*alignment, rows / 3, out);
}

}  // namespace animspace::pmsc
