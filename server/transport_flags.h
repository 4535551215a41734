// The command-line flags of the transport settings (server/server_builder.h), declared once for
// every binary that builds an animspace gRPC server: animspaced and the transport floor accept
// them under the same names, defaults and bounds.
#pragma once

#include <cstdint>

#include <CLI/CLI.hpp>

#include "server/options.h"

namespace animspace::server {

// --listen, --port-file, --worker-threads, --max-message-bytes, --grpc-memory-bytes,
// --max-streams-per-connection into `options`.
inline void add_transport_flags(CLI::App& app, ServerOptions& options) {
  app.add_option("--listen", options.listen_address, "gRPC address, host:port (port 0 picks a free one)")
      ->capture_default_str();
  app.add_option("--port-file", options.port_file, "Write the bound gRPC port to this file once listening");
  app.add_option("--worker-threads", options.worker_threads, "Upper bound on gRPC worker threads")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  app.add_option("--max-message-bytes", options.max_message_bytes, "Largest request or response message")
      ->check(CLI::Range(int64_t{1024}, int64_t{2000000000}))
      ->capture_default_str();
  app.add_option("--grpc-memory-bytes", options.grpc_memory_bytes,
                 "Memory gRPC may hold for requests being received, all connections together; past it calls "
                 "are reset RESOURCE_EXHAUSTED (0: unbounded; else at least twice --max-message-bytes)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 50))
      ->capture_default_str();
  app.add_option("--max-streams-per-connection", options.max_streams_per_connection,
                 "Calls one client connection may have open at once (HTTP/2 concurrent streams); more wait in the "
                 "client's gRPC until one ends, so one connection cannot hold every --max-concurrent-calls slot")
      ->check(CLI::Range(1u, 100000u))
      ->capture_default_str();
}

}  // namespace animspace::server
