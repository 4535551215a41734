#include "core/mesh_io/triangle_mesh_io.h"

#include <bit>
#include <cstdint>
#include <new>
#include <string>

#include "core/common/atomic_file.h"
#include "core/mesh_io/text_io.h"

namespace animspace::mesh_io {
namespace {

static_assert(std::endian::native == std::endian::little,
              "binary PLY is written by copying little endian float32/int32 memory");

enum class MeshFormat { kObj, kPly, kOff };

Result<MeshFormat> format_of(const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".obj") return MeshFormat::kObj;
  if (extension == ".ply") return MeshFormat::kPly;
  if (extension == ".off") return MeshFormat::kOff;
  return make_error(ErrorCode::kInvalidArgument,
                    path.string() + ": unknown mesh file extension '" + path.extension().string() +
                        "' (supported: .obj, .ply, .off)");
}

Status check_writable(const TriangleMesh& mesh, const std::string& destination) {
  if (mesh.V.rows() == 0) return make_error(ErrorCode::kInvalidArgument, destination + ": mesh has no vertices");
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v) {
    if (!mesh.V.row(v).allFinite()) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": vertex " + std::to_string(v) + " has a non-finite coordinate");
    }
  }
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    if (mesh.F.row(f).minCoeff() < 0 || mesh.F.row(f).maxCoeff() >= mesh.V.rows()) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": face " + std::to_string(f) + " has a vertex index outside 0.." +
                            std::to_string(mesh.V.rows() - 1));
    }
  }
  return Status::Ok();
}

// Text lines "<prefix>x y z".
void append_vertex_lines(const PointMatrix& V, std::string_view prefix, std::string& out) {
  for (Eigen::Index v = 0; v < V.rows(); ++v) {
    out += prefix;
    for (int axis = 0; axis < 3; ++axis) {
      append_number(out, V(v, axis));
      out += axis < 2 ? ' ' : '\n';
    }
  }
}

// Text lines "<prefix>a b c", indices shifted by `index_base`.
void append_face_lines(const FaceMatrix& F, std::string_view prefix, int index_base, std::string& out) {
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    out += prefix;
    for (int corner = 0; corner < 3; ++corner) {
      append_number(out, F(f, corner) + index_base);
      out += corner < 2 ? ' ' : '\n';
    }
  }
}

}  // namespace

std::string serialize_obj(const TriangleMesh& mesh) {
  std::string out;
  append_vertex_lines(mesh.V, "v ", out);
  append_face_lines(mesh.F, "f ", 1, out);
  return out;
}

std::string serialize_off(const TriangleMesh& mesh) {
  std::string out = "OFF\n" + std::to_string(mesh.V.rows()) + ' ' + std::to_string(mesh.F.rows()) + " 0\n";
  append_vertex_lines(mesh.V, "", out);
  append_face_lines(mesh.F, "3 ", 0, out);
  return out;
}

std::string serialize_ply(const TriangleMesh& mesh) {
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(mesh.V.rows()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(mesh.F.rows()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  // V is row-major float32: its memory is the vertex element's x y z records.
  out.append(reinterpret_cast<const char*>(mesh.V.data()), sizeof(float) * static_cast<size_t>(mesh.V.size()));
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    out += static_cast<char>(3);
    out.append(reinterpret_cast<const char*>(mesh.F.row(f).data()), 3 * sizeof(int32_t));
  }
  return out;
}

Result<TriangleMesh> read_triangle_mesh(const std::filesystem::path& path) {
  const auto format = format_of(path);
  if (!format.ok()) return format.error();
  const auto bytes = read_whole_file(path);
  if (!bytes.ok()) return bytes.error();
  switch (*format) {
    case MeshFormat::kObj: return parse_obj(*bytes, path.string());
    case MeshFormat::kPly: return parse_ply(*bytes, path.string());
    case MeshFormat::kOff: return parse_off(*bytes, path.string());
  }
  return make_error(ErrorCode::kInternal, path.string() + ": unhandled mesh format");
}

Status write_triangle_mesh(const std::filesystem::path& path, const TriangleMesh& mesh) {
  const auto format = format_of(path);
  if (!format.ok()) return format.error();
  ANIMSPACE_RETURN_IF_ERROR(check_writable(mesh, path.string()));
  try {
    switch (*format) {
      case MeshFormat::kObj: return write_file_atomically(path, serialize_obj(mesh));
      case MeshFormat::kPly: return write_file_atomically(path, serialize_ply(mesh));
      case MeshFormat::kOff: return write_file_atomically(path, serialize_off(mesh));
    }
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory while writing");
  }
  return make_error(ErrorCode::kInternal, path.string() + ": unhandled mesh format");
}

}  // namespace animspace::mesh_io
