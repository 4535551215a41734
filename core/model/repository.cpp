#include "core/model/repository.h"

#include <algorithm>
#include <limits>
#include <charconv>
#include <system_error>

namespace animspace::model {

Status validate_model_name(std::string_view name, std::string_view field) {
  const std::string f(field);
  if (name.empty()) return make_error(ErrorCode::kInvalidArgument, f + " is empty");
  if (name.size() > kMaxModelNameLength) {
    return make_error(ErrorCode::kInvalidArgument, f + " is " + std::to_string(name.size()) +
                                                       " characters long, the limit is " +
                                                       std::to_string(kMaxModelNameLength));
  }
  if (name[0] == '.') {
    return make_error(ErrorCode::kInvalidArgument, f + " '" + std::string(name) + "' starts with '.'");
  }
  for (char c : name) {
    const bool allowed = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
                         c == '-' || c == '.';
    if (!allowed) {
      return make_error(ErrorCode::kInvalidArgument,
                        f + " may contain only letters, digits, '_', '-' and '.', got '" + std::string(name) + "'");
    }
  }
  return Status::Ok();
}

bool parse_version(const std::string& text, uint64_t* version) {
  if (text.empty() || text[0] == '0') return false;
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, *version);
  return ec == std::errc() && ptr == end;
}

Result<std::vector<uint64_t>> list_versions(const std::filesystem::path& repository, const std::string& name) {
  const auto dir = repository / name;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    return make_error(ErrorCode::kNotFound,
                      "model '" + name + "' has no directory in the repository (" + dir.string() + ")");
  }
  std::vector<uint64_t> versions;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    uint64_t version = 0;
    if (it->is_directory(ec) && parse_version(it->path().filename().string(), &version)) versions.push_back(version);
  }
  if (ec) return make_error(ErrorCode::kIo, "cannot list " + dir.string() + ": " + ec.message());
  std::sort(versions.begin(), versions.end());
  return versions;
}

Status check_inside_repository(const std::filesystem::path& repository, const std::filesystem::path& path) {
  std::error_code ec;
  const std::filesystem::path root = std::filesystem::canonical(repository, ec);
  if (ec) return make_error(ErrorCode::kIo, "cannot resolve the repository " + repository.string() + ": " + ec.message());
  const std::filesystem::path resolved = std::filesystem::canonical(path, ec);
  if (ec) {
    return make_error(ec == std::errc::no_such_file_or_directory ? ErrorCode::kNotFound : ErrorCode::kIo,
                      "cannot resolve " + path.string() + ": " + ec.message());
  }
  const auto [inside, rest] = std::mismatch(root.begin(), root.end(), resolved.begin(), resolved.end());
  if (inside != root.end()) {
    return make_error(ErrorCode::kFailedPrecondition,
                      path.string() + " leads to " + resolved.string() + ", outside the repository " + root.string() +
                          ": a model must be inside it (links are followed only within the repository)");
  }
  return Status::Ok();
}

Result<uint64_t> publish_version(const std::filesystem::path& repository, const std::string& name,
                                 const container::ModelContainer& model) {
  ANIMSPACE_RETURN_IF_ERROR(validate_model_name(name));
  std::error_code ec;
  std::filesystem::create_directories(repository / name, ec);
  if (ec) return make_error(ErrorCode::kIo, "cannot create " + (repository / name).string() + ": " + ec.message());
  auto versions = list_versions(repository, name);
  if (!versions) return versions.error();
  // Versions cannot wrap (issue #54): one past 2⁶⁴ − 1 would be 0, which is no version, and
  // "version 0 published" was never loaded.
  if (!versions->empty() && versions->back() == std::numeric_limits<uint64_t>::max()) {
    return make_error(ErrorCode::kOutOfRange, "model '" + name + "' already has version " +
                                                  std::to_string(versions->back()) +
                                                  ", the largest a version number can be: publish under a new model "
                                                  "name, or remove that version's directory");
  }
  const uint64_t version = versions->empty() ? 1 : versions->back() + 1;
  const auto final_dir = repository / name / std::to_string(version);
  const auto staging = repository / name / (".publish-" + std::to_string(version));
  std::filesystem::remove_all(staging, ec);
  if (!std::filesystem::create_directories(staging, ec) && ec) {
    return make_error(ErrorCode::kIo, "cannot create " + staging.string() + ": " + ec.message());
  }
  if (auto written = container::write_file(staging / kModelFileName, model); !written) {
    std::filesystem::remove_all(staging, ec);
    return written.error();
  }
  // rename(2) of a directory onto an existing non-empty one fails: a version another process
  // published meanwhile is never replaced.
  std::filesystem::rename(staging, final_dir, ec);
  if (ec) {
    const std::string reason = ec.message();
    std::filesystem::remove_all(staging, ec);
    return make_error(ErrorCode::kIo, "cannot rename " + staging.string() + " to " + final_dir.string() + ": " + reason);
  }
  return version;
}

}  // namespace animspace::model
