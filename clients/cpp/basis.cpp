// Client::get_basis: PoseService.GetBasis's chunks reassembled into one array, every chunk checked
// against the first (a stream that changed version, shape or checksum midway, or skipped or
// repeated values, is refused rather than pieced together).
#include <cstring>
#include <span>
#include <stdexcept>
#include <string>

#include "clients/cpp/client.h"
#include "core/common/point_codec.h"
#include "core/common/sha256.h"

namespace animspace {
namespace {

// The problem with `chunk` given what came before, or empty.
// Bytes a value of `chunk` takes: FLOAT16 2, else 4 (FLOAT32, or unset from servers before it);
// 0 for an encoding GetBasis never sends.
size_t value_bytes(const v1::BasisChunk& chunk) {
  switch (chunk.values_encoding()) {
    case v1::POINT_ENCODING_UNSPECIFIED:
    case v1::POINT_ENCODING_FLOAT32: return sizeof(float);
    case v1::POINT_ENCODING_FLOAT16: return 2;
    default: return 0;
  }
}

// Values in a SKINNED slot: a bone's number, then its term's four (poses.proto, BasisChunk).
constexpr uint64_t kSlotValues = 5;

// DENSE (or unset, from servers before the layouts) or SKINNED; another value is refused.
v1::BasisLayout layout_of(const v1::BasisChunk& chunk) {
  return chunk.layout() == v1::BASIS_LAYOUT_UNSPECIFIED ? v1::BASIS_LAYOUT_DENSE : chunk.layout();
}

std::string check_chunk(const BasisData& basis, bool first, const v1::BasisChunk& chunk) {
  const size_t bytes = value_bytes(chunk);
  if (layout_of(chunk) != v1::BASIS_LAYOUT_DENSE && layout_of(chunk) != v1::BASIS_LAYOUT_SKINNED) {
    return "chunk at value " + std::to_string(chunk.offset()) + " has layout " +
           std::to_string(static_cast<int>(chunk.layout())) + ", not DENSE or SKINNED";
  }
  if (bytes == 0) {
    return "chunk at value " + std::to_string(chunk.offset()) + " has values_encoding " +
           v1::PointEncoding_Name(chunk.values_encoding()) + ", not FLOAT32 or FLOAT16";
  }
  if (chunk.data().size() % bytes != 0) {
    return "chunk at value " + std::to_string(chunk.offset()) + " holds " + std::to_string(chunk.data().size()) +
           " bytes, not whole " + (bytes == 2 ? "float16" : "float32") + " values";
  }
  if (first) {
    const uint64_t N = chunk.point_count(), M = chunk.basis_size();
    if (layout_of(chunk) == v1::BASIS_LAYOUT_SKINNED) {
      const uint64_t B = chunk.subspace_bone_count(), K = chunk.influences_per_point();
      if (chunk.channel_count() != 3 || B == 0 || K == 0 || 12 * B > M) {
        return "a SKINNED basis of D = " + std::to_string(chunk.channel_count()) + ", B = " + std::to_string(B) +
               ", K = " + std::to_string(K) + " and M = " + std::to_string(M) + ": expected D = 3, B, K ≥ 1, 12·B ≤ M";
      }
      const uint64_t expected = 3 * N * (M - 12 * B + 1) + kSlotValues * N * K;
      if (chunk.total_values() != expected) {
        return "total_values " + std::to_string(chunk.total_values()) +
               " is not N·3·(r+1) + 5·N·K = " + std::to_string(expected);
      }
    } else {
      const uint64_t expected = N * chunk.channel_count() * (M + 1);
      if (chunk.total_values() != expected) {
        return "total_values " + std::to_string(chunk.total_values()) + " is not N·D·(M+1) = " +
               std::to_string(expected);
      }
    }
    return chunk.offset() == 0 ? std::string() : "the first chunk starts at value " + std::to_string(chunk.offset());
  }
  if (chunk.model_version() != basis.model_version || chunk.basis_checksum() != basis.basis_checksum ||
      chunk.basis_sha256() != basis.basis_sha256 ||
      chunk.point_count() != basis.point_count || chunk.channel_count() != basis.channel_count ||
      chunk.basis_size() != basis.basis_size || chunk.aligned() != basis.aligned ||
      layout_of(chunk) != basis.layout || chunk.subspace_bone_count() != basis.subspace_bone_count ||
      chunk.influences_per_point() != basis.influences_per_point ||
      value_bytes(chunk) != (basis.values_encoding == v1::POINT_ENCODING_FLOAT16 ? 2 : sizeof(float))) {
    return "chunk at value " + std::to_string(chunk.offset()) + " describes another basis than the first chunk";
  }
  if (chunk.offset() != basis.values.size()) {
    return "chunk at value " + std::to_string(chunk.offset()) + " does not follow the " +
           std::to_string(basis.values.size()) + " values received";
  }
  return {};
}

}  // namespace

BasisData Client::get_basis(const std::string& model, uint64_t version, std::chrono::milliseconds deadline,
                            v1::PointEncoding values_encoding, v1::BasisLayout layout) {
  grpc::ClientContext context;
  prepare(&context, deadline.count() > 0 ? deadline : options_.deadline);
  v1::GetBasisRequest request;
  request.mutable_model()->set_name(model);
  request.mutable_model()->set_version(version);
  request.set_values_encoding(values_encoding);
  request.set_layout(layout);
  auto reader = poses_->GetBasis(&context, request);
  BasisData basis;
  uint64_t total = 0;
  std::string problem;
  std::string values_sha256;
  Sha256 sent;  // over the values as they came, checked against values_sha256
  v1::BasisChunk chunk;
  while (reader->Read(&chunk)) {
    const bool first = basis.chunk_count == 0;
    problem = check_chunk(basis, first, chunk);
    const size_t bytes = value_bytes(chunk);
    if (problem.empty() && chunk.offset() + chunk.data().size() / bytes > (first ? chunk.total_values() : total)) {
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
      basis.layout = layout_of(chunk);
      basis.subspace_bone_count = chunk.subspace_bone_count();
      basis.influences_per_point = chunk.influences_per_point();
      basis.values_encoding = bytes == 2 ? v1::POINT_ENCODING_FLOAT16 : v1::POINT_ENCODING_FLOAT32;
      basis.values_max_error = chunk.values_max_error();
      values_sha256 = chunk.values_sha256();
      total = chunk.total_values();
      basis.values.reserve(total);
    }
    const size_t at = basis.values.size();
    basis.values.resize(at + chunk.data().size() / bytes);
    if (bytes == 2) {
      sent.update(std::as_bytes(std::span<const char>(chunk.data())));
      point_codec::decode_float16(std::span<const char>(chunk.data()),
                                  std::span<float>(basis.values.data() + at, chunk.data().size() / 2));
    } else {
      std::memcpy(basis.values.data() + at, chunk.data().data(), chunk.data().size());
    }
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
  // A float32 basis is checked against basis_sha256 by make_basis; float16 values can only be
  // checked as they came.
  if (basis.values_encoding == v1::POINT_ENCODING_FLOAT16) {
    const std::string digest = sent.digest();
    if (digest != values_sha256) {
      throw std::runtime_error("GetBasis: the float16 values have SHA-256 " + hex_digest(digest) +
                               ", the server named " + hex_digest(values_sha256));
    }
  }
  return basis;
}

}  // namespace animspace
