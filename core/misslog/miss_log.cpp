// The miss log's byte layout is specified in docs/FORMATS.md ("Miss log (`<model>.misses`)");
// the constants below are that table, and the two must change together.
//
// The scanner is written for hostile input like the container parser: every length is checked
// against the bytes left in the file and against kMaxPayloadBytes before anything is allocated,
// all arithmetic is 64-bit, and every multi-byte load goes through memcpy.
#include "core/misslog/miss_log.h"

#include "core/common/posix_file.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <new>
#include <optional>
#include <utility>

#include "core/common/bytes.h"
#include "core/container/crc32.h"

namespace animspace::misslog {

// Fields are stored with memcpy as they lie in memory; a big-endian port would byte-swap in
// load/store and in the float copies.
static_assert(std::endian::native == std::endian::little,
              "the miss log code assumes a little-endian host");
static_assert(sizeof(float) == 4 && sizeof(double) == 8);

namespace {

// --- Layout (docs/FORMATS.md) ------------------------------------------------------------------

// PNG-style signature, as the model container's: the high-bit byte catches 7-bit channels,
// CR LF / LF catch newline conversion, 0x1A stops `type` on Windows.
constexpr std::string_view kFileMagic{"\x89" "MIS\r\n\x1a\n", 8};
constexpr uint64_t kFileHeaderSize = 16;
constexpr size_t kVersionAt = 8;
constexpr size_t kReservedAt = 12;

// "MREC" in a hex dump.
constexpr uint32_t kRecordMagic = 0x4345524DU;
constexpr uint64_t kRecordHeaderSize = 12;
constexpr size_t kRecordMagicAt = 0;
constexpr size_t kPayloadLengthAt = 4;
constexpr size_t kPayloadCrcAt = 8;

// Payload field offsets.
constexpr size_t kSequenceAt = 0;
constexpr size_t kModelVersionAt = 8;
constexpr size_t kUnixTimeAt = 16;
constexpr size_t kKeyPointErrorAt = 24;
constexpr size_t kBlendWeightAt = 32;
constexpr size_t kChannelsAt = 40;
constexpr size_t kStatusAt = 44;
constexpr size_t kLayoutAt = 45;  // version 3: 0 = whole frame, 1 = partial; then 2 reserved bytes
constexpr size_t kKeyCountAt = 48;
constexpr size_t kFullCountAt = 52;
constexpr uint64_t kFixedPayloadSize = 56;  // the float arrays follow

static_assert(kFullCountAt + 4 == kFixedPayloadSize);
static_assert(kMaxPayloadBytes < (uint64_t{1} << 32), "payload length is a uint32 field");

// Fuzzers cannot forge CRCs (see core/container/model_container.cpp).
#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
constexpr bool kVerifyChecksums = false;
#else
constexpr bool kVerifyChecksums = true;
#endif

std::string expected_file_header(uint32_t version = kFormatVersion) {
  std::string header(kFileHeaderSize, '\0');
  header.replace(0, kFileMagic.size(), kFileMagic);
  store_le<uint32_t>(header, kVersionAt, version);
  store_le<uint32_t>(header, kReservedAt, 0);
  return header;
}

// The status byte of each format version (miss_log.h): version 1 froze the API's numbering of
// the time, version 2 has the log's own codes.
uint8_t status_code(pmsc::CacheStatus status, uint32_t version) {
  switch (status) {
    case pmsc::CacheStatus::kBlend: return version == 1 ? 2 : 1;
    case pmsc::CacheStatus::kMiss: return version == 1 ? 3 : 2;
    case pmsc::CacheStatus::kHit: break;
  }
  return 0;  // never stored: check_record refuses a hit before encoding
}

std::optional<pmsc::CacheStatus> status_of_code(uint8_t code, uint32_t version) {
  for (const pmsc::CacheStatus status : {pmsc::CacheStatus::kBlend, pmsc::CacheStatus::kMiss}) {
    if (status_code(status, version) == code) return status;
  }
  return std::nullopt;
}

// --- System calls ------------------------------------------------------------------------------


// Reads up to `size` bytes at `offset`, stopping early only at end of file (the file may shrink
// under a concurrent reader). Returns the count read, or -errno.
int64_t read_at(int fd, char* data, uint64_t size, uint64_t offset) {
  uint64_t done = 0;
  while (done < size) {
    const ssize_t count = ::pread(fd, data + done, size - done, static_cast<off_t>(offset + done));
    if (count < 0) {
      if (errno == EINTR) continue;
      return -errno;
    }
    if (count == 0) break;
    done += static_cast<uint64_t>(count);
  }
  return static_cast<int64_t>(done);
}

// Writes all of `bytes` at `offset`: one pwrite() of the whole buffer, continued only if the
// kernel wrote part of it (a signal or the file size limit). Returns 0 or errno.
int write_at(int fd, std::string_view bytes, uint64_t offset) {
  uint64_t done = 0;
  while (done < bytes.size()) {
    const ssize_t count = ::pwrite(fd, bytes.data() + done, bytes.size() - done,
                                   static_cast<off_t>(offset + done));
    if (count < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (count == 0) return EIO;  // no progress and no reason; do not spin
    done += static_cast<uint64_t>(count);
  }
  return 0;
}

int fdatasync_retrying(int fd) {
  while (::fdatasync(fd) != 0) {
    if (errno != EINTR) return errno;
  }
  return 0;
}

int ftruncate_retrying(int fd, uint64_t size) {
  while (::ftruncate(fd, static_cast<off_t>(size)) != 0) {
    if (errno != EINTR) return errno;
  }
  return 0;
}

// A new directory entry is durable only once its directory is fsynced.
Status fsync_directory(const std::filesystem::path& path) {
  std::filesystem::path directory = path.parent_path();
  if (directory.empty()) directory = ".";
  const int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return io_error(path, "created, but cannot open its directory to fsync it", errno);
  FileDescriptor directory_file(fd);
  while (::fsync(directory_file.get()) != 0) {
    if (errno != EINTR) return io_error(path, "created, but cannot fsync its directory", errno);
  }
  return Status::Ok();
}

// --- File header -------------------------------------------------------------------------------

enum class HeaderState { kComplete, kIncomplete };
struct FileHeader {
  HeaderState state = HeaderState::kIncomplete;
  uint32_t version = kFormatVersion;  // of a complete header
};

// Checks the first min(size, 16) bytes. A file shorter than the header whose bytes are a prefix
// of it is a creation that never finished (kIncomplete); anything else that differs is kDataLoss
// naming the offset.
Result<FileHeader> check_file_header(const std::filesystem::path& path, std::string_view bytes) {
  if (bytes.size() < kFileHeaderSize) {
    // A prefix of the header of any version this build reads (the bytes present say nothing
    // about records, so the creation is completed in kFormatVersion).
    for (uint32_t version = kOldestFormatVersion; version <= kFormatVersion; ++version) {
      if (expected_file_header(version).starts_with(bytes)) return FileHeader{HeaderState::kIncomplete, kFormatVersion};
    }
    const std::string expected = expected_file_header();
    size_t i = 0;
    while (i < bytes.size() && bytes[i] == expected[i]) ++i;
    return make_error(ErrorCode::kDataLoss, path.string() + ": byte " + std::to_string(i) + ": not a miss log (" +
                                                std::to_string(bytes.size()) + "-byte file starting " +
                                                hex_bytes(bytes) + ", expected a prefix of " +
                                                hex_bytes(expected) + ")");
  }
  const std::string_view magic = bytes.substr(0, kFileMagic.size());
  if (magic != kFileMagic) {
    return make_error(ErrorCode::kDataLoss, path.string() + ": byte 0: not a miss log (magic " +
                                                hex_bytes(magic) + ", expected " +
                                                hex_bytes(kFileMagic) + ")");
  }
  const auto version = load_le<uint32_t>(bytes, kVersionAt);
  if (version < kOldestFormatVersion || version > kFormatVersion) {
    return make_error(ErrorCode::kDataLoss,
                      path.string() + ": byte " + std::to_string(kVersionAt) + ": miss log format version " +
                          std::to_string(version) + ", this build reads versions " +
                          std::to_string(kOldestFormatVersion) + " to " + std::to_string(kFormatVersion));
  }
  const auto reserved = load_le<uint32_t>(bytes, kReservedAt);
  if (reserved != 0) {
    return make_error(ErrorCode::kDataLoss, path.string() + ": byte " +
                                                std::to_string(kReservedAt) + ": reserved field " +
                                                hex32(reserved) + ", expected 0");
  }
  return FileHeader{HeaderState::kComplete, version};
}

// --- Records -----------------------------------------------------------------------------------

// Version 3's layout byte: a partial record lists its points (uint32, ascending) between the key
// and the full values. Earlier versions have no such byte (reserved, ignored).
constexpr uint8_t kWholeFrame = 0;
constexpr uint8_t kPartialFrame = 1;

uint8_t layout_of(std::string_view payload, uint32_t version) {
  return version >= kFirstPartialFormatVersion ? load_le<uint8_t>(payload, kLayoutAt) : kWholeFrame;
}

// `payload` passed check_payload in the file's `version`.
MissRecord decode_payload(std::string_view payload, uint32_t version) {
  MissRecord record;
  record.sequence = load_le<uint64_t>(payload, kSequenceAt);
  record.model_version = load_le<uint64_t>(payload, kModelVersionAt);
  record.unix_time_us = load_le<int64_t>(payload, kUnixTimeAt);
  record.key_point_error = load_le<double>(payload, kKeyPointErrorAt);
  record.blend_weight = load_le<double>(payload, kBlendWeightAt);
  record.channel_count = load_le<uint32_t>(payload, kChannelsAt);
  record.status = *status_of_code(load_le<uint8_t>(payload, kStatusAt), version);
  const auto key_count = load_le<uint32_t>(payload, kKeyCountAt);
  const auto full_count = load_le<uint32_t>(payload, kFullCountAt);
  record.key_values.resize(key_count);
  record.full_values.resize(full_count);
  const char* floats = payload.data() + kFixedPayloadSize;
  if (key_count > 0) std::memcpy(record.key_values.data(), floats, 4 * size_t{key_count});
  floats += 4 * size_t{key_count};
  if (layout_of(payload, version) == kPartialFrame) {
    record.full_points.resize(full_count / record.channel_count);
    std::memcpy(record.full_points.data(), floats, 4 * record.full_points.size());
    floats += 4 * record.full_points.size();
  }
  if (full_count > 0) std::memcpy(record.full_values.data(), floats, 4 * size_t{full_count});
  return record;
}

// What check_record looks at, from a record to append or from a payload as stored (the values
// as raw float32 bytes), so that reading checks a payload without decoding it first.
struct RecordView {
  std::optional<pmsc::CacheStatus> status;  // nullopt: a byte no status has in the file's version
  unsigned status_code = 0;                 // as stored, for messages
  uint32_t channel_count = 0;
  double key_point_error = 0;
  double blend_weight = 0;
  uint64_t key_count = 0;
  uint64_t full_count = 0;
  const char* key_bytes = nullptr;   // key_count float32
  const char* full_bytes = nullptr;  // full_count float32
  uint32_t version = kFormatVersion;        // of the file
  unsigned layout = kWholeFrame;            // as stored (version 3), for messages
  uint64_t full_point_count = 0;            // partial records: the points listed
  const char* full_point_bytes = nullptr;   // full_point_count uint32
};

RecordView view_of(const MissRecord& record, uint32_t version) {
  return {record.status,
          status_code(record.status, version),
          record.channel_count,
          record.key_point_error,
          record.blend_weight,
          record.key_values.size(),
          record.full_values.size(),
          reinterpret_cast<const char*>(record.key_values.data()),
          reinterpret_cast<const char*>(record.full_values.data()),
          version,
          record.full_points.empty() ? kWholeFrame : kPartialFrame,
          record.full_points.size(),
          reinterpret_cast<const char*>(record.full_points.data())};
}

// `payload` is as long as its counts say (check_payload has checked).
RecordView view_of_payload(std::string_view payload, uint32_t version) {
  const uint64_t key_count = load_le<uint32_t>(payload, kKeyCountAt);
  const uint64_t full_count = load_le<uint32_t>(payload, kFullCountAt);
  const uint32_t channels = load_le<uint32_t>(payload, kChannelsAt);
  const uint8_t layout = layout_of(payload, version);
  const uint64_t points = layout == kPartialFrame && channels > 0 ? full_count / channels : 0;
  const char* floats = payload.data() + kFixedPayloadSize;
  const uint8_t code = load_le<uint8_t>(payload, kStatusAt);
  return {status_of_code(code, version),
          code,
          channels,
          load_le<double>(payload, kKeyPointErrorAt),
          load_le<double>(payload, kBlendWeightAt),
          key_count,
          full_count,
          floats,
          floats + 4 * (key_count + points),
          version,
          layout,
          points,
          floats + 4 * key_count};
}

// The payload length of a record with these counts.
uint64_t payload_length(uint64_t key_count, uint64_t full_count, uint64_t full_point_count) {
  return kFixedPayloadSize + 4 * (key_count + full_point_count + full_count);
}

// The index of the first non-finite of `count` float32 stored from `bytes` on, or -1.
int64_t first_non_finite(const char* bytes, uint64_t count) {
  for (uint64_t i = 0; i < count; ++i) {
    float value = 0;
    std::memcpy(&value, bytes + 4 * i, sizeof value);
    if (!std::isfinite(value)) return static_cast<int64_t>(i);
  }
  return -1;
}

// Refuses what the format cannot hold or what would poison retraining (STYLE.md §5: no silent
// clamping). Returns the payload length.
Result<uint64_t> check_record(const RecordView& record) {
  if (!record.status || *record.status == pmsc::CacheStatus::kHit) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record status " +
                          (record.status ? std::string(pmsc::cache_status_name(*record.status))
                                         : "code " + std::to_string(record.status_code)) +
                          ", expected blend or miss");
  }
  if (record.channel_count == 0) {
    return make_error(ErrorCode::kInvalidArgument, "miss record channel_count is 0, expected ≥ 1");
  }
  if (record.key_count % record.channel_count != 0 || record.full_count % record.channel_count != 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record key_values (" + std::to_string(record.key_count) +
                          ") and full_values (" + std::to_string(record.full_count) +
                          ") must be multiples of channel_count (" + std::to_string(record.channel_count) +
                          ")");
  }
  if (record.layout != kWholeFrame) {
    if (record.version < kFirstPartialFormatVersion) {
      return make_error(ErrorCode::kFailedPrecondition,
                        "miss record full_points: a log of format version " + std::to_string(record.version) +
                            " holds whole frames only (partial frames need version " +
                            std::to_string(kFirstPartialFormatVersion) + ")");
    }
    if (record.layout != kPartialFrame) {
      return make_error(ErrorCode::kInvalidArgument,
                        "miss record layout " + std::to_string(record.layout) + ", expected 0 or 1");
    }
    if (record.full_point_count == 0 || record.full_count != record.full_point_count * record.channel_count) {
      return make_error(ErrorCode::kInvalidArgument,
                        "miss record full_values (" + std::to_string(record.full_count) + ") must be " +
                            std::to_string(record.channel_count) + " values for each of the " +
                            std::to_string(record.full_point_count) + " full_points (at least one)");
    }
    uint32_t previous = 0;
    for (uint64_t j = 0; j < record.full_point_count; ++j) {
      uint32_t point = 0;
      std::memcpy(&point, record.full_point_bytes + 4 * j, sizeof point);
      if (j > 0 && point <= previous) {
        return make_error(ErrorCode::kInvalidArgument,
                          "miss record full_points[" + std::to_string(j) + "] = " + std::to_string(point) +
                              " does not follow " + std::to_string(previous) + " (ascending, no repeats)");
      }
      previous = point;
    }
  }
  const uint64_t length = payload_length(record.key_count, record.full_count, record.full_point_count);
  if (length > kMaxPayloadBytes) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record of " + std::to_string(record.key_count) + " key and " +
                          std::to_string(record.full_count) +
                          " full values needs a payload of " + std::to_string(length) +
                          " bytes, more than the format's " + std::to_string(kMaxPayloadBytes));
  }
  if (!std::isfinite(record.key_point_error) || !std::isfinite(record.blend_weight)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record key_point_error and blend_weight must be finite");
  }
  if (const int64_t i = first_non_finite(record.key_bytes, record.key_count); i >= 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record key_values[" + std::to_string(i) + "] is not finite");
  }
  if (const int64_t i = first_non_finite(record.full_bytes, record.full_count); i >= 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "miss record full_values[" + std::to_string(i) + "] is not finite");
  }
  return length;
}

// Checks a payload whose CRC matched; returns an empty string or what is wrong.
std::string check_payload(std::string_view payload, uint64_t previous_sequence, uint32_t version) {
  const auto sequence = load_le<uint64_t>(payload, kSequenceAt);
  const auto channels = load_le<uint32_t>(payload, kChannelsAt);
  const auto key_count = load_le<uint32_t>(payload, kKeyCountAt);
  const auto full_count = load_le<uint32_t>(payload, kFullCountAt);
  if (channels == 0) return "channels is 0";
  const bool partial = layout_of(payload, version) == kPartialFrame;
  const uint64_t points = partial ? full_count / channels : 0;
  const uint64_t expected_length = payload_length(key_count, full_count, points);
  if (expected_length != payload.size()) {
    return "payload length " + std::to_string(payload.size()) + " does not match " +
           std::to_string(key_count) + " key and " + std::to_string(full_count) + " full values" +
           (partial ? " of " + std::to_string(points) + " listed points" : std::string()) + " (expected " +
           std::to_string(expected_length) + ")";
  }
  if (key_count % channels != 0 || full_count % channels != 0) {
    return std::to_string(key_count) + " key and " + std::to_string(full_count) +
           " full values are not multiples of " + std::to_string(channels) + " channels";
  }
  if (sequence <= previous_sequence) {
    return "sequence " + std::to_string(sequence) + " does not follow " +
           std::to_string(previous_sequence);
  }
  // What append refuses to write is refused when read, too: a status that is neither blend nor
  // miss, or a non-finite value, would otherwise reach retraining.
  if (const auto valid = check_record(view_of_payload(payload, version)); !valid.ok()) return valid.error().message;
  return {};
}

struct ScanResult {
  uint64_t records = 0;
  uint64_t last_sequence = 0;
  uint64_t end_offset = kFileHeaderSize;  // end of the last good record
  std::string reason;                     // why scanning stopped before `file_size`
};

// Walks the records from the file header to `file_size`, calling `on_record` with each valid
// payload, and stops at the first incomplete or invalid one (the recovery policy in
// miss_log.h). Allocates at most one payload, never more than the bytes left in the file.
Result<ScanResult> scan_records(int fd, uint64_t file_size, uint32_t version, const std::filesystem::path& path,
                                const std::function<void(std::string_view)>& on_record) {
  ScanResult scan;
  std::string header(kRecordHeaderSize, '\0');
  std::string payload;
  while (scan.end_offset < file_size) {
    const uint64_t at = scan.end_offset;
    const std::string where = " at byte " + std::to_string(at) + ": ";
    const uint64_t remaining = file_size - at;
    if (remaining < kRecordHeaderSize) {
      scan.reason = "torn record" + where + std::to_string(remaining) +
                    " bytes left, a record header needs " + std::to_string(kRecordHeaderSize);
      break;
    }
    const int64_t header_read = read_at(fd, header.data(), kRecordHeaderSize, at);
    if (header_read < 0) return io_error(path, "cannot read", static_cast<int>(-header_read));
    if (static_cast<uint64_t>(header_read) < kRecordHeaderSize) {
      scan.reason = "torn record" + where + "the file ended inside the record header";
      break;
    }
    const auto magic = load_le<uint32_t>(header, kRecordMagicAt);
    const auto length = uint64_t{load_le<uint32_t>(header, kPayloadLengthAt)};
    const auto stored_crc = load_le<uint32_t>(header, kPayloadCrcAt);
    if (magic != kRecordMagic) {
      scan.reason = "corrupt record" + where + "record magic " + hex32(magic) + ", expected " +
                    hex32(kRecordMagic);
      break;
    }
    if (length < kFixedPayloadSize || length > kMaxPayloadBytes) {
      scan.reason = "corrupt record" + where + "payload length " + std::to_string(length) +
                    " outside [" + std::to_string(kFixedPayloadSize) + ", " +
                    std::to_string(kMaxPayloadBytes) + "]";
      break;
    }
    if (length > remaining - kRecordHeaderSize) {
      scan.reason = "torn record" + where + "payload length " + std::to_string(length) +
                    " runs past the end of the file (" +
                    std::to_string(remaining - kRecordHeaderSize) + " bytes left)";
      break;
    }
    payload.resize(length);
    const int64_t payload_read = read_at(fd, payload.data(), length, at + kRecordHeaderSize);
    if (payload_read < 0) return io_error(path, "cannot read", static_cast<int>(-payload_read));
    if (static_cast<uint64_t>(payload_read) < length) {
      scan.reason = "torn record" + where + "the file ended inside the payload";
      break;
    }
    const uint32_t actual_crc = container::crc32(payload);
    if (kVerifyChecksums && actual_crc != stored_crc) {
      scan.reason = "corrupt record" + where + "payload CRC " + hex32(actual_crc) +
                    ", stored " + hex32(stored_crc);
      break;
    }
    if (std::string problem = check_payload(payload, scan.last_sequence, version); !problem.empty()) {
      scan.reason = "corrupt record" + where + problem;
      break;
    }
    on_record(payload);
    scan.last_sequence = load_le<uint64_t>(payload, kSequenceAt);
    scan.records += 1;
    scan.end_offset = at + kRecordHeaderSize + length;
  }
  return scan;
}

// The framed record (header + payload) with the sequence field and CRC left to fill in.
std::string encode_unsealed(const MissRecord& record, uint64_t payload_length, uint32_t version) {
  std::string framed(kRecordHeaderSize + payload_length, '\0');
  store_le<uint32_t>(framed, kRecordMagicAt, kRecordMagic);
  store_le<uint32_t>(framed, kPayloadLengthAt, static_cast<uint32_t>(payload_length));
  const size_t p = kRecordHeaderSize;
  store_le<uint64_t>(framed, p + kModelVersionAt, record.model_version);
  store_le<int64_t>(framed, p + kUnixTimeAt, record.unix_time_us);
  store_le<double>(framed, p + kKeyPointErrorAt, record.key_point_error);
  store_le<double>(framed, p + kBlendWeightAt, record.blend_weight);
  store_le<uint32_t>(framed, p + kChannelsAt, record.channel_count);
  store_le<uint8_t>(framed, p + kStatusAt, status_code(record.status, version));
  if (!record.full_points.empty()) store_le<uint8_t>(framed, p + kLayoutAt, kPartialFrame);
  store_le<uint32_t>(framed, p + kKeyCountAt, static_cast<uint32_t>(record.key_values.size()));
  store_le<uint32_t>(framed, p + kFullCountAt, static_cast<uint32_t>(record.full_values.size()));
  char* floats = framed.data() + p + kFixedPayloadSize;
  if (!record.key_values.empty()) {
    std::memcpy(floats, record.key_values.data(), 4 * record.key_values.size());
  }
  floats += 4 * record.key_values.size();
  if (!record.full_points.empty()) {
    std::memcpy(floats, record.full_points.data(), 4 * record.full_points.size());
    floats += 4 * record.full_points.size();
  }
  if (!record.full_values.empty()) std::memcpy(floats, record.full_values.data(), 4 * record.full_values.size());
  return framed;
}

void seal(std::string& framed, uint64_t sequence) {
  store_le<uint64_t>(framed, kRecordHeaderSize + kSequenceAt, sequence);
  const std::string_view payload = std::string_view(framed).substr(kRecordHeaderSize);
  store_le<uint32_t>(framed, kPayloadCrcAt, container::crc32(payload));
}

Result<uint64_t> file_size_of(int fd, const std::filesystem::path& path) {
  struct stat info {};
  if (::fstat(fd, &info) != 0) return io_error(path, "cannot stat", errno);
  if (!S_ISREG(info.st_mode)) {
    return make_error(ErrorCode::kIo, path.string() + ": not a regular file");
  }
  return static_cast<uint64_t>(info.st_size);
}

// The first min(size, 16) bytes of the file.
Result<std::string> read_header_bytes(int fd, uint64_t file_size,
                                      const std::filesystem::path& path) {
  std::string bytes(std::min(file_size, kFileHeaderSize), '\0');
  const int64_t count = read_at(fd, bytes.data(), bytes.size(), 0);
  if (count < 0) return io_error(path, "cannot read", static_cast<int>(-count));
  bytes.resize(static_cast<size_t>(count));
  return bytes;
}

}  // namespace

Result<FsyncPolicy> parse_fsync_policy(std::string_view text) {
  if (text == "always") return FsyncPolicy::kAlways;
  if (text == "interval") return FsyncPolicy::kInterval;
  if (text == "never") return FsyncPolicy::kNever;
  return make_error(ErrorCode::kInvalidArgument, "miss log fsync policy \"" + std::string(text) +
                                                     "\", expected always, interval or never");
}

MissLog::MissLog(std::filesystem::path path, int fd, uint32_t format_version, FsyncPolicy policy,
                 std::chrono::milliseconds fsync_interval)
    : path_(std::move(path)),
      fd_(fd),
      format_version_(format_version),
      policy_(policy),
      fsync_interval_(fsync_interval),
      last_sync_(std::chrono::steady_clock::now()) {}

MissLog::~MissLog() {
  {
    std::lock_guard lock(mutex_);
    // A destructor cannot report the error; callers that care call sync() first.
    (void)sync_locked();
  }
  ::close(fd_);  // releases the flock
}

Result<std::unique_ptr<MissLog>> MissLog::open(const std::filesystem::path& path,
                                               FsyncPolicy policy,
                                               std::chrono::milliseconds fsync_interval) {
  // O_EXCL first, to know whether the directory entry is new and must be made durable.
  bool created = true;
  int raw_fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (raw_fd < 0 && errno == EEXIST) {
    created = false;
    raw_fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  }
  if (raw_fd < 0) return io_error(path, "cannot open miss log", errno);
  FileDescriptor file(raw_fd);

  // One writer per file: two would hand out the same sequence numbers and overwrite each other.
  while (::flock(file.get(), LOCK_EX | LOCK_NB) != 0) {
    if (errno == EINTR) continue;
    if (errno == EWOULDBLOCK) {
      return make_error(ErrorCode::kFailedPrecondition,
                        path.string() + ": miss log is already open for writing (by this or "
                                        "another process)");
    }
    return io_error(path, "cannot lock miss log", errno);
  }

  auto size = file_size_of(file.get(), path);
  if (!size.ok()) return size.error();
  auto header = read_header_bytes(file.get(), *size, path);
  if (!header.ok()) return header.error();
  auto state = check_file_header(path, *header);
  if (!state.ok()) return state.error();  // nothing has been written

  RecoveryReport recovery;
  uint64_t end_offset = kFileHeaderSize;
  uint64_t last_sequence = 0;
  if (state->state == HeaderState::kIncomplete) {
    // New, or a creation cut short: the bytes present are a prefix of the header; complete it.
    if (!header->empty()) {
      recovery.reason = "incomplete file header (" + std::to_string(header->size()) + " of " +
                        std::to_string(kFileHeaderSize) + " bytes), completed";
    }
    if (int e = write_at(file.get(), expected_file_header(), 0); e != 0) {
      return io_error(path, "cannot write miss log header", e);
    }
    if (int e = fdatasync_retrying(file.get()); e != 0) {
      return io_error(path, "cannot fsync miss log header", e);
    }
  } else {
    ScanResult scan;
    try {
      auto scanned = scan_records(file.get(), *size, state->version, path, [](std::string_view) {});
      if (!scanned.ok()) return scanned.error();
      scan = std::move(*scanned);
    } catch (const std::bad_alloc&) {
      return io_error(path, "cannot scan miss log", ENOMEM);
    }
    recovery.records = scan.records;
    end_offset = scan.end_offset;
    last_sequence = scan.last_sequence;
    if (scan.end_offset < *size) {
      // Cut the tail so that the next record follows the last good one; make the cut durable
      // before anything is appended after it.
      if (int e = ftruncate_retrying(file.get(), scan.end_offset); e != 0) {
        return io_error(path, "cannot truncate the damaged tail (" + scan.reason + ")", e);
      }
      if (int e = fdatasync_retrying(file.get()); e != 0) {
        return io_error(path, "cannot fsync after truncating the damaged tail", e);
      }
      recovery.truncated_bytes = *size - scan.end_offset;
      recovery.reason = std::move(scan.reason);
    }
  }
  if (created) ANIMSPACE_RETURN_IF_ERROR(fsync_directory(path));

  std::unique_ptr<MissLog> log(new MissLog(path, file.release(), state->version, policy, fsync_interval));
  log->recovery_ = std::move(recovery);
  log->end_offset_ = end_offset;
  log->record_count_ = log->recovery_.records;
  log->last_sequence_ = last_sequence;
  return log;
}

void MissLog::set_max_bytes(uint64_t max_bytes) {
  std::lock_guard lock(mutex_);
  max_bytes_ = max_bytes;
}

uint64_t MissLog::size_bytes() const {
  std::lock_guard lock(mutex_);
  return end_offset_;
}

Result<uint64_t> MissLog::append(MissRecord& record) {
  auto length = check_record(view_of(record, format_version_));
  if (!length.ok()) return length.error();
  std::string framed;
  try {
    framed = encode_unsealed(record, *length, format_version_);
  } catch (const std::bad_alloc&) {
    return io_error(path_, "cannot encode miss record", ENOMEM);
  }

  std::lock_guard lock(mutex_);
  if (max_bytes_ > 0 && end_offset_ + framed.size() > max_bytes_) {
    return make_error(ErrorCode::kResourceExhausted,
                      path_.string() + ": the miss log is full: it holds " + std::to_string(end_offset_) +
                          " bytes and a record of " + std::to_string(framed.size()) +
                          " bytes would pass its bound of " + std::to_string(max_bytes_) + " bytes");
  }
  if (needs_truncate_) {
    if (int e = ftruncate_retrying(fd_, end_offset_); e != 0) {
      return io_error(path_, "cannot truncate the remains of a failed append", e);
    }
    needs_truncate_ = false;
  }
  const uint64_t sequence = last_sequence_ + 1;
  seal(framed, sequence);
  if (int e = write_at(fd_, framed, end_offset_); e != 0) {
    // Cut the partial record so that the next append follows the last good one; if even that
    // fails, retry before the next append (pwrite at end_offset_ would otherwise leave the
    // partial record's tail behind a shorter record).
    needs_truncate_ = ftruncate_retrying(fd_, end_offset_) != 0;
    return io_error(path_, "cannot append miss record " + std::to_string(sequence), e);
  }
  end_offset_ += framed.size();
  last_sequence_ = sequence;
  record_count_ += 1;
  dirty_ = true;
  record.sequence = sequence;

  const bool sync_now =
      policy_ == FsyncPolicy::kAlways ||
      (policy_ == FsyncPolicy::kInterval &&
       std::chrono::steady_clock::now() - last_sync_ >= fsync_interval_);
  if (sync_now) {
    // The record is in the file (and its sequence used); only its durability is in doubt.
    if (Status synced = sync_locked(); !synced.ok()) {
      return make_error(ErrorCode::kIo, "appended miss record " + std::to_string(sequence) +
                                            ", but " + synced.error().message);
    }
  }
  return sequence;
}

Status MissLog::sync() {
  std::lock_guard lock(mutex_);
  return sync_locked();
}

Status MissLog::sync_locked() {
  if (!dirty_) return Status::Ok();
  if (int e = fdatasync_retrying(fd_); e != 0) return io_error(path_, "cannot fsync miss log", e);
  dirty_ = false;
  last_sync_ = std::chrono::steady_clock::now();
  return Status::Ok();
}

uint64_t MissLog::record_count() const {
  std::lock_guard lock(mutex_);
  return record_count_;
}

uint64_t MissLog::last_sequence() const {
  std::lock_guard lock(mutex_);
  return last_sequence_;
}

Result<std::vector<MissRecord>> read_records(const std::filesystem::path& path,
                                             uint64_t after_sequence, ReadReport* report) {
  const int raw_fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (raw_fd < 0) {
    if (errno == ENOENT) return make_error(ErrorCode::kNotFound, path.string() + ": no such file");
    return io_error(path, "cannot open miss log", errno);
  }
  FileDescriptor file(raw_fd);
  // Records appended after this point are not read: a snapshot of the size bounds the scan.
  auto size = file_size_of(file.get(), path);
  if (!size.ok()) return size.error();
  auto header = read_header_bytes(file.get(), *size, path);
  if (!header.ok()) return header.error();
  auto state = check_file_header(path, *header);
  if (!state.ok()) return state.error();

  ReadReport local;
  std::vector<MissRecord> records;
  if (state->state == HeaderState::kIncomplete) {
    // A writer is creating the file right now (or crashed doing so): no records yet.
    local.ignored_tail_bytes = header->size();
    if (!header->empty()) {
      local.reason = "incomplete file header (" + std::to_string(header->size()) + " of " +
                     std::to_string(kFileHeaderSize) + " bytes)";
    }
  } else {
    try {
      auto scanned = scan_records(file.get(), *size, state->version, path, [&](std::string_view payload) {
        if (load_le<uint64_t>(payload, kSequenceAt) > after_sequence) {
          records.push_back(decode_payload(payload, state->version));
        }
      });
      if (!scanned.ok()) return scanned.error();
      local.records = scanned->records;
      local.ignored_tail_bytes = *size - scanned->end_offset;
      local.reason = std::move(scanned->reason);
    } catch (const std::bad_alloc&) {
      return io_error(path, "cannot read miss log", ENOMEM);
    }
  }
  if (report != nullptr) *report = std::move(local);
  return records;
}

}  // namespace animspace::misslog
