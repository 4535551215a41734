#include "core/pmsc/pmsc_model.h"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>

#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "core/common/format.h"
#include "core/common/kernels.h"
#include "core/pmsc/articulated_rig.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/key_projection.h"
#include "core/pmsc/local_fail_through.h"

namespace animspace::pmsc {

const char* error_estimator_name(ErrorEstimator estimator) {
  return estimator == ErrorEstimator::kWorstPoint ? "worst_point" : "key_rms";
}

const char* subspace_kind_name(SubspaceKind kind) {
  switch (kind) {
    case SubspaceKind::kLinear:
      return "linear";
    case SubspaceKind::kArticulated:
      return "articulated";
  }
  return "unknown";
}

namespace {

Error shape_error(const std::string& member, const std::string& expected, long rows, long cols) {
  return make_error(ErrorCode::kInvalidArgument, "pmsc model: " + member + " should be " + expected + ", got " +
                                                     std::to_string(rows) + "×" + std::to_string(cols));
}

// Gauss–Newton for the rigid motion estimated from the key points alone: it usually converges
// in 3–4 steps; stop when a step turns by less than this (radians) and moves by less than this
// times the model's extent.
constexpr int kMaxAlignmentIterations = 8;
constexpr double kAlignmentTolerance = 1e-7;

// Key rows as a 3 × K matrix of points (channels == 3).
Eigen::Matrix3Xd as_points(const Eigen::VectorXd& rows) {
  return Eigen::Map<const Eigen::Matrix3Xd>(rows.data(), 3, rows.size() / 3);
}

// Check points (issue #35): in range, not key points, not repeated, regions in range; a cross
// model has none (its output is not the control set the client poses). Copies their rows.
Status prepare_check_rows(PmscModel& m) {
  const long C = m.check_point_count();
  const long D = m.channel_count;
  m.check_mean.resize(0);
  m.check_basis.resize(0, m.basis.cols());
  if (C == 0) return Status::Ok();
  if (m.cross) return make_error(ErrorCode::kInvalidArgument, "pmsc model: a cross-PMSC model has no check points");
  std::vector<char> used(static_cast<size_t>(m.control_point_count), 0);
  for (int k : m.key_points) used[static_cast<size_t>(k)] = 1;
  for (long c = 0; c < C; ++c) {
    const int point = m.check_points[static_cast<size_t>(c)];
    if (point < 0 || point >= m.control_point_count) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: check point " + std::to_string(c) + " is " + std::to_string(point) +
                            ", outside [0, " + std::to_string(m.control_point_count) + ")");
    }
    if (used[static_cast<size_t>(point)]) {
      return make_error(ErrorCode::kInvalidArgument, "pmsc model: check point " + std::to_string(c) + " (point " +
                                                         std::to_string(point) +
                                                         ") is a key point or repeats another check point");
    }
    used[static_cast<size_t>(point)] = 1;
  }
  if (!m.check_regions.empty() &&
      (static_cast<long>(m.check_regions.size()) != C ||
       std::any_of(m.check_regions.begin(), m.check_regions.end(),
                   [&](int r) { return r < 0 || r >= m.region_count; }))) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: check_regions should give one region in [0, " + std::to_string(m.region_count) +
                          ") per check point (" + std::to_string(C) + ")");
  }
  if (m.region_count > 0 && m.check_regions.empty()) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: check_regions missing for a model with regions");
  }
  if (!(m.key_weight >= 0) || !std::isfinite(m.key_weight)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: key_weight must be finite and ≥ 0, got " + format_number(m.key_weight));
  }
  ANIMSPACE_RETURN_IF_ERROR(validate(m.key_only_epsilon));
  m.check_mean.resize(C * D);
  m.check_basis.resize(C * D, m.basis.cols());
  for (long c = 0; c < C; ++c) {
    const long row = static_cast<long>(m.check_points[static_cast<size_t>(c)]) * D;
    m.check_mean.segment(c * D, D) = m.mean.segment(row, D).cast<double>();
    m.check_basis.middleRows(c * D, D) = m.basis.middleRows(row, D).cast<double>();
  }
  return Status::Ok();
}

}  // namespace

Eigen::MatrixXd least_squares_projection(const Eigen::MatrixXd& key_basis, double max_condition,
                                         double* condition_number, double* regularization, Eigen::MatrixXd* range) {
  // Divide and conquer (kernels.h, thin_svd_serial: LAPACK's dgesdd under the BLAS kernel): an
  // articulated basis has hundreds of columns (issue #51), where Jacobi's sweeps over a 1900 × 425
  // A_key took seconds at every key-selection step and every calibration fold.
  const long rows = key_basis.rows(), columns = key_basis.cols(), k = std::min(rows, columns);
  Eigen::VectorXd s(k);
  Eigen::MatrixXd U(rows, k), Vt(k, columns);
  thin_svd_serial(rows, columns, key_basis.data(), rows, s.data(), U.data(), rows, Vt.data(), k);
  const double s_max = s.size() > 0 ? s(0) : 0.0;
  const double s_min = s.size() > 0 ? s(s.size() - 1) : 0.0;
  const double kappa = s_min > 0 ? s_max / s_min : std::numeric_limits<double>::infinity();
  double lambda = 0;
  Eigen::VectorXd inverse = Eigen::VectorXd::Zero(s.size());
  if (kappa > max_condition) {
    // Bounds the amplification of key-point noise at ~max_condition instead of 1/σ_min.
    lambda = std::pow(s_max / max_condition, 2);
    for (long i = 0; i < s.size(); ++i) inverse(i) = s(i) / (s(i) * s(i) + lambda);
  } else {
    inverse = s.cwiseInverse();
  }
  if (condition_number) *condition_number = kappa;
  if (regularization) *regularization = lambda;
  if (range) {
    long rank = 0;
    while (rank < s.size() && s(rank) > 0) ++rank;
    *range = U.leftCols(rank);
  }
  // P = V diag(inverse) Uᵀ, formed as its transpose U diag(inverse) Vᵀ through the kernel.
  U *= inverse.asDiagonal();
  Eigen::MatrixXd transposed(rows, columns);
  gemm_serial(rows, k, columns, U.data(), rows, Vt.data(), k, 0.0, transposed.data(), rows);
  return transposed.transpose();
}

Status prepare_projection(PmscModel& m) {
  const long D = m.channel_count;
  const long M = m.basis.cols();
  const long K = static_cast<long>(m.key_points.size());
  if (m.channel_count < 1) return make_error(ErrorCode::kInvalidArgument, "pmsc model: channels must be ≥ 1");
  if (m.aligned && m.channel_count != 3) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: rigid alignment needs 3 channels, got " +
                                                       std::to_string(m.channel_count));
  }
  if (m.point_count < 1) return make_error(ErrorCode::kInvalidArgument, "pmsc model: point_count must be ≥ 1");
  if (m.mean.size() != m.point_count * D) {
    return shape_error("mean", std::to_string(m.point_count * D) + "×1", m.mean.size(), 1);
  }
  if (m.basis.rows() != m.point_count * D || M < 1) {
    return shape_error("basis", std::to_string(m.point_count * D) + "×M (M ≥ 1)", m.basis.rows(), M);
  }
  if (m.subspace_kind == SubspaceKind::kArticulated) {
    if (D != 3 || m.cross || m.aligned || m.relative_tolerance) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: an articulated subspace is of positions (3 channels), not cross, aligned "
                        "or relative");
    }
    if (m.bone_count < 1 || m.residual_components < 0 || 12L * m.bone_count + m.residual_components != M) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: an articulated basis has 12·bones + residual components columns: expected " +
                            std::to_string(12L * m.bone_count + m.residual_components) + " (" +
                            std::to_string(m.bone_count) + " bones, " + std::to_string(m.residual_components) +
                            " residual components), got " + std::to_string(M));
    }
  } else if (m.bone_count != 0 || m.residual_components != 0) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: a linear subspace has no bones or residual components");
  }
  if (K < 1) return make_error(ErrorCode::kInvalidArgument, "pmsc model: no key points");
  for (long k = 0; k < K; ++k) {
    if (m.key_points[k] < 0 || m.key_points[k] >= m.control_point_count) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: key point " + std::to_string(k) + " is " + std::to_string(m.key_points[k]) +
                            ", outside [0, " + std::to_string(m.control_point_count) + ")");
    }
  }
  if (m.key_mean.size() != K * D) return shape_error("key_mean", std::to_string(K * D) + "×1", m.key_mean.size(), 1);
  if (m.key_basis.rows() != K * D || m.key_basis.cols() != M) {
    return shape_error("key_basis", std::to_string(K * D) + "×" + std::to_string(M), m.key_basis.rows(),
                       m.key_basis.cols());
  }
  if (K * D < M) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "pmsc model: " + std::to_string(K) + " key points × " + std::to_string(D) +
                          " channels give fewer equations than the " + std::to_string(M) + " basis vectors");
  }
  if (!m.mean.allFinite() || !m.basis.allFinite() || !m.key_mean.allFinite() || !m.key_basis.allFinite()) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: mean or basis holds NaN or Inf");
  }
  // The key rows are kept in double for the projection's accuracy, but they come from float32
  // frames, so training never puts a value beyond float range there; a stored one (found by
  // fuzzing: key_mean 2e307) would overflow e_key to Inf on the first pose served.
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  if (m.key_mean.cwiseAbs().maxCoeff() > kFloatMax || m.key_basis.cwiseAbs().maxCoeff() > kFloatMax) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: key_mean or key_basis holds a value beyond float32 range");
  }
  ANIMSPACE_RETURN_IF_ERROR(validate(m.epsilon));
  if (m.region_count > 0) {
    if (static_cast<long>(m.point_regions.size()) != m.point_count ||
        static_cast<long>(m.key_regions.size()) != K) {
      return make_error(ErrorCode::kInvalidArgument, "pmsc model: regions must give one region per point and key");
    }
    for (int r : m.point_regions) {
      if (r < 0 || r >= m.region_count) return make_error(ErrorCode::kInvalidArgument, "pmsc model: region out of range");
    }
    for (int r : m.key_regions) {
      if (r < 0 || r >= m.region_count) return make_error(ErrorCode::kInvalidArgument, "pmsc model: region out of range");
    }
    ANIMSPACE_RETURN_IF_ERROR(check_region_weights(m));
  } else if (m.region_weights.size() > 0) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: region_weights given for a model without regions");
  }
  if (!m.region_epsilon.empty() && static_cast<long>(m.region_epsilon.size()) != m.region_count) {
    return make_error(ErrorCode::kInvalidArgument, "pmsc model: region_epsilon should hold " +
                                                       std::to_string(m.region_count) + " thresholds, got " +
                                                       std::to_string(m.region_epsilon.size()));
  }
  for (const SoftCacheThresholds& t : m.region_epsilon) ANIMSPACE_RETURN_IF_ERROR(validate(t));
  ANIMSPACE_RETURN_IF_ERROR(prepare_check_rows(m));
  if (m.relative_tolerance) {
    if (m.aligned) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: a relative tolerance needs a model without rigid alignment");
    }
    if (m.mean.cwiseAbs().maxCoeff() != 0 || m.key_mean.cwiseAbs().maxCoeff() != 0) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: a relative-tolerance model is linear: its mean and key_mean must be 0");
    }
    // In float, as the basis is stored: S needs a few digits, and a double copy of an N·D × M
    // basis per calibration fold was most of what a relative model added to its training.
    Eigen::MatrixXf gram(m.basis.cols(), m.basis.cols());
    gram.setZero();
    gram_lower_serial(m.basis.rows(), m.basis.cols(), m.basis.data(), m.basis.outerStride(), gram.data(), gram.rows());
    m.basis_gram = gram.selfadjointView<Eigen::Lower>().toDenseMatrix().cast<double>();
  } else {
    m.basis_gram.resize(0, 0);
  }

  m.projection = least_squares_projection(m.key_basis, kMaxConditionNumber, &m.condition_number, &m.regularization,
                                          m.aligned ? &m.key_range : nullptr);
  if (m.aligned) {
    m.key_range_translation = Eigen::MatrixXd::Zero(m.key_range.cols(), 3);
    for (long k = 0; k < K; ++k) m.key_range_translation += m.key_range.middleRows(3 * k, 3).transpose();
  }
  if (!m.projection.allFinite()) return make_error(ErrorCode::kFailedPrecondition, "pmsc model: key basis is degenerate");
  // f̂ = mean + A·P·(keys − key_mean): ‖A‖_F·‖P‖_F bounds how far key values are amplified. The
  // regularisation caps ‖P‖₂ at κ_max / (2σ_max(A_key)); with A's M ≤ 200 orthonormal columns
  // that is √M·√M·1e6 / (2σ_max(A_key)), below 1e20 unless the key rows carry almost none of the
  // basis (σ_max < 1e-11). A stored key_basis tiny against the basis it indexes (1e-200: a
  // corrupt or hand-made file) would turn an ordinary pose into Inf points the cache calls hits.
  const double amplification = static_cast<double>(m.basis.stableNorm()) * m.projection.norm();
  if (!(amplification <= kMaxAmplification)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: key_basis is out of scale with basis: key values would be amplified up to " +
                          format_number(amplification) + " times, the limit is " + format_number(kMaxAmplification));
  }
  return Status::Ok();
}

namespace {

// Skew-symmetric matrix [v]× with [v]× w = v × w.
Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// p = P·b and the residual b − A_key·p for centred key values b, through the active kernel. One
// pose at a time, in a batch or alone alike: e_key, and so the verdict, never depends on what
// else was evaluated with a pose.
Eigen::VectorXd project_centred(const PmscModel& m, Eigen::VectorXd centred, Eigen::VectorXd& p) {
  const long M = m.projection.rows();
  const long rows = centred.size();
  p.resize(M);
  gemm(M, rows, 1, m.projection.data(), M, centred.data(), rows, 0.0, p.data(), M);
  Eigen::VectorXd product(rows);
  gemm(rows, M, 1, m.key_basis.data(), rows, p.data(), M, 0.0, product.data(), rows);
  centred -= product;
  return centred;
}

// Eq. 2 for one pose: p from the key values, and the key residual f_key − f̂_key in the subspace
// frame. With alignment the rigid motion and p are solved together, by Gauss–Newton on
//   min over (R, t, p) of ‖Rᵀ(f_key − t) − key_mean − A_key p‖²
// started from a Procrustes fit of the mean key shape. (Alternating Procrustes and projection
// converges very slowly: the aligned subspace still holds rotation-like directions.) Each step
// linearises the aligned keys, a + [a]×δω − δt, and eliminates p through the range U of A_key:
//   (GᵀG − (UᵀG)ᵀUᵀG) δ = Gᵀb − (UᵀG)ᵀUᵀb,   G_k = [−[a_k]×  I],  b = a − key_mean,
// where GᵀG and Gᵀb are sums over keys of 3×3 blocks and UᵀG costs O(K·r): each step is a few
// passes over the key rows and a 6×6 solve. `transform` maps the aligned frame to the world.
Eigen::VectorXd project_keys(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                             Eigen::VectorXd& p, geometry::RigidTransform& transform) {
  Eigen::VectorXd keys = key_values.cast<double>();
  transform = geometry::RigidTransform();
  if (!m.aligned) return project_centred(m, keys - m.key_mean, p);
  const long K = keys.size() / 3;
  const long r = m.key_range.cols();
  const Eigen::Matrix3Xd observed = as_points(keys);
  Eigen::Map<Eigen::Matrix3Xd> aligned(keys.data(), 3, K);
  using Strided = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, 3>>;
  const Strided U_x(m.key_range.data() + 0, K, r, Eigen::Stride<Eigen::Dynamic, 3>(3 * K, 3));
  const Strided U_y(m.key_range.data() + 1, K, r, Eigen::Stride<Eigen::Dynamic, 3>(3 * K, 3));
  const Strided U_z(m.key_range.data() + 2, K, r, Eigen::Stride<Eigen::Dynamic, 3>(3 * K, 3));
  const double scale = std::max(1.0, m.key_mean.cwiseAbs().maxCoeff());

  transform = geometry::fit_rigid(as_points(m.key_mean), observed);
  Eigen::VectorXd b;
  Eigen::MatrixXd UG(r, 6);
  for (int iteration = 0; iteration < kMaxAlignmentIterations; ++iteration) {
    const geometry::RigidTransform to_aligned = transform.inverse();
    aligned = (to_aligned.rotation * observed).colwise() + to_aligned.translation;
    b = keys - m.key_mean;
    const Eigen::Map<const Eigen::Matrix3Xd> b_points(b.data(), 3, K);
    // Uᵀ G: column j of the rotation part is Σ_k U_kᵀ (e_j × a_k).
    UG.col(0).noalias() = U_z.transpose() * aligned.row(1).transpose() - U_y.transpose() * aligned.row(2).transpose();
    UG.col(1).noalias() = U_x.transpose() * aligned.row(2).transpose() - U_z.transpose() * aligned.row(0).transpose();
    UG.col(2).noalias() = U_y.transpose() * aligned.row(0).transpose() - U_x.transpose() * aligned.row(1).transpose();
    UG.rightCols(3) = m.key_range_translation;
    const Eigen::VectorXd Ub = m.key_range.transpose() * b;
    // GᵀG and Gᵀb: Σ(|a|²I − a aᵀ), Σ[a]×, K·I; Σ a × b, Σ b.
    Eigen::Matrix<double, 6, 6> normal;
    const Eigen::Vector3d a_sum = aligned.rowwise().sum();
    normal.topLeftCorner<3, 3>() = aligned.squaredNorm() * Eigen::Matrix3d::Identity() - aligned * aligned.transpose();
    normal.topRightCorner<3, 3>() = skew(a_sum);
    normal.bottomLeftCorner<3, 3>() = skew(a_sum).transpose();
    normal.bottomRightCorner<3, 3>() = static_cast<double>(K) * Eigen::Matrix3d::Identity();
    Eigen::Matrix<double, 6, 1> rhs;
    rhs.head<3>().setZero();
    for (long k = 0; k < K; ++k) rhs.head<3>() += aligned.col(k).cross(b_points.col(k));
    rhs.tail<3>() = b_points.rowwise().sum();
    normal.noalias() -= UG.transpose() * UG;
    rhs.noalias() -= UG.transpose() * Ub;
    // The aligned subspace may itself contain near-rigid directions: keep the 6×6 solve posed.
    normal.diagonal().array() += 1e-12 * std::max(1.0, normal.diagonal().maxCoeff());
    const Eigen::Matrix<double, 6, 1> delta = normal.ldlt().solve(rhs);
    // Apply the step to the aligned frame, a ← exp(−[δω]×) a − δt, composed exactly.
    const Eigen::Vector3d omega = delta.head<3>();
    const double angle = omega.norm();
    const Eigen::Matrix3d step =
        angle > 0 ? Eigen::AngleAxisd(-angle, omega / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
    geometry::RigidTransform updated;
    updated.rotation = step * to_aligned.rotation;
    updated.translation = step * to_aligned.translation - delta.tail<3>();
    transform = updated.inverse();
    if (angle < kAlignmentTolerance && delta.tail<3>().norm() < kAlignmentTolerance * scale) break;
  }
  const geometry::RigidTransform to_aligned = transform.inverse();
  aligned = (to_aligned.rotation * observed).colwise() + to_aligned.translation;
  return project_centred(m, keys - m.key_mean, p);
}

double rms(const Eigen::VectorXd& residual) {
  return std::sqrt(residual.squaredNorm() / static_cast<double>(residual.size()));
}

}  // namespace

double pose_scale(const PmscModel& m, const Eigen::VectorXd& coordinates) {
  assert(m.relative_tolerance && m.basis_gram.rows() == coordinates.size());
  const double squared = coordinates.dot(m.basis_gram * coordinates);
  return std::sqrt(std::max(squared, 0.0) / static_cast<double>(m.point_count));
}

void estimate_coordinates(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                          PoseEstimate& out) {
  estimate_coordinates(m, key_values, Eigen::VectorXf(), out);
}

void estimate_coordinates(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                          const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out) {
  estimate_coordinates_with(m, key_values, check_values, out, KeyProjection());
}

void estimate_coordinates_with(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                               const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out,
                               const KeyProjection& projection) {
  assert(key_values.size() == m.key_mean.size());
  assert(check_values.size() == 0 || check_values.size() == m.check_mean.size());
  assert(m.projection.rows() == m.basis.cols());
  assert(!projection || !m.aligned);
  Eigen::VectorXd key_residual;
  if (projection) {
    out.alignment = geometry::RigidTransform();
    key_residual = projection(key_values.cast<double>() - m.key_mean, out.coordinates);
  } else {
    key_residual = project_keys(m, key_values, out.coordinates, out.alignment);
  }
  // Errors in model units, or as fractions of the pose's scale S (relative_tolerance).
  out.scale = m.relative_tolerance ? pose_scale(m, out.coordinates) : 1.0;
  const auto measured = [scale = out.scale](double error) {
    return scale > 0 ? error / scale : std::numeric_limits<double>::infinity();
  };
  out.key_point_error = measured(rms(key_residual));
  {
    const long D_keys = m.channel_count;
    double worst = 0;
    for (long k = 0; k * D_keys < key_residual.size(); ++k) {
      worst = std::max(worst, key_residual.segment(k * D_keys, D_keys).squaredNorm());
    }
    out.key_point_max_error = measured(std::sqrt(worst));
  }
  out.points.resize(0);
  const long D = m.channel_count;
  const long C = m.check_point_count();
  out.checked = C > 0 && check_values.size() == C * D;
  out.check_point_error = 0;

  // e_check: the check rows of f̂, moved to the world like every point, against the values sent.
  std::vector<double> check_errors;
  if (out.checked) {
    Eigen::VectorXd estimate = m.check_mean;
    gemm_serial(C * D, m.check_basis.cols(), 1, m.check_basis.data(), C * D, out.coordinates.data(),
                m.check_basis.cols(), 1.0, estimate.data(), C * D);
    if (m.aligned) {  // positions (D = 3): a map of 3 × C is only made for them
      Eigen::Map<Eigen::Matrix3Xd> points(estimate.data(), 3, C);
      points = (out.alignment.rotation * points).colwise() + out.alignment.translation;
    }
    check_errors.resize(static_cast<size_t>(C));
    for (long c = 0; c < C; ++c) {
      check_errors[static_cast<size_t>(c)] =
          measured((check_values.segment(c * D, D).cast<double>() - estimate.segment(c * D, D)).norm());
      out.check_point_error = std::max(out.check_point_error, check_errors[static_cast<size_t>(c)]);
    }
  }
  const double key_term =
      m.estimator == ErrorEstimator::kWorstPoint ? out.key_point_max_error : out.key_point_error;
  out.error_estimate = out.checked ? combined_error_estimate(m.key_weight, key_term, out.check_point_error) : key_term;

  // Local fail-through: the same estimate, restricted to the key (and check) points of each region.
  out.region_errors.assign(static_cast<size_t>(m.region_count), 0.0);
  if (m.region_count > 0) {
    std::vector<long> counts(static_cast<size_t>(m.region_count), 0);
    for (size_t k = 0; k < m.key_regions.size(); ++k) {
      const auto r = static_cast<size_t>(m.key_regions[k]);
      out.region_errors[r] += key_residual.segment(static_cast<long>(k) * D, D).squaredNorm();
      counts[r] += D;
    }
    for (size_t r = 0; r < counts.size(); ++r) {
      out.region_errors[r] =
          counts[r] > 0 ? measured(std::sqrt(out.region_errors[r] / static_cast<double>(counts[r]))) : 0.0;
    }
    if (out.checked) {
      std::vector<double> region_check(counts.size(), 0.0);
      for (long c = 0; c < C; ++c) {
        double& worst = region_check[static_cast<size_t>(m.check_regions[static_cast<size_t>(c)])];
        worst = std::max(worst, check_errors[static_cast<size_t>(c)]);
      }
      for (size_t r = 0; r < counts.size(); ++r) {
        out.region_errors[r] = combined_error_estimate(m.key_weight, out.region_errors[r], region_check[r]);
      }
    }
  }
}

void reconstruct(const PmscModel& m, std::span<const PoseEstimate* const> estimates,
                 std::span<float* const> destinations) {
  assert(estimates.size() == destinations.size());
  const long rows = m.basis.rows();
  const long M = m.basis.cols();
  const long B = static_cast<long>(estimates.size());
  if (B == 0) return;
  Eigen::MatrixXf coordinates(M, B);
  for (long b = 0; b < B; ++b) coordinates.col(b) = estimates[static_cast<size_t>(b)]->coordinates.cast<float>();
  if (B < kBlasGemmMinColumns) {
    // Alone (or nearly): one matrix–vector product per pose, straight into its destination —
    // the reconstruction a client holding the basis does (coordinates.h).
    for (long b = 0; b < B; ++b) {
      const PoseEstimate& estimate = *estimates[static_cast<size_t>(b)];
      const FloatAlignment alignment = float_alignment(estimate.alignment);
      reconstruct_coordinates(m.mean, m.basis, coordinates.col(b).data(), m.aligned ? &alignment : nullptr,
                              destinations[static_cast<size_t>(b)]);
    }
    return;
  }
  // One product for the batch, a block of rows at a time: the block's B columns stay in cache
  // while the mean is added on the way to each pose's destination, so every answer is written
  // once, and the basis is read once per batch instead of once per pose.
  const long block = std::max(kReconstructionBlockValues / B, 256L);
  Eigen::MatrixXf scratch(std::min(block, rows), B);
  for (long r0 = 0; r0 < rows; r0 += block) {
    const long n = std::min(block, rows - r0);
    gemm(n, M, B, m.basis.data() + r0, rows, coordinates.data(), M, 0.0f, scratch.data(), scratch.rows());
    for (long b = 0; b < B; ++b) {
      Eigen::Map<Eigen::VectorXf>(destinations[static_cast<size_t>(b)] + r0, n) =
          m.mean.segment(r0, n) + scratch.col(b).head(n);
    }
  }
  if (m.aligned) {
    for (long b = 0; b < B; ++b) {
      to_world(float_alignment(estimates[static_cast<size_t>(b)]->alignment), m.point_count,
               destinations[static_cast<size_t>(b)]);
    }
  }
}

void evaluate(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values, PoseEstimate& out) {
  estimate_coordinates(m, key_values, out);
  Eigen::VectorXf points(m.mean.size());
  const PoseEstimate* estimate = &out;
  float* destination = points.data();
  reconstruct(m, {&estimate, 1}, {&destination, 1});
  out.points = std::move(points);
}

void evaluate_batch(const PmscModel& m, const Eigen::Ref<const Eigen::MatrixXf>& key_values, Eigen::MatrixXf& points,
                    Eigen::VectorXd& key_point_errors) {
  assert(key_values.rows() == m.key_mean.size());
  const long B = key_values.cols();
  std::vector<PoseEstimate> estimates(static_cast<size_t>(B));
  std::vector<const PoseEstimate*> inputs(static_cast<size_t>(B));
  std::vector<float*> destinations(static_cast<size_t>(B));
  points.resize(m.mean.size(), B);
  key_point_errors.resize(B);
  for (long b = 0; b < B; ++b) {
    const auto i = static_cast<size_t>(b);
    estimate_coordinates(m, key_values.col(b), estimates[i]);
    key_point_errors(b) = estimates[i].key_point_error;
    inputs[i] = &estimates[i];
    destinations[i] = points.col(b).data();
  }
  reconstruct(m, inputs, destinations);
}

bool judge(const PmscModel& m, const PoseEstimate& estimate, CachedPose& out) {
  const SoftCacheDecision decision = decide(estimate.error_estimate, verdict_thresholds(m, estimate));
  out.status = decision.status;
  out.alpha = decision.alpha;
  out.key_point_error = estimate.key_point_error;
  out.key_point_max_error = estimate.key_point_max_error;
  out.check_point_error = estimate.check_point_error;
  out.checked = estimate.checked;
  out.error_estimate = estimate.error_estimate;
  out.scale = estimate.scale;
  out.region_errors = estimate.region_errors;
  out.full_evaluation_needed = false;
  out.computed_full_values.resize(0);
  return decision.status != CacheStatus::kHit && !m.cross;
}

void finish_cached(const PmscModel& m, const PoseEstimate& estimate, Eigen::Ref<Eigen::VectorXf> points,
                   const Eigen::VectorXf* full_values, const FullCalculation& full_calculation, CachedPose& out) {
  assert(full_values == nullptr || full_values->size() == m.mean.size());
  assert(points.size() == m.mean.size());
  if (!judge(m, estimate, out)) return;
  // Step 5: the full calculation, when the caller brought none and holds an engine.
  if (full_values == nullptr && full_calculation && full_calculation(out.computed_full_values)) {
    assert(out.computed_full_values.size() == m.mean.size());
    full_values = &out.computed_full_values;
  }
  if (full_values != nullptr && out.status == CacheStatus::kMiss) {
    points = *full_values;  // eq. 9: f itself, not 1·f + 0·f̂ (which an overflowed f̂ would spoil)
  } else if (full_values != nullptr) {
    blend(points, *full_values, out.alpha, points);
  } else {
    out.full_evaluation_needed = true;
  }
}

void evaluate_cached(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::VectorXf* full_values, CachedPose& out) {
  evaluate_cached(m, key_values, full_values, FullCalculation(), out);
}

void evaluate_cached(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::VectorXf* full_values, const FullCalculation& full_calculation,
                     CachedPose& out) {
  evaluate_cached(m, key_values, Eigen::VectorXf(), full_values, full_calculation, out);
}

void evaluate_cached(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::Ref<const Eigen::VectorXf>& check_values, const Eigen::VectorXf* full_values,
                     const FullCalculation& full_calculation, CachedPose& out) {
  PoseEstimate estimate;
  estimate_coordinates(m, key_values, check_values, estimate);
  Eigen::VectorXf points(m.mean.size());
  const PoseEstimate* input = &estimate;
  float* destination = points.data();
  reconstruct(m, {&input, 1}, {&destination, 1});
  out.points = std::move(points);
  finish_cached(m, estimate, out.points, full_values, full_calculation, out);
}

CalibrationSamples estimator_samples(const PmscModel& m) {
  CalibrationSamples samples = m.calibration.samples;
  if (m.estimator == ErrorEstimator::kWorstPoint) samples.key_point_errors = samples.key_point_max_errors;
  return samples;
}

Status apply_calibration(PmscModel& m, double tolerance, double blend_zone_ratio) {
  const CalibrationSamples& samples = m.calibration.samples;
  const double delta = m.calibration.false_hit_rate;
  if (!(delta > 0 && delta < 1)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "false_hit_rate must be in (0, 1), got " + format_number(delta));
  }
  if (!(tolerance > 0) || !std::isfinite(tolerance)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "error_tolerance must be a positive distance, got " + format_number(tolerance));
  }
  if (!(blend_zone_ratio >= 1) || !std::isfinite(blend_zone_ratio)) {
    return make_error(ErrorCode::kInvalidArgument, "blend_zone_ratio must be ≥ 1, got " + format_number(blend_zone_ratio));
  }
  if (samples.size() == 0) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "the model keeps no calibration samples (trained before calibration was stored); retrain it");
  }
  const long R = samples.region_key_point_errors.cols();
  if (R != 0 && R != m.region_count) {
    return make_error(ErrorCode::kInvalidArgument, "calibration samples have " + std::to_string(R) +
                                                       " region columns, the model has " +
                                                       std::to_string(m.region_count) + " regions");
  }
  if (static_cast<long>(samples.fold_family.size()) != samples.size()) {
    return make_error(ErrorCode::kInvalidArgument, "calibration samples: one fold family per sample expected");
  }
  const bool checked = !m.check_points.empty();
  if (checked != samples.checked() || (samples.checked() && samples.check_point_errors.size() != samples.size())) {
    return make_error(ErrorCode::kInvalidArgument,
                      "calibration samples: check point errors are " +
                          std::string(samples.checked() ? "present" : "absent") + " but the model has " +
                          std::to_string(m.check_point_count()) + " check points");
  }
  if (checked && R > 0 && samples.region_check_point_errors.cols() != R) {
    return make_error(ErrorCode::kInvalidArgument, "calibration samples: " + std::to_string(R) +
                                                       " region check columns expected, got " +
                                                       std::to_string(samples.region_check_point_errors.cols()));
  }
  if (m.estimator == ErrorEstimator::kWorstPoint && samples.key_point_max_errors.size() != samples.size()) {
    return make_error(ErrorCode::kInvalidArgument,
                      "calibration samples: the worst key point's error of every sample is needed by the estimator "
                      "worst_point, got " + std::to_string(samples.key_point_max_errors.size()) + " of " +
                          std::to_string(samples.size()));
  }
  const auto thresholds = [&](double epsilon_min) {
    return SoftCacheThresholds{epsilon_min, epsilon_min * blend_zone_ratio};
  };
  // The whole pose's key term, as the model's estimator measures it; the regions' samples are RMS
  // either way.
  const CalibrationSamples whole_samples = estimator_samples(m);
  m.key_weight = checked ? choose_key_weight(whole_samples, tolerance) : 1.0;
  const ExtrapolatedEpsilon whole =
      calibrate_extrapolated(whole_samples.error_estimates(m.key_weight), samples.max_errors, tolerance, delta);
  m.epsilon = thresholds(whole.epsilon_min);
  m.key_only_epsilon = checked ? thresholds(calibrate_extrapolated(whole_samples.key_point_errors, samples.max_errors,
                                                                   tolerance, delta)
                                                .epsilon_min)
                               : SoftCacheThresholds{};
  m.calibration.error_ratio = whole.epsilon_min > 0 ? tolerance / whole.epsilon_min : 0;
  m.calibration.over_tolerance = whole.over_tolerance;
  m.calibration.bad_samples = whole.bad_samples;
  m.region_epsilon.clear();
  for (long r = 0; r < R; ++r) {
    m.region_epsilon.push_back(thresholds(calibrate_extrapolated(samples.region_error_estimates(r, m.key_weight),
                                                                 samples.region_max_errors.col(r), tolerance, delta)
                                              .epsilon_min));
  }
  return Status::Ok();
}

namespace {

// The rows of `points` (D values each) of a full control frame, in that order.
Eigen::VectorXf gather_points(const PmscModel& m, const std::vector<int>& points,
                              const Eigen::Ref<const Eigen::VectorXf>& control_frame) {
  const long D = m.channel_count;
  assert(control_frame.size() == m.control_point_count * D);
  Eigen::VectorXf values(static_cast<long>(points.size()) * D);
  for (size_t k = 0; k < points.size(); ++k) {
    values.segment(static_cast<long>(k) * D, D) = control_frame.segment(static_cast<long>(points[k]) * D, D);
  }
  return values;
}

}  // namespace

Eigen::VectorXf gather_key_values(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& control_frame) {
  return gather_points(m, m.key_points, control_frame);
}

Eigen::VectorXf gather_check_values(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& control_frame) {
  return gather_points(m, m.check_points, control_frame);
}

bool calibration_guarantee_holds(const PmscModel& m) {
  return guarantee_holds(m.calibration.bad_samples, m.calibration.false_hit_rate);
}

namespace {

// The tolerance the guarantee speaks of, with its scale (issue #55: the sentence named none):
// "0.0123 model units, 0.45% of the mean pose's bounding-box diagonal", or a fraction of S. An
// articulated model's mean is the residual's mean, no pose: its scale is the rest pose's, read
// back off the skinning terms (articulated_rig.h).
std::string tolerance_text(const PmscModel& m) {
  const double tolerance = m.calibration.error_ratio * m.epsilon.epsilon_min;
  char text[160];
  if (m.relative_tolerance) {
    std::snprintf(text, sizeof text, "%.3g of each pose's own scale S", tolerance);
    return text;
  }
  if (m.channel_count == 3 && m.mean.size() >= 3) {
    double diagonal = 0;
    const char* pose = "mean";
    if (m.subspace_kind == SubspaceKind::kArticulated) {
      pose = "rest";
      if (auto rig = articulated_rig(m); rig.ok()) {
        diagonal = (rig->bind_points.colwise().maxCoeff() - rig->bind_points.colwise().minCoeff()).norm();
      }
    } else {
      const Eigen::Map<const Eigen::Matrix3Xf> points(m.mean.data(), 3, m.mean.size() / 3);
      diagonal = (points.rowwise().maxCoeff() - points.rowwise().minCoeff()).cast<double>().norm();
    }
    if (diagonal > 0) {
      std::snprintf(text, sizeof text, "%.3g model units, %.3g%% of the %s pose's bounding-box diagonal", tolerance,
                    100 * tolerance / diagonal, pose);
      return text;
    }
  }
  std::snprintf(text, sizeof text, "%.3g model units", tolerance);
  return text;
}

}  // namespace

std::string calibration_statement(const PmscModel& m) {
  const PmscModel::Calibration& c = m.calibration;
  if (c.samples.size() == 0) {
    return "no guarantee: ε was set before calibration was stored (the worst held-out ratio); retrain to state one";
  }
  if (c.bad_samples == 0) {
    return "no guarantee: calibrated before check points and extrapolated bad samples (issue #35); retrain to state one";
  }
  const std::string checked = m.check_points.empty() ? "" : " sent with its " + std::to_string(m.check_point_count()) + " check points";
  if (!calibration_guarantee_holds(m)) {
    return "no guarantee: " + std::to_string(c.bad_samples) + " over-tolerance samples cannot state a false-hit rate of " +
           format_number(c.false_hit_rate) + " (it needs at least " +
           std::to_string(static_cast<long>(std::ceil(1.0 / c.false_hit_rate - 1.0 - 1e-9))) +
           "); ε sits below every one of them";
  }
  // Issue #52 item 3: what the rate rests on — held-out frames that were over the tolerance
  // themselves, or residuals under it scaled up to it — and so when it says nothing.
  const long real = std::min(c.over_tolerance, c.bad_samples);
  const std::string rests_on =
      real == 0 ? "none of them from a held-out frame over the tolerance itself: the rate rests on residuals scaled up "
                  "to the tolerance alone, and is void for errors unlike theirs"
                : std::to_string(real) + " of them from held-out frames over the tolerance themselves, the other " +
                      std::to_string(c.bad_samples - real) + " from residuals under it, scaled up to it";
  return "a pose over the tolerance (" + tolerance_text(m) + ")" + checked + " is called HIT with probability at most " +
         format_number(c.false_hit_rate) + ", when its error is like the " + std::to_string(c.bad_samples) +
         " over-tolerance held-out samples ε was calibrated on (held-out frames, blocks of motion, sparser training; " +
         rests_on + "); void for motion unlike any of the training frames' folds";
}

double hit_rate(const PmscModel& m, const FrameMatrix& control_frames) {
  if (control_frames.rows() == 0) return 0;
  long hits = 0;
  PoseEstimate estimate;
  for (Eigen::Index f = 0; f < control_frames.rows(); ++f) {
    const Eigen::VectorXf frame = control_frames.row(f).transpose();
    estimate_coordinates(m, gather_key_values(m, frame), gather_check_values(m, frame), estimate);  // no f̂ needed
    hits += decide(estimate.error_estimate, verdict_thresholds(m, estimate)).status == CacheStatus::kHit ? 1 : 0;
  }
  return static_cast<double>(hits) / static_cast<double>(control_frames.rows());
}

namespace {

// Shortest text of each float as a float ("4.00016", not its double expansion).
std::string format_values(const float* values, long count) {
  std::string text = "(";
  for (long c = 0; c < count; ++c) {
    char buffer[32];
    const auto written = std::to_chars(buffer, buffer + sizeof buffer, values[c]);
    text += (c ? ", " : "") + std::string(buffer, written.ptr);
  }
  return text + ")";
}

}  // namespace

namespace {

// The values a pose was sent with at one of its points (a key point or a check point) against the
// D full values of that point.
Status check_sent_point(const PmscModel& m, const char* kind, long k, int point, const float* sent, const float* full) {
  const long D = m.channel_count;
  const double absolute = kKeyConsistencyAbsolute * m.epsilon.epsilon_min;
  for (long c = 0; c < D; ++c) {
    const double allowed = kKeyConsistencyRelative * std::max(std::abs(sent[c]), std::abs(full[c])) + absolute;
    if (!(std::abs(static_cast<double>(full[c]) - sent[c]) <= allowed)) {
      return make_error(ErrorCode::kInvalidArgument,
                        std::string(kind) + " point " + std::to_string(k) + " (point " + std::to_string(point) +
                            "): the full values hold " + format_values(full, D) + " but the " + kind +
                            " values hold " + format_values(sent, D) +
                            "; full values must be the pose the key values were read from");
    }
  }
  return Status::Ok();
}

// `sent` (|points|·D) against whole full values (control_point_count·D).
Status check_sent_points(const PmscModel& m, const char* kind, const std::vector<int>& points,
                         const Eigen::Ref<const Eigen::VectorXf>& sent, const Eigen::Ref<const Eigen::VectorXf>& full) {
  const long D = m.channel_count;
  assert(!m.cross);
  assert(sent.size() == static_cast<long>(points.size()) * D && full.size() == m.control_point_count * D);
  for (size_t k = 0; k < points.size(); ++k) {
    const long offset = static_cast<long>(k) * D;
    ANIMSPACE_RETURN_IF_ERROR(check_sent_point(m, kind, static_cast<long>(k), points[k], sent.data() + offset,
                                               full.data() + static_cast<long>(points[k]) * D));
  }
  return Status::Ok();
}

// The same against partial full values of the sorted `full_points`: the sent points among them.
Status check_sent_points(const PmscModel& m, const char* kind, const std::vector<int>& points,
                         const Eigen::Ref<const Eigen::VectorXf>& sent, const std::vector<int>& full_points,
                         const Eigen::Ref<const Eigen::VectorXf>& full) {
  const long D = m.channel_count;
  assert(!m.cross);
  assert(std::is_sorted(full_points.begin(), full_points.end()));
  assert(sent.size() == static_cast<long>(points.size()) * D && full.size() == static_cast<long>(full_points.size()) * D);
  for (size_t k = 0; k < points.size(); ++k) {
    const auto given = std::lower_bound(full_points.begin(), full_points.end(), points[k]);
    if (given == full_points.end() || *given != points[k]) continue;
    const long g = given - full_points.begin();
    ANIMSPACE_RETURN_IF_ERROR(check_sent_point(m, kind, static_cast<long>(k), points[k],
                                               sent.data() + static_cast<long>(k) * D, full.data() + g * D));
  }
  return Status::Ok();
}

}  // namespace

Status check_full_values_at_keys(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                 const Eigen::Ref<const Eigen::VectorXf>& full_values) {
  return check_sent_points(m, "key", m.key_points, key_values, full_values);
}

Status check_full_values_at_keys(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                 const std::vector<int>& full_points,
                                 const Eigen::Ref<const Eigen::VectorXf>& full_values) {
  return check_sent_points(m, "key", m.key_points, key_values, full_points, full_values);
}

Status check_full_values_at_checks(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& check_values,
                                   const Eigen::Ref<const Eigen::VectorXf>& full_values) {
  if (check_values.size() == 0) return Status::Ok();
  return check_sent_points(m, "check", m.check_points, check_values, full_values);
}

Status check_full_values_at_checks(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& check_values,
                                   const std::vector<int>& full_points,
                                   const Eigen::Ref<const Eigen::VectorXf>& full_values) {
  if (check_values.size() == 0) return Status::Ok();
  return check_sent_points(m, "check", m.check_points, check_values, full_points, full_values);
}

}  // namespace animspace::pmsc
