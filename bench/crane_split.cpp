#include "bench/crane_split.h"

#include <cstdio>

#include "core/container/model_container.h"
#include "core/pmsc/pmsc_io.h"

namespace animspace::bench {

std::optional<CraneSplit> train_crane_even(const SuiteOptions& options, const std::string& suite) {
  if (!options.data) {
    std::printf("%s: ../shared/data is absent; nothing to measure\n", suite.c_str());
    return std::nullopt;
  }
  auto sequence = mesh_io::load_sequence(*options.data / "crane");
  if (!sequence) {
    std::printf("%s: crane: %s (skipped)\n", suite.c_str(), sequence.error().message.c_str());
    return std::nullopt;
  }
  CraneSplit split;
  split.sequence = std::move(*sequence);
  const FrameMatrix& all = split.sequence.frames.samples;
  for (int f = 0; f < all.rows(); ++f) (f % 2 == 0 ? split.even : split.odd).push_back(f);
  split.train_frames.resize(static_cast<long>(split.even.size()), all.cols());
  for (size_t i = 0; i < split.even.size(); ++i) split.train_frames.row(static_cast<long>(i)) = all.row(split.even[i]);

  // The pmsc suite's settings: bound and tolerance as fractions of the reference's diagonal,
  // rigid motion left in (the `animspace train-pmsc` default), at most 200 key points.
  const auto& V = split.sequence.reference.V;
  const double diagonal = pmsc::bounding_box_diagonal(Eigen::Map<const Eigen::VectorXf>(V.data(), V.size()));
  pmsc::TrainingOptions training;
  training.error_bound = options.error_bound_diag * diagonal;
  training.error_tolerance = options.tolerance_diag * diagonal;
  training.max_key_points = 200;
  auto model = pmsc::train(split.train_frames, training, &split.report);
  if (!model) {
    std::printf("%s: crane: training failed: %s\n", suite.c_str(), model.error().message.c_str());
    return std::nullopt;
  }
  split.model = std::move(*model);
  return split;
}

bool write_crane_repository(const CraneSplit& split, const std::filesystem::path& repository,
                            const std::string& suite) {
  const auto container = pmsc::make_container(split.sequence.reference, split.train_frames, nullptr, split.model,
                                              split.report, "crane, even frames (animspace-bench " + suite + ")");
  const auto path = repository / kCraneModelName / "1" / "model.anim";
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  if (Status written = container::write_file(path, container); !written.ok()) {
    std::printf("%s: cannot write the model: %s\n", suite.c_str(), written.error().message.c_str());
    return false;
  }
  return true;
}

}  // namespace animspace::bench
