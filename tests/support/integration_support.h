// What the integration tests share: writing a model version into a repository, and waiting for
// a daemon to report SERVING through the client library.
#pragma once

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
#include "core/animspace/skeleton.h"
#include "core/container/model_container.h"

namespace animspace::testing {

inline void write_model(const std::filesystem::path& repo, const std::string& name, int version,
                        const container::ModelContainer& model) {
  const auto dir = repo / name / std::to_string(version);
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(container::write_file(dir / "model.anim", model).ok());
}

// Polls health until SERVING (it is NOT_SERVING while the repository loads); false after 30 s.
inline bool wait_until_serving(Client& client) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < deadline) {
    try {
      if (client.health() == grpc::health::v1::HealthCheckResponse::SERVING) return true;
    } catch (const RpcError&) {
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
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

}  // namespace animspace::testing
