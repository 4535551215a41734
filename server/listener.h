// The daemon's own accept loop in front of gRPC (issue #54 item 5).
//
// gRPC 1.51's listener stops for good after one accept4(2) fails with EMFILE: its read callback
// returns without asking to be called again (src/core/lib/iomgr/tcp_server_posix.cc, on_read), so
// at the descriptor limit every later client waited for its deadline while the process lived
// (grpc/grpc#20418; fixed upstream in 1.57 by grpc/grpc#33656, not in Debian 12's 1.51). Here the
// daemon binds and accepts itself and hands each connection to gRPC through its external
// connection acceptor, which applies the same credentials (TLS or plaintext) and transport. At the
// limit it keeps one descriptor in reserve: it closes the reserve, accepts the waiting connection
// and closes it at once — that client sees the connection refused (UNAVAILABLE, which clients
// retry) instead of a hang — takes the reserve back, and goes on accepting; once descriptors are
// free again, connections are served as before.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/server_builder.h>

#include "core/common/result.h"

namespace animspace::server {

class Listener {
 public:
  // Binds and listens on every address "host:port" or "[v6]:port" resolves to (port 0: one free
  // port, the same for all), SO_REUSEADDR without SO_REUSEPORT (issue #21). Errors:
  // kFailedPrecondition naming the process that holds a busy port, kInvalidArgument otherwise.
  static Result<std::unique_ptr<Listener>> bind(const std::string& listen_address);
  ~Listener();
  Listener(const Listener&) = delete;
  Listener& operator=(const Listener&) = delete;

  int port() const { return port_; }

  // Starts accepting on a thread of its own, handing every connection to `acceptor` (from
  // ServerBuilder::experimental().AddExternalConnectionAcceptor, once the server is started).
  void start(std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor);
  // Stops accepting and closes the listening sockets: before the server shuts down, which would
  // drop (and leak) a connection handed to it afterwards. Idempotent.
  void stop();

  // Connections accepted and closed at once because the process had no descriptor to serve them.
  uint64_t refused_at_descriptor_limit() const { return refused_.load(); }

 private:
  Listener(std::vector<int> sockets, int port, std::string address);
  void run();
  // accept4 on one listening socket until it has nothing waiting. False: back off (the
  // descriptor limit could not be worked around this time).
  bool accept_all(int socket);
  void refuse_one(int socket, int error_number);

  std::vector<int> sockets_;
  const int port_;
  const std::string address_;
  int wake_[2] = {-1, -1};  // a pipe: stop() writes, the loop's poll wakes
  int reserve_ = -1;        // /dev/null, held to be given up at the descriptor limit
  std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor_;
  std::thread thread_;
  std::atomic<uint64_t> refused_{0};
  std::atomic<bool> stopped_{false};
};

// Raises this process's soft descriptor limit to its hard limit (often 1024 → 524288 on Linux),
// so that the limit above is met later; returns the limit now in force.
uint64_t raise_descriptor_limit();

}  // namespace animspace::server
