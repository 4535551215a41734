#include "clients/cpp/tools/frame_selection.h"

#include <algorithm>
#include <exception>

namespace animspace::tools {

std::vector<int> parse_frame_selection(const std::string& text, int count, std::string* error) {
  std::vector<std::string> parts{""};
  for (char c : text) {
    if (c == ':') parts.emplace_back();
    else parts.back() += c;
  }
  if (parts.size() > 3) {
    *error = "--select: expected start:stop:step, got '" + text + "'";
    return {};
  }
  auto number = [&](const std::string& s, int fallback, bool* ok) {
    if (s.empty()) return fallback;
    try {
      size_t used = 0;
      const int v = std::stoi(s, &used);
      if (used != s.size()) *ok = false;
      return v;
    } catch (const std::exception&) {
      *ok = false;
      return fallback;
    }
  };
  bool ok = true;
  const int step = parts.size() > 2 ? number(parts[2], 1, &ok) : 1;
  int start = number(parts[0], 0, &ok);
  int stop = parts.size() > 1 ? number(parts[1], count, &ok) : start + 1;
  if (!ok || step <= 0) {
    *error = "--select: expected integers start:stop:step with step > 0, got '" + text + "'";
    return {};
  }
  if (start < 0) start += count;
  if (stop < 0) stop += count;
  start = std::max(0, start);
  stop = std::min(count, stop);
  std::vector<int> frames;
  for (int f = start; f < stop; f += step) frames.push_back(f);
  if (frames.empty()) *error = "--select '" + text + "' selects no frame of " + std::to_string(count);
  return frames;
}

FrameMatrix select_rows(const FrameMatrix& frames, const std::vector<int>& rows) {
  FrameMatrix out(static_cast<long>(rows.size()), frames.cols());
  for (size_t i = 0; i < rows.size(); ++i) out.row(static_cast<long>(i)) = frames.row(rows[i]);
  return out;
}

FrameMatrix take_rows(FrameMatrix& frames, const std::vector<int>& rows) {
  bool every_row = static_cast<Eigen::Index>(rows.size()) == frames.rows();
  for (size_t i = 0; every_row && i < rows.size(); ++i) every_row = rows[i] == static_cast<int>(i);
  FrameMatrix out = every_row ? std::move(frames) : select_rows(frames, rows);
  frames = FrameMatrix();
  return out;
}

}  // namespace animspace::tools
