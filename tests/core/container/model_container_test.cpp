#include "core/container/model_container.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/atomic_file.h"
#include "core/container/crc32.h"
#include "tests/support/test_support.h"

namespace animspace::container {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

// Layout constants restated from docs/FORMATS.md ("Model container (.anim)"), not taken from the
// implementation, so that these tests check the code against the document.
constexpr size_t kHeaderSize = 64;
constexpr size_t kEntrySize = 80;
constexpr size_t kVersionAt = 8;
constexpr size_t kHeaderSizeAt = 12;
constexpr size_t kFileSizeAt = 16;
constexpr size_t kSectionCountAt = 24;
constexpr size_t kEntrySizeAt = 28;
constexpr size_t kHeaderCrcAt = 60;
constexpr size_t kTypeAt = 48;
constexpr size_t kRowsAt = 52;
constexpr size_t kColsAt = 56;
constexpr size_t kPayloadCrcAt = 60;
constexpr size_t kOffsetAt = 64;
constexpr size_t kSizeAt = 72;
constexpr std::string_view kSource = "test.anim";

uint32_t get_u32(const std::string& file, size_t at) {
  uint32_t value = 0;
  std::memcpy(&value, file.data() + at, sizeof value);
  return value;
}
uint64_t get_u64(const std::string& file, size_t at) {
  uint64_t value = 0;
  std::memcpy(&value, file.data() + at, sizeof value);
  return value;
}
void put_u32(std::string& file, size_t at, uint32_t value) {
  std::memcpy(file.data() + at, &value, sizeof value);
}
void put_u64(std::string& file, size_t at, uint64_t value) {
  std::memcpy(file.data() + at, &value, sizeof value);
}
size_t entry_at(size_t index) { return kHeaderSize + kEntrySize * index; }

// Recomputes the header CRC and the whole-file CRC in the footer, so that a test can make one
// field wrong while every checksum stays right.
void reseal(std::string& file) {
  put_u32(file, kHeaderCrcAt, crc32(std::string_view(file).substr(0, kHeaderCrcAt)));
  const size_t footer = file.size() - 8;
  put_u32(file, footer, crc32(std::string_view(file).substr(0, footer)));
}

// Replaces the payload of table entry `index` in place (it must fit the entry's padded slot),
// fixes its size and CRC, and reseals the file.
void replace_payload(std::string& file, size_t index, std::string_view payload) {
  const size_t at = entry_at(index);
  const size_t offset = get_u64(file, at + kOffsetAt);
  const size_t slot = (get_u64(file, at + kSizeAt) + 7) / 8 * 8;
  ASSERT_LE(payload.size(), slot);
  std::memset(file.data() + offset, 0, slot);
  std::memcpy(file.data() + offset, payload.data(), payload.size());
  put_u64(file, at + kSizeAt, payload.size());
  put_u32(file, at + kPayloadCrcAt, crc32(payload));
  reseal(file);
}

template <typename Matrix>
bool same_bits(const Matrix& a, const Matrix& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(typename Matrix::Scalar) * a.size()) == 0;
}

// A small container whose table order the writer fixes (docs/FORMATS.md): entry 0 "meta",
// entry 1 "a" (2x3 float32), entry 2 "b" (text).
ModelContainer small_container() {
  ModelContainer c;
  c.metadata()["k"] = "v";
  FrameMatrix a(2, 3);
  a << 1, 2, 3, 4, 5, 6;
  c.set_matrix("a", a);
  c.set_text("b", "hello");
  return c;
}

ModelContainer full_container() {
  using F = std::numeric_limits<float>;
  using D = std::numeric_limits<double>;
  using I = std::numeric_limits<int32_t>;
  ModelContainer c;
  c.metadata()["kind"] = "pmsc";
  c.metadata()["description"] = "bending arm \"v2\" — ünïcödé\n\ttabs";
  c.metadata()["empty"] = "";

  c.set_bytes("blob", std::string("\0\x01\xff\x80 binary\0", 11));
  c.set_text("notes", "UTF-8 text: λ ∑ 🙂");
  FrameMatrix frames(3, 4);
  frames << 0.0f, -0.0f, F::denorm_min(), -F::denorm_min(),  //
      F::min(), F::max(), F::lowest(), F::epsilon(),          //
      1e-30f, -3.4e38f, F::infinity(), -F::infinity();
  c.set_matrix("frames", frames);
  Int32Matrix ints(2, 3);
  ints << I::min(), I::max(), 0, -1, 1, 123456789;
  c.set_matrix("ints", ints);
  Float64Matrix doubles(2, 5);
  doubles << 0.0, -0.0, D::denorm_min(), D::min(), D::max(),  //
      D::lowest(), D::epsilon(), 1e-300, -1e300, 0.1;
  c.set_matrix("doubles", doubles);
  PointMatrix points(2, 3);
  points << 0.5f, -1.25f, 1e10f, -0.0f, F::denorm_min(), 7.0f;
  c.set_points("mesh.points", points);
  FaceMatrix faces(2, 3);
  faces << 0, 1, 2, 2, 1, 0;
  c.set_faces("mesh.faces", faces);
  c.set_matrix("empty.rows", FrameMatrix(0, 7));
  c.set_matrix("empty.all", Float64Matrix(0, 0));
  c.set_bytes("empty.bytes", "");
  c.set_text(std::string(kMaxSectionNameLength, 'n'), "longest name");
  c.set_text(" ~spaces and symbols!~ ", "printable ASCII edge characters");
  return c;
}

TEST(ModelContainerTest, RoundTripsEverySectionTypeBitExactly) {
  const ModelContainer original = full_container();
  const std::string file = serialize(original);
  auto parsed = parse(file, kSource);
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;

  EXPECT_EQ(parsed->metadata(), original.metadata());
  EXPECT_EQ(parsed->section_names(), original.section_names());
  for (const auto& [name, section] : original.sections()) {
    const Section& copy = parsed->sections().at(name);
    EXPECT_EQ(copy.type, section.type) << name;
    EXPECT_EQ(copy.rows, section.rows) << name;
    EXPECT_EQ(copy.cols, section.cols) << name;
    EXPECT_EQ(copy.bytes, section.bytes) << name;
  }
  EXPECT_EQ(*parsed->bytes("blob"), std::string("\0\x01\xff\x80 binary\0", 11));
  EXPECT_EQ(*parsed->text("notes"), "UTF-8 text: λ ∑ 🙂");
  EXPECT_TRUE(same_bits(*parsed->float_matrix("frames"), *original.float_matrix("frames")));
  EXPECT_TRUE(same_bits(*parsed->int_matrix("ints", 3), *original.int_matrix("ints")));
  EXPECT_TRUE(same_bits(*parsed->double_matrix("doubles"), *original.double_matrix("doubles")));
  EXPECT_TRUE(same_bits(*parsed->points("mesh.points"), *original.points("mesh.points")));
  EXPECT_TRUE(same_bits(*parsed->faces("mesh.faces"), *original.faces("mesh.faces")));
  EXPECT_EQ(parsed->float_matrix("empty.rows")->cols(), 7);
  EXPECT_EQ(parsed->double_matrix("empty.all")->size(), 0);
  EXPECT_EQ(*parsed->bytes("empty.bytes"), "");
  // -0.0 and denormals survive as bit patterns, not just as equal values.
  const float negative_zero = (*parsed->float_matrix("frames"))(0, 1);
  EXPECT_TRUE(std::signbit(negative_zero));
  EXPECT_EQ((*parsed->float_matrix("frames"))(0, 2), std::numeric_limits<float>::denorm_min());

  // The writer's output is canonical: re-serialising the parsed container gives the same bytes.
  EXPECT_EQ(serialize(*parsed), file);
}

TEST(ModelContainerTest, EmptyContainerMatchesTheDocumentedLayout) {
  const std::string file = serialize(ModelContainer{});
  // Header + one entry ("meta") + "{}" padded to 8 + footer.
  ASSERT_EQ(file.size(), 64U + 80U + 8U + 8U);
  EXPECT_EQ(file.substr(0, 8), std::string("\x89" "ANM\r\n\x1a\n", 8));
  EXPECT_EQ(get_u32(file, kVersionAt), 1U);
  EXPECT_EQ(get_u32(file, kHeaderSizeAt), 64U);
  EXPECT_EQ(get_u64(file, kFileSizeAt), file.size());
  EXPECT_EQ(get_u32(file, kSectionCountAt), 1U);
  EXPECT_EQ(get_u32(file, kEntrySizeAt), 80U);
  EXPECT_EQ(file.substr(32, 28), std::string(28, '\0'));
  EXPECT_EQ(get_u32(file, kHeaderCrcAt), crc32(std::string_view(file).substr(0, 60)));
  EXPECT_EQ(file.substr(64, 48), std::string("meta") + std::string(44, '\0'));
  EXPECT_EQ(get_u32(file, 64 + kTypeAt), 1U);  // text
  EXPECT_EQ(get_u32(file, 64 + kRowsAt), 0U);
  EXPECT_EQ(get_u32(file, 64 + kColsAt), 0U);
  EXPECT_EQ(get_u32(file, 64 + kPayloadCrcAt), crc32("{}"));
  EXPECT_EQ(get_u64(file, 64 + kOffsetAt), 144U);
  EXPECT_EQ(get_u64(file, 64 + kSizeAt), 2U);
  EXPECT_EQ(file.substr(144, 8), std::string("{}\0\0\0\0\0\0", 8));
  EXPECT_EQ(get_u32(file, 152), crc32(std::string_view(file).substr(0, 152)));
  EXPECT_EQ(file.substr(156), "AEND");

  auto parsed = parse(file, kSource);
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_TRUE(parsed->sections().empty());
  EXPECT_TRUE(parsed->metadata().empty());
}

TEST(ModelContainerTest, PayloadsAreEightByteAligned) {
  const std::string file = serialize(full_container());
  const uint32_t count = get_u32(file, kSectionCountAt);
  EXPECT_EQ(count, full_container().sections().size() + 1);
  for (uint32_t i = 0; i < count; ++i) {
    EXPECT_EQ(get_u64(file, entry_at(i) + kOffsetAt) % 8, 0U) << "entry " << i;
  }
  EXPECT_EQ(file.size() % 8, 0U);
}

TEST(ModelContainerTest, EveryTruncationIsDataLoss) {
  const std::string file = serialize(small_container());
  for (size_t length = 0; length < file.size(); ++length) {
    auto parsed = parse(std::string_view(file).substr(0, length), kSource);
    ASSERT_FALSE(parsed.ok()) << "prefix of " << length << " bytes parsed";
    EXPECT_EQ(parsed.error().code, ErrorCode::kDataLoss) << length << ": " << parsed.error().message;
    EXPECT_NE(parsed.error().message.find("truncated"), std::string::npos)
        << length << ": " << parsed.error().message;
  }
}

TEST(ModelContainerTest, TrailingBytesAreDataLoss) {
  const std::string file = serialize(small_container()) + '\0';
  auto parsed = parse(file, kSource);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, ErrorCode::kDataLoss);
}

TEST(ModelContainerTest, EveryFlippedByteIsRefused) {
  const std::string file = serialize(small_container());
  for (size_t position = 0; position < file.size(); ++position) {
    std::string corrupt = file;
    corrupt[position] = static_cast<char>(corrupt[position] ^ 0xFF);
    auto parsed = parse(corrupt, kSource);
    ASSERT_FALSE(parsed.ok()) << "flipped byte " << position << " parsed";
    // Inside the magic the file is not ours; anywhere else a checksum or a check catches it,
    // including the version field (the header CRC is checked first).
    const ErrorCode expected = position < 8 ? ErrorCode::kInvalidArgument : ErrorCode::kDataLoss;
    EXPECT_EQ(parsed.error().code, expected) << position << ": " << parsed.error().message;
  }
}

TEST(ModelContainerTest, WrongMagicIsInvalidArgument) {
  const std::string file = serialize(small_container());
  for (const std::string& bad : {std::string("PK\x03\x04", 4) + file.substr(4),
                                 std::string("{\"kind\": \"json\"}"),
                                 std::string("\x89PNG\r\n\x1a\n", 8) + file.substr(8)}) {
    auto parsed = parse(bad, kSource);
    ASSERT_FALSE(parsed.ok());
    EXPECT_EQ(parsed.error().code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(parsed.error().message.rfind("test.anim: not an animspace model container", 0), 0U)
        << parsed.error().message;
  }
}

TEST(ModelContainerTest, TextModeTransferIsDiagnosed) {
  std::string file = serialize(small_container());
  file.replace(4, 2, "\n");  // CRLF → LF, as a text-mode copy does
  auto parsed = parse(file, kSource);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(parsed.error().message.find("text mode"), std::string::npos) << parsed.error().message;
}

TEST(ModelContainerTest, FutureVersionIsFailedPrecondition) {
  std::string file = serialize(small_container());
  put_u32(file, kVersionAt, 7);
  reseal(file);  // only the version is wrong
  auto parsed = parse(file, kSource);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_EQ(parsed.error().message,
            "test.anim: format version 7 is newer than this build supports (1)");
}

// Files whose checksums are all correct but whose structure is not: what a buggy writer or a
// crafted file produces. Each must be refused with kDataLoss naming the problem.
struct MalformedCase {
  const char* what;
  std::function<void(std::string&)> mutate;
  const char* expected_in_message;
};

void set_name(std::string& file, size_t index, std::string_view name_field) {
  std::memset(file.data() + entry_at(index), 0, 48);
  std::memcpy(file.data() + entry_at(index), name_field.data(), name_field.size());
}

TEST(ModelContainerTest, StructurallyInvalidFilesAreDataLoss) {
  constexpr uint64_t kHuge = std::numeric_limits<uint64_t>::max();
  const std::vector<MalformedCase> cases = {
      {"version 0", [](std::string& f) { put_u32(f, kVersionAt, 0); }, "version 0"},
      {"header size", [](std::string& f) { put_u32(f, kHeaderSizeAt, 72); }, "header size"},
      {"entry size", [](std::string& f) { put_u32(f, kEntrySizeAt, 88); }, "entry size"},
      {"reserved byte", [](std::string& f) { f[40] = 1; }, "reserved"},
      {"section count over limit", [](std::string& f) { put_u32(f, kSectionCountAt, 5000); },
       "exceeds the limit of 4096"},
      {"section count beyond file", [](std::string& f) { put_u32(f, kSectionCountAt, 4096); },
       "too small for 4096 sections"},
      {"file size too large", [](std::string& f) { put_u64(f, kFileSizeAt, f.size() + 8); },
       "truncated"},
      {"file size huge", [](std::string& f) { put_u64(f, kFileSizeAt, kHuge); }, "truncated"},
      {"file size too small", [](std::string& f) { put_u64(f, kFileSizeAt, f.size() - 8); },
       "unexpected bytes"},
      {"footer marker", [](std::string& f) { f[f.size() - 1] = 'X'; }, "footer marker"},
      {"empty name", [](std::string& f) { set_name(f, 2, ""); }, "empty name"},
      {"unterminated name", [](std::string& f) { set_name(f, 2, std::string(48, 'x')); },
       "not NUL-terminated"},
      {"control character in name", [](std::string& f) { set_name(f, 2, "b\x01"); },
       "non-printable"},
      {"non-ASCII name", [](std::string& f) { set_name(f, 2, "b\xc3\xa9"); }, "non-printable"},
      {"garbage after NUL", [](std::string& f) { set_name(f, 2, std::string("b\0x", 3)); },
       "padding"},
      {"duplicate name", [](std::string& f) { set_name(f, 2, "a"); }, "appears twice"},
      {"unknown type", [](std::string& f) { put_u32(f, entry_at(1) + kTypeAt, 9); },
       "unknown type 9"},
      {"text with a shape", [](std::string& f) { put_u32(f, entry_at(2) + kRowsAt, 1); },
       "has a shape"},
      {"rows disagree with size", [](std::string& f) { put_u32(f, entry_at(1) + kRowsAt, 3); },
       "needs 36 bytes"},
      {"rows*cols*4 overflows",
       [](std::string& f) {
         put_u32(f, entry_at(1) + kRowsAt, 0xFFFFFFFFU);
         put_u32(f, entry_at(1) + kColsAt, 0xFFFFFFFFU);
       },
       "more than 2^64"},
      {"misaligned offset",
       [](std::string& f) { put_u64(f, entry_at(1) + kOffsetAt, get_u64(f, entry_at(1) + kOffsetAt) + 4); },
       "not a multiple of 8"},
      {"offset inside the table", [](std::string& f) { put_u64(f, entry_at(1) + kOffsetAt, 64); },
       "outside the payload area"},
      {"offset past the end",
       [](std::string& f) { put_u64(f, entry_at(1) + kOffsetAt, kHuge - 7); },
       "outside the payload area"},
      {"size past the end", [](std::string& f) { put_u64(f, entry_at(2) + kSizeAt, kHuge); },
       "outside the payload area"},
      {"payload into the footer",
       [](std::string& f) { put_u64(f, entry_at(2) + kSizeAt, f.size() - 8 - get_u64(f, entry_at(2) + kOffsetAt) + 1); },
       "outside the payload area"},
      {"overlapping payloads",
       [](std::string& f) { put_u64(f, entry_at(2) + kOffsetAt, get_u64(f, entry_at(1) + kOffsetAt) + 16); },
       "overlaps"},
      {"metadata not text", [](std::string& f) { put_u32(f, entry_at(0) + kTypeAt, 0); },
       "reserved for metadata"},
      {"section checksum", [](std::string& f) { f[get_u64(f, entry_at(2) + kOffsetAt)] ^= 1; },
       "section 'b' checksum mismatch"},
      {"metadata not JSON", [](std::string& f) { replace_payload(f, 0, "{\"k\":\"v\""); },
       "not valid JSON"},
      {"metadata an array", [](std::string& f) { replace_payload(f, 0, "[\"k\"]"); },
       "JSON array"},
      {"metadata value a number", [](std::string& f) { replace_payload(f, 0, "{\"k\":1}"); },
       "key 'k' is a JSON number"},
      {"metadata deeply nested", [](std::string& f) { replace_payload(f, 0, "[[[[[[[[]]]]]]]]"); },
       "JSON array"},
  };
  const std::string good = serialize(small_container());
  ASSERT_EQ(good.substr(entry_at(1), 2), std::string("a\0", 2));  // the table order assumed above
  ASSERT_EQ(good.substr(entry_at(2), 2), std::string("b\0", 2));
  for (const MalformedCase& c : cases) {
    std::string file = good;
    c.mutate(file);
    reseal(file);
    auto parsed = parse(file, kSource);
    ASSERT_FALSE(parsed.ok()) << c.what << " parsed";
    EXPECT_EQ(parsed.error().code, ErrorCode::kDataLoss) << c.what << ": " << parsed.error().message;
    EXPECT_NE(parsed.error().message.find(c.expected_in_message), std::string::npos)
        << c.what << ": " << parsed.error().message;
    EXPECT_EQ(parsed.error().message.rfind("test.anim: byte ", 0), 0U)
        << c.what << ": " << parsed.error().message;
  }
}

// Random multi-byte damage with the checksums repaired, so that the structural checks (not the
// CRCs) must catch it. Never a crash; whatever parses must serialise and parse again.
TEST(ModelContainerTest, RandomDamageWithValidChecksumsNeverCrashes) {
  const std::string good = serialize(full_container());
  std::mt19937 random(20240601);
  std::uniform_int_distribution<size_t> position(0, good.size() - 9);
  std::uniform_int_distribution<int> count(1, 4);
  std::uniform_int_distribution<int> value(0, 255);
  int accepted = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::string file = good;
    for (int i = count(random); i > 0; --i) {
      // Bias towards the header and table, where the structure lives.
      size_t at = position(random);
      if (trial % 2 == 0) at %= entry_at(get_u32(good, kSectionCountAt));
      file[at] = static_cast<char>(value(random));
    }
    reseal(file);
    auto parsed = parse(file, kSource);
    if (!parsed.ok()) continue;
    ++accepted;
    ASSERT_TRUE(parse(serialize(*parsed), kSource).ok()) << "trial " << trial;
  }
  EXPECT_LT(accepted, 3000);
}

TEST(ModelContainerTest, TypedGetterMismatchNamesTheSection) {
  ModelContainer c;
  c.set_matrix("weights", FrameMatrix(FrameMatrix::Zero(2, 4)));
  c.set_faces("mesh.faces", FaceMatrix::Zero(5, 3));
  c.set_text("readme", "text");

  struct Mismatch {
    Error error;
    std::string section;
    std::string expected_fragment;
  };
  const std::vector<Mismatch> mismatches = {
      {c.int_matrix("weights").error(), "weights", "expected an int32 matrix, got a float32 matrix (2x4)"},
      {c.points("weights").error(), "weights", "with 3 columns, got a float32 matrix (2x4)"},
      {c.float_matrix("weights", 5).error(), "weights", "with 5 columns"},
      {c.double_matrix("weights").error(), "weights", "expected a float64 matrix"},
      {c.points("mesh.faces").error(), "mesh.faces", "expected a float32 matrix, got an int32 matrix (5x3)"},
      {c.bytes("readme").error(), "readme", "expected bytes, got text"},
      {c.text("weights").error(), "weights", "expected text"},
  };
  for (const Mismatch& m : mismatches) {
    EXPECT_EQ(m.error.code, ErrorCode::kInvalidArgument) << m.error.message;
    EXPECT_NE(m.error.message.find("'" + m.section + "'"), std::string::npos) << m.error.message;
    EXPECT_NE(m.error.message.find(m.expected_fragment), std::string::npos) << m.error.message;
  }
  EXPECT_TRUE(c.faces("mesh.faces").ok());
  EXPECT_TRUE(c.int_matrix("mesh.faces", 3).ok());
  EXPECT_TRUE(c.float_matrix("weights", 4).ok());
}

TEST(ModelContainerTest, MissingSectionIsNotFound) {
  const ModelContainer c = small_container();
  for (const Error& error : {c.bytes("absent").error(), c.text("absent").error(),
                             c.float_matrix("absent").error(), c.points("absent").error(),
                             c.faces("absent").error(), c.double_matrix("absent").error()}) {
    EXPECT_EQ(error.code, ErrorCode::kNotFound);
    EXPECT_NE(error.message.find("'absent'"), std::string::npos) << error.message;
  }
  // The metadata is not a section.
  EXPECT_FALSE(c.has_section("meta"));
  EXPECT_EQ(c.text("meta").error().code, ErrorCode::kNotFound);
}

TEST(ModelContainerTest, SettersReplaceAndNamesAreSorted) {
  ModelContainer c;
  c.set_text("z", "first");
  c.set_bytes("a", "x");
  c.set_text("z", "second");
  EXPECT_EQ(c.section_names(), (std::vector<std::string>{"a", "z"}));
  EXPECT_EQ(*c.text("z"), "second");
  EXPECT_TRUE(c.has_section("a"));
  c.metadata()["kind"] = "pmsc";
  EXPECT_EQ(c.metadata_value("kind"), "pmsc");
  EXPECT_EQ(c.metadata_value("missing", "fallback"), "fallback");
}

TEST(ModelContainerDeathTest, ReservedOrInvalidSectionNamesAreAsserted) {
  ModelContainer c;
  EXPECT_DEBUG_DEATH(c.set_text("meta", "x"), "");
  EXPECT_DEBUG_DEATH(c.set_text("", "x"), "");
  EXPECT_DEBUG_DEATH(c.set_text(std::string(kMaxSectionNameLength + 1, 'n'), "x"), "");
  EXPECT_DEBUG_DEATH(c.set_text("tab\there", "x"), "");
}

TEST(ModelContainerTest, WriteFileReadFileRoundTrip) {
  TempDir dir;
  const fs::path path = dir / "model.anim";
  const ModelContainer original = full_container();
  ASSERT_TRUE(write_file(path, original).ok());
  // Written a piece at a time (issue #53), the file is byte for byte what serialize makes whole.
  const auto on_disk = read_whole_file(path);
  ASSERT_TRUE(on_disk.ok());
  EXPECT_EQ(*on_disk, serialize(original));
  auto loaded = read_file(path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(serialize(*loaded), serialize(original));

  // Overwrite: the new content replaces the old, and no temporary file is left behind.
  ASSERT_TRUE(write_file(path, small_container()).ok());
  auto reloaded = read_file(path);
  ASSERT_TRUE(reloaded.ok()) << reloaded.error().message;
  EXPECT_EQ(reloaded->section_names(), (std::vector<std::string>{"a", "b"}));
  size_t entries = 0;
  for (const auto& entry : fs::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename(), "model.anim");
    ++entries;
  }
  EXPECT_EQ(entries, 1U);
}

TEST(ModelContainerTest, ReadFileErrorsNameThePath) {
  TempDir dir;
  auto missing = read_file(dir / "absent.anim");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);

  const fs::path text_file = dir / "model.txt";
  testing::write_text_file(text_file, "not a model\n");
  auto wrong = read_file(text_file);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(wrong.error().message.rfind(text_file.string() + ": ", 0), 0U) << wrong.error().message;
}

// Issue #54 item 4: a container padded to a sparse gigabyte, or a gigabyte that is no container,
// is refused from its header and the size on disk; neither is read into memory (the peak
// resident size does not grow by anything like it).
TEST(ModelContainerTest, AHugeFileIsJudgedByItsHeaderBeforeItIsRead) {
  TempDir dir;
  constexpr uint64_t kSize = uint64_t{1} << 30;
  const auto peak_rss_bytes = [] {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return static_cast<uint64_t>(usage.ru_maxrss) * 1024;
  };
  const uint64_t peak_before = peak_rss_bytes();

  const fs::path padded = dir / "padded.anim";
  const std::string model = serialize(small_container());
  ASSERT_TRUE(write_file(padded, small_container()).ok());
  ASSERT_EQ(::truncate(padded.c_str(), static_cast<off_t>(kSize)), 0);
  auto refused = read_file(padded);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kDataLoss);
  EXPECT_NE(refused.error().message.find(std::to_string(kSize - model.size()) +
                                         " unexpected bytes after the end of the file"),
            std::string::npos)
      << refused.error().message;

  const fs::path stranger = dir / "stranger.anim";
  testing::write_text_file(stranger, "root:*:19000:0:99999:7:::\n");
  ASSERT_EQ(::truncate(stranger.c_str(), static_cast<off_t>(kSize)), 0);
  refused = read_file(stranger);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("not an animspace model container"), std::string::npos);

  EXPECT_LT(peak_rss_bytes() - peak_before, kSize / 8);
}

TEST(ModelContainerTest, OneRowIsThatRowOfTheWholeMatrix) {
  ModelContainer c;
  FrameMatrix frames(5, 6);
  for (Eigen::Index r = 0; r < frames.rows(); ++r) {
    for (Eigen::Index k = 0; k < frames.cols(); ++k) frames(r, k) = static_cast<float>(10 * r + k) + 0.25f;
  }
  c.set_matrix("frames", frames);
  for (int64_t r = 0; r < 5; ++r) {
    auto row = c.float_matrix_row("frames", r);
    ASSERT_TRUE(row.ok()) << row.error().message;
    ASSERT_EQ(row->rows(), 1);
    EXPECT_EQ(*row, frames.row(r));
  }
  for (int64_t bad : {int64_t{-1}, int64_t{5}}) {
    auto row = c.float_matrix_row("frames", bad);
    ASSERT_FALSE(row.ok());
    EXPECT_EQ(row.error().code, ErrorCode::kOutOfRange);
    EXPECT_NE(row.error().message.find("row " + std::to_string(bad) + " out of range (5 rows)"), std::string::npos)
        << row.error().message;
  }
  EXPECT_EQ(c.float_matrix_row("missing", 0).error().code, ErrorCode::kNotFound);
  c.set_matrix("ints", Int32Matrix(Int32Matrix::Zero(2, 2)));
  EXPECT_EQ(c.float_matrix_row("ints", 0).error().code, ErrorCode::kInvalidArgument);
}

// Issue #53: a matrix moved into a section (its pages given back as they are copied) is the
// section's bytes, whole and row by row, across several copy blocks and an uneven last one;
// the matrix is left empty. Values from a formula, so nothing of the matrix is needed to check.
TEST(ModelContainerTest, AMatrixMovedInIsWhatItHeldAndIsLeftEmpty) {
  const auto value = [](Eigen::Index r, Eigen::Index k) { return static_cast<float>(r) * 0.5f - static_cast<float>(k); };
  FrameMatrix frames(1037, 40001);  // 166 MB: two whole 64 MB blocks and a part
  for (Eigen::Index r = 0; r < frames.rows(); ++r) {
    for (Eigen::Index k = 0; k < frames.cols(); ++k) frames(r, k) = value(r, k);
  }
  ModelContainer c;
  c.set_matrix("frames", std::move(frames));
  EXPECT_EQ(frames.size(), 0);
  auto read = c.float_matrix("frames");
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->rows(), 1037);
  ASSERT_EQ(read->cols(), 40001);
  long wrong = 0;
  for (Eigen::Index r = 0; r < read->rows(); ++r) {
    for (Eigen::Index k = 0; k < read->cols(); ++k) wrong += (*read)(r, k) != value(r, k) ? 1 : 0;
  }
  EXPECT_EQ(wrong, 0);
  auto last = c.float_matrix_row("frames", 1036);
  ASSERT_TRUE(last.ok()) << last.error().message;
  EXPECT_EQ((*last)(0, 40000), value(1036, 40000));
}

// Issue #53: a container read with a resident limit keeps the small sections in memory and leaves
// the large ones on disk; every typed read of either gives what was written, whole or one row, and
// the container writes out unchanged.
TEST(ModelContainerTest, SectionsLeftOnDiskReadBackAsTheyWere) {
  TempDir dir;
  ModelContainer written = full_container();
  FrameMatrix frames(40, 30);
  for (Eigen::Index r = 0; r < frames.rows(); ++r) {
    for (Eigen::Index k = 0; k < frames.cols(); ++k) frames(r, k) = static_cast<float>(r) - 0.125f * static_cast<float>(k);
  }
  written.set_matrix("sequence.frames", frames);  // 4,800 bytes
  const fs::path path = dir / "model.anim";
  ASSERT_TRUE(write_file(path, written).ok());

  constexpr uint64_t kLimit = 64;
  auto lazy = read_file(path, ReadOptions{kLimit});
  ASSERT_TRUE(lazy.ok()) << lazy.error().message;
  uint64_t expected_on_disk = 0;
  for (const auto& [name, section] : written.sections()) {
    const Section& read = lazy->sections().at(name);
    EXPECT_EQ(read.on_disk, section.bytes.size() > kLimit) << name;
    EXPECT_EQ(read.size(), section.bytes.size()) << name;
    EXPECT_EQ(read.bytes.empty(), read.on_disk || section.bytes.empty()) << name;
    if (read.on_disk) expected_on_disk += section.bytes.size();
  }
  EXPECT_GT(expected_on_disk, frames.size() * sizeof(float) - 1);
  EXPECT_EQ(lazy->bytes_on_disk(), expected_on_disk);
  EXPECT_EQ(lazy->metadata(), written.metadata());
  EXPECT_EQ(*lazy->float_matrix("sequence.frames"), frames);
  for (int64_t r : {int64_t{0}, int64_t{17}, int64_t{39}}) EXPECT_EQ(*lazy->float_matrix_row("sequence.frames", r), frames.row(r));
  EXPECT_EQ(lazy->float_matrix_row("sequence.frames", 40).error().code, ErrorCode::kOutOfRange);

  // A copy of a section on disk stays on disk and reads the same; writing reads it from the file.
  ModelContainer copied;
  copied.copy_section(*lazy, "sequence.frames");
  EXPECT_TRUE(copied.sections().at("sequence.frames").on_disk);
  EXPECT_EQ(*copied.float_matrix("sequence.frames"), frames);
  const fs::path again = dir / "again.anim";
  ASSERT_TRUE(write_file(again, *lazy).ok());
  auto whole = read_file(again);
  ASSERT_TRUE(whole.ok()) << whole.error().message;
  EXPECT_EQ(whole->bytes_on_disk(), 0U);
  EXPECT_EQ(serialize(*whole), serialize(written));
  ModelContainer loaded = *lazy;
  ASSERT_TRUE(loaded.load_sections().ok());
  EXPECT_EQ(loaded.bytes_on_disk(), 0U);
  EXPECT_EQ(serialize(loaded), serialize(written));
}

// A file changed after it was read (rewritten in place, replaced by rename, or damaged with its
// size and time kept) makes the reads of the sections left there fail with an error naming the
// file — never a crash, never the new file's values — while the resident sections still read.
TEST(ModelContainerTest, AFileChangedSinceItWasReadFailsTheReadsOfWhatIsLeftThere) {
  TempDir dir;
  ModelContainer written = small_container();
  FrameMatrix frames = FrameMatrix::Constant(50, 20, 1.5f);
  written.set_matrix("sequence.frames", frames);
  const fs::path path = dir / "model.anim";
  const auto read_lazily = [&] {
    EXPECT_TRUE(write_file(path, written).ok());
    auto lazy = read_file(path, ReadOptions{1024});
    EXPECT_TRUE(lazy.ok() && lazy->sections().at("sequence.frames").on_disk);
    return std::move(lazy).value();
  };

  {  // truncated in place (what `cp other.anim model.anim` does first)
    const ModelContainer lazy = read_lazily();
    ASSERT_EQ(::truncate(path.c_str(), 100), 0);
    auto read = lazy.float_matrix("sequence.frames");
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.error().code, ErrorCode::kFailedPrecondition);
    EXPECT_EQ(read.error().message.rfind(path.string() + ": changed since it was loaded", 0), 0U) << read.error().message;
    EXPECT_EQ(lazy.float_matrix_row("sequence.frames", 3).error().code, ErrorCode::kFailedPrecondition);
    EXPECT_TRUE(lazy.float_matrix("a").ok());  // resident
    ModelContainer copy = lazy;
    EXPECT_EQ(copy.load_sections().error().code, ErrorCode::kFailedPrecondition);
    EXPECT_EQ(write_file(dir / "out.anim", lazy).error().code, ErrorCode::kFailedPrecondition);
  }
  {  // replaced by another file of the same size (a new inode)
    const ModelContainer lazy = read_lazily();
    ModelContainer other = written;
    other.set_matrix("sequence.frames", FrameMatrix(FrameMatrix::Constant(50, 20, -7.0f)));
    ASSERT_TRUE(write_file(path, other).ok());
    ASSERT_EQ(fs::file_size(path), serialize(written).size());
    EXPECT_EQ(lazy.float_matrix("sequence.frames").error().code, ErrorCode::kFailedPrecondition);
  }
  {  // damaged in place with its size and modification time kept: the section's CRC catches it
    const ModelContainer lazy = read_lazily();
    struct stat before {};
    ASSERT_EQ(::stat(path.c_str(), &before), 0);
    const uint64_t at = lazy.sections().at("sequence.frames").disk_offset + 8;
    {
      std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
      file.seekp(static_cast<std::streamoff>(at));
      file.put('\x7f');
    }
    const timespec times[2] = {before.st_atim, before.st_mtim};
    ASSERT_EQ(::utimensat(AT_FDCWD, path.c_str(), times, 0), 0);
    auto read = lazy.float_matrix("sequence.frames");
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.error().code, ErrorCode::kDataLoss);
    EXPECT_NE(read.error().message.find("checksum mismatch when read again"), std::string::npos) << read.error().message;
  }
  {  // removed
    const ModelContainer lazy = read_lazily();
    ASSERT_TRUE(fs::remove(path));
    EXPECT_EQ(lazy.float_matrix("sequence.frames").error().code, ErrorCode::kIo);
  }
}

}  // namespace
}  // namespace animspace::container
