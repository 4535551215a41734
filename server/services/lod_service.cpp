#include "server/services/lod_service.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <memory>
#include <optional>
#include <string>

#include "core/animspace/model.h"
#include "core/common/types.h"
#include "core/lod/levels.h"
#include "server/lod_selection.h"
#include "server/model_lookup.h"
#include "server/raw_messages.h"
#include "server/status_mapping.h"
#include "server/stream_reactor.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

namespace as = animation_space;
using Request = v1::GetLodRequest;

// The wire format is little-endian (lod.proto); this build copies values as they are.
static_assert(std::endian::native == std::endian::little, "animspaced assumes a little-endian host");

constexpr const char* kRpc = "LodService/GetLod";
constexpr uint32_t kDefaultVerticesPerChunk = 65536;
constexpr uint32_t kMaxVerticesPerChunk = 1u << 20;
// Payload bytes of one block: a few MiB keeps every message far below what a client accepts by
// default (64 MiB) and lets HTTP/2 flow control interleave streams; a quarter of
// --max-message-bytes leaves room for framing on a server configured smaller.
constexpr int64_t kMaxBlockBytes = int64_t{4} << 20;
// Wire bytes per element: a CSR offset, a bone index, a 4-vector (p_j or Δp), a posed vertex, a face.
constexpr int64_t kOffsetBytes = 4;
constexpr int64_t kBoneBytes = 4;
constexpr int64_t kVectorBytes = 16;
constexpr int64_t kPosedVertexBytes = 12;
constexpr int64_t kFaceBytes = 12;

template <typename T>
void put(char*& at, T value) {
  std::memcpy(at, &value, sizeof(value));
  at += sizeof(value);
}

// Columns [begin, end) of a 4 × I matrix as 4 float32 each: float32 is the wire precision of every
// position the API sends (common.proto); the core keeps doubles for simplification (§6).
std::string pack_vectors(const as::InfluenceVectors& vectors, int begin, int end) {
  std::string out(static_cast<size_t>(end - begin) * kVectorBytes, '\0');
  char* at = out.data();
  for (int k = begin; k < end; ++k) {
    for (int r = 0; r < 4; ++r) put(at, static_cast<float>(vectors(r, k)));
  }
  return out;
}

// Built one chunk at a time (server/stream_reactor.h owns the order, the lifetime and
// cancellation): each build reads and advances the phase below, so builds never overlap.
class LodStream final : public StreamReactor<grpc::ServerWriteReactor<grpc::ByteBuffer>, grpc::ByteBuffer> {
 public:
  // Parses the request, authenticates and admits the call, then streams; the reactor deletes
  // itself when done.
  static LodStream* start(ServiceEnvironment& env, grpc::CallbackServerContext* context,
                          const grpc::ByteBuffer* request);

 private:
  enum class Phase { kHeader, kVertices, kFaces, kSkeleton, kEnd };

  LodStream(ServiceEnvironment& env, grpc::CallbackServerContext* context)
      : StreamReactor(context, env.request_pool, env.metrics, kRpc), env_(env) {}

  // One chunk built ahead of the one on the wire, no more (back-pressure reaches the builder), and
  // one build at a time.
  bool want_more(size_t unwritten, size_t producing) const override { return producing == 0 && unwritten < 2; }
  void request_more() override {
    submit([this] { return build_next(); });
  }

  // Validates the request, resolves the model and the level, and precomputes what the blocks are
  // cut from. Runs on the request pool, once, before the header.
  grpc::Status prepare();
  // The next chunk on the request pool (prepare() first), or the end of the stream.
  Outcome build_next();
  // The next chunk in stream order, or false when the stream is complete.
  bool next_chunk(v1::LodChunk* chunk, grpc::Status* status);
  void fill_header(v1::LodHeader* header) const;
  // How many vertices from `first` one block carries: at most vertices_per_block_, and as many as
  // fit in block_bytes_ by their influence counts (always at least one).
  uint32_t block_vertex_count(uint32_t first) const;
  void fill_vertices(uint32_t first, uint32_t count, v1::VertexBlock* block) const;
  void fill_faces(uint32_t first, uint32_t count, v1::FaceBlock* block) const;
  void fill_skeleton(v1::Skeleton* skeleton) const;

  ServiceEnvironment& env_;
  Request request_;  // a copy: builds may run after gRPC has freed its own

  // What is sent: set by prepare(), then read by one build at a time, each build ordered after
  // the previous one by the reactor's lock (want_more).
  std::shared_ptr<const LoadedModel> model_;  // keeps the level alive across a hot swap
  LodChoice choice_;
  Request::Form form_ = Request::FORM_UNSPECIFIED;
  PointMatrix posed_;                     // FORM_POSED: the level at the pose, V × 3
  std::optional<lod::Geomorph> morph_;    // include_geomorph below the coarsest level
  const as::InfluenceSets* influences_ = nullptr;  // FORM_ANIMATION_SPACE: what the blocks carry
  const as::InfluenceVectors* positions_ = nullptr;
  const as::InfluenceVectors* delta_ = nullptr;  // null with geomorph_ at the coarsest level: Δp = 0
  bool geomorph_ = false;
  uint32_t vertices_per_block_ = kDefaultVerticesPerChunk;
  uint32_t faces_per_block_ = kDefaultVerticesPerChunk;
  int64_t block_bytes_ = kMaxBlockBytes;
  bool prepared_ = false;
  Phase phase_ = Phase::kHeader;
  uint32_t next_vertex_ = 0;
  uint32_t next_face_ = 0;
};

LodStream* LodStream::start(ServiceEnvironment& env, grpc::CallbackServerContext* context,
                            const grpc::ByteBuffer* request) {
  auto* stream = new LodStream(env, context);
  if (grpc::Status unread = parse_message(*request, "the request", stream->request_); !unread.ok()) {
    stream->finish_early(std::move(unread));
    return stream;
  }
  if (stream->admit(env, Access::kUser)) stream->pump();  // starts the first build
  return stream;
}

grpc::Status LodStream::prepare() {
  const Request& r = request_;
  // The request's own fields first: they need no model.
  if (r.form() != Request::FORM_ANIMATION_SPACE && r.form() != Request::FORM_POSED) {
    const std::string got =
        Request::Form_IsValid(r.form()) ? Request::Form_Name(r.form()) : std::to_string(static_cast<int>(r.form()));
    return invalid_argument("form: expected FORM_ANIMATION_SPACE or FORM_POSED, got " + got);
  }
  form_ = r.form();
  if (form_ == Request::FORM_ANIMATION_SPACE && r.has_pose()) {
    return invalid_argument(
        "pose: expected no pose with FORM_ANIMATION_SPACE (the node poses the mesh itself), got one; "
        "a posed mesh is FORM_POSED");
  }
  if (form_ == Request::FORM_POSED && r.include_geomorph()) {
    return invalid_argument(
        "include_geomorph: expected FORM_ANIMATION_SPACE (Δp is per influence, §7.3), got FORM_POSED");
  }
  if (r.vertices_per_chunk() > kMaxVerticesPerChunk) {
    return invalid_argument("vertices_per_chunk: expected 0 (the default, " + std::to_string(kDefaultVerticesPerChunk) +
                            ") or 1.." + std::to_string(kMaxVerticesPerChunk) + ", got " +
                            std::to_string(r.vertices_per_chunk()));
  }
  if (grpc::Status s = find_model(env_.registry, r.model(), "model", model_); !s.ok()) return s;
  set_model(model_->name);
  if (grpc::Status s = select_lod_level(*model_, r, &choice_); !s.ok()) return s;
  const as::AnimationSpaceModel& level = choice_.lod->model;

  if (form_ == Request::FORM_POSED) {
    as::TransformList globals = level.skeleton.rest;
    if (r.has_pose()) {
      if (grpc::Status s = decode_skeleton_pose(r.pose(), "pose", level.skeleton, globals); !s.ok()) return s;
    }
    // v = Σ_j G_j p_j (eq. 3.1) for the whole level at once, with the core's evaluator: 12 bytes
    // per vertex, less than the level itself, and the blocks are then plain copies.
    as::evaluate(level, globals, posed_);
  } else {
    influences_ = &level.influences;
    positions_ = &level.positions;
    geomorph_ = r.include_geomorph();
    if (geomorph_ && choice_.level + 1 < model_->lod_levels->count()) {
      // §7.3: morphing needs p^l and p^{l+1} on the same influences, so the aligned (union) set
      // replaces the level's own; p_j = 0 where only the coarser vertex has bone j.
      morph_ = lod::geomorph(*model_->lod_levels, choice_.level);
      influences_ = &morph_->aligned;
      positions_ = &morph_->position;
      delta_ = &morph_->delta;
    }
  }
  if (r.vertices_per_chunk() != 0) vertices_per_block_ = r.vertices_per_chunk();
  block_bytes_ = std::max<int64_t>(1, std::min(kMaxBlockBytes, env_.options.max_message_bytes / 4));
  // Face blocks as large in bytes as posed vertex blocks (12 bytes each).
  faces_per_block_ = static_cast<uint32_t>(
      std::clamp<int64_t>(block_bytes_ / kFaceBytes, 1, static_cast<int64_t>(vertices_per_block_)));
  return grpc::Status::OK;
}

void LodStream::fill_header(v1::LodHeader* header) const {
  const as::AnimationSpaceModel& level = choice_.lod->model;
  header->set_model_version(model_->version);
  header->set_level(static_cast<uint32_t>(choice_.level));
  header->set_level_count(static_cast<uint32_t>(model_->lod_levels->count()));
  header->set_epsilon(static_cast<float>(choice_.lod->epsilon));
  header->set_vertex_count(static_cast<uint32_t>(level.vertex_count()));
  header->set_face_count(static_cast<uint32_t>(level.faces.rows()));
  header->set_bone_count(static_cast<uint32_t>(level.bone_count()));
  header->set_influence_count(influences_ ? static_cast<uint32_t>(influences_->influence_count()) : 0);
  header->set_form(form_);
  header->set_tolerated_error(static_cast<float>(choice_.tolerated_error));
}

uint32_t LodStream::block_vertex_count(uint32_t first) const {
  const auto vertices = static_cast<uint32_t>(choice_.lod->model.vertex_count());
  const uint32_t limit = std::min(vertices_per_block_, vertices - first);
  if (form_ == Request::FORM_POSED) {
    return static_cast<uint32_t>(std::clamp<int64_t>(block_bytes_ / kPosedVertexBytes, 1, limit));
  }
  // A vertex costs its influences: a rig with many bones per vertex gets fewer vertices per block.
  const int64_t per_influence = kBoneBytes + kVectorBytes + (geomorph_ ? kVectorBytes : 0);
  int64_t bytes = kOffsetBytes;  // the block's leading offset, 0
  uint32_t count = 0;
  while (count < limit) {
    const int v = static_cast<int>(first + count);
    const int64_t cost = kOffsetBytes + per_influence * (influences_->end(v) - influences_->begin(v));
    if (count > 0 && bytes + cost > block_bytes_) break;
    bytes += cost;
    ++count;
  }
  return count;
}

void LodStream::fill_vertices(uint32_t first, uint32_t count, v1::VertexBlock* block) const {
  block->set_first_vertex(first);
  block->set_vertex_count(count);
  if (form_ == Request::FORM_POSED) {
    encode_points(posed_.data() + size_t{first} * 3, count, 3, block->mutable_positions());
    return;
  }
  const as::InfluenceSets& sets = *influences_;
  const int begin = sets.begin(static_cast<int>(first));
  const int end = sets.begin(static_cast<int>(first + count));
  std::string offsets(size_t{count + 1} * kOffsetBytes, '\0');
  char* at = offsets.data();
  for (uint32_t v = 0; v <= count; ++v) put(at, static_cast<uint32_t>(sets.begin(static_cast<int>(first + v)) - begin));
  std::string bones(static_cast<size_t>(end - begin) * kBoneBytes, '\0');
  at = bones.data();
  for (int k = begin; k < end; ++k) put(at, static_cast<uint32_t>(sets.bones[static_cast<size_t>(k)]));
  block->set_influence_offsets(std::move(offsets));
  block->set_bone_indices(std::move(bones));
  block->set_animation_positions(pack_vectors(*positions_, begin, end));
  if (geomorph_) {
    block->set_geomorph_delta(delta_ ? pack_vectors(*delta_, begin, end)
                                     : std::string(static_cast<size_t>(end - begin) * kVectorBytes, '\0'));
  }
}

void LodStream::fill_faces(uint32_t first, uint32_t count, v1::FaceBlock* block) const {
  const FaceMatrix& faces = choice_.lod->model.faces;
  block->set_first_face(first);
  block->set_face_count(count);
  std::string indices(size_t{count} * kFaceBytes, '\0');
  char* at = indices.data();
  for (uint32_t f = first; f < first + count; ++f) {
    for (int c = 0; c < 3; ++c) put(at, static_cast<uint32_t>(faces(f, c)));
  }
  block->set_indices(std::move(indices));
}

void LodStream::fill_skeleton(v1::Skeleton* out) const {
  const as::Skeleton& skeleton = choice_.lod->model.skeleton;
  for (int32_t parent : skeleton.parents) out->add_parents(parent);
  // Ĝ_j in SkeletonPose.transforms layout, as decode_skeleton_pose reads it: the top three rows of
  // each 4×4, row-major, float32.
  std::string rest(skeleton.rest.size() * 12 * sizeof(float), '\0');
  char* at = rest.data();
  for (const as::Transform& G : skeleton.rest) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) put(at, static_cast<float>(G(r, c)));
    }
  }
  out->set_rest_transforms(std::move(rest));
  for (const std::string& name : skeleton.names) out->add_bone_names(name);
}

bool LodStream::next_chunk(v1::LodChunk* chunk, grpc::Status* status) {
  const as::AnimationSpaceModel& level = choice_.lod->model;
  const auto vertices = static_cast<uint32_t>(level.vertex_count());
  const auto faces = static_cast<uint32_t>(level.faces.rows());
  std::string what;
  switch (phase_) {
    case Phase::kHeader:
      fill_header(chunk->mutable_header());
      what = "the header";
      phase_ = Phase::kVertices;
      break;
    case Phase::kVertices: {
      const uint32_t count = block_vertex_count(next_vertex_);
      fill_vertices(next_vertex_, count, chunk->mutable_vertices());
      what = count == 1 ? "vertex " + std::to_string(next_vertex_)
                        : "vertices " + std::to_string(next_vertex_) + ".." + std::to_string(next_vertex_ + count - 1);
      next_vertex_ += count;
      if (next_vertex_ == vertices) phase_ = faces > 0 ? Phase::kFaces : Phase::kSkeleton;
      break;
    }
    case Phase::kFaces: {
      const uint32_t count = std::min(faces_per_block_, faces - next_face_);
      fill_faces(next_face_, count, chunk->mutable_faces());
      what = "face " + std::to_string(next_face_);
      next_face_ += count;
      if (next_face_ == faces) phase_ = Phase::kSkeleton;
      break;
    }
    case Phase::kSkeleton:
      if (form_ != Request::FORM_ANIMATION_SPACE) return false;
      fill_skeleton(chunk->mutable_skeleton());
      what = "the skeleton";
      phase_ = Phase::kEnd;
      break;
    case Phase::kEnd:
      return false;
  }
  // Blocks are sized to a quarter of the limit; only one vertex with more influences than that,
  // or a skeleton of very many bones, can still exceed it.
  const size_t bytes = chunk->ByteSizeLong();
  if (bytes > static_cast<uint64_t>(env_.options.max_message_bytes)) {
    *status = {grpc::StatusCode::RESOURCE_EXHAUSTED,
               "the chunk carrying " + what + " would be " + std::to_string(bytes) + " bytes, the limit is " +
                   std::to_string(env_.options.max_message_bytes) + " (--max-message-bytes)"};
  }
  return true;
}

LodStream::Outcome LodStream::build_next() {
  if (!prepared_) {
    prepared_ = true;
    if (grpc::Status s = prepare(); !s.ok()) return Outcome::end(std::move(s));
  }
  v1::LodChunk chunk;
  grpc::Status status;
  if (!next_chunk(&chunk, &status)) return Outcome::end(grpc::Status::OK);
  if (!status.ok()) return Outcome::end(std::move(status));
  grpc::ByteBuffer bytes;
  if (grpc::Status s = serialize_message(chunk, bytes); !s.ok()) return Outcome::end(std::move(s));
  return Outcome::write(std::move(bytes));
}

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* LodServiceImpl::GetLod(grpc::CallbackServerContext* context,
                                                                   const grpc::ByteBuffer* request) {
  return LodStream::start(env_, context, request);
}

}  // namespace animspace::server
