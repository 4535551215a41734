// The subdivision matrix S of a control mesh (Merry 2007 §4.2; Umlauf 2005): after k uniform
// refinement steps every vertex is an affine combination of the control vertices, V' = S V
// (rows are vertices here; the thesis writes V' = V S with vertices as columns), and S depends on
// the connectivity alone. Built by OpenSubdiv 3.5's Far (TopologyRefiner, PrimvarRefiner), in
// double precision, for Loop (Loop 1987) and Catmull–Clark (Catmull & Clark 1978) as Pixar's
// RenderMan and OpenSubdiv define them: smooth boundary curves with their corners kept
// (VTX_BOUNDARY_EDGE_AND_CORNER), no creases.
//
// Alongside S, the limit tangents of the refined vertices, U and W (rows sum to 0): the limit
// surface of the refined mesh at refined vertex i has tangents ∂u = Σ_c U_ic v_c and
// ∂v = Σ_c W_ic v_c, so a model posed as V = G P (eq. 3.1) gets its limit normal ∂u × ∂v from the
// animation-space tangents P U and P W in every pose — tangent planes (§3.5) that are exact, not
// fitted (§4.3.1). A refined vertex where OpenSubdiv takes no limit (an isolated vertex, or one
// whose neighbourhood is not a manifold fan) gets zero tangent rows, so its posed normal is 0
// (model.h's degenerate case).
//
// No stencil weight is written here: the rows are OpenSubdiv's own, obtained by running its
// PrimvarRefiner on rows of the identity instead of on points (each "primvar" is a sparse row).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/SparseCore>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::subdivision {

// kAuto: Loop when every face is a triangle, else Catmull–Clark (defined for any polygon, so a
// mixed triangle/quad mesh is refined by Catmull–Clark as a whole; its first step makes every
// face a quad). Loop on a mesh with a non-triangle is refused.
enum class Scheme { kAuto, kLoop, kCatmullClark };

const char* scheme_name(Scheme scheme);  // "auto", "loop", "catmull-clark"
// "auto", "loop", "catmull-clark" (also "catmark"). Errors: kInvalidArgument naming `field`.
Result<Scheme> parse_scheme(const std::string& name, const std::string& field);

// A polygon mesh's connectivity: face f has face_sizes[f] ≥ 3 corners, listed counter-clockwise
// (seen from outside) back to back in face_indices.
struct PolygonTopology {
  int32_t vertex_count = 0;
  std::vector<int32_t> face_sizes;
  std::vector<int32_t> face_indices;

  int64_t face_count() const { return static_cast<int64_t>(face_sizes.size()); }
};

// The triangles of `faces` (#F by 3) over `vertex_count` vertices.
PolygonTopology triangle_topology(const FaceMatrix& faces, int32_t vertex_count);

// Each polygon split into triangles as a fan from its first corner (a quad into two); the refined
// surface's vertices are unchanged by this, only how a renderer joins them.
FaceMatrix triangulate(const PolygonTopology& topology);

inline constexpr int kMaxLevels = 6;
inline constexpr int64_t kDefaultMaxVertices = int64_t{1} << 22;  // 4,194,304

struct SubdivisionOptions {
  int levels = 1;  // uniform refinement steps, 1 … kMaxLevels
  Scheme scheme = Scheme::kAuto;
  // Refuse (kResourceExhausted) when level k would have more vertices than this.
  int64_t max_vertices = kDefaultMaxVertices;
  bool tangents = true;  // also U and W
};

// Sizes after k steps, counted from the connectivity without refining (Loop: V' = V + E,
// E' = 2E + 3F, F' = 4F; Catmull–Clark: V' = V + E + F, E' = 2E + Σ n_f, F' = Σ n_f).
struct RefinedSize {
  int64_t vertices = 0;
  int64_t edges = 0;
  int64_t faces = 0;
};
RefinedSize refined_size(const PolygonTopology& topology, Scheme resolved, int levels);

// Row-major sparse, #V_k by #V_0 (column c: control vertex c).
using SparseRows = Eigen::SparseMatrix<double, Eigen::RowMajor, int32_t>;

struct SubdivisionMatrices {
  Scheme scheme = Scheme::kLoop;  // the one used (never kAuto)
  int levels = 0;
  SparseRows S;          // refined vertices; each row sums to 1
  SparseRows tangent_u;  // limit ∂u at each refined vertex; rows sum to 0 (empty without tangents)
  SparseRows tangent_v;  // limit ∂v; ∂u × ∂v points the way the faces' normals do
  PolygonTopology refined;  // level k's faces (triangles for Loop, quads for Catmull–Clark)
};

// Errors: kInvalidArgument (levels outside 1 … kMaxLevels naming "levels"; a face with fewer
// than 3 corners, an index outside [0, V) or a repeated corner, naming the face; Loop asked for
// a mesh with a non-triangle; no faces), kResourceExhausted (more than max_vertices at level k,
// with both counts), kInternal (OpenSubdiv refused the topology).
Result<SubdivisionMatrices> subdivision_matrices(const PolygonTopology& topology, const SubdivisionOptions& options);

}  // namespace animspace::subdivision
