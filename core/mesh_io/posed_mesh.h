// Writing a posed mesh for a render farm or a DCC tool: OBJ, PLY, glTF 2.0 (.gltf / .glb).
//
// Before writing, the triangles are reordered for the post-transform vertex cache and the
// vertices for fetch locality with meshoptimizer (Debian's libmeshoptimizer), which is what a
// renderer wants from a mesh it will draw many times; positions are float32.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::mesh_io {

// Texture coordinates, one row per vertex (or per face corner, see split_seams): u, v with v up
// (OBJ's convention; glTF's TEXCOORD_0 is written as 1 − v).
using UvMatrix = Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor>;

// A posed mesh, optionally with unit normals (#V × 3, or empty) and texture coordinates
// (#V × 2, or empty).
struct PosedMesh {
  PointMatrix points;
  FaceMatrix faces;
  PointMatrix normals;
  UvMatrix uvs;
};

// The mesh with a UV per vertex from UVs per face corner (`corner_uvs`: 3·#F × 2, row 3f + k the
// UV of corner k of face f): a vertex whose corners carry different UVs (a seam of a texture
// atlas) becomes one vertex per distinct UV, with the same position and normal. `mesh` must have
// no UVs yet (asserted), and corner_uvs 3·#F rows (asserted).
PosedMesh split_seams(const PosedMesh& mesh, const UvMatrix& corner_uvs);

// The vertex split behind split_seams, for any per-vertex data (a skinned character's weights):
// `faces` over the new vertices, `source[o]` the input vertex of new vertex o, `uvs` its UV.
// New vertices are numbered in order of first use by the faces; a vertex no face uses is dropped.
struct SeamSplit {
  FaceMatrix faces;
  std::vector<int32_t> source;
  UvMatrix uvs;
};
SeamSplit split_seam_vertices(const FaceMatrix& faces, Eigen::Index vertex_count, const UvMatrix& corner_uvs);

// The same mesh with faces in meshopt_optimizeVertexCache order and vertices in
// meshopt_optimizeVertexFetch order (normals follow their vertices). Vertices no face uses are
// dropped. The set of triangles (as point triples, each with its orientation) is unchanged.
PosedMesh optimise_for_rendering(const PosedMesh& mesh);

// The glTF 2.0 document (one mesh, one primitive: POSITION with min/max, NORMAL when present,
// uint32 indices) as .glb bytes or as .gltf JSON with an embedded base64 buffer.
// Errors: kInvalidArgument for an empty mesh, non-finite values, indices out of range or
// normals whose row count differs from the points'.
Result<std::string> serialize_glb(const PosedMesh& mesh);
Result<std::string> serialize_gltf(const PosedMesh& mesh);

// Writes `mesh` after optimise_for_rendering, choosing the format by the extension of `path`
// (.obj, .ply, .glb, .gltf, any case), atomically. Every format carries the normals when the mesh
// has them: OBJ as `vn` lines (corners `v//vn`), binary PLY as float properties nx ny nz after
// x y z, glTF as the NORMAL attribute; and the UVs when it has them: OBJ as `vt` lines (corners
// `v/vt` or `v/vt/vn`, one vt per vertex), PLY as float properties s t, glTF as TEXCOORD_0.
// Errors: kInvalidArgument for an unknown extension or a bad mesh (as above); kIo on failure.
Status write_posed_mesh(const std::filesystem::path& path, const PosedMesh& mesh);

}  // namespace animspace::mesh_io
