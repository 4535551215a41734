// The in-memory model registry over a model repository directory.
//
// Layout: <repository>/<model>/<version>/model.anim, version a positive integer (as in
// TensorFlow Serving and Triton). Every version found is loaded; a version that fails to load
// is recorded with its reason and never served, and the versions already serving are untouched.
// Readers take a shared_ptr snapshot of one version, so a call in flight keeps its model alive
// while a reload or unload swaps the registry underneath it.
#pragma once

#include <cstdint>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/model/repository.h"
#include "core/model/servable.h"

namespace animspace::server {

using model::kModelFileName;

// Sections of a model file larger than this stay on disk once the file has been checked
// (container::ReadOptions; --resident-section-bytes): what a loaded version holds is its runtime,
// built from the file at load, not a second copy of the file — a studio model's training frames
// (sequence.frames, read only by Retrain) are gigabytes (issue #53). What requests read from the
// container (faces, rest points, an atlas, one stored frame for a thumbnail) is read from the
// file when asked; 1 MiB keeps a typical character's faces and rest points in memory.
inline constexpr uint64_t kDefaultResidentSectionLimit = uint64_t{1} << 20;

// One loaded, immutable model version: the servable core made of its file (runtimes, engine,
// info), and where and when it was loaded.
struct LoadedModel : model::Servable {
  std::string name;
  uint64_t version = 0;
  std::filesystem::path path;
  uint64_t file_size_bytes = 0;
  int64_t loaded_at_unix_s = 0;
  // The heap the version holds (its runtimes and resident sections), measured as the growth of
  // the allocator's bytes in use across its load: what --memory-budget counts.
  uint64_t resident_bytes = 0;
  // How long its load took: the retry hint of a request that finds it loading again.
  std::chrono::milliseconds load_time{0};
  container::ModelContainer container;
};

struct VersionEntry {
  uint64_t version = 0;
  std::shared_ptr<const LoadedModel> model;  // null when the version was refused or evicted
  std::string error;                         // why it was refused
  // Issue #53: the version loaded, and was later unloaded to keep the registry within its
  // --memory-budget. It is still served: the next request for it loads it again. What it was
  // stays known for listing: its info, file size and the last measured load.
  bool evicted = false;
  model::ModelInfo evicted_info;
  uint64_t evicted_file_size_bytes = 0;
  uint64_t evicted_resident_bytes = 0;
  std::chrono::milliseconds evicted_load_time{0};
  // The registry's use clock at the version's last lookup: the least recently used loaded
  // version is evicted first. Shared by the entry's copies, bumped under a shared lock.
  std::shared_ptr<std::atomic<uint64_t>> last_use = std::make_shared<std::atomic<uint64_t>>(0);

  // Loaded now, or evicted and loaded again on request.
  bool servable() const { return model != nullptr || evicted; }
};

struct ModelEntry {
  std::string name;
  std::map<uint64_t, VersionEntry> versions;
  // Newest servable version (loaded or evicted), 0 when none loaded.
  uint64_t default_version() const;
};

// What find() tells a caller whose deadline came while the version it asked for was being
// loaded again: retry after about `after` (the version's last load time). Zero otherwise.
struct ReloadHint {
  std::chrono::milliseconds after{0};
};

// The registry's memory as --memory-budget sees it (animspace_registry_* metrics).
struct RegistryMemory {
  uint64_t budget_bytes = 0;    // 0: no budget
  uint64_t resident_bytes = 0;  // Σ resident_bytes of the versions loaded now
  uint64_t evictions = 0;       // versions unloaded to keep within the budget, since start
  uint64_t reloads = 0;         // evicted versions loaded again on request, since start
};

using model::validate_model_name;  // core/model/repository.h

class ModelRegistry {
 public:
  // memory_budget_bytes (--memory-budget; 0 = none): after every load, the least recently used
  // loaded versions are evicted until the resident bytes of those left are within it. The
  // version just loaded is never evicted by its own load, so a budget smaller than one version
  // serves one version at a time; and an evicted version a call in flight still holds is freed
  // when that call ends.
  explicit ModelRegistry(std::filesystem::path repository,
                         uint64_t resident_section_limit = kDefaultResidentSectionLimit,
                         uint64_t memory_budget_bytes = 0);

  const std::filesystem::path& repository() const { return repository_; }

  // Scans the repository and loads every model version in it. Returns the number of versions
  // that loaded; refusals are recorded in the entries (and logged).
  int load_all();
  // Whether load_all() has finished: before, a model that is not loaded may only not be loaded
  // yet (the daemon's health is NOT_SERVING meanwhile).
  bool repository_loaded() const { return repository_loaded_.load(std::memory_order_acquire); }

  // The repository poll (--poll-interval-s): loads versions that appeared since the last scan.
  // Versions already known — loaded or refused — are left alone, so a refused file is logged
  // once, not on every poll (LoadModel re-reads it on request). Returns the versions loaded.
  int load_new_versions();

  // Writes `model` as the next version of `name` (one above the newest directory) and loads it,
  // which makes it the default: calls in flight keep the version they hold, later calls get the
  // new one (hot swap). The version directory is written under a hidden temporary name and
  // renamed into place, so neither a poll nor a crash ever sees a half-written version.
  // Errors: kIo naming the path (e.g. a read-only repository), or the loader's.
  Result<uint64_t> publish(const std::string& name, const container::ModelContainer& model);

  // Loads one model: every version in its directory (version 0) or exactly one. Versions
  // already loaded are re-read only when named explicitly. Errors: kNotFound when the
  // directory does not exist; the loader's error when the one named version is refused.
  Result<ModelEntry> load(const std::string& name, uint64_t version);

  // Stops serving a model (version 0) or one version. Errors: kNotFound.
  Status unload(const std::string& name, uint64_t version);

  // The version to serve: `version`, or the default when 0. Errors: kNotFound naming the model
  // or the version (and which versions exist), kFailedPrecondition for a refused version.
  //
  // An evicted version is loaded again here (issue #53): the first caller loads it on its own
  // thread, whatever its deadline; callers meanwhile wait for that load until `deadline`. One
  // whose deadline comes first gets kFailedPrecondition "… is being loaded again …" with
  // `hint->after` set to the version's last load time — for the server, UNAVAILABLE with that
  // retry hint (model_lookup.h). A load that fails makes the version refused, as at start-up.
  Result<std::shared_ptr<const LoadedModel>> find(
      const std::string& name, uint64_t version,
      std::chrono::system_clock::time_point deadline = std::chrono::system_clock::time_point::max(),
      ReloadHint* hint = nullptr);

  Result<ModelEntry> describe(const std::string& name) const;
  std::vector<ModelEntry> list() const;  // sorted by name
  int loaded_version_count() const;
  RegistryMemory memory() const;

  // Test seam: called on the loading thread before every version file is read.
  void set_before_load_for_testing(std::function<void(const std::string& name, uint64_t version)> hook) {
    before_load_ = std::move(hook);
  }

 private:
  int scan(bool retry_known);
  // Reads and checks one version file; never throws.
  VersionEntry load_version(const std::string& name, uint64_t version, const std::filesystem::path& dir) const;
  // Version directories under <repository>/<name>, ascending. Errors: kNotFound.
  Result<std::vector<uint64_t>> scan_versions(const std::string& name) const;
  // Loads an evicted version again for find(), or waits for the load another caller started.
  Result<std::shared_ptr<const LoadedModel>> reload(const std::string& name, uint64_t version,
                                                    std::chrono::system_clock::time_point deadline,
                                                    ReloadHint* hint);
  // Evicts least recently used versions, other than `keep`, until the resident bytes are within
  // the budget. Takes the lock; frees what it evicted after releasing it.
  void keep_within_budget(const std::set<std::pair<std::string, uint64_t>>& keep);
  void touch(const VersionEntry& entry) const;

  std::atomic<bool> repository_loaded_{false};
  std::filesystem::path repository_;
  uint64_t resident_section_limit_;
  uint64_t memory_budget_bytes_;
  std::function<void(const std::string&, uint64_t)> before_load_;
  // One version file is read at a time, so that each load's heap growth is its own.
  mutable std::mutex load_mutex_;
  mutable std::atomic<uint64_t> use_clock_{0};
  std::atomic<uint64_t> evictions_{0};
  std::atomic<uint64_t> reloads_{0};
  // Evicted versions being loaded again, and the condition their waiters wait on.
  std::mutex reload_mutex_;
  std::condition_variable reloaded_;
  std::set<std::pair<std::string, uint64_t>> reloading_;
  mutable std::shared_mutex mutex_;
  std::mutex publish_mutex_;  // one publish at a time, so version numbers never collide
  std::map<std::string, ModelEntry> models_;
  // Versions unloaded on purpose: the poll does not bring them back (LoadModel does).
  std::set<std::pair<std::string, uint64_t>> dismissed_;
};

}  // namespace animspace::server
