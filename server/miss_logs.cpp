#include "server/miss_logs.h"

#include <spdlog/spdlog.h>

#include "core/misslog/miss_frames.h"

namespace animspace::server {

MissLogs::MissLogs(std::filesystem::path directory, misslog::FsyncPolicy policy,
                   std::chrono::milliseconds fsync_interval, uint64_t max_bytes)
    : directory_(std::move(directory)), policy_(policy), fsync_interval_(fsync_interval), max_bytes_(max_bytes) {}

std::filesystem::path MissLogs::path_of(const std::string& model) const { return directory_ / (model + ".misses"); }

Result<misslog::MissLog*> MissLogs::open(const std::string& model) {
  std::lock_guard lock(mutex_);
  auto it = logs_.find(model);
  if (it != logs_.end()) return it->second.get();
  auto log = misslog::MissLog::open(path_of(model), policy_, fsync_interval_);
  if (!log) return log.error();
  (*log)->set_max_bytes(max_bytes_);
  const auto& recovery = (*log)->recovery();
  if (recovery.truncated_bytes > 0) {
    spdlog::warn("miss log {}: recovered {} records, cut {} bytes of torn tail ({})", path_of(model).string(),
                 recovery.records, recovery.truncated_bytes, recovery.reason);
  }
  return logs_.emplace(model, std::move(*log)).first->second.get();
}

int MissLogs::recover_existing() {
  int opened = 0;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(directory_, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() != ".misses" || !it->is_regular_file(ec)) continue;
    const std::string model = it->path().stem().string();
    auto log = open(model);
    if (!log) {
      spdlog::error("miss log {}: {}", it->path().string(), log.error().message);
      continue;
    }
    spdlog::info("miss log {}: {} records", it->path().string(), (*log)->record_count());
    ++opened;
  }
  return opened;
}

Result<uint64_t> MissLogs::append(const std::string& model, const pmsc::PmscModel& evaluated,
                                  misslog::MissRecord& record) {
  auto log = open(model);
  if (!log) return log.error();
  misslog::fit_to_format(evaluated, (*log)->format_version(), record);
  auto appended = (*log)->append(record);
  if (!appended && appended.error().code == ErrorCode::kResourceExhausted) {
    std::string message = appended.error().message +
                          " (--miss-log-max-bytes): blends and misses are served but not logged until the daemon "
                          "restarts with a larger bound (docs/OPERATIONS.md, \"Miss logs\")";
    // The first refusal is the one an operator needs to read; the metric counts every one.
    if (!full_warned_.exchange(true)) spdlog::warn("miss log of {}: {}", model, message);
    return make_error(ErrorCode::kResourceExhausted, std::move(message));
  }
  return appended;
}

uint64_t MissLogs::size_bytes(const std::string& model) {
  std::lock_guard lock(mutex_);
  const auto it = logs_.find(model);
  return it == logs_.end() ? 0 : it->second->size_bytes();
}

void MissLogs::sync_all() {
  std::lock_guard lock(mutex_);
  for (auto& [model, log] : logs_) {
    if (auto synced = log->sync(); !synced) spdlog::error("miss log of {}: {}", model, synced.error().message);
  }
}

}  // namespace animspace::server
