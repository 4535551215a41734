#include "core/mesh_io/posed_mesh.h"

#include <bit>
#include <cassert>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include <meshoptimizer.h>

#include "core/common/atomic_file.h"
#include "core/mesh_io/gltf_writing.h"
#include "core/mesh_io/text_io.h"

namespace animspace::mesh_io {
namespace {

enum class ExportFormat { kObj, kPly, kGlb, kGltf };

Result<ExportFormat> format_of(const std::filesystem::path& path) {
  const std::string extension = mesh_io::lowercase_extension(path);
  if (extension == ".obj") return ExportFormat::kObj;
  if (extension == ".ply") return ExportFormat::kPly;
  if (extension == ".glb") return ExportFormat::kGlb;
  if (extension == ".gltf") return ExportFormat::kGltf;
  return make_error(ErrorCode::kInvalidArgument,
                    path.string() + ": unknown posed mesh file extension '" + path.extension().string() +
                        "' (supported: .obj, .ply, .glb, .gltf)");
}

// The conditions every writer needs; `destination` prefixes the messages.
Status check_mesh(const PosedMesh& mesh, const std::string& destination) {
  const Eigen::Index vertex_count = mesh.points.rows();
  if (vertex_count == 0) return make_error(ErrorCode::kInvalidArgument, destination + ": mesh has no vertices");
  if (mesh.faces.rows() == 0) return make_error(ErrorCode::kInvalidArgument, destination + ": mesh has no faces");
  for (Eigen::Index v = 0; v < vertex_count; ++v) {
    if (!mesh.points.row(v).allFinite()) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": vertex " + std::to_string(v) + " has a non-finite coordinate");
    }
  }
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    if (mesh.faces.row(f).minCoeff() < 0 || mesh.faces.row(f).maxCoeff() >= vertex_count) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": face " + std::to_string(f) + " has a vertex index outside 0.." +
                            std::to_string(vertex_count - 1));
    }
  }
  if (mesh.normals.rows() != 0) {
    if (mesh.normals.rows() != vertex_count) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": " + std::to_string(mesh.normals.rows()) + " normals for " +
                            std::to_string(vertex_count) + " vertices");
    }
    for (Eigen::Index v = 0; v < vertex_count; ++v) {
      if (!mesh.normals.row(v).allFinite()) {
        return make_error(ErrorCode::kInvalidArgument,
                          destination + ": normal " + std::to_string(v) + " has a non-finite component");
      }
    }
  }
  if (mesh.uvs.rows() != 0) {
    if (mesh.uvs.rows() != vertex_count) {
      return make_error(ErrorCode::kInvalidArgument, destination + ": " + std::to_string(mesh.uvs.rows()) +
                                                         " texture coordinates for " + std::to_string(vertex_count) +
                                                         " vertices");
    }
    if (!mesh.uvs.allFinite()) {
      return make_error(ErrorCode::kInvalidArgument, destination + ": a texture coordinate is not finite");
    }
  }
  return Status::Ok();
}

Result<std::string> serialize_gltf_document(const PosedMesh& mesh, bool binary) {
  const std::string kind = binary ? "glb" : "gltf";
  ANIMSPACE_RETURN_IF_ERROR(check_mesh(mesh, kind));
  const size_t vertex_count = static_cast<size_t>(mesh.points.rows());
  const size_t index_count = 3 * static_cast<size_t>(mesh.faces.rows());
  const bool has_normals = mesh.normals.rows() != 0;
  const size_t position_bytes = 3 * sizeof(float) * vertex_count;
  const size_t normal_bytes = has_normals ? position_bytes : 0;
  const size_t index_bytes = sizeof(uint32_t) * index_count;
  const bool has_uvs = mesh.uvs.rows() != 0;
  const size_t uv_bytes = has_uvs ? 2 * sizeof(float) * vertex_count : 0;
  if (position_bytes + normal_bytes + uv_bytes + index_bytes > gltf_writing::kMaxBufferBytes) {
    return make_error(ErrorCode::kInvalidArgument,
                      kind + ": mesh of " + std::to_string(vertex_count) + " vertices and " +
                          std::to_string(index_count / 3) + " faces is too large for a glTF buffer");
  }
  try {
    tinygltf::Model model = gltf_writing::new_document();
    model.buffers[0].data.reserve(position_bytes + normal_bytes + index_bytes);

    tinygltf::Primitive primitive;
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    // Row-major float32: x0 y0 z0 x1 …
    const int position =
        gltf_writing::append_accessor(model, mesh.points.data(), position_bytes, TINYGLTF_TARGET_ARRAY_BUFFER,
                                      TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_count);
    // min/max are required for POSITION; float32 values are exact in double.
    const Eigen::RowVector3f lo = mesh.points.colwise().minCoeff();
    const Eigen::RowVector3f hi = mesh.points.colwise().maxCoeff();
    model.accessors[static_cast<size_t>(position)].minValues = {lo.x(), lo.y(), lo.z()};
    model.accessors[static_cast<size_t>(position)].maxValues = {hi.x(), hi.y(), hi.z()};
    primitive.attributes["POSITION"] = position;
    if (has_normals) {
      primitive.attributes["NORMAL"] =
          gltf_writing::append_accessor(model, mesh.normals.data(), normal_bytes, TINYGLTF_TARGET_ARRAY_BUFFER,
                                        TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertex_count);
    }
    if (has_uvs) {
      // glTF's texture origin is the top-left corner: (u, 1 − v).
      UvMatrix flipped = mesh.uvs;
      flipped.col(1).array() = 1 - flipped.col(1).array();
      primitive.attributes["TEXCOORD_0"] =
          gltf_writing::append_accessor(model, flipped.data(), uv_bytes, TINYGLTF_TARGET_ARRAY_BUFFER,
                                        TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, vertex_count);
    }
    // int32 indices in [0, #V): the same bytes as uint32.
    primitive.indices =
        gltf_writing::append_accessor(model, mesh.faces.data(), index_bytes, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER,
                                      TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, index_count);

    tinygltf::Mesh gltf_mesh;
    gltf_mesh.primitives.push_back(std::move(primitive));
    model.meshes.push_back(std::move(gltf_mesh));
    tinygltf::Node node;
    node.mesh = 0;
    model.nodes.push_back(std::move(node));
    tinygltf::Scene scene;
    scene.nodes.push_back(0);
    model.scenes.push_back(std::move(scene));
    model.defaultScene = 0;
    return gltf_writing::serialize_document(model, binary, kind);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, kind + ": out of memory while serialising");
  }
}

// OBJ with `vn` lines when the mesh has normals: each vertex's normal shares its index, so a
// corner is written `v//vn` with the same number twice.
std::string serialize_posed_obj(const PosedMesh& mesh) {
  const bool has_normals = mesh.normals.rows() != 0;
  std::string out;
  const auto append_rows = [&out](const PointMatrix& rows, std::string_view prefix) {
    for (Eigen::Index v = 0; v < rows.rows(); ++v) {
      out += prefix;
      for (int axis = 0; axis < 3; ++axis) {
        append_number(out, rows(v, axis));
        out += axis < 2 ? ' ' : '\n';
      }
    }
  };
  const bool has_uvs = mesh.uvs.rows() != 0;
  append_rows(mesh.points, "v ");
  if (has_normals) append_rows(mesh.normals, "vn ");
  for (Eigen::Index v = 0; v < mesh.uvs.rows(); ++v) {
    out += "vt ";
    append_number(out, mesh.uvs(v, 0));
    out += ' ';
    append_number(out, mesh.uvs(v, 1));
    out += '\n';
  }
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    out += "f ";
    for (int corner = 0; corner < 3; ++corner) {
      append_number(out, mesh.faces(f, corner) + 1);
      if (has_uvs) {
        out += '/';
        append_number(out, mesh.faces(f, corner) + 1);
      }
      if (has_normals) {
        out += has_uvs ? "/" : "//";
        append_number(out, mesh.faces(f, corner) + 1);
      }
      out += corner < 2 ? ' ' : '\n';
    }
  }
  return out;
}

static_assert(std::endian::native == std::endian::little,
              "binary PLY is written by copying little endian float32/int32 memory");

// Binary little-endian PLY; with normals each vertex record is x y z nx ny nz (float32), the
// property names most readers (Blender, MeshLab, Open3D) take as normals.
std::string serialize_posed_ply(const PosedMesh& mesh) {
  const bool has_normals = mesh.normals.rows() != 0;
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(mesh.points.rows()) +
                    "\nproperty float x\nproperty float y\nproperty float z\n";
  if (has_normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
  const bool has_uvs = mesh.uvs.rows() != 0;
  if (has_uvs) out += "property float s\nproperty float t\n";
  out += "element face " + std::to_string(mesh.faces.rows()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (Eigen::Index v = 0; v < mesh.points.rows(); ++v) {
    out.append(reinterpret_cast<const char*>(mesh.points.row(v).data()), 3 * sizeof(float));
    if (has_normals) out.append(reinterpret_cast<const char*>(mesh.normals.row(v).data()), 3 * sizeof(float));
    if (has_uvs) out.append(reinterpret_cast<const char*>(mesh.uvs.row(v).data()), 2 * sizeof(float));
  }
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    out += static_cast<char>(3);
    out.append(reinterpret_cast<const char*>(mesh.faces.row(f).data()), 3 * sizeof(int32_t));
  }
  return out;
}

}  // namespace

PosedMesh optimise_for_rendering(const PosedMesh& mesh) {
  const size_t vertex_count = static_cast<size_t>(mesh.points.rows());
  const size_t index_count = 3 * static_cast<size_t>(mesh.faces.rows());
  assert(mesh.normals.rows() == 0 || mesh.normals.rows() == mesh.points.rows());
  assert(mesh.faces.size() == 0 ||
         (mesh.faces.minCoeff() >= 0 && mesh.faces.maxCoeff() < static_cast<int32_t>(vertex_count)));

  PosedMesh out;
  if (index_count == 0) {  // every vertex is unused
    out.points.resize(0, 3);
    out.faces.resize(0, 3);
    out.normals.resize(0, 3);
    out.uvs.resize(0, 2);
    return out;
  }
  std::vector<unsigned int> indices(index_count);
  for (size_t i = 0; i < index_count; ++i) indices[i] = static_cast<unsigned int>(mesh.faces.data()[i]);

  std::vector<unsigned int> cache_order(index_count);
  meshopt_optimizeVertexCache(cache_order.data(), indices.data(), index_count, vertex_count);
  std::vector<unsigned int> remap(vertex_count);
  const size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), cache_order.data(), index_count, vertex_count);

  out.faces.resize(static_cast<Eigen::Index>(index_count / 3), 3);
  static_assert(sizeof(unsigned int) == sizeof(int32_t));
  meshopt_remapIndexBuffer(reinterpret_cast<unsigned int*>(out.faces.data()), cache_order.data(), index_count,
                           remap.data());
  out.points.resize(static_cast<Eigen::Index>(used), 3);
  meshopt_remapVertexBuffer(out.points.data(), mesh.points.data(), vertex_count, 3 * sizeof(float), remap.data());
  if (mesh.normals.rows() != 0) {
    out.normals.resize(static_cast<Eigen::Index>(used), 3);
    meshopt_remapVertexBuffer(out.normals.data(), mesh.normals.data(), vertex_count, 3 * sizeof(float),
                              remap.data());
  } else {
    out.normals.resize(0, 3);
  }
  if (mesh.uvs.rows() != 0) {
    out.uvs.resize(static_cast<Eigen::Index>(used), 2);
    meshopt_remapVertexBuffer(out.uvs.data(), mesh.uvs.data(), vertex_count, 2 * sizeof(float), remap.data());
  } else {
    out.uvs.resize(0, 2);
  }
  return out;
}

SeamSplit split_seam_vertices(const FaceMatrix& faces, Eigen::Index vertex_count, const UvMatrix& corner_uvs) {
  assert(corner_uvs.rows() == 3 * faces.rows());
  SeamSplit out;
  out.faces.resize(faces.rows(), 3);
  std::vector<Eigen::RowVector2f> uv;
  // Per input vertex, the output vertices made for it so far (few: one per chart it borders).
  std::vector<std::vector<int32_t>> made(static_cast<size_t>(vertex_count));
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t v = faces(f, k);
      const Eigen::RowVector2f t = corner_uvs.row(3 * f + k);
      int32_t found = -1;
      for (int32_t o : made[static_cast<size_t>(v)]) {
        if (uv[static_cast<size_t>(o)] == t) found = o;
      }
      if (found < 0) {
        found = static_cast<int32_t>(out.source.size());
        out.source.push_back(v);
        uv.push_back(t);
        made[static_cast<size_t>(v)].push_back(found);
      }
      out.faces(f, k) = found;
    }
  }
  out.uvs.resize(static_cast<Eigen::Index>(uv.size()), 2);
  for (size_t o = 0; o < uv.size(); ++o) out.uvs.row(static_cast<Eigen::Index>(o)) = uv[o];
  return out;
}

PosedMesh split_seams(const PosedMesh& mesh, const UvMatrix& corner_uvs) {
  assert(mesh.uvs.rows() == 0);
  assert(corner_uvs.rows() == 3 * mesh.faces.rows());
  SeamSplit split = split_seam_vertices(mesh.faces, mesh.points.rows(), corner_uvs);
  PosedMesh out;
  const auto n = static_cast<Eigen::Index>(split.source.size());
  out.faces = std::move(split.faces);
  out.uvs = std::move(split.uvs);
  out.points.resize(n, 3);
  out.normals.resize(mesh.normals.rows() != 0 ? n : 0, 3);
  for (Eigen::Index o = 0; o < n; ++o) {
    out.points.row(o) = mesh.points.row(split.source[static_cast<size_t>(o)]);
    if (mesh.normals.rows() != 0) out.normals.row(o) = mesh.normals.row(split.source[static_cast<size_t>(o)]);
  }
  return out;
}

Result<std::string> serialize_glb(const PosedMesh& mesh) { return serialize_gltf_document(mesh, true); }

Result<std::string> serialize_gltf(const PosedMesh& mesh) { return serialize_gltf_document(mesh, false); }

Status write_posed_mesh(const std::filesystem::path& path, const PosedMesh& mesh) {
  const auto format = format_of(path);
  if (!format.ok()) return format.error();
  ANIMSPACE_RETURN_IF_ERROR(check_mesh(mesh, path.string()));
  try {
    const PosedMesh optimised = optimise_for_rendering(mesh);
    switch (*format) {
      case ExportFormat::kObj:
      case ExportFormat::kPly:
        return write_file_atomically(path, *format == ExportFormat::kObj ? serialize_posed_obj(optimised)
                                                                          : serialize_posed_ply(optimised));
      case ExportFormat::kGlb:
      case ExportFormat::kGltf: {
        auto bytes = *format == ExportFormat::kGlb ? serialize_glb(optimised) : serialize_gltf(optimised);
        if (!bytes.ok()) {
          Error error = bytes.error();
          error.message = path.string() + ": " + error.message;
          return error;
        }
        return write_file_atomically(path, *bytes);
      }
    }
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory while writing");
  }
  return make_error(ErrorCode::kInternal, path.string() + ": unhandled posed mesh format");
}

}  // namespace animspace::mesh_io
