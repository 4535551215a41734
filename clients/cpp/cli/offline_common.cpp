#include "clients/cpp/cli/offline_common.h"

#include <algorithm>
#include <cstdio>

#include "core/mesh_io/text_io.h"
#include "core/model/repository.h"

namespace animspace::cli {

int fail(const char* command, const std::string& message) {
  std::fprintf(stderr, "animspace %s: %s\n", command, message.c_str());
  return 2;
}

std::string check_output_extension(const std::string& output, std::initializer_list<const char*> extensions,
                                   const std::string& what) {
  const std::string extension = mesh_io::lowercase_extension(output);
  std::string listed;
  for (const char* allowed : extensions) {
    if (extension == allowed) return "";
    listed += (listed.empty() ? "" : ", ") + std::string(allowed);
  }
  const std::string given = std::filesystem::path(output).extension().string();
  return "-o " + output + ": " + (given.empty() ? "no extension" : "unknown extension '" + given + "'") + "; " + what +
         ": " + listed;
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

std::string model_name_of(const std::filesystem::path& model_file) {
  const std::filesystem::path version_dir = model_file.parent_path();
  uint64_t version = 0;
  if (model_file.filename() == model::kModelFileName && model::parse_version(version_dir.filename().string(), &version) &&
      !version_dir.parent_path().filename().empty()) {
    return version_dir.parent_path().filename().string();
  }
  return model_file.stem().string();
}

void print_serving_hint(const std::string& model) {
  if (model.empty()) return;
  std::printf("a daemon serving this repository loads it at its next poll (its --poll-interval-s, 30 s by "
              "default; 0 never polls), or at once with `animspace load %s`\n",
              model.c_str());
}

void add_model_output_options(CLI::App* cmd, std::string& output, std::string& model, unsigned& version) {
  cmd->add_option("-o,--output", output, "Output model.anim file, or the repository folder with --model")->required();
  cmd->add_option("--model", model, "Model name: write <output>/<model>/<version>/model.anim");
  cmd->add_option("--version", version, "Version to write (default: one above the newest)");
}

}  // namespace animspace::cli
