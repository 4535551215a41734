#include "core/lod/progressive_mesh.h"

#include <cassert>

namespace animspace::lod {

namespace as = animation_space;

MeshState MeshState::from_model(const as::AnimationSpaceModel& model) {
  MeshState state;
  const int V = model.vertex_count();
  state.vertex_alive_.assign(static_cast<size_t>(V), 1);
  state.face_alive_.assign(static_cast<size_t>(model.faces.rows()), 1);
  state.vertices_.reserve(static_cast<size_t>(V));
  for (int v = 0; v < V; ++v) state.vertices_.push_back(vertex_state(model, v));
  state.faces_ = model.faces;
  state.live_vertices_ = V;
  state.live_faces_ = static_cast<int>(model.faces.rows());
  state.live_influences_ = model.influences.influence_count();
  return state;
}

void MeshState::apply(const Simplification& step) {
  VertexState& vertex = vertices_[static_cast<size_t>(step.vertex)];
  assert(vertex_alive(step.vertex));
  if (step.kind == SimplificationKind::kInfluenceRemoval) {
    live_influences_ += step.after.influence_count() - vertex.influence_count();
    vertex = step.after;
    return;
  }
  for (const int32_t f : step.removed_faces) {
    assert(face_alive(f));
    face_alive_[static_cast<size_t>(f)] = 0;
    --live_faces_;
  }
  for (const int32_t f : step.moved_faces) {
    for (int c = 0; c < 3; ++c) {
      if (faces_(f, c) == step.vertex) faces_(f, c) = step.target;
    }
  }
  live_influences_ -= vertex.influence_count();
  vertex_alive_[static_cast<size_t>(step.vertex)] = 0;
  vertex = VertexState{};
  --live_vertices_;
}

void MeshState::undo(const Simplification& step) {
  VertexState& vertex = vertices_[static_cast<size_t>(step.vertex)];
  if (step.kind == SimplificationKind::kInfluenceRemoval) {
    assert(vertex_alive(step.vertex));
    live_influences_ += step.before.influence_count() - vertex.influence_count();
    vertex = step.before;
    return;
  }
  // Vertex split: u comes back with the state it had, takes its corners back from v, and the
  // faces on edge uv reappear.
  assert(!vertex_alive(step.vertex));
  vertex = step.before;
  vertex_alive_[static_cast<size_t>(step.vertex)] = 1;
  ++live_vertices_;
  live_influences_ += vertex.influence_count();
  for (const int32_t f : step.moved_faces) {
    for (int c = 0; c < 3; ++c) {
      if (faces_(f, c) == step.target) faces_(f, c) = step.vertex;
    }
  }
  for (size_t k = 0; k < step.removed_faces.size(); ++k) {
    const int32_t f = step.removed_faces[k];
    faces_.row(f) = step.removed_face_corners.row(static_cast<Eigen::Index>(k));
    face_alive_[static_cast<size_t>(f)] = 1;
    ++live_faces_;
  }
}

as::AnimationSpaceModel MeshState::to_model(const as::Skeleton& skeleton, std::vector<int32_t>* vertex_ids,
                                            std::vector<int32_t>* face_ids) const {
  as::AnimationSpaceModel model;
  model.skeleton = skeleton;
  const int V = static_cast<int>(vertices_.size());
  std::vector<int32_t> compact(static_cast<size_t>(V), -1);
  std::vector<int32_t> ids;
  ids.reserve(static_cast<size_t>(live_vertices_));
  std::vector<VertexState> live;
  live.reserve(static_cast<size_t>(live_vertices_));
  for (int v = 0; v < V; ++v) {
    if (!vertex_alive(v)) continue;
    compact[static_cast<size_t>(v)] = static_cast<int32_t>(ids.size());
    ids.push_back(v);
    live.push_back(vertex(v));
  }
  model.influences.offsets.assign(live.size() + 1, 0);  // as many vertices as states
  set_vertex_states(model, live);
  assert(model.influences.influence_count() == live_influences_);
  std::vector<int32_t> faces;
  for (int f = 0; f < static_cast<int>(faces_.rows()); ++f) {
    if (face_alive(f)) faces.push_back(f);
  }
  model.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t k = 0; k < faces.size(); ++k) {
    for (int c = 0; c < 3; ++c) {
      model.faces(static_cast<Eigen::Index>(k), c) = compact[static_cast<size_t>(faces_(faces[k], c))];
    }
  }
  if (vertex_ids) *vertex_ids = std::move(ids);
  if (face_ids) *face_ids = std::move(faces);
  return model;
}

MeshState ProgressiveMesh::base_state() const {
  MeshState state;
  state.vertex_alive_.assign(static_cast<size_t>(input_vertex_count), 0);
  state.face_alive_.assign(static_cast<size_t>(input_face_count), 0);
  state.vertices_.resize(static_cast<size_t>(input_vertex_count));
  state.faces_ = FaceMatrix::Constant(input_face_count, 3, -1);
  for (size_t k = 0; k < base_vertex_ids.size(); ++k) {
    const int32_t v = base_vertex_ids[k];
    state.vertex_alive_[static_cast<size_t>(v)] = 1;
    state.vertices_[static_cast<size_t>(v)] = vertex_state(base, static_cast<int>(k));
  }
  for (size_t k = 0; k < base_face_ids.size(); ++k) {
    const int32_t f = base_face_ids[k];
    state.face_alive_[static_cast<size_t>(f)] = 1;
    for (int c = 0; c < 3; ++c) {
      state.faces_(f, c) = base_vertex_ids[static_cast<size_t>(base.faces(static_cast<Eigen::Index>(k), c))];
    }
  }
  state.live_vertices_ = static_cast<int>(base_vertex_ids.size());
  state.live_faces_ = static_cast<int>(base_face_ids.size());
  state.live_influences_ = base.influences.influence_count();
  return state;
}

MeshState ProgressiveMesh::state_after(size_t step_count) const {
  assert(step_count <= steps.size());
  MeshState state = base_state();
  for (size_t k = steps.size(); k > step_count; --k) state.undo(steps[k - 1]);
  return state;
}

}  // namespace animspace::lod
