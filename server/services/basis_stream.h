// PoseService.GetBasis: a model version's mean and basis, streamed once to a client that takes
// answers as coordinates (POINT_ENCODING_COORDINATES) and reconstructs the points itself
// (core/pmsc/coordinates.h). The values are cut into chunks of at most a quarter of
// --max-message-bytes (and 4 MiB), built one ahead of the wire (server/stream_reactor.h owns the
// order, the lifetime and cancellation); the version is resolved once, so a hot swap during the
// download never mixes two bases.
#pragma once

#include <grpcpp/grpcpp.h>

#include "server/service_environment.h"

namespace animspace::server {

// Parses the request, authenticates and admits the call, then streams; the reactor deletes
// itself when done.
grpc::ServerWriteReactor<grpc::ByteBuffer>* start_basis_stream(ServiceEnvironment& env,
                                                               grpc::CallbackServerContext* context,
                                                               const grpc::ByteBuffer* request);

}  // namespace animspace::server
