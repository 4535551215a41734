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
#include <filesystem>
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
  container::ModelContainer container;
};

struct VersionEntry {
  uint64_t version = 0;
  std::shared_ptr<const LoadedModel> model;  // null when the version was refused
  std::string error;                         // why it was refused
};

struct ModelEntry {
  std::string name;
  std::map<uint64_t, VersionEntry> versions;
  // Newest version that loaded, 0 when none did.
  uint64_t default_version() const;
};

using model::validate_model_name;  // core/model/repository.h

class ModelRegistry {
 public:
  explicit ModelRegistry(std::filesystem::path repository,
                         uint64_t resident_section_limit = kDefaultResidentSectionLimit);

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
  Result<std::shared_ptr<const LoadedModel>> find(const std::string& name, uint64_t version) const;

  Result<ModelEntry> describe(const std::string& name) const;
  std::vector<ModelEntry> list() const;  // sorted by name
  int loaded_version_count() const;

 private:
  int scan(bool retry_known);
  // Reads and checks one version file; never throws.
  VersionEntry load_version(const std::string& name, uint64_t version, const std::filesystem::path& dir) const;
  // Version directories under <repository>/<name>, ascending. Errors: kNotFound.
  Result<std::vector<uint64_t>> scan_versions(const std::string& name) const;

  std::atomic<bool> repository_loaded_{false};
  std::filesystem::path repository_;
  uint64_t resident_section_limit_;
  mutable std::shared_mutex mutex_;
  std::mutex publish_mutex_;  // one publish at a time, so version numbers never collide
  std::map<std::string, ModelEntry> models_;
  // Versions unloaded on purpose: the poll does not bring them back (LoadModel does).
  std::set<std::pair<std::string, uint64_t>> dismissed_;
};

}  // namespace animspace::server
