#include "tests/server/support/in_process_server.h"

#include <thread>

#include <gtest/gtest.h>

#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"

namespace animspace::testing {

void RenderLog::record(const render::Scene& scene) {
  std::lock_guard lock(mutex_);
  scenes_.push_back(scene);
}

std::vector<render::Scene> RenderLog::scenes() const {
  std::lock_guard lock(mutex_);
  return scenes_;
}

std::array<uint8_t, 4> FakeRenderer::fake_pixel(int x, int y) {
  return {static_cast<uint8_t>(x), static_cast<uint8_t>(y), static_cast<uint8_t>(x ^ y), 255};
}

Result<render::Image> FakeRenderer::render(const render::Scene& scene) {
  log_->record(scene);
  if (scene.width < 1 || scene.height < 1) return make_error(ErrorCode::kInvalidArgument, "width/height: below 1");
  render::Image image;
  image.width = scene.width;
  image.height = scene.height;
  image.rgba.resize(size_t{4} * static_cast<size_t>(scene.width) * static_cast<size_t>(scene.height));
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const auto pixel = fake_pixel(x, y);
      std::copy(pixel.begin(), pixel.end(), image.rgba.begin() + 4 * (static_cast<ptrdiff_t>(y) * scene.width + x));
    }
  }
  return image;
}

namespace {

// Frames of the demo animation the small models are made from (the demo uses 120).
constexpr int kSmallFrames = 24;

void write_model(const std::filesystem::path& repository, std::string_view name,
                 const Result<container::ModelContainer>& model) {
  ASSERT_TRUE(model.ok()) << name << ": " << model.error().message;
  const auto dir = repository / std::string(name) / "1";
  std::filesystem::create_directories(dir);
  const Status written = container::write_file(dir / "model.anim", *model);
  ASSERT_TRUE(written.ok()) << written.error().message;
}

}  // namespace

void write_small_repository(const std::filesystem::path& repository) {
  write_model(repository, demo::kDemoModelName, demo::make_demo_container({}, kSmallFrames));
  write_model(repository, demo::kDemoPmscModelName, demo::make_demo_pmsc_container(kSmallFrames));
  write_model(repository, demo::kDemoAnimationSpaceModelName, demo::make_demo_animation_space_container(kSmallFrames));
}

InProcessServer::InProcessServer(const std::filesystem::path& repository, server::ServerOptions options) {
  options.repository = repository;
  options.listen_address = "127.0.0.1:0";
  auto renders = renders_;
  daemon_ =
      std::make_unique<server::Daemon>(std::move(options), [renders]() -> Result<std::unique_ptr<render::Renderer>> {
        return std::unique_ptr<render::Renderer>(std::make_unique<FakeRenderer>(renders));
      });
  const Status started = daemon_->start();
  EXPECT_TRUE(started.ok()) << started.error().message;
  if (!started.ok()) return;
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(-1);
  arguments.SetMaxSendMessageSize(-1);
  channel_ = daemon_->in_process_channel(arguments);
}

InProcessServer::~InProcessServer() {
  channel_.reset();
  daemon_->shutdown();
}

bool eventually(const std::function<bool()>& condition, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

void Gate::open() {
  {
    std::lock_guard lock(mutex_);
    open_ = true;
  }
  opened_.notify_all();
}

void Gate::wait() {
  std::unique_lock lock(mutex_);
  opened_.wait(lock, [this] { return open_; });
}

}  // namespace animspace::testing
