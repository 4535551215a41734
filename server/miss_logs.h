// The daemon's miss logs: one durable append-only file per model (core/misslog/miss_log.h),
// <miss-log-dir>/<model>.misses, opened on the model's first miss. Retraining reads them back.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "core/common/result.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::server {

class MissLogs {
 public:
  // `max_bytes` bounds each log's file (MissLog::set_max_bytes; 0: no bound).
  MissLogs(std::filesystem::path directory, misslog::FsyncPolicy policy, std::chrono::milliseconds fsync_interval,
           uint64_t max_bytes = 0);

  // Appends one record to `model`'s log (a validated model name), assigning its sequence, in
  // the form the log's format version holds (misslog::fit_to_format with `evaluated`, the model
  // version that judged it). Errors: the log's (kIo, kDataLoss for a log whose header is not ours,
  // kResourceExhausted for a full log, saying what an operator does about it).
  Result<uint64_t> append(const std::string& model, const pmsc::PmscModel& evaluated, misslog::MissRecord& record);
  // The size of `model`'s log file in bytes (0 before its first miss).
  uint64_t size_bytes(const std::string& model);

  std::filesystem::path path_of(const std::string& model) const;
  // Opens every existing log in the directory at start-up, so a torn tail left by a crash is
  // cut (and reported) before serving begins. Returns how many logs were opened.
  int recover_existing();
  // Flushes every open log to disk (shutdown).
  void sync_all();

 private:
  Result<misslog::MissLog*> open(const std::string& model);

  std::filesystem::path directory_;
  misslog::FsyncPolicy policy_;
  std::chrono::milliseconds fsync_interval_;
  uint64_t max_bytes_;
  std::atomic<bool> full_warned_{false};
  std::mutex mutex_;
  std::map<std::string, std::unique_ptr<misslog::MissLog>> logs_;
};

}  // namespace animspace::server
