#include "clients/cpp/cli/key_frames.h"

#include <filesystem>

#include "core/container/model_container.h"
#include "core/mesh_io/sequence_io.h"
#include "core/model/model_info.h"

namespace animspace::cli {

Result<FrameMatrix> load_sequence_frames(const std::string& sequence, const std::string& pc2) {
  if (std::filesystem::path(sequence).extension() == ".anim") {
    auto container = container::read_file(sequence);
    if (!container) return container.error();
    return container->float_matrix(model::sections::kSequenceFrames);
  }
  auto loaded = mesh_io::load_sequence(sequence, pc2);
  if (!loaded) return loaded.error();
  return FrameMatrix(loaded->frames.samples);
}

Eigen::VectorXf gather_key_values(const FrameMatrix& frames, int frame, const v1::DescribeKeyPointsResponse& keys) {
  const long D = keys.channel_count();
  const auto K = static_cast<long>(keys.key_point_indices_size());
  Eigen::VectorXf out(K * D);
  for (long k = 0; k < K; ++k) {
    const long point = keys.key_point_indices(static_cast<int>(k));
    out.segment(k * D, D) = frames.row(frame).segment(point * D, D).transpose();
  }
  return out;
}

}  // namespace animspace::cli
