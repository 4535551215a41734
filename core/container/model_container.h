// The model container: one file holding everything the daemon serves for one model version.
//
// A container is a set of named sections (meshes, matrices, metadata) behind a versioned header
// and checksums, so that a truncated, corrupt, wrong-magic or future-version file is refused with
// a precise error and never half-loaded. Files are written atomically (temporary file, fsync,
// rename, fsync of the directory), so a reader sees either the old file or the complete new one.
// The byte layout is documented in docs/FORMATS.md.
#pragma once

#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::container {

// Bumped when the byte layout changes; readers refuse versions newer than this.
inline constexpr uint32_t kFormatVersion = 1;
// Longest section name, in bytes (names are ASCII, e.g. "mesh.faces"); the on-disk name field
// is one byte longer so that a name is always NUL-terminated.
inline constexpr size_t kMaxSectionNameLength = 47;
// Most sections one container may hold, the metadata section included. Readers refuse larger
// counts before allocating anything.
inline constexpr size_t kMaxSections = 4096;
// The section that stores `metadata()` as a JSON object; reserved, set_* assert it is not used.
inline constexpr std::string_view kMetadataSectionName = "meta";

// How a section's bytes are to be read.
enum class SectionType : uint32_t {
  kBytes = 0,       // opaque bytes
  kText = 1,        // UTF-8 text
  kFloat32Matrix = 2,  // rows × cols float32, row-major
  kInt32Matrix = 3,    // rows × cols int32, row-major
  kFloat64Matrix = 4,  // rows × cols float64, row-major
};

using Int32Matrix = Eigen::Matrix<int32_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Float64Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A container file as read_file found it, so that a section left there is read again only from
// that very file (defined in model_container.cpp).
struct FileIdentity;

struct Section {
  SectionType type = SectionType::kBytes;
  uint32_t rows = 0;  // matrices only
  uint32_t cols = 0;  // matrices only
  std::string bytes;  // payload (for matrices: rows·cols elements, little-endian, row-major)
  // Left on disk by read_file (ReadOptions::resident_section_limit): `bytes` is empty and the
  // payload is disk_size bytes at disk_offset of the container's file, with CRC-32 disk_crc; the
  // typed reads fetch it (or one row of it) from the file each time they are asked.
  bool on_disk = false;
  uint64_t disk_offset = 0;
  uint64_t disk_size = 0;
  uint32_t disk_crc = 0;
  std::shared_ptr<const FileIdentity> disk_file;

  uint64_t size() const { return on_disk ? disk_size : bytes.size(); }
};

// How read_file holds what it read.
struct ReadOptions {
  // Sections whose payload is larger than this stay on disk once the whole file has been checked
  // (every checksum verified): a server then holds, per loaded version, the runtime built from
  // its file and not a second copy of the file (issue #53: a studio model's training frames alone
  // are gigabytes). Each later read of such a section reads the file again, after checking that
  // it is still the file that was loaded (device, inode, size and modification time); a file
  // changed or truncated since is an error of that read, never a crash (why this is not mmap: a
  // mapped file truncated in place — `cp` over it — kills the reader with SIGBUS).
  uint64_t resident_section_limit = std::numeric_limits<uint64_t>::max();
};

// A list of indices as an N × 1 int32 section (offsets, ids, maps).
Int32Matrix as_column(std::span<const int32_t> values);

class ModelContainer {
 public:
  // Free-form string metadata (kind, description, creator, …), stored as a JSON object in the
  // reserved section kMetadataSectionName. Keys and values must be UTF-8 (JSON can hold nothing
  // else): `serialize` writes an invalid sequence as U+FFFD rather than fail.
  std::map<std::string, std::string>& metadata() { return metadata_; }
  const std::map<std::string, std::string>& metadata() const { return metadata_; }
  // The metadata value for `key`, or `fallback` when absent.
  std::string metadata_value(const std::string& key, const std::string& fallback = "") const;
  // The metadata value for `key` as a decimal integer. Errors: kInvalidArgument naming the key
  // and the text when it is absent or not exactly an integer.
  Result<int> metadata_int(const std::string& key) const;

  // Adds or replaces a section. Names must be 1..kMaxSectionNameLength printable ASCII
  // characters (0x20–0x7E), must not be kMetadataSectionName, and a container holds at most
  // kMaxSections - 1 of them (all asserted: names are chosen by code, not by users).
  void set_bytes(const std::string& name, std::string bytes);
  void set_text(const std::string& name, std::string text);
  void set_matrix(const std::string& name, const FrameMatrix& m);
  // The same, taking the matrix: it is copied a block at a time and each block's pages go back to
  // the system once copied, so that a matrix of gigabytes (a studio sequence's training frames,
  // issue #53) is never held twice. `m` is empty afterwards.
  void set_matrix(const std::string& name, FrameMatrix&& m);
  void set_matrix(const std::string& name, const Int32Matrix& m);
  void set_matrix(const std::string& name, const Float64Matrix& m);
  void set_points(const std::string& name, const PointMatrix& m);
  void set_faces(const std::string& name, const FaceMatrix& m);

  bool has_section(std::string_view name) const;
  // Drops a section (no-op when absent): for a writer whose new data makes a stored one stale.
  void remove_section(std::string_view name);
  // Adds or replaces section `name` with `from`'s as it is: one left on disk stays there (read
  // from `from`'s file). Precondition (asserted): `from` has it.
  void copy_section(const ModelContainer& from, const std::string& name);
  std::vector<std::string> section_names() const;  // sorted
  const std::map<std::string, Section, std::less<>>& sections() const { return sections_; }

  // Typed reads. Errors: kNotFound naming the section when it is absent; kInvalidArgument
  // naming the section, the expected and the actual type or shape when it does not match.
  // `expected_cols` < 0 accepts any column count.
  Result<std::string> bytes(std::string_view name) const;
  Result<std::string> text(std::string_view name) const;
  Result<FrameMatrix> float_matrix(std::string_view name, int expected_cols = -1) const;
  // Row `row` alone (1 × cols). Errors as above, and kOutOfRange naming the row and the count.
  Result<FrameMatrix> float_matrix_row(std::string_view name, int64_t row) const;
  Result<Int32Matrix> int_matrix(std::string_view name, int expected_cols = -1) const;
  Result<Float64Matrix> double_matrix(std::string_view name, int expected_cols = -1) const;
  Result<PointMatrix> points(std::string_view name) const;  // a float32 matrix with 3 columns
  Result<FaceMatrix> faces(std::string_view name) const;    // an int32 matrix with 3 columns
  // The reads of a section left on disk (ReadOptions) also fail with kFailedPrecondition naming
  // the file when it changed since it was read, and kDataLoss or kIo when it cannot be read back
  // whole and unchanged (its CRC is checked again on every whole-section read).

  // Sections left on disk by read_file, and their payload bytes in all (0 for a container built
  // in memory or read whole).
  uint64_t bytes_on_disk() const;
  // Reads every section left on disk into memory (before the file goes away, or before
  // serialising). Errors: those of the typed reads.
  Status load_sections();

 private:
  // Fills sections_ and metadata_ directly from validated bytes, without re-encoding.
  friend Result<ModelContainer> parse(std::string_view bytes, std::string_view source);
  friend Result<ModelContainer> read_file(const std::filesystem::path& path, const ReadOptions& options);

  // A section's payload, or `length` bytes of it from `offset` — from memory, or from the file.
  Result<std::string> payload(std::string_view name, const Section& section) const;
  Result<std::string> payload_range(std::string_view name, const Section& section, uint64_t offset,
                                    uint64_t length) const;
  template <typename Matrix>
  Result<Matrix> read_matrix(std::string_view name, SectionType wanted, int expected_cols) const;
  template <typename Matrix>
  Result<Matrix> read_matrix_row(std::string_view name, SectionType wanted, int64_t row) const;

  std::map<std::string, std::string> metadata_;
  std::map<std::string, Section, std::less<>> sections_;
};

// Serialises to the on-disk byte layout (header, section table, payloads, footer checksum);
// docs/FORMATS.md, "Model container (.anim)". Precondition (asserted): no section is left on disk
// (load_sections first; write_file does).
std::string serialize(const ModelContainer& container);

// Parses bytes produced by `serialize`. `source` names the origin in error messages (a path).
// Errors: kInvalidArgument for a wrong magic; kFailedPrecondition for a format version newer
// than kFormatVersion; kDataLoss for truncation, checksum mismatch or inconsistent offsets
// (with the byte offset where the problem was found). Safe on any input: every offset and size
// is checked against `bytes` before it is read, and nothing is allocated beyond what `bytes`
// can justify.
Result<ModelContainer> parse(std::string_view bytes, std::string_view source);

// Reads and parses a container file, keeping the sections `options` says in memory. Errors as
// `parse`, plus kNotFound / kIo for the file, and kFailedPrecondition when it changed while read.
Result<ModelContainer> read_file(const std::filesystem::path& path, const ReadOptions& options = {});

// Writes atomically: a temporary file in the same directory, fsync, rename over `path`, fsync
// of the directory. On failure `path` is untouched and the temporary file removed. Sections left
// on disk are read first (errors as load_sections).
Status write_file(const std::filesystem::path& path, const ModelContainer& container);

}  // namespace animspace::container
