#include "core/animspace/skinning_weights.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numeric>

#include <Eigen/Dense>

#include "core/common/parallel.h"

namespace animspace::animation_space {
namespace {

// Solves the equality-constrained problem on the free set F: min ½ zᵀ Q_FF z − c_Fᵀ z with
// Σ z = 1, through its KKT system [Q_FF 1; 1ᵀ 0] [z; ν] = [c_F; 1]. A complete orthogonal
// decomposition gives the minimum-norm solution when Q_FF is singular (bones moving alike share
// the weight instead of the solve failing). Returns z and sets ν.
Eigen::VectorXd solve_on_free_set(const Eigen::MatrixXd& Q, const Eigen::VectorXd& c, const std::vector<int>& free,
                                  double* nu) {
  const int m = static_cast<int>(free.size());
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(m + 1, m + 1);
  Eigen::VectorXd rhs(m + 1);
  for (int a = 0; a < m; ++a) {
    for (int b = 0; b < m; ++b) K(a, b) = Q(free[static_cast<size_t>(a)], free[static_cast<size_t>(b)]);
    K(a, m) = K(m, a) = 1;
    rhs(a) = c(free[static_cast<size_t>(a)]);
  }
  rhs(m) = 1;
  const Eigen::VectorXd solution = K.completeOrthogonalDecomposition().solve(rhs);
  *nu = solution(m);
  return solution.head(m);
}

}  // namespace

Eigen::VectorXd solve_simplex_qp(const Eigen::MatrixXd& Q, const Eigen::VectorXd& c) {
  const int n = static_cast<int>(c.size());
  assert(n >= 1 && Q.rows() == n && Q.cols() == n);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(n);
  // Start at the best corner e_j (objective ½ Q_jj − c_j): feasible, one free variable.
  int start = 0;
  for (int j = 1; j < n; ++j) {
    if (0.5 * Q(j, j) - c(j) < 0.5 * Q(start, start) - c(start)) start = j;
  }
  w(start) = 1;
  std::vector<int> free{start};
  // Multipliers below −tolerance mean the objective still falls along that bone.
  const double tolerance = 1e-12 * (Q.diagonal().cwiseAbs().maxCoeff() + c.cwiseAbs().maxCoeff() + 1e-300);
  for (int step = 0; step < 10 * n + 20; ++step) {
    double nu = 0;
    const Eigen::VectorXd z = solve_on_free_set(Q, c, free, &nu);
    // Step from w towards z until the first free weight reaches 0 (blocking constraint).
    double alpha = 1;
    int blocking = -1;
    for (size_t a = 0; a < free.size(); ++a) {
      const double from = w(free[a]), to = z(static_cast<Eigen::Index>(a));
      if (to < 0 && from - to > 0 && from / (from - to) < alpha) {
        alpha = from / (from - to);
        blocking = static_cast<int>(a);
      }
    }
    for (size_t a = 0; a < free.size(); ++a) w(free[a]) += alpha * (z(static_cast<Eigen::Index>(a)) - w(free[a]));
    if (blocking >= 0) {
      w(free[static_cast<size_t>(blocking)]) = 0;
      free.erase(free.begin() + blocking);
      continue;
    }
    // At the minimiser on the free set: with Q w − c + ν 1 − λ = 0, a bound bone with λ_j < 0
    // would lower the objective if freed; free the most negative one.
    const Eigen::VectorXd gradient = Q * w - c;
    int entering = -1;
    double most_negative = -tolerance;
    for (int j = 0; j < n; ++j) {
      if (std::find(free.begin(), free.end(), j) != free.end()) continue;
      const double lambda = gradient(j) + nu;
      if (lambda < most_negative) {
        most_negative = lambda;
        entering = j;
      }
    }
    if (entering < 0) break;
    free.push_back(entering);
  }
  // Rounding can leave −1e-17 or a sum of 1 ± ulp; the simplex is the contract.
  w = w.cwiseMax(0.0);
  return w / w.sum();
}

SkinningWeights solve_skinning_weights(const Eigen::Matrix3Xd& rest, const std::vector<Eigen::Matrix3Xd>& frames,
                                       const std::vector<TransformList>& motions, const InfluenceSets& candidates,
                                       const SkinningWeights& previous, const geometry::Adjacency& neighbours,
                                       double scale, const WeightSolveOptions& options) {
  const int vertices = static_cast<int>(rest.cols());
  const int frame_count = static_cast<int>(frames.size());
  const double data_scale = 1.0 / (static_cast<double>(frame_count) * scale * scale);
  const double mu = options.smoothness;
  std::vector<std::vector<std::pair<int32_t, double>>> solved(static_cast<size_t>(vertices));

  parallel_for_chunks(vertices, 64, [&](int64_t begin, int64_t end) {
    Eigen::MatrixXd A;
    for (int i = static_cast<int>(begin); i < static_cast<int>(end); ++i) {
      std::vector<int32_t> bones(candidates.bones.begin() + candidates.begin(i), candidates.bones.begin() + candidates.end(i));
      auto& out = solved[static_cast<size_t>(i)];
      if (bones.empty()) {
        for (int k = previous.influences.begin(i); k < previous.influences.end(i); ++k) {
          out.emplace_back(previous.influences.bones[static_cast<size_t>(k)], previous.weights(k));
        }
        continue;
      }
      const int n = static_cast<int>(bones.size());
      Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(n, n);
      Eigen::VectorXd c = Eigen::VectorXd::Zero(n);
      A.resize(3, n);
      const Eigen::Vector4d point(rest(0, i), rest(1, i), rest(2, i), 1.0);
      for (int f = 0; f < frame_count; ++f) {
        const TransformList& M = motions[static_cast<size_t>(f)];
        for (int a = 0; a < n; ++a) A.col(a) = M[static_cast<size_t>(bones[static_cast<size_t>(a)])].topRows<3>() * point;
        Q.noalias() += A.transpose() * A;
        c.noalias() += A.transpose() * frames[static_cast<size_t>(f)].col(i);
      }
      Q *= data_scale;
      c *= data_scale;
      // w̄: the neighbours' current weights on these bones, averaged.
      if (mu > 0) {
        Eigen::VectorXd mean = Eigen::VectorXd::Zero(n);
        const int degree = neighbours.end(i) - neighbours.begin(i);
        for (int e = neighbours.begin(i); e < neighbours.end(i); ++e) {
          const int other = neighbours.at(e);
          for (int k = previous.influences.begin(other); k < previous.influences.end(other); ++k) {
            const auto found = std::find(bones.begin(), bones.end(), previous.influences.bones[static_cast<size_t>(k)]);
            if (found != bones.end()) mean(found - bones.begin()) += previous.weights(k);
          }
        }
        if (degree > 0) {
          Q.diagonal().array() += mu;
          c += mu * mean / degree;
        }
      }
      Eigen::VectorXd w = solve_simplex_qp(Q, c);
      // SSDR's sparsity: the K largest weights, solved again on their own.
      std::vector<int> order(static_cast<size_t>(n));
      std::iota(order.begin(), order.end(), 0);
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return w(a) > w(b); });
      int kept = 0;
      while (kept < n && kept < options.max_influences && w(order[static_cast<size_t>(kept)]) > 0) ++kept;
      order.resize(static_cast<size_t>(kept));
      if (kept < static_cast<int>((w.array() > 0).count())) {
        Eigen::MatrixXd Qs(kept, kept);
        Eigen::VectorXd cs(kept);
        for (int a = 0; a < kept; ++a) {
          cs(a) = c(order[static_cast<size_t>(a)]);
          for (int b = 0; b < kept; ++b) Qs(a, b) = Q(order[static_cast<size_t>(a)], order[static_cast<size_t>(b)]);
        }
        const Eigen::VectorXd ws = solve_simplex_qp(Qs, cs);
        w.setZero();
        for (int a = 0; a < kept; ++a) w(order[static_cast<size_t>(a)]) = ws(a);
      }
      for (int a = 0; a < n; ++a) {
        if (w(a) > 0) out.emplace_back(bones[static_cast<size_t>(a)], w(a));
      }
      std::sort(out.begin(), out.end());
    }
  });

  SkinningWeights result;
  result.influences.offsets.reserve(static_cast<size_t>(vertices) + 1);
  std::vector<double> weights;
  for (const auto& vertex : solved) {
    for (const auto& [bone, weight] : vertex) {
      result.influences.bones.push_back(bone);
      weights.push_back(weight);
    }
    result.influences.offsets.push_back(static_cast<int32_t>(result.influences.bones.size()));
  }
  result.weights = Eigen::Map<const Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  return result;
}

}  // namespace animspace::animation_space
