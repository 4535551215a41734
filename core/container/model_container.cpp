// The model container's byte layout is specified in docs/FORMATS.md ("Model container (.anim)");
// the constants below are that table, and the two must change together.
//
// parse() is written for hostile input (it will be fuzzed, and model repositories are copied
// around by hand): every offset and size is checked against the buffer in 64-bit arithmetic that
// cannot overflow before any byte is read, the section count is bounded before anything is
// allocated, and every multi-byte load goes through memcpy (no alignment assumed).
#include "core/container/model_container.h"

#include "core/common/posix_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <new>
#include <utility>

#include <nlohmann/json.hpp>

#include "core/common/atomic_file.h"
#include "core/common/bytes.h"
#include "core/container/crc32.h"

namespace animspace::container {

Int32Matrix as_column(std::span<const int32_t> values) {
  Int32Matrix column(static_cast<Eigen::Index>(values.size()), 1);
  for (size_t i = 0; i < values.size(); ++i) column(static_cast<Eigen::Index>(i), 0) = values[i];
  return column;
}

// The format is little-endian and payloads are memcpy'd to and from Eigen storage as they are.
// A big-endian port would byte-swap in load/store and in the matrix copies.
static_assert(std::endian::native == std::endian::little,
              "the model container code assumes a little-endian host");

namespace {

// --- Layout (docs/FORMATS.md) ------------------------------------------------------------------

// Like PNG's signature: a high-bit byte catches 7-bit channels, CR LF catches CRLF→LF
// conversion, the lone LF catches LF→CRLF conversion, and 0x1A stops `type` on DOS/Windows.
constexpr std::string_view kMagic{"\x89" "ANM\r\n\x1a\n", 8};
constexpr std::string_view kFooterMarker{"AEND", 4};

constexpr uint64_t kHeaderSize = 64;
constexpr uint64_t kEntrySize = 80;
constexpr uint64_t kFooterSize = 8;
constexpr uint64_t kAlignment = 8;
constexpr size_t kNameFieldSize = kMaxSectionNameLength + 1;

// Header field offsets. Bytes 0–15 and the header CRC at 60 keep their meaning in every format
// version, so that any reader can tell corruption from a newer version.
constexpr size_t kMagicAt = 0;
constexpr size_t kVersionAt = 8;
constexpr size_t kHeaderSizeAt = 12;
constexpr size_t kFileSizeAt = 16;
constexpr size_t kSectionCountAt = 24;
constexpr size_t kEntrySizeAt = 28;
constexpr size_t kReservedAt = 32;
constexpr size_t kHeaderCrcAt = 60;

// Section-table entry field offsets, relative to the entry.
constexpr size_t kNameAt = 0;
constexpr size_t kTypeAt = 48;
constexpr size_t kRowsAt = 52;
constexpr size_t kColsAt = 56;
constexpr size_t kPayloadCrcAt = 60;
constexpr size_t kOffsetAt = 64;
constexpr size_t kSizeAt = 72;

static_assert(kNameAt + kNameFieldSize == kTypeAt);
static_assert(kSizeAt + 8 == kEntrySize);
static_assert(kHeaderCrcAt + 4 == kHeaderSize);
static_assert(kHeaderSize % kAlignment == 0 && kEntrySize % kAlignment == 0);
static_assert(kMaxSections * kEntrySize < std::numeric_limits<uint32_t>::max());

// Fuzzers cannot forge CRCs, so a fuzz build (libFuzzer and OSS-Fuzz define this macro) reports
// mismatches as success and lets the structural checks behind them be exercised. Never defined
// in a production build.
#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
constexpr bool kVerifyChecksums = false;
#else
constexpr bool kVerifyChecksums = true;
#endif

uint64_t align_up(uint64_t n) { return (n + kAlignment - 1) / kAlignment * kAlignment; }

// --- Section types -----------------------------------------------------------------------------

constexpr uint32_t kLargestSectionType = static_cast<uint32_t>(SectionType::kFloat64Matrix);

// Bytes per element for matrix types, 0 for the others.
uint64_t element_size(SectionType type) {
  switch (type) {
    case SectionType::kFloat32Matrix: return 4;
    case SectionType::kInt32Matrix: return 4;
    case SectionType::kFloat64Matrix: return 8;
    case SectionType::kBytes:
    case SectionType::kText: return 0;
  }
  return 0;
}

// "an int32 matrix", for messages.
std::string type_phrase(SectionType type) {
  switch (type) {
    case SectionType::kBytes: return "bytes";
    case SectionType::kText: return "text";
    case SectionType::kFloat32Matrix: return "a float32 matrix";
    case SectionType::kInt32Matrix: return "an int32 matrix";
    case SectionType::kFloat64Matrix: return "a float64 matrix";
  }
  return "an unknown type";
}

std::string shape_phrase(const Section& section) {
  std::string phrase = type_phrase(section.type);
  if (element_size(section.type) != 0) {
    phrase += " (" + std::to_string(section.rows) + "x" + std::to_string(section.cols) + ")";
  }
  return phrase;
}

bool is_valid_section_name(std::string_view name) {
  if (name.empty() || name.size() > kMaxSectionNameLength) return false;
  return std::all_of(name.begin(), name.end(), [](char c) { return c >= 0x20 && c <= 0x7E; });
}

// What every set_* asserts before inserting `name`.
[[maybe_unused]] bool can_add_section(const std::map<std::string, Section, std::less<>>& sections,
                     const std::string& name) {
  return is_valid_section_name(name) && name != kMetadataSectionName &&
         (sections.contains(name) || sections.size() + 1 < kMaxSections);
}

// A section's header for matrix m, its bytes still to come.
template <typename Matrix>
Section matrix_header(SectionType type, const Matrix& m) {
  static_assert(Matrix::IsRowMajor || Matrix::ColsAtCompileTime == 1, "sections are row-major");
  assert(sizeof(typename Matrix::Scalar) == element_size(type));
  assert(static_cast<uint64_t>(m.rows()) <= std::numeric_limits<uint32_t>::max());
  assert(static_cast<uint64_t>(m.cols()) <= std::numeric_limits<uint32_t>::max());
  Section section;
  section.type = type;
  section.rows = static_cast<uint32_t>(m.rows());
  section.cols = static_cast<uint32_t>(m.cols());
  return section;
}

template <typename Matrix>
Section matrix_section(SectionType type, const Matrix& m) {
  Section section = matrix_header(type, m);
  section.bytes.resize(static_cast<size_t>(m.size()) * sizeof(typename Matrix::Scalar));
  if (!section.bytes.empty()) std::memcpy(section.bytes.data(), m.data(), section.bytes.size());
  return section;
}

// --- Typed reads -------------------------------------------------------------------------------

Result<const Section*> find_section(const std::map<std::string, Section, std::less<>>& sections,
                                    std::string_view name, SectionType wanted) {
  const auto it = sections.find(name);
  if (it == sections.end()) {
    std::string present;
    for (const auto& [other, unused] : sections) present += (present.empty() ? "" : ", ") + other;
    return make_error(ErrorCode::kNotFound,
                      "section '" + std::string(name) + "' not found (the container has: " +
                          (present.empty() ? "no sections" : present) + ")");
  }
  if (it->second.type != wanted) {
    return make_error(ErrorCode::kInvalidArgument,
                      "section '" + std::string(name) + "': expected " + type_phrase(wanted) +
                          ", got " + shape_phrase(it->second));
  }
  return &it->second;
}

// --- Metadata as JSON --------------------------------------------------------------------------

std::string metadata_to_json(const std::map<std::string, std::string>& metadata) {
  nlohmann::json object = nlohmann::json::object();
  for (const auto& [key, value] : metadata) object[key] = value;
  // `replace` turns invalid UTF-8 into U+FFFD instead of throwing (see ModelContainer::metadata).
  return object.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

// --- Parsing -----------------------------------------------------------------------------------

struct ParsedEntry {
  std::string_view name;
  Section section;  // payload not yet copied
  uint64_t offset = 0;
  uint64_t size = 0;
  uint32_t crc = 0;
  size_t table_at = 0;  // byte offset of the entry, for messages
};

struct Parsed {
  std::map<std::string, std::string> metadata;
  std::vector<std::pair<std::string, Section>> sections;
};

class Parser {
 public:
  Parser(std::string_view bytes, std::string_view source)
      : bytes_(bytes), source_(source), total_size_(bytes.size()) {}

  // A parser of the first bytes of a file of `total_size` bytes: only check_head may be called.
  Parser(std::string_view head, uint64_t total_size, std::string_view source)
      : bytes_(head), source_(source), total_size_(total_size) {}

  // Magic and header against the size on disk, before the rest is read (issue #54 item 4).
  Status check_head() {
    ANIMSPACE_RETURN_IF_ERROR(check_magic());
    return check_header();
  }

  // Sections whose payload is larger than `limit` are checked but not copied: they are left on
  // disk (ReadOptions::resident_section_limit).
  Result<Parsed> run(uint64_t resident_section_limit = std::numeric_limits<uint64_t>::max()) {
    resident_section_limit_ = resident_section_limit;
    ANIMSPACE_RETURN_IF_ERROR(check_magic());
    ANIMSPACE_RETURN_IF_ERROR(check_header());
    ANIMSPACE_RETURN_IF_ERROR(check_footer());
    std::vector<ParsedEntry> entries;
    entries.reserve(section_count_);  // bounded by kMaxSections in check_header
    for (uint32_t i = 0; i < section_count_; ++i) {
      auto entry = read_entry(i);
      if (!entry.ok()) return entry.error();
      entries.push_back(std::move(entry).value());
    }
    ANIMSPACE_RETURN_IF_ERROR(check_names_unique(entries));
    ANIMSPACE_RETURN_IF_ERROR(check_no_overlap(entries));
    return collect(entries);
  }

 private:
  Error data_loss(uint64_t at, const std::string& what) const {
    return make_error(ErrorCode::kDataLoss,
                      std::string(source_) + ": byte " + std::to_string(at) + ": " + what);
  }

  Status check_checksum(uint64_t at, std::string_view what, uint32_t stored,
                        uint32_t computed) const {
    if (kVerifyChecksums && stored != computed) {
      return data_loss(at, std::string(what) + " checksum mismatch: stored " + hex32(stored) +
                               ", computed " + hex32(computed));
    }
    return Status::Ok();
  }

  Status check_magic() const {
    const std::string_view start = bytes_.substr(0, kMagic.size());
    if (start == kMagic) return Status::Ok();
    if (kMagic.starts_with(start)) {
      return data_loss(total_size_, "truncated: the file is " + std::to_string(total_size_) +
                                          " bytes, shorter than the " +
                                          std::to_string(kMagic.size()) + "-byte magic");
    }
    std::string message = std::string(source_) +
                          ": not an animspace model container (bad magic: got " +
                          hex_bytes(start) + ", expected " + hex_bytes(kMagic) + ")";
    if (start.substr(0, 4) == kMagic.substr(0, 4)) {
      message += "; the name matches but the line-ending bytes do not, so the file was probably "
                 "transferred in text mode";
    }
    return make_error(ErrorCode::kInvalidArgument, std::move(message));
  }

  Status check_header() {
    if (total_size_ < kHeaderSize || bytes_.size() < kHeaderSize) {
      return data_loss(total_size_, "truncated: the file is " + std::to_string(total_size_) +
                                          " bytes, the header alone is " +
                                          std::to_string(kHeaderSize));
    }
    // Checked before the version so that a corrupt version field reads as corruption.
    ANIMSPACE_RETURN_IF_ERROR(check_checksum(kHeaderCrcAt, "header", load_le<uint32_t>(bytes_, kHeaderCrcAt),
                                             crc32(bytes_.substr(0, kHeaderCrcAt))));

    const uint32_t version = load_le<uint32_t>(bytes_, kVersionAt);
    if (version > kFormatVersion) {
      return make_error(ErrorCode::kFailedPrecondition,
                        std::string(source_) + ": format version " + std::to_string(version) +
                            " is newer than this build supports (" +
                            std::to_string(kFormatVersion) + ")");
    }
    if (version == 0) return data_loss(kVersionAt, "format version 0 does not exist");

    if (const uint32_t size = load_le<uint32_t>(bytes_, kHeaderSizeAt); size != kHeaderSize) {
      return data_loss(kHeaderSizeAt, "header size is " + std::to_string(size) + ", expected " +
                                          std::to_string(kHeaderSize));
    }
    if (const uint32_t size = load_le<uint32_t>(bytes_, kEntrySizeAt); size != kEntrySize) {
      return data_loss(kEntrySizeAt, "section entry size is " + std::to_string(size) +
                                         ", expected " + std::to_string(kEntrySize));
    }
    for (size_t at = kReservedAt; at < kHeaderCrcAt; ++at) {
      if (bytes_[at] != '\0') return data_loss(at, "reserved header byte is not zero");
    }

    section_count_ = load_le<uint32_t>(bytes_, kSectionCountAt);
    if (section_count_ > kMaxSections) {
      return data_loss(kSectionCountAt, "section count " + std::to_string(section_count_) +
                                            " exceeds the limit of " +
                                            std::to_string(kMaxSections));
    }

    file_size_ = load_le<uint64_t>(bytes_, kFileSizeAt);
    if (file_size_ > total_size_) {
      return data_loss(total_size_, "truncated: the header says the file is " +
                                          std::to_string(file_size_) + " bytes, got " +
                                          std::to_string(total_size_));
    }
    if (file_size_ < total_size_) {
      return data_loss(file_size_, std::to_string(total_size_ - file_size_) +
                                       " unexpected bytes after the end of the file (the header "
                                       "says the file is " +
                                       std::to_string(file_size_) + " bytes)");
    }
    // No overflow: section_count_ <= kMaxSections.
    table_end_ = kHeaderSize + kEntrySize * section_count_;
    if (file_size_ < table_end_ + kFooterSize) {
      return data_loss(kFileSizeAt, "file size " + std::to_string(file_size_) + " is too small for " +
                                        std::to_string(section_count_) +
                                        " sections (at least " +
                                        std::to_string(table_end_ + kFooterSize) + " bytes)");
    }
    payload_end_ = file_size_ - kFooterSize;
    return Status::Ok();
  }

  Status check_footer() const {
    const std::string_view marker = bytes_.substr(payload_end_ + 4, kFooterMarker.size());
    if (marker != kFooterMarker) {
      return data_loss(payload_end_ + 4, "footer marker is " + hex_bytes(marker) + ", expected " +
                                             hex_bytes(kFooterMarker));
    }
    return check_checksum(payload_end_, "file", load_le<uint32_t>(bytes_, payload_end_),
                          crc32(bytes_.substr(0, payload_end_)));
  }

  Result<ParsedEntry> read_entry(uint32_t index) const {
    ParsedEntry entry;
    entry.table_at = kHeaderSize + kEntrySize * index;  // < table_end_ <= bytes_.size()
    const std::string_view raw = bytes_.substr(entry.table_at, kEntrySize);
    const std::string label = "section " + std::to_string(index);

    // Name: 1..47 printable ASCII bytes, then NUL up to the end of the 48-byte field.
    const std::string_view field = raw.substr(kNameAt, kNameFieldSize);
    const size_t length = std::min(field.find('\0'), field.size());
    if (length == 0) return data_loss(entry.table_at, label + " has an empty name");
    if (length > kMaxSectionNameLength) {
      return data_loss(entry.table_at + kMaxSectionNameLength, label + " name is not NUL-terminated");
    }
    for (size_t i = 0; i < kNameFieldSize; ++i) {
      const char c = field[i];
      const bool ok = i < length ? (c >= 0x20 && c <= 0x7E) : c == '\0';
      if (!ok) {
        return data_loss(entry.table_at + i,
                         label + (i < length ? " name has a non-printable byte "
                                             : " name padding has a non-zero byte ") +
                             hex_bytes(field.substr(i, 1)));
      }
    }
    entry.name = field.substr(0, length);
    const std::string where = label + " '" + std::string(entry.name) + "'";

    const uint32_t type = load_le<uint32_t>(raw, kTypeAt);
    if (type > kLargestSectionType) {
      return data_loss(entry.table_at + kTypeAt, where + " has unknown type " + std::to_string(type));
    }
    entry.section.type = static_cast<SectionType>(type);
    entry.section.rows = load_le<uint32_t>(raw, kRowsAt);
    entry.section.cols = load_le<uint32_t>(raw, kColsAt);
    entry.crc = load_le<uint32_t>(raw, kPayloadCrcAt);
    entry.offset = load_le<uint64_t>(raw, kOffsetAt);
    entry.size = load_le<uint64_t>(raw, kSizeAt);

    if (entry.name == kMetadataSectionName && entry.section.type != SectionType::kText) {
      return data_loss(entry.table_at + kTypeAt,
                       where + " is reserved for metadata and must be text, got " +
                           type_phrase(entry.section.type));
    }

    // Shape: rows·cols·element size == size. rows·cols < 2^64 always; the multiplication by the
    // element size is checked.
    const uint64_t element = element_size(entry.section.type);
    if (element == 0) {
      if (entry.section.rows != 0 || entry.section.cols != 0) {
        return data_loss(entry.table_at + kRowsAt,
                         where + " is " + type_phrase(entry.section.type) +
                             " but has a shape (" + std::to_string(entry.section.rows) + "x" +
                             std::to_string(entry.section.cols) + ")");
      }
    } else {
      const uint64_t count = uint64_t{entry.section.rows} * entry.section.cols;
      const bool overflows = count > std::numeric_limits<uint64_t>::max() / element;
      if (overflows || count * element != entry.size) {
        return data_loss(entry.table_at + kSizeAt,
                         where + " is " + shape_phrase(entry.section) + " and needs " +
                             (overflows ? std::string("more than 2^64")
                                        : std::to_string(count * element)) +
                             " bytes, but its size is " + std::to_string(entry.size));
      }
    }

    // Placement: aligned, after the table, before the footer. Written as subtractions from
    // bounds already known to be ordered, so that nothing can wrap.
    if (entry.offset % kAlignment != 0) {
      return data_loss(entry.table_at + kOffsetAt, where + " offset " + std::to_string(entry.offset) +
                                                       " is not a multiple of " +
                                                       std::to_string(kAlignment));
    }
    if (entry.offset < table_end_ || entry.offset > payload_end_ ||
        entry.size > payload_end_ - entry.offset) {
      return data_loss(entry.table_at + kOffsetAt,
                       where + " payload [" + std::to_string(entry.offset) + ", +" +
                           std::to_string(entry.size) + ") lies outside the payload area [" +
                           std::to_string(table_end_) + ", " + std::to_string(payload_end_) + ")");
    }
    return entry;
  }

  Status check_names_unique(const std::vector<ParsedEntry>& entries) const {
    std::map<std::string_view, size_t> seen;
    for (const ParsedEntry& entry : entries) {
      const auto [it, inserted] = seen.emplace(entry.name, entry.table_at);
      if (!inserted) {
        return data_loss(entry.table_at, "section name '" + std::string(entry.name) +
                                             "' appears twice (first at byte " +
                                             std::to_string(it->second) + ")");
      }
    }
    return Status::Ok();
  }

  Status check_no_overlap(const std::vector<ParsedEntry>& entries) const {
    std::vector<const ParsedEntry*> by_offset;
    by_offset.reserve(entries.size());
    for (const ParsedEntry& entry : entries) by_offset.push_back(&entry);
    std::sort(by_offset.begin(), by_offset.end(), [](const ParsedEntry* a, const ParsedEntry* b) {
      return a->offset != b->offset ? a->offset < b->offset : a->size < b->size;
    });
    for (size_t i = 1; i < by_offset.size(); ++i) {
      const ParsedEntry& previous = *by_offset[i - 1];
      const ParsedEntry& current = *by_offset[i];
      // previous.offset + previous.size <= payload_end_ was checked: no overflow.
      if (current.offset < previous.offset + previous.size) {
        return data_loss(current.table_at + kOffsetAt,
                         "section '" + std::string(current.name) + "' payload at " +
                             std::to_string(current.offset) + " overlaps section '" +
                             std::string(previous.name) + "' [" +
                             std::to_string(previous.offset) + ", +" +
                             std::to_string(previous.size) + ")");
      }
    }
    return Status::Ok();
  }

  Result<Parsed> collect(std::vector<ParsedEntry>& entries) const {
    Parsed parsed;
    parsed.sections.reserve(entries.size());
    for (ParsedEntry& entry : entries) {
      // offset + size <= payload_end_ <= bytes_.size(), checked in read_entry.
      const std::string_view payload =
          bytes_.substr(static_cast<size_t>(entry.offset), static_cast<size_t>(entry.size));
      ANIMSPACE_RETURN_IF_ERROR(check_checksum(entry.table_at + kPayloadCrcAt,
                                               "section '" + std::string(entry.name) + "'",
                                               entry.crc, crc32(payload)));
      if (entry.name == kMetadataSectionName) {
        ANIMSPACE_RETURN_IF_ERROR(parse_metadata(payload, entry.offset, parsed.metadata));
        continue;
      }
      if (entry.size > resident_section_limit_) {
        entry.section.on_disk = true;
        entry.section.disk_offset = entry.offset;
        entry.section.disk_size = entry.size;
        entry.section.disk_crc = entry.crc;
      } else {
        entry.section.bytes.assign(payload);
      }
      parsed.sections.emplace_back(std::string(entry.name), std::move(entry.section));
    }
    return parsed;
  }

  // The metadata section is a JSON object whose values are all strings.
  Status parse_metadata(std::string_view text, uint64_t at,
                        std::map<std::string, std::string>& metadata) const {
    // nlohmann 3.11 parses and destroys without recursion, so deep nesting cannot exhaust the
    // stack; it can only fail the object-of-strings check below.
    nlohmann::json document;
    try {
      document = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {
      return data_loss(at, "metadata is not valid JSON: " + std::string(e.what()));
    }
    if (!document.is_object()) {
      return data_loss(at, std::string("metadata is a JSON ") + document.type_name() +
                               ", expected an object");
    }
    for (const auto& [key, value] : document.items()) {
      if (!value.is_string()) {
        return data_loss(at, "metadata value for key '" + key + "' is a JSON " +
                                 value.type_name() + ", expected a string");
      }
      metadata[key] = value.get<std::string>();
    }
    return Status::Ok();
  }

  std::string_view bytes_;
  std::string_view source_;
  uint64_t total_size_;  // the file's size: bytes_.size(), or the size on disk for a head
  uint32_t section_count_ = 0;
  uint64_t file_size_ = 0;
  uint64_t table_end_ = 0;    // first byte after the section table
  uint64_t payload_end_ = 0;  // first byte of the footer
  uint64_t resident_section_limit_ = std::numeric_limits<uint64_t>::max();
};

}  // namespace

// --- ModelContainer ----------------------------------------------------------------------------

Result<int> ModelContainer::metadata_int(const std::string& key) const {
  const std::string text = metadata_value(key);
  int value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
    return make_error(ErrorCode::kInvalidArgument,
                      "metadata '" + key + "' should be an integer, got '" + text + "'");
  }
  return value;
}

std::string ModelContainer::metadata_value(const std::string& key,
                                           const std::string& fallback) const {
  const auto it = metadata_.find(key);
  return it == metadata_.end() ? fallback : it->second;
}

void ModelContainer::set_bytes(const std::string& name, std::string bytes) {
  assert(can_add_section(sections_, name));
  Section section;
  section.type = SectionType::kBytes;
  section.bytes = std::move(bytes);
  sections_[name] = std::move(section);
}

void ModelContainer::set_text(const std::string& name, std::string text) {
  assert(can_add_section(sections_, name));
  Section section;
  section.type = SectionType::kText;
  section.bytes = std::move(text);
  sections_[name] = std::move(section);
}

void ModelContainer::set_matrix(const std::string& name, const FrameMatrix& m) {
  assert(can_add_section(sections_, name));
  sections_[name] = matrix_section(SectionType::kFloat32Matrix, m);
}

void ModelContainer::set_matrix(const std::string& name, FrameMatrix&& m) {
  assert(can_add_section(sections_, name));
  Section section = matrix_header(SectionType::kFloat32Matrix, m);
  const size_t total = static_cast<size_t>(m.size()) * sizeof(float);
  // Reserved, not resized: a resize would write (and so hold) every page before the copy does.
  section.bytes.reserve(total);
  const char* source = reinterpret_cast<const char*>(m.data());
  const auto page = static_cast<uintptr_t>(::sysconf(_SC_PAGESIZE));
  // Only pages wholly inside the matrix are released (its first and last may hold the
  // allocator's bookkeeping); they are never read again before the matrix is freed.
  uintptr_t released = (reinterpret_cast<uintptr_t>(source) + page - 1) / page * page;
  constexpr size_t kBlock = size_t{64} << 20;
  for (size_t done = 0; done < total; done += kBlock) {
    const size_t n = std::min(kBlock, total - done);
    section.bytes.append(source + done, n);
    const uintptr_t copied = (reinterpret_cast<uintptr_t>(source) + done + n) / page * page;
    if (copied > released) {
      ::madvise(reinterpret_cast<void*>(released), copied - released, MADV_DONTNEED);
      released = copied;
    }
  }
  m = FrameMatrix();
  sections_[name] = std::move(section);
}

void ModelContainer::set_matrix(const std::string& name, const Int32Matrix& m) {
  assert(can_add_section(sections_, name));
  sections_[name] = matrix_section(SectionType::kInt32Matrix, m);
}

void ModelContainer::set_matrix(const std::string& name, const Float64Matrix& m) {
  assert(can_add_section(sections_, name));
  sections_[name] = matrix_section(SectionType::kFloat64Matrix, m);
}

void ModelContainer::set_points(const std::string& name, const PointMatrix& m) {
  assert(can_add_section(sections_, name));
  sections_[name] = matrix_section(SectionType::kFloat32Matrix, m);
}

void ModelContainer::set_faces(const std::string& name, const FaceMatrix& m) {
  assert(can_add_section(sections_, name));
  sections_[name] = matrix_section(SectionType::kInt32Matrix, m);
}

bool ModelContainer::has_section(std::string_view name) const {
  return sections_.find(name) != sections_.end();
}

void ModelContainer::copy_section(const ModelContainer& from, const std::string& name) {
  assert(from.has_section(name) && can_add_section(sections_, name));
  sections_[name] = from.sections_.find(name)->second;
}

void ModelContainer::remove_section(std::string_view name) {
  if (const auto at = sections_.find(name); at != sections_.end()) sections_.erase(at);
}

std::vector<std::string> ModelContainer::section_names() const {
  std::vector<std::string> names;
  names.reserve(sections_.size());
  for (const auto& [name, unused] : sections_) names.push_back(name);
  return names;
}

struct FileIdentity {
  std::filesystem::path path;
  uint64_t device = 0;
  uint64_t inode = 0;
  uint64_t size = 0;
  int64_t modified_ns = 0;
};

namespace {

FileIdentity identify(const std::filesystem::path& path, const struct stat& status) {
  FileIdentity identity;
  identity.path = path;
  identity.device = static_cast<uint64_t>(status.st_dev);
  identity.inode = static_cast<uint64_t>(status.st_ino);
  identity.size = static_cast<uint64_t>(status.st_size);
  identity.modified_ns = int64_t{status.st_mtim.tv_sec} * 1'000'000'000 + status.st_mtim.tv_nsec;
  return identity;
}

Result<FileIdentity> identify(const std::filesystem::path& path) {
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0) return io_error(path, "stat", errno);
  return identify(path, status);
}

bool same_file(const FileIdentity& a, const FileIdentity& b) {
  return a.device == b.device && a.inode == b.inode && a.size == b.size && a.modified_ns == b.modified_ns;
}

std::string describe(const FileIdentity& f) {
  return "inode " + std::to_string(f.inode) + ", " + std::to_string(f.size) + " bytes";
}

}  // namespace

Result<std::string> ModelContainer::payload_range(std::string_view name, const Section& section, uint64_t offset,
                                                  uint64_t length) const {
  assert(offset <= section.size() && length <= section.size() - offset);
  if (!section.on_disk) return section.bytes.substr(static_cast<size_t>(offset), static_cast<size_t>(length));
  assert(section.disk_file != nullptr);
  const FileIdentity& file = *section.disk_file;
  const std::filesystem::path& path = file.path;
  const std::string what = "section '" + std::string(name) + "'";
  FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (fd.get() < 0) return io_error(path, "open to read " + what + " again", errno);
  struct stat status {};
  if (::fstat(fd.get(), &status) != 0) return io_error(path, "fstat", errno);
  const FileIdentity now = identify(path, status);
  if (!same_file(now, file)) {
    return make_error(ErrorCode::kFailedPrecondition,
                      path.string() + ": changed since it was loaded (" + describe(file) + " then, " + describe(now) +
                          " now), so its " + what + " cannot be read: load the version again");
  }
  std::string out(static_cast<size_t>(length), '\0');
  auto done = read_at(fd.get(), path, out.data(), length, section.disk_offset + offset);
  if (!done.ok()) return done.error();
  if (*done != length) {
    return make_error(ErrorCode::kDataLoss, path.string() + ": byte " +
                                                std::to_string(section.disk_offset + offset + *done) + ": " + what +
                                                " ends early: expected " + std::to_string(length) + " bytes, got " +
                                                std::to_string(*done));
  }
  return out;
}

Result<std::string> ModelContainer::payload(std::string_view name, const Section& section) const {
  auto bytes = payload_range(name, section, 0, section.size());
  if (!bytes.ok() || !section.on_disk) return bytes;
  if (const uint32_t computed = crc32(*bytes); kVerifyChecksums && computed != section.disk_crc) {
    return make_error(ErrorCode::kDataLoss,
                      section.disk_file->path.string() + ": byte " + std::to_string(section.disk_offset) +
                          ": section '" + std::string(name) + "' checksum mismatch when read again: stored " +
                          hex32(section.disk_crc) + ", computed " + hex32(computed));
  }
  return bytes;
}

template <typename Matrix>
Result<Matrix> ModelContainer::read_matrix(std::string_view name, SectionType wanted, int expected_cols) const {
  auto found = find_section(sections_, name, wanted);
  if (!found.ok()) return found.error();
  const Section& section = **found;
  if (expected_cols >= 0 && section.cols != static_cast<uint32_t>(expected_cols)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "section '" + std::string(name) + "': expected " + type_phrase(wanted) +
                          " with " + std::to_string(expected_cols) + " columns, got " +
                          shape_phrase(section));
  }
  // parse() and set_* guarantee rows·cols·element size == the payload's size.
  assert(static_cast<uint64_t>(section.rows) * section.cols * sizeof(typename Matrix::Scalar) == section.size());
  Matrix m(static_cast<Eigen::Index>(section.rows), static_cast<Eigen::Index>(section.cols));
  if (!section.on_disk) {
    if (!section.bytes.empty()) std::memcpy(m.data(), section.bytes.data(), section.bytes.size());
    return m;
  }
  auto bytes = payload(name, section);
  if (!bytes.ok()) return bytes.error();
  if (!bytes->empty()) std::memcpy(m.data(), bytes->data(), bytes->size());
  return m;
}

// One row of a matrix section, copied alone (a frame of a long sequence without the rest; from
// the file, one row's bytes).
template <typename Matrix>
Result<Matrix> ModelContainer::read_matrix_row(std::string_view name, SectionType wanted, int64_t row) const {
  auto found = find_section(sections_, name, wanted);
  if (!found.ok()) return found.error();
  const Section& section = **found;
  if (row < 0 || row >= static_cast<int64_t>(section.rows)) {
    return make_error(ErrorCode::kOutOfRange, "section '" + std::string(name) + "': row " + std::to_string(row) +
                                                  " out of range (" + std::to_string(section.rows) + " rows)");
  }
  const size_t row_bytes = size_t{section.cols} * sizeof(typename Matrix::Scalar);
  Matrix m(1, static_cast<Eigen::Index>(section.cols));
  if (row_bytes == 0) return m;
  auto bytes = payload_range(name, section, static_cast<uint64_t>(row) * row_bytes, row_bytes);
  if (!bytes.ok()) return bytes.error();
  std::memcpy(m.data(), bytes->data(), row_bytes);
  return m;
}

uint64_t ModelContainer::bytes_on_disk() const {
  uint64_t total = 0;
  for (const auto& [name, section] : sections_) total += section.on_disk ? section.disk_size : 0;
  return total;
}

Status ModelContainer::load_sections() {
  for (auto& [name, section] : sections_) {
    if (!section.on_disk) continue;
    auto bytes = payload(name, section);
    if (!bytes.ok()) return bytes.error();
    section.bytes = std::move(*bytes);
    section.on_disk = false;
    section.disk_file.reset();
  }
  return Status::Ok();
}

Result<std::string> ModelContainer::bytes(std::string_view name) const {
  auto found = find_section(sections_, name, SectionType::kBytes);
  if (!found.ok()) return found.error();
  return payload(name, **found);
}

Result<std::string> ModelContainer::text(std::string_view name) const {
  auto found = find_section(sections_, name, SectionType::kText);
  if (!found.ok()) return found.error();
  return payload(name, **found);
}

Result<FrameMatrix> ModelContainer::float_matrix(std::string_view name, int expected_cols) const {
  return read_matrix<FrameMatrix>(name, SectionType::kFloat32Matrix, expected_cols);
}

Result<FrameMatrix> ModelContainer::float_matrix_row(std::string_view name, int64_t row) const {
  return read_matrix_row<FrameMatrix>(name, SectionType::kFloat32Matrix, row);
}

Result<Int32Matrix> ModelContainer::int_matrix(std::string_view name, int expected_cols) const {
  return read_matrix<Int32Matrix>(name, SectionType::kInt32Matrix, expected_cols);
}

Result<Float64Matrix> ModelContainer::double_matrix(std::string_view name,
                                                    int expected_cols) const {
  return read_matrix<Float64Matrix>(name, SectionType::kFloat64Matrix, expected_cols);
}

Result<PointMatrix> ModelContainer::points(std::string_view name) const {
  return read_matrix<PointMatrix>(name, SectionType::kFloat32Matrix, 3);
}

Result<FaceMatrix> ModelContainer::faces(std::string_view name) const {
  return read_matrix<FaceMatrix>(name, SectionType::kInt32Matrix, 3);
}

// --- Serialisation -----------------------------------------------------------------------------

namespace {

// The file as pieces in order (header and section table, each payload, padding, footer), the
// checksums computed before or as they go, so that writing a file never holds it whole (issue #53:
// a model with 1.1 GB of training frames was serialised into a second 1.1 GB string).
void emit(const ModelContainer& container, const AppendPiece& append) {
  struct Planned {
    std::string_view name;
    SectionType type;
    uint32_t rows;
    uint32_t cols;
    std::string_view payload;
    uint64_t offset;
  };
  const std::string metadata_json = metadata_to_json(container.metadata());

  // Plan: metadata first, then the sections in name order, each payload 8-byte aligned.
  std::vector<Planned> planned;
  planned.reserve(container.sections().size() + 1);
  planned.push_back({kMetadataSectionName, SectionType::kText, 0, 0, metadata_json, 0});
  for (const auto& [name, section] : container.sections()) {
    assert(is_valid_section_name(name) && name != kMetadataSectionName && !section.on_disk);
    planned.push_back({name, section.type, section.rows, section.cols, section.bytes, 0});
  }
  assert(planned.size() <= kMaxSections);
  const uint64_t table_end = kHeaderSize + kEntrySize * planned.size();
  uint64_t cursor = table_end;
  for (Planned& p : planned) {
    p.offset = cursor;
    cursor = align_up(cursor + p.payload.size());
  }
  const uint64_t payload_end = cursor;
  const uint64_t file_size = payload_end + kFooterSize;

  // Header and section table, zero-filled so that reserved bytes need no code.
  std::string head(static_cast<size_t>(table_end), '\0');
  for (size_t i = 0; i < planned.size(); ++i) {
    const Planned& p = planned[i];
    const size_t entry_at = kHeaderSize + kEntrySize * i;
    // min() keeps a release build (asserts off) from writing past the name field.
    std::memcpy(head.data() + entry_at + kNameAt, p.name.data(), std::min(p.name.size(), kMaxSectionNameLength));
    store_le<uint32_t>(head, entry_at + kTypeAt, static_cast<uint32_t>(p.type));
    store_le<uint32_t>(head, entry_at + kRowsAt, p.rows);
    store_le<uint32_t>(head, entry_at + kColsAt, p.cols);
    store_le<uint32_t>(head, entry_at + kPayloadCrcAt, crc32(p.payload));
    store_le<uint64_t>(head, entry_at + kOffsetAt, p.offset);
    store_le<uint64_t>(head, entry_at + kSizeAt, p.payload.size());
  }
  std::memcpy(head.data() + kMagicAt, kMagic.data(), kMagic.size());
  store_le<uint32_t>(head, kVersionAt, kFormatVersion);
  store_le<uint32_t>(head, kHeaderSizeAt, static_cast<uint32_t>(kHeaderSize));
  store_le<uint64_t>(head, kFileSizeAt, file_size);
  store_le<uint32_t>(head, kSectionCountAt, static_cast<uint32_t>(planned.size()));
  store_le<uint32_t>(head, kEntrySizeAt, static_cast<uint32_t>(kEntrySize));
  store_le<uint32_t>(head, kHeaderCrcAt, crc32(std::string_view(head).substr(0, kHeaderCrcAt)));

  // The footer's CRC runs over every byte before it, piece by piece.
  uint32_t file_crc = 0;
  const auto write = [&](std::string_view piece) {
    file_crc = crc32_update(file_crc, piece);
    return append(piece);
  };
  if (!write(head)) return;
  static constexpr char kZeros[8] = {};
  uint64_t written = table_end;
  for (const Planned& p : planned) {
    assert(written == p.offset);
    if (!write(p.payload)) return;
    written += p.payload.size();
    const uint64_t padding = align_up(written) - written;
    if (padding > 0 && !write(std::string_view(kZeros, static_cast<size_t>(padding)))) return;
    written += padding;
  }
  assert(written == payload_end);
  std::string footer(static_cast<size_t>(kFooterSize), '\0');
  store_le<uint32_t>(footer, 0, file_crc);
  std::memcpy(footer.data() + 4, kFooterMarker.data(), kFooterMarker.size());
  append(footer);
}

}  // namespace

std::string serialize(const ModelContainer& container) {
  std::string out;
  emit(container, [&](std::string_view piece) {
    out.append(piece);
    return true;
  });
  return out;
}

Result<ModelContainer> parse(std::string_view bytes, std::string_view source) {
  try {
    auto parsed = Parser(bytes, source).run();
    if (!parsed.ok()) return parsed.error();
    ModelContainer container;
    container.metadata_ = std::move(parsed->metadata);
    for (auto& [name, section] : parsed->sections) {
      container.sections_.emplace(std::move(name), std::move(section));
    }
    return container;
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted,
                      std::string(source) + ": out of memory while reading the model container");
  } catch (const std::exception& e) {
    return make_error(ErrorCode::kInternal,
                      std::string(source) + ": unexpected error while reading the model "
                                            "container: " + e.what());
  }
}

Result<ModelContainer> read_file(const std::filesystem::path& path, const ReadOptions& options) {
  const std::string source = path.string();
  const bool keep_on_disk = options.resident_section_limit != std::numeric_limits<uint64_t>::max();
  // What the file is before and after it is read: sections left on disk are read again only from
  // this very file.
  Result<FileIdentity> before = FileIdentity{};
  if (keep_on_disk) before = identify(path);
  auto bytes = read_regular_file(path, kHeaderSize, [&](std::string_view head, uint64_t size_on_disk) {
    return Parser(head, size_on_disk, source).check_head();
  });
  if (!bytes.ok()) return bytes.error();
  if (!before.ok()) return before.error();
  try {
    auto parsed = Parser(*bytes, source).run(options.resident_section_limit);
    if (!parsed.ok()) return parsed.error();
    bytes->clear();
    bytes->shrink_to_fit();
    ModelContainer container;
    container.metadata_ = std::move(parsed->metadata);
    std::shared_ptr<const FileIdentity> file;
    for (auto& [name, section] : parsed->sections) {
      if (section.on_disk && file == nullptr) {
        auto after = identify(path);
        if (!after.ok()) return after.error();
        if (!same_file(*before, *after)) {
          return make_error(ErrorCode::kFailedPrecondition, source + ": changed while it was being read (" +
                                                                describe(*before) + " before, " + describe(*after) +
                                                                " after): read it again");
        }
        file = std::make_shared<const FileIdentity>(std::move(*after));
      }
      if (section.on_disk) section.disk_file = file;
      container.sections_.emplace(std::move(name), std::move(section));
    }
    return container;
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, source + ": out of memory while reading the model container");
  } catch (const std::exception& e) {
    return make_error(ErrorCode::kInternal,
                      source + ": unexpected error while reading the model container: " + e.what());
  }
}

Status write_file(const std::filesystem::path& path, const ModelContainer& container) {
  try {
    if (container.bytes_on_disk() > 0) {
      ModelContainer resident = container;
      ANIMSPACE_RETURN_IF_ERROR(resident.load_sections());
      return write_file_atomically(path, [&](const AppendPiece& append) { emit(resident, append); });
    }
    return write_file_atomically(path, [&](const AppendPiece& append) { emit(container, append); });
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted,
                      path.string() + ": out of memory while serialising the model container");
  }
}

}  // namespace animspace::container
