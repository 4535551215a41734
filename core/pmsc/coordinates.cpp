#include "core/pmsc/coordinates.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <span>
#include <string>
#include <vector>

#include "core/common/kernels.h"
#include "core/common/point_codec.h"
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

namespace {

// Float16Basis of `parts` as one run of values; `name(i)` says where value i lies, for the error.
template <typename Name>
Result<Float16Basis> float16_of(std::initializer_list<std::span<const float>> parts, Name&& name) {
  Float16Basis out;
  Sha256 digest;
  // In blocks, so that a basis of hundreds of megabytes needs no second copy.
  constexpr size_t kBlock = size_t{1} << 20;
  std::vector<char> halves(2 * kBlock);
  size_t index = 0;  // of the first value of the span being encoded
  for (const std::span<const float> values : parts) {
    for (size_t at = 0; at < values.size(); at += kBlock) {
      const auto block = values.subspan(at, std::min(kBlock, values.size() - at));
      const auto encoded = std::span<char>(halves.data(), 2 * block.size());
      auto error = point_codec::encode_float16(block, 1, encoded);
      if (!error) {
        // Name the value by where it lies in the subspace, not the codec's point and channel.
        const auto bad = std::find_if(block.begin(), block.end(),
                                      [](float v) { return !(std::abs(v) <= point_codec::kMaxFloat16); });
        return make_error(ErrorCode::kOutOfRange,
                          "the subspace cannot be sent as float16: its " +
                              name(index + at + static_cast<size_t>(bad - block.begin())) + " is " +
                              std::to_string(bad == block.end() ? 0.0f : *bad) + ", beyond binary16's ±65504");
      }
      out.max_error = std::max(out.max_error, *error);
      digest.update(std::as_bytes(std::span<const char>(encoded)));
    }
    index += values.size();
  }
  out.sha256 = digest.digest();
  return out;
}

}  // namespace

Result<Float16Basis> float16_basis(const Eigen::VectorXf& mean, const Eigen::MatrixXf& basis) {
  const auto rows = static_cast<size_t>(mean.size());
  return float16_of({std::span<const float>(mean.data(), rows),
                     std::span<const float>(basis.data(), static_cast<size_t>(basis.size()))},
                    [rows](size_t i) {
                      return i < rows ? "mean value " + std::to_string(i)
                                      : "basis value " + std::to_string((i - rows) % rows) + " of column " +
                                            std::to_string((i - rows) / rows);
                    });
}

Result<Float16Basis> float16_values(std::initializer_list<std::span<const float>> parts) {
  return float16_of(parts, [](size_t i) { return "value " + std::to_string(i); });
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
