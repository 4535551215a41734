// Helpers shared by the offline commands that build model versions (train-pmsc, fit, import-rig).
#pragma once

#include <filesystem>
#include <string>

#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::cli {

// Prints "animspace <command>: <message>" to stderr and returns the offline commands' exit
// status for bad input or a failed step (2).
int fail(const char* command, const std::string& message);

// Where to write: `output` itself when `model` is empty, else
// <output>/<model>/<version>/model.anim with version 0 meaning one above the newest present.
std::filesystem::path model_output_path(const std::string& output, const std::string& model, unsigned version);

// Creates the parent folder and writes the container atomically.
Status write_model_file(const std::filesystem::path& path, const container::ModelContainer& model);

}  // namespace animspace::cli
