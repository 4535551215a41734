#include "core/misslog/miss_frames.h"

#include <algorithm>
#include <system_error>
#include <vector>

#include "core/misslog/miss_log.h"

namespace animspace::misslog {

Result<MissFrames> read_miss_frames(const std::filesystem::path& path, uint64_t after_sequence,
                                    const pmsc::PmscModel& model, uint64_t model_version) {
  const long width = static_cast<long>(model.point_count) * model.channel_count;
  const long key_width = static_cast<long>(model.key_point_count()) * model.channel_count;
  MissFrames out;
  out.last_sequence = after_sequence;
  out.frames.resize(0, width);
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return out;
  ReadReport report;
  auto records = read_records(path, after_sequence, &report);
  if (!records) return records.error();
  std::vector<const MissRecord*> usable;
  for (const auto& record : *records) {
    out.last_sequence = std::max(out.last_sequence, record.sequence);
    if (static_cast<long>(record.full_values.size()) != width) {
      ++out.skipped;
      continue;
    }
    if (!model.cross && record.model_version == model_version &&
        static_cast<long>(record.key_values.size()) == key_width &&
        !pmsc::check_full_values_at_keys(model, Eigen::Map<const Eigen::VectorXf>(record.key_values.data(), key_width),
                                         Eigen::Map<const Eigen::VectorXf>(record.full_values.data(), width))
             .ok()) {
      ++out.inconsistent;
      continue;
    }
    usable.push_back(&record);
  }
  out.frames.resize(static_cast<long>(usable.size()), width);
  for (size_t row = 0; row < usable.size(); ++row) {
    out.frames.row(static_cast<long>(row)) = Eigen::Map<const Eigen::RowVectorXf>(usable[row]->full_values.data(), width);
  }
  return out;
}

}  // namespace animspace::misslog
