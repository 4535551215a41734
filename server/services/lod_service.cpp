#include "server/services/lod_service.h"

#include <algorithm>
#include <memory>
#include <optional>
#include <string>

#include "core/animspace/model.h"
#include "core/atlas/atlas_io.h"
#include "core/lod/level_blocks.h"
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

constexpr const char* kRpc = "LodService/GetLod";
constexpr uint32_t kDefaultVerticesPerChunk = 65536;
constexpr uint32_t kMaxVerticesPerChunk = 1u << 20;
// Payload bytes of one block: a few MiB keeps every message far below what a client accepts by
// default (64 MiB) and lets HTTP/2 flow control interleave streams; a quarter of
// --max-message-bytes leaves room for framing on a server configured smaller.
constexpr int64_t kMaxBlockBytes = int64_t{4} << 20;

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

  // Validates the request, resolves the model and the level, and lays out what the blocks are cut
  // from (lod::LevelBlocks). Runs on the request pool, once, before the header.
  grpc::Status prepare();
  // The next chunk on the request pool (prepare() first), or the end of the stream.
  Outcome build_next();
  // The next chunk in stream order, or false when the stream is complete.
  bool next_chunk(v1::LodChunk* chunk, grpc::Status* status);
  void fill_header(v1::LodHeader* header) const;
  void fill_vertices(uint32_t first, uint32_t count, v1::VertexBlock* block) const;
  void fill_skeleton(v1::Skeleton* skeleton) const;

  ServiceEnvironment& env_;
  Request request_;  // a copy: builds may run after gRPC has freed its own

  // What is sent: set by prepare(), then read by one build at a time, each build ordered after
  // the previous one by the reactor's lock (want_more).
  std::shared_ptr<const LoadedModel> model_;  // keeps the level alive across a hot swap
  LodChoice choice_;
  std::optional<lod::LevelBlocks> blocks_;
  std::optional<atlas::Atlas> atlas_;  // include_texture_coordinates at level 0: the model's atlas
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
  if (r.form() == Request::FORM_ANIMATION_SPACE && r.has_pose()) {
    return invalid_argument(
        "pose: expected no pose with FORM_ANIMATION_SPACE (the node poses the mesh itself), got one; "
        "a posed mesh is FORM_POSED");
  }
  if (r.form() == Request::FORM_POSED && r.include_geomorph()) {
    return invalid_argument(
        "include_geomorph: expected FORM_ANIMATION_SPACE (Δp is per influence, §7.3), got FORM_POSED");
  }
  if (r.include_texture_coordinates() && r.form() != Request::FORM_POSED) {
    return invalid_argument(
        "include_texture_coordinates: expected FORM_POSED (UVs go with the drawn mesh), got FORM_ANIMATION_SPACE");
  }
  if (r.vertices_per_chunk() > kMaxVerticesPerChunk) {
    return invalid_argument("vertices_per_chunk: expected 0 (the default, " + std::to_string(kDefaultVerticesPerChunk) +
                            ") or 1.." + std::to_string(kMaxVerticesPerChunk) + ", got " +
                            std::to_string(r.vertices_per_chunk()));
  }
  if (grpc::Status s = find_model(env_.registry, r.model(), "model", model_, nullptr, deadline()); !s.ok()) return s;
  set_model(model_->name);
  if (grpc::Status s = select_lod_level(*model_, r, &choice_); !s.ok()) return s;
  if (r.include_texture_coordinates()) {
    // Level 0 serves the atlas itself; a coarser level the corner UVs build-lod stored with it
    // (lod/chart_atlas.h: its faces keep their charts, its borders the atlas's).
    const long faces = model_->lod_levels->levels.front().model.faces.rows();
    auto stored = atlas::load_atlas(model_->container, faces, model_->path.string());
    if (!stored) return to_grpc_status(stored.error());
    if (!*stored) {
      return failed_precondition("include_texture_coordinates: model '" + model_->name + "' version " +
                                 std::to_string(model_->version) +
                                 " stores no texture atlas (expected atlas sections; `animspace atlas` adds them)");
    }
    if (choice_.level == 0) {
      atlas_ = std::move(**stored);
    } else if (choice_.lod->corner_uvs.rows() == 0) {
      return failed_precondition("include_texture_coordinates: level " + std::to_string(choice_.level) +
                                 " of model '" + model_->name + "' version " + std::to_string(model_->version) +
                                 " stores no texture coordinates (its levels were built without the atlas; "
                                 "`animspace build-lod` on the model with its atlas stores them)");
    }
  }

  lod::LevelBlockOptions options;
  as::TransformList globals;
  if (r.form() == Request::FORM_POSED) {
    options.form = lod::LevelForm::kPosed;
    if (r.has_pose()) {
      const as::Skeleton& skeleton = choice_.lod->model.skeleton;
      if (grpc::Status s = decode_skeleton_pose(r.pose(), "pose", skeleton, globals); !s.ok()) return s;
      options.pose = &globals;
    }
  } else {
    options.form = lod::LevelForm::kAnimationSpace;
    options.geomorph = r.include_geomorph();
  }
  if (atlas_) {
    options.corner_uvs = &atlas_->uvs;
  } else if (r.include_texture_coordinates()) {
    options.corner_uvs = &choice_.lod->corner_uvs;  // the level outlives the stream (model_)
  }
  options.max_block_vertices = r.vertices_per_chunk() != 0 ? r.vertices_per_chunk() : kDefaultVerticesPerChunk;
  options.max_block_bytes = std::max<int64_t>(1, std::min(kMaxBlockBytes, env_.options.max_message_bytes / 4));
  blocks_.emplace(*model_->lod_levels, choice_.level, options);
  return grpc::Status::OK;
}

void LodStream::fill_header(v1::LodHeader* header) const {
  const as::AnimationSpaceModel& level = choice_.lod->model;
  header->set_model_version(model_->version);
  header->set_level(static_cast<uint32_t>(choice_.level));
  header->set_level_count(static_cast<uint32_t>(model_->lod_levels->count()));
  header->set_epsilon(static_cast<float>(choice_.lod->epsilon));
  header->set_vertex_count(blocks_->vertex_count());
  header->set_face_count(blocks_->face_count());
  header->set_bone_count(static_cast<uint32_t>(level.bone_count()));
  header->set_influence_count(blocks_->influence_count());
  header->set_form(request_.form());
  header->set_tolerated_error(static_cast<float>(choice_.tolerated_error));
  header->set_texture_coordinates(blocks_->has_corner_uvs());
}

void LodStream::fill_vertices(uint32_t first, uint32_t count, v1::VertexBlock* block) const {
  block->set_first_vertex(first);
  block->set_vertex_count(count);
  if (blocks_->form() == lod::LevelForm::kPosed) {
    encode_points(blocks_->posed().data() + size_t{first} * 3, count, 3, block->mutable_positions());
    return;
  }
  lod::InfluenceBlock bytes = blocks_->influence_block(first, count);
  block->set_influence_offsets(std::move(bytes.influence_offsets));
  block->set_bone_indices(std::move(bytes.bone_indices));
  block->set_animation_positions(std::move(bytes.animation_positions));
  if (blocks_->geomorph()) block->set_geomorph_delta(std::move(bytes.geomorph_delta));
}

void LodStream::fill_skeleton(v1::Skeleton* out) const {
  const as::Skeleton& skeleton = choice_.lod->model.skeleton;
  for (int32_t parent : skeleton.parents) out->add_parents(parent);
  out->set_rest_transforms(lod::pack_rest_transforms(skeleton));
  for (const std::string& name : skeleton.names) out->add_bone_names(name);
}

bool LodStream::next_chunk(v1::LodChunk* chunk, grpc::Status* status) {
  const uint32_t vertices = blocks_->vertex_count();
  const uint32_t faces = blocks_->face_count();
  std::string what;
  switch (phase_) {
    case Phase::kHeader:
      fill_header(chunk->mutable_header());
      what = "the header";
      phase_ = Phase::kVertices;
      break;
    case Phase::kVertices: {
      const uint32_t count = blocks_->block_vertex_count(next_vertex_);
      fill_vertices(next_vertex_, count, chunk->mutable_vertices());
      what = count == 1 ? "vertex " + std::to_string(next_vertex_)
                        : "vertices " + std::to_string(next_vertex_) + ".." + std::to_string(next_vertex_ + count - 1);
      next_vertex_ += count;
      if (next_vertex_ == vertices) phase_ = faces > 0 ? Phase::kFaces : Phase::kSkeleton;
      break;
    }
    case Phase::kFaces: {
      const uint32_t count = std::min(blocks_->faces_per_block(), faces - next_face_);
      v1::FaceBlock* block = chunk->mutable_faces();
      block->set_first_face(next_face_);
      block->set_face_count(count);
      block->set_indices(blocks_->face_block(next_face_, count));
      if (blocks_->has_corner_uvs()) block->set_texture_coordinates(blocks_->face_uv_block(next_face_, count));
      what = "face " + std::to_string(next_face_);
      next_face_ += count;
      if (next_face_ == faces) phase_ = Phase::kSkeleton;
      break;
    }
    case Phase::kSkeleton:
      if (blocks_->form() != lod::LevelForm::kAnimationSpace) return false;
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
    *status = resource_exhausted("the chunk carrying " + what + " would be " + std::to_string(bytes) +
                                 " bytes, the limit is " + std::to_string(env_.options.max_message_bytes) +
                                 " (--max-message-bytes)");
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
