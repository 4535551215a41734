// Daemon configuration, filled from command-line flags (server/main.cpp).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>

namespace animspace::server {

struct ServerOptions {
  // host:port for gRPC; port 0 picks a free port (reported in the "listening" log line).
  std::string listen_address = "127.0.0.1:50051";
  // Model repository, <repository>/<model>/<version>/model.anim.
  std::filesystem::path repository;
  // gRPC worker threads (sync server pool upper bound).
  int worker_threads = 8;
  // Largest request and response message, bytes.
  int64_t max_message_bytes = 64LL << 20;
  // Memory gRPC's transport may hold across all connections (a grpc::ResourceQuota), mostly
  // requests still arriving: gRPC 1.51 receives a message whole before it compares it with
  // max_message_bytes, so without this bound one oversized request costs its full size. Past it,
  // the transport resets calls with RESOURCE_EXHAUSTED. 0 = unbounded; otherwise at least twice
  // max_message_bytes, so that a request of the largest size fits while it arrives.
  int64_t grpc_memory_bytes = 256LL << 20;
  // Calls one HTTP/2 connection may have open at once (its SETTINGS_MAX_CONCURRENT_STREAMS), so
  // that one connection cannot take every max_concurrent_calls slot (issue #54 item 6).
  uint32_t max_streams_per_connection = 64;
  // A streamed response the client has not taken for this long — its flow-control window stays
  // shut — ends its stream CANCELLED, which frees the call slot and the message held for it
  // (issue #54 item 6). 0 = never.
  std::chrono::milliseconds stream_stall_timeout{30000};
  // Largest batch in one evaluation request, poses.
  uint32_t max_batch_poses = 1024;
  // Dynamic batching (server/pose_batcher.h): the most poses reconstructed as one product, and
  // how long the thread that takes a batch may wait for it to fill (0: only poses already
  // waiting join; no pose is delayed).
  uint32_t max_batch_size = 64;
  std::chrono::microseconds batch_delay{0};
  // The kernel of the dense products (core/common/kernels.h): "blas" (OpenBLAS, dispatched to
  // this CPU at load time) or "portable" (Eigen as compiled, baseline x86-64).
  std::string kernel = "blas";
  // Largest thumbnail edge, pixels.
  uint32_t max_thumbnail_px = 4096;
  // EGL platform of the render thread: "auto", "surfaceless", "device" or "none". With "auto" a
  // machine where EGL cannot be opened serves everything but thumbnails; an explicit platform
  // that cannot be opened stops start-up.
  std::string renderer = "auto";
  // Thumbnails queued for the render thread before RESOURCE_EXHAUSTED.
  uint32_t render_queue_depth = 16;
  // Calls served at once before RESOURCE_EXHAUSTED.
  uint32_t max_concurrent_calls = 256;
  // host:port for the Prometheus text endpoint (GET /metrics); empty disables it.
  std::string metrics_address;
  // spdlog level name: trace, debug, info, warn, error, critical, off.
  std::string log_level = "info";
  // How long in-flight calls may run after SIGTERM/SIGINT before they are cancelled.
  std::chrono::milliseconds shutdown_grace{5000};
  // Threads of the pool that runs request work (evaluation, retraining, loading); 0 = one per
  // core. gRPC's own threads only receive and send.
  int work_threads = 0;
  // Poll the repository for new model versions every this many seconds (0 = never).
  // Every 30 s by default, so that a version built into the repository (train-pmsc, build-lod,
  // retrain-offline) is served without a manual LoadModel (issue #55 item 8); 0 = never.
  double poll_interval_s = 30;
  // Where per-model miss logs live (<dir>/<model>.misses); empty = the repository itself.
  std::filesystem::path miss_log_dir;
  // Miss log durability: "always" (fsync every record), "interval" (fsync at most every
  // miss_log_fsync_interval), "never" (leave it to the OS).
  std::string miss_log_fsync = "interval";
  std::chrono::milliseconds miss_log_fsync_interval{1000};
  // The most bytes one model's miss log may hold (0 = no bound): past it, blends and misses are
  // served but not logged, counted in animspace_misses_not_logged_total{reason="full"}.
  uint64_t miss_log_max_bytes = uint64_t{1} << 30;
  // Model file sections larger than this are read from the file when asked instead of held in
  // memory per loaded version (model_registry.h).
  uint64_t resident_section_bytes = uint64_t{1} << 20;
  // The heap the loaded model versions may hold together (0 = no bound): past it, the least
  // recently used versions are evicted and loaded again by the next request for them
  // (model_registry.h, issue #53).
  uint64_t memory_budget_bytes = 0;
  // TLS: server certificate chain and private key (PEM). Both empty: plaintext.
  std::filesystem::path tls_cert;
  std::filesystem::path tls_key;
  // TLS: CA bundle (PEM) that client certificates must chain to; set = client certs required.
  std::filesystem::path tls_client_ca;
  // Bearer tokens (one per line, '#' comments) accepted on every RPC except health; empty = no
  // authentication.
  std::filesystem::path auth_token_file;
  // Bearer tokens required for admin RPCs (LoadModel, UnloadModel, Retrain, GetStats reset);
  // empty = admin RPCs need only what every RPC needs.
  std::filesystem::path admin_token_file;
  // File to write the bound gRPC port to once listening (for tests and supervisors); optional.
  std::filesystem::path port_file;
};

}  // namespace animspace::server
