// Where a test or a benchmark finds the programs its build made and the checkout it was built
// from. Every program of a build is in its bin/ (CMAKE_RUNTIME_OUTPUT_DIRECTORY), so a program is
// found beside the running one; the checkout's path is compiled into build_tree.cpp alone. Paths
// compiled into every file that uses them made each of those files miss the compiler cache
// whenever the checkout moved (CI's fresh clone): ccache keys a file on its command line, and its
// base_dir rewriting does not reach a -D value (docs/CI.md).
#pragma once

#include <filesystem>
#include <string_view>

namespace animspace::harness {

// `name` in the running program's folder: the program of that name this build made. Throws
// std::runtime_error when the running program's path cannot be read.
std::filesystem::path program_path(std::string_view name);

// The source tree this build was configured from.
std::filesystem::path source_dir();

}  // namespace animspace::harness
