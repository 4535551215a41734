// Helpers shared by the offline commands that build model versions (train-pmsc, fit, import-rig).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/container/model_container.h"

namespace animspace::cli {

// Prints "animspace <command>: <message>" to stderr and returns the offline commands' exit
// status for bad input or a failed step (2).
int fail(const char* command, const std::string& message);

// Parses a Python-style slice "start:stop:step" (each part optional, negative counts from the
// end) over `count` items. Errors go to `error` and yield an empty list.
std::vector<int> parse_frame_selection(const std::string& text, int count, std::string* error);

// The rows of `frames` listed in `rows`, in that order.
FrameMatrix select_rows(const FrameMatrix& frames, const std::vector<int>& rows);

// Where to write: `output` itself when `model` is empty, else
// <output>/<model>/<version>/model.anim with version 0 meaning one above the newest present.
std::filesystem::path model_output_path(const std::string& output, const std::string& model, unsigned version);

// Creates the parent folder and writes the container atomically.
Status write_model_file(const std::filesystem::path& path, const container::ModelContainer& model);

}  // namespace animspace::cli
