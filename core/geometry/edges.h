// Mesh connectivity: the undirected edges of a triangle mesh and its vertex adjacency.
//
// Users: eq. 4.4's edge term of animation-space fitting (Merry 2007 §4.1.3), the segmentation's
// region growing (§4.1.4), and the renderer's wireframe overlay. A degenerate face (two equal
// indices) contributes no edge between its equal corners.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "core/common/types.h"

namespace animspace::geometry {

// The unique undirected edges of `faces` (#F by 3, indices ≥ 0), each (a, b) with a < b, sorted
// ascending. #E ≤ 3·#F.
std::vector<std::pair<int32_t, int32_t>> unique_edges(const FaceMatrix& faces);

// Undirected vertex adjacency in compressed form: the neighbours of vertex i are
// neighbours[offsets[i] … offsets[i+1]−1], ascending, without repeats and without i itself.
struct Adjacency {
  std::vector<int32_t> offsets;     // #V + 1
  std::vector<int32_t> neighbours;  // 2·#E

  int32_t begin(int32_t i) const { return offsets[static_cast<size_t>(i)]; }
  int32_t end(int32_t i) const { return offsets[static_cast<size_t>(i) + 1]; }
  int32_t at(int32_t k) const { return neighbours[static_cast<size_t>(k)]; }
};

// The adjacency of `vertex_count` vertices (≥ every index in `faces` + 1, asserted) over the
// edges of `faces`. Vertices in no face have no neighbours.
Adjacency vertex_adjacency(int32_t vertex_count, const FaceMatrix& faces);

}  // namespace animspace::geometry
