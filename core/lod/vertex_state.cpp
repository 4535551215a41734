#include "core/lod/vertex_state.h"

#include <cassert>

namespace animspace::lod {

VertexState vertex_state(const animation_space::AnimationSpaceModel& model, int vertex) {
  assert(vertex >= 0 && vertex < model.vertex_count());
  const int begin = model.influences.begin(vertex);
  const int count = model.influences.end(vertex) - begin;
  VertexState state;
  state.bones.assign(model.influences.bones.begin() + begin, model.influences.bones.begin() + begin + count);
  state.position = model.positions.middleCols(begin, count);
  if (model.has_tangents()) {
    state.tangent_s = model.tangent_s.middleCols(begin, count);
    state.tangent_t = model.tangent_t.middleCols(begin, count);
  }
  return state;
}

void set_vertex_states(animation_space::AnimationSpaceModel& model, const std::vector<VertexState>& states) {
  assert(static_cast<int>(states.size()) == model.vertex_count());
  const bool tangents = !states.empty() && states.front().has_tangents();
  int total = 0;
  for (const VertexState& s : states) {
    assert(s.has_tangents() == tangents);
    total += s.influence_count();
  }
  model.influences.offsets.assign(1, 0);
  model.influences.bones.clear();
  model.influences.bones.reserve(static_cast<size_t>(total));
  model.positions.resize(4, total);
  model.tangent_s.resize(4, tangents ? total : 0);
  model.tangent_t.resize(4, tangents ? total : 0);
  int column = 0;
  for (const VertexState& s : states) {
    const int k = s.influence_count();
    model.influences.bones.insert(model.influences.bones.end(), s.bones.begin(), s.bones.end());
    model.positions.middleCols(column, k) = s.position;
    if (tangents) {
      model.tangent_s.middleCols(column, k) = s.tangent_s;
      model.tangent_t.middleCols(column, k) = s.tangent_t;
    }
    column += k;
    model.influences.offsets.push_back(column);
  }
}

}  // namespace animspace::lod
