// One level of detail cut into blocks of little-endian bytes, for a consumer that receives a level
// a block at a time (LodService's stream; Merry 2007 §7.3): the arrays are laid out once per
// request — the level posed at a pose, its animation-space form, or that form on the influences a
// geomorph to the next coarser level needs — and each block is a copy of a range of them.
//
// Layouts (the ones lod.proto's VertexBlock, FaceBlock and Skeleton document), all little-endian:
//   influence offsets  count + 1 uint32, the block's first vertex at 0 (compressed rows)
//   bone indices       one uint32 per influence
//   4-vectors          p_j or Δp, 4 float32 per influence: float32 is the wire precision of every
//                      position the API sends; the core keeps doubles for simplification (§6)
//   faces              3 uint32 per face
//   corner UVs         6 float32 per face: (u, v) of corners 0, 1, 2 (a texture atlas's)
//   rest transforms    Ĝ_j as the top three rows of each 4 × 4, row-major, 12 float32 per bone
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/animspace/model.h"
#include "core/common/types.h"
#include "core/lod/levels.h"

namespace animspace::lod {

// Bytes per element in a block.
inline constexpr int64_t kOffsetBytes = 4;       // a CSR offset
inline constexpr int64_t kBoneBytes = 4;         // a bone index
inline constexpr int64_t kVectorBytes = 16;      // a 4-vector, p_j or Δp
inline constexpr int64_t kPosedVertexBytes = 12;  // a posed vertex
inline constexpr int64_t kFaceBytes = 12;        // a face
inline constexpr int64_t kFaceUvBytes = 24;      // a face's corner UVs

enum class LevelForm {
  kAnimationSpace,  // influences and p_j: the consumer poses the mesh itself (v = Σ G_j p_j)
  kPosed,           // positions at one pose
};

struct LevelBlockOptions {
  LevelForm form = LevelForm::kAnimationSpace;
  // kPosed: the pose G_j (one per bone of the level), or null for the rest pose Ĝ_j.
  const animation_space::TransformList* pose = nullptr;
  // kAnimationSpace only (asserted): carry Δp to the next coarser level on the aligned influences
  // (lod::geomorph); at the coarsest level Δp = 0 on the level's own influences.
  bool geomorph = false;
  // Per-corner UVs of the level's faces (3·#F × 2, corner c of face f in row 3f + c; asserted),
  // or null: face blocks then also cost kFaceUvBytes per face. Read by face_uv_block, so they
  // must outlive the result.
  const Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>* corner_uvs = nullptr;
  uint32_t max_block_vertices = 65536;  // ≥ 1
  // Payload bytes per block, ≥ 1: a vertex block holds as many vertices as fit (at least one,
  // whatever its influences cost); a face block as many faces as fit, at most max_block_vertices.
  int64_t max_block_bytes = int64_t{4} << 20;
};

// The byte arrays of one vertex block of the animation-space form.
struct InfluenceBlock {
  std::string influence_offsets;
  std::string bone_indices;
  std::string animation_positions;  // p_j
  std::string geomorph_delta;       // Δp; empty unless LevelBlockOptions::geomorph
};

class LevelBlocks {
 public:
  // Lays out level `level` of `lods` (asserted in range) as `options` say: kPosed evaluates the
  // whole level at the pose once (eq. 3.1; the blocks are then plain copies), kAnimationSpace with
  // geomorph builds the aligned set once (lod::geomorph). `lods` must outlive the result.
  LevelBlocks(const LodLevels& lods, int level, const LevelBlockOptions& options);

  LevelForm form() const { return options_.form; }
  bool geomorph() const { return options_.geomorph; }
  const LodLevel& level() const { return lods_->levels[static_cast<size_t>(level_)]; }
  uint32_t vertex_count() const { return static_cast<uint32_t>(level().model.vertex_count()); }
  uint32_t face_count() const { return static_cast<uint32_t>(level().model.faces.rows()); }
  // Influences the vertex blocks carry: the aligned set with a geomorph below the coarsest level,
  // else the level's own; 0 for kPosed.
  uint32_t influence_count() const;

  // How many vertices the block starting at vertex `first` (< vertex_count()) carries: at most
  // max_block_vertices and the vertices left, and as many as fit in max_block_bytes by their
  // influence counts (a posed vertex costs kPosedVertexBytes; an animation-space one
  // kOffsetBytes and kBoneBytes + kVectorBytes per influence, another kVectorBytes with a geomorph,
  // plus the block's leading offset); always at least one.
  uint32_t block_vertex_count(uint32_t first) const;
  // Faces per face block: max_block_bytes / kFaceBytes (kFaceBytes + kFaceUvBytes with corner
  // UVs), within [1, max_block_vertices].
  uint32_t faces_per_block() const;

  // kPosed: the level at the pose, #V × 3 float32 (rows [first, first + count) are one block).
  const PointMatrix& posed() const { return posed_; }
  // kAnimationSpace: vertices [first, first + count) (asserted within the level).
  InfluenceBlock influence_block(uint32_t first, uint32_t count) const;
  // Faces [first, first + count) (asserted within the level).
  std::string face_block(uint32_t first, uint32_t count) const;
  bool has_corner_uvs() const { return options_.corner_uvs != nullptr; }
  // The corner UVs of faces [first, first + count), as float32 (asserted: has_corner_uvs()).
  std::string face_uv_block(uint32_t first, uint32_t count) const;

 private:
  const animation_space::InfluenceSets& influences() const;
  const animation_space::InfluenceVectors& positions() const;

  const LodLevels* lods_;
  int level_;
  LevelBlockOptions options_;
  PointMatrix posed_;              // kPosed
  std::optional<Geomorph> morph_;  // geomorph below the coarsest level
};

// Ĝ_j of every bone, in the rest-transform layout above (what SkeletonPose.transforms reads).
std::string pack_rest_transforms(const animation_space::Skeleton& skeleton);

}  // namespace animspace::lod
