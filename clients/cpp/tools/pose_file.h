// Skeleton poses as text files, for `animspace lod --pose-file`, `animspace pose` and
// `animspace-loadtest --rpc skinning`: whitespace
// separated numbers, for each bone in model order the top three rows of its 4×4 affine matrix,
// row-major (the SkeletonPose.transforms layout); '#' starts a comment. A file may hold several
// poses one after another (B × 12 numbers each).
#pragma once

#include <string>
#include <vector>

#include "clients/cpp/results.h"
#include "core/common/result.h"

namespace animspace::tools {

// The poses in `path`. With `bone_count` 0 the whole file is one pose; otherwise the numbers
// must split into poses of bone_count × 12. Errors name the file (and line for a bad number).
Result<std::vector<SkeletonPose>> read_pose_file(const std::string& path, v1::SkeletonPose::Space space,
                                                 uint32_t bone_count = 0);

// "global" → SPACE_GLOBAL, "local" → SPACE_LOCAL (the flags' values, checked by CLI11).
v1::SkeletonPose::Space pose_space(const std::string& name);

}  // namespace animspace::tools
