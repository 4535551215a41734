// Frames of a sequence and their key points, as `play` streams them and `thumbnail` draws them.
#pragma once

#include <string>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::cli {

// The frames (F × N·3) of a mesh sequence on disk (a folder with reference.obj + frames.pc2 or
// OBJ frames, or a mesh file with `pc2`), or the sequence.frames of a model.anim (the demo
// repository's `arm` holds the expensive rig's frames).
Result<FrameMatrix> load_sequence_frames(const std::string& sequence, const std::string& pc2);

}  // namespace animspace::cli
