// What the lod and scale suites share to compare simplified meshes across poses (Merry 2007
// §8.5): a subset of a model's vertices with their own skinning, meshoptimizer's rest-pose
// simplification as users run it, and the error of a simplified mesh over a set of poses.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/animspace/model.h"
#include "core/lod/surface_distance.h"

namespace animspace::bench {

// A simplified mesh: the input vertices it keeps, with their (possibly simplified) skinning, and
// its faces; and how long it took to make.
struct Simplified {
  animation_space::AnimationSpaceModel model;
  double build_seconds = 0;
};

// `model` posed by `G`, in double.
lod::Points3d posed(const animation_space::AnimationSpaceModel& model, const animation_space::TransformList& G);

// The length of the rest pose's bounding-box diagonal: what errors are divided by.
double rest_diagonal(const animation_space::AnimationSpaceModel& model);

// `model` restricted to `keep` (input vertex ids, increasing), with `faces` given in input ids.
animation_space::AnimationSpaceModel subset(const animation_space::AnimationSpaceModel& model,
                                            const std::vector<int32_t>& keep,
                                            const std::vector<std::array<int32_t, 3>>& faces);

// meshopt_simplify of the rest pose to about `target_vertices`: it targets an index count, so it
// is asked for the triangles a closed mesh of that many vertices has, with no error limit. The
// kept vertices keep their skinning, so the result poses like the input.
Simplified meshoptimizer_rest(const animation_space::AnimationSpaceModel& model, int target_vertices);

// Over `poses`: the distance from every posed input vertex to the posed simplified surface
// (lod/surface_distance.h), RMS and largest, divided by `diagonal`.
struct SurfaceError {
  double rms = 0;
  double max = 0;
};
SurfaceError measure_across_poses(const animation_space::AnimationSpaceModel& input,
                                  const animation_space::AnimationSpaceModel& simplified,
                                  const std::vector<animation_space::TransformList>& poses, double diagonal);

}  // namespace animspace::bench
