// Tangent planes for animation-space normals: Merry 2007 §4.3.2 (eq. 4.8, from SSD normals) and
// §4.3.1 with Appendix A.1 (fitting a plane to the incident faces' planes).
#include "core/animspace/tangents.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "core/common/parallel.h"

namespace animspace::animation_space {
namespace {

// TangentFitOptions::weight_length_scale by default, as a fraction of the rest bounding-box
// diagonal. Measured on the cow rig (../shared/data/cow-rig, 16 bones, ~40 cm bones on a 268 cm
// diagonal), fitted normals against the area-weighted normals of its 7 posed meshes, 99.9th
// percentile / max angle: fraction 1: 7.5° / 39°; 1/3: 4.9° / 28°; 1/6: 3.9° / 19°;
// 1/10: 3.9° / 16°; 1/20: 3.9° / 14°; 1/50: 4.3° / 13° (eq. 4.8 from rest normals: 30° / 171°).
// The weight component multiplies a bone's translation, whose pose-to-pose change is on the
// order of a bone length, a tenth of the model or so.
constexpr double kDefaultWeightLengthFraction = 0.1;

// Vertices per thread below which threading does not pay (each fit is a small eigenproblem).
constexpr int64_t kVerticesPerThread = 512;

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

// Unit ŝ, t̂ with ŝ × t̂ = n̂ (n̂ unit): ŝ = normalise(n̂ × e) for the axis e least aligned with n̂.
void rest_tangents(const Eigen::Vector3d& normal, Eigen::Vector3d& s, Eigen::Vector3d& t) {
  Eigen::Index axis;
  normal.cwiseAbs().minCoeff(&axis);
  s = normal.cross(Eigen::Vector3d::Unit(axis)).normalized();
  t = normal.cross(s);
}

// Faces incident to each vertex, as compressed rows.
struct VertexFaces {
  std::vector<int32_t> offsets;
  std::vector<int32_t> faces;
};

VertexFaces vertex_faces(const FaceMatrix& F, int vertex_count) {
  VertexFaces result;
  result.offsets.assign(static_cast<size_t>(vertex_count) + 1, 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int c = 0; c < 3; ++c) ++result.offsets[static_cast<size_t>(F(f, c)) + 1];
  }
  for (size_t i = 1; i < result.offsets.size(); ++i) result.offsets[i] += result.offsets[i - 1];
  result.faces.resize(static_cast<size_t>(result.offsets.back()));
  std::vector<int32_t> next(result.offsets.begin(), result.offsets.end() - 1);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int c = 0; c < 3; ++c) result.faces[static_cast<size_t>(next[static_cast<size_t>(F(f, c))]++)] = static_cast<int32_t>(f);
  }
  return result;
}

// Per-thread scratch of fit_tangent_planes: slot[j] is bone j's position in the vertex's
// influence set, or -1.
struct FitScratch {
  std::vector<int> slot;
  std::vector<double> weights;     // w_k of the current vertex's influences
  TransformList rest_inverse;      // Ĝ_k⁻¹ of the current vertex's bones
  Eigen::VectorXd a, b;
  Eigen::MatrixXd A;
};

// Writes R_i(p_u), vertex u's position re-expressed on the bones of the current vertex i, into
// `out` (4k). A component on one of i's bones is kept; a component p_m on another bone m is the
// rest-pose point Ĝ_m p_m, carried instead the way vertex i itself moves: Σ_k w_k Ĝ_k⁻¹ Ĝ_m p_m
// over i's bones k with i's weights w_k = p̲_k. R_i is linear, is the identity on vectors on i's
// bones, and keeps both the rest-pose projection and the weight (Σ_k w_k = 1), so edge vectors
// stay weight-0 and project to the rest mesh's edges.
void reexpress_position(const AnimationSpaceModel& model, int u, const FitScratch& scratch, Eigen::VectorXd& out) {
  out.setZero();
  for (int k = model.influences.begin(u); k < model.influences.end(u); ++k) {
    const size_t bone = static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)]);
    const int local = scratch.slot[bone];
    if (local >= 0) {
      out.segment<4>(4 * local) += model.positions.col(k);
      continue;
    }
    const Eigen::Vector4d rest_point = model.skeleton.rest[bone] * model.positions.col(k);
    for (int j = 0; j < static_cast<int>(scratch.weights.size()); ++j) {
      out.segment<4>(4 * j) += scratch.weights[static_cast<size_t>(j)] * (scratch.rest_inverse[static_cast<size_t>(j)] * rest_point);
    }
  }
}

// Makes the weight components (every 4th) of `x` (k bones) sum to exactly 0 by subtracting
// their mean, against rounding.
void remove_weight(Eigen::VectorXd& x, int k) {
  double mean = 0;
  for (int j = 0; j < k; ++j) mean += x(4 * j + 3);
  mean /= k;
  for (int j = 0; j < k; ++j) x(4 * j + 3) -= mean;
}

}  // namespace

Eigen::MatrixX3d rest_positions(const AnimationSpaceModel& model) {
  Eigen::MatrixX3d rest(model.vertex_count(), 3);
  for (int i = 0; i < model.vertex_count(); ++i) {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      v += model.skeleton.rest[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] * model.positions.col(k);
    }
    rest.row(i) = v.head<3>().transpose();
  }
  return rest;
}

Result<TangentPlanes> tangent_planes_from_normals(const AnimationSpaceModel& model, const Eigen::MatrixX3d& rest_normals) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  if (rest_normals.rows() != model.vertex_count()) {
    return invalid("rest normals: expected " + std::to_string(model.vertex_count()) + " rows (one per vertex), got " +
                   std::to_string(rest_normals.rows()));
  }
  TransformList rest_inverse(model.skeleton.rest.size());
  for (size_t j = 0; j < rest_inverse.size(); ++j) rest_inverse[j] = affine_inverse(model.skeleton.rest[j]);
  TangentPlanes planes;
  planes.s = InfluenceVectors::Zero(4, model.influences.influence_count());
  planes.t = InfluenceVectors::Zero(4, model.influences.influence_count());
  for (int i = 0; i < model.vertex_count(); ++i) {
    const Eigen::Vector3d normal = rest_normals.row(i).transpose();
    if (!normal.allFinite()) return invalid("rest normal of vertex " + std::to_string(i) + " is not finite");
    const double length = normal.norm();
    if (length == 0) {
      ++planes.degenerate_vertices;
      continue;
    }
    Eigen::Vector3d s_hat, t_hat;
    rest_tangents(normal / length, s_hat, t_hat);
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      // Eq. 4.8: q_j = w_j Ĝ_j⁻¹ ŝ; ŝ is a vector (fourth component 0), so q_j has weight 0.
      const double w = model.positions(3, k);
      const auto& inverse = rest_inverse[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])];
      planes.s.col(k).head<3>() = w * (inverse.topLeftCorner<3, 3>() * s_hat);
      planes.t.col(k).head<3>() = w * (inverse.topLeftCorner<3, 3>() * t_hat);
    }
  }
  return planes;
}

Result<TangentPlanes> fit_tangent_planes(const AnimationSpaceModel& model, const TangentFitOptions& options) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  if (model.faces.rows() == 0) {
    return invalid("model has no faces; tangent planes are fitted to the faces around each vertex (Merry 2007 §4.3.1)");
  }
  double length_scale = options.weight_length_scale;
  if (!(length_scale > 0)) {
    const Eigen::MatrixX3d rest = rest_positions(model);
    length_scale = kDefaultWeightLengthFraction * (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).norm();
    if (!(length_scale > 0)) length_scale = 1;  // all vertices coincide: every plane is degenerate anyway
  }
  const VertexFaces incident = vertex_faces(model.faces, model.vertex_count());
  TransformList rest_inverse(model.skeleton.rest.size());
  for (size_t j = 0; j < rest_inverse.size(); ++j) rest_inverse[j] = affine_inverse(model.skeleton.rest[j]);

  TangentPlanes planes;
  planes.s = InfluenceVectors::Zero(4, model.influences.influence_count());
  planes.t = InfluenceVectors::Zero(4, model.influences.influence_count());
  std::vector<int64_t> degenerate(static_cast<size_t>(model.vertex_count()), 0);
  parallel_for_chunks(model.vertex_count(), kVerticesPerThread, [&](int64_t first, int64_t last) {
    FitScratch scratch;
    scratch.slot.assign(static_cast<size_t>(model.bone_count()), -1);
    Eigen::VectorXd p_i, p_u, p_w;
    for (int64_t vertex = first; vertex < last; ++vertex) {
      const int i = static_cast<int>(vertex);
      const int begin = model.influences.begin(i), k = model.influences.end(i) - begin, n = 4 * k;
      scratch.weights.resize(static_cast<size_t>(k));
      scratch.rest_inverse.resize(static_cast<size_t>(k));
      for (int local = 0; local < k; ++local) {
        const size_t bone = static_cast<size_t>(model.influences.bones[static_cast<size_t>(begin + local)]);
        scratch.slot[bone] = local;
        scratch.weights[static_cast<size_t>(local)] = model.positions(3, begin + local);
        scratch.rest_inverse[static_cast<size_t>(local)] = rest_inverse[bone];
      }
      p_i.resize(n), p_u.resize(n), p_w.resize(n);
      scratch.A.setZero(n, n);
      reexpress_position(model, i, scratch, p_i);
      double input_scale = 0;
      for (int32_t at = incident.offsets[static_cast<size_t>(i)]; at < incident.offsets[static_cast<size_t>(i) + 1]; ++at) {
        const auto face = model.faces.row(incident.faces[static_cast<size_t>(at)]);
        const int corner = face(0) == i ? 0 : face(1) == i ? 1 : 2;
        // A.1: the face's plane B_f = (p_u − p_i) ∧ (p_w − p_i), corners in the face's order.
        reexpress_position(model, face((corner + 1) % 3), scratch, p_u);
        reexpress_position(model, face((corner + 2) % 3), scratch, p_w);
        scratch.a = p_u - p_i;
        scratch.b = p_w - p_i;
        for (int j = 0; j < k; ++j) {  // into the normalised space of the fitting metric (A.1.2's C)
          scratch.a(4 * j + 3) *= length_scale;
          scratch.b(4 * j + 3) *= length_scale;
        }
        scratch.A.noalias() += scratch.a * scratch.b.transpose() - scratch.b * scratch.a.transpose();
        input_scale += scratch.a.norm() * scratch.b.norm();
      }
      for (int local = 0; local < k; ++local) {
        scratch.slot[static_cast<size_t>(model.influences.bones[static_cast<size_t>(begin + local)])] = -1;
      }
      // The top singular pair of the antisymmetric A: its singular values come in equal pairs,
      // and the right singular vectors of the largest span the fitted plane. AᵀA is symmetric,
      // so its top eigenvector b is one; a = A b / σ completes it with aᵀ A b = σ > 0 and a ⟂ b.
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(scratch.A.transpose() * scratch.A);
      const double sigma = std::sqrt(std::max(0.0, solver.eigenvalues()(n - 1)));
      if (!(sigma > 1e-12 * input_scale) || !std::isfinite(sigma)) {
        degenerate[static_cast<size_t>(i)] = 1;
        continue;
      }
      Eigen::VectorXd b = solver.eigenvectors().col(n - 1);
      Eigen::VectorXd a = scratch.A * b / sigma;
      a -= a.dot(b) * b;  // exact orthogonality against rounding
      a.normalize();
      for (int j = 0; j < k; ++j) {  // back from the normalised space
        a(4 * j + 3) /= length_scale;
        b(4 * j + 3) /= length_scale;
      }
      remove_weight(a, k);  // 0 up to rounding: the plane avoids A's null space (A.1.2)
      remove_weight(b, k);
      for (int local = 0; local < k; ++local) {
        planes.s.col(begin + local) = a.segment<4>(4 * local);
        planes.t.col(begin + local) = b.segment<4>(4 * local);
      }
    }
  });
  for (const int64_t d : degenerate) planes.degenerate_vertices += d;
  return planes;
}

}  // namespace animspace::animation_space
