// The fuzz harness shared by the triangle-mesh parsers (OBJ, PLY, OFF): what a parsed mesh must
// satisfy (core/mesh_io/triangle_mesh_io.h), and that the matching writer round-trips it.
#pragma once

#include <cstring>
#include <string>
#include <string_view>

#include "core/mesh_io/triangle_mesh_io.h"
#include "fuzz/fuzz_support.h"

namespace animspace::fuzz {

using MeshParser = Result<TriangleMesh> (*)(std::string_view, std::string_view);
using MeshWriter = std::string (*)(const TriangleMesh&);

// Parses `bytes`; a mesh it accepts must be one write_triangle_mesh accepts (#V > 0, every
// coordinate finite, every face index in [0, #V)), and writing then parsing it again must give
// V bit for bit and F exactly (the header promises the round trip).
inline void fuzz_mesh_parser(std::string_view bytes, MeshParser parse, MeshWriter write, std::string_view source) {
  const Result<TriangleMesh> mesh = parse(bytes, source);
  if (!mesh) {
    check_refusal(mesh.error(), source);
    return;
  }
  const PointMatrix& V = mesh->V;
  const FaceMatrix& F = mesh->F;
  FUZZ_CHECK(V.rows() > 0);
  FUZZ_CHECK(V.allFinite());
  FUZZ_CHECK(F.size() == 0 || (F.minCoeff() >= 0 && F.maxCoeff() < V.rows()));

  const Result<TriangleMesh> again = parse(write(*mesh), source);
  FUZZ_CHECK(again.ok());
  FUZZ_CHECK(again->V.rows() == V.rows() && again->F.rows() == F.rows());
  FUZZ_CHECK(std::memcmp(again->V.data(), V.data(), sizeof(float) * static_cast<size_t>(V.size())) == 0);
  FUZZ_CHECK(again->F == F);
}

}  // namespace animspace::fuzz
