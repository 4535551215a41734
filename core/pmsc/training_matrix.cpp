#include "core/pmsc/training_matrix.h"

#include <algorithm>
#include <cassert>
#include <type_traits>
#include <utility>

#include "core/common/kernels.h"

namespace animspace::pmsc {

TrainingMatrix::TrainingMatrix(const float* values, long rows, long cols, Eigen::VectorXd offset)
    : floats_(values), rows_(rows), cols_(cols), stride_(rows), offset_(std::move(offset)) {
  assert(offset_.size() == 0 || offset_.size() == rows_);
}

TrainingMatrix::TrainingMatrix(const Eigen::MatrixXd& values, Eigen::VectorXd offset)
    : doubles_(values.data()),
      rows_(values.rows()),
      cols_(values.cols()),
      stride_(values.outerStride()),
      offset_(std::move(offset)) {
  assert(offset_.size() == 0 || offset_.size() == rows_);
}

TrainingMatrix TrainingMatrix::with_offset(Eigen::VectorXd offset) const {
  TrainingMatrix out = *this;
  out.offset_ = std::move(offset);
  assert(out.offset_.size() == 0 || out.offset_.size() == rows_);
  return out;
}

void TrainingMatrix::rows_into(long first, long count, Eigen::MatrixXd& out) const {
  assert(first >= 0 && first + count <= rows_ && out.rows() >= count && out.cols() >= cols_);
  for (long f = 0; f < cols_; ++f) {
    auto column = out.col(f).head(count);
    if (floats_ != nullptr) {
      column = Eigen::Map<const Eigen::VectorXf>(floats_ + f * stride_ + first, count).cast<double>();
    } else {
      column = Eigen::Map<const Eigen::VectorXd>(doubles_ + f * stride_ + first, count);
    }
    if (offset_.size() > 0) column -= offset_.segment(first, count);
  }
}

Eigen::VectorXd TrainingMatrix::col(long f) const {
  Eigen::VectorXd out(rows_);
  if (floats_ != nullptr) {
    out = Eigen::Map<const Eigen::VectorXf>(floats_ + f * stride_, rows_).cast<double>();
  } else {
    out = Eigen::Map<const Eigen::VectorXd>(doubles_ + f * stride_, rows_);
  }
  if (offset_.size() > 0) out -= offset_;
  return out;
}

Eigen::VectorXd TrainingMatrix::value_mean() const {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(rows_);
  for (long f = 0; f < cols_; ++f) {
    if (floats_ != nullptr) {
      sum += Eigen::Map<const Eigen::VectorXf>(floats_ + f * stride_, rows_).cast<double>();
    } else {
      sum += Eigen::Map<const Eigen::VectorXd>(doubles_ + f * stride_, rows_);
    }
  }
  return cols_ > 0 ? Eigen::VectorXd(sum / static_cast<double>(cols_)) : sum;
}

// The products below take the double values in place when there is nothing to promote or
// subtract (the tests' matrices, an aligned or cross training's own copy), else block by block.

Eigen::MatrixXd TrainingMatrix::gram() const {
  const long F = cols_;
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(F, F);
  if (doubles_ != nullptr && offset_.size() == 0) {
    gram_lower_serial(rows_, F, doubles_, stride_, gram.data(), F);
  } else {
    Eigen::MatrixXd block(std::min(kBlockRows, rows_), F);
    Eigen::MatrixXd part = Eigen::MatrixXd::Zero(F, F);
    for (long r0 = 0; r0 < rows_; r0 += kBlockRows) {
      const long n = std::min(kBlockRows, rows_ - r0);
      rows_into(r0, n, block);
      gram_lower_serial(n, F, block.data(), block.outerStride(), part.data(), F);
      gram.triangularView<Eigen::Lower>() += part;
    }
  }
  return gram.selfadjointView<Eigen::Lower>();
}

// Each block of rows promoted, multiplied and written; into a float result through a double block
// (the product is formed in double, then rounded once).
template <typename Scalar>
void TrainingMatrix::times_into(const Eigen::Ref<const Eigen::MatrixXd>& W,
                                Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>& out) const {
  assert(W.rows() == cols_);
  constexpr bool kDouble = std::is_same_v<Scalar, double>;
  const long F = cols_, k = W.cols();
  out.resize(rows_, k);
  if (k == 0) return;
  if constexpr (kDouble) {
    if (doubles_ != nullptr && offset_.size() == 0) {
      gemm_serial(rows_, F, k, doubles_, stride_, W.data(), W.outerStride(), 0.0, out.data(), out.outerStride());
      return;
    }
  }
  Eigen::MatrixXd block(std::min(kBlockRows, rows_), F);
  Eigen::MatrixXd product(kDouble ? 0 : block.rows(), kDouble ? 0 : k);
  for (long r0 = 0; r0 < rows_; r0 += kBlockRows) {
    const long n = std::min(kBlockRows, rows_ - r0);
    rows_into(r0, n, block);
    if constexpr (kDouble) {
      gemm_serial(n, F, k, block.data(), block.outerStride(), W.data(), W.outerStride(), 0.0, out.data() + r0,
                  out.outerStride());
    } else {
      gemm_serial(n, F, k, block.data(), block.outerStride(), W.data(), W.outerStride(), 0.0, product.data(),
                  product.outerStride());
      out.middleRows(r0, n) = product.topRows(n).template cast<Scalar>();
    }
  }
}

void TrainingMatrix::times(const Eigen::Ref<const Eigen::MatrixXd>& W, Eigen::MatrixXd& out) const {
  times_into(W, out);
}

void TrainingMatrix::times(const Eigen::Ref<const Eigen::MatrixXd>& W, Eigen::MatrixXf& out) const {
  times_into(W, out);
}

Eigen::MatrixXd TrainingMatrix::transposed_times(const Eigen::Ref<const Eigen::MatrixXd>& A) const {
  assert(A.rows() == rows_);
  const long F = cols_, k = A.cols();
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(k, F);
  if (k == 0) return out;
  if (doubles_ != nullptr && offset_.size() == 0) {
    gemm_transposed_serial(k, rows_, F, A.data(), A.outerStride(), doubles_, stride_, 0.0, out.data(), k);
    return out;
  }
  Eigen::MatrixXd block(std::min(kBlockRows, rows_), F);
  for (long r0 = 0; r0 < rows_; r0 += kBlockRows) {
    const long n = std::min(kBlockRows, rows_ - r0);
    rows_into(r0, n, block);
    gemm_transposed_serial(k, n, F, A.data() + r0, A.outerStride(), block.data(), block.outerStride(), 1.0,
                           out.data(), k);
  }
  return out;
}

Eigen::MatrixXd TrainingMatrix::gather_rows(const std::vector<int>& points, int channels) const {
  Eigen::MatrixXd out(static_cast<long>(points.size()) * channels, cols_);
  Eigen::MatrixXd block(channels, cols_);
  for (size_t k = 0; k < points.size(); ++k) {
    rows_into(static_cast<long>(points[k]) * channels, channels, block);
    out.middleRows(static_cast<long>(k) * channels, channels) = block;
  }
  return out;
}

}  // namespace animspace::pmsc
