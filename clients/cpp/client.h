// animspace::Client — a thin C++ client for animspaced.
//
// Depends only on the generated animspace.v1 and grpc.health.v1 stubs. Every call has a
// deadline; a failed call throws RpcError carrying the gRPC code and the server's message
// (which names the offending field).
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "animspace/v1/lod.grpc.pb.h"
#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "animspace/v1/stats.grpc.pb.h"
#include "animspace/v1/training.grpc.pb.h"
#include "animspace/v1/skinning.grpc.pb.h"
#include "clients/cpp/key_point_stream.h"
#include "clients/cpp/results.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace animspace {

class RpcError : public std::runtime_error {
 public:
  RpcError(std::string rpc, const grpc::Status& status);
  grpc::StatusCode code() const { return code_; }
  // The server's message alone (what() adds the RPC and the code name).
  const std::string& server_message() const { return server_message_; }

 private:
  grpc::StatusCode code_;
  std::string server_message_;
};

// One level of detail, reassembled from LodService.GetLod's chunks (clients/cpp/lod_mesh.cpp).
// Arrays are flat and host-endian, ready for Eigen::Map (e.g. a V×3 row-major float map over
// `positions`).
struct LodMesh {
  v1::LodHeader header;
  std::vector<float> positions;           // FORM_POSED: vertex_count × 3
  std::vector<uint32_t> influence_offsets;  // FORM_ANIMATION_SPACE: vertex_count + 1 (CSR)
  std::vector<uint32_t> bone_indices;       // one per influence
  std::vector<float> animation_positions;   // 4 per influence (p_j, Σ_j p_j.w = 1)
  std::vector<float> geomorph_delta;        // 4 per influence, when requested
  std::vector<uint32_t> indices;            // face_count × 3
  // With include_texture_coordinates (header.texture_coordinates()): face_count × 3 × 2, (u, v)
  // of each face's corners in `indices` order, the model's texture atlas.
  std::vector<float> corner_uvs;
  v1::Skeleton skeleton;                    // FORM_ANIMATION_SPACE
  // What the stream took: chunks read and their serialized bytes (for transfer reports).
  uint64_t chunk_count = 0;
  uint64_t bytes_received = 0;
};

// RenderService.RenderThumbnail's answer (the reply's field names).
struct Thumbnail {
  std::string png;  // 8-bit RGBA PNG
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint64_t model_version = 0;
  uint32_t lod_level = 0;
  std::optional<PoseResult> pose;  // the soft cache's verdict when drawn from key points (no points)
  double render_ms = 0;
  // With a heat map (full_values): the largest |full − estimate| and the error drawn red, model
  // units; whether the asked-for legend fitted on the image.
  double heat_max_error = 0;
  double heat_scale_max = 0;
  bool heat_legend_drawn = false;
};

// A model version's subspace as PoseService.GetBasis sends it, reassembled and checked
// (clients/cpp/basis.cpp): the N·D mean followed by the N·D × M basis column by column.
struct BasisData {
  uint64_t model_version = 0;
  uint64_t basis_checksum = 0;  // as the server named it (coordinates.h verifies it)
  std::string basis_sha256;     // likewise, 32 raw bytes (empty from servers before issue #54)
  uint32_t point_count = 0;     // N
  uint32_t channel_count = 0;   // D
  uint32_t basis_size = 0;      // M
  bool aligned = false;
  // DENSE: N·D·(M + 1) values, the mean then the basis; SKINNED (an articulated model's, issue #51
  // item 4): N·3·(r + 1) + 5·N·K, laid out as poses.proto's BasisChunk says.
  std::vector<float> values;
  v1::BasisLayout layout = v1::BASIS_LAYOUT_DENSE;
  uint32_t subspace_bone_count = 0;   // SKINNED: B
  uint32_t influences_per_point = 0;  // SKINNED: K
  uint64_t chunk_count = 0;
  uint64_t bytes_received = 0;
  // How the values came (issue #53): FLOAT32, exact; or FLOAT16, widened here, each within
  // values_max_error of the float32 basis that basis_checksum and basis_sha256 name.
  v1::PointEncoding values_encoding = v1::POINT_ENCODING_FLOAT32;
  float values_max_error = 0;
};

struct ClientOptions {
  // Deadline applied to every call.
  std::chrono::milliseconds deadline{10000};
  // Largest message received, bytes (poses and LOD chunks can be large).
  int max_receive_message_bytes = 64 << 20;
  // Bearer token sent as "authorization: Bearer <token>" on every call (empty: none).
  std::string token;
  // TLS: PEM of the CA that signed the server's certificate; empty with `tls` false = plaintext.
  bool tls = false;
  std::string tls_root_certificates;  // empty: the system's roots
  // TLS client certificate and key (PEM), for servers that require them.
  std::string tls_client_certificate;
  std::string tls_client_key;
  // Name the server certificate must carry, when it differs from the target's host.
  std::string tls_server_name;
};

class Client {
 public:
  // `target` is a gRPC target: "host:port", "dns:///name:port", "ipv4:a:p,b:p", …
  explicit Client(const std::string& target, ClientOptions options = {});
  // Uses an existing channel (TLS, interceptors, load balancing configured by the caller).
  Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options = {});

  // grpc.health.v1 status of `service` ("" = the whole server).
  grpc::health::v1::HealthCheckResponse::ServingStatus health(const std::string& service = "");
  std::vector<v1::ModelSummary> list_models();
  v1::ModelSummary describe_model(const std::string& name, uint64_t version = 0);
  v1::ModelSummary load_model(const std::string& name, uint64_t version = 0);
  void unload_model(const std::string& name, uint64_t version = 0);
  v1::GetServerInfoResponse server_info();
  v1::GetStatsResponse stats(const std::string& model = "", bool reset = false);
  // The key points a PMSC model needs, in the order evaluate_key_points expects them.
  KeyPoints describe_key_points(const std::string& model, uint64_t version = 0);
  // The soft cache (Meyer & Anderson 2006 §5): one pose, or a batch answered in order.
  PoseResult evaluate_key_points(const std::string& model, const KeyPointPose& pose, const EvaluateOptions& options = {});
  std::vector<PoseResult> evaluate_key_points_batch(const std::string& model, std::span<const KeyPointPose> poses,
                                                    const EvaluateOptions& options = {});
  // A session for playing a sequence (see key_point_stream.h).
  std::unique_ptr<KeyPointStream> open_stream(const std::string& model, const StreamOptions& options = {});
  // Client fail-through: the full values of a pose that blended or missed, from the caller's own
  // posing engine; `version` is the result's model_version. All N×D values, or — local
  // fail-through — the values of `full_points` only (|full_points|×D, in that order; at least the
  // PoseResult::full_points of this pose): the answer is then blended point by point, its points in
  // `points_encoding` (as EvaluateOptions::points_encoding).
  // `skip_miss_log`: test traffic (EvaluateOptions::skip_miss_log), answered but not logged.
  CompletedMiss complete_miss(const std::string& model, uint64_t version, const KeyPointPose& pose,
                              std::span<const float> full_values, std::span<const uint32_t> full_points = {},
                              v1::PointEncoding points_encoding = v1::POINT_ENCODING_UNSPECIFIED,
                              bool skip_miss_log = false);
  // Skinning through an animation-space model (Merry 2007 §3.1): one result per pose, in order.
  SkinningResult evaluate_skeleton_pose(const std::string& model, std::span<const SkeletonPose> poses,
                                        const SkinningOptions& options = {});
  // Retraining can take minutes: `deadline` overrides the client's default for this call.
  v1::RetrainResponse retrain(const v1::RetrainRequest& request, std::chrono::milliseconds deadline);

  // Streams one level and reassembles it, checking that the blocks arrive in order and add up to
  // the header's counts (std::runtime_error otherwise). `deadline` 0 = the client's default.
  LodMesh get_lod(const v1::GetLodRequest& request, std::chrono::milliseconds deadline = {});
  // The subspace answers sent as coordinates are reconstructed with (once per model version;
  // clients/cpp/coordinates.h caches it). Throws std::runtime_error for chunks out of order or
  // inconsistent with each other. `deadline` 0 = the client's default.
  // `values_encoding` FLOAT16 asks for half the bytes (GetBasisRequest.values_encoding): the
  // values are checked against the SHA-256 of what was sent, and a basis made of them reconstructs
  // within the bound poses.proto states (about 2^-11·(|mean_i| + Σ_j |A_ij p_j|) more than float32).
  // `layout` (GetBasisRequest.layout): COMPACT gets an articulated model's basis SKINNED, a
  // fraction of the values (a tenth with tens of bones); BasisData::layout says which came (a server before it sends DENSE).
  BasisData get_basis(const std::string& model, uint64_t version = 0, std::chrono::milliseconds deadline = {},
                      v1::PointEncoding values_encoding = v1::POINT_ENCODING_FLOAT32,
                      v1::BasisLayout layout = v1::BASIS_LAYOUT_DENSE);
  // A render waits behind others on the daemon's render thread: `deadline` 0 = the client's default.
  Thumbnail render_thumbnail(const v1::RenderThumbnailRequest& request, std::chrono::milliseconds deadline = {});

  const std::shared_ptr<grpc::Channel>& channel() const { return channel_; }
  // Adds the bearer token (if any) to a context, for calls made on channel() directly, such as
  // a stream that must outlive the per-call deadline.
  void authorize(grpc::ClientContext* context) const;

 private:
  void prepare(grpc::ClientContext* context) const;
  void prepare(grpc::ClientContext* context, std::chrono::milliseconds deadline) const;

  ClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::ModelService::Stub> models_;
  std::unique_ptr<v1::StatsService::Stub> stats_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
  std::unique_ptr<v1::SkinningService::Stub> skinning_;
  std::unique_ptr<v1::TrainingService::Stub> training_;
  std::unique_ptr<v1::LodService::Stub> lod_;
  std::unique_ptr<v1::RenderService::Stub> render_;
  std::unique_ptr<grpc::health::v1::Health::Stub> health_;
};

// N points × D channels as the API's packed little-endian float32 PointArray.
v1::PointArray make_point_array(const float* values, uint32_t points, uint32_t channels);

// Name of a gRPC status code ("NOT_FOUND").
const char* status_code_name(grpc::StatusCode code);

}  // namespace animspace
