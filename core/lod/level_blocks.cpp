#include "core/lod/level_blocks.h"

#include <algorithm>
#include <cassert>
#include <cstddef>

#include "core/common/bytes.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;

// Columns [begin, end) of a 4 × I matrix, 4 float32 each.
std::string pack_vectors(const as::InfluenceVectors& vectors, int begin, int end) {
  std::string out(static_cast<size_t>(end - begin) * kVectorBytes, '\0');
  size_t at = 0;
  for (int k = begin; k < end; ++k) {
    for (int r = 0; r < 4; ++r) {
      store_le(out, at, static_cast<float>(vectors(r, k)));
      at += sizeof(float);
    }
  }
  return out;
}

}  // namespace

LevelBlocks::LevelBlocks(const LodLevels& lods, int level, const LevelBlockOptions& options)
    : lods_(&lods), level_(level), options_(options) {
  assert(level >= 0 && level < lods.count());
  assert(options.max_block_vertices >= 1 && options.max_block_bytes >= 1);
  assert(!(options.geomorph && options.form == LevelForm::kPosed));
  const as::AnimationSpaceModel& model = this->level().model;
  if (options.form == LevelForm::kPosed) {
    assert(options.pose == nullptr || static_cast<int>(options.pose->size()) == model.bone_count());
    as::evaluate(model, options.pose ? *options.pose : model.skeleton.rest, posed_);
  } else if (options.geomorph && level + 1 < lods.count()) {
    // §7.3: morphing needs p^l and p^{l+1} on the same influences, so the aligned (union) set
    // replaces the level's own; p_j = 0 where only the coarser vertex has bone j.
    morph_ = lod::geomorph(lods, level);
  }
  assert(options.corner_uvs == nullptr || options.corner_uvs->rows() == 3 * model.faces.rows());
  options_.pose = nullptr;  // read once, above; the caller's pose need not outlive this
}

const as::InfluenceSets& LevelBlocks::influences() const {
  return morph_ ? morph_->aligned : level().model.influences;
}

const as::InfluenceVectors& LevelBlocks::positions() const {
  return morph_ ? morph_->position : level().model.positions;
}

uint32_t LevelBlocks::influence_count() const {
  return options_.form == LevelForm::kPosed ? 0 : static_cast<uint32_t>(influences().influence_count());
}

uint32_t LevelBlocks::block_vertex_count(uint32_t first) const {
  assert(first < vertex_count());
  const uint32_t limit = std::min(options_.max_block_vertices, vertex_count() - first);
  if (options_.form == LevelForm::kPosed) {
    return static_cast<uint32_t>(std::clamp<int64_t>(options_.max_block_bytes / kPosedVertexBytes, 1, limit));
  }
  // A vertex costs its influences: a rig with many bones per vertex gets fewer vertices per block.
  const as::InfluenceSets& sets = influences();
  const int64_t per_influence = kBoneBytes + kVectorBytes + (options_.geomorph ? kVectorBytes : 0);
  int64_t bytes = kOffsetBytes;  // the block's leading offset, 0
  uint32_t count = 0;
  while (count < limit) {
    const int v = static_cast<int>(first + count);
    const int64_t cost = kOffsetBytes + per_influence * (sets.end(v) - sets.begin(v));
    if (count > 0 && bytes + cost > options_.max_block_bytes) break;
    bytes += cost;
    ++count;
  }
  return count;
}

uint32_t LevelBlocks::faces_per_block() const {
  const int64_t per_face = kFaceBytes + (options_.corner_uvs ? kFaceUvBytes : 0);
  return static_cast<uint32_t>(std::clamp<int64_t>(options_.max_block_bytes / per_face, 1,
                                                   static_cast<int64_t>(options_.max_block_vertices)));
}

InfluenceBlock LevelBlocks::influence_block(uint32_t first, uint32_t count) const {
  assert(options_.form == LevelForm::kAnimationSpace);
  assert(first <= vertex_count() && count <= vertex_count() - first);
  const as::InfluenceSets& sets = influences();
  const int begin = sets.begin(static_cast<int>(first));
  const int end = sets.begin(static_cast<int>(first + count));
  InfluenceBlock block;
  block.influence_offsets.assign(size_t{count + 1} * kOffsetBytes, '\0');
  for (uint32_t v = 0; v <= count; ++v) {
    store_le(block.influence_offsets, size_t{v} * kOffsetBytes,
             static_cast<uint32_t>(sets.begin(static_cast<int>(first + v)) - begin));
  }
  block.bone_indices.assign(static_cast<size_t>(end - begin) * kBoneBytes, '\0');
  for (int k = begin; k < end; ++k) {
    store_le(block.bone_indices, static_cast<size_t>(k - begin) * kBoneBytes,
             static_cast<uint32_t>(sets.bones[static_cast<size_t>(k)]));
  }
  block.animation_positions = pack_vectors(positions(), begin, end);
  if (options_.geomorph) {
    // At the coarsest level nothing is coarser: Δp = 0.
    block.geomorph_delta = morph_ ? pack_vectors(morph_->delta, begin, end)
                                  : std::string(static_cast<size_t>(end - begin) * kVectorBytes, '\0');
  }
  return block;
}

std::string LevelBlocks::face_block(uint32_t first, uint32_t count) const {
  assert(first <= face_count() && count <= face_count() - first);
  const FaceMatrix& faces = level().model.faces;
  std::string out(size_t{count} * kFaceBytes, '\0');
  size_t at = 0;
  for (uint32_t f = first; f < first + count; ++f) {
    for (int c = 0; c < 3; ++c) {
      store_le(out, at, static_cast<uint32_t>(faces(f, c)));
      at += sizeof(uint32_t);
    }
  }
  return out;
}

std::string pack_rest_transforms(const as::Skeleton& skeleton) {
  std::string out(skeleton.rest.size() * 12 * sizeof(float), '\0');
  size_t at = 0;
  for (const as::Transform& G : skeleton.rest) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        store_le(out, at, static_cast<float>(G(r, c)));
        at += sizeof(float);
      }
    }
  }
  return out;
}

}  // namespace animspace::lod

namespace animspace::lod {

std::string LevelBlocks::face_uv_block(uint32_t first, uint32_t count) const {
  assert(options_.corner_uvs != nullptr);
  assert(first <= face_count() && count <= face_count() - first);
  const auto& uvs = *options_.corner_uvs;
  std::string out(size_t{count} * kFaceUvBytes, '\0');
  size_t at = 0;
  for (Eigen::Index r = Eigen::Index{first} * 3; r < (Eigen::Index{first} + count) * 3; ++r) {
    for (int k = 0; k < 2; ++k) {
      store_le(out, at, static_cast<float>(uvs(r, k)));
      at += sizeof(float);
    }
  }
  return out;
}

}  // namespace animspace::lod
