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

}  // namespace animspace::lod
