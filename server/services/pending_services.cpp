#include "server/services/pending_services.h"

#include "server/call_scope.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

grpc::Status pending(Metrics& metrics, const char* rpc, const std::string& model, const char* why) {
  CallScope scope(metrics, rpc);
  scope.set_model(model);
  return scope.finish(unimplemented(std::string("animspace.v1.") + rpc, why));
}

constexpr const char* kLodPending = "LOD meshes over RPC (issue #7) have not landed; `animspace export-lod` "
                                    "writes a level offline";
constexpr const char* kRenderPending = "headless EGL thumbnails (issue #7) have not landed";

// A server-streaming call that ends at once with a status.
class FinishedWriter final : public grpc::ServerWriteReactor<v1::LodChunk> {
 public:
  explicit FinishedWriter(grpc::Status status) { Finish(std::move(status)); }
  void OnDone() override { delete this; }
};

}  // namespace

grpc::ServerWriteReactor<v1::LodChunk>* LodServiceImpl::GetLod(grpc::CallbackServerContext*,
                                                               const v1::GetLodRequest* request) {
  return new FinishedWriter(pending(env_.metrics, "LodService/GetLod", request->model().name(), kLodPending));
}

grpc::ServerUnaryReactor* RenderServiceImpl::RenderThumbnail(grpc::CallbackServerContext* context,
                                                             const v1::RenderThumbnailRequest* request,
                                                             v1::RenderThumbnailResponse*) {
  auto* reactor = context->DefaultReactor();
  reactor->Finish(pending(env_.metrics, "RenderService/RenderThumbnail", request->model().name(), kRenderPending));
  return reactor;
}

}  // namespace animspace::server
