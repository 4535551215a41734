#include "harness/build_tree.h"

#include <stdexcept>
#include <string>
#include <system_error>

namespace animspace::harness {

std::filesystem::path program_path(std::string_view name) {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (error) throw std::runtime_error("cannot read /proc/self/exe to find " + std::string(name) + ": " + error.message());
  return self.parent_path() / name;
}

std::filesystem::path source_dir() { return ANIMSPACE_SOURCE_DIR; }

}  // namespace animspace::harness
