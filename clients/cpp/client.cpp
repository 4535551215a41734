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

v1::DescribeKeyPointsResponse Client::describe_key_points(const std::string& model, uint64_t version) {
  grpc::ClientContext context;
  prepare(&context);
  v1::DescribeKeyPointsRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(version);
  v1::DescribeKeyPointsResponse response;
  check("DescribeKeyPoints", poses_->DescribeKeyPoints(&context, request, &response));
  return response;
}

v1::EvaluateKeyPointsResponse Client::evaluate_key_points(const v1::EvaluateKeyPointsRequest& request) {
  grpc::ClientContext context;
  prepare(&context);
  v1::EvaluateKeyPointsResponse response;
  check("EvaluateKeyPoints", poses_->EvaluateKeyPoints(&context, request, &response));
  return response;
}

v1::CompleteMissResponse Client::complete_miss(const v1::CompleteMissRequest& request) {
  grpc::ClientContext context;
  prepare(&context);
  v1::CompleteMissResponse response;
  check("CompleteMiss", poses_->CompleteMiss(&context, request, &response));
  return response;
}

v1::RetrainResponse Client::retrain(const v1::RetrainRequest& request, std::chrono::milliseconds deadline) {
  grpc::ClientContext context;
  prepare(&context, deadline);
  v1::RetrainResponse response;
  check("Retrain", training_->Retrain(&context, request, &response));
  return response;
}

v1::RenderThumbnailResponse Client::render_thumbnail(const v1::RenderThumbnailRequest& request) {
  grpc::ClientContext context;
  prepare(&context);
  v1::RenderThumbnailResponse response;
  check("RenderThumbnail", render_->RenderThumbnail(&context, request, &response));
  return response;
}

}  // namespace animspace
