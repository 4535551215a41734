// A temporary directory for a suite's repositories and daemons, removed when the suite ends.
#pragma once

#include <filesystem>
#include <string>

namespace animspace::bench {

// `animspace-bench-<suite>-XXXXXX` under the system's temp folder, removed with everything in it
// on destruction. Throws std::runtime_error when it cannot be made.
class ScratchDirectory {
 public:
  explicit ScratchDirectory(const std::string& suite);
  ~ScratchDirectory();
  ScratchDirectory(const ScratchDirectory&) = delete;
  ScratchDirectory& operator=(const ScratchDirectory&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace animspace::bench
