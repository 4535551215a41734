#include "core/animspace/animspace_io.h"

#include "core/container/sections.h"

namespace animspace::animation_space {
namespace {

using container::Float64Matrix;

Error with_source(const Error& e, const std::string& source) { return make_error(e.code, source + ": " + e.message); }

}  // namespace

TransformList rest_pose(const Skeleton& skeleton) { return skeleton.rest; }

Result<StoredMetrics> stored_metrics_from_poses(const AnimationSpaceModel& model, const std::vector<TransformList>& poses) {
  auto metrics = metrics_from_poses(model.skeleton, poses);
  if (!metrics) return metrics.error();
  auto sphere = pose_bounding_sphere(model, *metrics);
  if (!sphere) return sphere.error();
  return StoredMetrics{std::move(*metrics), *sphere};
}

void store_metrics(const StoredMetrics& stored, container::ModelContainer& out) {
  const AnimationSpaceMetrics& m = stored.metrics;
  const int b = m.bone_count();
  assert(m.P.rows() == 4L * b && static_cast<int>(m.expected_joints.size()) == b);
  out.set_matrix(sections::kExpectation, Float64Matrix(m.P));
  Float64Matrix joints(b, 16), bounds(b, 5);
  for (int j = 0; j < b; ++j) {
    joints.row(j) = pose_row({m.expected_joints[static_cast<size_t>(j)]});
    const JointBound& bound = m.joint_bounds[static_cast<size_t>(j)];
    bounds.row(j) << bound.linear_norm, bound.translation_centre.transpose(), bound.translation_radius;
  }
  out.set_matrix(sections::kExpectedJoints, joints);
  out.set_matrix(sections::kJointBounds, bounds);
  Float64Matrix sphere(1, 4);
  sphere << stored.bounding_sphere.centre.transpose(), stored.bounding_sphere.radius;
  out.set_matrix(sections::kBoundingSphere, sphere);
}

Result<StoredMetrics> load_metrics(const container::ModelContainer& in, int bone_count, const std::string& source) {
  if (!in.has_section(sections::kExpectation)) {
    return make_error(ErrorCode::kNotFound, source + ": the model stores no metrics (section '" +
                                                std::string(sections::kExpectation) + "')");
  }
  auto P = in.double_matrix(sections::kExpectation, 4 * bone_count);
  if (!P) return P.error();
  if (P->rows() != 4L * bone_count) {
    return container::section_shape_error(source, sections::kExpectation, std::to_string(4 * bone_count) + "×" + std::to_string(4 * bone_count),
                       P->rows(), P->cols());
  }
  auto joints = in.double_matrix(sections::kExpectedJoints, 16);
  if (!joints) return joints.error();
  auto bounds = in.double_matrix(sections::kJointBounds, 5);
  if (!bounds) return bounds.error();
  auto sphere = in.double_matrix(sections::kBoundingSphere, 4);
  if (!sphere) return sphere.error();
  if (joints->rows() != bone_count) {
    return container::section_shape_error(source, sections::kExpectedJoints, std::to_string(bone_count) + "×16", joints->rows(), joints->cols());
  }
  if (bounds->rows() != bone_count) {
    return container::section_shape_error(source, sections::kJointBounds, std::to_string(bone_count) + "×5", bounds->rows(), bounds->cols());
  }
  if (sphere->rows() != 1 || !sphere->allFinite() || (*sphere)(0, 3) < 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": section 'animspace.bounding_sphere' should be 1×4 finite values with radius ≥ 0");
  }
  StoredMetrics stored;
  stored.metrics.P = *P;
  for (int j = 0; j < bone_count; ++j) {
    stored.metrics.expected_joints.push_back(pose_from_row(*joints, j, 1)[0]);
    JointBound bound;
    bound.linear_norm = (*bounds)(j, 0);
    bound.translation_centre = bounds->row(j).segment<3>(1).transpose();
    bound.translation_radius = (*bounds)(j, 4);
    stored.metrics.joint_bounds.push_back(bound);
  }
  stored.bounding_sphere.centre = sphere->row(0).head<3>().transpose();
  stored.bounding_sphere.radius = (*sphere)(0, 3);
  const Status status = validate(stored.metrics, bone_count);
  if (!status.ok()) return with_source(status.error(), source);
  return stored;
}

Float64Matrix pose_row(const TransformList& globals) {
  Float64Matrix row(1, 16 * static_cast<Eigen::Index>(globals.size()));
  for (size_t j = 0; j < globals.size(); ++j) {
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) row(0, 16 * static_cast<Eigen::Index>(j) + 4 * r + c) = globals[j](r, c);
    }
  }
  return row;
}

TransformList pose_from_row(const Float64Matrix& rows, Eigen::Index row, int bone_count) {
  assert(rows.cols() == 16L * bone_count);
  TransformList globals(static_cast<size_t>(bone_count));
  for (int j = 0; j < bone_count; ++j) {
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) globals[static_cast<size_t>(j)](r, c) = rows(row, 16L * j + 4 * r + c);
    }
  }
  return globals;
}

void store_skeleton(const Skeleton& skeleton, container::ModelContainer& out) {
  out.set_matrix(container::sections::kSkeletonParents, container::as_column(skeleton.parents));
  Float64Matrix rest(skeleton.bone_count(), 16);
  for (int j = 0; j < skeleton.bone_count(); ++j) rest.row(j) = pose_row({skeleton.rest[static_cast<size_t>(j)]});
  out.set_matrix(container::sections::kSkeletonRest, rest);
}

Result<Skeleton> load_skeleton(const container::ModelContainer& in, const std::string& source) {
  auto parents = in.int_matrix(container::sections::kSkeletonParents, 1);
  if (!parents) return parents.error();
  auto rest = in.double_matrix(container::sections::kSkeletonRest, 16);
  if (!rest) return rest.error();
  if (rest->rows() != parents->rows()) {
    return container::section_shape_error(source, container::sections::kSkeletonRest, std::to_string(parents->rows()) + "×16", rest->rows(),
                       rest->cols());
  }
  Skeleton skeleton;
  skeleton.parents.assign(parents->data(), parents->data() + parents->size());
  for (Eigen::Index j = 0; j < rest->rows(); ++j) skeleton.rest.push_back(pose_from_row(*rest, j, 1)[0]);
  const Status status = validate(skeleton);
  if (!status.ok()) return with_source(status.error(), source);
  return skeleton;
}

void store_influences(const AnimationSpaceModel& model, const std::string& prefix, container::ModelContainer& out) {
  out.set_matrix(prefix + "influence_offsets", container::as_column(model.influences.offsets));
  out.set_matrix(prefix + "influence_bones", container::as_column(model.influences.bones));
  out.set_matrix(prefix + "positions", Float64Matrix(model.positions.transpose()));
  if (model.has_tangents()) {
    Float64Matrix tangents(model.positions.cols(), 8);
    tangents.leftCols<4>() = model.tangent_s.transpose();
    tangents.rightCols<4>() = model.tangent_t.transpose();
    out.set_matrix(prefix + "tangents", tangents);
  }
}

Status load_influences(const container::ModelContainer& in, const std::string& prefix, const std::string& source,
                       AnimationSpaceModel& model) {
  const std::string offsets_name = prefix + "influence_offsets";
  const std::string bones_name = prefix + "influence_bones";
  const std::string positions_name = prefix + "positions";
  const std::string tangents_name = prefix + "tangents";
  auto offsets = in.int_matrix(offsets_name, 1);
  if (!offsets) return offsets.error();
  auto bones = in.int_matrix(bones_name, 1);
  if (!bones) return bones.error();
  auto positions = in.double_matrix(positions_name, 4);
  if (!positions) return positions.error();
  if (positions->rows() != bones->rows()) {
    return container::section_shape_error(source, positions_name.c_str(), std::to_string(bones->rows()) + "×4", positions->rows(),
                       positions->cols());
  }
  model.influences.offsets.assign(offsets->data(), offsets->data() + offsets->size());
  model.influences.bones.assign(bones->data(), bones->data() + bones->size());
  model.positions = positions->transpose();
  if (in.has_section(tangents_name)) {
    auto tangents = in.double_matrix(tangents_name, 8);
    if (!tangents) return tangents.error();
    if (tangents->rows() != bones->rows()) {
      return container::section_shape_error(source, tangents_name.c_str(), std::to_string(bones->rows()) + "×8", tangents->rows(),
                         tangents->cols());
    }
    model.tangent_s = tangents->leftCols<4>().transpose();
    model.tangent_t = tangents->rightCols<4>().transpose();
  }
  return Status::Ok();
}

void store(const AnimationSpaceModel& model, container::ModelContainer& out) {
  assert(validate(model).ok());
  out.metadata()["kind"] = container::kind_name(container::ModelKind::kAnimationSpace);
  store_skeleton(model.skeleton, out);
  store_influences(model, sections::kModelPrefix, out);
  PointMatrix rest_points;
  evaluate(model, rest_pose(model.skeleton), rest_points);
  out.set_points(container::sections::kRestPoints, rest_points);
  if (model.faces.rows() > 0) out.set_faces(container::sections::kFaces, model.faces);
}

Result<AnimationSpaceModel> load(const container::ModelContainer& in, const std::string& source) {
  AnimationSpaceModel model;
  auto skeleton = load_skeleton(in, source);
  if (!skeleton) return skeleton.error();
  model.skeleton = std::move(*skeleton);

  ANIMSPACE_RETURN_IF_ERROR(load_influences(in, sections::kModelPrefix, source, model));
  if (in.has_section(container::sections::kFaces)) {
    auto faces = in.faces(container::sections::kFaces);
    if (!faces) return faces.error();
    model.faces = *faces;
  }
  const Status status = validate(model);
  if (!status.ok()) return with_source(status.error(), source);
  return model;
}

}  // namespace animspace::animation_space
