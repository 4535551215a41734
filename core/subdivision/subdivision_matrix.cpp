#include "core/subdivision/subdivision_matrix.h"

#include <algorithm>
#include <cassert>
#include <memory>
#include <utility>

#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>

namespace animspace::subdivision {

namespace {

namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

// One row of S as OpenSubdiv's PrimvarRefiner sees a primvar: it only ever clears a value and
// adds another scaled by a weight, so running it on rows of the identity yields the rows of the
// refinement matrix (the same trick Far::StencilTableFactory uses internally; done here because
// the limit tangents need the refiner's Limit on the same rows). Entries are unsorted and unique;
// rows are short (the support of one refined vertex), so a linear search beats a map.
struct SparseRow {
  std::vector<std::pair<int32_t, double>> entries;

  void Clear() { entries.clear(); }
  void AddWithWeight(const SparseRow& source, double weight) {
    if (weight == 0) return;
    for (const auto& [column, value] : source.entries) add(column, weight * value);
  }
  void add(int32_t column, double value) {
    for (auto& entry : entries) {
      if (entry.first == column) {
        entry.second += value;
        return;
      }
    }
    entries.emplace_back(column, value);
  }
};

SparseRows to_matrix(std::vector<SparseRow>& rows, int32_t columns) {
  std::vector<Eigen::Triplet<double, int32_t>> triplets;
  size_t count = 0;
  for (const SparseRow& row : rows) count += row.entries.size();
  triplets.reserve(count);
  for (size_t r = 0; r < rows.size(); ++r) {
    for (const auto& [column, value] : rows[r].entries) {
      triplets.emplace_back(static_cast<int32_t>(r), column, value);
    }
    rows[r].entries = {};
  }
  SparseRows matrix(static_cast<int32_t>(rows.size()), columns);
  matrix.setFromTriplets(triplets.begin(), triplets.end());
  matrix.makeCompressed();
  return matrix;
}

int64_t unique_edge_count(const PolygonTopology& topology) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  edges.reserve(topology.face_indices.size());
  size_t corner = 0;
  for (const int32_t size : topology.face_sizes) {
    for (int32_t k = 0; k < size; ++k) {
      const int32_t a = topology.face_indices[corner + static_cast<size_t>(k)];
      const int32_t b = topology.face_indices[corner + static_cast<size_t>((k + 1) % size)];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
    corner += static_cast<size_t>(size);
  }
  std::sort(edges.begin(), edges.end());
  return static_cast<int64_t>(std::unique(edges.begin(), edges.end()) - edges.begin());
}

Status validate_topology(const PolygonTopology& topology) {
  if (topology.face_sizes.empty()) {
    return make_error(ErrorCode::kInvalidArgument, "subdivision needs faces: the mesh has none (a point set)");
  }
  size_t corner = 0;
  for (size_t f = 0; f < topology.face_sizes.size(); ++f) {
    const int32_t size = topology.face_sizes[f];
    if (size < 3) {
      return make_error(ErrorCode::kInvalidArgument,
                        "face " + std::to_string(f) + ": expected at least 3 corners, got " + std::to_string(size));
    }
    if (corner + static_cast<size_t>(size) > topology.face_indices.size()) {
      return make_error(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + ": corner list ends early (" +
                                                         std::to_string(topology.face_indices.size()) + " indices)");
    }
    for (int32_t k = 0; k < size; ++k) {
      const int32_t v = topology.face_indices[corner + static_cast<size_t>(k)];
      if (v < 0 || v >= topology.vertex_count) {
        return make_error(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + ": vertex " + std::to_string(v) +
                                                           " outside [0, " + std::to_string(topology.vertex_count) +
                                                           ")");
      }
      for (int32_t m = 0; m < k; ++m) {
        if (topology.face_indices[corner + static_cast<size_t>(m)] == v) {
          return make_error(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + ": repeats vertex " +
                                                             std::to_string(v) + " (a degenerate face)");
        }
      }
    }
    corner += static_cast<size_t>(size);
  }
  if (corner != topology.face_indices.size()) {
    return make_error(ErrorCode::kInvalidArgument, "face_indices: expected " + std::to_string(corner) +
                                                       " indices (the sum of face_sizes), got " +
                                                       std::to_string(topology.face_indices.size()));
  }
  return {};
}

}  // namespace

const char* scheme_name(Scheme scheme) {
  switch (scheme) {
    case Scheme::kAuto: return "auto";
    case Scheme::kLoop: return "loop";
    case Scheme::kCatmullClark: return "catmull-clark";
  }
  return "auto";
}

Result<Scheme> parse_scheme(const std::string& name, const std::string& field) {
  if (name == "auto") return Scheme::kAuto;
  if (name == "loop") return Scheme::kLoop;
  if (name == "catmull-clark" || name == "catmark") return Scheme::kCatmullClark;
  return make_error(ErrorCode::kInvalidArgument,
                    field + ": expected auto, loop or catmull-clark, got '" + name + "'");
}

PolygonTopology triangle_topology(const FaceMatrix& faces, int32_t vertex_count) {
  PolygonTopology topology;
  topology.vertex_count = vertex_count;
  topology.face_sizes.assign(static_cast<size_t>(faces.rows()), 3);
  topology.face_indices.assign(faces.data(), faces.data() + faces.size());  // row-major: corners in order
  return topology;
}

FaceMatrix triangulate(const PolygonTopology& topology) {
  int64_t triangles = 0;
  for (const int32_t size : topology.face_sizes) triangles += size - 2;
  FaceMatrix faces(triangles, 3);
  Eigen::Index row = 0;
  size_t corner = 0;
  for (const int32_t size : topology.face_sizes) {
    const int32_t* f = topology.face_indices.data() + corner;
    for (int32_t k = 1; k + 1 < size; ++k) faces.row(row++) << f[0], f[k], f[k + 1];
    corner += static_cast<size_t>(size);
  }
  return faces;
}

RefinedSize refined_size(const PolygonTopology& topology, Scheme resolved, int levels) {
  assert(resolved != Scheme::kAuto);
  RefinedSize size{topology.vertex_count, unique_edge_count(topology), topology.face_count()};
  int64_t corners = static_cast<int64_t>(topology.face_indices.size());
  for (int l = 0; l < levels; ++l) {
    RefinedSize next;
    if (resolved == Scheme::kLoop) {
      next = {size.vertices + size.edges, 2 * size.edges + 3 * size.faces, 4 * size.faces};
    } else {
      next = {size.vertices + size.edges + size.faces, 2 * size.edges + corners, corners};
    }
    size = next;
    corners = resolved == Scheme::kLoop ? 3 * size.faces : 4 * size.faces;
  }
  return size;
}

Result<SubdivisionMatrices> subdivision_matrices(const PolygonTopology& topology, const SubdivisionOptions& options) {
  // 1. Check the request and the mesh; resolve the scheme from the face sizes.
  if (options.levels < 1 || options.levels > kMaxLevels) {
    return make_error(ErrorCode::kInvalidArgument, "levels: expected 1 … " + std::to_string(kMaxLevels) + ", got " +
                                                       std::to_string(options.levels));
  }
  if (auto valid = validate_topology(topology); !valid.ok()) return valid.error();
  const bool all_triangles =
      std::all_of(topology.face_sizes.begin(), topology.face_sizes.end(), [](int32_t n) { return n == 3; });
  Scheme scheme = options.scheme;
  if (scheme == Scheme::kAuto) scheme = all_triangles ? Scheme::kLoop : Scheme::kCatmullClark;
  if (scheme == Scheme::kLoop && !all_triangles) {
    const auto f = std::find_if(topology.face_sizes.begin(), topology.face_sizes.end(), [](int32_t n) { return n != 3; });
    return make_error(ErrorCode::kInvalidArgument,
                      "Loop subdivision needs triangles: face " + std::to_string(f - topology.face_sizes.begin()) +
                          " has " + std::to_string(*f) + " corners (use catmull-clark)");
  }

  // 2. Refuse an output over the limit before building anything of its size.
  const RefinedSize size = refined_size(topology, scheme, options.levels);
  if (size.vertices > options.max_vertices) {
    return make_error(ErrorCode::kResourceExhausted,
                      "levels: " + std::to_string(options.levels) + " steps of " + scheme_name(scheme) +
                          " would make " + std::to_string(size.vertices) + " vertices, over the limit of " +
                          std::to_string(options.max_vertices) + "; use fewer levels");
  }

  // 3. OpenSubdiv's topology, refined uniformly; the last level keeps its full topology because
  // the limit tangents need each refined vertex's neighbourhood.
  Far::TopologyDescriptor descriptor;
  descriptor.numVertices = topology.vertex_count;
  descriptor.numFaces = static_cast<int>(topology.face_count());
  descriptor.numVertsPerFace = topology.face_sizes.data();
  descriptor.vertIndicesPerFace = topology.face_indices.data();
  Sdc::Options sdc;
  sdc.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
  using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
  const Factory::Options factory_options(scheme == Scheme::kLoop ? Sdc::SCHEME_LOOP : Sdc::SCHEME_CATMARK, sdc);
  std::unique_ptr<Far::TopologyRefiner> refiner(Factory::Create(descriptor, factory_options));
  if (!refiner) return make_error(ErrorCode::kInternal, "OpenSubdiv refused the mesh's topology");
  Far::TopologyRefiner::UniformOptions uniform(options.levels);
  uniform.fullTopologyInLastLevel = true;
  refiner->RefineUniform(uniform);

  // 4. The rows: the identity pushed through every level (S), then the limit tangents of the
  // finest level's vertices, composed with S by the same refiner.
  const Far::PrimvarRefinerReal<double> primvar(*refiner);
  std::vector<SparseRow> rows(static_cast<size_t>(topology.vertex_count));
  for (int32_t v = 0; v < topology.vertex_count; ++v) rows[static_cast<size_t>(v)].entries.emplace_back(v, 1.0);
  for (int level = 1; level <= options.levels; ++level) {
    std::vector<SparseRow> next(static_cast<size_t>(refiner->GetLevel(level).GetNumVertices()));
    primvar.Interpolate(level, rows, next);
    rows = std::move(next);
  }
  SubdivisionMatrices out;
  out.scheme = scheme;
  out.levels = options.levels;
  if (options.tangents) {
    std::vector<SparseRow> limit(rows.size()), du(rows.size()), dv(rows.size());
    primvar.Limit(rows, limit, du, dv);
    out.tangent_u = to_matrix(du, topology.vertex_count);
    out.tangent_v = to_matrix(dv, topology.vertex_count);
  }
  out.S = to_matrix(rows, topology.vertex_count);
  assert(out.S.rows() == size.vertices);

  // 5. The finest level's faces.
  const Far::TopologyLevel& finest = refiner->GetLevel(options.levels);
  out.refined.vertex_count = finest.GetNumVertices();
  out.refined.face_sizes.reserve(static_cast<size_t>(finest.GetNumFaces()));
  for (int f = 0; f < finest.GetNumFaces(); ++f) {
    const Far::ConstIndexArray corners = finest.GetFaceVertices(f);
    out.refined.face_sizes.push_back(corners.size());
    for (int k = 0; k < corners.size(); ++k) out.refined.face_indices.push_back(corners[k]);
  }
  return out;
}

}  // namespace animspace::subdivision
