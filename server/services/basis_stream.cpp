#include "server/services/basis_stream.h"

#include <algorithm>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "animspace/v1/poses.pb.h"
#include "core/common/point_codec.h"
#include "server/model_lookup.h"
#include "server/pose_input.h"
#include "server/raw_messages.h"
#include "server/stream_reactor.h"

namespace animspace::server {
namespace {

constexpr const char* kRpc = "PoseService/GetBasis";
constexpr int64_t kMaxChunkBytes = int64_t{4} << 20;

class BasisStream final : public StreamReactor<grpc::ServerWriteReactor<grpc::ByteBuffer>, grpc::ByteBuffer> {
 public:
  static BasisStream* start(ServiceEnvironment& env, grpc::CallbackServerContext* context,
                            const grpc::ByteBuffer* request) {
    auto* stream = new BasisStream(env, context);
    if (grpc::Status unread = parse_message(*request, "the request", stream->request_); !unread.ok()) {
      stream->finish_early(std::move(unread));
      return stream;
    }
    if (stream->admit(env, Access::kUser)) stream->pump();  // starts the first build
    return stream;
  }

 private:
  BasisStream(ServiceEnvironment& env, grpc::CallbackServerContext* context)
      : StreamReactor(context, env.request_pool, env.metrics, kRpc), env_(env) {}

  // One chunk built ahead of the one on the wire, one build at a time.
  bool want_more(size_t unwritten, size_t producing) const override { return producing == 0 && unwritten < 2; }
  void request_more() override {
    submit([this] { return build_next(); });
  }

  Outcome build_next() {
    if (!model_) {
      if (grpc::Status s = find_model(env_.registry, request_.model(), "model", model_, nullptr, deadline()); !s.ok()) {
        return Outcome::end(std::move(s));
      }
      set_model(model_->name);
      if (grpc::Status s = require_pmsc(*model_, "it has no subspace to send"); !s.ok()) {
        return Outcome::end(std::move(s));
      }
      switch (request_.values_encoding()) {
        case v1::POINT_ENCODING_UNSPECIFIED:
        case v1::POINT_ENCODING_FLOAT32: half_ = false; break;
        case v1::POINT_ENCODING_FLOAT16: half_ = true; break;
        default:
          return Outcome::end(invalid_argument("values_encoding: expected FLOAT32 or FLOAT16, got " +
                                               v1::PointEncoding_Name(request_.values_encoding())));
      }
      if (grpc::Status s = choose_layout(); !s.ok()) return Outcome::end(std::move(s));
      const pmsc::PmscModel& m = *model_->pmsc;
      if (skinned_) {
        const auto parts = skinned_->parts(m);
        parts_.assign(parts.begin(), parts.end());
      } else {
        parts_ = {std::span<const float>(m.mean.data(), static_cast<size_t>(m.mean.size())),
                  std::span<const float>(m.basis.data(), static_cast<size_t>(m.basis.size()))};
      }
      total_ = 0;
      for (const auto part : parts_) total_ += part.size();
      chunk_values_ = static_cast<uint64_t>(
          std::max<int64_t>(1, std::min(kMaxChunkBytes, env_.options.max_message_bytes / 4)) /
          static_cast<int64_t>(value_bytes()));
    }
    if (sent_ == total_ && sent_any_) return Outcome::end(grpc::Status::OK);
    const pmsc::PmscModel& m = *model_->pmsc;
    v1::BasisChunk chunk;
    chunk.set_model_version(model_->version);
    chunk.set_basis_checksum(model_->basis_checksum);
    chunk.set_basis_sha256(model_->basis_sha256);
    chunk.set_point_count(static_cast<uint32_t>(m.point_count));
    chunk.set_channel_count(static_cast<uint32_t>(m.channel_count));
    chunk.set_basis_size(static_cast<uint32_t>(m.basis_size()));
    chunk.set_aligned(m.aligned);
    chunk.set_total_values(total_);
    chunk.set_offset(sent_);
    chunk.set_values_encoding(half_ ? v1::POINT_ENCODING_FLOAT16 : v1::POINT_ENCODING_FLOAT32);
    if (skinned_) {
      chunk.set_layout(v1::BASIS_LAYOUT_SKINNED);
      chunk.set_subspace_bone_count(static_cast<uint32_t>(skinned_->bone_count));
      chunk.set_influences_per_point(static_cast<uint32_t>(skinned_->influences));
      chunk.set_values_sha256(half_ ? skinned_->float16.sha256 : skinned_->sha256);
      chunk.set_values_max_error(half_ ? skinned_->float16.max_error : 0.0f);
    } else {
      chunk.set_layout(v1::BASIS_LAYOUT_DENSE);
      chunk.set_values_sha256(half_ ? model_->float16_basis.sha256 : model_->basis_sha256);
      chunk.set_values_max_error(half_ ? model_->float16_basis.max_error : 0.0f);
    }
    const uint64_t count = std::min(chunk_values_, total_ - sent_);
    std::string* data = chunk.mutable_data();
    data->resize(count * value_bytes());
    // The parts one after the other (DENSE: the mean, then the basis column by column; SKINNED:
    // the mean, the slots, the residual columns), cut anywhere.
    uint64_t written = 0;
    while (written < count) {
      uint64_t at = sent_ + written;
      size_t part = 0;
      while (at >= parts_[part].size()) at -= parts_[part++].size();
      const float* source = parts_[part].data() + at;
      const uint64_t run = std::min(count - written, parts_[part].size() - at);
      if (half_) {
        // In range: float16_refusal is empty (checked at load, the values are immutable).
        const auto encoded = point_codec::encode_float16(
            std::span<const float>(source, run), 1, std::span<char>(data->data() + written * 2, run * 2));
        if (!encoded) return Outcome::end(to_grpc_status(encoded.error()));
      } else {
        std::memcpy(data->data() + written * sizeof(float), source, run * sizeof(float));
      }
      written += run;
    }
    sent_ += count;
    sent_any_ = true;
    grpc::ByteBuffer bytes;
    if (grpc::Status s = serialize_message(chunk, bytes); !s.ok()) return Outcome::end(std::move(s));
    return Outcome::write(std::move(bytes));
  }

  // The layout asked for and the model has, and whether its values fit float16 (each layout's own
  // refusal: a value beyond ±65504, or bone numbers beyond 2048).
  grpc::Status choose_layout() {
    const std::string model = "model '" + model_->name + "' version " + std::to_string(model_->version);
    switch (request_.layout()) {
      case v1::BASIS_LAYOUT_UNSPECIFIED:
      case v1::BASIS_LAYOUT_DENSE: break;
      case v1::BASIS_LAYOUT_SKINNED:
        if (!model_->skinned) {
          return {grpc::StatusCode::FAILED_PRECONDITION,
                  "layout: " + model + " has no SKINNED layout (" + model_->skinned_refusal + "); ask for DENSE"};
        }
        skinned_ = model_->skinned;
        break;
      case v1::BASIS_LAYOUT_COMPACT: skinned_ = model_->skinned; break;
      default:
        return invalid_argument("layout: expected DENSE, SKINNED or COMPACT, got " +
                                std::to_string(static_cast<int>(request_.layout())));
    }
    const std::string& refusal = skinned_ ? skinned_->float16_refusal : model_->float16_refusal;
    if (half_ && !refusal.empty()) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "values_encoding: " + model + ": " + refusal + "; ask for FLOAT32"};
    }
    return grpc::Status::OK;
  }

  ServiceEnvironment& env_;
  v1::GetBasisRequest request_;  // a copy: builds may run after gRPC has freed its own
  // Read by one build at a time, each ordered after the previous by the reactor's lock.
  std::shared_ptr<const LoadedModel> model_;  // pins the version for the whole download
  uint64_t total_ = 0;
  uint64_t chunk_values_ = 0;
  uint64_t sent_ = 0;
  bool sent_any_ = false;
  bool half_ = false;  // values_encoding FLOAT16
  std::shared_ptr<const model::Servable::SkinnedLayout> skinned_;  // null: the DENSE layout
  std::vector<std::span<const float>> parts_;  // the values sent, in order, within model_
  size_t value_bytes() const { return half_ ? 2 : sizeof(float); }
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* start_basis_stream(ServiceEnvironment& env,
                                                               grpc::CallbackServerContext* context,
                                                               const grpc::ByteBuffer* request) {
  return BasisStream::start(env, context, request);
}

}  // namespace animspace::server
