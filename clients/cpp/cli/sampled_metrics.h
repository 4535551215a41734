// The metrics of a model for the offline commands that weigh error or stretch over its poses
// (build-lod, atlas): the stored P = E[GᵀG] (Merry 2007 §3.3), or — for a model that stores none,
// such as an imported rig — estimated from random joint rotations (--sample-poses).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::cli {

struct SamplePoseArgs {
  int sample_poses = 0;  // 0: the model's stored metrics
  double max_joint_angle_degrees = 35;
  unsigned seed = 1;
};

// --sample-poses, --max-joint-angle and --seed.
void add_sample_pose_options(CLI::App* cmd, SamplePoseArgs& a);

// With --sample-poses: the metrics of that many random poses, stored into `out` with where they
// came from (metadata animspace.metrics). Without: the metrics `in` stores. Errors: the
// estimate's, prefixed "--sample-poses: "; stored metrics that are missing or unreadable, with
// the advice to give --sample-poses (and `alternative`, when not empty).
Result<animation_space::StoredMetrics> model_metrics(const container::ModelContainer& in,
                                                     const animation_space::AnimationSpaceModel& model,
                                                     const SamplePoseArgs& a, const std::string& source,
                                                     container::ModelContainer& out, const std::string& alternative = "");

}  // namespace animspace::cli
