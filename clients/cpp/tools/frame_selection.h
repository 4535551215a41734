// Which frames of a sequence a command works on: `--select start:stop:step`, shared by the
// command line (train-pmsc, fit, play, evaluate) and animspace-loadtest.
#pragma once

#include <string>
#include <vector>

#include "core/common/types.h"

namespace animspace::tools {

// Parses a Python-style slice "start:stop:step" (each part optional, negative counts from the
// end) over `count` items. Errors go to `error` and yield an empty list.
std::vector<int> parse_frame_selection(const std::string& text, int count, std::string* error);

// The rows of `frames` listed in `rows`, in that order.
FrameMatrix select_rows(const FrameMatrix& frames, const std::vector<int>& rows);
// The same, taking `frames` (left empty): when `rows` is every row in order they move, so a long
// sequence is never held twice.
FrameMatrix take_rows(FrameMatrix& frames, const std::vector<int>& rows);

}  // namespace animspace::tools
