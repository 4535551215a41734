#include "loadtest/workload.h"

#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/pose_file.h"
#include "clients/cpp/tools/sequence_frames.h"

namespace animspace::loadtest {
namespace {

Error invalid(std::string message) { return Error{ErrorCode::kInvalidArgument, std::move(message)}; }

}  // namespace

Result<Rpc> parse_rpc(const std::string& name) {
  if (name == "evaluate") return Rpc::kEvaluate;
  if (name == "stream") return Rpc::kStream;
  if (name == "skinning") return Rpc::kSkinning;
  return invalid("--rpc: expected evaluate, stream or skinning, got '" + name + "'");
}

const char* rpc_name(Rpc rpc) {
  switch (rpc) {
    case Rpc::kEvaluate: return "evaluate";
    case Rpc::kStream: return "stream";
    case Rpc::kSkinning: return "skinning";
  }
  return "?";
}

Result<Workload> make_workload(Client& client, const WorkloadArgs& a) {
  if (a.batch == 0) return invalid("--batch: expected at least 1 pose per call, got 0");
  Workload w;
  w.model = a.model;
  w.rpc = a.rpc;
  w.batch = a.batch;
  w.omit_points = a.omit_points && !a.coordinates;
  w.skip_miss_log = !a.log_misses;
  if (a.coordinates) {
    if (a.rpc == Rpc::kSkinning) return invalid("--coordinates: skeleton poses are answered as points; leave it out");
    w.points_encoding = v1::POINT_ENCODING_COORDINATES;
  }

  if (a.rpc == Rpc::kSkinning) {
    if (a.pose_file.empty()) return invalid("--rpc skinning replays skeleton poses: give --pose-file");
    const v1::ModelSummary summary = client.describe_model(a.model, a.version);
    uint32_t bones = 0;
    for (const auto& v : summary.versions()) {
      const uint64_t wanted = a.version == 0 ? summary.default_version() : a.version;
      if (v.version() == wanted) {
        bones = v.bone_count();
        w.version = v.version();
      }
    }
    if (bones == 0) return invalid("model '" + a.model + "' has no skeleton: --rpc skinning needs one");
    auto poses = tools::read_pose_file(a.pose_file, tools::pose_space(a.pose_space), bones);
    if (!poses) return poses.error();
    w.skeleton_poses = std::move(*poses);
    for (size_t i = 0; i < w.skeleton_poses.size(); ++i) w.frame_numbers.push_back(static_cast<int>(i));
    return w;
  }

  if (a.sequence.empty()) return invalid("--rpc " + std::string(rpc_name(a.rpc)) + " replays a sequence: give --sequence");
  auto frames = tools::load_sequence_frames(a.sequence, a.pc2);
  if (!frames) return frames.error();
  std::string error;
  const std::vector<int> selected = tools::parse_frame_selection(a.select, static_cast<int>(frames->rows()), &error);
  if (selected.empty()) return invalid(error);
  const KeyPoints keys = client.describe_key_points(a.model, a.version);
  if (frames->cols() != static_cast<long>(keys.control_point_count) * keys.channel_count) {
    return invalid(a.sequence + ": " + std::to_string(frames->cols() / std::max(1u, keys.channel_count)) +
                   " points per frame, model '" + a.model + "' expects " + std::to_string(keys.control_point_count));
  }
  w.version = keys.model_version;
  w.channel_count = keys.channel_count;
  for (int f : selected) {
    const std::span<const float> frame(frames->row(f).data(), static_cast<size_t>(frames->cols()));
    w.key_frames.push_back(keys.gather(frame));
    w.check_frames.push_back(keys.gather_check_values(frame));  // a client sends its check points too
    w.frame_numbers.push_back(f);
  }
  return w;
}

}  // namespace animspace::loadtest
