// animspaced: serves trained character-animation models over gRPC.
#include <pthread.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "core/demo/demo_repository.h"
#include "server/daemon.h"
#include "server/transport_flags.h"
#include "server/version.h"

namespace {

// Main takes the stop signals with sigwait, blocked in every thread it starts. A thread that a
// library started before main (OpenBLAS's pthread build started a pool when it was loaded) never
// blocked them, the kernel may deliver a process signal to it, and with the default action that
// ended the daemon without its graceful shutdown. So a handler is installed as well: it runs
// only on such a thread (main and the threads it starts block the signals) and sends the signal
// on to main, where sigwait takes it. pthread_kill is async-signal-safe.
pthread_t main_thread;

void forward_stop_signal(int signal_number) { pthread_kill(main_thread, signal_number); }

// Generates the bundled demo repository in a fresh temporary directory: the embedded default
// that lets `animspaced` serve something with nothing else present.
std::filesystem::path make_demo_repository() {
  const auto dir = std::filesystem::temp_directory_path() / ("animspaced-demo-" + std::to_string(::getpid()));
  std::error_code ignored;
  std::filesystem::remove_all(dir, ignored);
  if (auto status = animspace::demo::write_bundled_demo(dir); !status.ok()) {
    spdlog::critical("cannot write the demo repository: {}", status.error().message);
    std::exit(EXIT_FAILURE);
  }
  spdlog::info("no --model-repository given: serving the bundled demo repository generated in {}", dir.string());
  return dir;
}

}  // namespace

int main(int argc, char** argv) {
  animspace::server::ServerOptions options;
  CLI::App app{"animspaced — serves trained character-animation models (PMSC soft cache, animation-space "
               "skinning, LOD, thumbnails) over gRPC"};
  app.set_version_flag("--version", animspace::server::kServerVersion);
  animspace::server::add_transport_flags(app, options);
  app.add_option("--model-repository", options.repository,
                 "Model repository <repo>/<model>/<version>/model.anim; default: generate and serve the "
                 "bundled demo repository");
  app.add_option("--max-batch-poses", options.max_batch_poses, "Largest batch in one evaluation request")
      ->check(CLI::Range(1u, 1000000u))
      ->capture_default_str();
  app.add_option("--max-batch-size", options.max_batch_size,
                 "Dynamic batching: the most waiting poses of one model reconstructed as one matrix product")
      ->check(CLI::Range(1u, 4096u))
      ->capture_default_str();
  int64_t batch_delay_us = options.batch_delay.count();
  app.add_option("--batch-delay-us", batch_delay_us,
                 "Dynamic batching: how long a batch may wait to fill to --max-batch-size (0: batch only the "
                 "poses already waiting, adding no latency)")
      ->check(CLI::Range(int64_t{0}, int64_t{1000000}))
      ->capture_default_str();
  app.add_option("--kernel", options.kernel,
                 "Dense products: blas (OpenBLAS, dispatched to this CPU at start) or portable (Eigen, baseline "
                 "x86-64)")
      ->check(CLI::IsMember({"blas", "portable"}))
      ->capture_default_str();
  app.add_option("--max-thumbnail-px", options.max_thumbnail_px, "Largest thumbnail edge in pixels")
      ->check(CLI::Range(16u, 4096u))
      ->capture_default_str();
  app.add_option("--renderer", options.renderer,
                 "Thumbnails: EGL platform auto (a GPU's EGL device, else Mesa surfaceless), surfaceless, device, "
                 "or none (RenderThumbnail answers UNAVAILABLE)")
      ->check(CLI::IsMember({"auto", "surfaceless", "device", "none"}))
      ->capture_default_str();
  app.add_option("--render-queue-depth", options.render_queue_depth,
                 "Thumbnails waiting for the render thread before RESOURCE_EXHAUSTED")
      ->check(CLI::Range(1u, 4096u))
      ->capture_default_str();
  app.add_option("--max-concurrent-calls", options.max_concurrent_calls,
                 "Calls served at once before RESOURCE_EXHAUSTED")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
  app.add_option("--metrics-listen", options.metrics_address,
                 "host:port for Prometheus text metrics at /metrics (empty: off)");
  app.add_option("--log-level", options.log_level, "trace, debug, info, warn, error, critical or off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}))
      ->capture_default_str();
  int64_t grace_ms = options.shutdown_grace.count();
  app.add_option("--shutdown-grace-ms", grace_ms, "Time in-flight calls get to finish after SIGTERM/SIGINT")
      ->check(CLI::Range(int64_t{0}, int64_t{600000}))
      ->capture_default_str();
  int64_t stall_ms = options.stream_stall_timeout.count();
  app.add_option("--stream-stall-ms", stall_ms,
                 "A streamed response the client has not taken for this long (its flow-control window shut) ends "
                 "the stream CANCELLED, freeing its call slot and the message held for it (0: never)")
      ->check(CLI::Range(int64_t{0}, int64_t{86400000}))
      ->capture_default_str();
  app.add_option("--work-threads", options.work_threads,
                 "Threads that run request work (evaluation, skinning); 0 = one per core")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  app.add_option("--poll-interval-s", options.poll_interval_s,
                 "Poll the repository for new model versions every this many seconds, so that a version built "
                 "into it is served without `animspace load` (0 = never)")
      ->check(CLI::Range(0.0, 86400.0))
      ->capture_default_str();
  app.add_option("--miss-log-dir", options.miss_log_dir,
                 "Where per-model miss logs (<model>.misses) are written; default: the repository");
  app.add_option("--miss-log-fsync", options.miss_log_fsync,
                 "Miss log durability: always (fsync each record), interval, never")
      ->check(CLI::IsMember({"always", "interval", "never"}))
      ->capture_default_str();
  int64_t fsync_ms = options.miss_log_fsync_interval.count();
  app.add_option("--miss-log-fsync-interval-ms", fsync_ms, "With --miss-log-fsync interval: longest time between fsyncs")
      ->check(CLI::Range(int64_t{1}, int64_t{3600000}))
      ->capture_default_str();
  app.add_option("--miss-log-max-bytes", options.miss_log_max_bytes,
                 "The most bytes one model's miss log may hold (0 = no bound); past it, blends and misses are "
                 "served but not logged, and animspace_misses_not_logged_total{reason=\"full\"} counts them")
      ->capture_default_str();
  app.add_option("--resident-section-bytes", options.resident_section_bytes,
                 "Model file sections larger than this (a PMSC model's training frames, large meshes) stay on disk, "
                 "checked at load and read again when a request needs them, instead of held in memory for every "
                 "loaded version")
      ->capture_default_str();
  app.add_option("--memory-budget", options.memory_budget_bytes,
                 "The heap the loaded model versions may hold together, bytes or with a unit (16GiB, 512MB; 0 = no "
                 "bound): past it, the least recently used versions are evicted, and the next request for one "
                 "loads it again, waiting within its deadline or getting UNAVAILABLE with a retry hint")
      ->transform(CLI::AsSizeValue(false))
      ->capture_default_str();
  app.add_option("--tls-cert", options.tls_cert, "TLS: server certificate chain (PEM); with --tls-key");
  app.add_option("--tls-key", options.tls_key, "TLS: server private key (PEM)");
  app.add_option("--tls-client-ca", options.tls_client_ca,
                 "TLS: require client certificates signed by this CA bundle (PEM)");
  app.add_option("--auth-token-file", options.auth_token_file,
                 "Bearer tokens accepted on every RPC but health, one per line ('#' comments)");
  app.add_option("--admin-token-file", options.admin_token_file,
                 "Bearer tokens required for LoadModel, UnloadModel, Retrain and GetStats reset");
  CLI11_PARSE(app, argc, argv);
  options.shutdown_grace = std::chrono::milliseconds(grace_ms);
  options.stream_stall_timeout = std::chrono::milliseconds(stall_ms);
  options.batch_delay = std::chrono::microseconds(batch_delay_us);
  options.miss_log_fsync_interval = std::chrono::milliseconds(fsync_ms);

  spdlog::set_level(spdlog::level::from_str(options.log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e%z %^%l%$ animspaced[%P] %v");

  // Block the stop signals in every thread we start (the gRPC threads inherit this mask) and
  // take them synchronously here, so shutdown runs on an ordinary thread and not in a signal
  // handler; forward_stop_signal sends on those that reach a library's own thread.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  main_thread = pthread_self();
  struct sigaction forward {};
  forward.sa_handler = forward_stop_signal;
  sigemptyset(&forward.sa_mask);
  sigaction(SIGTERM, &forward, nullptr);
  sigaction(SIGINT, &forward, nullptr);

  const bool demo = options.repository.empty();
  if (demo) options.repository = make_demo_repository();

  spdlog::info("animspaced {} starting (pid {})", animspace::server::kServerVersion, ::getpid());
  int exit_code = EXIT_SUCCESS;
  {
    animspace::server::Daemon daemon(options);
    if (auto status = daemon.start(); !status.ok()) {
      spdlog::critical("{}", status.error().message);
      exit_code = EXIT_FAILURE;
    } else {
      int signal_number = 0;
      sigwait(&stop_signals, &signal_number);
      spdlog::info("received {}", signal_number == SIGTERM ? "SIGTERM" : "SIGINT");
      daemon.shutdown();
    }
  }
  if (demo) {
    std::error_code ignored;
    std::filesystem::remove_all(options.repository, ignored);
  }
  return exit_code;
}
