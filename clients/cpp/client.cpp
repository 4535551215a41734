#include "clients/cpp/client.h"

#include <bit>

namespace animspace {
namespace {

std::shared_ptr<grpc::Channel> make_channel(const std::string& target, const ClientOptions& options) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  if (!options.tls) return grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args);
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = options.tls_root_certificates;
  ssl.pem_cert_chain = options.tls_client_certificate;
  ssl.pem_private_key = options.tls_client_key;
  if (!options.tls_server_name.empty()) args.SetSslTargetNameOverride(options.tls_server_name);
  return grpc::CreateCustomChannel(target, grpc::SslCredentials(ssl), args);
}

void check(const char* rpc, const grpc::Status& status) {
  if (!status.ok()) throw RpcError(rpc, status);
}

}  // namespace

const char* status_code_name(grpc::StatusCode code) {
  static constexpr const char* kNames[] = {
      "OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
      "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION", "ABORTED",
      "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  const int index = static_cast<int>(code);
  if (index < 0 || index >= static_cast<int>(std::size(kNames))) return "UNKNOWN";
  return kNames[index];
}

RpcError::RpcError(std::string rpc, const grpc::Status& status)
    : std::runtime_error(rpc + " failed: " + status_code_name(status.error_code()) + ": " +
                         status.error_message()),
      code_(status.error_code()),
      server_message_(status.error_message()) {}

Client::Client(const std::string& target, ClientOptions options)
    : Client(make_channel(target, options), options) {}

Client::Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options)
    : options_(options),
      channel_(std::move(channel)),
      models_(v1::ModelService::NewStub(channel_)),
      stats_(v1::StatsService::NewStub(channel_)),
      poses_(v1::PoseService::NewStub(channel_)),
      skinning_(v1::SkinningService::NewStub(channel_)),
      training_(v1::TrainingService::NewStub(channel_)),
      lod_(v1::LodService::NewStub(channel_)),
      render_(v1::RenderService::NewStub(channel_)),
      health_(grpc::health::v1::Health::NewStub(channel_)) {}

void Client::prepare(grpc::ClientContext* context) const { prepare(context, options_.deadline); }

void Client::prepare(grpc::ClientContext* context, std::chrono::milliseconds deadline) const {
  context->set_deadline(std::chrono::system_clock::now() + deadline);
  authorize(context);
}

void Client::authorize(grpc::ClientContext* context) const {
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
}

v1::PointArray make_point_array(const float* values, uint32_t points, uint32_t channels) {
  static_assert(std::endian::native == std::endian::little, "the wire format is little-endian float32");
  v1::PointArray out;
  out.set_point_count(points);
  out.set_channel_count(channels);
  out.set_data(values, size_t{points} * channels * sizeof(float));
  return out;
}

grpc::health::v1::HealthCheckResponse::ServingStatus Client::health(const std::string& service) {
  grpc::ClientContext context;
  prepare(&context);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  check("Health/Check", health_->Check(&context, request, &response));
  return response.status();
}

std::vector<v1::ModelSummary> Client::list_models() {
  grpc::ClientContext context;
  prepare(&context);
  v1::ListModelsResponse response;
  check("ListModels", models_->ListModels(&context, v1::ListModelsRequest(), &response));
  return {response.models().begin(), response.models().end()};
}

v1::ModelSummary Client::describe_model(const std::string& name, uint64_t version) {
  grpc::ClientContext context;
  prepare(&context);
  v1::DescribeModelRequest request;
  request.mutable_model()->set_name(name);
  request.mutable_model()->set_version(version);
  v1::DescribeModelResponse response;
  check("DescribeModel", models_->DescribeModel(&context, request, &response));
  return response.model();
}

v1::ModelSummary Client::load_model(const std::string& name, uint64_t version) {
  grpc::ClientContext context;
  prepare(&context);
  v1::LoadModelRequest request;
  request.mutable_model()->set_name(name);
  request.mutable_model()->set_version(version);
  v1::LoadModelResponse response;
  check("LoadModel", models_->LoadModel(&context, request, &response));
  return response.model();
}

void Client::unload_model(const std::string& name, uint64_t version) {
  grpc::ClientContext context;
  prepare(&context);
  v1::UnloadModelRequest request;
  request.mutable_model()->set_name(name);
  request.mutable_model()->set_version(version);
  v1::UnloadModelResponse response;
  check("UnloadModel", models_->UnloadModel(&context, request, &response));
}

v1::GetServerInfoResponse Client::server_info() {
  grpc::ClientContext context;
  prepare(&context);
  v1::GetServerInfoResponse response;
  check("GetServerInfo", models_->GetServerInfo(&context, v1::GetServerInfoRequest(), &response));
  return response;
}

v1::GetStatsResponse Client::stats(const std::string& model, bool reset) {
  grpc::ClientContext context;
  prepare(&context);
  v1::GetStatsRequest request;
  request.set_model(model);
  request.set_reset(reset);
  v1::GetStatsResponse response;
  check("GetStats", stats_->GetStats(&context, request, &response));
  return response;
}

KeyPoints Client::describe_key_points(const std::string& model, uint64_t version) {
  grpc::ClientContext context;
  prepare(&context);
  v1::DescribeKeyPointsRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(version);
  v1::DescribeKeyPointsResponse response;
  check("DescribeKeyPoints", poses_->DescribeKeyPoints(&context, request, &response));
  KeyPoints out;
  out.model_version = response.model_version();
  out.indices.assign(response.key_point_indices().begin(), response.key_point_indices().end());
  out.channel_count = response.channel_count();
  out.control_point_count = response.control_point_count();
  out.regions.assign(response.key_point_regions().begin(), response.key_point_regions().end());
  out.fail_through = response.fail_through();
  out.check_point_indices.assign(response.check_point_indices().begin(), response.check_point_indices().end());
  out.check_point_regions.assign(response.check_point_regions().begin(), response.check_point_regions().end());
  out.basis_checksum = response.basis_checksum();
  out.basis_sha256 = response.basis_sha256();
  for (const auto& [what, indices] :
       {std::pair{"key point", &out.indices}, std::pair{"check point", &out.check_point_indices}}) {
    for (uint32_t index : *indices) {
      if (index >= out.control_point_count) {
        throw std::runtime_error(std::string("malformed DescribeKeyPoints answer: ") + what + " index " +
                                 std::to_string(index) + " ≥ control_point_count " +
                                 std::to_string(out.control_point_count));
      }
    }
  }
  return out;
}

PoseResult Client::evaluate_key_points(const std::string& model, const KeyPointPose& pose,
                                       const EvaluateOptions& options) {
  return std::move(evaluate_key_points_batch(model, std::span(&pose, 1), options).front());
}

std::vector<PoseResult> Client::evaluate_key_points_batch(const std::string& model,
                                                          std::span<const KeyPointPose> poses,
                                                          const EvaluateOptions& options) {
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(options.version);
  request.set_omit_points(options.omit_points);
  request.set_include_region_errors(options.include_region_errors);
  request.set_local_fail_through(options.local_fail_through);
  request.set_skip_miss_log(options.skip_miss_log);
  request.set_points_encoding(options.points_encoding);
  for (const KeyPointPose& pose : poses) *request.add_poses() = encode_key_point_pose(pose);
  grpc::ClientContext context;
  prepare(&context);
  v1::EvaluateKeyPointsResponse response;
  check("EvaluateKeyPoints", poses_->EvaluateKeyPoints(&context, request, &response));
  if (static_cast<size_t>(response.results_size()) != poses.size()) {
    throw std::runtime_error("EvaluateKeyPoints answered " + std::to_string(response.results_size()) +
                             " results for " + std::to_string(poses.size()) + " poses");
  }
  std::vector<PoseResult> out;
  out.reserve(poses.size());
  for (const auto& result : response.results()) out.push_back(decode_pose_result(result));
  return out;
}

std::unique_ptr<KeyPointStream> Client::open_stream(const std::string& model, const StreamOptions& options) {
  auto context = std::make_unique<grpc::ClientContext>();
  authorize(context.get());  // the stream's own deadline, if any, replaces the per-call one
  return std::unique_ptr<KeyPointStream>(new KeyPointStream(*poses_, std::move(context), model, options));
}

CompletedMiss Client::complete_miss(const std::string& model, uint64_t version, const KeyPointPose& pose,
                                    std::span<const float> full_values, std::span<const uint32_t> full_points,
                                    v1::PointEncoding points_encoding, bool skip_miss_log) {
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(version);
  v1::KeyPointPose encoded = encode_key_point_pose(pose);
  *request.mutable_key_values() = std::move(*encoded.mutable_key_values());
  // The check values the evaluation sent, so that the server's verdict repeats.
  if (encoded.has_check_values()) *request.mutable_check_values() = std::move(*encoded.mutable_check_values());
  const uint32_t channels = pose.channel_count;
  if (full_values.size() % channels != 0) {
    throw std::invalid_argument("complete_miss: full_values holds " + std::to_string(full_values.size()) +
                                " floats, not a whole number of " + std::to_string(channels) + "-channel points");
  }
  if (!full_points.empty() && full_values.size() != full_points.size() * channels) {
    throw std::invalid_argument("complete_miss: full_values holds " + std::to_string(full_values.size()) +
                                " floats, expected " + std::to_string(channels) + " for each of the " +
                                std::to_string(full_points.size()) + " full_points");
  }
  *request.mutable_full_values() =
      make_point_array(full_values.data(), static_cast<uint32_t>(full_values.size() / channels), channels);
  request.mutable_full_points()->Add(full_points.begin(), full_points.end());
  request.set_points_encoding(points_encoding);
  request.set_skip_miss_log(skip_miss_log);
  grpc::ClientContext context;
  prepare(&context);
  v1::CompleteMissResponse response;
  check("CompleteMiss", poses_->CompleteMiss(&context, request, &response));
  return {decode_pose_result(response.result()), response.logged(), response.not_logged_reason()};
}

SkinningResult Client::evaluate_skeleton_pose(const std::string& model, std::span<const SkeletonPose> poses,
                                              const SkinningOptions& options) {
  v1::EvaluateSkeletonPoseRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(options.version);
  request.set_include_normals(options.include_normals);
  request.set_lod_level(options.lod_level);
  for (const SkeletonPose& pose : poses) *request.add_poses() = encode_skeleton_pose(pose);
  grpc::ClientContext context;
  prepare(&context);
  v1::EvaluateSkeletonPoseResponse response;
  check("EvaluateSkeletonPose", skinning_->EvaluateSkeletonPose(&context, request, &response));
  if (static_cast<size_t>(response.poses_size()) != poses.size()) {
    throw std::runtime_error("EvaluateSkeletonPose answered " + std::to_string(response.poses_size()) +
                             " poses for " + std::to_string(poses.size()));
  }
  SkinningResult out;
  out.model_version = response.model_version();
  for (const auto& pose : response.poses()) {
    out.poses.push_back({decode_points(pose.points()),
                         pose.has_normals() ? decode_points(pose.normals()) : Points{}});
  }
  return out;
}

v1::RetrainResponse Client::retrain(const v1::RetrainRequest& request, std::chrono::milliseconds deadline) {
  grpc::ClientContext context;
  prepare(&context, deadline);
  v1::RetrainResponse response;
  check("Retrain", training_->Retrain(&context, request, &response));
  return response;
}

Thumbnail Client::render_thumbnail(const v1::RenderThumbnailRequest& request, std::chrono::milliseconds deadline) {
  grpc::ClientContext context;
  prepare(&context, deadline.count() > 0 ? deadline : options_.deadline);
  v1::RenderThumbnailResponse response;
  check("RenderThumbnail", render_->RenderThumbnail(&context, request, &response));
  Thumbnail out;
  out.png = std::move(*response.mutable_png());
  out.width_px = response.width_px();
  out.height_px = response.height_px();
  out.model_version = response.model_version();
  out.lod_level = response.lod_level();
  if (response.has_pose()) out.pose = decode_pose_result(response.pose());
  out.render_ms = response.render_ms();
  out.heat_max_error = response.heat_max_error();
  out.heat_scale_max = response.heat_scale_max();
  out.heat_legend_drawn = response.heat_legend_drawn();
  return out;
}

}  // namespace animspace
