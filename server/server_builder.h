// The gRPC server every animspace binary builds: animspaced and the transport floor
// (server/transport_floor/) share these settings, so the floor measures exactly the transport the
// daemon's clients get — the same message limits, memory quota, thread bound, port policy and
// health/reflection services — and differs only in the work behind each call.
#pragma once

#include <memory>

#include <grpcpp/grpcpp.h>

#include "core/common/result.h"
#include "server/options.h"

namespace animspace::server {

// Checks the transport flags against each other. Errors: kInvalidArgument naming the flag.
Status check_transport_options(const ServerOptions& options);

// A builder with the health and reflection services enabled and every transport setting of
// `options` applied, listening through the daemon's own accept loop (server/listener.h):
// `*acceptor` is what Listener::start takes once the server is built. The caller registers its
// services and builds. Enabling health and reflection is process-wide in gRPC; it is repeated
// harmlessly.
std::unique_ptr<grpc::ServerBuilder> make_server_builder(
    const ServerOptions& options, const std::shared_ptr<grpc::ServerCredentials>& credentials,
    std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor>* acceptor);

// Why BuildAndStart failed once the address was bound: the credentials (kInvalidArgument).
Status start_failure(const ServerOptions& options);

}  // namespace animspace::server
