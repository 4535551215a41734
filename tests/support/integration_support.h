// What the integration tests share: writing a model version into a repository, and waiting for
// a daemon (or a client) to reach a state.
#pragma once

#include <chrono>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
#include "core/animspace/skeleton.h"
#include "core/container/model_container.h"
#include "core/demo/bending_arm.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/train.h"

namespace animspace::testing {

inline void write_model(const std::filesystem::path& repo, const std::string& name, int version,
                        const container::ModelContainer& model) {
  const auto dir = repo / name / std::to_string(version);
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(container::write_file(dir / "model.anim", model).ok());
}

// How the tests wait (STYLE.md §8): for a state they can observe — a version served, a counter
// reached, a file present — polled every `poll` until `timeout`, never for a fixed time. The
// timeout is a generous bound for a loaded or sanitizer-built machine, not an expected duration:
// a state that comes at all comes long before it. True when `condition` held, false on timeout.
inline bool wait_until(const std::function<bool()>& condition,
                       std::chrono::milliseconds timeout = std::chrono::seconds(60),
                       std::chrono::milliseconds poll = std::chrono::milliseconds(2)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(poll);
  }
  return true;
}

// Polls health until SERVING (it is NOT_SERVING while the repository loads); false after 30 s.
inline bool wait_until_serving(Client& client) {
  return wait_until(
      [&client] {
        try {
          return client.health() == grpc::health::v1::HealthCheckResponse::SERVING;
        } catch (const RpcError&) {
          return false;
        }
      },
      std::chrono::seconds(30), std::chrono::milliseconds(20));
}

// The status code `call` ends with: OK, or the code of the RpcError it throws.
inline grpc::StatusCode code_of(const std::function<void()>& call) {
  try {
    call();
    return grpc::StatusCode::OK;
  } catch (const RpcError& e) {
    return e.code();
  }
}

// Global transforms G_j as the client's SkeletonPose (SPACE_GLOBAL, 12 floats per bone, rows 0–2).
inline SkeletonPose client_skeleton_pose(const animation_space::TransformList& globals) {
  SkeletonPose pose;
  pose.space = v1::SkeletonPose::SPACE_GLOBAL;
  for (const auto& G : globals) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) pose.transforms.push_back(static_cast<float>(G(r, c)));
    }
  }
  return pose;
}

// The same pose on the wire.
inline v1::SkeletonPose global_skeleton_pose(const animation_space::TransformList& globals) {
  return encode_skeleton_pose(client_skeleton_pose(globals));
}

// The bending arm posed by its expensive rig (biceps bulge and elbow correction included),
// point-major (x0 y0 z0 x1 …).
inline Eigen::VectorXf expensive_arm_frame(const demo::ArmRig& rig, double elbow_deg, double shoulder_deg) {
  constexpr double kDegree = 3.14159265358979323846 / 180.0;
  demo::ArmPose pose;
  pose.elbow_angle_rad = elbow_deg * kDegree;
  pose.shoulder_angle_rad = shoulder_deg * kDegree;
  const PointMatrix points = demo::pose_expensive(pose, rig);
  return Eigen::Map<const Eigen::VectorXf>(points.data(), points.size());
}

// A PMSC model of the arm trained only on elbow angles 0°–50° (every `elbow_step_deg`, shoulder
// −20°, 0°, 20°): a bent elbow at 120° is a pose it has never seen (a miss) until it is retrained
// with that pose. A finer `arm` mesh or a smaller step makes a bigger model that trains longer.
// With `remove_rigid_motion` the model is aligned (its answers carry a rigid transform).
inline container::ModelContainer narrow_arm_model(const demo::BendingArmOptions& arm = {},
                                                  double elbow_step_deg = 5, bool remove_rigid_motion = false) {
  const demo::ArmRig rig = demo::make_arm_rig(arm);
  std::vector<Eigen::VectorXf> frames;
  for (double elbow = 0; elbow <= 50; elbow += elbow_step_deg) {
    for (double shoulder : {-20.0, 0.0, 20.0}) frames.push_back(expensive_arm_frame(rig, elbow, shoulder));
  }
  FrameMatrix training(static_cast<Eigen::Index>(frames.size()), frames[0].size());
  for (size_t f = 0; f < frames.size(); ++f) training.row(static_cast<Eigen::Index>(f)) = frames[f].transpose();
  const double diagonal = pmsc::bounding_box_diagonal(frames[0]);
  pmsc::TrainingOptions options;
  options.error_bound = 0.0025 * diagonal;
  options.error_tolerance = 0.01 * diagonal;
  options.max_key_points = 60;
  options.region_count = 0;
  options.remove_rigid_motion = remove_rigid_motion;
  pmsc::TrainingReport report;
  auto model = pmsc::train(training, options, &report);
  EXPECT_TRUE(model.ok()) << model.error().message;
  auto out = pmsc::make_container(rig.rest, training, nullptr, *model, report, "arm, elbow 0-50 degrees only");
  pmsc::store_training_options(options, out);
  return out;
}

}  // namespace animspace::testing
