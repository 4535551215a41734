// What the integration tests share: writing a model version into a repository, and waiting for
// a daemon to report SERVING through the client library.
#pragma once

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
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

}  // namespace animspace::testing
