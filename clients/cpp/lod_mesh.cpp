// Client::get_lod: reassembles LodService.GetLod's stream into one LodMesh, checking every chunk
// against the header as it arrives (order, contiguity, sizes, index ranges), so that a truncated
// or reordered stream is an error rather than a mesh with holes.
#include <algorithm>
#include <bit>
#include <cstring>
#include <string>

#include "clients/cpp/client.h"

namespace animspace {
namespace {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

// Most elements reserved up front from the header's counts: a bogus header cannot make the client
// allocate gigabytes before the first block shows the counts are real.
constexpr uint64_t kMaxReserve = uint64_t{1} << 24;

template <typename T>
void append(std::vector<T>& out, const std::string& bytes) {
  if (bytes.empty()) return;  // memcpy into an empty vector's null data() is undefined, even for 0 bytes
  const size_t old = out.size();
  out.resize(old + bytes.size() / sizeof(T));
  std::memcpy(out.data() + old, bytes.data(), bytes.size());
}

class Assembler {
 public:
  explicit Assembler(LodMesh& mesh) : mesh_(mesh) {}

  // Takes one chunk; returns what is wrong with it, or "" when it fits.
  std::string take(const v1::LodChunk& chunk) {
    if (!has_header_ && chunk.payload_case() != v1::LodChunk::kHeader) {
      return "the first chunk must be the header, got payload " + std::to_string(chunk.payload_case());
    }
    switch (chunk.payload_case()) {
      case v1::LodChunk::kHeader: return header(chunk.header());
      case v1::LodChunk::kVertices: return vertices(chunk.vertices());
      case v1::LodChunk::kFaces: return faces(chunk.faces());
      case v1::LodChunk::kSkeleton: return skeleton(chunk.skeleton());
      case v1::LodChunk::PAYLOAD_NOT_SET: break;
    }
    return "a chunk without a payload";
  }

  // After the stream ended cleanly: everything the header announced arrived.
  std::string complete() const {
    const v1::LodHeader& h = mesh_.header;
    if (!has_header_) return "the stream ended without a header";
    if (vertices_ != h.vertex_count()) {
      return "the stream ended after " + std::to_string(vertices_) + " of " + std::to_string(h.vertex_count()) +
             " vertices";
    }
    if (faces_ != h.face_count()) {
      return "the stream ended after " + std::to_string(faces_) + " of " + std::to_string(h.face_count()) + " faces";
    }
    if (animation_space() && influences_ != h.influence_count()) {
      return "the vertex blocks carry " + std::to_string(influences_) + " influences, the header says " +
             std::to_string(h.influence_count());
    }
    if (animation_space() && !has_skeleton_) return "the stream ended without the skeleton";
    return "";
  }

 private:
  bool animation_space() const { return mesh_.header.form() == v1::GetLodRequest::FORM_ANIMATION_SPACE; }

  std::string header(const v1::LodHeader& h) {
    if (has_header_) return "a second header";
    if (h.form() != v1::GetLodRequest::FORM_ANIMATION_SPACE && h.form() != v1::GetLodRequest::FORM_POSED) {
      return "header.form: expected FORM_ANIMATION_SPACE or FORM_POSED, got " + std::to_string(h.form());
    }
    has_header_ = true;
    mesh_.header = h;
    const uint64_t vertices = std::min<uint64_t>(h.vertex_count(), kMaxReserve);
    const uint64_t influences = std::min<uint64_t>(h.influence_count(), kMaxReserve);
    mesh_.indices.reserve(3 * std::min<uint64_t>(h.face_count(), kMaxReserve));
    if (h.texture_coordinates()) mesh_.corner_uvs.reserve(6 * std::min<uint64_t>(h.face_count(), kMaxReserve));
    if (animation_space()) {
      mesh_.influence_offsets.reserve(vertices + 1);
      mesh_.influence_offsets.push_back(0);
      mesh_.bone_indices.reserve(influences);
      mesh_.animation_positions.reserve(4 * influences);
    } else {
      mesh_.positions.reserve(3 * vertices);
    }
    return "";
  }

  std::string vertices(const v1::VertexBlock& b) {
    const v1::LodHeader& h = mesh_.header;
    const std::string at = "vertex block at " + std::to_string(b.first_vertex());
    if (faces_ > 0 || has_skeleton_) return at + ": vertex blocks must come before faces and the skeleton";
    if (b.first_vertex() != vertices_) {
      return at + ": expected first_vertex " + std::to_string(vertices_) + " (blocks in order, contiguous)";
    }
    if (b.vertex_count() == 0 || uint64_t{b.first_vertex()} + b.vertex_count() > h.vertex_count()) {
      return at + ": vertex_count " + std::to_string(b.vertex_count()) + " does not fit in the header's " +
             std::to_string(h.vertex_count()) + " vertices";
    }
    const uint32_t n = b.vertex_count();
    if (!animation_space()) {
      const v1::PointArray& p = b.positions();
      if (p.point_count() != n || p.channel_count() != 3 || p.data().size() != size_t{n} * 12) {
        return at + ": positions must be " + std::to_string(n) + " × 3 float32 (" + std::to_string(size_t{n} * 12) +
               " bytes), got " + std::to_string(p.point_count()) + " × " + std::to_string(p.channel_count()) + " in " +
               std::to_string(p.data().size()) + " bytes";
      }
      append(mesh_.positions, p.data());
      vertices_ += n;
      return "";
    }
    if (b.influence_offsets().size() != (size_t{n} + 1) * 4) {
      return at + ": influence_offsets must be " + std::to_string(size_t{n} + 1) + " uint32, got " +
             std::to_string(b.influence_offsets().size()) + " bytes";
    }
    std::vector<uint32_t> offsets;
    append(offsets, b.influence_offsets());
    if (offsets.front() != 0) return at + ": influence_offsets must start at 0";
    for (size_t i = 1; i < offsets.size(); ++i) {
      if (offsets[i] < offsets[i - 1]) return at + ": influence_offsets decrease at entry " + std::to_string(i);
    }
    const uint64_t count = offsets.back();
    if (b.bone_indices().size() != count * 4 || b.animation_positions().size() != count * 16) {
      return at + ": " + std::to_string(count) + " influences need " + std::to_string(count * 4) +
             " bytes of bone_indices and " + std::to_string(count * 16) + " of animation_positions, got " +
             std::to_string(b.bone_indices().size()) + " and " + std::to_string(b.animation_positions().size());
    }
    // Geomorph data is all or nothing: the first block decides.
    const bool morph = !b.geomorph_delta().empty();
    if (vertices_ == 0) has_geomorph_ = morph;
    if (morph != has_geomorph_ || (morph && b.geomorph_delta().size() != count * 16)) {
      return at + ": geomorph_delta must be " + std::to_string(has_geomorph_ ? count * 16 : 0) + " bytes, got " +
             std::to_string(b.geomorph_delta().size());
    }
    if (influences_ + count > h.influence_count()) {
      return at + ": more influences than the header's " + std::to_string(h.influence_count());
    }
    const size_t first_bone = mesh_.bone_indices.size();
    append(mesh_.bone_indices, b.bone_indices());
    for (size_t k = first_bone; k < mesh_.bone_indices.size(); ++k) {
      if (mesh_.bone_indices[k] >= h.bone_count()) {
        return at + ": bone index " + std::to_string(mesh_.bone_indices[k]) + " is not below bone_count " +
               std::to_string(h.bone_count());
      }
    }
    for (size_t i = 1; i < offsets.size(); ++i) mesh_.influence_offsets.push_back(influences_ + offsets[i]);
    append(mesh_.animation_positions, b.animation_positions());
    if (morph) append(mesh_.geomorph_delta, b.geomorph_delta());
    influences_ += static_cast<uint32_t>(count);
    vertices_ += n;
    return "";
  }

  std::string faces(const v1::FaceBlock& b) {
    const v1::LodHeader& h = mesh_.header;
    const std::string at = "face block at " + std::to_string(b.first_face());
    if (vertices_ != h.vertex_count()) return at + ": faces must follow every vertex block";
    if (has_skeleton_) return at + ": faces must come before the skeleton";
    if (b.first_face() != faces_) {
      return at + ": expected first_face " + std::to_string(faces_) + " (blocks in order, contiguous)";
    }
    if (b.face_count() == 0 || uint64_t{b.first_face()} + b.face_count() > h.face_count()) {
      return at + ": face_count " + std::to_string(b.face_count()) + " does not fit in the header's " +
             std::to_string(h.face_count()) + " faces";
    }
    if (b.indices().size() != size_t{b.face_count()} * 12) {
      return at + ": indices must be " + std::to_string(size_t{b.face_count()} * 12) + " bytes, got " +
             std::to_string(b.indices().size());
    }
    const size_t uv_bytes = h.texture_coordinates() ? size_t{b.face_count()} * 24 : 0;
    if (b.texture_coordinates().size() != uv_bytes) {
      return at + ": texture_coordinates must be " + std::to_string(uv_bytes) + " bytes (header.texture_coordinates " +
             (h.texture_coordinates() ? "set" : "unset") + "), got " + std::to_string(b.texture_coordinates().size());
    }
    const size_t first = mesh_.indices.size();
    append(mesh_.indices, b.indices());
    for (size_t k = first; k < mesh_.indices.size(); ++k) {
      if (mesh_.indices[k] >= h.vertex_count()) {
        return at + ": vertex index " + std::to_string(mesh_.indices[k]) + " is not below vertex_count " +
               std::to_string(h.vertex_count());
      }
    }
    append(mesh_.corner_uvs, b.texture_coordinates());
    faces_ += b.face_count();
    return "";
  }

  std::string skeleton(const v1::Skeleton& s) {
    const v1::LodHeader& h = mesh_.header;
    if (!animation_space()) return "a skeleton in a FORM_POSED stream";
    if (has_skeleton_) return "a second skeleton";
    if (vertices_ != h.vertex_count() || faces_ != h.face_count()) {
      return "the skeleton must follow every vertex and face block";
    }
    if (static_cast<uint64_t>(s.parents_size()) != h.bone_count() ||
        s.rest_transforms().size() != size_t{h.bone_count()} * 48 ||
        (s.bone_names_size() != 0 && static_cast<uint64_t>(s.bone_names_size()) != h.bone_count())) {
      return "skeleton: expected " + std::to_string(h.bone_count()) + " parents, " +
             std::to_string(size_t{h.bone_count()} * 48) + " bytes of rest_transforms and no or as many names, got " +
             std::to_string(s.parents_size()) + ", " + std::to_string(s.rest_transforms().size()) + " and " +
             std::to_string(s.bone_names_size());
    }
    mesh_.skeleton = s;
    has_skeleton_ = true;
    return "";
  }

  LodMesh& mesh_;
  bool has_header_ = false;
  bool has_skeleton_ = false;
  bool has_geomorph_ = false;
  uint32_t vertices_ = 0;
  uint32_t faces_ = 0;
  uint32_t influences_ = 0;
};

}  // namespace

LodMesh Client::get_lod(const v1::GetLodRequest& request, std::chrono::milliseconds deadline) {
  grpc::ClientContext context;
  prepare(&context, deadline.count() > 0 ? deadline : options_.deadline);
  auto reader = lod_->GetLod(&context, request);
  LodMesh mesh;
  Assembler assembler(mesh);
  std::string problem;
  v1::LodChunk chunk;
  while (reader->Read(&chunk)) {
    mesh.chunk_count += 1;
    mesh.bytes_received += chunk.ByteSizeLong();
    problem = assembler.take(chunk);
    if (!problem.empty()) {
      context.TryCancel();  // the rest of the stream is of no use
      break;
    }
  }
  const grpc::Status status = reader->Finish();
  if (!problem.empty()) throw std::runtime_error("GetLod: " + problem);
  if (!status.ok()) throw RpcError("GetLod", status);
  if (problem = assembler.complete(); !problem.empty()) throw std::runtime_error("GetLod: " + problem);
  return mesh;
}

}  // namespace animspace
