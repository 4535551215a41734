// The training examples a miss log holds: the full frames of its records, for retraining
// (pmsc/retrain.h; Meyer & Anderson 2007 §2.4: a miss computes the full values f, which are
// exactly the example the subspace lacked).
#pragma once

#include <cstdint>
#include <filesystem>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::misslog {

// The full frames of a miss log's records after `after_sequence`, for pmsc::retrain(): records without
// full values (misses nobody completed) have nothing to teach and are skipped, counted in
// `skipped`. A missing file is no misses. `last_sequence` is the newest record read (at least
// `after_sequence`). Errors: the log reader's (kDataLoss naming the path and byte offset, kIo).
struct MissFrames {
  FrameMatrix frames;  // rows × width
  uint64_t last_sequence = 0;
  uint64_t skipped = 0;
};
Result<MissFrames> read_miss_frames(const std::filesystem::path& path, uint64_t after_sequence, long width);


}  // namespace animspace::misslog
