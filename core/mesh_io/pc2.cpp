#include "core/mesh_io/pc2.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>

#include "core/common/atomic_file.h"
#include "core/common/posix_file.h"
#include "core/common/bytes.h"

namespace animspace::mesh_io {
namespace {

static_assert(std::endian::native == std::endian::little,
              "PC2 is little endian and is read and written by copying memory");

constexpr std::string_view kMagic{"POINTCACHE2\0", 12};
constexpr size_t kHeaderBytes = 32;
constexpr size_t kVersionOffset = 12;
constexpr size_t kNumPointsOffset = 16;
constexpr size_t kStartFrameOffset = 20;
constexpr size_t kSampleRateOffset = 24;
constexpr size_t kNumSamplesOffset = 28;

template <typename T>
void store(std::string& bytes, T value) {
  bytes.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

Error at_byte(ErrorCode code, std::string_view source, size_t offset, const std::string& message) {
  return make_error(code, std::string(source) + ": byte " + std::to_string(offset) + ": " + message);
}

// The first non-finite value of `samples`, or -1.
Eigen::Index first_non_finite(const FrameMatrix& samples) {
  const float* values = samples.data();
  for (Eigen::Index i = 0; i < samples.size(); ++i) {
    if (!std::isfinite(values[i])) return i;
  }
  return -1;
}

std::string describe_value(Eigen::Index flat_index, int num_points) {
  static constexpr const char* kAxis[] = {"x", "y", "z"};
  const Eigen::Index per_frame = 3 * Eigen::Index{num_points};
  return "frame " + std::to_string(flat_index / per_frame) + ", point " +
         std::to_string(flat_index % per_frame / 3) + ", " + kAxis[flat_index % 3];
}

Status check_cache(const PointCache& cache) {
  if (cache.num_points <= 0) return make_error(ErrorCode::kInvalidArgument, "num_points must be > 0, got " + std::to_string(cache.num_points));
  if (cache.samples.rows() == 0) return make_error(ErrorCode::kInvalidArgument, "a point cache needs at least one sample");
  if (cache.samples.cols() != 3 * Eigen::Index{cache.num_points}) {
    return make_error(ErrorCode::kInvalidArgument, "samples has " + std::to_string(cache.samples.cols()) +
                                                       " columns, expected 3 × num_points = " +
                                                       std::to_string(3 * Eigen::Index{cache.num_points}));
  }
  if (!std::isfinite(cache.start_frame)) return make_error(ErrorCode::kInvalidArgument, "start_frame is not finite");
  if (!(std::isfinite(cache.sample_rate) && cache.sample_rate > 0)) {
    return make_error(ErrorCode::kInvalidArgument, "sample_rate must be finite and > 0, got " + std::to_string(cache.sample_rate));
  }
  if (const Eigen::Index bad = first_non_finite(cache.samples); bad >= 0) {
    return make_error(ErrorCode::kInvalidArgument, "non-finite value at " + describe_value(bad, cache.num_points));
  }
  return Status::Ok();
}

}  // namespace

PointMatrix PointCache::frame(int index) const {
  assert(index >= 0 && index < num_frames());
  return Eigen::Map<const PointMatrix>(samples.row(index).data(), num_points, 3);
}

namespace {

// The header's fields, checked, and the payload size they promise, checked against the real size
// of the data (`total_size`: the file's, or the bytes') before anything is allocated.
struct Pc2Header {
  PointCache cache;  // counts and frame numbers; samples not yet allocated
  int32_t num_samples = 0;
  uint64_t payload_bytes = 0;
};

Result<Pc2Header> parse_header(std::string_view head, uint64_t total_size, std::string_view source) {
  if (head.size() < kHeaderBytes) {
    return at_byte(ErrorCode::kDataLoss, source, head.size(),
                   "truncated header: expected " + std::to_string(kHeaderBytes) + " bytes, got " +
                       std::to_string(head.size()));
  }
  if (head.substr(0, kMagic.size()) != kMagic) {
    return at_byte(ErrorCode::kInvalidArgument, source, 0, "expected the magic \"POINTCACHE2\\0\", not a PC2 file");
  }
  if (const auto version = load_le<int32_t>(head, kVersionOffset); version != 1) {
    return at_byte(ErrorCode::kFailedPrecondition, source, kVersionOffset,
                   "unsupported version " + std::to_string(version) + ", expected 1");
  }
  Pc2Header header;
  PointCache& cache = header.cache;
  cache.num_points = load_le<int32_t>(head, kNumPointsOffset);
  cache.start_frame = load_le<float>(head, kStartFrameOffset);
  cache.sample_rate = load_le<float>(head, kSampleRateOffset);
  const int32_t num_samples = load_le<int32_t>(head, kNumSamplesOffset);
  if (cache.num_points <= 0) {
    return at_byte(ErrorCode::kInvalidArgument, source, kNumPointsOffset,
                   "expected numPoints > 0, got " + std::to_string(cache.num_points));
  }
  if (!std::isfinite(cache.start_frame)) {
    return at_byte(ErrorCode::kInvalidArgument, source, kStartFrameOffset, "startFrame is not finite");
  }
  if (!(std::isfinite(cache.sample_rate) && cache.sample_rate > 0)) {
    return at_byte(ErrorCode::kInvalidArgument, source, kSampleRateOffset,
                   "expected a finite sampleRate > 0, got " + std::to_string(cache.sample_rate));
  }
  if (num_samples <= 0) {
    return at_byte(ErrorCode::kInvalidArgument, source, kNumSamplesOffset,
                   "expected numSamples > 0, got " + std::to_string(num_samples));
  }

  // The header's counts are untrusted: compare them with the real size before allocating. The
  // payload size can exceed 64 bits (12 · (2^31)^2), hence the overflow check.
  const uint64_t frame_bytes = 3 * sizeof(float) * static_cast<uint64_t>(cache.num_points);
  uint64_t payload_bytes = 0;
  const bool overflows = __builtin_mul_overflow(frame_bytes, static_cast<uint64_t>(num_samples), &payload_bytes) ||
                         payload_bytes > UINT64_MAX - kHeaderBytes;
  if (overflows || payload_bytes + kHeaderBytes != total_size) {
    const bool truncated = overflows || payload_bytes + kHeaderBytes > total_size;
    return at_byte(ErrorCode::kDataLoss, source, total_size,
                   std::string(truncated ? "truncated" : "trailing bytes") + ": the header's " +
                       std::to_string(num_samples) + " samples × " + std::to_string(cache.num_points) +
                       " points need " + (overflows ? "more than 2^64" : std::to_string(payload_bytes + kHeaderBytes)) +
                       " bytes, the data has " + std::to_string(total_size));
  }
  header.num_samples = num_samples;
  header.payload_bytes = payload_bytes;
  return header;
}

// The header's samples allocated (the row-major matrix has the file's layout), or
// kResourceExhausted.
Status allocate_samples(Pc2Header& header, std::string_view source) {
  try {
    header.cache.samples.resize(header.num_samples, 3 * Eigen::Index{header.cache.num_points});
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, std::string(source) + ": out of memory for " +
                                                         std::to_string(header.payload_bytes) + " bytes of samples");
  }
  return Status::Ok();
}

Status check_samples_finite(const PointCache& cache, std::string_view source) {
  if (const Eigen::Index bad = first_non_finite(cache.samples); bad >= 0) {
    return at_byte(ErrorCode::kInvalidArgument, source, kHeaderBytes + sizeof(float) * static_cast<size_t>(bad),
                   "non-finite value at " + describe_value(bad, cache.num_points));
  }
  return Status::Ok();
}

}  // namespace

Result<PointCache> parse_pc2(std::string_view bytes, std::string_view source) {
  auto header = parse_header(bytes.substr(0, kHeaderBytes), bytes.size(), source);
  if (!header.ok()) return header.error();
  ANIMSPACE_RETURN_IF_ERROR(allocate_samples(*header, source));
  std::memcpy(header->cache.samples.data(), bytes.data() + kHeaderBytes, header->payload_bytes);
  ANIMSPACE_RETURN_IF_ERROR(check_samples_finite(header->cache, source));
  return std::move(header->cache);
}

// The samples are read straight into their matrix: a long cache (a studio sequence is gigabytes,
// issue #53) is held once, never also as the file's bytes.
Result<PointCache> read_pc2(const std::filesystem::path& path) {
  const std::string source = path.string();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error_number = errno;
    if (error_number == ENOENT) return make_error(ErrorCode::kNotFound, source + ": no such file");
    return io_error(path, "cannot open", error_number);
  }
  FileDescriptor file(fd);
  struct stat info {};
  if (::fstat(file.get(), &info) != 0) return io_error(path, "cannot stat", errno);
  std::string head(kHeaderBytes, '\0');
  auto got = read_at(file.get(), path, head.data(), kHeaderBytes, 0);
  if (!got.ok()) return got.error();
  head.resize(static_cast<size_t>(*got));
  auto header = parse_header(head, static_cast<uint64_t>(info.st_size), source);
  if (!header.ok()) return header.error();
  ANIMSPACE_RETURN_IF_ERROR(allocate_samples(*header, source));
  got = read_at(file.get(), path, reinterpret_cast<char*>(header->cache.samples.data()), header->payload_bytes,
                kHeaderBytes);
  if (!got.ok()) return got.error();
  if (*got != header->payload_bytes) {
    return at_byte(ErrorCode::kDataLoss, source, kHeaderBytes + *got,
                   "truncated while being read: expected " + std::to_string(header->payload_bytes + kHeaderBytes) +
                       " bytes");
  }
  ANIMSPACE_RETURN_IF_ERROR(check_samples_finite(header->cache, source));
  return std::move(header->cache);
}

std::string pc2_header(int num_points, int num_samples, float start_frame, float sample_rate) {
  assert(num_points > 0 && num_samples > 0);
  std::string bytes;
  bytes.append(kMagic);
  store<int32_t>(bytes, 1);
  store<int32_t>(bytes, num_points);
  store<float>(bytes, start_frame);
  store<float>(bytes, sample_rate);
  store<int32_t>(bytes, num_samples);
  return bytes;
}

std::string serialize_pc2(const PointCache& cache) {
  assert(cache.num_points > 0 && cache.samples.rows() > 0 &&
         cache.samples.cols() == 3 * Eigen::Index{cache.num_points});
  std::string bytes =
      pc2_header(cache.num_points, static_cast<int>(cache.samples.rows()), cache.start_frame, cache.sample_rate);
  bytes.reserve(kHeaderBytes + sizeof(float) * static_cast<size_t>(cache.samples.size()));
  bytes.append(reinterpret_cast<const char*>(cache.samples.data()), sizeof(float) * static_cast<size_t>(cache.samples.size()));
  return bytes;
}

Status write_pc2(const std::filesystem::path& path, const PointCache& cache) {
  if (const Status valid = check_cache(cache); !valid.ok()) {
    return make_error(valid.error().code, path.string() + ": " + valid.error().message);
  }
  try {
    return write_file_atomically(path, serialize_pc2(cache));
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory while writing");
  }
}

}  // namespace animspace::mesh_io
