#include "bench/scratch_directory.h"

#include <stdlib.h>

#include <stdexcept>
#include <system_error>

namespace animspace::bench {

ScratchDirectory::ScratchDirectory(const std::string& suite) {
  std::string pattern = (std::filesystem::temp_directory_path() / ("animspace-bench-" + suite + "-XXXXXX")).string();
  if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed for " + pattern);
  path_ = pattern;
}

ScratchDirectory::~ScratchDirectory() {
  std::error_code ignored;
  std::filesystem::remove_all(path_, ignored);
}

}  // namespace animspace::bench
