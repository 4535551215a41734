#include "core/geometry/edges.h"

#include <algorithm>
#include <cassert>
#include <numeric>

namespace animspace::geometry {

std::vector<std::pair<int32_t, int32_t>> unique_edges(const FaceMatrix& faces) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  edges.reserve(static_cast<size_t>(faces.rows()) * 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int32_t a = faces(f, c), b = faces(f, (c + 1) % 3);
      if (a != b) edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

Adjacency vertex_adjacency(int32_t vertex_count, const FaceMatrix& faces) {
  assert(faces.size() == 0 || faces.maxCoeff() < vertex_count);
  const std::vector<std::pair<int32_t, int32_t>> edges = unique_edges(faces);
  Adjacency adjacency;
  adjacency.offsets.assign(static_cast<size_t>(vertex_count) + 1, 0);
  for (const auto& [a, b] : edges) {
    ++adjacency.offsets[static_cast<size_t>(a) + 1];
    ++adjacency.offsets[static_cast<size_t>(b) + 1];
  }
  std::partial_sum(adjacency.offsets.begin(), adjacency.offsets.end(), adjacency.offsets.begin());
  // The edges are sorted by (a, b), a < b, so vertex v meets its smaller neighbours (v as b, in
  // ascending a) before any edge (v, b), and those in ascending b: each list comes out ascending.
  adjacency.neighbours.resize(2 * edges.size());
  std::vector<int32_t> next(adjacency.offsets.begin(), adjacency.offsets.end() - 1);
  for (const auto& [a, b] : edges) {
    adjacency.neighbours[static_cast<size_t>(next[static_cast<size_t>(a)]++)] = b;
    adjacency.neighbours[static_cast<size_t>(next[static_cast<size_t>(b)]++)] = a;
  }
  return adjacency;
}

}  // namespace animspace::geometry
