// Linear-blend rigs → animation space (Merry 2007 §3.1), and the rig readers behind it:
// libigl TGF/DMAT/Tmat (mesh_io/libigl_rig.h) and glTF 2.0 skins (mesh_io/gltf_skin.h).
#include "core/animspace/import.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <utility>

#include <Eigen/Geometry>

#include "core/common/format.h"
#include "core/mesh_io/gltf_skin.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::animation_space {
namespace {

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

// One vertex's influences as a file gives them: bones in our numbering, any order, possibly
// repeated (glTF slots), possibly zero.
using RawInfluences = std::vector<std::pair<int32_t, double>>;

// Appends one vertex's influences to `rig.model`, applying the shared weight rules of import.h
// (sum check, exact zeros out, drop_below, rescale to 1). `where` names the vertex in errors.
Status append_vertex(RawInfluences& raw, double sum_tolerance, const WeightOptions& options, const std::string& where,
                     ImportedRig& rig, std::vector<double>& weights) {
  std::sort(raw.begin(), raw.end());
  double sum = 0;
  for (const auto& [bone, w] : raw) {
    if (!std::isfinite(w)) return invalid(where + ": weight of bone " + std::to_string(bone) + " is not finite");
    sum += w;
  }
  if (!(std::abs(sum - 1.0) <= sum_tolerance)) {
    return invalid(where + ": weights sum to " + format_number(sum) + ", expected 1 (±" + format_number(sum_tolerance) +
                   ")");
  }
  // Merge repeated bones first, so that drop_below applies to a bone's total weight.
  RawInfluences merged;
  for (const auto& [bone, w] : raw) {
    if (!merged.empty() && merged.back().first == bone) {
      merged.back().second += w;
    } else {
      merged.emplace_back(bone, w);
    }
  }
  // The budget: the smallest weights, in order, while their sum stays within it.
  std::vector<char> in_budget(merged.size(), 0);
  if (options.drop_budget > 0) {
    std::vector<size_t> order(merged.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return std::abs(merged[a].second) < std::abs(merged[b].second); });
    double spent = 0;
    for (size_t k = 0; k + 1 < order.size(); ++k) {  // the largest weight always stays
      const double w = std::abs(merged[order[k]].second);
      if (w < options.drop_below) continue;  // dropped by the threshold already, not from the budget
      if (spent + w > options.drop_budget) break;
      spent += w;
      in_budget[order[k]] = 1;
    }
  }
  double kept_sum = 0, dropped_sum = 0;
  const size_t first = rig.model.influences.bones.size();
  for (size_t i = 0; i < merged.size(); ++i) {
    const auto& [bone, w] = merged[i];
    if (w == 0.0) continue;
    if (std::abs(w) < options.drop_below || in_budget[i]) {
      ++rig.dropped_weights;
      dropped_sum += std::abs(w);
      continue;
    }
    rig.model.influences.bones.push_back(bone);
    weights.push_back(w);
    kept_sum += w;
  }
  rig.max_dropped_weight_sum = std::max(rig.max_dropped_weight_sum, dropped_sum);
  if (rig.model.influences.bones.size() == first || !(kept_sum > 0)) {
    return invalid(where + ": no influence left (weights below drop_below " + format_number(options.drop_below) +
                   " are dropped)");
  }
  for (size_t k = first; k < weights.size(); ++k) weights[k] /= kept_sum;
  rig.model.influences.offsets.push_back(static_cast<int32_t>(rig.model.influences.bones.size()));
  return Status::Ok();
}

void finish_weights(ImportedRig& rig, const std::vector<double>& weights) {
  rig.model.weights = Eigen::Map<const Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
}

// Orders bones so that parents precede children, keeping the file's order otherwise (a stable
// topological sort). `source_parent[b]` is the file bone that is b's parent, or -1 for the
// super-root. Returns the order (file bones) or an empty vector when the bones form a cycle.
std::vector<int32_t> parents_first_order(const std::vector<int32_t>& source_parent) {
  const size_t count = source_parent.size();
  std::vector<int32_t> order;
  std::vector<bool> placed(count, false);
  order.reserve(count);
  bool progress = true;
  while (order.size() < count && progress) {
    progress = false;
    for (size_t b = 0; b < count; ++b) {
      const int32_t parent = source_parent[b];
      if (!placed[b] && (parent < 0 || placed[static_cast<size_t>(parent)])) {
        placed[b] = true;
        order.push_back(static_cast<int32_t>(b));
        progress = true;
      }
    }
  }
  if (order.size() < count) order.clear();
  return order;
}

// Fills rig.model.skeleton and rig.bone_of_source from per-file-bone parents and rest transforms.
void build_skeleton(const std::vector<int32_t>& order, const std::vector<int32_t>& source_parent,
                    const TransformList& source_rest, const std::vector<std::string>& source_names, ImportedRig& rig) {
  Skeleton& skeleton = rig.model.skeleton;
  skeleton = root_only_skeleton();
  skeleton.names = {"root"};
  rig.bone_of_source.assign(source_parent.size(), -1);
  for (const int32_t b : order) {
    const size_t source = static_cast<size_t>(b);
    rig.bone_of_source[source] = skeleton.bone_count();
    const int32_t parent = source_parent[source];
    skeleton.parents.push_back(parent < 0 ? 0 : rig.bone_of_source[static_cast<size_t>(parent)]);
    skeleton.rest.push_back(source_rest[source]);
    skeleton.names.push_back(source_names[source]);
  }
}

}  // namespace

AnimationSpaceModel from_linear_blend(const LinearBlendModel& lbs) {
  assert(validate(lbs).ok());
  AnimationSpaceModel model;
  model.skeleton = lbs.skeleton;
  model.faces = lbs.faces;
  TransformList rest_inverse(lbs.skeleton.rest.size());
  for (size_t j = 0; j < rest_inverse.size(); ++j) rest_inverse[j] = affine_inverse(lbs.skeleton.rest[j]);

  std::vector<Eigen::Vector4d> columns;
  columns.reserve(static_cast<size_t>(lbs.influences.influence_count()));
  model.influences.offsets.reserve(static_cast<size_t>(lbs.vertex_count()) + 1);
  model.influences.bones.reserve(static_cast<size_t>(lbs.influences.influence_count()));
  for (int i = 0; i < lbs.vertex_count(); ++i) {
    const Eigen::Vector4d rest_point = lbs.rest_points.col(i).homogeneous();
    for (int k = lbs.influences.begin(i); k < lbs.influences.end(i); ++k) {
      const double w = lbs.weights(k);
      if (w == 0.0) continue;
      const int32_t bone = lbs.influences.bones[static_cast<size_t>(k)];
      // §3.1: p_j = w_j Ĝ_j⁻¹ v̂; its fourth component is w_j exactly (Ĝ_j⁻¹ is affine).
      columns.push_back(w * (rest_inverse[static_cast<size_t>(bone)] * rest_point));
      model.influences.bones.push_back(bone);
    }
    model.influences.offsets.push_back(static_cast<int32_t>(model.influences.bones.size()));
  }
  model.positions.resize(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) model.positions.col(static_cast<Eigen::Index>(k)) = columns[k];
  return model;
}

// ---------------------------------------------------------------------------------------------
// libigl rigs

Result<ImportedRig> rig_from_libigl(const TriangleMesh& rest, const mesh_io::TgfSkeleton& tgf,
                                    const Eigen::MatrixXd& weights, const LibiglSources& sources,
                                    const WeightOptions& options) {
  const Eigen::Index vertex_count = rest.V.rows();
  const Eigen::Index bone_count = tgf.bones.rows();
  const Eigen::Index joint_count = tgf.joints.rows();
  if (bone_count == 0) return invalid(sources.skeleton + ": no bones");
  if (weights.rows() != vertex_count || weights.cols() != bone_count) {
    return invalid(sources.weights + ": expected " + std::to_string(vertex_count) + " rows (vertices of " +
                   sources.mesh + ") by " + std::to_string(bone_count) + " columns (bones of " + sources.skeleton +
                   "), got " + std::to_string(weights.rows()) + " by " + std::to_string(weights.cols()));
  }
  if (!tgf.joints.allFinite()) return invalid(sources.skeleton + ": a joint position is not finite");

  // Hierarchy: the parent of bone b is the bone that ends at b's first joint.
  std::vector<int32_t> bone_ending_at(static_cast<size_t>(joint_count), -1);
  for (Eigen::Index b = 0; b < bone_count; ++b) {
    for (int c = 0; c < 2; ++c) {
      if (tgf.bones(b, c) < 0 || tgf.bones(b, c) >= joint_count) {
        return invalid(sources.skeleton + ": bone " + std::to_string(b) + " uses joint " +
                       std::to_string(tgf.bones(b, c)) + ", expected 0 … " + std::to_string(joint_count - 1));
      }
    }
    int32_t& ending = bone_ending_at[static_cast<size_t>(tgf.bones(b, 1))];
    if (ending >= 0) {
      return invalid(sources.skeleton + ": bones " + std::to_string(ending) + " and " + std::to_string(b) +
                     " both end at joint " + std::to_string(tgf.bones(b, 1) + 1) +
                     " (1-based), so the skeleton is not a tree");
    }
    ending = static_cast<int32_t>(b);
  }
  std::vector<int32_t> source_parent(static_cast<size_t>(bone_count));
  TransformList source_rest(static_cast<size_t>(bone_count));
  std::vector<std::string> source_names(static_cast<size_t>(bone_count));
  for (Eigen::Index b = 0; b < bone_count; ++b) {
    const int parent_joint = tgf.bones(b, 0);
    source_parent[static_cast<size_t>(b)] = bone_ending_at[static_cast<size_t>(parent_joint)];
    // The bone frame sits at its parent joint with the model's axes.
    source_rest[static_cast<size_t>(b)] =
        make_transform(Eigen::Matrix3d::Identity(), tgf.joints.row(parent_joint).transpose());
    source_names[static_cast<size_t>(b)] = "tgf_bone_" + std::to_string(b);
  }
  const std::vector<int32_t> order = parents_first_order(source_parent);
  if (order.empty()) return invalid(sources.skeleton + ": the bones form a cycle");

  ImportedRig rig;
  build_skeleton(order, source_parent, source_rest, source_names, rig);
  rig.model.faces = rest.F;
  rig.model.rest_points = rest.V.cast<double>().transpose();

  std::vector<double> kept_weights;
  RawInfluences raw;
  for (Eigen::Index v = 0; v < vertex_count; ++v) {
    raw.clear();
    for (Eigen::Index b = 0; b < bone_count; ++b) {
      raw.emplace_back(rig.bone_of_source[static_cast<size_t>(b)], weights(v, b));
    }
    ANIMSPACE_RETURN_IF_ERROR(append_vertex(raw, options.sum_tolerance, options,
                                            sources.weights + ": row " + std::to_string(v) + " (vertex " +
                                                std::to_string(v) + ")",
                                            rig, kept_weights));
  }
  finish_weights(rig, kept_weights);
  ANIMSPACE_RETURN_IF_ERROR(validate(rig.model));
  return rig;
}

Result<ImportedRig> read_libigl_rig(const std::filesystem::path& mesh, const std::filesystem::path& tgf,
                                    const std::filesystem::path& dmat, const WeightOptions& options) {
  auto rest = mesh_io::read_triangle_mesh(mesh);
  if (!rest.ok()) return rest.error();
  auto skeleton = mesh_io::read_tgf(tgf);
  if (!skeleton.ok()) return skeleton.error();
  auto weights = mesh_io::read_dmat(dmat);
  if (!weights.ok()) return weights.error();
  return rig_from_libigl(*rest, *skeleton, *weights, LibiglSources{mesh.string(), tgf.string(), dmat.string()},
                         options);
}

Result<TransformList> pose_from_tmat(const ImportedRig& rig, const std::vector<Eigen::Matrix<double, 4, 3>>& transforms,
                                     const std::string& source) {
  if (transforms.size() != rig.bone_of_source.size()) {
    return invalid(source + ": expected " + std::to_string(rig.bone_of_source.size()) + " transforms (one per bone), got " +
                   std::to_string(transforms.size()));
  }
  const Skeleton& skeleton = rig.model.skeleton;
  TransformList globals(static_cast<size_t>(skeleton.bone_count()), Transform::Identity());
  for (size_t b = 0; b < transforms.size(); ++b) {
    if (!transforms[b].allFinite()) return invalid(source + ": transform of bone " + std::to_string(b) + " is not finite");
    // Row-vector form [v̂ 1] T_b is the column-vector skinning matrix S = T_bᵀ = G_j Ĝ_j⁻¹.
    Transform skinning = Transform::Identity();
    skinning.topRows<3>() = transforms[b].transpose();
    const size_t bone = static_cast<size_t>(rig.bone_of_source[b]);
    globals[bone] = skinning * skeleton.rest[bone];
  }
  return globals;
}

Result<TransformList> read_tmat_pose(const ImportedRig& rig, const std::filesystem::path& tmat) {
  auto transforms = mesh_io::read_tmat(tmat);
  if (!transforms.ok()) return transforms.error();
  return pose_from_tmat(rig, *transforms, tmat.string());
}

// ---------------------------------------------------------------------------------------------
// glTF 2.0 skins

Result<GltfRig> read_gltf_rig(const std::filesystem::path& file, const GltfImportOptions& options) {
  auto read = mesh_io::read_gltf_skin(file, options.node);
  if (!read.ok()) return read.error();
  const mesh_io::GltfSkin& skin = *read;

  // The skeleton: the skin's joints after the super-root, parents first; Ĝ_j is the inverse of
  // the joint's inverse bind matrix, and G_j the joint node's global transform (§3.7.3).
  const size_t joint_count = skin.joint_parents.size();
  TransformList source_rest(joint_count);
  for (size_t j = 0; j < joint_count; ++j) source_rest[j] = affine_inverse(skin.inverse_bind_matrices[j]);
  const std::vector<int32_t> order = parents_first_order(skin.joint_parents);
  assert(order.size() == joint_count);  // read_gltf_skin ruled out cycles of nodes
  GltfRig result;
  ImportedRig& rig = result.rig;
  build_skeleton(order, skin.joint_parents, source_rest, skin.joint_names, rig);
  result.pose.assign(static_cast<size_t>(rig.model.skeleton.bone_count()), Transform::Identity());
  for (size_t j = 0; j < joint_count; ++j) {
    result.pose[static_cast<size_t>(rig.bone_of_source[j])] = skin.joint_node_transforms[j];
  }

  // The influences, primitive by primitive (a vertex is named within its primitive).
  std::vector<double> kept_weights;
  RawInfluences raw;
  for (size_t p = 0; p < skin.primitives.size(); ++p) {
    const mesh_io::GltfSkin::Primitive& primitive = skin.primitives[p];
    const std::string where = skin.file + ": mesh " + std::to_string(skin.mesh) + " primitive " + std::to_string(p);
    const double sum_tolerance = options.weights.sum_tolerance + primitive.weight_quantisation;
    for (int64_t v = 0; v < primitive.vertex_count; ++v) {
      const auto vertex = static_cast<size_t>(primitive.first_vertex + v);
      raw.clear();
      for (int64_t k = skin.slot_offsets[vertex]; k < skin.slot_offsets[vertex + 1]; ++k) {
        raw.emplace_back(rig.bone_of_source[static_cast<size_t>(skin.slot_joints[static_cast<size_t>(k)])],
                         skin.slot_weights[static_cast<size_t>(k)]);
      }
      ANIMSPACE_RETURN_IF_ERROR(
          append_vertex(raw, sum_tolerance, options.weights, where + " vertex " + std::to_string(v), rig, kept_weights));
    }
  }
  finish_weights(rig, kept_weights);
  rig.model.rest_points = skin.points.transpose();
  rig.model.faces = skin.faces;
  result.rest_normals = skin.normals;
  if (Status status = validate(rig.model); !status.ok()) {
    return invalid(skin.file + ": the imported rig is invalid: " + status.error().message);
  }
  return result;
}

}  // namespace animspace::animation_space
