// Client::get_basis: PoseService.GetBasis's chunks reassembled into one array, every chunk checked
// against the first (a stream that changed version, shape or checksum midway, or skipped or
// repeated values, is refused rather than pieced together).
#include <cstring>
#include <stdexcept>
#include <string>

#include "clients/cpp/client.h"

namespace animspace {
namespace {

// The problem with `chunk` given what came before, or empty.
std::string check_chunk(const BasisData& basis, bool first, const v1::BasisChunk& chunk) {
  if (chunk.data().size() % sizeof(float) != 0) {
    return "chunk at value " + std::to_string(chunk.offset()) + " holds " + std::to_string(chunk.data().size()) +
           " bytes, not whole float32 values";
  }
  if (first) {
    const uint64_t expected = uint64_t{chunk.point_count()} * chunk.channel_count() * (uint64_t{chunk.basis_size()} + 1);
    if (chunk.total_values() != expected) {
      return "total_values " + std::to_string(chunk.total_values()) + " is not N·D·(M+1) = " + std::to_string(expected);
    }
    return chunk.offset() == 0 ? std::string() : "the first chunk starts at value " + std::to_string(chunk.offset());
  }
  if (chunk.model_version() != basis.model_version || chunk.basis_checksum() != basis.basis_checksum ||
      chunk.basis_sha256() != basis.basis_sha256 ||
      chunk.point_count() != basis.point_count || chunk.channel_count() != basis.channel_count ||
      chunk.basis_size() != basis.basis_size || chunk.aligned() != basis.aligned) {
    return "chunk at value " + std::to_string(chunk.offset()) + " describes another basis than the first chunk";
  }
  if (chunk.offset() != basis.values.size()) {
    return "chunk at value " + std::to_string(chunk.offset()) + " does not follow the " +
           std::to_string(basis.values.size()) + " values received";
  }
  return {};
}

}  // namespace

BasisData Client::get_basis(const std::string& model, uint64_t version, std::chrono::milliseconds deadline) {
  grpc::ClientContext context;
  prepare(&context, deadline.count() > 0 ? deadline : options_.deadline);
  v1::GetBasisRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(version);
  auto reader = poses_->GetBasis(&context, request);
  BasisData basis;
  uint64_t total = 0;
  std::string problem;
  v1::BasisChunk chunk;
  while (reader->Read(&chunk)) {
    const bool first = basis.chunk_count == 0;
    problem = check_chunk(basis, first, chunk);
    if (problem.empty() && chunk.offset() + chunk.data().size() / sizeof(float) > (first ? chunk.total_values() : total)) {
      problem = "chunk at value " + std::to_string(chunk.offset()) + " runs past total_values";
    }
    if (!problem.empty()) {
      context.TryCancel();  // the rest of the stream is of no use
      break;
    }
    if (first) {
      basis.model_version = chunk.model_version();
      basis.basis_checksum = chunk.basis_checksum();
      basis.basis_sha256 = chunk.basis_sha256();
      basis.point_count = chunk.point_count();
      basis.channel_count = chunk.channel_count();
      basis.basis_size = chunk.basis_size();
      basis.aligned = chunk.aligned();
      total = chunk.total_values();
      basis.values.reserve(total);
    }
    const size_t at = basis.values.size();
    basis.values.resize(at + chunk.data().size() / sizeof(float));
    std::memcpy(basis.values.data() + at, chunk.data().data(), chunk.data().size());
    basis.chunk_count += 1;
    basis.bytes_received += chunk.ByteSizeLong();
  }
  const grpc::Status status = reader->Finish();
  if (!problem.empty()) throw std::runtime_error("GetBasis: " + problem);
  if (!status.ok()) throw RpcError("GetBasis", status);
  if (basis.chunk_count == 0 || basis.values.size() != total) {
    throw std::runtime_error("GetBasis: the stream ended after " + std::to_string(basis.values.size()) + " of " +
                             std::to_string(total) + " values");
  }
  return basis;
}

}  // namespace animspace
