// Point Cache 2 (.pc2) files: a sequence of point positions, as read and written by Blender and
// 3ds Max (format as documented in ../shared/data/README.md and Blender's io_export_pc2.py).
//
// Layout, little endian, no padding:
//   byte  0  char[12] "POINTCACHE2\0"
//   byte 12  int32    version (1)
//   byte 16  int32    numPoints
//   byte 20  float32  startFrame
//   byte 24  float32  sampleRate (frames between samples)
//   byte 28  int32    numSamples
//   byte 32  float32  numSamples × numPoints × (x, y, z)
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::mesh_io {

struct PointCache {
  float start_frame = 0;  // frame number of the first sample
  float sample_rate = 1;  // frames between consecutive samples, > 0
  int num_points = 0;
  // numSamples by 3·num_points, float32; row s is sample s as x0 y0 z0 x1 y1 z1 …, exactly the
  // file's layout.
  FrameMatrix samples;

  // Sample `index` (0 ≤ index < num_frames()) as a num_points by 3 matrix.
  PointMatrix frame(int index) const;
  int num_frames() const { return static_cast<int>(samples.rows()); }
};

// Parses PC2 bytes; `source` (usually the file name) prefixes every error, which gives the byte
// offset of the offending field or value.
// Errors: kInvalidArgument for a wrong magic, a count ≤ 0, a non-finite or non-positive sample
// rate, a non-finite start frame or a non-finite coordinate (naming frame and point);
// kFailedPrecondition for a version other than 1; kDataLoss when the size disagrees with the
// header (truncated, or trailing bytes: expected vs actual byte count). Counts are checked
// against the actual size before anything is allocated.
Result<PointCache> parse_pc2(std::string_view bytes, std::string_view source);

// Reads and parses a PC2 file. Errors: those of parse_pc2, and kNotFound / kIo from the read.
Result<PointCache> read_pc2(const std::filesystem::path& path);

// The PC2 bytes of `cache`. Precondition (asserted): num_points > 0, at least one sample and
// samples.cols() == 3·num_points; write_pc2 checks these and finiteness for callers with
// untrusted data.
std::string serialize_pc2(const PointCache& cache);

// The 32 header bytes of a PC2 file of `num_samples` samples of `num_points` points: what a
// writer that streams a long sequence sample by sample (never holding it whole) puts first.
// Precondition (asserted): both counts > 0.
std::string pc2_header(int num_points, int num_samples, float start_frame = 0, float sample_rate = 1);

// Writes `cache` to `path` atomically (write_file_atomically).
// Errors: kInvalidArgument when `cache` would not read back (a count ≤ 0, samples.cols() ≠
// 3·num_points, a non-finite value, a sample rate ≤ 0); kIo from the write.
Status write_pc2(const std::filesystem::path& path, const PointCache& cache);

}  // namespace animspace::mesh_io
