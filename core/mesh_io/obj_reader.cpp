// parse_obj: Wavefront OBJ (Advanced Visualizer manual, appendix B1), `v` and `f` only.
#include <cstdint>
#include <new>
#include <string>
#include <vector>

#include "core/mesh_io/mesh_builder.h"
#include "core/mesh_io/text_io.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::mesh_io {
namespace {

// One corner of an OBJ face, `v`, `v/vt`, `v//vn` or `v/vt/vn`, as a zero-based vertex index.
// `vertex_count` is the number of vertices defined above the face (what negative indices count
// back from, and the most a positive one may reach).
Result<int32_t> parse_face_corner(const TextReader& in, std::string_view corner, int vertex_count) {
  constexpr std::string_view kCornerForms = "a face corner v, v/vt, v//vn or v/vt/vn";
  std::string_view parts[3];
  int part_count = 0;
  for (std::string_view rest = corner;; ++part_count) {
    if (part_count == 3) return in.error(kCornerForms, corner);
    const size_t slash = rest.find('/');
    parts[part_count] = rest.substr(0, slash);
    if (slash == std::string_view::npos) {
      ++part_count;
      break;
    }
    rest.remove_prefix(slash + 1);
  }
  // Only v//vn may leave a part empty; texture and normal indices are checked, not kept.
  const bool well_formed = !parts[0].empty() && (part_count < 2 || !parts[part_count - 1].empty());
  if (!well_formed) return in.error(kCornerForms, corner);
  for (int k = 1; k < part_count; ++k) {
    if (!parts[k].empty() && !in.parse<int>(parts[k], kCornerForms).ok()) return in.error(kCornerForms, corner);
  }
  const auto index = in.parse<int>(parts[0], kCornerForms);
  if (!index.ok()) return index.error();
  // B1 "Referencing groups of vertices": 1-based, or negative relative to the latest vertex.
  const int64_t resolved = *index > 0 ? int64_t{*index} - 1 : int64_t{vertex_count} + *index;
  if (*index == 0 || resolved < 0 || resolved >= vertex_count) {
    const std::string count = std::to_string(vertex_count);
    return in.error(vertex_count == 0 ? std::string("a vertex index, but no vertex is defined above this face")
                                      : "a vertex index in 1.." + count + " or -" + count + "..-1 (" + count +
                                            " vertices defined so far)",
                    parts[0]);
  }
  return static_cast<int32_t>(resolved);
}

}  // namespace

Result<TriangleMesh> parse_obj(std::string_view text, std::string_view source) try {
  MeshBuilder mesh;
  std::vector<int32_t> polygon;  // the face being read
  TextReader in(text, source);
  while (in.next_line()) {
    const std::string_view keyword = in.next_token();
    if (keyword == "v") {
      float xyz[3];
      for (float& coordinate : xyz) {
        const auto value = in.read<float>("a vertex coordinate");
        if (!value.ok()) return value.error();
        coordinate = *value;
      }
      for (std::string_view extra = in.next_token(); !extra.empty(); extra = in.next_token()) {
        if (const auto value = in.parse<float>(extra, "a number (w or vertex colour) or end of line"); !value.ok()) {
          return value.error();
        }
      }
      mesh.add_vertex(xyz[0], xyz[1], xyz[2]);
    } else if (keyword == "f") {
      polygon.clear();
      for (std::string_view corner = in.next_token(); !corner.empty(); corner = in.next_token()) {
        const auto index = parse_face_corner(in, corner, mesh.vertex_count());
        if (!index.ok()) return index.error();
        polygon.push_back(*index);
      }
      if (polygon.size() < 3) {
        return in.error("expected a face with at least 3 vertices, got " + std::to_string(polygon.size()));
      }
      mesh.add_polygon(polygon);
    }
  }
  if (mesh.vertex_count() == 0) {
    return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": no vertices ('v' lines)");
  }
  return mesh.build();
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

}  // namespace animspace::mesh_io
