// Mesh sequences stored as one OBJ file per frame (frame0001.obj, frame0002.obj, …), the form
// in which captured performances such as Vlasic et al. 2008 and Sumner & Popović 2004 are
// distributed. Every frame must have the first frame's vertex count and triangles.
#pragma once

#include <filesystem>
#include <vector>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/mesh_io/pc2.h"

namespace animspace::mesh_io {

struct MeshSequence {
  FaceMatrix F;        // #F by 3, the first file's triangles (zero-based)
  PointCache frames;   // one sample per file, in the given order; start_frame 0, sample_rate 1
};

// Reads `files` (at least one) with parse_obj. Errors: kInvalidArgument for an empty list, a
// parse error, or a file whose vertex count or triangles differ from the first file's (naming
// the file, the first differing triangle and both values); kNotFound / kIo from the reads.
Result<MeshSequence> read_obj_sequence(const std::vector<std::filesystem::path>& files);

// The *.obj files (extension in any case) directly in `directory`, in natural order: runs of
// digits compare as numbers, so frame2.obj < frame10.obj.
// Errors: kNotFound when `directory` is not a directory or holds no *.obj file; kIo when it
// cannot be listed.
Result<std::vector<std::filesystem::path>> list_obj_sequence(const std::filesystem::path& directory);

}  // namespace animspace::mesh_io
