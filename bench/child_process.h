// Running one of the project's command-line tools as a user would, measured from the outside:
// wall time and the child's own peak resident memory (wait4's rusage), so that a suite can report
// what a command costs without the bench's own memory in the figure.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace animspace::bench {

struct ChildRun {
  int exit_status = -1;         // the exit code, 128 + signal when killed, -1 when it did not start
  double seconds = 0;           // wall time from spawn to exit
  uint64_t peak_rss_bytes = 0;  // ru_maxrss of the child (its largest resident set)
};

// Runs `argv` (argv[0] a path) with stdout and stderr into `log` and waits for it.
ChildRun run_program(const std::vector<std::string>& argv, const std::filesystem::path& log);

// The whole of a text file ("" when it cannot be read): a failed child's log, a report it wrote.
std::string read_text(const std::filesystem::path& path);

}  // namespace animspace::bench
