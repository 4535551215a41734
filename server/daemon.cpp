#include "server/daemon.h"

#include <grpc/grpc.h>
#include <sys/socket.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <httplib.h>
#include <spdlog/spdlog.h>

#include "core/common/atomic_file.h"
#include "core/common/kernels.h"
#include "server/port_owner.h"
#include "server/server_builder.h"
#include "server/services/lod_service.h"
#include "server/services/model_service.h"
#include "server/services/pose_service.h"
#include "server/services/render_service.h"
#include "server/services/skinning_service.h"
#include "server/services/stats_service.h"
#include "server/services/training_service.h"

namespace animspace::server {
namespace {

// Who holds `address`'s port when a bind failed, if anyone does.
std::optional<std::string> busy_address_owner(const std::string& address) {
  const auto port = port_of_address(address);
  return port ? describe_tcp_listener(*port) : std::nullopt;
}

// Splits "host:port" (or "[v6]:port"). Errors: kInvalidArgument naming the flag.
Result<std::pair<std::string, int>> split_host_port(const std::string& address, const char* flag) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size()) {
    return make_error(ErrorCode::kInvalidArgument,
                      std::string(flag) + ": expected host:port, got '" + address + "'");
  }
  std::string host = address.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  int port = -1;
  try {
    size_t used = 0;
    port = std::stoi(address.substr(colon + 1), &used);
    if (used != address.size() - colon - 1) port = -1;
  } catch (const std::exception&) {
    port = -1;
  }
  if (port < 0 || port > 65535) {
    return make_error(ErrorCode::kInvalidArgument,
                      std::string(flag) + ": port must be 0..65535, got '" + address.substr(colon + 1) + "'");
  }
  return std::make_pair(host, port);
}

}  // namespace

Daemon::Daemon(ServerOptions options, MakeRenderer make_renderer)
    : options_(std::move(options)),
      make_renderer_(std::move(make_renderer)),
      registry_(options_.repository, options_.resident_section_bytes, options_.memory_budget_bytes),
      admission_(options_.max_concurrent_calls) {}

Daemon::~Daemon() { shutdown(); }

Status Daemon::start() {
  std::error_code ec;
  if (!std::filesystem::is_directory(options_.repository, ec)) {
    return make_error(ErrorCode::kNotFound,
                      "--model-repository: '" + options_.repository.string() + "' is not a directory");
  }

  ANIMSPACE_RETURN_IF_ERROR(check_transport_options(options_));
  auto authenticator = Authenticator::from_options(options_);
  if (!authenticator) return authenticator.error();
  authenticator_ = std::make_unique<Authenticator>(std::move(*authenticator));
  auto credentials = make_server_credentials(options_);
  if (!credentials) return credentials.error();
  auto fsync_policy = misslog::parse_fsync_policy(options_.miss_log_fsync);
  if (!fsync_policy) return fsync_policy.error();
  const auto miss_log_dir = options_.miss_log_dir.empty() ? options_.repository : options_.miss_log_dir;
  if (!std::filesystem::is_directory(miss_log_dir, ec)) {
    return make_error(ErrorCode::kNotFound, "--miss-log-dir: '" + miss_log_dir.string() + "' is not a directory");
  }
  miss_logs_ = std::make_unique<MissLogs>(miss_log_dir, *fsync_policy, options_.miss_log_fsync_interval,
                                          options_.miss_log_max_bytes);
  Kernel kernel = Kernel::kBlas;
  if (!parse_kernel(options_.kernel, kernel)) {
    return make_error(ErrorCode::kInvalidArgument, "--kernel: expected blas or portable, got '" + options_.kernel + "'");
  }
  if (options_.max_batch_size < 1) {
    return make_error(ErrorCode::kInvalidArgument, "--max-batch-size: expected at least 1, got 0");
  }
  use_kernel(kernel);
  batcher_ = std::make_unique<PoseBatcher>(PoseBatcher::Options{options_.batch_delay, options_.max_batch_size});
  request_pool_ = std::make_unique<WorkPool>(
      options_.work_threads > 0 ? options_.work_threads : default_work_threads(), "animspace-work");
  admin_pool_ = std::make_unique<WorkPool>(1, "animspace-admin");
  env_ = std::make_unique<ServiceEnvironment>(ServiceEnvironment{registry_, metrics_, options_, *request_pool_,
                                                                 *admin_pool_, admission_, *authenticator_,
                                                                 *miss_logs_, *batcher_});

  ANIMSPACE_RETURN_IF_ERROR(start_renderer());

  model_service_ = std::make_unique<ModelServiceImpl>(*env_);
  stats_service_ = std::make_unique<StatsServiceImpl>(*env_);
  pose_service_ = std::make_unique<PoseServiceImpl>(*env_);
  skinning_service_ = std::make_unique<SkinningServiceImpl>(*env_);
  lod_service_ = std::make_unique<LodServiceImpl>(*env_);
  render_service_ = std::make_unique<RenderServiceImpl>(*env_);
  training_service_ = std::make_unique<TrainingServiceImpl>(*env_);

  raise_descriptor_limit();
  auto listener = Listener::bind(options_.listen_address);
  if (!listener) return listener.error();
  listener_ = std::move(*listener);
  port_ = listener_->port();
  std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor;
  const auto builder = make_server_builder(options_, *credentials, &acceptor);
  builder->RegisterService(model_service_.get());
  builder->RegisterService(stats_service_.get());
  builder->RegisterService(pose_service_.get());
  builder->RegisterService(skinning_service_.get());
  builder->RegisterService(lod_service_.get());
  builder->RegisterService(render_service_.get());
  builder->RegisterService(training_service_.get());
  server_ = builder->BuildAndStart();
  if (!server_) {
    listener_.reset();
    return start_failure(options_);
  }
  listener_->start(std::move(acceptor));
  // Health is NOT_SERVING until the repository is loaded, so that load balancers and probes
  // wait for a replica that can answer.
  server_->GetHealthCheckService()->SetServingStatus(false);
  spdlog::info("listening on {} (port {}), health NOT_SERVING while loading", options_.listen_address, port_);
  if (!options_.port_file.empty()) {
    ANIMSPACE_RETURN_IF_ERROR(write_file_atomically(options_.port_file, std::to_string(port_) + "\n"));
  }
  ANIMSPACE_RETURN_IF_ERROR(start_metrics_endpoint());

  miss_logs_->recover_existing();
  const int loaded = registry_.load_all();
  refresh_model_gauges(*env_);
  spdlog::info("repository {}: {} model version(s) loaded", options_.repository.string(), loaded);
  spdlog::info("work pool: {} thread(s); at most {} concurrent calls; miss logs in {} (fsync {}){}{}",
               request_pool_->thread_count(), options_.max_concurrent_calls, miss_log_dir.string(),
               options_.miss_log_fsync, tls_enabled(options_) ? "; TLS" : "",
               authenticator_->enabled() ? "; bearer tokens required" : "");
  housekeeping_thread_ = std::thread([this] { housekeeping(); });
  server_->GetHealthCheckService()->SetServingStatus(true);
  spdlog::info("health SERVING");
  return Status::Ok();
}

Status Daemon::start_renderer() {
  if (options_.renderer == "none") {
    env_->renderer_unavailable = "the server was started with --renderer none";
    return Status::Ok();
  }
  auto platform = render::parse_egl_platform(options_.renderer);
  if (!platform) return make_error(ErrorCode::kInvalidArgument, "--renderer: " + platform.error().message);
  auto thread = make_renderer_ ? RenderThread::start(make_renderer_, options_.render_queue_depth)
                               : RenderThread::start(*platform, options_.render_queue_depth);
  if (!thread) {
    if (*platform != render::EglPlatform::kAuto || make_renderer_) {
      return make_error(thread.error().code, "--renderer " + options_.renderer + ": " + thread.error().message);
    }
    env_->renderer_unavailable = "no EGL platform could be opened: " + thread.error().message;
    spdlog::warn("thumbnails disabled: {}", env_->renderer_unavailable);
    return Status::Ok();
  }
  render_thread_ = std::move(*thread);
  env_->renderer = render_thread_.get();
  spdlog::info("renderer: {} (queue depth {})", render_thread_->description(), options_.render_queue_depth);
  return Status::Ok();
}

std::shared_ptr<grpc::Channel> Daemon::in_process_channel(const grpc::ChannelArguments& arguments) const {
  return server_->InProcessChannel(arguments);
}

Status Daemon::start_metrics_endpoint() {
  if (options_.metrics_address.empty()) return Status::Ok();
  auto host_port = split_host_port(options_.metrics_address, "--metrics-listen");
  if (!host_port) return host_port.error();
  metrics_http_ = std::make_unique<httplib::Server>();
  // cpp-httplib sets SO_REUSEPORT by default, which would let two daemons share the metrics port
  // and each scrape read one of them at random; SO_REUSEADDR alone only reuses TIME_WAIT ports.
  metrics_http_->set_socket_options([](socket_t socket) {
    int yes = 1;
    ::setsockopt(socket, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  metrics_http_->Get("/metrics", [this](const httplib::Request&, httplib::Response& response) {
    const RegistryMemory memory = registry_.memory();
    metrics_.set_registry_memory(memory.budget_bytes, memory.resident_bytes, memory.evictions, memory.reloads);
    response.set_content(metrics_.prometheus_text(), "text/plain; version=0.0.4");
  });
  const auto& [host, port] = *host_port;
  int bound = port;
  if (port == 0) {
    bound = metrics_http_->bind_to_any_port(host);
  } else if (!metrics_http_->bind_to_port(host, port)) {
    bound = -1;
  }
  if (bound <= 0) {
    if (auto owner = busy_address_owner(options_.metrics_address)) {
      return make_error(ErrorCode::kFailedPrecondition,
                        "--metrics-listen: '" + options_.metrics_address + "' is already in use by " + *owner);
    }
    return make_error(ErrorCode::kInvalidArgument,
                      "--metrics-listen: cannot bind '" + options_.metrics_address + "'");
  }
  metrics_thread_ = std::thread([this] { metrics_http_->listen_after_bind(); });
  spdlog::info("metrics on http://{}:{}/metrics", host, bound);
  return Status::Ok();
}

void Daemon::housekeeping() {
  // Wakes at the miss-log fsync interval (so an "interval" log is durable within it even when no
  // further miss arrives) and polls the repository when its period has passed.
  const auto tick = options_.miss_log_fsync_interval;
  const auto poll_period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(options_.poll_interval_s));
  auto next_poll = std::chrono::steady_clock::now() + poll_period;
  std::unique_lock lock(housekeeping_mutex_);
  while (!housekeeping_wake_.wait_for(lock, tick, [this] { return housekeeping_stopped_; })) {
    lock.unlock();
    miss_logs_->sync_all();
    if (options_.poll_interval_s > 0 && std::chrono::steady_clock::now() >= next_poll) {
      if (registry_.load_new_versions() > 0) refresh_model_gauges(*env_);
      next_poll = std::chrono::steady_clock::now() + poll_period;
    }
    lock.lock();
  }
}

void Daemon::shutdown() {
  if (stopped_) return;
  stopped_ = true;
  if (server_) {
    server_->GetHealthCheckService()->SetServingStatus(false);
    spdlog::info("shutting down: health NOT_SERVING, finishing in-flight calls (grace {} ms)",
                 options_.shutdown_grace.count());
    // No new connection is handed to a server shutting down (gRPC would neither serve nor close it).
    listener_->stop();
    const auto deadline = std::chrono::system_clock::now() + options_.shutdown_grace;
    std::thread stopper([this, deadline] { server_->Shutdown(deadline); });
    // gRPC's shutdown also waits for every client connection to close, and an idle synchronous
    // C++ client never reads the GOAWAY, so it would always take the whole grace period. Once
    // our handlers have had nothing in flight for two consecutive polls, nothing is left to
    // finish: drop the remaining connections (new calls are already refused).
    int idle_polls = 0;
    while (std::chrono::system_clock::now() < deadline && idle_polls < 2) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      idle_polls = metrics_.calls_in_flight() == 0 ? idle_polls + 1 : 0;
    }
    if (idle_polls >= 2) grpc_server_cancel_all_calls(server_->c_server());
    stopper.join();
    server_->Wait();
  }
  {
    std::lock_guard lock(housekeeping_mutex_);
    housekeeping_stopped_ = true;
  }
  housekeeping_wake_.notify_all();
  if (housekeeping_thread_.joinable()) housekeeping_thread_.join();
  // The gRPC server has finished every call, so nothing queues work any more; joining the pools
  // also waits for a handler body still running after its call was answered (it may read
  // env_->renderer, found by TSan), and only then does the renderer go.
  if (request_pool_) request_pool_->stop();
  if (admin_pool_) admin_pool_->stop();
  if (env_) env_->renderer = nullptr;
  render_thread_.reset();
  if (miss_logs_) miss_logs_->sync_all();
  if (metrics_http_) {
    metrics_http_->stop();
    if (metrics_thread_.joinable()) metrics_thread_.join();
  }
  spdlog::info("stopped");
}

}  // namespace animspace::server
