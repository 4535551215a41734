#include "clients/cpp/cli/offline_common.h"

#include <algorithm>
#include <cstdio>

namespace animspace::cli {

int fail(const char* command, const std::string& message) {
  std::fprintf(stderr, "animspace %s: %s\n", command, message.c_str());
  return 2;
}

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

std::filesystem::path model_output_path(const std::string& output, const std::string& model, unsigned version) {
  if (model.empty()) return output;
  const std::filesystem::path dir = std::filesystem::path(output) / model;
  if (version == 0) {
    version = 1;
    std::error_code ec;
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (!name.empty() && name.find_first_not_of("0123456789") == std::string::npos && name[0] != '0') {
        version = std::max(version, static_cast<unsigned>(std::stoul(name)) + 1);
      }
    }
  }
  return dir / std::to_string(version) / "model.anim";
}

Status write_model_file(const std::filesystem::path& path, const container::ModelContainer& model) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) {
    return make_error(ErrorCode::kIo, "cannot create " + path.parent_path().string() + ": " + ec.message());
  }
  return container::write_file(path, model);
}

}  // namespace animspace::cli
