// One vertex of an animation-space model while it is being simplified (Merry 2007 ch. 6).
//
// The simplifier and the progressive mesh handle vertices one at a time — an edge collapse
// removes one, an influence removal (§6.3) rewrites one — so a vertex is kept as its own small
// sparse record rather than as a slice of the model's compressed rows.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"

namespace animspace::lod {

struct VertexState {
  std::vector<int32_t> bones;                  // strictly increasing
  animation_space::InfluenceVectors position;  // 4 × bones.size(), weight Σ p̲_j = 1
  // Tangent plane (§3.5): both empty, or both 4 × bones.size() with weight 0.
  animation_space::InfluenceVectors tangent_s;
  animation_space::InfluenceVectors tangent_t;

  int influence_count() const { return static_cast<int>(bones.size()); }
  bool has_tangents() const { return tangent_s.cols() > 0; }
  friend bool operator==(const VertexState& a, const VertexState& b) {
    return a.bones == b.bones && a.position == b.position && a.tangent_s == b.tangent_s && a.tangent_t == b.tangent_t;
  }
};

// y += C p for a p given on `bones` as one 4-vector per bone (the columns of `vectors`): the
// normalised-animation-space image (y = C p, C = P^½, §3.3.2) of a vertex or of a move, where
// L2,2 inner products are dot products.
template <typename Vectors>
void add_normalised(const Eigen::MatrixXd& C, const int32_t* bones, const Vectors& vectors,
                    Eigen::Ref<Eigen::VectorXd> y) {
  for (Eigen::Index j = 0; j < vectors.cols(); ++j) y.noalias() += C.middleCols(4 * bones[j], 4) * vectors.col(j);
}

// Vertex `vertex` of `model` (asserted in range).
VertexState vertex_state(const animation_space::AnimationSpaceModel& model, int vertex);

// The inverse: `model`'s influences, positions and tangents rebuilt from one state per vertex
// (asserted: as many states as vertices, all with tangents or none). Skeleton and faces stay.
void set_vertex_states(animation_space::AnimationSpaceModel& model, const std::vector<VertexState>& states);

}  // namespace animspace::lod
