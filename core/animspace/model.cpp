#include "core/animspace/model.h"

#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include "core/common/parallel.h"

namespace animspace::animation_space {
namespace {

// Influences per thread below which threading does not pay for the thread start-up.
constexpr int64_t kInfluencesPerThread = 32768;

Error vertex_error(int vertex, const std::string& problem) {
  return make_error(ErrorCode::kInvalidArgument, "vertex " + std::to_string(vertex) + ": " + problem);
}

// Calls body(vertex_begin, vertex_end) over chunks of roughly equal influence counts.
template <typename Body>
void for_vertex_chunks(const InfluenceSets& influences, Body&& body) {
  const int64_t vertices = influences.vertex_count();
  const int64_t average = std::max<int64_t>(1, influences.influence_count() / std::max<int64_t>(1, vertices));
  parallel_for_chunks(vertices, kInfluencesPerThread / average, body);
}

Status check_vectors(const InfluenceVectors& vectors, const InfluenceSets& influences, const char* what) {
  if (vectors.cols() != influences.influence_count()) {
    return make_error(ErrorCode::kInvalidArgument, std::string(what) + " has " + std::to_string(vectors.cols()) +
                                                       " columns, expected one per influence (" +
                                                       std::to_string(influences.influence_count()) + ")");
  }
  for (int i = 0; i < influences.vertex_count(); ++i) {
    for (int k = influences.begin(i); k < influences.end(i); ++k) {
      if (!vectors.col(k).allFinite()) return vertex_error(i, std::string(what) + " has a NaN or infinite entry");
    }
  }
  return Status::Ok();
}

}  // namespace

Status validate(const InfluenceSets& influences, int bone_count) {
  if (influences.offsets.empty() || influences.offsets.front() != 0) {
    return make_error(ErrorCode::kInvalidArgument, "influence offsets must start with 0");
  }
  if (influences.offsets.back() != influences.influence_count()) {
    return make_error(ErrorCode::kInvalidArgument,
                      "influence offsets end at " + std::to_string(influences.offsets.back()) + ", expected " +
                          std::to_string(influences.influence_count()) + " (the number of influences)");
  }
  for (int i = 0; i < influences.vertex_count(); ++i) {
    if (influences.end(i) <= influences.begin(i)) return vertex_error(i, "has no influencing bone");
    // Only the last offset was compared with the count above: a middle one past it would send
    // the loop below beyond `bones` (found by fuzzing a stored model's offsets).
    if (influences.end(i) > influences.influence_count()) {
      return vertex_error(i, "influence offset " + std::to_string(influences.end(i)) + " is past the " +
                                 std::to_string(influences.influence_count()) + " influences");
    }
    for (int k = influences.begin(i); k < influences.end(i); ++k) {
      const int bone = influences.bones[static_cast<size_t>(k)];
      if (bone < 0 || bone >= bone_count) {
        return vertex_error(i, "influence bone " + std::to_string(bone) + " is outside 0 … " +
                                   std::to_string(bone_count - 1));
      }
      if (k > influences.begin(i) && bone <= influences.bones[static_cast<size_t>(k) - 1]) {
        return vertex_error(i, "influence bones must be strictly increasing");
      }
    }
  }
  return Status::Ok();
}

Status validate(const AnimationSpaceModel& model, double weight_tolerance) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model.skeleton));
  ANIMSPACE_RETURN_IF_ERROR(validate(model.influences, model.bone_count()));
  ANIMSPACE_RETURN_IF_ERROR(check_vectors(model.positions, model.influences, "positions"));
  const Eigen::VectorXd weights = vertex_weights(model);
  for (int i = 0; i < model.vertex_count(); ++i) {
    if (std::abs(weights(i) - 1.0) > weight_tolerance) {
      return vertex_error(i, "weight p̲ is " + std::to_string(weights(i)) + ", expected 1 (Merry 2007 §3.1)");
    }
  }
  if (model.tangent_s.cols() != model.tangent_t.cols()) {
    return make_error(ErrorCode::kInvalidArgument, "tangent planes need both s and t, or neither");
  }
  if (model.has_tangents()) {
    ANIMSPACE_RETURN_IF_ERROR(check_vectors(model.tangent_s, model.influences, "tangent s"));
    ANIMSPACE_RETURN_IF_ERROR(check_vectors(model.tangent_t, model.influences, "tangent t"));
    for (int i = 0; i < model.vertex_count(); ++i) {
      double weight_s = 0, weight_t = 0;
      for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
        weight_s += model.tangent_s(3, k);
        weight_t += model.tangent_t(3, k);
      }
      if (std::abs(weight_s) > weight_tolerance || std::abs(weight_t) > weight_tolerance) {
        return vertex_error(i, "tangent vectors must have weight 0");
      }
    }
  }
  for (Eigen::Index f = 0; f < model.faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int index = model.faces(f, c);
      if (index < 0 || index >= model.vertex_count()) {
        return make_error(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + " indexes vertex " +
                                                           std::to_string(index) + ", expected 0 … " +
                                                           std::to_string(model.vertex_count() - 1));
      }
    }
  }
  return Status::Ok();
}

Eigen::VectorXd vertex_weights(const AnimationSpaceModel& model) {
  Eigen::VectorXd weights(model.vertex_count());
  for (int i = 0; i < model.vertex_count(); ++i) {
    double sum = 0;
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) sum += model.positions(3, k);
    weights(i) = sum;
  }
  return weights;
}

Eigen::VectorXd dense_position(const AnimationSpaceModel& model, int vertex) {
  Eigen::VectorXd p = Eigen::VectorXd::Zero(4L * model.bone_count());
  for (int k = model.influences.begin(vertex); k < model.influences.end(vertex); ++k) {
    p.segment<4>(4L * model.influences.bones[static_cast<size_t>(k)]) = model.positions.col(k);
  }
  return p;
}

PoseMatrices pose_matrices(const TransformList& globals) {
  PoseMatrices matrices(globals.size());
  for (size_t j = 0; j < globals.size(); ++j) matrices[j] = globals[j];
  return matrices;
}

namespace {

// v_i = Σ_j G_j p_j over vertex i's influences (eq. 3.1).
Eigen::Vector3f pose_vertex(const AnimationSpaceModel& model, const PoseMatrices& G, int64_t i) {
  const int32_t* bones = model.influences.bones.data();
  const double* p = model.positions.data();
  Eigen::Vector4d v = Eigen::Vector4d::Zero();
  for (int k = model.influences.offsets[static_cast<size_t>(i)]; k < model.influences.offsets[static_cast<size_t>(i) + 1]; ++k) {
    v.noalias() += G[static_cast<size_t>(bones[k])] * Eigen::Map<const Eigen::Vector4d, Eigen::Aligned16>(p + 4L * k);
  }
  return v.head<3>().cast<float>();
}

}  // namespace

void evaluate(const AnimationSpaceModel& model, const TransformList& globals, PointMatrix& out) {
  assert(static_cast<int>(globals.size()) == model.bone_count());
  const PoseMatrices G = pose_matrices(globals);
  out.resize(model.vertex_count(), 3);
  for_vertex_chunks(model.influences, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) out.row(i) = pose_vertex(model, G, i).transpose();
  });
}

void evaluate_vertices(const AnimationSpaceModel& model, const TransformList& globals,
                       const std::vector<int>& vertices, PointMatrix& out) {
  assert(static_cast<int>(globals.size()) == model.bone_count());
  const PoseMatrices G = pose_matrices(globals);
  out.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (size_t j = 0; j < vertices.size(); ++j) {
    assert(vertices[j] >= 0 && vertices[j] < model.vertex_count());
    out.row(static_cast<Eigen::Index>(j)) = pose_vertex(model, G, vertices[j]).transpose();
  }
}

void evaluate_normals(const AnimationSpaceModel& model, const TransformList& globals, PointMatrix& out) {
  assert(model.has_tangents());
  assert(static_cast<int>(globals.size()) == model.bone_count());
  const PoseMatrices G = pose_matrices(globals);
  out.resize(model.vertex_count(), 3);
  for_vertex_chunks(model.influences, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) {
      Eigen::Vector4d s = Eigen::Vector4d::Zero(), t = Eigen::Vector4d::Zero();
      for (int k = model.influences.offsets[static_cast<size_t>(i)]; k < model.influences.offsets[static_cast<size_t>(i) + 1]; ++k) {
        const auto& Gj = G[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])];
        s.noalias() += Gj * model.tangent_s.col(k);
        t.noalias() += Gj * model.tangent_t.col(k);
      }
      const Eigen::Vector3d n = s.head<3>().cross(t.head<3>());
      const double length = n.norm();
      out.row(i) = (length > 0 ? Eigen::Vector3d(n / length) : Eigen::Vector3d::Zero()).cast<float>().transpose();
    }
  });
}

Status validate(const LinearBlendModel& model) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model.skeleton));
  ANIMSPACE_RETURN_IF_ERROR(validate(model.influences, model.skeleton.bone_count()));
  if (model.rest_points.cols() != model.vertex_count()) {
    return make_error(ErrorCode::kInvalidArgument, "rest points: expected " + std::to_string(model.vertex_count()) +
                                                       " columns, got " + std::to_string(model.rest_points.cols()));
  }
  if (model.weights.size() != model.influences.influence_count()) {
    return make_error(ErrorCode::kInvalidArgument, "weights: expected one per influence (" +
                                                       std::to_string(model.influences.influence_count()) + "), got " +
                                                       std::to_string(model.weights.size()));
  }
  for (int i = 0; i < model.vertex_count(); ++i) {
    if (!model.rest_points.col(i).allFinite()) return vertex_error(i, "rest point has a NaN or infinite entry");
    double sum = 0;
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      if (!std::isfinite(model.weights(k))) return vertex_error(i, "weight is NaN or infinite");
      sum += model.weights(k);
    }
    if (std::abs(sum - 1.0) > 1e-6) return vertex_error(i, "weights sum to " + std::to_string(sum) + ", expected 1");
  }
  return Status::Ok();
}

void evaluate(const LinearBlendModel& model, const TransformList& globals, PointMatrix& out) {
  assert(globals.size() == model.skeleton.rest.size());
  TransformList skinning(globals.size());
  for (size_t j = 0; j < globals.size(); ++j) skinning[j] = globals[j] * affine_inverse(model.skeleton.rest[j]);
  const PoseMatrices M = pose_matrices(skinning);
  out.resize(model.vertex_count(), 3);
  const int32_t* bones = model.influences.bones.data();
  for_vertex_chunks(model.influences, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) {
      const Eigen::Vector4d rest = model.rest_points.col(i).homogeneous();
      Eigen::Vector4d v = Eigen::Vector4d::Zero();
      for (int k = model.influences.offsets[static_cast<size_t>(i)]; k < model.influences.offsets[static_cast<size_t>(i) + 1]; ++k) {
        v.noalias() += model.weights(k) * (M[static_cast<size_t>(bones[k])] * rest);
      }
      out.row(i) = v.head<3>().cast<float>().transpose();
    }
  });
}

}  // namespace animspace::animation_space
