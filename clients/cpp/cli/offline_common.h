// Helpers shared by the commands: failing with a message, output files and model versions.
#pragma once

#include <filesystem>
#include <initializer_list>
#include <string>

#include <CLI/CLI.hpp>

#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::cli {

// Prints "animspace <command>: <message>" to stderr and returns the offline commands' exit
// status for bad input or a failed step (2).
int fail(const char* command, const std::string& message);

// Empty when `output` ends in one of `extensions` (lower case with the dot, compared ignoring
// case), else the refusal "-o x.xyz: unknown extension '.xyz'; <what>: .pc2" that a command prints
// before doing any work — an output file is never written in a format its name does not say.
std::string check_output_extension(const std::string& output, std::initializer_list<const char*> extensions,
                                   const std::string& what);

// Where to write: `output` itself when `model` is empty, else
// <output>/<model>/<version>/model.anim with version 0 meaning one above the newest present.
std::filesystem::path model_output_path(const std::string& output, const std::string& model, unsigned version);

// The name of the model a file holds: <model> for <repository>/<model>/<version>/model.anim,
// else the file's stem (exported characters are named after it).
std::string model_name_of(const std::filesystem::path& model_file);

// After "wrote …" into a repository (--model given): how a daemon serving it comes to serve the new
// version (issue #55 item 8: a version built and never served looked like a failed build).
void print_serving_hint(const std::string& model);

// The options every command that writes a model shares: -o/--output (required), --model and
// --version, read by model_output_path.
void add_model_output_options(CLI::App* cmd, std::string& output, std::string& model, unsigned& version);

// Creates the parent folder and writes the container atomically.
Status write_model_file(const std::filesystem::path& path, const container::ModelContainer& model);

}  // namespace animspace::cli
