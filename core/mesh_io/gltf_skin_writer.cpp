// A skinned, animated character as glTF 2.0. Section numbers are those of the Khronos "glTF 2.0
// Specification" (2.0.1): §3.5 Scenes and nodes, §3.6 buffers and accessors, §3.7.2 meshes,
// §3.7.3 skins, §3.11 animations, Appendix C interpolation.
//
// The pipeline: validate everything (the file must pose exactly as the caller's transforms do,
// so nothing is repaired), then lay out the one buffer (mesh, skin attributes, inverse binds,
// animation) and the nodes, then serialise through tinygltf (gltf_writing.h, shared with
// posed_mesh.cpp).
#include "core/mesh_io/gltf_skin_writer.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <exception>
#include <limits>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>

#include "core/common/atomic_file.h"
#include "core/common/format.h"
#include "core/geometry/normals.h"
#include "core/mesh_io/gltf_writing.h"
#include "core/mesh_io/text_io.h"

namespace animspace::mesh_io {
namespace {

// JOINTS_n are written as UNSIGNED_SHORT, the widest component type §3.7.3.3 allows.
constexpr int64_t kMaxJoints = 65536;
// How far from orthonormal a rotation block may be (largest entry of RᵀR − I), and how far a
// vertex's weights may sum from 1: both well above double rounding of data that was computed in
// float, well below anything a renderer would show.
constexpr double kRigidTolerance = 1e-6;
constexpr double kWeightSumTolerance = 1e-6;
// Normals the caller gives must be unit (§3.7.2.1 NORMAL: "unit XYZ vertex normals"), allowing
// for float rounding and normalisation in single precision.
constexpr double kUnitNormalTolerance = 1e-3;

Error invalid(const std::string& destination, const std::string& message) {
  return make_error(ErrorCode::kInvalidArgument, destination + ": " + message);
}

std::string row_text(const Eigen::RowVector4d& row) {
  return format_number(row(0)) + " " + format_number(row(1)) + " " + format_number(row(2)) + " " +
         format_number(row(3));
}

// Empty when `transform` is rigid (finite, last row exactly 0 0 0 1, RᵀR ≈ I, det R > 0), else
// the reason, to follow the field's name. Rigid is what glTF can carry without scale: a node's
// TRS with scale 1 (§3.5.3), and what keeps the inverse bind matrix exact as Rᵀ, −Rᵀt.
std::string rigid_problem(const Eigen::Matrix4d& transform) {
  if (!transform.allFinite()) return "has a non-finite entry";
  if (transform.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
    return "has last row " + row_text(transform.row(3)) + ", expected 0 0 0 1";
  }
  const Eigen::Matrix3d rotation = transform.topLeftCorner<3, 3>();
  const double off = (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off > kRigidTolerance) {
    return "is not rigid: the largest entry of RᵀR − I is " + format_number(off) + ", expected at most 1e-6";
  }
  const double determinant = rotation.determinant();
  if (!(determinant > 0)) return "is not a rotation: det R = " + format_number(determinant) + ", expected > 0";
  return {};
}

// Empty when `transform` is an invertible affine map (finite, last row exactly 0 0 0 1, σ_min of
// the linear part above kSingularRatio σ_max), else the reason: what two nodes can carry (T·U·Σ
// and Vᵀ) and what has an inverse bind matrix.
constexpr double kSingularRatio = 1e-12;
std::string affine_problem(const Eigen::Matrix4d& transform) {
  if (!transform.allFinite()) return "has a non-finite entry";
  if (transform.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
    return "has last row " + row_text(transform.row(3)) + ", expected 0 0 0 1";
  }
  const Eigen::Vector3d singular = Eigen::JacobiSVD<Eigen::Matrix3d>(transform.topLeftCorner<3, 3>()).singularValues();
  if (!(singular(2) > kSingularRatio * singular(0))) {
    return "is singular: its linear part's singular values are " + format_number(singular(0)) + ", " +
           format_number(singular(1)) + ", " + format_number(singular(2)) + ", expected the smallest above 1e-12 "
           "of the largest";
  }
  return {};
}

std::string transform_problem(const SkinnedCharacter& c, const Eigen::Matrix4d& transform) {
  return c.affine_joints ? affine_problem(transform) : rigid_problem(transform);
}

Status check_morph_targets(const SkinnedCharacter& c, const std::string& destination) {
  const size_t target_count = c.morph_targets.size();
  for (size_t k = 0; k < target_count; ++k) {
    if (c.morph_targets[k].rows() != c.bind_points.rows()) {
      return invalid(destination, "morph_targets[" + std::to_string(k) + "] has " +
                                      std::to_string(c.morph_targets[k].rows()) + " rows, expected #V = " +
                                      std::to_string(c.bind_points.rows()));
    }
    if (!c.morph_targets[k].allFinite()) {
      return invalid(destination, "morph_targets[" + std::to_string(k) + "] has a non-finite offset");
    }
  }
  if (!c.morph_target_names.empty() && c.morph_target_names.size() != target_count) {
    return invalid(destination, "morph_target_names has " + std::to_string(c.morph_target_names.size()) +
                                    " names, expected 0 or one per target (" + std::to_string(target_count) + ")");
  }
  const Eigen::Index expected_rows = target_count == 0 ? 0 : static_cast<Eigen::Index>(c.frame_globals.size());
  if (c.frame_morph_weights.rows() != expected_rows ||
      (expected_rows != 0 && c.frame_morph_weights.cols() != static_cast<Eigen::Index>(target_count))) {
    return invalid(destination, "frame_morph_weights is " + std::to_string(c.frame_morph_weights.rows()) + "×" +
                                    std::to_string(c.frame_morph_weights.cols()) + ", expected " +
                                    std::to_string(expected_rows) + "×" + std::to_string(target_count) +
                                    " (frames × morph targets)");
  }
  if (!c.frame_morph_weights.allFinite()) return invalid(destination, "frame_morph_weights has a non-finite weight");
  return Status::Ok();
}

// Every condition the writer relies on; `destination` ("glb", "gltf" or the path) prefixes the
// messages, which name the field, the index and what was expected.
Status check_character(const SkinnedCharacter& c, const std::string& destination) {
  const Eigen::Index vertex_count = c.bind_points.rows();
  if (vertex_count == 0) return invalid(destination, "bind_points has no rows (a mesh needs vertices)");
  for (Eigen::Index v = 0; v < vertex_count; ++v) {
    if (!c.bind_points.row(v).allFinite()) {
      return invalid(destination, "bind_points row " + std::to_string(v) + " has a non-finite coordinate");
    }
  }
  if (c.faces.rows() == 0) return invalid(destination, "faces has no rows (a mesh needs triangles)");
  for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
    for (int corner = 0; corner < 3; ++corner) {
      const int32_t index = c.faces(f, corner);
      if (index < 0 || index >= vertex_count) {
        return invalid(destination, "faces(" + std::to_string(f) + ", " + std::to_string(corner) +
                                        ") = " + std::to_string(index) + ", expected a vertex in [0, " +
                                        std::to_string(vertex_count) + ")");
      }
    }
  }
  if (c.normals.rows() != 0) {
    if (c.normals.rows() != vertex_count) {
      return invalid(destination, "normals has " + std::to_string(c.normals.rows()) +
                                      " rows, expected 0 or #V = " + std::to_string(vertex_count));
    }
    for (Eigen::Index v = 0; v < vertex_count; ++v) {
      const double length = c.normals.row(v).norm();
      if (!std::isfinite(length) || std::abs(length - 1) > kUnitNormalTolerance) {
        return invalid(destination, "normals row " + std::to_string(v) + " has length " + format_number(length) +
                                        ", expected a unit vector (within 1e-3)");
      }
    }
  }

  if (c.uvs.rows() != 0) {
    if (c.uvs.rows() != vertex_count) {
      return invalid(destination, "uvs has " + std::to_string(c.uvs.rows()) + " rows, expected 0 or #V = " +
                                      std::to_string(vertex_count));
    }
    for (Eigen::Index v = 0; v < vertex_count; ++v) {
      if (!c.uvs.row(v).allFinite()) return invalid(destination, "uvs row " + std::to_string(v) + " is not finite");
    }
  }

  // The skeleton.
  const size_t joint_count = c.joint_parents.size();
  if (joint_count == 0) return invalid(destination, "joint_parents is empty (a skin needs at least one joint)");
  if (static_cast<int64_t>(joint_count) > kMaxJoints) {
    return invalid(destination, "joint_parents has " + std::to_string(joint_count) +
                                    " joints, more than the 65536 that UNSIGNED_SHORT JOINTS_n can index");
  }
  for (size_t j = 0; j < joint_count; ++j) {
    const int32_t parent = c.joint_parents[j];
    if (parent < -1 || parent >= static_cast<int64_t>(j)) {
      return invalid(destination, "joint_parents[" + std::to_string(j) + "] = " + std::to_string(parent) +
                                      ", expected -1 or a joint before " + std::to_string(j) + " (parents first)");
    }
  }
  if (!c.joint_names.empty() && c.joint_names.size() != joint_count) {
    return invalid(destination, "joint_names has " + std::to_string(c.joint_names.size()) +
                                    " names, expected 0 or J = " + std::to_string(joint_count));
  }
  if (c.bind_globals.size() != joint_count) {
    return invalid(destination, "bind_globals has " + std::to_string(c.bind_globals.size()) +
                                    " transforms, expected J = " + std::to_string(joint_count));
  }
  for (size_t j = 0; j < joint_count; ++j) {
    const std::string problem = transform_problem(c, c.bind_globals[j]);
    if (!problem.empty()) return invalid(destination, "bind_globals[" + std::to_string(j) + "] " + problem);
  }

  // The influences, compressed rows.
  const size_t influence_count = c.joints.size();
  if (c.offsets.size() != static_cast<size_t>(vertex_count) + 1) {
    return invalid(destination, "offsets has " + std::to_string(c.offsets.size()) +
                                    " entries, expected #V + 1 = " + std::to_string(vertex_count + 1));
  }
  if (c.weights.size() != influence_count) {
    return invalid(destination, "weights has " + std::to_string(c.weights.size()) +
                                    " entries, expected one per entry of joints (" + std::to_string(influence_count) +
                                    ")");
  }
  if (c.offsets.front() != 0) {
    return invalid(destination, "offsets[0] = " + std::to_string(c.offsets.front()) + ", expected 0");
  }
  if (c.offsets.back() < 0 || static_cast<size_t>(c.offsets.back()) != influence_count) {
    return invalid(destination, "offsets[" + std::to_string(vertex_count) + "] = " + std::to_string(c.offsets.back()) +
                                    ", expected the number of influences (joints has " +
                                    std::to_string(influence_count) + " entries)");
  }
  // First the row structure, so that each vertex's range below is known to be in bounds.
  for (Eigen::Index v = 0; v < vertex_count; ++v) {
    const int32_t begin = c.offsets[static_cast<size_t>(v)], end = c.offsets[static_cast<size_t>(v) + 1];
    if (end < begin) {
      return invalid(destination, "offsets[" + std::to_string(v + 1) + "] = " + std::to_string(end) + " < offsets[" +
                                      std::to_string(v) + "] = " + std::to_string(begin) + " (must not decrease)");
    }
    if (static_cast<size_t>(end) > influence_count) {
      return invalid(destination, "offsets[" + std::to_string(v + 1) + "] = " + std::to_string(end) +
                                      " is past the end of joints (" + std::to_string(influence_count) + " entries)");
    }
  }
  std::vector<Eigen::Index> seen_at(joint_count, -1);  // the vertex that last named each joint with weight > 0
  for (Eigen::Index v = 0; v < vertex_count; ++v) {
    const int32_t begin = c.offsets[static_cast<size_t>(v)], end = c.offsets[static_cast<size_t>(v) + 1];
    double sum = 0;
    for (int32_t i = begin; i < end; ++i) {
      const int32_t joint = c.joints[static_cast<size_t>(i)];
      const double weight = c.weights[static_cast<size_t>(i)];
      const std::string at = "[" + std::to_string(i) + "] (vertex " + std::to_string(v) + ")";
      if (joint < 0 || static_cast<size_t>(joint) >= joint_count) {
        return invalid(destination, "joints" + at + " = " + std::to_string(joint) + ", expected a joint in [0, " +
                                        std::to_string(joint_count) + ")");
      }
      if (!std::isfinite(weight) || weight < 0) {
        return invalid(destination, "weights" + at + " = " + format_number(weight) + ", expected a finite weight ≥ 0");
      }
      // §3.7.3.3: "Joints MUST NOT contain more than one non-zero weight for a given vertex."
      if (weight > 0) {
        if (seen_at[static_cast<size_t>(joint)] == v) {
          return invalid(destination, "joints" + at + " = " + std::to_string(joint) +
                                          " appears twice among the vertex's non-zero weights (glTF allows one "
                                          "weight per joint and vertex; add them)");
        }
        seen_at[static_cast<size_t>(joint)] = v;
      }
      sum += weight;
    }
    if (!(std::abs(sum - 1) <= kWeightSumTolerance)) {
      return invalid(destination, "weights of vertex " + std::to_string(v) + " (entries [" + std::to_string(begin) +
                                      ", " + std::to_string(end) + ")) sum to " + format_number(sum) +
                                      ", expected 1 within 1e-6");
    }
  }

  ANIMSPACE_RETURN_IF_ERROR(check_morph_targets(c, destination));

  // The animation.
  if (c.frame_globals.empty()) return Status::Ok();
  if (!std::isfinite(c.frames_per_second) || !(c.frames_per_second > 0)) {
    return invalid(destination,
                   "frames_per_second = " + format_number(c.frames_per_second) + ", expected a finite number > 0");
  }
  for (size_t k = 0; k < c.frame_globals.size(); ++k) {
    const Matrix4dList& frame = c.frame_globals[k];
    if (frame.size() != joint_count) {
      return invalid(destination, "frame_globals[" + std::to_string(k) + "] has " + std::to_string(frame.size()) +
                                      " transforms, expected J = " + std::to_string(joint_count));
    }
    for (size_t j = 0; j < joint_count; ++j) {
      const std::string problem = transform_problem(c, frame[j]);
      if (!problem.empty()) {
        return invalid(destination, "frame_globals[" + std::to_string(k) + "][" + std::to_string(j) + "] " + problem);
      }
    }
  }
  // §3.11: sampler inputs are float seconds, strictly increasing; a huge rate or frame count
  // could make neighbours round to the same float.
  for (size_t k = 1; k < c.frame_globals.size(); ++k) {
    const float before = static_cast<float>(static_cast<double>(k - 1) / c.frames_per_second);
    const float now = static_cast<float>(static_cast<double>(k) / c.frames_per_second);
    if (!(now > before) || !std::isfinite(now)) {
      return invalid(destination, "frames_per_second = " + format_number(c.frames_per_second) + ": frames " +
                                      std::to_string(k - 1) + " and " + std::to_string(k) +
                                      " get the same float32 time, which glTF keyframes cannot hold");
    }
  }
  return Status::Ok();
}

// A rigid transform as translation and unit quaternion.
struct RigidTrs {
  Eigen::Vector3d translation;
  Eigen::Quaterniond rotation;
};

// parent⁻¹ · child for rigid transforms (parent⁻¹ = [Rᵀ, −Rᵀt]), decomposed (§3.5.3: a node's
// local transform is T · R · S; S is 1 here). `parent` null: a root, whose local is its global.
// The rotation block is within 1e-6 of orthonormal, so the quaternion is normalised to unit, as
// §3.5.3 requires.
RigidTrs local_trs(const Eigen::Matrix4d* parent, const Eigen::Matrix4d& child) {
  Eigen::Matrix3d rotation = child.topLeftCorner<3, 3>();
  Eigen::Vector3d translation = child.topRightCorner<3, 1>();
  if (parent != nullptr) {
    const Eigen::Matrix3d parent_rotation_t = parent->topLeftCorner<3, 3>().transpose();
    rotation = parent_rotation_t * rotation;
    translation = parent_rotation_t * (translation - parent->topRightCorner<3, 1>());
  }
  RigidTrs out{translation, Eigen::Quaterniond(rotation)};
  out.rotation.normalize();
  return out;
}

std::vector<RigidTrs> local_pose(const std::vector<int32_t>& parents, const Matrix4dList& globals) {
  std::vector<RigidTrs> locals;
  locals.reserve(parents.size());
  for (size_t j = 0; j < parents.size(); ++j) {
    const Eigen::Matrix4d* parent = parents[j] < 0 ? nullptr : &globals[static_cast<size_t>(parents[j])];
    locals.push_back(local_trs(parent, globals[j]));
  }
  return locals;
}

// An affine joint's local transform as its two nodes: the shape node's T, U, Σ and the joint
// node's Vᵀ, with T · U Σ Vᵀ the transform (U, V rotations; Σ's last entry negative for a
// reflection). The SVD's columns may flip in pairs without changing U Σ Vᵀ; the pair nearest
// `previous` (the last frame's) is taken, so that LINEAR keys between frames turn the short way.
struct AffineTrs {
  Eigen::Vector3d translation;
  Eigen::Quaterniond outer;
  Eigen::Vector3d scale;
  Eigen::Quaterniond inner;
  Eigen::Matrix3d u, v;  // the rotations, for the next frame's choice
};

AffineTrs affine_trs(const Eigen::Matrix4d& local, const AffineTrs* previous) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(local.topLeftCorner<3, 3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU(), v = svd.matrixV();
  Eigen::Vector3d scale = svd.singularValues();
  const Eigen::Matrix3d flip_last = Eigen::Vector3d(1, 1, -1).asDiagonal();
  if (u.determinant() < 0) {
    u = u * flip_last;
    scale(2) = -scale(2);
  }
  if (v.determinant() < 0) {
    v = v * flip_last;
    scale(2) = -scale(2);
  }
  if (previous != nullptr) {
    double best = -std::numeric_limits<double>::infinity();
    Eigen::Matrix3d best_flip = Eigen::Matrix3d::Identity();
    for (const Eigen::Vector3d& signs : {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(-1, -1, 1),
                                         Eigen::Vector3d(-1, 1, -1), Eigen::Vector3d(1, -1, -1)}) {
      const Eigen::Matrix3d flip = signs.asDiagonal();
      const double closeness = (previous->u.transpose() * u * flip).trace() + (previous->v.transpose() * v * flip).trace();
      if (closeness > best) {
        best = closeness;
        best_flip = flip;
      }
    }
    u = u * best_flip;
    v = v * best_flip;
  }
  AffineTrs out{local.topRightCorner<3, 1>(), Eigen::Quaterniond(u), scale, Eigen::Quaterniond(Eigen::Matrix3d(v.transpose())),
                u, v};
  out.outer.normalize();
  out.inner.normalize();
  return out;
}

std::vector<AffineTrs> affine_pose(const std::vector<int32_t>& parents, const Matrix4dList& globals,
                                   const std::vector<AffineTrs>* previous) {
  std::vector<AffineTrs> locals;
  locals.reserve(parents.size());
  for (size_t j = 0; j < parents.size(); ++j) {
    const Eigen::Matrix4d local =
        parents[j] < 0 ? globals[j] : Eigen::Matrix4d(globals[static_cast<size_t>(parents[j])].inverse() * globals[j]);
    locals.push_back(affine_trs(local, previous != nullptr ? &(*previous)[j] : nullptr));
  }
  return locals;
}

// The sign of q nearest `previous` (q and −q are the same rotation).
Eigen::Quaterniond near_sign(Eigen::Quaterniond q, const Eigen::Quaterniond& previous) {
  if (q.coeffs().dot(previous.coeffs()) < 0) q.coeffs() = -q.coeffs();
  return q;
}

// #V × 3 positions (or offsets) as a float32 VEC3 accessor with the min/max §3.6.2.5 asks of
// every POSITION accessor, a morph target's included.
int append_positions(tinygltf::Model& model, const Eigen::MatrixX3d& values) {
  const PointMatrix points = values.cast<float>();
  const auto count = static_cast<size_t>(points.rows());
  const int accessor = gltf_writing::append_accessor(model, points.data(), sizeof(float) * 3 * count,
                                                     TINYGLTF_TARGET_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                     TINYGLTF_TYPE_VEC3, count);
  const Eigen::RowVector3f lo = points.colwise().minCoeff(), hi = points.colwise().maxCoeff();
  model.accessors[static_cast<size_t>(accessor)].minValues = {lo.x(), lo.y(), lo.z()};
  model.accessors[static_cast<size_t>(accessor)].maxValues = {hi.x(), hi.y(), hi.z()};
  return accessor;
}

template <typename T>
int append_vector(tinygltf::Model& model, const std::vector<T>& values, int target, int component_type, int type,
                  size_t count) {
  return gltf_writing::append_accessor(model, values.data(), values.size() * sizeof(T), target, component_type, type,
                                       count);
}

Result<std::string> serialize_character(const SkinnedCharacter& c, bool binary, const std::string& destination) {
  ANIMSPACE_RETURN_IF_ERROR(check_character(c, destination));
  const size_t vertex_count = static_cast<size_t>(c.bind_points.rows());
  const size_t face_count = static_cast<size_t>(c.faces.rows());
  const size_t joint_count = c.joint_parents.size();
  const size_t frame_count = c.frame_globals.size();
  size_t max_influences = 0;
  for (size_t v = 0; v < vertex_count; ++v) {
    max_influences = std::max(max_influences, static_cast<size_t>(c.offsets[v + 1] - c.offsets[v]));
  }
  // §3.7.3.3: four joints per JOINTS_n / WEIGHTS_n set; a vertex with more uses further sets.
  // Every primitive needs JOINTS_0 / WEIGHTS_0, even if (oddly) no vertex has an influence.
  const size_t set_count = std::max<size_t>(1, (max_influences + 3) / 4);
  // The buffer's size, in double so that the estimate itself cannot overflow (padding to 4 bytes
  // adds at most 3 per accessor).
  const double bytes = static_cast<double>(vertex_count) * (2 * 12 + (c.uvs.rows() != 0 ? 8 : 0) + static_cast<double>(set_count) * (8 + 16)) +
                       static_cast<double>(face_count) * 12 + static_cast<double>(joint_count) * 64 +
                       static_cast<double>(frame_count) * (4 + static_cast<double>(joint_count) * (2 * 12 + 2 * 16)) +
                       static_cast<double>(c.morph_targets.size()) * (static_cast<double>(vertex_count) * 12 +
                                                                     static_cast<double>(frame_count) * 4 + 4) +
                       4.0 * (6 + static_cast<double>(set_count) * 2 + static_cast<double>(joint_count) * 2);
  if (bytes > static_cast<double>(gltf_writing::kMaxBufferBytes)) {
    return invalid(destination, "a character of " + std::to_string(vertex_count) + " vertices, " +
                                    std::to_string(joint_count) + " joints and " + std::to_string(frame_count) +
                                    " frames needs a buffer of " + format_number(bytes) +
                                    " bytes, over the 2 GiB a glTF buffer can hold here");
  }

  try {
    tinygltf::Model model = gltf_writing::new_document();
    model.buffers[0].data.reserve(static_cast<size_t>(bytes));

    // 1. The mesh: float32 positions (with the min/max §3.6.2.5 requires of POSITION), unit
    //    normals, uint32 indices.
    tinygltf::Primitive primitive;
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    primitive.attributes["POSITION"] = append_positions(model, c.bind_points);
    PointMatrix normals;
    if (c.normals.rows() != 0) {
      // Within 1e-3 of unit length (checked); normalised in double so that float32 holds them
      // as close to unit as it can, which is what validators measure.
      normals = c.normals.rowwise().normalized().cast<float>();
    } else {
      normals = geometry::area_weighted_normals(c.bind_points, c.faces).cast<float>();
      // A zero row (a vertex in no non-degenerate face) is no unit normal; write none rather
      // than invent one.
      if ((normals.rowwise().squaredNorm().array() == 0).any()) normals.resize(0, 3);
    }
    if (normals.rows() != 0) {
      primitive.attributes["NORMAL"] = gltf_writing::append_accessor(
          model, normals.data(), sizeof(float) * 3 * vertex_count, TINYGLTF_TARGET_ARRAY_BUFFER,
          TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_count);
    }
    if (c.uvs.rows() != 0) {
      // glTF's texture origin is the top-left corner: (u, 1 − v).
      UvMatrix flipped = c.uvs;
      flipped.col(1).array() = 1 - flipped.col(1).array();
      primitive.attributes["TEXCOORD_0"] = gltf_writing::append_accessor(
          model, flipped.data(), sizeof(float) * 2 * vertex_count, TINYGLTF_TARGET_ARRAY_BUFFER,
          TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, vertex_count);
    }
    // int32 indices in [0, #V): the same bytes as uint32.
    primitive.indices = gltf_writing::append_accessor(
        model, c.faces.data(), sizeof(int32_t) * 3 * face_count, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER,
        TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, 3 * face_count);

    // 2. The influences: slot s of vertex v is influence offsets[v] + s, in set s / 4. Unused
    //    slots and zero weights get joint 0 (§3.7.3.3: unused joint values SHOULD be zero).
    for (size_t set = 0; set < set_count; ++set) {
      std::vector<uint16_t> slot_joints(4 * vertex_count, 0);
      std::vector<float> slot_weights(4 * vertex_count, 0.0f);
      for (size_t v = 0; v < vertex_count; ++v) {
        for (size_t slot = 0; slot < 4; ++slot) {
          const size_t i = static_cast<size_t>(c.offsets[v]) + 4 * set + slot;
          if (i >= static_cast<size_t>(c.offsets[v + 1])) break;
          const float weight = static_cast<float>(c.weights[i]);
          if (weight == 0) continue;
          slot_joints[4 * v + slot] = static_cast<uint16_t>(c.joints[i]);
          slot_weights[4 * v + slot] = weight;
        }
      }
      primitive.attributes["JOINTS_" + std::to_string(set)] =
          append_vector(model, slot_joints, TINYGLTF_TARGET_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                        TINYGLTF_TYPE_VEC4, vertex_count);
      primitive.attributes["WEIGHTS_" + std::to_string(set)] =
          append_vector(model, slot_weights, TINYGLTF_TARGET_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_FLOAT,
                        TINYGLTF_TYPE_VEC4, vertex_count);
    }
    // 2b. The morph targets (§3.7.2.2): POSITION offsets, written as the positions are.
    const size_t target_count = c.morph_targets.size();
    for (size_t k = 0; k < target_count; ++k) {
      primitive.targets.push_back({{"POSITION", append_positions(model, c.morph_targets[k])}});
    }
    tinygltf::Mesh mesh;
    mesh.name = c.name;
    mesh.primitives.push_back(std::move(primitive));
    if (target_count != 0) {
      mesh.weights.assign(target_count, 0.0);
      // Not in the specification, but the convention its exporters and importers share (Blender's
      // shape key names, three.js's morphTargetDictionary).
      tinygltf::Value::Array names;
      for (size_t k = 0; k < target_count; ++k) {
        names.emplace_back(c.morph_target_names.empty() || c.morph_target_names[k].empty()
                               ? "target_" + std::to_string(k)
                               : c.morph_target_names[k]);
      }
      mesh.extras = tinygltf::Value(tinygltf::Value::Object{{"targetNames", tinygltf::Value(std::move(names))}});
    }
    model.meshes.push_back(std::move(mesh));

    // 3. The skin (§3.7.3.1): joint j is node j; inverse bind matrices (float MAT4, column-major,
    //    last row 0 0 0 1) are the exact inverses of the bind globals, computed in double before
    //    rounding: [Rᵀ, −Rᵀt] of rigid ones, Eigen's general inverse of affine ones.
    std::vector<float> inverse_binds(16 * joint_count);
    for (size_t j = 0; j < joint_count; ++j) {
      Eigen::Matrix4d inverse = Eigen::Matrix4d::Identity();
      if (c.affine_joints) {
        inverse.topLeftCorner<3, 3>() = c.bind_globals[j].topLeftCorner<3, 3>().inverse();
      } else {
        inverse.topLeftCorner<3, 3>() = c.bind_globals[j].topLeftCorner<3, 3>().transpose();
      }
      inverse.topRightCorner<3, 1>() = -inverse.topLeftCorner<3, 3>() * c.bind_globals[j].topRightCorner<3, 1>();
      const Eigen::Matrix4f single = inverse.cast<float>();  // column-major, as glTF stores it
      std::copy(single.data(), single.data() + 16, inverse_binds.begin() + static_cast<std::ptrdiff_t>(16 * j));
    }
    tinygltf::Skin skin;
    skin.name = c.name + " rig";
    skin.inverseBindMatrices =
        append_vector(model, inverse_binds, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_MAT4, joint_count);

    // 4. The nodes: joints with their bind-pose local TRS, children by joint_parents; the mesh
    //    node (J) at the scene root without a transform, as §3.7.3.2 ignores it anyway. Affine
    //    joints: joint j's node holds Vᵀ, under its shape node J + 2 + j (T, U, Σ), which hangs
    //    from the parent joint's node or from the common root J + 1.
    const auto joint_name = [&](size_t j) {
      return c.joint_names.empty() || c.joint_names[j].empty() ? "joint_" + std::to_string(j) : c.joint_names[j];
    };
    const std::vector<RigidTrs> bind_locals =
        c.affine_joints ? std::vector<RigidTrs>() : local_pose(c.joint_parents, c.bind_globals);
    const std::vector<AffineTrs> bind_affine =
        c.affine_joints ? affine_pose(c.joint_parents, c.bind_globals, nullptr) : std::vector<AffineTrs>();
    std::vector<int> root_joints;
    for (size_t j = 0; j < joint_count; ++j) {
      tinygltf::Node node;
      node.name = joint_name(j);
      if (c.affine_joints) {
        const Eigen::Quaterniond& inner = bind_affine[j].inner;
        node.rotation = {inner.x(), inner.y(), inner.z(), inner.w()};
      } else {
        const RigidTrs& local = bind_locals[j];
        node.translation = {local.translation.x(), local.translation.y(), local.translation.z()};
        node.rotation = {local.rotation.x(), local.rotation.y(), local.rotation.z(), local.rotation.w()};
      }
      model.nodes.push_back(std::move(node));
      skin.joints.push_back(static_cast<int>(j));
      if (c.affine_joints) continue;  // hung below its shape node, after the common root
      if (c.joint_parents[j] < 0) {
        root_joints.push_back(static_cast<int>(j));
      } else {
        model.nodes[static_cast<size_t>(c.joint_parents[j])].children.push_back(static_cast<int>(j));
      }
    }
    const auto shape_node = [&](size_t j) { return static_cast<int>(joint_count + 2 + j); };
    if (c.affine_joints) {
      for (size_t j = 0; j < joint_count; ++j) {
        if (c.joint_parents[j] < 0) {
          root_joints.push_back(shape_node(j));
        } else {
          model.nodes[static_cast<size_t>(c.joint_parents[j])].children.push_back(shape_node(j));
        }
      }
    }
    tinygltf::Node mesh_node;
    mesh_node.name = c.name;
    mesh_node.mesh = 0;
    mesh_node.skin = 0;
    model.nodes.push_back(std::move(mesh_node));
    tinygltf::Scene scene;
    scene.nodes.push_back(static_cast<int>(joint_count));
    // §3.7.3.2: a skin's joints MUST have a common root node. One root joint is it; several (or
    // shape nodes above the joints) get an untransformed "skeleton" node above them (node J + 1),
    // which leaves every global as is.
    if (root_joints.size() == 1 && !c.affine_joints) {
      skin.skeleton = root_joints.front();
      scene.nodes.push_back(root_joints.front());
    } else {
      tinygltf::Node common_root;
      common_root.name = c.name + " rig";
      common_root.children = root_joints;
      model.nodes.push_back(std::move(common_root));
      skin.skeleton = static_cast<int>(joint_count) + 1;
      scene.nodes.push_back(skin.skeleton);
    }
    for (size_t j = 0; c.affine_joints && j < joint_count; ++j) {
      tinygltf::Node shape;
      shape.name = joint_name(j) + " shape";
      const AffineTrs& local = bind_affine[j];
      shape.translation = {local.translation.x(), local.translation.y(), local.translation.z()};
      shape.rotation = {local.outer.x(), local.outer.y(), local.outer.z(), local.outer.w()};
      shape.scale = {local.scale.x(), local.scale.y(), local.scale.z()};
      shape.children = {static_cast<int>(j)};
      model.nodes.push_back(std::move(shape));
    }
    model.skins.push_back(std::move(skin));
    model.scenes.push_back(std::move(scene));
    model.defaultScene = 0;

    // 5. The animation (§3.11): one time accessor (float seconds k / fps, with the min/max an
    //    input must have), per joint a translation (VEC3) and a rotation (VEC4, x y z w) sampler
    //    of the local transforms, LINEAR (affine joints: the shape node's translation, rotation
    //    and scale, the joint node's rotation), and the morph weights' sampler.
    if (frame_count != 0) {
      tinygltf::Animation animation;
      animation.name = c.animation_name;
      std::vector<float> times(frame_count);
      for (size_t k = 0; k < frame_count; ++k) {
        times[k] = static_cast<float>(static_cast<double>(k) / c.frames_per_second);
      }
      const int input =
          append_vector(model, times, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR, frame_count);
      model.accessors[static_cast<size_t>(input)].minValues = {times.front()};
      model.accessors[static_cast<size_t>(input)].maxValues = {times.back()};
      const auto add_channel = [&](int node, const char* path, int output) {
        tinygltf::AnimationSampler sampler;
        sampler.input = input;
        sampler.output = output;
        sampler.interpolation = "LINEAR";
        animation.samplers.push_back(std::move(sampler));
        tinygltf::AnimationChannel channel;
        channel.sampler = static_cast<int>(animation.samplers.size() - 1);
        channel.target_node = node;
        channel.target_path = path;
        animation.channels.push_back(std::move(channel));
      };
      const auto add_vec3 = [&](const std::vector<float>& values) {
        return append_vector(model, values, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, frame_count);
      };
      const auto add_vec4 = [&](const std::vector<float>& values) {
        return append_vector(model, values, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC4, frame_count);
      };
      const auto put3 = [](std::vector<float>& out, size_t k, const Eigen::Vector3d& value) {
        for (size_t axis = 0; axis < 3; ++axis) out[3 * k + axis] = static_cast<float>(value(static_cast<Eigen::Index>(axis)));
      };
      // Eigen's coeffs() are x y z w, glTF's order.
      const auto put4 = [](std::vector<float>& out, size_t k, const Eigen::Quaterniond& q) {
        for (size_t e = 0; e < 4; ++e) out[4 * k + e] = static_cast<float>(q.coeffs()(static_cast<Eigen::Index>(e)));
      };

      std::vector<float> translations(3 * frame_count), rotations(4 * frame_count);
      if (!c.affine_joints) {
        std::vector<std::vector<RigidTrs>> locals(frame_count);
        for (size_t k = 0; k < frame_count; ++k) locals[k] = local_pose(c.joint_parents, c.frame_globals[k]);
        for (size_t j = 0; j < joint_count; ++j) {
          // q and −q are the same rotation. Appendix C's slerp takes the short arc whatever the
          // signs, but the spec lets clients approximate it (e.g. normalised lerp of components),
          // which turns the long way round between quaternions with a negative dot product; so each
          // frame's sign follows the previous frame's (the first follows the bind pose's, for
          // clients that blend from the rest pose into the animation).
          Eigen::Quaterniond previous = bind_locals[j].rotation;
          for (size_t k = 0; k < frame_count; ++k) {
            const RigidTrs& local = locals[k][j];
            previous = near_sign(local.rotation, previous);
            put3(translations, k, local.translation);
            put4(rotations, k, previous);
          }
          add_channel(static_cast<int>(j), "translation", add_vec3(translations));
          add_channel(static_cast<int>(j), "rotation", add_vec4(rotations));
        }
      } else {
        std::vector<std::vector<AffineTrs>> locals(frame_count);
        for (size_t k = 0; k < frame_count; ++k) {
          locals[k] = affine_pose(c.joint_parents, c.frame_globals[k], k == 0 ? &bind_affine : &locals[k - 1]);
        }
        std::vector<float> scales(3 * frame_count), inner_rotations(4 * frame_count);
        for (size_t j = 0; j < joint_count; ++j) {
          Eigen::Quaterniond previous_outer = bind_affine[j].outer, previous_inner = bind_affine[j].inner;
          for (size_t k = 0; k < frame_count; ++k) {
            const AffineTrs& local = locals[k][j];
            previous_outer = near_sign(local.outer, previous_outer);
            previous_inner = near_sign(local.inner, previous_inner);
            put3(translations, k, local.translation);
            put4(rotations, k, previous_outer);
            put3(scales, k, local.scale);
            put4(inner_rotations, k, previous_inner);
          }
          add_channel(shape_node(j), "translation", add_vec3(translations));
          add_channel(shape_node(j), "rotation", add_vec4(rotations));
          add_channel(shape_node(j), "scale", add_vec3(scales));
          add_channel(static_cast<int>(j), "rotation", add_vec4(inner_rotations));
        }
      }
      if (target_count != 0) {
        // §3.11: a "weights" output holds every target's weight of frame 0, then of frame 1, ….
        std::vector<float> weights(frame_count * target_count);
        for (size_t k = 0; k < frame_count; ++k) {
          for (size_t t = 0; t < target_count; ++t) {
            weights[k * target_count + t] =
                static_cast<float>(c.frame_morph_weights(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(t)));
          }
        }
        add_channel(static_cast<int>(joint_count), "weights",
                    append_vector(model, weights, 0, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR,
                                  frame_count * target_count));
      }
      model.animations.push_back(std::move(animation));
    }
    return gltf_writing::serialize_document(model, binary, destination);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, destination + ": out of memory while building the document");
  } catch (const std::exception& exception) {
    return make_error(ErrorCode::kInternal, destination + ": failed while building the document: " + exception.what());
  }
}

}  // namespace

SkinnedCharacter split_seams(const SkinnedCharacter& character, const UvMatrix& corner_uvs) {
  assert(character.uvs.rows() == 0);
  assert(corner_uvs.rows() == 3 * character.faces.rows());
  const Eigen::Index vertex_count = character.bind_points.rows();
  SeamSplit split = split_seam_vertices(character.faces, vertex_count, corner_uvs);
  Eigen::MatrixX3d normals = character.normals;
  if (normals.rows() == 0 && character.faces.rows() > 0) {
    normals = geometry::area_weighted_normals(character.bind_points, character.faces);
    if ((normals.rowwise().squaredNorm().array() == 0).any()) normals.resize(0, 3);  // left to the writer
  }
  SkinnedCharacter out = character;
  const auto n = static_cast<Eigen::Index>(split.source.size());
  out.faces = std::move(split.faces);
  out.uvs = std::move(split.uvs);
  out.bind_points.resize(n, 3);
  out.normals.resize(normals.rows() != 0 ? n : 0, 3);
  for (Eigen::MatrixX3d& target : out.morph_targets) target.resize(n, 3);
  out.offsets.assign(1, 0);
  out.joints.clear();
  out.weights.clear();
  for (Eigen::Index o = 0; o < n; ++o) {
    const int32_t v = split.source[static_cast<size_t>(o)];
    out.bind_points.row(o) = character.bind_points.row(v);
    if (normals.rows() != 0) out.normals.row(o) = normals.row(v);
    for (size_t k = 0; k < out.morph_targets.size(); ++k) out.morph_targets[k].row(o) = character.morph_targets[k].row(v);
    for (int32_t i = character.offsets[static_cast<size_t>(v)]; i < character.offsets[static_cast<size_t>(v) + 1]; ++i) {
      out.joints.push_back(character.joints[static_cast<size_t>(i)]);
      out.weights.push_back(character.weights[static_cast<size_t>(i)]);
    }
    out.offsets.push_back(static_cast<int32_t>(out.joints.size()));
  }
  return out;
}

Result<std::string> serialize_skinned_glb(const SkinnedCharacter& character) {
  return serialize_character(character, true, "glb");
}

Result<std::string> serialize_skinned_gltf(const SkinnedCharacter& character) {
  return serialize_character(character, false, "gltf");
}

Status write_skinned_character(const std::filesystem::path& path, const SkinnedCharacter& character) {
  std::string extension;
  try {
    extension = lowercase_extension(path);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory");
  }
  if (extension != ".glb" && extension != ".gltf") {
    return invalid(path.string(), "unknown skinned character file extension '" + path.extension().string() +
                                      "' (supported: .glb, .gltf)");
  }
  auto bytes = serialize_character(character, extension == ".glb", path.string());
  if (!bytes.ok()) return bytes.error();
  return write_file_atomically(path, *bytes);
}

}  // namespace animspace::mesh_io
