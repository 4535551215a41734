// animspaced's lifecycle: bind, report NOT_SERVING, load the repository, report SERVING, serve,
// and on shutdown report NOT_SERVING, stop accepting, let in-flight calls finish within the
// grace period, exit.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "core/common/result.h"
#include "server/admission.h"
#include "server/auth.h"
#include "server/listener.h"
#include "server/metrics.h"
#include "server/miss_logs.h"
#include "server/model_registry.h"
#include "server/options.h"
#include "server/render_thread.h"
#include "server/service_environment.h"
#include "server/work_pool.h"

namespace grpc {
class Channel;
class ChannelArguments;
class Server;
}  // namespace grpc
namespace httplib {
class Server;
}

namespace animspace::server {

class ModelServiceImpl;
class StatsServiceImpl;
class PoseServiceImpl;
class SkinningServiceImpl;
class LodServiceImpl;
class RenderServiceImpl;
class TrainingServiceImpl;

class Daemon {
 public:
  // `make_renderer`, when set, replaces the EGL renderer --renderer names (in-process tests draw
  // with a fake); "--renderer none" still means no renderer.
  explicit Daemon(ServerOptions options, MakeRenderer make_renderer = {});
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Reads the security files, binds the gRPC (and metrics) addresses, then loads every model in
  // the repository and turns health to SERVING. Errors: kInvalidArgument when an address cannot
  // be bound or a flag is inconsistent, kNotFound when the repository or a security file does
  // not exist.
  Status start();

  // The bound gRPC port (after start()).
  int port() const { return port_; }

  // A channel to this server inside the process, without the network (after start()).
  std::shared_ptr<grpc::Channel> in_process_channel(const grpc::ChannelArguments& arguments) const;

  // What the services share (after start()): in-process tests reach the pools and metrics.
  ServiceEnvironment& environment() const { return *env_; }

  // Graceful stop: NOT_SERVING, stop accepting, in-flight calls get `options.shutdown_grace`
  // to finish, then the rest are cancelled. Idempotent.
  void shutdown();

 private:
  Status start_metrics_endpoint();
  // Opens the EGL platform --renderer names on the render thread. With "auto", a failure leaves
  // the server without thumbnails (logged); an explicit platform that fails stops start-up.
  Status start_renderer();
  // Until shutdown: flushes the miss logs every fsync interval and loads new model versions
  // every --poll-interval-s.
  void housekeeping();

  ServerOptions options_;
  MakeRenderer make_renderer_;
  ModelRegistry registry_;
  Metrics metrics_;
  Admission admission_;
  std::unique_ptr<Authenticator> authenticator_;
  std::unique_ptr<MissLogs> miss_logs_;
  // Before the pools: destroyed after them, once no task can hold a batch open.
  std::unique_ptr<PoseBatcher> batcher_;
  std::unique_ptr<WorkPool> request_pool_;
  std::unique_ptr<WorkPool> admin_pool_;
  std::unique_ptr<RenderThread> render_thread_;
  std::unique_ptr<ServiceEnvironment> env_;
  std::unique_ptr<ModelServiceImpl> model_service_;
  std::unique_ptr<StatsServiceImpl> stats_service_;
  std::unique_ptr<PoseServiceImpl> pose_service_;
  std::unique_ptr<SkinningServiceImpl> skinning_service_;
  std::unique_ptr<LodServiceImpl> lod_service_;
  std::unique_ptr<RenderServiceImpl> render_service_;
  std::unique_ptr<TrainingServiceImpl> training_service_;
  std::unique_ptr<Listener> listener_;  // accepts for server_ (server/listener.h)
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<httplib::Server> metrics_http_;
  std::thread metrics_thread_;
  std::thread housekeeping_thread_;
  std::mutex housekeeping_mutex_;
  std::condition_variable housekeeping_wake_;
  bool housekeeping_stopped_ = false;
  int port_ = 0;
  bool stopped_ = false;
};

}  // namespace animspace::server
