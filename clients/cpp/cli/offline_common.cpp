#include "clients/cpp/cli/offline_common.h"

#include <algorithm>
#include <cstdio>

namespace animspace::cli {

int fail(const char* command, const std::string& message) {
  std::fprintf(stderr, "animspace %s: %s\n", command, message.c_str());
  return 2;
}

std::filesystem::path model_output_path(const std::string& output, const std::string& model, unsigned version) {
  if (model.empty()) return output;
  const std::filesystem::path dir = std::filesystem::path(output) / model;
  if (version == 0) {
    version = 1;
    std::error_code ec;
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (!name.empty() && name.find_first_not_of("0123456789") == std::string::npos && name[0] != '0') {
        version = std::max(version, static_cast<unsigned>(std::stoul(name)) + 1);
      }
    }
  }
  return dir / std::to_string(version) / "model.anim";
}

Status write_model_file(const std::filesystem::path& path, const container::ModelContainer& model) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) {
    return make_error(ErrorCode::kIo, "cannot create " + path.parent_path().string() + ": " + ec.message());
  }
  return container::write_file(path, model);
}

}  // namespace animspace::cli
