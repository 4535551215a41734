// Fuzz target: misslog::read_records, the reader of the append-only miss log
// (core/misslog/miss_log.h; layout in docs/FORMATS.md, "Miss log").
//
// read_records takes a path, so each input is written to one file per process (removed at exit). Each record
// carries a CRC of its payload, which mutations almost never keep right, so every input is read
// twice: as it is, and with every record's CRC recomputed, so that mutations reach the payload
// checks behind it.
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/common/bytes.h"
#include "core/container/crc32.h"
#include "core/misslog/miss_log.h"
#include "fuzz/fuzz_support.h"

namespace animspace::fuzz {
namespace {

// Layout constants restated from docs/FORMATS.md.
constexpr size_t kFileHeaderSize = 16;
constexpr size_t kRecordHeaderSize = 12;
constexpr size_t kPayloadLengthAt = 4;
constexpr size_t kPayloadCrcAt = 8;
constexpr size_t kFixedPayloadSize = 56;

// Recomputes the CRC of every record whose payload lies inside the file, walking the records
// as the reader does (by their length fields).
std::string reseal(std::string_view bytes) {
  std::string out(bytes);
  size_t at = kFileHeaderSize;
  while (at <= out.size() && out.size() - at >= kRecordHeaderSize) {
    const size_t length = load_le<uint32_t>(out, at + kPayloadLengthAt);
    if (length > out.size() - at - kRecordHeaderSize) break;
    store_le<uint32_t>(out, at + kPayloadCrcAt,
                       container::crc32(std::string_view(out).substr(at + kRecordHeaderSize, length)));
    at += kRecordHeaderSize + length;
  }
  return out;
}

// This process's scratch file, removed when the process exits normally. Memory-backed /dev/shm
// where there is one: a file round trip there is ~10× faster than in /tmp.
struct ScratchFile {
  std::string path = (std::filesystem::is_directory("/dev/shm") ? "/dev/shm" : "/tmp") +
                     std::string("/animspace-fuzz-") + std::to_string(::getpid()) + ".misses";
  ~ScratchFile() { std::remove(path.c_str()); }
};

void read_as_miss_log(std::string_view bytes) {
  static const ScratchFile scratch;
  const std::string& path = scratch.path;
  {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    FUZZ_CHECK(file.good());
  }
  misslog::ReadReport report;
  const auto records = misslog::read_records(path, 0, &report);
  if (!records) {
    FUZZ_CHECK(records.error().code == ErrorCode::kDataLoss);  // only the file header can be refused
    check_refusal(records.error(), path);
    return;
  }
  // With after_sequence 0 every record is returned, and the records plus the ignored tail are
  // the whole file.
  FUZZ_CHECK(report.records == records->size());
  FUZZ_CHECK(report.reason.empty() == (report.ignored_tail_bytes == 0));
  // (A file shorter than its header is a creation in progress: all of it is the ignored tail.)
  uint64_t accounted = bytes.size() < kFileHeaderSize ? 0 : kFileHeaderSize;
  uint64_t previous_sequence = 0;
  for (const misslog::MissRecord& record : *records) {
    FUZZ_CHECK(record.sequence > previous_sequence);
    previous_sequence = record.sequence;
    FUZZ_CHECK(record.channel_count >= 1);
    FUZZ_CHECK(record.key_values.size() % record.channel_count == 0);
    FUZZ_CHECK(record.full_values.size() % record.channel_count == 0);
    accounted += kRecordHeaderSize + kFixedPayloadSize + 4 * (record.key_values.size() + record.full_values.size());
  }
  FUZZ_CHECK(accounted + report.ignored_tail_bytes == bytes.size());
}

}  // namespace
}  // namespace animspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace::fuzz;
  const std::string_view bytes = as_bytes(data, size);
  read_as_miss_log(bytes);
  if (size > kFileHeaderSize) read_as_miss_log(reseal(bytes));
  return 0;
}
