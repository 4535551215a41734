#include "core/atlas/stretch.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

namespace animspace::atlas {

FaceMetrics face_metrics(const PointMatrix& points, const FaceMatrix& faces) {
  FaceMetrics g(faces.rows(), 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3d x0 = points.row(faces(f, 0)).cast<double>().transpose();
    const Eigen::Vector3d e1 = points.row(faces(f, 1)).cast<double>().transpose() - x0;
    const Eigen::Vector3d e2 = points.row(faces(f, 2)).cast<double>().transpose() - x0;
    g.row(f) << e1.squaredNorm(), e1.dot(e2), e2.squaredNorm();
  }
  return g;
}

TriangleStretch triangle_stretch(double g11, double g12, double g22, const Eigen::Vector2d& u0,
                                 const Eigen::Vector2d& u1, const Eigen::Vector2d& u2) {
  TriangleStretch s;
  s.surface_area = 0.5 * std::sqrt(std::max(0.0, g11 * g22 - g12 * g12));
  const Eigen::Vector2d a = u1 - u0, b = u2 - u0;
  const double det = a.x() * b.y() - a.y() * b.x();
  s.uv_area = 0.5 * det;
  if (!(det > 0)) {
    s.l2_squared = s.linf_squared = std::numeric_limits<double>::infinity();
    return s;
  }
  // D = U⁻¹ with U = [a b]; JᵀJ = Dᵀ g D.
  const double d00 = b.y() / det, d01 = -b.x() / det, d10 = -a.y() / det, d11 = a.x() / det;
  const double m00 = d00 * (g11 * d00 + g12 * d10) + d10 * (g12 * d00 + g22 * d10);
  const double m01 = d00 * (g11 * d01 + g12 * d11) + d10 * (g12 * d01 + g22 * d11);
  const double m11 = d01 * (g11 * d01 + g12 * d11) + d11 * (g12 * d01 + g22 * d11);
  const double half_trace = 0.5 * (m00 + m11);
  s.l2_squared = half_trace;
  s.linf_squared = half_trace + std::sqrt(0.25 * (m00 - m11) * (m00 - m11) + m01 * m01);
  return s;
}

namespace {

struct Sums {
  double surface = 0, uv = 0, weighted_l2 = 0, worst_linf = 0;
  int64_t flipped = 0;
};

Sums sum_stretch(const FaceMetrics& g, const CornerUvs& uvs) {
  assert(uvs.rows() == 3 * g.rows());
  Sums s;
  for (Eigen::Index f = 0; f < g.rows(); ++f) {
    const TriangleStretch t = triangle_stretch(g(f, 0), g(f, 1), g(f, 2), uvs.row(3 * f).transpose(),
                                               uvs.row(3 * f + 1).transpose(), uvs.row(3 * f + 2).transpose());
    if (!(t.uv_area > 0)) {
      ++s.flipped;
      continue;
    }
    s.surface += t.surface_area;
    s.uv += t.uv_area;
    s.weighted_l2 += t.surface_area * t.l2_squared;
    s.worst_linf = std::max(s.worst_linf, t.linf_squared);
  }
  return s;
}

}  // namespace

Stretch stretch(const FaceMetrics& metrics, const CornerUvs& uvs) {
  const Sums s = sum_stretch(metrics, uvs);
  Stretch out;
  out.flipped = s.flipped;
  if (s.surface > 0) {
    const double scale = s.uv / s.surface;  // Sander 2001: the UV area normalised to the surface's
    out.l2 = std::sqrt(s.weighted_l2 / s.surface * scale);
    out.linf = std::sqrt(s.worst_linf * scale);
  }
  return out;
}

Stretch stretch_across_poses(const std::vector<PointMatrix>& posed, const FaceMatrix& faces, const CornerUvs& uvs) {
  assert(!posed.empty());
  Stretch out;
  double mean_l2_squared = 0;
  for (const PointMatrix& points : posed) {
    const Stretch pose = stretch(face_metrics(points, faces), uvs);
    mean_l2_squared += pose.l2 * pose.l2 / static_cast<double>(posed.size());
    out.linf = std::max(out.linf, pose.linf);
    out.flipped = pose.flipped;  // the same UVs in every pose
  }
  out.l2 = std::sqrt(mean_l2_squared);
  return out;
}

}  // namespace animspace::atlas
