// The frames of a mesh sequence, as the command line reads them (`play` streams them, `thumbnail`
// draws them, `evaluate` scores against them) and animspace-loadtest replays them.
#pragma once

#include <string>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::tools {

// The frames (F × N·3) of a mesh sequence on disk (a folder with reference.obj + frames.pc2 or
// OBJ frames, or a mesh file with `pc2`), or the sequence.frames of a model.anim (the demo
// repository's `arm` holds the expensive rig's frames).
Result<FrameMatrix> load_sequence_frames(const std::string& sequence, const std::string& pc2);

}  // namespace animspace::tools
