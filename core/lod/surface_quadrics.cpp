#include "core/lod/surface_quadrics.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <utility>

namespace animspace::lod {

SurfaceQuadrics::SurfaceQuadrics(const Eigen::MatrixXd& Y, const FaceMatrix& faces) {
  const Eigen::Index n = Y.rows();
  const auto V = static_cast<size_t>(Y.cols());
  planes_.resize(V);
  weights_.assign(V, 0.0);

  // Undirected edges with the faces using them: an edge of one face is on the boundary.
  std::vector<std::pair<std::pair<int32_t, int32_t>, int32_t>> edges;
  edges.reserve(static_cast<size_t>(3 * faces.rows()));
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = faces(f, k), b = faces(f, (k + 1) % 3);
      assert(a >= 0 && static_cast<size_t>(a) < V && b >= 0 && static_cast<size_t>(b) < V);
      edges.push_back({{std::min(a, b), std::max(a, b)}, static_cast<int32_t>(f)});
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<std::pair<int32_t, int32_t>> boundary;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    if (j - i == 1) boundary.push_back(edges[i].first);
    i = j;
  }

  const Eigen::Index count = faces.rows() + static_cast<Eigen::Index>(boundary.size());
  origin_.resize(n, count);
  e1_.resize(n, count);
  e2_.resize(n, count);
  plane_weight_.reserve(static_cast<size_t>(count));
  Eigen::Index next = 0;
  const auto add = [&](const std::vector<int32_t>& corners, double weight, const Eigen::VectorXd& a,
                       const Eigen::VectorXd& e1, const Eigen::VectorXd& e2) {
    origin_.col(next) = a;
    e1_.col(next) = e1;
    e2_.col(next) = e2;
    plane_weight_.push_back(weight);
    for (const int32_t v : corners) {
      planes_[static_cast<size_t>(v)].push_back(static_cast<int32_t>(next));
      weights_[static_cast<size_t>(v)] += weight;
    }
    ++next;
  };

  Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::VectorXd a = Y.col(faces(f, 0));
    const Eigen::VectorXd ab = Y.col(faces(f, 1)) - a;
    const Eigen::VectorXd ac = Y.col(faces(f, 2)) - a;
    // Gram–Schmidt; the area is ½|ab||ac_⊥|.
    const double length = ab.norm();
    if (!(length > 0)) continue;
    const Eigen::VectorXd e1 = ab / length;
    const Eigen::VectorXd perpendicular = ac - e1.dot(ac) * e1;
    const double height = perpendicular.norm();
    if (!(height > 1e-12 * std::max(length, ac.norm()))) continue;  // degenerate: no plane
    add({faces(f, 0), faces(f, 1), faces(f, 2)}, 0.5 * length * height, a, e1, perpendicular / height);
  }
  for (const auto& [a, b] : boundary) {
    const Eigen::VectorXd edge = Y.col(b) - Y.col(a);
    const double length = edge.norm();
    if (!(length > 0)) continue;
    add({a, b}, length * length, Y.col(a), edge / length, zero);
  }
  origin_.conservativeResize(n, next);
  e1_.conservativeResize(n, next);
  e2_.conservativeResize(n, next);
}

double SurfaceQuadrics::error(int v, const Eigen::Ref<const Eigen::VectorXd>& y) const {
  double sum = 0;
  for (const int32_t p : planes_[static_cast<size_t>(v)]) {
    const auto d = y - origin_.col(p);
    const double s1 = e1_.col(p).dot(d);
    const double s2 = e2_.col(p).dot(d);
    // ‖d‖² − s₁² − s₂² is the squared length of d's part off the plane; computed as such it can
    // round below zero when y lies on the plane.
    sum += plane_weight_[static_cast<size_t>(p)] * std::max(0.0, d.squaredNorm() - s1 * s1 - s2 * s2);
  }
  return sum;
}

void SurfaceQuadrics::merge(int from, int into) {
  assert(from != into);
  std::vector<int32_t>& source = planes_[static_cast<size_t>(from)];
  std::vector<int32_t>& target = planes_[static_cast<size_t>(into)];
  target.insert(target.end(), source.begin(), source.end());
  weights_[static_cast<size_t>(into)] += weights_[static_cast<size_t>(from)];
  source.clear();
  source.shrink_to_fit();
  weights_[static_cast<size_t>(from)] = 0;
}

}  // namespace animspace::lod
