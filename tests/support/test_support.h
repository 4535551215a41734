// Small helpers shared by the test suites.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace animspace::testing {

// A fresh directory under the system temporary directory, removed with its contents when the
// object goes out of scope.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// The reference data folder (../shared/data), or nullopt when it is absent; tests that need it
// call GTEST_SKIP() with a message in that case.
std::optional<std::filesystem::path> shared_data_dir();

// A TCP port on 127.0.0.1 that was free a moment ago (bound to port 0, read back, closed).
int free_tcp_port();

// Writes `text` to `path` (test fixtures only; not atomic).
void write_text_file(const std::filesystem::path& path, const std::string& text);

}  // namespace animspace::testing
