// One entry point for "a mesh sequence on disk", whichever form it takes: a folder holding
// reference.obj + frames.pc2 (the form of ../shared/data), a reference mesh and a PC2 file
// named separately, or a folder of per-frame OBJ files.
#pragma once

#include <filesystem>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/mesh_io/pc2.h"

namespace animspace::mesh_io {

struct LoadedSequence {
  TriangleMesh reference;  // the reference mesh (first frame's connectivity)
  PointCache frames;       // F samples of reference.V.rows() points
};

// `path` is a folder (reference.obj + frames.pc2, or *.obj frames) or a reference mesh file, in
// which case `pc2` names the point cache. Errors: kNotFound for a missing file; kInvalidArgument
// when the point count of the cache differs from the reference's (naming both files and counts).
Result<LoadedSequence> load_sequence(const std::filesystem::path& path, const std::filesystem::path& pc2 = {});

}  // namespace animspace::mesh_io
