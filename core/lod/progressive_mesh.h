// A progressive mesh in animation space (Hoppe 1996; Merry 2007 §6.1, §6.3.1): the simplest mesh
// the simplifier reached (the base mesh) and the records that refine it back, one by one, to the
// input model exactly.
//
// Two kinds of simplification share one sequence, ordered by cost (§6.3.1):
//   - a half-edge collapse u → v (Fig. 6.4): vertex u disappears, the faces on edge uv vanish and
//     u's other faces take v in its place; v keeps its position (no new vertices, §6.2.1);
//   - an influence removal (§6.3): one vertex loses one bone and moves by the correction s.
// Each record keeps the state it overwrote, so it can be undone (a vertex split or an influence
// split) as well as applied. Vertex and face numbers are those of the input model throughout.
#pragma once

#include <cstdint>
#include <vector>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/lod/vertex_state.h"

namespace animspace::lod {

enum class SimplificationKind : uint8_t { kEdgeCollapse = 0, kInfluenceRemoval = 1 };

struct Simplification {
  SimplificationKind kind = SimplificationKind::kEdgeCollapse;
  // Memoryless cost (§6.2.1, §6.3.1): the largest L2,2 deviation this step introduces between the
  // previous and the new surface (edge collapse), or ‖s‖₂,₂ (influence removal). Model units.
  double cost = 0;
  // Edge collapse: the removed vertex u. Influence removal: the vertex that lost a bone.
  int32_t vertex = -1;
  // Edge collapse: the kept vertex v. Influence removal: the bone removed.
  int32_t target = -1;
  // Edge collapse only: the faces that vanish, with their corners at that moment, and the faces
  // whose corner u became v.
  std::vector<int32_t> removed_faces;
  FaceMatrix removed_face_corners;
  std::vector<int32_t> moved_faces;
  // The vertex's state before the step (edge collapse: u's; influence removal: the vertex's) and,
  // for an influence removal, after it.
  VertexState before;
  VertexState after;
};

// The mesh at some point of the sequence, in the input's numbering: which vertices and faces are
// alive, every live vertex's state, every live face's current corners.
class MeshState {
 public:
  // The input model itself (validate it first).
  static MeshState from_model(const animation_space::AnimationSpaceModel& model);

  void apply(const Simplification& step);  // simplify (asserts the step fits this state)
  void undo(const Simplification& step);   // refine: the inverse of apply

  int live_vertex_count() const { return live_vertices_; }
  int live_face_count() const { return live_faces_; }
  int live_influence_count() const { return live_influences_; }
  bool vertex_alive(int v) const { return vertex_alive_[static_cast<size_t>(v)] != 0; }
  bool face_alive(int f) const { return face_alive_[static_cast<size_t>(f)] != 0; }
  const VertexState& vertex(int v) const { return vertices_[static_cast<size_t>(v)]; }
  const FaceMatrix& faces() const { return faces_; }  // input face count rows; dead rows stale

  // The live part as a model of its own (vertices and faces in input order), and for each of its
  // vertices the input vertex it is.
  animation_space::AnimationSpaceModel to_model(const animation_space::Skeleton& skeleton,
                                                std::vector<int32_t>* vertex_ids = nullptr,
                                                std::vector<int32_t>* face_ids = nullptr) const;

 private:
  friend struct ProgressiveMesh;
  std::vector<uint8_t> vertex_alive_;
  std::vector<uint8_t> face_alive_;
  std::vector<VertexState> vertices_;
  FaceMatrix faces_;
  int live_vertices_ = 0;
  int live_faces_ = 0;
  int live_influences_ = 0;
};

struct ProgressiveMesh {
  animation_space::Skeleton skeleton;
  int input_vertex_count = 0;
  int input_face_count = 0;
  // The base mesh: the model after every step, and the input numbers of its vertices and faces.
  animation_space::AnimationSpaceModel base;
  std::vector<int32_t> base_vertex_ids;
  std::vector<int32_t> base_face_ids;
  // Simplification order (cheapest first); refinement undoes them from the back.
  std::vector<Simplification> steps;

  // The base mesh spread out over the input's numbering (nothing of the input is used).
  MeshState base_state() const;
  // The state after the first `step_count` steps, by refining the base mesh.
  MeshState state_after(size_t step_count) const;
};

}  // namespace animspace::lod
