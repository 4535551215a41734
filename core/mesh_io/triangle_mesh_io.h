// Triangle meshes from and to OBJ, PLY and OFF files.
//
// Formats: OBJ — Wavefront "Object Files (.obj)", Advanced Visualizer manual appendix B1; PLY —
// Turk, "The PLY Polygon File Format" (1994), ASCII and binary of either byte order; OFF — the
// Geomview "OFF" object file format (text).
//
// The parsers are our own and strict (obj.cpp, ply.cpp, off.cpp): errors name `file:line:` (text)
// or `file: byte N:` (binary) with what was expected and what was found. OpenMesh 9's readers
// were the first choice, but fed malformed files they segfault (PLY headers), loop for ever (a
// PLY list length of -4, an OFF comment before the keyword) or quietly return stale values (a
// truncated OFF), which a daemon reading uploaded files cannot afford; they also split the
// vertices of non-manifold faces, renumbering vertices that a point cache indexes.
//
// Writers: OBJ and OFF as text with the shortest decimals that read back to the same float32,
// PLY as binary little endian; all three round-trip V bit for bit.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::mesh_io {

// Reads a mesh, choosing the format by the extension of `path`: .obj, .ply or .off, in any case.
// Returns V (#V by 3, float32, in the file's units) and F (#F by 3, zero-based). Polygons are
// fan-triangulated, (a b c d) → (a b c) (a c d); the file's vertex order is kept, vertices that
// no face uses included, so a point cloud gives 0 faces. Faces that repeat a vertex are kept.
// Errors: kInvalidArgument for an unknown extension, a malformed file, a face index outside the
// vertex list, a non-finite coordinate or a file without vertices; kDataLoss for a binary PLY
// whose size disagrees with its header; kNotFound / kIo when the file cannot be read.
Result<TriangleMesh> read_triangle_mesh(const std::filesystem::path& path);

// Writes `mesh` (V #V by 3 finite, #V > 0; F #F by 3 with indices in [0, #V)) in the format of
// the extension of `path`, atomically (write_file_atomically).
// Errors: kInvalidArgument for an unknown extension or a mesh that breaks those conditions;
// kIo when the write fails.
Status write_triangle_mesh(const std::filesystem::path& path, const TriangleMesh& mesh);

// Parsers of file contents; `source` (usually the file name) prefixes every error.

// OBJ: `v x y z` lines (further numbers on the line — w, or a vertex colour r g b — must be
// numbers and are ignored) and `f` lines whose corners are v, v/vt, v//vn or v/vt/vn; indices are
// 1-based, negative ones count back from the last vertex defined above the line (-1 is the
// latest), and a face may only use vertices defined above it. Other statements (vt, vn, g, o, s,
// l, p, usemtl, mtllib, comments) are ignored.
Result<TriangleMesh> parse_obj(std::string_view text, std::string_view source);

// PLY, ASCII or binary: the `vertex` element's x, y, z (any numeric type) and the `face`
// element's `vertex_indices` (or `vertex_index`) lists; other properties and elements are
// checked for structure and skipped. The vertex element must come before the face element.
Result<TriangleMesh> parse_ply(std::string_view bytes, std::string_view source);

// OFF (and COFF, NOFF, CNOFF, STOFF …, whose extra per-vertex numbers are ignored): the keyword,
// `#vertices #faces [#edges]`, vertex lines `x y z …`, face lines `n i0 … i(n-1) [colour]` with
// zero-based indices; `#` comments and blank lines anywhere. Binary OFF is refused.
Result<TriangleMesh> parse_off(std::string_view text, std::string_view source);

// File contents for a mesh that write_triangle_mesh would accept (the caller checks).
std::string serialize_obj(const TriangleMesh& mesh);
std::string serialize_ply(const TriangleMesh& mesh);  // binary little endian, float32 x y z, int32 lists
std::string serialize_off(const TriangleMesh& mesh);

}  // namespace animspace::mesh_io
