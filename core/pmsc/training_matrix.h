// The training matrix of the PCA and the key selection (pca.h, key_points.h) without a double
// copy of the frames (issue #53 item 2).
//
// Training reads X = T − o·1ᵀ (R × F: the frames less an offset per row, the mean) in double
// precision, as the papers' least squares deserve. Held as a double matrix and then centred in a
// second one, X cost four times the float32 positions — at 186k points × 2,000 frames, 18 GB of a
// 24 GB machine. A TrainingMatrix reads the frames where they already are (the F × R row-major
// float FrameMatrix is R × F column-major: the same bytes) and promotes a block of rows to double
// at a time, less the offset. Every value it gives is exactly what the double copies held
// (double(float) − offset); only products that sum over the rows (XᵀX, AᵀX) add their blocks in
// another order, a rounding of eps·‖X‖² (pca.cpp's floor sits far above it).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace animspace::pmsc {

class TrainingMatrix {
 public:
  // Over float32 values, R × F column-major with leading dimension `rows` (not owned: they must
  // outlive the view), less `offset` (R; empty: zero).
  TrainingMatrix(const float* values, long rows, long cols, Eigen::VectorXd offset = Eigen::VectorXd());
  // Over a double matrix (not owned), less `offset` (empty: zero).
  explicit TrainingMatrix(const Eigen::MatrixXd& values, Eigen::VectorXd offset = Eigen::VectorXd());

  long rows() const { return rows_; }
  long cols() const { return cols_; }
  const Eigen::VectorXd& offset() const { return offset_; }
  // The same values less another offset.
  TrainingMatrix with_offset(Eigen::VectorXd offset) const;

  // Rows [first, first + count) of X into the top of `out` (at least count × F; not resized, so a
  // caller's block buffer is reused).
  void rows_into(long first, long count, Eigen::MatrixXd& out) const;
  Eigen::VectorXd col(long f) const;
  // The mean of the columns of T (the values, without the offset): the training frames' mean.
  Eigen::VectorXd value_mean() const;
  // XᵀX (F × F, both triangles).
  Eigen::MatrixXd gram() const;
  // X·W (R × k) into `out` (resized; its storage kept when the size repeats).
  void times(const Eigen::Ref<const Eigen::MatrixXd>& W, Eigen::MatrixXd& out) const;
  // The same product rounded to float as each block is made: never a double R × k.
  void times(const Eigen::Ref<const Eigen::MatrixXd>& W, Eigen::MatrixXf& out) const;
  // Aᵀ·X (k × F) for A R × k.
  Eigen::MatrixXd transposed_times(const Eigen::Ref<const Eigen::MatrixXd>& A) const;
  // The rows of `points` ((K·D) × F), point-major as gather_key_rows.
  Eigen::MatrixXd gather_rows(const std::vector<int>& points, int channels) const;

  // Rows per block of the products above: at 2,000 frames a block is 49 MB of double.
  static constexpr long kBlockRows = 3072;

 private:
  const float* floats_ = nullptr;
  const double* doubles_ = nullptr;
  long rows_ = 0;
  long cols_ = 0;
  long stride_ = 0;  // leading dimension of the values
  Eigen::VectorXd offset_;

  template <typename Scalar>
  void times_into(const Eigen::Ref<const Eigen::MatrixXd>& W,
                  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>& out) const;
};

}  // namespace animspace::pmsc
