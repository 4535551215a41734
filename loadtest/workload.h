// What animspace-loadtest sends: real sequences replayed frame by frame. For a PMSC model each
// frame's key points are taken from the frame itself (in DescribeKeyPoints order), as a posing
// engine would compute them; for an animation-space model the frames are skeleton poses from a
// pose file. The frames are prepared once, before any timing starts.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "clients/cpp/client.h"
#include "core/common/result.h"

namespace animspace::loadtest {

enum class Rpc {
  kEvaluate,  // PoseService.EvaluateKeyPoints, `batch` poses per call
  kStream,    // PoseService.StreamKeyPoints, one stream per client, a frame per message
  kSkinning,  // SkinningService.EvaluateSkeletonPose, `batch` poses per call
};

Result<Rpc> parse_rpc(const std::string& name);
const char* rpc_name(Rpc rpc);

struct WorkloadArgs {
  std::string model;
  uint64_t version = 0;  // 0: the served default, resolved once and pinned
  Rpc rpc = Rpc::kEvaluate;
  std::string sequence;   // PC2/OBJ sequence (folder, or mesh + pc2) or a model.anim's frames
  std::string pc2;
  std::string select = "::";
  std::string pose_file;  // kSkinning: poses, 12 numbers per bone each
  std::string pose_space = "global";
  uint32_t batch = 1;
  bool omit_points = true;  // verdicts only: the load is the evaluation, not the transfer
  // Answers as subspace coordinates (POINT_ENCODING_COORDINATES, issue #36): M values per answer
  // instead of N·D points; the load tester does not reconstruct them (`animspace play
  // --coordinates` measures the client's side).
  bool coordinates = false;
  // A load test is test traffic: its blends and misses stay out of the production miss log
  // (skip_miss_log) unless --log-misses asks to load the logging path too (issue #55 item 6).
  bool log_misses = false;
};

struct Workload {
  std::string model;
  uint64_t version = 0;  // resolved
  Rpc rpc = Rpc::kEvaluate;
  uint32_t batch = 1;
  bool omit_points = true;
  bool skip_miss_log = true;
  v1::PointEncoding points_encoding = v1::POINT_ENCODING_UNSPECIFIED;
  uint32_t channel_count = 3;
  std::vector<std::vector<float>> key_frames;  // kEvaluate, kStream: K·D values per frame
  std::vector<std::vector<float>> check_frames;  // the same frames' C·D check values (empty: C = 0)
  std::vector<SkeletonPose> skeleton_poses;    // kSkinning
  std::vector<int> frame_numbers;              // the sequence frame each entry came from

  size_t frame_count() const { return rpc == Rpc::kSkinning ? skeleton_poses.size() : key_frames.size(); }
};

// Reads the frames and asks the server (through `client`) what the model needs. Errors name the
// file or the mismatch (points per frame against the model's control points, bones per pose).
Result<Workload> make_workload(Client& client, const WorkloadArgs& args);

}  // namespace animspace::loadtest
