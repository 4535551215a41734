#include "core/misslog/miss_frames.h"

#include <algorithm>
#include <system_error>
#include <vector>

#include "core/misslog/miss_log.h"
#include "core/pmsc/local_fail_through.h"

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
  // Rows of the result: a whole frame as logged, or a partial frame completed here.
  std::vector<const float*> rows;
  std::vector<Eigen::VectorXf> completed;
  completed.reserve(records->size());  // rows point into it: no reallocation
  for (const auto& record : *records) {
    out.last_sequence = std::max(out.last_sequence, record.sequence);
    if (!record.full_points.empty()) {
      // A partial frame (local fail-through) is completed from the model that judged it, so only
      // records of that model version, with its key count and points inside it, can be used.
      const long D = model.channel_count;
      const bool usable = !model.cross && record.model_version == model_version &&
                          static_cast<long>(record.key_values.size()) == key_width &&
                          static_cast<long>(record.full_values.size()) ==
                              static_cast<long>(record.full_points.size()) * D &&
                          record.full_points.back() < static_cast<uint32_t>(model.point_count);
      if (!usable) {
        ++out.skipped;
        continue;
      }
      const std::vector<int> points(record.full_points.begin(), record.full_points.end());
      const Eigen::Map<const Eigen::VectorXf> keys(record.key_values.data(), key_width);
      const Eigen::Map<const Eigen::VectorXf> values(record.full_values.data(),
                                                     static_cast<long>(record.full_values.size()));
      if (!pmsc::check_full_values_at_keys(model, keys, points, values).ok()) {
        ++out.inconsistent;
        continue;
      }
      completed.push_back(pmsc::complete_partial_frame(model, keys, points, values));
      rows.push_back(completed.back().data());
      ++out.partial;
      continue;
    }
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
    rows.push_back(record.full_values.data());
  }
  out.frames.resize(static_cast<long>(rows.size()), width);
  for (size_t row = 0; row < rows.size(); ++row) {
    out.frames.row(static_cast<long>(row)) = Eigen::Map<const Eigen::RowVectorXf>(rows[row], width);
  }
  return out;
}

void fit_to_format(const pmsc::PmscModel& model, uint32_t format_version, MissRecord& record) {
  if (record.full_points.empty() || format_version >= kFirstPartialFormatVersion) return;
  const std::vector<int> points(record.full_points.begin(), record.full_points.end());
  const Eigen::Map<const Eigen::VectorXf> key_values(record.key_values.data(),
                                                     static_cast<long>(record.key_values.size()));
  const Eigen::Map<const Eigen::VectorXf> full_values(record.full_values.data(),
                                                      static_cast<long>(record.full_values.size()));
  const Eigen::VectorXf frame = pmsc::complete_partial_frame(model, key_values, points, full_values);
  record.full_values.assign(frame.data(), frame.data() + frame.size());
  record.full_points.clear();
}

}  // namespace animspace::misslog
