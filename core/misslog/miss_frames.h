// The training examples a miss log holds: the full frames of its records, for retraining
// (pmsc/retrain.h; Meyer & Anderson 2007 §2.4: a miss computes the full values f, which are
// exactly the example the subspace lacked).
#pragma once

#include <cstdint>
#include <filesystem>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::misslog {

// The full frames of a miss log's records after `after_sequence`, for pmsc::retrain() of
// `model` (served as `model_version`): records without full values (misses nobody completed)
// have nothing to teach and are skipped, counted in `skipped`; records of `model_version` whose
// full values do not repeat their key values (pmsc::check_full_values_at_keys — logs written
// before the server checked CompleteMiss may hold such a "full pose") are left out, counted in
// `inconsistent`. Records of other versions were logged against another key set and are taken as
// they are. A missing file is no misses. `last_sequence` is the newest record read (at least
// `after_sequence`). Errors: the log reader's (kDataLoss naming the path and byte offset, kIo).
//
// A partial frame (local fail-through: full values of the points listed in full_points only) is
// not a full training frame: it is completed with pmsc::complete_partial_frame — its key points
// take their key values, every other point the model's estimate f̂ for the record's key values,
// which the soft cache judged within tolerance there (Meyer & Anderson 2007 §2.4) — and counted
// in `partial`. Only a record of `model_version` can be completed (f̂ needs that model's key set);
// partial records of other versions, or whose points or value counts do not fit the model, are
// skipped. The consistency check applies to the key points among the listed points.
struct MissFrames {
  FrameMatrix frames;  // rows × point_count·D
  uint64_t last_sequence = 0;
  uint64_t skipped = 0;
  uint64_t inconsistent = 0;
  uint64_t partial = 0;  // frames completed from partial records (included in `frames`)
};
Result<MissFrames> read_miss_frames(const std::filesystem::path& path, uint64_t after_sequence,
                                    const pmsc::PmscModel& model, uint64_t model_version);

// The record as a log of `format_version` can hold it: a partial frame (full_points) in a log
// created before kFirstPartialFormatVersion becomes the whole frame retraining would complete
// from it anyway (pmsc::complete_partial_frame with the record's key values, as above), so a
// server never refuses a miss for the age of its log. `model` is the version that evaluated the
// record (not cross-PMSC when it is partial). Any other record is left as it is.
void fit_to_format(const pmsc::PmscModel& model, uint32_t format_version, MissRecord& record);

}  // namespace animspace::misslog
