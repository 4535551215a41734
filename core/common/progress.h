// Progress of long offline work (training, fitting, simplification), so that a command line can
// draw a progress bar. Reported between units of work, one call at a time (a stage that runs on
// several threads reports from whichever finished a unit, never two at once); `done` ≤ `total`,
// both counted in the stage's own unit (key points, folds, collapses, vertices). An empty
// callback costs one branch.
#pragma once

#include <cstdint>
#include <functional>
#include <string_view>

namespace animspace {

using ProgressCallback = std::function<void(std::string_view stage, int64_t done, int64_t total)>;

inline void report_progress(const ProgressCallback& progress, std::string_view stage, int64_t done, int64_t total) {
  if (progress) progress(stage, done, total);
}

}  // namespace animspace
