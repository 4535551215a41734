#include "core/misslog/miss_log.h"

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/bytes.h"
#include "core/container/crc32.h"
#include "tests/support/test_support.h"

namespace animspace::misslog {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using testing::TempDir;

// Layout restated from docs/FORMATS.md ("Miss log"), not taken from the implementation, so that
// these tests check the code against the document.
constexpr size_t kFileHeaderSize = 16;
constexpr size_t kRecordHeaderSize = 12;
constexpr size_t kFixedPayloadSize = 56;
constexpr unsigned char kFileMagic[8] = {0x89, 'M', 'I', 'S', 0x0D, 0x0A, 0x1A, 0x0A};

size_t record_size(size_t key_count, size_t full_count) {
  return kRecordHeaderSize + kFixedPayloadSize + 4 * (key_count + full_count);
}

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

// Deterministic values from a tag, so a record read back can be checked against a recomputation.
float value_of(uint64_t tag, size_t index) {
  return static_cast<float>(tag) * 100.0F + static_cast<float>(index) * 0.25F - 7.0F;
}

MissRecord make_record(uint64_t tag, size_t key_count, size_t full_count, uint32_t channels = 3) {
  MissRecord record;
  record.model_version = tag;
  record.unix_time_us = 1'700'000'000'000'000 + static_cast<int64_t>(tag);
  record.status = tag % 2 == 0 ? pmsc::CacheStatus::kBlend : pmsc::CacheStatus::kMiss;
  record.key_point_error = 0.125 * static_cast<double>(tag) + 0.001;
  record.blend_weight = 1.0 / static_cast<double>(tag + 2);
  record.channel_count = channels;
  for (size_t i = 0; i < key_count; ++i) record.key_values.push_back(value_of(tag, i));
  for (size_t i = 0; i < full_count; ++i) record.full_values.push_back(-value_of(tag, i));
  return record;
}

void expect_same_content(const MissRecord& expected, const MissRecord& actual) {
  EXPECT_EQ(expected.model_version, actual.model_version);
  EXPECT_EQ(expected.unix_time_us, actual.unix_time_us);
  EXPECT_EQ(expected.status, actual.status);
  EXPECT_EQ(expected.key_point_error, actual.key_point_error);
  EXPECT_EQ(expected.blend_weight, actual.blend_weight);
  EXPECT_EQ(expected.channel_count, actual.channel_count);
  EXPECT_EQ(expected.key_values, actual.key_values);
  EXPECT_EQ(expected.full_values, actual.full_values);
  EXPECT_EQ(expected.full_points, actual.full_points);
}

std::unique_ptr<MissLog> open_or_die(const fs::path& path,
                                     FsyncPolicy policy = FsyncPolicy::kNever) {
  auto log = MissLog::open(path, policy, milliseconds(10));
  EXPECT_TRUE(log.ok()) << (log.ok() ? "" : log.error().message);
  return log.ok() ? std::move(*log) : nullptr;
}

std::vector<MissRecord> read_or_die(const fs::path& path, uint64_t after = 0,
                                    ReadReport* report = nullptr) {
  auto records = read_records(path, after, report);
  EXPECT_TRUE(records.ok()) << (records.ok() ? "" : records.error().message);
  return records.ok() ? std::move(*records) : std::vector<MissRecord>{};
}

// Appends records 1..count of make_record(i, key_count, full_count) to a new log at `path`.
void write_records(const fs::path& path, uint64_t count, size_t key_count, size_t full_count) {
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  for (uint64_t i = 1; i <= count; ++i) {
    MissRecord record = make_record(i, key_count, full_count);
    ASSERT_TRUE(log->append(record).ok());
  }
}

TEST(MissLogFsyncPolicy, ParsesTheThreeNamesAndRejectsOthers) {
  ASSERT_TRUE(parse_fsync_policy("always").ok());
  EXPECT_EQ(*parse_fsync_policy("always"), FsyncPolicy::kAlways);
  EXPECT_EQ(*parse_fsync_policy("interval"), FsyncPolicy::kInterval);
  EXPECT_EQ(*parse_fsync_policy("never"), FsyncPolicy::kNever);
  for (const char* bad : {"", "Always", "sometimes", "never ", "1"}) {
    auto policy = parse_fsync_policy(bad);
    ASSERT_FALSE(policy.ok()) << bad;
    EXPECT_EQ(policy.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(policy.error().message.find("\"" + std::string(bad) + "\""), std::string::npos)
        << policy.error().message;
  }
}

TEST(MissLog, RoundTripsRecordsWithAndWithoutFullValues) {
  TempDir dir;
  const fs::path path = dir / "arm.misses";
  std::vector<MissRecord> written = {make_record(1, 6, 0), make_record(2, 6, 12),
                                     make_record(3, 4, 10, 2), make_record(4, 0, 0, 1)};
  {
    auto log = open_or_die(path, FsyncPolicy::kAlways);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(log->recovery().records, 0U);
    EXPECT_EQ(log->recovery().truncated_bytes, 0U);
    EXPECT_TRUE(log->recovery().reason.empty());
    EXPECT_EQ(log->path(), path);
    for (size_t i = 0; i < written.size(); ++i) {
      auto sequence = log->append(written[i]);
      ASSERT_TRUE(sequence.ok()) << sequence.error().message;
      EXPECT_EQ(*sequence, i + 1);
      EXPECT_EQ(written[i].sequence, i + 1);
    }
    EXPECT_EQ(log->record_count(), 4U);
    EXPECT_EQ(log->last_sequence(), 4U);
  }
  EXPECT_EQ(fs::file_size(path), kFileHeaderSize + record_size(6, 0) + record_size(6, 12) +
                                     record_size(4, 10) + record_size(0, 0));

  ReadReport report;
  const auto all = read_or_die(path, 0, &report);
  ASSERT_EQ(all.size(), 4U);
  for (size_t i = 0; i < all.size(); ++i) {
    EXPECT_EQ(all[i].sequence, i + 1);
    expect_same_content(written[i], all[i]);
  }
  EXPECT_EQ(report.records, 4U);
  EXPECT_EQ(report.ignored_tail_bytes, 0U);
  EXPECT_TRUE(report.reason.empty());

  const auto after_two = read_or_die(path, 2, &report);
  ASSERT_EQ(after_two.size(), 2U);
  EXPECT_EQ(after_two[0].sequence, 3U);
  EXPECT_EQ(after_two[1].sequence, 4U);
  EXPECT_EQ(report.records, 4U);  // counted before the filter
  EXPECT_TRUE(read_or_die(path, 4).empty());
  EXPECT_TRUE(read_or_die(path, 1000).empty());
}

// Decodes a written file by hand from the documented offsets.
TEST(MissLog, WritesTheDocumentedByteLayout) {
  TempDir dir;
  const fs::path path = dir / "layout.misses";
  MissRecord record = make_record(7, 3, 6);
  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    ASSERT_TRUE(log->append(record).ok());
  }
  const std::string bytes = read_bytes(path);
  ASSERT_EQ(bytes.size(), kFileHeaderSize + record_size(3, 6));
  EXPECT_EQ(std::memcmp(bytes.data(), kFileMagic, 8), 0);
  EXPECT_EQ(load_le<uint32_t>(bytes, 8), 3U);   // format version
  EXPECT_EQ(load_le<uint32_t>(bytes, 12), 0U);  // reserved

  const size_t r = kFileHeaderSize;
  EXPECT_EQ(bytes.substr(r, 4), "MREC");
  const uint32_t length = load_le<uint32_t>(bytes, r + 4);
  EXPECT_EQ(length, kFixedPayloadSize + 4 * 9);
  const size_t p = r + kRecordHeaderSize;
  EXPECT_EQ(load_le<uint32_t>(bytes, r + 8), container::crc32(std::string_view(bytes).substr(p)));
  EXPECT_EQ(load_le<uint64_t>(bytes, p + 0), 1U);  // sequence
  EXPECT_EQ(load_le<uint64_t>(bytes, p + 8), 7U);  // model version
  EXPECT_EQ(load_le<int64_t>(bytes, p + 16), 1'700'000'000'000'007);
  EXPECT_EQ(load_le<double>(bytes, p + 24), 0.125 * 7 + 0.001);
  EXPECT_EQ(load_le<double>(bytes, p + 32), 1.0 / 9.0);
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 40), 3U);  // channels
  EXPECT_EQ(load_le<uint8_t>(bytes, p + 44), 2U);  // status: version 2's (and 3's) code for a miss
  EXPECT_EQ(bytes.substr(p + 45, 3), std::string(3, '\0'));  // layout 0: a whole frame; reserved
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 48), 3U);  // key value count
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 52), 6U);  // full value count
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(load_le<float>(bytes, p + 56 + 4 * i), value_of(7, i));
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(load_le<float>(bytes, p + 56 + 12 + 4 * i), -value_of(7, i));
  }
}

TEST(MissLog, ReopenContinuesSequencesAndCounts) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 3, 3, 3);
  {
    auto log = open_or_die(path, FsyncPolicy::kInterval);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(log->recovery().records, 3U);
    EXPECT_EQ(log->recovery().truncated_bytes, 0U);
    EXPECT_TRUE(log->recovery().reason.empty());
    EXPECT_EQ(log->record_count(), 3U);
    EXPECT_EQ(log->last_sequence(), 3U);
    MissRecord record = make_record(4, 3, 0);
    auto sequence = log->append(record);
    ASSERT_TRUE(sequence.ok());
    EXPECT_EQ(*sequence, 4U);
    EXPECT_EQ(log->record_count(), 4U);
    EXPECT_TRUE(log->sync().ok());
  }
  const auto records = read_or_die(path);
  ASSERT_EQ(records.size(), 4U);
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(records[i].sequence, i + 1);
}

TEST(MissLog, SecondWriterOnTheSameFileIsRefused) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  auto first = open_or_die(path);
  ASSERT_NE(first, nullptr);
  auto second = MissLog::open(path, FsyncPolicy::kNever, milliseconds(10));
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.error().code, ErrorCode::kFailedPrecondition);
  first.reset();
  EXPECT_TRUE(MissLog::open(path, FsyncPolicy::kNever, milliseconds(10)).ok());
}

TEST(MissLog, InvalidRecordsAreRefusedWithoutUsingASequence) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  std::vector<MissRecord> bad(6, make_record(1, 6, 6));
  bad[0].status = pmsc::CacheStatus::kHit;  // a hit is never logged
  bad[1].channel_count = 0;
  bad[2].key_values.pop_back();  // 5 values, 3 channels
  bad[3].full_values.pop_back();
  bad[4].full_values[4] = std::numeric_limits<float>::quiet_NaN();
  bad[5].key_point_error = std::numeric_limits<double>::infinity();
  for (auto& record : bad) {
    auto sequence = log->append(record);
    ASSERT_FALSE(sequence.ok());
    EXPECT_EQ(sequence.error().code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(record.sequence, 0U);
  }
  EXPECT_NE(log->append(bad[4]).error().message.find("full_values[4]"), std::string::npos);
  MissRecord good = make_record(1, 6, 6);
  auto sequence = log->append(good);
  ASSERT_TRUE(sequence.ok());
  EXPECT_EQ(*sequence, 1U);
  EXPECT_EQ(fs::file_size(path), kFileHeaderSize + record_size(6, 6));
}

// Issue #55 item 6: a bounded log refuses the record that would pass its bound, leaves the file as
// it was and uses no sequence; records that fit still go in, and a larger bound takes more.
TEST(MissLog, ABoundedLogRefusesTheRecordThatWouldPassItsBound) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  const uint64_t one = record_size(6, 6);
  log->set_max_bytes(kFileHeaderSize + 2 * one);  // room for exactly two records
  for (uint64_t i = 1; i <= 2; ++i) {
    MissRecord record = make_record(i, 6, 6);
    auto sequence = log->append(record);
    ASSERT_TRUE(sequence.ok()) << sequence.error().message;
    EXPECT_EQ(*sequence, i);
  }
  EXPECT_EQ(log->size_bytes(), kFileHeaderSize + 2 * one);
  MissRecord third = make_record(3, 6, 6);
  auto refused = log->append(third);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kResourceExhausted);
  EXPECT_NE(refused.error().message.find("the miss log is full: it holds " + std::to_string(kFileHeaderSize + 2 * one) +
                                         " bytes and a record of " + std::to_string(one) +
                                         " bytes would pass its bound of " +
                                         std::to_string(kFileHeaderSize + 2 * one) + " bytes"),
            std::string::npos)
      << refused.error().message;
  EXPECT_EQ(third.sequence, 0U);
  EXPECT_EQ(fs::file_size(path), kFileHeaderSize + 2 * one);
  // A smaller record that fits still goes in (the bound is on bytes, not records).
  log->set_max_bytes(kFileHeaderSize + 2 * one + record_size(3, 0));
  MissRecord small = make_record(4, 3, 0);
  EXPECT_FALSE(log->append(third).ok());
  auto fitted = log->append(small);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  EXPECT_EQ(*fitted, 3U);
  log->set_max_bytes(0);  // unbounded
  EXPECT_TRUE(log->append(third).ok());
  log.reset();
  EXPECT_EQ(read_or_die(path).size(), 4U);
}

// Cutting the file anywhere inside the last record is a torn write: recovery keeps the records
// before it, cuts the file back to their end, and appending works again.
TEST(MissLogRecovery, TornLastRecordAtEveryByteOffset) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  const std::vector<MissRecord> originals = {make_record(1, 6, 9), make_record(2, 3, 0),
                                             make_record(3, 3, 0)};
  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    for (MissRecord record : originals) ASSERT_TRUE(log->append(record).ok());
  }
  const std::string full = read_bytes(path);
  const size_t good_end = kFileHeaderSize + record_size(6, 9) + record_size(3, 0);
  ASSERT_EQ(full.size(), good_end + record_size(3, 0));

  for (size_t cut = good_end + 1; cut < full.size(); ++cut) {
    SCOPED_TRACE("cut at byte " + std::to_string(cut));
    write_bytes(path, full.substr(0, cut));
    {
      auto log = open_or_die(path);
      ASSERT_NE(log, nullptr);
      EXPECT_EQ(log->recovery().records, 2U);
      EXPECT_EQ(log->recovery().truncated_bytes, cut - good_end);
      EXPECT_NE(log->recovery().reason.find("at byte " + std::to_string(good_end)),
                std::string::npos)
          << log->recovery().reason;
      EXPECT_EQ(fs::file_size(path), good_end);
      EXPECT_EQ(log->last_sequence(), 2U);
      MissRecord again = make_record(9, 3, 3);
      auto sequence = log->append(again);
      ASSERT_TRUE(sequence.ok());
      EXPECT_EQ(*sequence, 3U);
    }
    const auto records = read_or_die(path);
    ASSERT_EQ(records.size(), 3U);
    expect_same_content(originals[0], records[0]);
    expect_same_content(originals[1], records[1]);
    expect_same_content(make_record(9, 3, 3), records[2]);
    EXPECT_EQ(records[2].sequence, 3U);
  }
}

TEST(MissLogRecovery, ReaderReportsATornTailWithoutTouchingTheFile) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 2, 3, 3);
  std::string bytes = read_bytes(path);
  bytes.resize(bytes.size() - 5);
  write_bytes(path, bytes);
  ReadReport report;
  const auto records = read_or_die(path, 0, &report);
  EXPECT_EQ(records.size(), 1U);
  EXPECT_EQ(report.records, 1U);
  EXPECT_EQ(report.ignored_tail_bytes, record_size(3, 3) - 5);
  EXPECT_NE(report.reason.find("torn record at byte " +
                               std::to_string(kFileHeaderSize + record_size(3, 3))),
            std::string::npos)
      << report.reason;
  EXPECT_EQ(read_bytes(path), bytes);
}

// Appends `tail` to a file of three valid records and checks that open() cuts exactly it.
void expect_tail_recovered(const std::string& tail, const std::string& reason_part) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 3, 3, 6);
  const size_t good_end = kFileHeaderSize + 3 * record_size(3, 6);
  write_bytes(path, read_bytes(path) + tail);
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->recovery().records, 3U);
  EXPECT_EQ(log->recovery().truncated_bytes, tail.size());
  EXPECT_NE(log->recovery().reason.find(reason_part), std::string::npos)
      << log->recovery().reason;
  EXPECT_EQ(fs::file_size(path), good_end);
  MissRecord record = make_record(4, 3, 0);
  ASSERT_TRUE(log->append(record).ok());
  EXPECT_EQ(read_or_die(path).size(), 4U);
}

std::string record_header(uint32_t magic, uint32_t length, uint32_t crc) {
  std::string header(kRecordHeaderSize, '\0');
  store_le(header, 0, magic);
  store_le(header, 4, length);
  store_le(header, 8, crc);
  return header;
}

constexpr uint32_t kRecordMagic = 0x4345524DU;  // "MREC"

TEST(MissLogRecovery, RandomGarbageAfterValidRecords) {
  std::mt19937 random(42);
  std::string garbage(1000, '\0');
  for (char& c : garbage) c = static_cast<char>(random() & 0xFF);
  expect_tail_recovered(garbage, "at byte " + std::to_string(kFileHeaderSize + 3 * record_size(3, 6)));
}

TEST(MissLogRecovery, RecordHeaderClaimingAHugeLength) {
  // Beyond the format's 1 GiB bound, and within it but past the end of the file.
  expect_tail_recovered(record_header(kRecordMagic, 0xFFFFFFFFU, 0) + std::string(40, 'x'),
                        "payload length 4294967295 outside");
  expect_tail_recovered(record_header(kRecordMagic, 1U << 30, 0) + std::string(40, 'x'),
                        "runs past the end of the file");
  expect_tail_recovered(record_header(kRecordMagic, 8, 0) + std::string(40, 'x'),
                        "payload length 8 outside");
}

// A file that really is larger than the bound (sparse, so it costs no disk) with a length just
// over it: the scanner must refuse the length rather than allocate and read it.
TEST(MissLogRecovery, LengthOverTheBoundIsNotAllocatedEvenWhenTheFileIsThatLarge) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    MissRecord record = make_record(1, 3, 3);
    ASSERT_TRUE(log->append(record).ok());
  }
  const size_t good_end = kFileHeaderSize + record_size(3, 3);
  write_bytes(path, read_bytes(path) + record_header(kRecordMagic, (1U << 30) + 1, 0));
  const uintmax_t sparse_size = uintmax_t{3} << 29;  // 1.5 GiB
  fs::resize_file(path, sparse_size);

  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  auto log = open_or_die(path);
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->recovery().records, 1U);
  EXPECT_EQ(log->recovery().truncated_bytes, sparse_size - good_end);
  EXPECT_NE(log->recovery().reason.find("outside"), std::string::npos) << log->recovery().reason;
  EXPECT_EQ(fs::file_size(path), good_end);
  // ru_maxrss is in KiB; a 1 GiB buffer, zero-filled on allocation, would show.
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256 * 1024);
}

TEST(MissLogRecovery, FlippedByteInTheLastRecordIsCaughtByTheCrc) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 3, 3, 6);
  const size_t last_at = kFileHeaderSize + 2 * record_size(3, 6);
  std::string bytes = read_bytes(path);
  bytes[last_at + kRecordHeaderSize + 60] ^= 0x10;  // inside the first key value
  write_bytes(path, bytes);

  ReadReport report;
  EXPECT_EQ(read_or_die(path, 0, &report).size(), 2U);
  EXPECT_NE(report.reason.find("CRC"), std::string::npos) << report.reason;

  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->recovery().records, 2U);
  EXPECT_EQ(log->recovery().truncated_bytes, record_size(3, 6));
  EXPECT_NE(log->recovery().reason.find("corrupt record at byte " + std::to_string(last_at)),
            std::string::npos)
      << log->recovery().reason;
  EXPECT_NE(log->recovery().reason.find("CRC"), std::string::npos);
  EXPECT_EQ(fs::file_size(path), last_at);
}

// The documented choice: corruption in the middle cuts the file there, losing the valid records
// after it (a crash cannot produce this; resynchronising could mis-frame float data).
TEST(MissLogRecovery, CorruptRecordInTheMiddleCutsEverythingFromIt) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 5, 3, 3);
  const size_t second_at = kFileHeaderSize + record_size(3, 3);
  std::string bytes = read_bytes(path);
  bytes[second_at + kRecordHeaderSize + 8] ^= 0x01;  // model version of record 2
  write_bytes(path, bytes);

  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->recovery().records, 1U);
  EXPECT_EQ(log->recovery().truncated_bytes, 4 * record_size(3, 3));
  EXPECT_NE(log->recovery().reason.find("corrupt record at byte " + std::to_string(second_at)),
            std::string::npos)
      << log->recovery().reason;
  EXPECT_EQ(log->last_sequence(), 1U);
  MissRecord record = make_record(6, 3, 3);
  EXPECT_EQ(*log->append(record), 2U);
}

TEST(MissLogRecovery, NonIncreasingSequenceIsCorruption) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  write_records(path, 2, 3, 0);
  // Duplicate record 1 (a valid, CRC-checked record) after record 2.
  std::string bytes = read_bytes(path);
  bytes += bytes.substr(kFileHeaderSize, record_size(3, 0));
  write_bytes(path, bytes);
  ReadReport report;
  EXPECT_EQ(read_or_die(path, 0, &report).size(), 2U);
  EXPECT_NE(report.reason.find("sequence 1 does not follow 2"), std::string::npos)
      << report.reason;
}

// A record whose CRC matches but whose content append would have refused — a status that is
// neither blend nor miss, a NaN key value — is corruption too: it never reaches retraining.
TEST(MissLogRecovery, ValidChecksumDoesNotPassWhatAppendWouldRefuse) {
  const auto reads_one_record_then = [](const std::function<void(std::string&, size_t)>& spoil) {
    TempDir dir;
    const fs::path path = dir / "m.misses";
    write_records(path, 2, 3, 0);
    std::string bytes = read_bytes(path);
    const size_t r = kFileHeaderSize + record_size(3, 0);  // the second record
    const size_t p = r + kRecordHeaderSize;
    spoil(bytes, p);
    const std::string_view payload = std::string_view(bytes).substr(p, record_size(3, 0) - kRecordHeaderSize);
    store_le<uint32_t>(bytes, r + 8, container::crc32(payload));
    write_bytes(path, bytes);
    ReadReport report;
    EXPECT_EQ(read_or_die(path, 0, &report).size(), 1U);
    return report.reason;
  };
  const std::string status =
      reads_one_record_then([](std::string& bytes, size_t p) { store_le<uint8_t>(bytes, p + 44, 7); });
  EXPECT_NE(status.find("miss record status code 7, expected blend or miss"), std::string::npos) << status;
  const std::string nan = reads_one_record_then(
      [](std::string& bytes, size_t p) { store_le<float>(bytes, p + 56 + 4, std::numeric_limits<float>::quiet_NaN()); });
  EXPECT_NE(nan.find("miss record key_values[1] is not finite"), std::string::npos) << nan;
}

TEST(MissLogHeader, BadFileHeaderIsDataLossAndLeavesTheFileAlone) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    MissRecord record = make_record(1, 3, 3);
    ASSERT_TRUE(log->append(record).ok());
  }
  const std::string good = read_bytes(path);
  struct Case {
    const char* name;
    size_t at;
    std::string bytes;
  };
  std::vector<Case> cases;
  cases.push_back({"magic", 0, good});
  cases.back().bytes[3] = 'X';
  cases.push_back({"version 4", 8, good});
  store_le<uint32_t>(cases.back().bytes, 8, 4);
  cases.push_back({"version 0", 8, good});
  store_le<uint32_t>(cases.back().bytes, 8, 0);
  cases.push_back({"reserved", 12, good});
  store_le<uint32_t>(cases.back().bytes, 12, 1);
  cases.push_back({"short, not a prefix", 2, good.substr(0, 2) + "Z"});
  cases.push_back({"text file", 0, std::string("hello, this is not a miss log\n")});
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    write_bytes(path, c.bytes);
    auto log = MissLog::open(path, FsyncPolicy::kAlways, milliseconds(10));
    ASSERT_FALSE(log.ok());
    EXPECT_EQ(log.error().code, ErrorCode::kDataLoss);
    EXPECT_NE(log.error().message.find(path.string()), std::string::npos) << log.error().message;
    EXPECT_NE(log.error().message.find("byte " + std::to_string(c.at)), std::string::npos)
        << log.error().message;
    EXPECT_EQ(read_bytes(path), c.bytes);
    auto records = read_records(path, 0, nullptr);
    ASSERT_FALSE(records.ok());
    EXPECT_EQ(records.error().code, ErrorCode::kDataLoss);
  }
}

// A crash while creating the file leaves a prefix of the header: no records, and open completes it.
TEST(MissLogHeader, IncompleteHeaderFromAnInterruptedCreation) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  std::string prefix(reinterpret_cast<const char*>(kFileMagic), 8);
  prefix += std::string("\x01\x00", 2);
  write_bytes(path, prefix);

  ReadReport report;
  EXPECT_TRUE(read_or_die(path, 0, &report).empty());
  EXPECT_EQ(report.ignored_tail_bytes, 10U);
  EXPECT_EQ(read_bytes(path), prefix);

  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->recovery().records, 0U);
  EXPECT_FALSE(log->recovery().reason.empty());
  EXPECT_EQ(fs::file_size(path), kFileHeaderSize);
  MissRecord record = make_record(1, 3, 0);
  EXPECT_EQ(*log->append(record), 1U);
  EXPECT_EQ(read_or_die(path).size(), 1U);
}

// Version 1 logs (written by releases before the log owned its status codes) keep loading: a
// file built here byte by byte from docs/FORMATS.md's version-1 layout — status byte 2 for a
// blend, 3 for a miss — reads back with those statuses, and appends stay in version 1.
std::string version1_record(uint64_t sequence, uint8_t status_code, const std::vector<float>& key_values) {
  std::string payload(kFixedPayloadSize + 4 * key_values.size(), '\0');
  store_le<uint64_t>(payload, 0, sequence);
  store_le<uint64_t>(payload, 8, 40 + sequence);  // model version
  store_le<int64_t>(payload, 16, 1'600'000'000'000'000);
  store_le<double>(payload, 24, 0.5);   // e_key
  store_le<double>(payload, 32, 0.25);  // α
  store_le<uint32_t>(payload, 40, 3);   // channels
  store_le<uint8_t>(payload, 44, status_code);
  store_le<uint32_t>(payload, 48, static_cast<uint32_t>(key_values.size()));
  store_le<uint32_t>(payload, 52, 0);  // no full values
  for (size_t i = 0; i < key_values.size(); ++i) store_le<float>(payload, 56 + 4 * i, key_values[i]);
  std::string framed(kRecordHeaderSize, '\0');
  framed.replace(0, 4, "MREC");
  store_le<uint32_t>(framed, 4, static_cast<uint32_t>(payload.size()));
  store_le<uint32_t>(framed, 8, container::crc32(payload));
  return framed + payload;
}

TEST(MissLogCompatibility, Version1LogsReadWithTheirOwnStatusCodesAndStayVersion1) {
  TempDir dir;
  const fs::path path = dir / "v1.misses";
  std::string bytes(reinterpret_cast<const char*>(kFileMagic), 8);
  bytes += std::string(8, '\0');
  store_le<uint32_t>(bytes, 8, 1);
  bytes += version1_record(1, 2, {1, 2, 3});  // blend
  bytes += version1_record(2, 3, {4, 5, 6});  // miss
  write_bytes(path, bytes);

  const std::vector<MissRecord> records = read_or_die(path);
  ASSERT_EQ(records.size(), 2U);
  EXPECT_EQ(records[0].status, pmsc::CacheStatus::kBlend);
  EXPECT_EQ(records[1].status, pmsc::CacheStatus::kMiss);
  EXPECT_EQ(records[1].model_version, 42U);
  EXPECT_EQ(records[1].key_values, (std::vector<float>{4, 5, 6}));

  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(log->format_version(), 1U);
    EXPECT_EQ(log->recovery().records, 2U);
    MissRecord blend = make_record(2, 3, 0);  // tag 2: a blend
    ASSERT_EQ(*log->append(blend), 3U);
  }
  const std::string after = read_bytes(path);
  EXPECT_EQ(load_le<uint32_t>(after, 8), 1U);  // still version 1
  EXPECT_EQ(after.substr(0, bytes.size()), bytes);
  EXPECT_EQ(load_le<uint8_t>(after, bytes.size() + kRecordHeaderSize + 44), 2U);  // version 1's blend
  const std::vector<MissRecord> again = read_or_die(path);
  ASSERT_EQ(again.size(), 3U);
  EXPECT_EQ(again[2].status, pmsc::CacheStatus::kBlend);
}

TEST(MissLogCompatibility, StatusCodesMeanWhatTheirVersionSays) {
  // Code 1 is a blend in versions 2 and 3 but no status at all in version 1; code 3 the reverse.
  for (const uint32_t version : {1U, 2U, 3U}) {
    for (const uint8_t code : {uint8_t{1}, uint8_t{2}, uint8_t{3}}) {
      SCOPED_TRACE("version " + std::to_string(version) + ", code " + std::to_string(code));
      TempDir dir;
      const fs::path path = dir / "m.misses";
      std::string bytes(reinterpret_cast<const char*>(kFileMagic), 8);
      bytes += std::string(8, '\0');
      store_le<uint32_t>(bytes, 8, version);
      bytes += version1_record(1, code, {1, 2, 3});  // the record layout is the same in both
      write_bytes(path, bytes);
      ReadReport report;
      const std::vector<MissRecord> records = read_or_die(path, 0, &report);
      const bool valid = version == 1 ? code >= 2 : code <= 2;
      ASSERT_EQ(records.size(), valid ? 1U : 0U) << report.reason;
      if (!valid) continue;
      const pmsc::CacheStatus expected =
          (version == 1 ? code == 2 : code == 1) ? pmsc::CacheStatus::kBlend : pmsc::CacheStatus::kMiss;
      EXPECT_EQ(records[0].status, expected);
    }
  }
}

// Version 3's partial frames (local fail-through), byte by byte from docs/FORMATS.md: layout byte
// 45 = 1, then the listed points (uint32, ascending) between the key and the full values.
TEST(MissLogPartialFrames, PartialRecordsRoundTripInTheDocumentedLayout) {
  TempDir dir;
  const fs::path path = dir / "partial.misses";
  MissRecord partial = make_record(4, 3, 6);
  partial.full_points = {2, 9};
  MissRecord whole = make_record(5, 3, 6);
  {
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(log->format_version(), 3U);
    ASSERT_TRUE(log->append(partial).ok());
    ASSERT_TRUE(log->append(whole).ok());
  }
  const std::string bytes = read_bytes(path);
  const size_t p = kFileHeaderSize + kRecordHeaderSize;
  EXPECT_EQ(load_le<uint32_t>(bytes, kFileHeaderSize + 4), kFixedPayloadSize + 4 * (3 + 2 + 6));
  EXPECT_EQ(load_le<uint8_t>(bytes, p + 45), 1U);    // layout: partial
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 52), 6U);   // full value count: 2 points · 3
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 56 + 12), 2U);
  EXPECT_EQ(load_le<uint32_t>(bytes, p + 56 + 16), 9U);
  EXPECT_EQ(load_le<float>(bytes, p + 56 + 20), -value_of(4, 0));
  ASSERT_EQ(bytes.size(), kFileHeaderSize + record_size(3, 6) + 8 + record_size(3, 6));

  const std::vector<MissRecord> records = read_or_die(path);
  ASSERT_EQ(records.size(), 2U);
  expect_same_content(partial, records[0]);
  expect_same_content(whole, records[1]);
}

TEST(MissLogPartialFrames, MalformedPartialRecordsAreRefusedNamingTheField) {
  TempDir dir;
  auto log = open_or_die(dir / "m.misses");
  ASSERT_NE(log, nullptr);
  MissRecord unsorted = make_record(2, 3, 6);
  unsorted.full_points = {5, 5};
  auto appended = log->append(unsorted);
  ASSERT_FALSE(appended.ok());
  EXPECT_EQ(appended.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(appended.error().message.find("full_points[1] = 5 does not follow 5"), std::string::npos)
      << appended.error().message;
  MissRecord miscounted = make_record(2, 3, 6);
  miscounted.full_points = {1, 2, 3};
  appended = log->append(miscounted);
  ASSERT_FALSE(appended.ok());
  EXPECT_NE(appended.error().message.find("full_values (6) must be 3 values for each of the 3 full_points"),
            std::string::npos)
      << appended.error().message;
  EXPECT_EQ(log->record_count(), 0U);
}

TEST(MissLogPartialFrames, OlderLogsKeepWholeFramesAndRefusePartialOnes) {
  TempDir dir;
  const fs::path path = dir / "v2.misses";
  std::string bytes(reinterpret_cast<const char*>(kFileMagic), 8);
  bytes += std::string(8, '\0');
  store_le<uint32_t>(bytes, 8, 2);
  write_bytes(path, bytes);
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  EXPECT_EQ(log->format_version(), 2U);
  MissRecord partial = make_record(2, 3, 3);
  partial.full_points = {4};
  auto appended = log->append(partial);
  ASSERT_FALSE(appended.ok());
  EXPECT_EQ(appended.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(appended.error().message.find("format version 2 holds whole frames only"), std::string::npos)
      << appended.error().message;
  MissRecord whole = make_record(2, 3, 3);
  ASSERT_TRUE(log->append(whole).ok());
  log.reset();
  const std::string after = read_bytes(path);
  EXPECT_EQ(load_le<uint32_t>(after, 8), 2U);
  EXPECT_EQ(after.size(), kFileHeaderSize + record_size(3, 3));
  const std::vector<MissRecord> records = read_or_die(path);
  ASSERT_EQ(records.size(), 1U);
  expect_same_content(whole, records[0]);
}

TEST(MissLogHeader, MissingAndEmptyFiles) {
  TempDir dir;
  auto missing = read_records(dir / "absent.misses", 0, nullptr);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);

  write_bytes(dir / "empty.misses", "");
  ReadReport report;
  EXPECT_TRUE(read_or_die(dir / "empty.misses", 0, &report).empty());
  EXPECT_EQ(report.ignored_tail_bytes, 0U);
  EXPECT_TRUE(report.reason.empty());

  auto no_directory = MissLog::open(dir / "no" / "such" / "dir.misses", FsyncPolicy::kNever,
                                    milliseconds(10));
  ASSERT_FALSE(no_directory.ok());
  EXPECT_EQ(no_directory.error().code, ErrorCode::kIo);
}

// The file size limit makes the kernel write part of a record and then refuse: the partial
// record must be cut away, and the log must stay appendable.
TEST(MissLog, FailedWriteIsCutBackAndLaterAppendsStayReadable) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  MissRecord first = make_record(1, 3, 3);
  ASSERT_TRUE(log->append(first).ok());
  const size_t good_end = kFileHeaderSize + record_size(3, 3);

  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  rlimit limited = saved;
  limited.rlim_cur = good_end + 100;
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  struct sigaction previous {};
  ASSERT_EQ(sigaction(SIGXFSZ, &ignore, &previous), 0);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limited), 0);
  MissRecord big = make_record(2, 3, 300);
  auto failed = log->append(big);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &saved), 0);
  ASSERT_EQ(sigaction(SIGXFSZ, &previous, nullptr), 0);

  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.error().code, ErrorCode::kIo);
  EXPECT_NE(failed.error().message.find(path.string()), std::string::npos);
  EXPECT_EQ(big.sequence, 0U);
  EXPECT_EQ(fs::file_size(path), good_end);
  EXPECT_EQ(log->record_count(), 1U);
  EXPECT_EQ(log->last_sequence(), 1U);

  MissRecord next = make_record(3, 3, 3);
  EXPECT_EQ(*log->append(next), 2U);
  const auto records = read_or_die(path);
  ASSERT_EQ(records.size(), 2U);
  expect_same_content(make_record(3, 3, 3), records[1]);
}

TEST(MissLogConcurrency, FourThreadsAppendUniqueContiguousSequences) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  constexpr int kThreads = 4;
  constexpr int kPerThread = 200;
  std::vector<std::vector<uint64_t>> sequences(kThreads);
  {
    auto log = MissLog::open(path, FsyncPolicy::kInterval, milliseconds(20));
    ASSERT_TRUE(log.ok());
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        for (int i = 0; i < kPerThread; ++i) {
          // The tag names the writer, so each record read back can be checked.
          MissRecord record = make_record(static_cast<uint64_t>(t * 1000 + i), 3, 6);
          auto sequence = (*log)->append(record);
          if (sequence.ok()) sequences[static_cast<size_t>(t)].push_back(*sequence);
        }
      });
    }
    for (auto& thread : threads) thread.join();
    EXPECT_EQ((*log)->record_count(), uint64_t{kThreads * kPerThread});
    EXPECT_EQ((*log)->last_sequence(), uint64_t{kThreads * kPerThread});
  }
  std::set<uint64_t> unique;
  for (const auto& list : sequences) {
    EXPECT_EQ(list.size(), size_t{kPerThread});
    EXPECT_TRUE(std::is_sorted(list.begin(), list.end()));  // one thread's appends keep order
    unique.insert(list.begin(), list.end());
  }
  ASSERT_EQ(unique.size(), size_t{kThreads * kPerThread});
  EXPECT_EQ(*unique.begin(), 1U);
  EXPECT_EQ(*unique.rbegin(), uint64_t{kThreads * kPerThread});

  const auto records = read_or_die(path);
  ASSERT_EQ(records.size(), size_t{kThreads * kPerThread});
  std::vector<uint64_t> seen_tags;
  for (size_t i = 0; i < records.size(); ++i) {
    EXPECT_EQ(records[i].sequence, i + 1);
    expect_same_content(make_record(records[i].model_version, 3, 6), records[i]);
    seen_tags.push_back(records[i].model_version);
  }
  std::sort(seen_tags.begin(), seen_tags.end());
  std::vector<uint64_t> expected_tags;
  for (int t = 0; t < kThreads; ++t) {
    for (int i = 0; i < kPerThread; ++i) expected_tags.push_back(static_cast<uint64_t>(t * 1000 + i));
  }
  EXPECT_EQ(seen_tags, expected_tags);
}

TEST(MissLogConcurrency, ReaderSeesAGrowingPrefixWhileAWriterAppends) {
  TempDir dir;
  const fs::path path = dir / "m.misses";
  auto log = open_or_die(path);
  ASSERT_NE(log, nullptr);
  constexpr uint64_t kRecords = 300;
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (uint64_t i = 1; i <= kRecords; ++i) {
      MissRecord record = make_record(i, 3, 600);
      if (!log->append(record).ok()) break;
    }
    done = true;
  });
  uint64_t previous = 0;
  int reads = 0;
  bool contiguous = true;
  while (!done || reads == 0) {
    auto records = read_records(path, 0, nullptr);
    ASSERT_TRUE(records.ok()) << records.error().message;
    for (size_t i = 0; i < records->size(); ++i) {
      contiguous = contiguous && (*records)[i].sequence == i + 1 &&
                   (*records)[i].model_version == i + 1 &&
                   (*records)[i].full_values == make_record(i + 1, 3, 600).full_values;
    }
    EXPECT_GE(records->size(), previous);
    previous = records->size();
    ++reads;
  }
  writer.join();
  EXPECT_TRUE(contiguous);
  EXPECT_EQ(read_or_die(path).size(), kRecords);
}

// kill -9 in the middle of appending: the child appends large records as fast as it can with no
// fsync and is killed at an arbitrary point, possibly inside a write(). Whatever it left must
// open, and hold exactly the records 1..k, each intact.
TEST(MissLogCrash, KilledWriterLeavesContiguousIntactRecords) {
  constexpr size_t kFull = 30000;  // 120 KB of full values: a write spans many pages
  for (int round = 0; round < 3; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    TempDir dir;
    const fs::path path = dir / "m.misses";
    int ready[2];
    ASSERT_EQ(pipe(ready), 0);
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      // Child: no gtest macros; any failure is an exit code the parent never sees as success.
      ::close(ready[0]);
      auto log = MissLog::open(path, FsyncPolicy::kNever, milliseconds(1000));
      if (!log.ok()) _exit(2);
      for (uint64_t tag = 1;; ++tag) {
        MissRecord record = make_record(tag, 3, kFull);
        if (!(*log)->append(record).ok()) _exit(3);
        if (tag == 1) {
          const char byte = 1;
          if (::write(ready[1], &byte, 1) != 1) _exit(4);
        }
      }
    }
    ::close(ready[1]);
    char byte = 0;
    ASSERT_EQ(::read(ready[0], &byte, 1), 1);
    ::close(ready[0]);
    // Kill at a point that moves on each round, read from the file rather than a clock: once it
    // holds more than 2 + round records (the kill may then land inside the next write, or not).
    const uint64_t past = kFileHeaderSize + (2 + static_cast<uint64_t>(round)) * record_size(3, kFull);
    while (fs::file_size(path) <= past) std::this_thread::yield();
    ASSERT_EQ(::kill(child, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(::waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "child status " << status;

    const auto before_open = read_or_die(path);
    auto log = open_or_die(path);
    ASSERT_NE(log, nullptr);
    const uint64_t k = log->recovery().records;
    EXPECT_GE(k, 1U);
    EXPECT_EQ(log->last_sequence(), k);
    EXPECT_EQ(fs::file_size(path), kFileHeaderSize + k * record_size(3, kFull));
    EXPECT_EQ(before_open.size(), k);

    const auto records = read_or_die(path);
    ASSERT_EQ(records.size(), k);
    for (uint64_t i = 0; i < k; ++i) {
      EXPECT_EQ(records[i].sequence, i + 1);
      EXPECT_EQ(records[i].model_version, i + 1);
      EXPECT_EQ(records[i].full_values, make_record(i + 1, 3, kFull).full_values);
    }
    MissRecord next = make_record(k + 1, 3, 3);
    EXPECT_EQ(*log->append(next), k + 1);
  }
}

}  // namespace
}  // namespace animspace::misslog
