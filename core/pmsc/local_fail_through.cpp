#include "core/pmsc/local_fail_through.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "core/common/format.h"

namespace animspace::pmsc {
namespace {

constexpr double kRowSumTolerance = 1e-6;

// Weight of region r in point i, whichever memberships the model has.
double membership(const PmscModel& m, long i, int r) {
  if (m.region_weights.size() == 0) return m.point_regions[static_cast<size_t>(i)] == r ? 1.0 : 0.0;
  return m.region_weights(i, r);
}

}  // namespace

Eigen::MatrixXd soft_region_weights(const Eigen::MatrixXd& signatures, const std::vector<int>& point_regions,
                                    int region_count, double border_band) {
  const long N = signatures.rows();
  const long R = region_count;
  assert(static_cast<long>(point_regions.size()) == N && R >= 1);
  assert(border_band > 0 && border_band <= 1);

  // Phase 1: centroids c_r, the means of the hard regions' signatures.
  Eigen::MatrixXd centroids = Eigen::MatrixXd::Zero(R, signatures.cols());
  Eigen::VectorXd counts = Eigen::VectorXd::Zero(R);
  for (long i = 0; i < N; ++i) {
    const int r = point_regions[static_cast<size_t>(i)];
    assert(r >= 0 && r < R);
    centroids.row(r) += signatures.row(i);
    counts(r) += 1;
  }
  for (long r = 0; r < R; ++r) {
    if (counts(r) > 0) centroids.row(r) /= counts(r);
  }

  // Phase 2: ‖x_i − c_r‖² for every point and region, as one product (‖x‖² − 2x·c + ‖c‖²).
  Eigen::MatrixXd distances = -2.0 * signatures * centroids.transpose();
  distances.colwise() += signatures.rowwise().squaredNorm();
  distances.rowwise() += centroids.rowwise().squaredNorm().transpose();
  Eigen::MatrixXd separation(R, R);  // ‖c_r − c_s‖²
  for (long r = 0; r < R; ++r) {
    for (long s = 0; s < R; ++s) separation(r, s) = (centroids.row(r) - centroids.row(s)).squaredNorm();
  }

  // Phase 3: u_r = clamp(½ + min_s t_rs, 0, 1), the kMaxRegionsPerPoint largest kept and normalised.
  Eigen::MatrixXd weights = Eigen::MatrixXd::Zero(N, R);
  std::vector<double> u(static_cast<size_t>(R));
  std::vector<long> order(static_cast<size_t>(R));
  for (long i = 0; i < N; ++i) {
    for (long r = 0; r < R; ++r) {
      double depth = std::numeric_limits<double>::infinity();
      for (long s = 0; s < R; ++s) {
        // An empty region has no centroid; coinciding centroids have no bisector (each gets ½).
        if (s == r || counts(s) == 0) continue;
        const double t = separation(r, s) > 0
                             ? (distances(i, s) - distances(i, r)) / (2.0 * border_band * separation(r, s))
                             : 0.0;
        depth = std::min(depth, t);
      }
      u[static_cast<size_t>(r)] = counts(r) == 0 ? 0.0 : std::clamp(0.5 + depth, 0.0, 1.0);
    }
    std::iota(order.begin(), order.end(), 0L);
    const long kept = std::min<long>(R, kMaxRegionsPerPoint);
    std::partial_sort(order.begin(), order.begin() + kept, order.end(), [&](long a, long b) {
      return u[static_cast<size_t>(a)] > u[static_cast<size_t>(b)] ||
             (u[static_cast<size_t>(a)] == u[static_cast<size_t>(b)] && a < b);
    });
    double total = 0;
    for (long j = 0; j < kept; ++j) total += u[static_cast<size_t>(order[static_cast<size_t>(j)])];
    // The nearest centroid's region has every t_rs ≥ 0, so u ≥ ½ there and total ≥ ½.
    assert(total >= 0.5);
    for (long j = 0; j < kept; ++j) {
      const long r = order[static_cast<size_t>(j)];
      weights(i, r) = u[static_cast<size_t>(r)] / total;
    }
  }
  return weights;
}

Eigen::MatrixXd hard_region_weights(const std::vector<int>& point_regions, int region_count) {
  Eigen::MatrixXd weights = Eigen::MatrixXd::Zero(static_cast<long>(point_regions.size()), region_count);
  for (size_t i = 0; i < point_regions.size(); ++i) weights(static_cast<long>(i), point_regions[i]) = 1.0;
  return weights;
}

Status check_region_weights(const PmscModel& m) {
  const Eigen::MatrixXd& w = m.region_weights;
  if (w.size() == 0) return Status::Ok();
  if (w.rows() != m.point_count || w.cols() != m.region_count) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: region_weights should be " + std::to_string(m.point_count) + "×" +
                          std::to_string(m.region_count) + " (points × regions), got " + std::to_string(w.rows()) +
                          "×" + std::to_string(w.cols()));
  }
  for (long i = 0; i < w.rows(); ++i) {
    int non_zero = 0;
    for (long r = 0; r < w.cols(); ++r) {
      if (!(w(i, r) >= 0 && w(i, r) <= 1)) {
        return make_error(ErrorCode::kInvalidArgument, "pmsc model: region_weights of point " + std::to_string(i) +
                                                           ", region " + std::to_string(r) + " is " +
                                                           format_number(w(i, r)) + ", expected a value in [0, 1]");
      }
      non_zero += w(i, r) > 0 ? 1 : 0;
    }
    if (non_zero > kMaxRegionsPerPoint) {
      return make_error(ErrorCode::kInvalidArgument,
                        "pmsc model: region_weights of point " + std::to_string(i) + " has " +
                            std::to_string(non_zero) + " regions, at most " + std::to_string(kMaxRegionsPerPoint) +
                            " expected");
    }
    const double sum = w.row(i).sum();
    if (!(std::abs(sum - 1.0) <= kRowSumTolerance)) {
      return make_error(ErrorCode::kInvalidArgument, "pmsc model: region_weights of point " + std::to_string(i) +
                                                         " sum to " + format_number(sum) + ", expected 1");
    }
  }
  return Status::Ok();
}

LocalFailThrough local_fail_through(const PmscModel& m, double error_estimate,
                                    const std::vector<double>& region_errors, bool checked) {
  LocalFailThrough out;
  if (m.cross) return out;
  const long N = m.point_count;
  if (!regions_judged_alone(m, checked)) {
    // One region, the whole pose: the whole-pose α of eqs. 9–11 at every point.
    const double alpha =
        decide(error_estimate, checked || m.check_points.empty() ? m.epsilon : m.key_only_epsilon).alpha;
    if (alpha > 0) {
      out.full_points.resize(static_cast<size_t>(N));
      std::iota(out.full_points.begin(), out.full_points.end(), 0);
      out.full_point_blend_weights.assign(static_cast<size_t>(N), alpha);
    }
    return out;
  }
  assert(static_cast<int>(region_errors.size()) == m.region_count);
  std::vector<double> region_alpha(static_cast<size_t>(m.region_count));
  for (int r = 0; r < m.region_count; ++r) {
    region_alpha[static_cast<size_t>(r)] = decide(region_errors[static_cast<size_t>(r)], region_thresholds(m, r)).alpha;
  }
  for (long i = 0; i < N; ++i) {
    double alpha = 0;
    for (int r = 0; r < m.region_count; ++r) {
      if (region_alpha[static_cast<size_t>(r)] > 0) alpha += membership(m, i, r) * region_alpha[static_cast<size_t>(r)];
    }
    // Weights summing to 1 within rounding must not make α exceed eq. 11's range.
    alpha = std::min(alpha, 1.0);
    if (alpha > 0) {
      out.full_points.push_back(static_cast<int>(i));
      out.full_point_blend_weights.push_back(alpha);
    }
  }
  return out;
}

Status check_covers(const LocalFailThrough& needed, const std::vector<int>& full_points) {
  assert(std::is_sorted(full_points.begin(), full_points.end()));
  auto given = full_points.begin();
  for (size_t j = 0; j < needed.full_points.size(); ++j) {
    const int point = needed.full_points[j];
    given = std::lower_bound(given, full_points.end(), point);
    if (given == full_points.end() || *given != point) {
      return make_error(ErrorCode::kInvalidArgument,
                        "point " + std::to_string(point) + " needs the full calculation (blend weight " +
                            format_number(needed.full_point_blend_weights[j]) + ") but is not among the " +
                            std::to_string(full_points.size()) + " points given");
    }
  }
  return Status::Ok();
}

void blend_partial(const PmscModel& m, const LocalFailThrough& local, const Eigen::Ref<const Eigen::VectorXf>& estimate,
                   const std::vector<int>& full_points, const Eigen::Ref<const Eigen::VectorXf>& full_values,
                   Eigen::Ref<Eigen::VectorXf> out) {
  const long D = m.channel_count;
  assert(estimate.size() == m.point_count * D && out.size() == estimate.size());
  assert(full_values.size() == static_cast<long>(full_points.size()) * D);
  assert(check_covers(local, full_points).ok());
  if (out.data() != estimate.data()) out = estimate;
  auto given = full_points.begin();
  for (size_t j = 0; j < local.full_points.size(); ++j) {
    const long i = local.full_points[j];
    given = std::lower_bound(given, full_points.end(), static_cast<int>(i));
    const long g = given - full_points.begin();
    const double alpha = local.full_point_blend_weights[j];
    if (alpha >= 1.0) {
      out.segment(i * D, D) = full_values.segment(g * D, D);  // eq. 9: f itself
    } else {
      blend(estimate.segment(i * D, D), full_values.segment(g * D, D), alpha, out.segment(i * D, D));
    }
  }
}

Status evaluate_cached_local(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                             const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                             const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local) {
  return evaluate_cached_local(m, key_values, Eigen::VectorXf(), full_points, full_values, full_calculation, out, local);
}

Status evaluate_cached_local(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                             const Eigen::Ref<const Eigen::VectorXf>& check_values,
                             const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                             const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local) {
  PoseEstimate estimate;
  estimate_coordinates(m, key_values, check_values, estimate);
  out.points.resize(m.mean.size());
  const PoseEstimate* input = &estimate;
  float* destination = out.points.data();
  reconstruct(m, {&input, 1}, {&destination, 1});
  return finish_cached_local(m, estimate, out.points, full_points, full_values, full_calculation, out, local);
}

Status finish_cached_local(const PmscModel& m, const PoseEstimate& estimate, Eigen::Ref<Eigen::VectorXf> points,
                           const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                           const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local) {
  assert(points.size() == m.mean.size());
  local = LocalFailThrough();
  // The whole-pose verdict first; a hit (or a cross-PMSC model, which has no f) is f̂.
  if (!judge(m, estimate, out)) return Status::Ok();
  local = local_fail_through(m, out.error_estimate, out.region_errors, out.checked);
  if (full_values != nullptr) {
    ANIMSPACE_RETURN_IF_ERROR(check_covers(local, full_points));
    blend_partial(m, local, points, full_points, *full_values, points);
  } else if (local.full_points.empty()) {
    // Every region within tolerance: f̂ is the answer.
  } else if (full_calculation && full_calculation(local.full_points, out.computed_full_values)) {
    assert(out.computed_full_values.size() == static_cast<long>(local.full_points.size()) * m.channel_count);
    blend_partial(m, local, points, local.full_points, out.computed_full_values, points);
  } else {
    out.computed_full_values.resize(0);
    out.full_evaluation_needed = true;
  }
  return Status::Ok();
}

bool regions_judged_alone(const PmscModel& m, bool checked) {
  return m.region_count > 0 && (checked || m.check_points.empty());
}

std::vector<CacheStatus> region_statuses(const PmscModel& m, const CachedPose& pose) {
  std::vector<CacheStatus> out(pose.region_errors.size(), pose.status);
  if (!regions_judged_alone(m, pose.checked)) return out;
  for (size_t r = 0; r < out.size(); ++r) {
    out[r] = decide(pose.region_errors[r], region_thresholds(m, static_cast<int>(r))).status;
  }
  return out;
}

Eigen::VectorXf complete_partial_frame(const PmscModel& m, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                       const std::vector<int>& full_points,
                                       const Eigen::Ref<const Eigen::VectorXf>& full_values) {
  const long D = m.channel_count;
  assert(!m.cross);
  assert(full_values.size() == static_cast<long>(full_points.size()) * D);
  PoseEstimate estimate;
  evaluate(m, key_values, estimate);
  Eigen::VectorXf frame = std::move(estimate.points);
  for (size_t k = 0; k < m.key_points.size(); ++k) {
    frame.segment(static_cast<long>(m.key_points[k]) * D, D) = key_values.segment(static_cast<long>(k) * D, D);
  }
  for (size_t j = 0; j < full_points.size(); ++j) {
    assert(full_points[j] >= 0 && full_points[j] < m.point_count);
    frame.segment(static_cast<long>(full_points[j]) * D, D) = full_values.segment(static_cast<long>(j) * D, D);
  }
  return frame;
}

}  // namespace animspace::pmsc
