// parse_off: the Geomview OFF object file format, text form.
#include <cstdint>
#include <new>
#include <string>
#include <vector>

#include "core/mesh_io/mesh_builder.h"
#include "core/mesh_io/text_io.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::mesh_io {
namespace {

// The first token of the next line that has one, skipping blank lines and `#` comments; empty at
// the end of the text.
std::string_view next_content_line(TextReader& in) {
  while (in.next_line()) {
    const std::string_view token = in.next_token();
    if (!token.empty() && token.front() != '#') return token;
  }
  return {};
}

// [ST][C][N]OFF: texture coordinates, colours and normals after x y z. (4OFF and nOFF, with other
// than 3 coordinates, are not meshes in our sense.)
bool is_off_keyword(std::string_view keyword) {
  if (keyword.starts_with("ST")) keyword.remove_prefix(2);
  if (keyword.starts_with('C')) keyword.remove_prefix(1);
  if (keyword.starts_with('N')) keyword.remove_prefix(1);
  return keyword == "OFF";
}

// The rest of the line must be numbers (colours, normals, texture coordinates): checked, ignored.
Status skip_numbers(TextReader& in, std::string_view what) {
  for (std::string_view extra = in.next_token(); !extra.empty(); extra = in.next_token()) {
    if (extra.front() == '#') break;  // a comment to the end of the line
    if (const auto value = in.parse<double>(extra, what); !value.ok()) return value.error();
  }
  return Status::Ok();
}

}  // namespace

Result<TriangleMesh> parse_off(std::string_view text, std::string_view source) try {
  TextReader in(text, source);
  const std::string_view keyword = next_content_line(in);
  if (keyword.empty()) return in.error("expected 'OFF', got end of file");
  if (!is_off_keyword(keyword)) return in.error("'OFF' (or COFF, NOFF, CNOFF, STOFF)", keyword);

  // The counts may share the keyword's line.
  std::string_view first_count = in.next_token();
  if (first_count.empty()) first_count = next_content_line(in);
  if (first_count == "BINARY") return in.error("text OFF (binary OFF is not supported)", first_count);
  const auto vertex_count = in.parse<int>(first_count, "the vertex count");
  if (!vertex_count.ok()) return vertex_count.error();
  const auto face_count = in.read<int>("the face count");
  if (!face_count.ok()) return face_count.error();
  if (*vertex_count < 0 || *face_count < 0) {
    return in.error("non-negative counts", std::to_string(*vertex_count) + " " + std::to_string(*face_count));
  }
  ANIMSPACE_RETURN_IF_ERROR(skip_numbers(in, "the edge count or end of line"));

  MeshBuilder mesh;
  for (int v = 0; v < *vertex_count; ++v) {
    const std::string_view x = next_content_line(in);
    if (x.empty()) {
      return in.error("expected " + std::to_string(*vertex_count) + " vertices, got end of file after " + std::to_string(v));
    }
    float xyz[3];
    for (int axis = 0; axis < 3; ++axis) {
      const auto value = in.parse<float>(axis == 0 ? x : in.next_token(), "a vertex coordinate");
      if (!value.ok()) return value.error();
      xyz[axis] = *value;
    }
    ANIMSPACE_RETURN_IF_ERROR(skip_numbers(in, "a number (colour, normal, texture coordinate) or end of line"));
    mesh.add_vertex(xyz[0], xyz[1], xyz[2]);
  }
  const std::string index_range = "a vertex index in 0.." + std::to_string(*vertex_count - 1);
  std::vector<int32_t> polygon;
  for (int f = 0; f < *face_count; ++f) {
    const std::string_view size = next_content_line(in);
    if (size.empty()) {
      return in.error("expected " + std::to_string(*face_count) + " faces, got end of file after " + std::to_string(f));
    }
    const auto corners = in.parse<int>(size, "the number of vertices in a face");
    if (!corners.ok()) return corners.error();
    if (*corners < 3) return in.error("a face with at least 3 vertices", size);
    polygon.clear();
    for (int k = 0; k < *corners; ++k) {
      const std::string_view token = in.next_token();
      const auto index = in.parse<int>(token, index_range);
      if (!index.ok()) return index.error();
      if (*index < 0 || *index >= *vertex_count) return in.error(index_range, token);
      polygon.push_back(*index);
    }
    ANIMSPACE_RETURN_IF_ERROR(skip_numbers(in, "a colour or end of line"));
    mesh.add_polygon(polygon);
  }
  if (const std::string_view extra = next_content_line(in); !extra.empty()) {
    return in.error("end of file after " + std::to_string(*face_count) + " faces", extra);
  }
  if (*vertex_count == 0) return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": no vertices");
  return mesh.build();
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

}  // namespace animspace::mesh_io
