#include "server/model_registry.h"

#include <malloc.h>
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// The sanitizer runtimes' allocator statistics (LLVM's sanitizer/allocator_interface.h, which
// GCC 12 does not install; libasan and libtsan both export the function).
extern "C" size_t __sanitizer_get_current_allocated_bytes();
#endif

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

// Bytes the allocator has handed out and not had back: glibc's arenas and mmapped blocks, or the
// sanitizer's own allocator, which replaces glibc's under ASan and TSan.
uint64_t heap_in_use() {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  return __sanitizer_get_current_allocated_bytes();
#else
  const struct mallinfo2 info = ::mallinfo2();
  return info.uordblks + info.hblkhd;
#endif
}

std::string mebibytes(uint64_t bytes) { return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / (1 << 20)); }

}  // namespace

uint64_t ModelEntry::default_version() const {
  for (auto it = versions.rbegin(); it != versions.rend(); ++it) {
    if (it->second.servable()) return it->first;
  }
  return 0;
}

ModelRegistry::ModelRegistry(std::filesystem::path repository, uint64_t resident_section_limit,
                             uint64_t memory_budget_bytes)
    : repository_(std::move(repository)),
      resident_section_limit_(resident_section_limit),
      memory_budget_bytes_(memory_budget_bytes) {}

VersionEntry ModelRegistry::load_version(const std::string& name, uint64_t version,
                                         const std::filesystem::path& dir) const {
  VersionEntry entry;
  entry.version = version;
  const auto path = dir / kModelFileName;
  std::lock_guard loading(load_mutex_);
  if (before_load_) before_load_(name, version);
  const auto started = std::chrono::steady_clock::now();
  const uint64_t heap_before = heap_in_use();
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
  // What the load left on the heap is what this version holds: the file's bytes, read whole for
  // the checksum, are freed by now. Loads are one at a time; a request running meanwhile adds
  // its own few allocations to the figure.
  const uint64_t heap_after = heap_in_use();
  loaded->resident_bytes = heap_after > heap_before ? heap_after - heap_before : 0;
  loaded->load_time =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - started);
  entry.model = std::move(loaded);
  entry.last_use->store(++use_clock_, std::memory_order_relaxed);
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
  // By name, not in the directory's order: the log reads the same on every machine, and under a
  // --memory-budget the models evicted at start-up are the first by name.
  std::sort(names.begin(), names.end());
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
      VersionEntry entry;
      entry.version = v;
      fresh.push_back(std::move(entry));
    }
  }
  // A version directory whose model file is not there yet is one being written by a tool that
  // made the directory first: it is not recorded, so the next poll looks at it again.
  std::set<uint64_t> not_written_yet;
  for (auto& entry : fresh) {
    const auto dir = repository_ / name / std::to_string(entry.version);
    std::error_code absent;
    if (!std::filesystem::exists(dir / kModelFileName, absent)) not_written_yet.insert(entry.version);
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

  std::set<std::pair<std::string, uint64_t>> just_loaded;
  {
    std::unique_lock lock(mutex_);
    ModelEntry& model = models_[name];
    model.name = name;
    for (auto& entry : fresh) {
      if (!entry.model && not_written_yet.count(entry.version)) continue;
      auto& slot = model.versions[entry.version];
      // A refused reload of a version that is serving keeps the serving copy (nothing stored is
      // lost); the refusal is still reported to the caller below.
      if (!entry.model && slot.model) continue;
      if (entry.model) just_loaded.insert({name, entry.version});
      slot = entry;
    }
  }
  keep_within_budget(just_loaded);
  if (version != 0) {
    const auto& named = fresh.front();
    if (!named.model) return make_error(ErrorCode::kFailedPrecondition, named.error);
  }
  std::shared_lock lock(mutex_);
  auto now = models_.find(name);
  if (now == models_.end()) return make_error(ErrorCode::kNotFound, "model '" + name + "' was unloaded while it loaded");
  ModelEntry entry = now->second;
  // The versions this call loaded, as it loaded them, even if a concurrent load evicted one since.
  for (const auto& loaded : fresh) {
    if (loaded.model) entry.versions[loaded.version] = loaded;
  }
  return entry;
}

void ModelRegistry::keep_within_budget(const std::set<std::pair<std::string, uint64_t>>& keep) {
  if (memory_budget_bytes_ == 0) return;
  std::vector<std::shared_ptr<const LoadedModel>> evicted;  // freed after the lock
  {
    std::unique_lock lock(mutex_);
    uint64_t resident = 0;
    struct Candidate {
      uint64_t last_use;
      const std::string* name;
      VersionEntry* entry;
    };
    std::vector<Candidate> candidates;
    for (auto& [name, model] : models_) {
      for (auto& [version, entry] : model.versions) {
        if (!entry.model) continue;
        resident += entry.model->resident_bytes;
        if (!keep.count({name, version})) {
          candidates.push_back({entry.last_use->load(std::memory_order_relaxed), &name, &entry});
        }
      }
    }
    std::sort(candidates.begin(), candidates.end(),
              [](const Candidate& a, const Candidate& b) { return a.last_use < b.last_use; });
    for (const Candidate& c : candidates) {
      if (resident <= memory_budget_bytes_) break;
      VersionEntry& entry = *c.entry;
      const LoadedModel& m = *entry.model;
      resident -= m.resident_bytes;
      spdlog::info("model {} version {} evicted ({} resident) to keep within --memory-budget {}: {} resident now; "
                   "the next request for it loads it again",
                   *c.name, entry.version, mebibytes(m.resident_bytes), mebibytes(memory_budget_bytes_),
                   mebibytes(resident));
      entry.evicted = true;
      entry.evicted_info = m.info;
      entry.evicted_file_size_bytes = m.file_size_bytes;
      entry.evicted_resident_bytes = m.resident_bytes;
      entry.evicted_load_time = m.load_time;
      evicted.push_back(std::move(entry.model));
      entry.model = nullptr;
      evictions_.fetch_add(1, std::memory_order_relaxed);
    }
  }
  if (evicted.empty()) return;
  evicted.clear();
  ::malloc_trim(0);  // as in unload(): give the evicted versions' memory back to the system now
}

void ModelRegistry::touch(const VersionEntry& entry) const {
  if (memory_budget_bytes_ != 0) entry.last_use->store(++use_clock_, std::memory_order_relaxed);
}

Result<std::shared_ptr<const LoadedModel>> ModelRegistry::reload(const std::string& name, uint64_t version,
                                                                 std::chrono::system_clock::time_point deadline,
                                                                 ReloadHint* hint) {
  const auto key = std::make_pair(name, version);
  const std::string which = "model '" + name + "' version " + std::to_string(version);
  {
    std::unique_lock waiting(reload_mutex_);
    const auto loaded_elsewhere = [&] { return reloading_.count(key) == 0; };
    if (deadline == std::chrono::system_clock::time_point::max()) {
      reloaded_.wait(waiting, loaded_elsewhere);
    } else if (!reloaded_.wait_until(waiting, deadline, loaded_elsewhere)) {
      std::chrono::milliseconds last_load{0};
      {
        std::shared_lock lock(mutex_);
        if (auto m = models_.find(name); m != models_.end()) {
          if (auto v = m->second.versions.find(version); v != m->second.versions.end()) {
            last_load = v->second.evicted_load_time;
          }
        }
      }
      const auto after = std::max(last_load, std::chrono::milliseconds{1});
      if (hint != nullptr) hint->after = after;
      return make_error(ErrorCode::kFailedPrecondition,
                        which + " is being loaded again (it was evicted to keep within the server's --memory-budget) "
                        "and the call's deadline came first; its last load took " +
                            std::to_string(last_load.count()) + " ms: retry after that");
    }
    // Nobody is loading it now: it is ours to load, unless a load we waited for left it loaded
    // (or refused, or unloaded).
    {
      std::shared_lock lock(mutex_);
      auto m = models_.find(name);
      const VersionEntry* entry = nullptr;
      if (m != models_.end()) {
        if (auto v = m->second.versions.find(version); v != m->second.versions.end()) entry = &v->second;
      }
      if (entry == nullptr) return make_error(ErrorCode::kNotFound, which + " was unloaded");
      if (entry->model) {
        touch(*entry);
        return entry->model;
      }
      if (!entry->evicted) return make_error(ErrorCode::kFailedPrecondition, which + " was refused: " + entry->error);
    }
    reloading_.insert(key);
  }
  struct Done {
    ModelRegistry& registry;
    const std::pair<std::string, uint64_t>& key;
    ~Done() {
      {
        std::lock_guard waiting(registry.reload_mutex_);
        registry.reloading_.erase(key);
      }
      registry.reloaded_.notify_all();
    }
  } done{*this, key};
  auto loaded = load(name, version);
  if (!loaded) return loaded.error();
  reloads_.fetch_add(1, std::memory_order_relaxed);
  spdlog::info("{} loaded again on request ({} resident)", which,
               mebibytes(loaded->versions.at(version).model->resident_bytes));
  return loaded->versions.at(version).model;
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

Result<std::shared_ptr<const LoadedModel>> ModelRegistry::find(const std::string& name, uint64_t version,
                                                                std::chrono::system_clock::time_point deadline,
                                                                ReloadHint* hint) {
  uint64_t wanted = 0;
  {
  std::shared_lock lock(mutex_);
  auto it = models_.find(name);
  if (it == models_.end()) {
    return make_error(ErrorCode::kNotFound, "model '" + name + "' is not loaded");
  }
  const ModelEntry& model = it->second;
  wanted = version == 0 ? model.default_version() : version;
  auto v = model.versions.find(wanted);
  if (wanted == 0 || v == model.versions.end()) {
    std::string available;
    for (const auto& [n, entry] : model.versions) {
      if (!entry.servable()) continue;
      available += (available.empty() ? "" : ", ") + std::to_string(n);
    }
    return make_error(ErrorCode::kNotFound,
                      "model '" + name + "' has no servable version " + std::to_string(version) +
                          " (available: " + (available.empty() ? "none" : available) + ")");
  }
  if (v->second.model) {
    touch(v->second);
    return v->second.model;
  }
  if (!v->second.evicted) {
    return make_error(ErrorCode::kFailedPrecondition, "model '" + name + "' version " +
                                                          std::to_string(wanted) +
                                                          " was refused: " + v->second.error);
  }
  }
  return reload(name, wanted, deadline, hint);
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

RegistryMemory ModelRegistry::memory() const {
  RegistryMemory memory;
  memory.budget_bytes = memory_budget_bytes_;
  memory.evictions = evictions_.load(std::memory_order_relaxed);
  memory.reloads = reloads_.load(std::memory_order_relaxed);
  std::shared_lock lock(mutex_);
  for (const auto& [name, entry] : models_) {
    for (const auto& [v, version] : entry.versions) {
      if (version.model) memory.resident_bytes += version.model->resident_bytes;
    }
  }
  return memory;
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
