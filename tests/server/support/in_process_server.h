// The real services in the test process: server::Daemon (every service, the pools, admission,
// metrics, the registry over a temporary model repository) reached through
// grpc::Server::InProcessChannel, drawing thumbnails with a fake renderer that records each scene
// it is asked for. Service logic is tested here; tests/integration keeps what needs a process of
// its own (signals, flags, the CLI, TLS, a real EGL context).
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "core/render/renderer.h"
#include "server/daemon.h"
#include "server/options.h"
#include "tests/support/test_support.h"

namespace animspace::testing {

// What the fake renderer was asked to draw, in order; shared by the test and the render thread.
class RenderLog {
 public:
  void record(const render::Scene& scene);
  std::vector<render::Scene> scenes() const;

 private:
  mutable std::mutex mutex_;
  std::vector<render::Scene> scenes_;
};

// A renderer that draws nothing: it records the scene and answers an image of the scene's size
// whose pixel (x, y) is fake_pixel(x, y), or the renderer's own refusal of a size below 1.
class FakeRenderer final : public render::Renderer {
 public:
  explicit FakeRenderer(std::shared_ptr<RenderLog> log) : log_(std::move(log)) {}
  Result<render::Image> render(const render::Scene& scene) override;
  std::string description() const override { return kDescription; }

  static constexpr const char* kDescription = "fake renderer (tests/server/support)";
  static std::array<uint8_t, 4> fake_pixel(int x, int y);

 private:
  std::shared_ptr<RenderLog> log_;
};

// The small models the in-process tests serve: the demo's bending arm with fewer frames, so that
// a test process builds its repository in moments (names as in core/demo/demo_repository.h):
// "arm" (mesh sequence), "arm-pmsc" (PMSC) and "arm-animspace" (animation space with LOD levels).
void write_small_repository(const std::filesystem::path& repository);

// A suite of tests over one small repository, written once per suite (it takes seconds).
class SmallRepositoryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repository_ = new TempDir();
    write_small_repository(repository_->path());
  }
  static void TearDownTestSuite() {
    delete repository_;
    repository_ = nullptr;
  }
  static const std::filesystem::path& repository() { return repository_->path(); }

 private:
  static inline TempDir* repository_ = nullptr;
};

class InProcessServer {
 public:
  // Serves `repository` with `options` (its repository and listen address are set here; the
  // address is 127.0.0.1:0, unused by the tests). Fails the test if the daemon does not start.
  explicit InProcessServer(const std::filesystem::path& repository, server::ServerOptions options = {});
  ~InProcessServer();
  InProcessServer(const InProcessServer&) = delete;
  InProcessServer& operator=(const InProcessServer&) = delete;

  // A channel that accepts messages of any size (the server's own limit applies).
  std::shared_ptr<grpc::Channel> channel() const { return channel_; }
  server::ServiceEnvironment& environment() const { return daemon_->environment(); }
  const RenderLog& renders() const { return *renders_; }

 private:
  std::shared_ptr<RenderLog> renders_ = std::make_shared<RenderLog>();
  std::unique_ptr<server::Daemon> daemon_;
  std::shared_ptr<grpc::Channel> channel_;
};

// Polls `condition` until it holds or `timeout` (generous: a state, not a timing) passes.
bool eventually(const std::function<bool()>& condition, std::chrono::seconds timeout = std::chrono::seconds(60));

// A gate pool work waits on, opened by the test: orders events that are races in a real server.
class Gate {
 public:
  void open();
  void wait();

 private:
  std::mutex mutex_;
  std::condition_variable opened_;
  bool open_ = false;
};

}  // namespace animspace::testing
