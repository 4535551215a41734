#include "server/model_registry.h"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <charconv>
#include <mutex>
#include <system_error>

#include <spdlog/spdlog.h>

#include "core/model/repository.h"

namespace animspace::server {
namespace {

int64_t unix_now_s() {
  return std::chrono::duration_cast<std::chrono::seconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

uint64_t ModelEntry::default_version() const {
  for (auto it = versions.rbegin(); it != versions.rend(); ++it) {
    if (it->second.model) return it->first;
  }
  return 0;
}

ModelRegistry::ModelRegistry(std::filesystem::path repository, uint64_t resident_section_limit)
    : repository_(std::move(repository)), resident_section_limit_(resident_section_limit) {}

VersionEntry ModelRegistry::load_version(const std::string& name, uint64_t version,
                                         const std::filesystem::path& dir) const {
  VersionEntry entry;
  entry.version = version;
  const auto path = dir / kModelFileName;
  auto container = container::read_file(path, container::ReadOptions{resident_section_limit_});
  if (!container) {
    entry.error = container.error().message;
    return entry;
  }
  auto servable = model::load_servable(*container, path.string());
  if (!servable) {
    entry.error = servable.error().message;
    return entry;
  }
  auto loaded = std::make_shared<LoadedModel>();
  static_cast<model::Servable&>(*loaded) = std::move(*servable);
  loaded->name = name;
  loaded->version = version;
  loaded->path = path;
  std::error_code ec;
  loaded->file_size_bytes = std::filesystem::file_size(path, ec);
  loaded->loaded_at_unix_s = unix_now_s();
  loaded->container = std::move(*container);
  entry.model = std::move(loaded);
  return entry;
}

Result<std::vector<uint64_t>> ModelRegistry::scan_versions(const std::string& name) const {
  return model::list_versions(repository_, name);
}

int ModelRegistry::load_all() {
  const int loaded = scan(true);
  repository_loaded_.store(true, std::memory_order_release);
  return loaded;
}

int ModelRegistry::load_new_versions() { return scan(false); }

int ModelRegistry::scan(bool retry_known) {
  std::vector<std::string> names;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(repository_, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!it->is_directory(ec)) continue;
    if (!validate_model_name(name).ok()) {
      if (retry_known) spdlog::warn("repository: skipping directory '{}': not a valid model name", name);
      continue;
    }
    names.push_back(name);
  }
  if (ec) spdlog::error("repository: cannot list {}: {}", repository_.string(), ec.message());
  int loaded = 0;
  for (const auto& name : names) {
    if (retry_known) {
      auto entry = load(name, 0);
      if (!entry) continue;
      for (const auto& [version, v] : entry->versions) loaded += v.model ? 1 : 0;
      continue;
    }
    // Polling: only versions never seen and not unloaded on purpose.
    auto versions = scan_versions(name);
    if (!versions) continue;
    for (uint64_t v : *versions) {
      {
        std::shared_lock lock(mutex_);
        const auto known = models_.find(name);
        if (known != models_.end() && known->second.versions.count(v)) continue;
        if (dismissed_.count({name, v})) continue;
      }
      loaded += load(name, v) ? 1 : 0;
    }
  }
  return loaded;
}

Result<uint64_t> ModelRegistry::publish(const std::string& name, const container::ModelContainer& model) {
  std::lock_guard publishing(publish_mutex_);
  auto version = model::publish_version(repository_, name, model);
  if (!version) return version.error();
  auto loaded = load(name, *version);
  if (!loaded) return loaded.error();
  return *version;
}

Result<ModelEntry> ModelRegistry::load(const std::string& name, uint64_t version) {
  ANIMSPACE_RETURN_IF_ERROR(validate_model_name(name));
  auto versions = scan_versions(name);
  if (!versions) return versions.error();
  if (version != 0 && std::find(versions->begin(), versions->end(), version) == versions->end()) {
    return make_error(ErrorCode::kNotFound,
                      "model '" + name + "' has no version " + std::to_string(version) + " in the repository");
  }

  // Read files without holding the lock: loading may take seconds, serving must not wait.
  std::vector<VersionEntry> fresh;
  {
    std::unique_lock lock(mutex_);
    for (uint64_t v : *versions) {
      if (version == 0 || v == version) dismissed_.erase({name, v});
    }
  }
  {
    std::shared_lock lock(mutex_);
    const auto existing = models_.find(name);
    for (uint64_t v : *versions) {
      if (version != 0 && v != version) continue;
      const bool already_loaded = existing != models_.end() && existing->second.versions.count(v) &&
                                  existing->second.versions.at(v).model;
      if (version == 0 && already_loaded) continue;
      fresh.push_back({v, nullptr, ""});
    }
  }
  for (auto& entry : fresh) {
    const auto dir = repository_ / name / std::to_string(entry.version);
    // Issue #54: nothing reached through a link out of the repository is read. (A file that is
    // not there is the loader's to report, as before.)
    if (Status inside = model::check_inside_repository(repository_, dir / kModelFileName);
        !inside.ok() && inside.error().code == ErrorCode::kFailedPrecondition) {
      entry.error = inside.error().message;
    } else {
      entry = load_version(name, entry.version, dir);
    }
    if (entry.model) {
      spdlog::info("model {} version {} loaded: {} ({} points, {} faces, {} frames, {} bytes)", name,
                   entry.version, container::kind_name(entry.model->info.kind), entry.model->info.point_count,
                   entry.model->info.face_count, entry.model->info.frame_count,
                   entry.model->file_size_bytes);
    } else {
      spdlog::error("model {} version {} refused: {}", name, entry.version, entry.error);
    }
  }

  std::unique_lock lock(mutex_);
  ModelEntry& model = models_[name];
  model.name = name;
  for (auto& entry : fresh) {
    auto& slot = model.versions[entry.version];
    // A refused reload of a version that is serving keeps the serving copy (nothing stored is
    // lost); the refusal is still reported to the caller below.
    if (!entry.model && slot.model) continue;
    slot = entry;
  }
  if (version != 0) {
    const auto& named = fresh.front();
    if (!named.model) return make_error(ErrorCode::kFailedPrecondition, named.error);
  }
  return model;
}

Status ModelRegistry::unload(const std::string& name, uint64_t version) {
  std::vector<VersionEntry> dropped;  // destroyed after the lock, then their memory returned
  {
    std::unique_lock lock(mutex_);
    auto it = models_.find(name);
    if (it == models_.end()) return make_error(ErrorCode::kNotFound, "model '" + name + "' is not loaded");
    if (version == 0) {
      for (auto& [v, entry] : it->second.versions) {
        dismissed_.insert({name, v});
        dropped.push_back(std::move(entry));
      }
      models_.erase(it);
      spdlog::info("model {} unloaded (all versions)", name);
    } else {
      const auto at = it->second.versions.find(version);
      if (at == it->second.versions.end()) {
        return make_error(ErrorCode::kNotFound,
                          "model '" + name + "' has no loaded version " + std::to_string(version));
      }
      dismissed_.insert({name, version});
      dropped.push_back(std::move(at->second));
      it->second.versions.erase(at);
      if (it->second.versions.empty()) models_.erase(it);
      spdlog::info("model {} version {} unloaded", name, version);
    }
  }
  dropped.clear();
  // glibc keeps freed heap for reuse; an unloaded model's hundreds of megabytes go back to the
  // system now (issue #54 item 9) — unless a call in flight still holds the version, whose
  // memory is freed, and kept by the allocator, when that call ends.
  ::malloc_trim(0);
  return Status::Ok();
}

Result<std::shared_ptr<const LoadedModel>> ModelRegistry::find(const std::string& name,
                                                                uint64_t version) const {
  std::shared_lock lock(mutex_);
  auto it = models_.find(name);
  if (it == models_.end()) {
    return make_error(ErrorCode::kNotFound, "model '" + name + "' is not loaded");
  }
  const ModelEntry& model = it->second;
  const uint64_t wanted = version == 0 ? model.default_version() : version;
  auto v = model.versions.find(wanted);
  if (wanted == 0 || v == model.versions.end()) {
    std::string available;
    for (const auto& [n, entry] : model.versions) {
      if (!entry.model) continue;
      available += (available.empty() ? "" : ", ") + std::to_string(n);
    }
    return make_error(ErrorCode::kNotFound,
                      "model '" + name + "' has no servable version " + std::to_string(version) +
                          " (available: " + (available.empty() ? "none" : available) + ")");
  }
  if (!v->second.model) {
    return make_error(ErrorCode::kFailedPrecondition, "model '" + name + "' version " +
                                                          std::to_string(wanted) +
                                                          " was refused: " + v->second.error);
  }
  return v->second.model;
}

Result<ModelEntry> ModelRegistry::describe(const std::string& name) const {
  std::shared_lock lock(mutex_);
  auto it = models_.find(name);
  if (it == models_.end()) return make_error(ErrorCode::kNotFound, "model '" + name + "' is not loaded");
  return it->second;
}

std::vector<ModelEntry> ModelRegistry::list() const {
  std::shared_lock lock(mutex_);
  std::vector<ModelEntry> out;
  out.reserve(models_.size());
  for (const auto& [name, entry] : models_) out.push_back(entry);
  return out;
}

int ModelRegistry::loaded_version_count() const {
  std::shared_lock lock(mutex_);
  int count = 0;
  for (const auto& [name, entry] : models_) {
    for (const auto& [v, version] : entry.versions) count += version.model ? 1 : 0;
  }
  return count;
}

}  // namespace animspace::server
