// What the serve and loadtest suites share: crane split into even frames (training) and odd frames
// (replayed), a PMSC model trained on the even ones with the pmsc suite's settings, and the
// temporary repository a real animspaced serves it from.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bench/bench_support.h"
#include "bench/scratch_directory.h"
#include "core/common/types.h"
#include "core/mesh_io/sequence_io.h"
#include "core/pmsc/train.h"

namespace animspace::bench {

inline constexpr const char* kCraneModelName = "crane";

// Crane interleaved (Meyer & Anderson 2007 §2): trained on frames 0, 2, 4, …, tested on 1, 3, 5, ….
struct CraneSplit {
  mesh_io::LoadedSequence sequence;  // all 175 frames
  std::vector<int> even, odd;        // frame indices
  FrameMatrix train_frames;          // the even frames, |even| × N·3
  pmsc::PmscModel model;             // unaligned, K ≤ 200, bound and tolerance from options
  pmsc::TrainingReport report;
};

// Loads <data>/crane and trains on its even frames. Prints why and returns nullopt when the data
// is absent or training fails (`suite` prefixes the message).
std::optional<CraneSplit> train_crane_even(const SuiteOptions& options, const std::string& suite);

// Writes the model as <repository>/crane/1/model.anim. Prints why and returns false on failure.
bool write_crane_repository(const CraneSplit& split, const std::filesystem::path& repository,
                            const std::string& suite);

}  // namespace animspace::bench
