// LodService: one level of detail of an animation-space model for a render-farm node, chosen by
// pixel tolerance and view (eq. 7.2), by vertex budget or by index (server/lod_selection.h),
// streamed in chunks (Merry 2007 §7.3).
//
// The stream is written one chunk at a time: each chunk is built on the request pool while the
// one before it is on the wire, and the next is started only when gRPC reports a write done, so a
// slow client holds back the server (flow control) and at most two chunks exist beyond the level
// itself. The level is already in memory (the registry's LoadedModel); the posed form evaluates it
// once at the start, as SkinningService does, and include_geomorph builds lod::geomorph's aligned
// set once (§7.3); lod::LevelBlocks (core/lod/level_blocks.h) lays these out and cuts the blocks.
#pragma once

#include "animspace/v1/lod.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
class LodServiceImpl final : public v1::LodService::WithRawCallbackMethod_GetLod<v1::LodService::Service> {
 public:
  explicit LodServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerWriteReactor<grpc::ByteBuffer>* GetLod(grpc::CallbackServerContext* context,
                                                     const grpc::ByteBuffer* request) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
