#include "server/server_builder.h"

#include <algorithm>
#include <string>

#include <grpc/grpc.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include "server/auth.h"

namespace animspace::server {

Status check_transport_options(const ServerOptions& options) {
  if (options.grpc_memory_bytes != 0 && options.grpc_memory_bytes < 2 * options.max_message_bytes) {
    return make_error(ErrorCode::kInvalidArgument,
                      "--grpc-memory-bytes: expected 0 (unbounded) or at least twice --max-message-bytes (" +
                          std::to_string(2 * options.max_message_bytes) + "), got " +
                          std::to_string(options.grpc_memory_bytes) +
                          "; a request of the largest size must fit while it arrives");
  }
  return Status::Ok();
}

std::unique_ptr<grpc::ServerBuilder> make_server_builder(
    const ServerOptions& options, const std::shared_ptr<grpc::ServerCredentials>& credentials,
    std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor>* acceptor) {
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  auto builder = std::make_unique<grpc::ServerBuilder>();
  // Connections come from server/listener.h's accept loop, not gRPC's (issue #54 item 5).
  *acceptor = builder->experimental().AddExternalConnectionAcceptor(
      grpc::ServerBuilder::experimental_type::ExternalConnectionType::FROM_FD, credentials);
  // gRPC sets SO_REUSEPORT by default: a second daemon would bind a busy address and take a random
  // share of its connections. One address, one daemon (issue #21).
  builder->AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // One connection, a share of the call slots (issue #54 item 6): a peer that opens more streams
  // has them refused by HTTP/2 (a gRPC client queues them until one ends).
  builder->AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, static_cast<int>(options.max_streams_per_connection));
  builder->SetMaxReceiveMessageSize(static_cast<int>(options.max_message_bytes));
  builder->SetMaxSendMessageSize(static_cast<int>(options.max_message_bytes));
  grpc::ResourceQuota quota("animspaced");
  quota.SetMaxThreads(std::max(2, options.worker_threads));
  // gRPC 1.51 buffers a whole message before its size check (grpc/grpc#43012); the quota is what
  // bounds that memory. Measured (docs/RELIABILITY.md): one 256 MiB request against a 1 MiB limit
  // peaks at +251 MiB unbounded and +10 MiB under a 16 MiB quota.
  if (options.grpc_memory_bytes > 0) quota.Resize(static_cast<size_t>(options.grpc_memory_bytes));
  builder->SetResourceQuota(quota);  // the builder takes its own reference
  // Sync-server pollers (the health service) wake at this period; it bounds shutdown's wait.
  builder->SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::CQ_TIMEOUT_MSEC, 100);
  return builder;
}

Status start_failure(const ServerOptions& options) {
  return make_error(ErrorCode::kInvalidArgument,
                    "cannot start the gRPC server on '" + options.listen_address + "'" +
                        (tls_enabled(options) ? ": do --tls-cert and --tls-key belong together?" : ""));
}

}  // namespace animspace::server
