#include "clients/cpp/tools/pose_file.h"

#include <cmath>
#include <cstdlib>
#include <sstream>

#include "core/common/atomic_file.h"

namespace animspace::tools {

v1::SkeletonPose::Space pose_space(const std::string& name) {
  return name == "local" ? v1::SkeletonPose::SPACE_LOCAL : v1::SkeletonPose::SPACE_GLOBAL;
}

Result<std::vector<SkeletonPose>> read_pose_file(const std::string& path, v1::SkeletonPose::Space space,
                                                 uint32_t bone_count) {
  auto text = read_whole_file(path);
  if (!text) return text.error();
  std::vector<float> values;
  std::istringstream lines(*text);
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    line = line.substr(0, line.find('#'));
    std::istringstream words(line);
    std::string word;
    while (words >> word) {
      char* end = nullptr;
      const float value = std::strtof(word.c_str(), &end);
      if (end != word.c_str() + word.size() || !std::isfinite(value)) {
        return Error{ErrorCode::kInvalidArgument, path + ":" + std::to_string(number) + ": expected a finite number, got '" + word + "'"};
      }
      values.push_back(value);
    }
  }
  const size_t per_pose = bone_count == 0 ? values.size() : size_t{bone_count} * 12;
  if (values.empty() || values.size() % 12 != 0 || values.size() % per_pose != 0) {
    const std::string expected =
        bone_count == 0 ? "12 numbers per bone" : "a multiple of " + std::to_string(per_pose) + " numbers (" +
                                                      std::to_string(bone_count) + " bones × 12 per pose)";
    return Error{ErrorCode::kInvalidArgument, path + ": expected " + expected +
                                                  " (the top three rows of each bone's matrix), got " +
                                                  std::to_string(values.size())};
  }
  std::vector<SkeletonPose> poses;
  for (size_t first = 0; first < values.size(); first += per_pose) {
    poses.push_back({space, std::vector<float>(values.begin() + static_cast<long>(first),
                                               values.begin() + static_cast<long>(first + per_pose))});
  }
  return poses;
}

}  // namespace animspace::tools
