// The miss log: a durable, append-only file of the poses a PMSC model served badly.
//
// When the soft cache (Meyer & Anderson 2007 §4) reports BLEND or MISS for a pose, the daemon
// appends that pose here, one file per model (`<model>.misses`); a nightly retrain then builds a
// new subspace from the original training frames plus the logged misses that carry full values
// (Meyer & Anderson 2006 §5: the subspace is only as good as the poses it was trained on).
//
// The byte layout is specified in docs/FORMATS.md, "Miss log (`<model>.misses`)": a 16-byte file
// header, then framed records (magic, payload length, CRC-32 of the payload, payload). Each
// record goes to the file in one write() at the end of the last good record, so a crash or
// kill -9 can tear at most the last record.
//
// Recovery policy (MissLog::open): records are scanned from the start; at the first record that
// is incomplete (header or payload running past the end of the file) or invalid (record magic,
// length bounds, CRC, counts, sequence not increasing) the file is cut back to the end of the
// record before it, and the reason is reported. A torn last write is the expected case. A bad
// record followed by more bytes is real corruption (a crash cannot produce it), and records
// after it are lost too: we do not try to resynchronise on the next record magic, because a
// record's float payload may contain the magic and a mis-framed "record" could pass. Losing
// logged misses costs only retraining data, never a served pose; refusing to open would stop
// the daemon from logging at all.
//
// One MissLog per file: open() takes an exclusive flock(), so a second writer (another process,
// or a second MissLog in this one) is refused rather than allowed to interleave sequences.
// read_records() takes no lock and never modifies the file; it may run while a writer appends.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/result.h"
#include "core/pmsc/soft_cache.h"

namespace animspace::misslog {

// When appended records are forced to stable storage (fdatasync).
enum class FsyncPolicy {
  kAlways,    // after every record: an acknowledged append survives power loss
  kInterval,  // after a record when the previous fsync is older than the interval, and at sync()
  kNever,     // only at sync() and close; otherwise the operating system decides
};

// "always" | "interval" | "never" (exact, lower case). Errors: kInvalidArgument naming the text
// and the accepted values.
Result<FsyncPolicy> parse_fsync_policy(std::string_view text);

// Format versions (docs/FORMATS.md). New logs are written in kFormatVersion; a log of an older
// version is read, and appended to, in its own version. Version 1 stored the API's CacheStatus
// numbers of the time (blend 2, miss 3); from version 2 the log owns its codes (blend 1, miss 2),
// so the file format depends on no wire enum. Version 3 adds partial frames (local
// fail-through): full values of the listed points only (MissRecord::full_points); its whole-frame
// records are laid out as version 2's.
inline constexpr uint32_t kFormatVersion = 3;
inline constexpr uint32_t kOldestFormatVersion = 1;
inline constexpr uint32_t kFirstPartialFormatVersion = 3;

// Format limits. A record payload is at most kMaxPayloadBytes, so that a corrupt length field
// can never ask for a giant allocation.
inline constexpr uint64_t kMaxPayloadBytes = uint64_t{1} << 30;  // 1 GiB

// One logged pose. K key points, N points, D channels; values are point-major
// (x0 y0 z0 x1 y1 z1 … for D = 3), in model units, as the request carried them.
struct MissRecord {
  uint64_t sequence = 0;       // assigned by MissLog::append: 1, 2, 3 … over the file's life
  uint64_t model_version = 0;  // the model version that produced the estimate
  int64_t unix_time_us = 0;    // set by the caller: when the pose was served
  pmsc::CacheStatus status = pmsc::CacheStatus::kMiss;  // kBlend or kMiss (a hit is never logged)
  double key_point_error = 0;  // e_key, RMS key-point error of the estimate (model units)
  double blend_weight = 0;     // α of the soft-cache blend, in [0, 1]
  uint32_t channel_count = 3;       // D ≥ 1
  std::vector<float> key_values;   // K·D
  std::vector<float> full_values;  // N·D, |full_points|·D, or empty when the full values are not known
  // Partial frame (local fail-through, format version ≥ 3): the points, ascending, whose full
  // values full_values holds. Empty: full_values is the whole frame (or empty).
  std::vector<uint32_t> full_points;
};

struct RecoveryReport {
  uint64_t records = 0;          // complete records found (and kept) when the file was opened
  uint64_t truncated_bytes = 0;  // bytes cut from the end of the file
  std::string reason;            // why the tail was cut ("… at byte X: …"); empty if not
};

class MissLog {
 public:
  // Opens `path`, or creates it (with its file header, fsyncing the directory). Scans every
  // record; a torn or corrupt tail is truncated away (ftruncate + fsync) and reported in
  // recovery(), keeping every complete record before it (see the policy above). A file of
  // fewer than 16 bytes that is a prefix of the file header (a crash during creation) is
  // completed. `fsync_interval` matters only for kInterval.
  // Errors: kDataLoss naming the path and the byte offset for a bad file header (wrong magic,
  // unsupported format version, non-zero reserved field) — the file is not modified;
  // kFailedPrecondition when another MissLog holds the file open; kIo naming the path and the
  // operating system's reason otherwise.
  static Result<std::unique_ptr<MissLog>> open(const std::filesystem::path& path,
                                               FsyncPolicy policy,
                                               std::chrono::milliseconds fsync_interval);

  ~MissLog();  // syncs if anything was written since the last sync, then closes
  MissLog(const MissLog&) = delete;
  MissLog& operator=(const MissLog&) = delete;

  // Thread-safe. Assigns record.sequence (last_sequence() + 1; also returned) and appends the
  // framed record with one write(), then fsyncs per the policy. On error record.sequence is
  // unchanged, no sequence number is used up, and the file is cut back to the end of the last
  // good record so that later appends stay readable.
  // Errors: kInvalidArgument naming the field for a record the format cannot hold or that would
  // poison retraining (channels 0, value counts not multiples of channels, full_points not
  // ascending or not matching the full values, a payload over kMaxPayloadBytes, status hit,
  // non-finite numbers); kFailedPrecondition for a partial record (full_points) in a log of a
  // format version before kFirstPartialFormatVersion; kResourceExhausted when the record would
  // take the file past the bound of set_max_bytes (the file is untouched); kIo naming the path
  // (disk full, file size limit, fsync failure).
  Result<uint64_t> append(MissRecord& record);

  // Bounds the file's size: an append that would take it past `max_bytes` is refused (0: no
  // bound, the default). A log is tomorrow's training data, not an archive: one busy client can
  // otherwise fill a disk with misses no retrain will ever read (issue #55 item 6). Thread-safe.
  void set_max_bytes(uint64_t max_bytes);
  uint64_t size_bytes() const;  // the file header and every good record

  // Forces every appended record to stable storage (whatever the policy). Thread-safe.
  // Errors: kIo naming the path.
  Status sync();

  uint64_t record_count() const;   // records in the file: recovered + appended
  uint64_t last_sequence() const;  // 0 for a log without records
  const RecoveryReport& recovery() const { return recovery_; }
  const std::filesystem::path& path() const { return path_; }
  // The file's format version: kFormatVersion for a log this build created, else the version
  // the file was created in (records are appended in it).
  uint32_t format_version() const { return format_version_; }

 private:
  MissLog(std::filesystem::path path, int fd, uint32_t format_version, FsyncPolicy policy,
          std::chrono::milliseconds fsync_interval);
  Status sync_locked();

  const std::filesystem::path path_;
  const int fd_;
  const uint32_t format_version_;
  const FsyncPolicy policy_;
  const std::chrono::milliseconds fsync_interval_;
  RecoveryReport recovery_;

  mutable std::mutex mutex_;
  uint64_t end_offset_ = 0;       // end of the last good record: where the next one goes
  uint64_t max_bytes_ = 0;        // 0: unbounded
  uint64_t record_count_ = 0;
  uint64_t last_sequence_ = 0;
  bool dirty_ = false;            // bytes written since the last successful fdatasync
  bool needs_truncate_ = false;   // a failed append left bytes past end_offset_
  std::chrono::steady_clock::time_point last_sync_;
};

struct ReadReport {
  uint64_t records = 0;             // complete records in the file, before the after_sequence filter
  uint64_t ignored_tail_bytes = 0;  // bytes after the last complete record
  std::string reason;               // why those bytes were ignored; empty if there were none
};

// Reads every complete record (sequence > `after_sequence`) without locking or modifying the
// file. Safe while a writer appends: a record still being written shows up as an ignored tail,
// reported in `report` (may be null) like MissLog::open would report it. Memory used is bounded
// by the file size.
// Errors: kNotFound if there is no file; kDataLoss naming the path and the byte offset for a bad
// file header; kIo otherwise.
Result<std::vector<MissRecord>> read_records(const std::filesystem::path& path,
                                             uint64_t after_sequence, ReadReport* report);

}  // namespace animspace::misslog
