// Retraining a PMSC model from its own training frames plus the misses logged while serving it:
// "train each night, better tomorrow" (Meyer & Anderson 2007 §2.4: a miss computes the full
// values f, which are exactly the example the subspace lacked; §2.1: the basis is refit from the
// training matrix, now with those examples in it).
//
// The new training set is the old one (sequence.frames of the serving version) with the miss
// frames appended, and it becomes the new version's sequence.frames — so the next retrain starts
// from it and never needs the already-folded miss-log records again; pmsc.misses_through says
// which records those were. The training options are the ones the model was trained with
// (pmsc.options.*, pmsc_io.h), optionally with a new error bound or key budget.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/container/model_container.h"
#include "core/pmsc/train.h"

namespace animspace::pmsc {

// Metadata keys written by retrain.
inline constexpr const char* kMissesThroughKey = "pmsc.misses_through";  // largest miss-log sequence folded in
inline constexpr const char* kRetrainedFromKey = "pmsc.retrained_from";  // version the retrain started from
// Offline retrains fold in several logs at once — one per replica, each numbering its records
// from 1 — so their watermark is kept per log: pmsc.misses_through.<log>, <log> the log's path
// relative to the miss-log root ("animspaced-7f9c/crane.misses"). retrain() carries these over.
inline constexpr const char* kMissesThroughLogPrefix = "pmsc.misses_through.";

struct RetrainOptions {
  double error_bound = 0;   // > 0 overrides the stored error_bound (model units)
  int max_key_points = 0;   // > 0 overrides the stored key budget
};

struct RetrainResult {
  // Complete and servable: the model, its training report and options, the new training set as
  // sequence.frames, and everything of the old version that is not a training result.
  container::ModelContainer container;
  TrainingReport report;
  int training_frames = 0;  // rows of the new training set (old frames + misses)
  int misses_used = 0;      // rows of miss_frames
  // What changed for the soft cache, so that an operator can see why the hit rate moved
  // (issue #21): both versions' thresholds, and the hit rate of each on the new training set.
  SoftCacheThresholds previous_epsilon;
  SoftCacheThresholds epsilon;
  double previous_hit_rate = 0;
  double hit_rate = 0;
};

// The miss-log sequence number through which misses are already in the container's training
// set (metadata pmsc.misses_through): a retrain reads only newer records. 0 when absent — and
// when not a decimal integer, where re-reading folded records can only duplicate training rows,
// never lose a miss.
uint64_t misses_through(const container::ModelContainer& in);
// The same for one of several logs (kMissesThroughLogPrefix); 0 when absent.
uint64_t misses_through_log(const container::ModelContainer& in, const std::string& log);
// Sets the log's watermark to `sequence` unless it is already past it (never backwards).
void advance_misses_through_log(container::ModelContainer& out, const std::string& log, uint64_t sequence);

// Retrains the model of `current` (a pmsc container with sequence.frames and pmsc.options.*; the
// version `current_version` of its model) on its training frames plus `miss_frames` (R × N·D
// full values from the miss log, R ≥ 0; a 0-row matrix of any width means no misses).
//
// The result keeps every metadata entry of `current` outside pmsc.* (description, generator,
// units, up_axis, …) and every section outside pmsc.* (rest mesh, faces, a posing engine), except
// that other per-frame sequence.* sections (sequence.bone_transforms, …) are dropped when misses
// are added, since they no longer describe the training frames row for row. It writes the new
// pmsc.* model sections and metadata, the training report, the options actually used,
// pmsc.misses_through = max(last_miss_sequence, misses_through(current)) (never backwards, so a
// retrain without misses cannot make the next one re-read folded records) and
// pmsc.retrained_from = current_version.
//
// Errors (messages start with `source`): kFailedPrecondition for a cross-PMSC model ("cross-PMSC
// models have no full values to learn from"), a container that is not a pmsc model, one without
// sequence.frames or without stored options (load_training_options); kInvalidArgument when
// miss_frames has the wrong width ("expected N·D = …, got …") or a row with NaN/Inf, or the
// stored options disagree with pmsc.channels; the trainer's errors.
// Whether retrain() of `current` with `miss_rows` miss frames and `options` would train on
// anything but exactly the frames and options `current` was trained with. When it would not, its
// result is `current` again (training is deterministic: the same frames and options give the same
// basis, keys and ε), and there is nothing to publish — a nightly retrain that finds no completed
// miss must say so rather than serve a copy under a new version number. Errors: those of
// load_training_options.
Result<bool> retrain_changes_anything(const container::ModelContainer& current, long miss_rows,
                                      const RetrainOptions& options, const std::string& source);

Result<RetrainResult> retrain(const container::ModelContainer& current, uint64_t current_version,
                              const FrameMatrix& miss_frames, uint64_t last_miss_sequence,
                              const RetrainOptions& options, const std::string& source);

}  // namespace animspace::pmsc
