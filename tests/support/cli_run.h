// Running the `animspace` command line from a test: stdout captured, stderr to a file (not a
// terminal, as in a script), the exit status; and its --json output parsed.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace animspace::testing {

struct CliRun {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// Runs `command` (a shell command line) with stderr redirected to `err_path`.
inline CliRun run_command(const std::string& command, const std::filesystem::path& err_path) {
  CliRun run;
  FILE* pipe = popen((command + " 2>" + err_path.string()).c_str(), "r");
  if (pipe == nullptr) return run;
  char buffer[4096];
  size_t n = 0;
  while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) run.out.append(buffer, n);
  const int status = pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream err(err_path);
  run.err.assign(std::istreambuf_iterator<char>(err), {});
  return run;
}

// stdout of a successful --json run as JSON (a test failure, and {}, otherwise).
inline nlohmann::json json_of(const CliRun& run) {
  EXPECT_EQ(run.exit_code, 0) << run.err;
  try {
    return nlohmann::json::parse(run.out);
  } catch (const nlohmann::json::exception& e) {
    ADD_FAILURE() << "not JSON: " << e.what() << "\n" << run.out;
    return {};
  }
}

}  // namespace animspace::testing
