#include "clients/cpp/tools/sequence_frames.h"

#include <filesystem>

#include "core/container/model_container.h"
#include "core/mesh_io/sequence_io.h"
#include "core/container/sections.h"

namespace animspace::tools {

Result<FrameMatrix> load_sequence_frames(const std::string& sequence, const std::string& pc2) {
  if (std::filesystem::path(sequence).extension() == ".anim") {
    auto container = container::read_file(sequence);
    if (!container) return container.error();
    return container->float_matrix(container::sections::kSequenceFrames);
  }
  auto loaded = mesh_io::load_sequence(sequence, pc2);
  if (!loaded) return loaded.error();
  return FrameMatrix(loaded->frames.samples);
}

}  // namespace animspace::tools
