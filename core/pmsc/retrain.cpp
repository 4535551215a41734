#include "core/pmsc/retrain.h"

#include <algorithm>
#include <charconv>
#include <system_error>

#include "core/container/sections.h"
#include "core/pmsc/pmsc_io.h"

namespace animspace::pmsc {
namespace {

bool starts_with_pmsc(const std::string& name) { return name.rfind("pmsc.", 0) == 0; }

}  // namespace

namespace {

uint64_t parse_sequence(const std::string& text) {
  uint64_t value = 0;
  const char* end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, value);
  return error == std::errc() && stop == end ? value : 0;
}

}  // namespace

uint64_t misses_through(const container::ModelContainer& in) {
  return parse_sequence(in.metadata_value(kMissesThroughKey));
}

uint64_t misses_through_log(const container::ModelContainer& in, const std::string& log) {
  return parse_sequence(in.metadata_value(kMissesThroughLogPrefix + log));
}

void advance_misses_through_log(container::ModelContainer& out, const std::string& log, uint64_t sequence) {
  out.metadata()[kMissesThroughLogPrefix + log] = std::to_string(std::max(sequence, misses_through_log(out, log)));
}

Result<bool> retrain_changes_anything(const container::ModelContainer& current, long miss_rows,
                                      const RetrainOptions& options, const std::string& source) {
  if (miss_rows > 0) return true;
  auto stored = load_training_options(current, source);
  if (!stored) return stored.error();
  return (options.error_bound > 0 && options.error_bound != stored->error_bound) ||
         (options.max_key_points > 0 && options.max_key_points != stored->max_key_points);
}

Result<RetrainResult> retrain(const container::ModelContainer& current, uint64_t current_version,
                              const FrameMatrix& miss_frames, uint64_t last_miss_sequence,
                              const RetrainOptions& options, const std::string& source) {
  // What can be retrained: a PMSC model whose outputs have a full calculation, its training
  // frames and the options it was trained with.
  const std::string kind = current.metadata_value("kind");
  if (kind == container::kind_name(container::ModelKind::kCrossPmsc) || current.metadata_value("pmsc.cross") == "1") {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": cross-PMSC models have no full values to learn from");
  }
  if (kind != container::kind_name(container::ModelKind::kPmsc)) {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": only pmsc models can be retrained, this one has kind '" + kind + "'");
  }
  if (!current.has_section(container::sections::kSequenceFrames)) {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": the model keeps no training frames (section 'sequence.frames') to retrain from");
  }
  auto old_frames = current.float_matrix(container::sections::kSequenceFrames);
  if (!old_frames) return make_error(old_frames.error().code, source + ": " + old_frames.error().message);
  auto previous = load(current, source);
  if (!previous) return previous.error();
  auto training_options = load_training_options(current, source);
  if (!training_options) return training_options.error();
  TrainingOptions o = std::move(*training_options);
  auto channels = current.metadata_int("pmsc.channels");
  if (!channels) return make_error(channels.error().code, source + ": " + channels.error().message);
  if (*channels != o.channel_count) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": metadata 'pmsc.options.channels' is " + std::to_string(o.channel_count) +
                          " but the model has pmsc.channels = " + std::to_string(*channels));
  }

  // The misses: full values f of poses the soft cache could not answer (2007 §2.4).
  const Eigen::Index width = old_frames->cols();
  const Eigen::Index R = miss_frames.rows();
  if (R > 0 && miss_frames.cols() != width) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": miss frames have the wrong width (expected N·D = " + std::to_string(width) +
                          ", got " + std::to_string(miss_frames.cols()) + ")");
  }
  for (Eigen::Index r = 0; r < R; ++r) {
    if (!miss_frames.row(r).allFinite()) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": miss frame " + std::to_string(r) + " holds NaN or Inf values");
    }
  }
  if (options.error_bound > 0) o.error_bound = options.error_bound;
  if (options.max_key_points > 0) o.max_key_points = options.max_key_points;
  if (o.subspace_kind == SubspaceKind::kArticulated && current.has_section("mesh.faces")) {
    // The skinning's parts are kept spatially coherent by the mesh it was first trained with.
    auto faces = current.faces("mesh.faces");
    if (!faces) return make_error(faces.error().code, source + ": " + faces.error().message);
    o.faces = *faces;
  }

  // The new training set: old frames, then the misses. A new basis is fit to all of it (2007
  // §2.1), keys are reselected and ε recalibrated on held-out frames, exactly as the first time.
  FrameMatrix frames(old_frames->rows() + R, width);
  frames.topRows(old_frames->rows()) = *old_frames;
  if (R > 0) frames.bottomRows(R) = miss_frames;
  RetrainResult result;
  auto model = train(frames, o, &result.report);
  if (!model) return make_error(model.error().code, source + ": retraining: " + model.error().message);

  // The new container: the fresh model and its results, then everything of `current` that is
  // not a training result.
  container::ModelContainer& out = result.container;
  for (const auto& [key, value] : current.metadata()) {
    // Per-log watermarks say which records are folded in, like misses_through: never dropped.
    if (!starts_with_pmsc(key) || key.rfind(kMissesThroughLogPrefix, 0) == 0) out.metadata()[key] = value;
  }
  store(*model, out);
  store_training_report(result.report, out);
  store_training_options(o, out);
  out.metadata()[kMissesThroughKey] = std::to_string(std::max(last_miss_sequence, misses_through(current)));
  out.metadata()[kRetrainedFromKey] = std::to_string(current_version);
  copy_sections(
      current,
      [&](const std::string& name) {
        if (starts_with_pmsc(name) || name == container::sections::kSequenceFrames) return false;
        // Other sequence.* sections have one row per old training frame.
        return R == 0 || name.rfind("sequence.", 0) != 0;
      },
      out);
  out.set_matrix(container::sections::kSequenceFrames, frames);

  result.training_frames = static_cast<int>(frames.rows());
  result.misses_used = static_cast<int>(R);
  result.epsilon = model->epsilon;
  result.hit_rate = hit_rate(*model, frames);
  result.previous_epsilon = previous->epsilon;
  result.previous_hit_rate = hit_rate(*previous, frames);
  return result;
}

}  // namespace animspace::pmsc
