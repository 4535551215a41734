#include "core/misslog/miss_frames.h"

#include <algorithm>
#include <system_error>

#include "core/misslog/miss_log.h"

namespace animspace::misslog {

Result<MissFrames> read_miss_frames(const std::filesystem::path& path, uint64_t after_sequence, long width) {
  MissFrames out;
  out.last_sequence = after_sequence;
  out.frames.resize(0, width);
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return out;
  ReadReport report;
  auto records = read_records(path, after_sequence, &report);
  if (!records) return records.error();
  long usable = 0;
  for (const auto& record : *records) usable += static_cast<long>(record.full_values.size()) == width ? 1 : 0;
  out.frames.resize(usable, width);
  long row = 0;
  for (const auto& record : *records) {
    out.last_sequence = std::max(out.last_sequence, record.sequence);
    if (static_cast<long>(record.full_values.size()) != width) {
      ++out.skipped;
      continue;
    }
    out.frames.row(row++) = Eigen::Map<const Eigen::RowVectorXf>(record.full_values.data(), width);
  }
  return out;
}

}  // namespace animspace::misslog
