// Triangle meshes from and to OBJ, PLY and OFF files.
//
// - OBJ: Wavefront "Object Files (.obj)", Advanced Visualizer manual appendix B1. Parsed here by
//   a strict parser of our own: only `v` and `f` matter to a TriangleMesh, and every error names
//   `file:line:` with what was expected and what was found.
// - PLY: Turk, "The PLY Polygon File Format" (1994); OFF: the Geomview / Princeton Shape
//   Benchmark object file format. Read through OpenMesh 9's IO (ASCII and binary variants).
//
// Writing is our own for all three (OBJ and OFF as text with the shortest decimals that read
// back to the same float32, PLY as binary little endian), so V round-trips bit for bit and a
// non-manifold mesh is written as it is: OpenMesh's half-edge TriMesh would have to split the
// vertices of non-manifold faces to hold it.
#pragma once

#include <filesystem>
#include <string_view>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::mesh_io {

// Reads a mesh, choosing the format by the extension of `path`: .obj, .ply or .off, in any case.
// Returns V (#V by 3, float32, in the file's units) and F (#F by 3, zero-based). Polygons are
// fan-triangulated, (a b c d) → (a b c) (a c d); the file's vertex order is kept, vertices that
// no face uses included, so a point cloud gives 0 faces.
// Errors: kInvalidArgument for an unknown extension, a malformed file (`file:line: expected …,
// got …` for OBJ), a face index outside the vertex list, a non-finite coordinate or a file
// without vertices; kNotFound / kIo when the file cannot be read.
Result<TriangleMesh> read_triangle_mesh(const std::filesystem::path& path);

// Parses OBJ text; `source` (usually the file name) prefixes every error as `source:line:`.
// Reads `v x y z` lines (further numbers on the line — w, or a vertex colour r g b — are
// checked to be numbers and ignored) and `f` lines whose corners are v, v/vt, v//vn or v/vt/vn;
// indices are 1-based, negative ones count back from the last vertex defined before the line
// (-1 is the latest). A face may only use vertices defined above it. Other statements (vt, vn,
// g, o, s, l, p, usemtl, mtllib, comments) are ignored.
Result<TriangleMesh> parse_obj(std::string_view text, std::string_view source);

// Writes `mesh` (V #V by 3 finite, F #F by 3 with indices in [0, #V)) in the format of the
// extension of `path`, atomically (write_file_atomically).
// Errors: kInvalidArgument for an unknown extension, a mesh without vertices, a non-finite
// coordinate or a face index out of range; kIo when the write fails.
Status write_triangle_mesh(const std::filesystem::path& path, const TriangleMesh& mesh);

}  // namespace animspace::mesh_io
