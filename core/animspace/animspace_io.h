// Storing an animation-space model in the model container, and loading it back for serving.
//
// Sections (docs/FORMATS.md): skeleton.parents (B × 1 i32), skeleton.rest_transforms (B × 16
// f64, Ĝ_j row-major), animspace.influence_offsets (V+1 × 1 i32), animspace.influence_bones
// (I × 1 i32), animspace.positions (I × 4 f64, p_j per influence), animspace.tangents (I × 8
// f64: s_j then t_j, optional), mesh.rest_points (V × 3 f32: the model evaluated in its rest
// pose, what DescribeModel, thumbnails and LOD start from), mesh.faces (optional); and, when
// the model's metrics are known (§3.3, §7.2), animspace.expectation (4b × 4b f64, P = E[GᵀG]),
// animspace.expected_joints (b × 16 f64, E[L_j]), animspace.joint_bounds (b × 5 f64: s, v1, r1
// of B[L_j]) and animspace.bounding_sphere (1 × 4 f64: centre, radius). The metrics are stored,
// not recomputed, because the pose distributions they came from are not kept (§3.4). Positions stay
// float64: fitting and the L2,2 metric are done in double (thesis §8.1 found even double needed
// care), and a model is small next to the frames it was fitted to.
#pragma once

#include <string>

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::animation_space {

namespace sections {
// The influence sections below are this prefix + "influence_offsets", "influence_bones",
// "positions", "tangents"; LOD levels store the same four under "lod.<l>." (core/lod/lod_io.h).
inline constexpr const char* kModelPrefix = "animspace.";
inline constexpr const char* kInfluenceOffsets = "animspace.influence_offsets";
inline constexpr const char* kInfluenceBones = "animspace.influence_bones";
inline constexpr const char* kPositions = "animspace.positions";
inline constexpr const char* kTangents = "animspace.tangents";
inline constexpr const char* kExpectation = "animspace.expectation";
inline constexpr const char* kExpectedJoints = "animspace.expected_joints";
inline constexpr const char* kJointBounds = "animspace.joint_bounds";
inline constexpr const char* kBoundingSphere = "animspace.bounding_sphere";
}  // namespace sections

// A model's metrics and the bounding sphere they give, as stored beside it.
struct StoredMetrics {
  AnimationSpaceMetrics metrics;
  geometry::BoundingSphere bounding_sphere;
};

// Writes the skeleton and model sections and mesh.rest_points / mesh.faces; sets metadata
// "kind" = "animation_space". `model` must be valid (asserted in debug builds).
void store(const AnimationSpaceModel& model, container::ModelContainer& out);

// Reads and validates (validate(AnimationSpaceModel)) a stored model. Errors name `source` and
// the section, with expected vs actual shape.
Result<AnimationSpaceModel> load(const container::ModelContainer& in, const std::string& source);

// The metrics "sampled from example poses" (metrics_from_poses, §3.3.1) and the bounding sphere
// they give (§7.2): what fitting stores with a model, since it has the poses at hand.
Result<StoredMetrics> stored_metrics_from_poses(const AnimationSpaceModel& model, const std::vector<TransformList>& poses);

// Writes the metric sections. `stored` must belong to a model with `bone_count` bones (asserted).
void store_metrics(const StoredMetrics& stored, container::ModelContainer& out);

// Reads and validates the metric sections, or nullopt-like kNotFound when the model has none.
Result<StoredMetrics> load_metrics(const container::ModelContainer& in, int bone_count, const std::string& source);

// The rest pose G_j = Ĝ_j of the model's skeleton.
TransformList rest_pose(const Skeleton& skeleton);

// The four influence sections of `model` (offsets, bones, positions, optional tangents) under
// `prefix`, and reading them back into `model` (sizes checked against each other, not validated:
// the caller validates the assembled model). Errors name `source` and the section.
void store_influences(const AnimationSpaceModel& model, const std::string& prefix, container::ModelContainer& out);
Status load_influences(const container::ModelContainer& in, const std::string& prefix, const std::string& source,
                       AnimationSpaceModel& model);

// Skeleton sections alone (shared with other kinds that carry a rig).
void store_skeleton(const Skeleton& skeleton, container::ModelContainer& out);
Result<Skeleton> load_skeleton(const container::ModelContainer& in, const std::string& source);

// A pose as stored in sequence.bone_transforms: one row of B·16 row-major 4×4 matrices.
container::Float64Matrix pose_row(const TransformList& globals);
TransformList pose_from_row(const container::Float64Matrix& rows, Eigen::Index row, int bone_count);

}  // namespace animspace::animation_space
