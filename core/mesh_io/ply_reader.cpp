// parse_ply: Turk, "The PLY Polygon File Format" (1994) — ASCII, binary_little_endian and
// binary_big_endian; the vertex element's x y z and the face element's vertex index lists.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <new>
#include <string>
#include <vector>

#include "core/mesh_io/mesh_builder.h"
#include "core/mesh_io/text_io.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::mesh_io {
namespace {

static_assert(std::endian::native == std::endian::little, "binary PLY values are decoded by copying memory");

struct ScalarType {
  std::string_view name;
  std::string_view alias;  // the sized spelling some exporters write (int8, float32 …)
  int bytes;
  bool is_integral;
  bool is_signed;
};

constexpr ScalarType kScalarTypes[] = {
    {"char", "int8", 1, true, true},       {"uchar", "uint8", 1, true, false},
    {"short", "int16", 2, true, true},     {"ushort", "uint16", 2, true, false},
    {"int", "int32", 4, true, true},       {"uint", "uint32", 4, true, false},
    {"float", "float32", 4, false, true},  {"double", "float64", 8, false, true},
};

const ScalarType* find_type(std::string_view name) {
  for (const ScalarType& type : kScalarTypes) {
    if (name == type.name || name == type.alias) return &type;
  }
  return nullptr;
}

// x, y, z first: their value is the axis.
enum class Role { kX, kY, kZ, kVertexIndices, kSkip };

struct Property {
  const ScalarType* type = nullptr;
  const ScalarType* list_length_type = nullptr;  // null for a scalar property
  Role role = Role::kSkip;
};

struct Element {
  std::string_view name;
  int count = 0;
  std::vector<Property> properties;
};

enum class Encoding { kAscii, kLittleEndian, kBigEndian };

struct Header {
  Encoding encoding = Encoding::kAscii;
  std::vector<Element> elements;
};

Role role_of(std::string_view element, std::string_view property, bool is_list) {
  if (element == "vertex" && !is_list) {
    if (property == "x") return Role::kX;
    if (property == "y") return Role::kY;
    if (property == "z") return Role::kZ;
  }
  if (element == "face" && is_list && (property == "vertex_indices" || property == "vertex_index")) {
    return Role::kVertexIndices;
  }
  return Role::kSkip;
}

// Reads the header up to and including `end_header`, leaving `in` on that line.
Result<Header> parse_header(TextReader& in) {
  if (!in.next_line()) return in.error("expected 'ply' on the first line, got end of file");
  if (const std::string_view magic = in.next_token(); magic != "ply") return in.error("'ply' on the first line", magic);
  Header header;
  bool has_format = false;
  while (in.next_line()) {
    const std::string_view keyword = in.next_token();
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (!has_format) {
      if (keyword != "format") return in.error("'format' after 'ply'", keyword);
      const std::string_view encoding = in.next_token();
      if (encoding == "ascii") {
        header.encoding = Encoding::kAscii;
      } else if (encoding == "binary_little_endian") {
        header.encoding = Encoding::kLittleEndian;
      } else if (encoding == "binary_big_endian") {
        header.encoding = Encoding::kBigEndian;
      } else {
        return in.error("ascii, binary_little_endian or binary_big_endian", encoding);
      }
      if (const std::string_view version = in.next_token(); version != "1.0") return in.error("version 1.0", version);
      has_format = true;
    } else if (keyword == "element") {
      Element element;
      element.name = in.next_token();
      if (element.name.empty()) return in.error("an element name", element.name);
      const auto count = in.read<int>("an element count");
      if (!count.ok()) return count.error();
      if (*count < 0) return in.error("a non-negative element count", std::to_string(*count));
      element.count = *count;
      header.elements.push_back(element);
    } else if (keyword == "property") {
      if (header.elements.empty()) return in.error("an element before its properties", keyword);
      Element& element = header.elements.back();
      Property property;
      std::string_view type = in.next_token();
      if (type == "list") {
        const std::string_view length_type = in.next_token();
        property.list_length_type = find_type(length_type);
        if (property.list_length_type == nullptr || !property.list_length_type->is_integral) {
          return in.error("an integral list length type", length_type);
        }
        type = in.next_token();
      }
      property.type = find_type(type);
      if (property.type == nullptr) return in.error("a PLY property type (char, uchar, …, float, double)", type);
      const std::string_view name = in.next_token();
      if (name.empty()) return in.error("a property name", name);
      property.role = role_of(element.name, name, property.list_length_type != nullptr);
      if (property.role == Role::kVertexIndices && !property.type->is_integral) {
        return in.error("integral vertex indices", type);
      }
      element.properties.push_back(property);
    } else if (keyword == "end_header") {
      if (!has_format) return in.error("'format' before 'end_header'", keyword);
      return header;
    } else {
      return in.error("a header line (element, property, comment, end_header)", keyword);
    }
  }
  return in.error("expected 'end_header', got end of file");
}

// The values of the body, in order, from text tokens or binary records; every error names the
// line (ASCII) or byte offset (binary) it was found at.
class BodyReader {
 public:
  BodyReader(TextReader& in, Encoding encoding, std::string_view bytes, std::string_view source)
      : in_(in), encoding_(encoding), bytes_(bytes), source_(source), offset_(bytes.size() - in.rest_after_line().size()) {}

  Result<double> read(const ScalarType& type, std::string_view what) {
    if (encoding_ == Encoding::kAscii) {
      const std::string_view token = in_.next_token_any_line();
      if (token.empty()) return in_.error("expected " + std::string(what) + ", got end of file");
      if (type.is_integral) {
        const auto value = in_.parse<int>(token, what);
        if (!value.ok()) return value.error();
        return *value;
      }
      return in_.parse<double>(token, what);
    }
    if (bytes_.size() - offset_ < static_cast<size_t>(type.bytes)) {
      return make_error(ErrorCode::kDataLoss, location() + "truncated: expected " + std::string(what) + " (" +
                                                  std::to_string(type.bytes) + " bytes), the file ends");
    }
    unsigned char raw[8];
    std::memcpy(raw, bytes_.data() + offset_, static_cast<size_t>(type.bytes));
    if (encoding_ == Encoding::kBigEndian) std::reverse(raw, raw + type.bytes);
    offset_ += static_cast<size_t>(type.bytes);
    return decode(type, raw);
  }

  // ASCII: nothing but whitespace may follow; binary: no byte may.
  Status expect_end() {
    if (encoding_ == Encoding::kAscii) {
      if (const std::string_view extra = in_.next_token_any_line(); !extra.empty()) {
        return in_.error("end of file after the last element", extra);
      }
    } else if (offset_ != bytes_.size()) {
      return make_error(ErrorCode::kDataLoss, location() + "trailing bytes: the elements end here, the file has " +
                                                  std::to_string(bytes_.size()) + " bytes");
    }
    return Status::Ok();
  }

  // Where the next value starts: a byte offset (binary; the line is tracked by the reader).
  size_t offset() const { return offset_; }

  // An error at the current line (ASCII) or at byte `offset` (binary).
  Error error(const std::string& message, size_t offset) const {
    if (encoding_ == Encoding::kAscii) return in_.error(message);
    return make_error(ErrorCode::kInvalidArgument, location(offset) + message);
  }
  Error error(const std::string& message) const { return error(message, offset_); }

 private:
  std::string location(size_t offset) const { return std::string(source_) + ": byte " + std::to_string(offset) + ": "; }
  std::string location() const { return location(offset_); }

  static double decode(const ScalarType& type, const unsigned char* raw) {
    const auto as = [raw]<typename T>(T) {
      T value;
      std::memcpy(&value, raw, sizeof(T));
      return static_cast<double>(value);
    };
    if (!type.is_integral) return type.bytes == 4 ? as(float{}) : as(double{});
    switch (type.bytes) {
      case 1: return type.is_signed ? as(int8_t{}) : as(uint8_t{});
      case 2: return type.is_signed ? as(int16_t{}) : as(uint16_t{});
      default: return type.is_signed ? as(int32_t{}) : as(uint32_t{});
    }
  }

  TextReader& in_;
  Encoding encoding_;
  std::string_view bytes_;
  std::string_view source_;
  size_t offset_;  // binary: the next byte to read
};

}  // namespace

Result<TriangleMesh> parse_ply(std::string_view bytes, std::string_view source) try {
  TextReader in(bytes, source);
  const auto header = parse_header(in);
  if (!header.ok()) return header.error();
  const auto vertex = std::find_if(header->elements.begin(), header->elements.end(),
                                   [](const Element& element) { return element.name == "vertex"; });
  const auto face = std::find_if(header->elements.begin(), header->elements.end(),
                                 [](const Element& element) { return element.name == "face"; });
  const auto has = [](const auto& element, Role role) {
    return std::any_of(element->properties.begin(), element->properties.end(),
                       [role](const Property& property) { return property.role == role; });
  };
  if (vertex == header->elements.end() || !has(vertex, Role::kX) || !has(vertex, Role::kY) || !has(vertex, Role::kZ)) {
    return in.error("expected a vertex element with properties x, y and z in the header");
  }
  if (face != header->elements.end() && (face < vertex || !has(face, Role::kVertexIndices))) {
    return in.error("expected the face element after the vertex element, with a vertex_indices list");
  }

  const Element* vertex_element = &*vertex;
  const Element* face_element = face == header->elements.end() ? nullptr : &*face;

  BodyReader body(in, header->encoding, bytes, source);
  MeshBuilder mesh;
  std::vector<int32_t> polygon;
  for (const Element& element : header->elements) {
    // An element without properties holds nothing in any encoding: its instances are not walked
    // one by one (a header may declare two billion of them).
    if (element.properties.empty()) continue;
    for (int instance = 0; instance < element.count; ++instance) {
      const size_t start = body.offset();
      double xyz[3] = {0, 0, 0};
      polygon.clear();
      for (const Property& property : element.properties) {
        if (property.list_length_type == nullptr) {
          const auto value = body.read(*property.type, "a " + std::string(property.type->name) + " value");
          if (!value.ok()) return value.error();
          if (property.role <= Role::kZ) xyz[static_cast<int>(property.role)] = *value;
          continue;
        }
        const auto length = body.read(*property.list_length_type, "a list length");
        if (!length.ok()) return length.error();
        if (*length < 0) {
          return body.error("expected a non-negative list length, got " + std::to_string(static_cast<int64_t>(*length)));
        }
        // A corrupt length runs out of data after at most the file's size in items.
        const auto items = static_cast<int64_t>(*length);
        for (int64_t item = 0; item < items; ++item) {
          const bool is_index = property.role == Role::kVertexIndices;
          const auto value = body.read(*property.type, is_index ? "a vertex index" : "a list item");
          if (!value.ok()) return value.error();
          if (is_index) {
            if (*value < 0 || *value >= mesh.vertex_count()) {
              return body.error("face " + std::to_string(instance) + ": expected a vertex index in 0.." +
                                std::to_string(mesh.vertex_count() - 1) + ", got " + std::to_string(static_cast<int64_t>(*value)));
            }
            polygon.push_back(static_cast<int32_t>(*value));
          }
        }
      }
      if (&element == vertex_element) {
        for (const double coordinate : xyz) {
          if (!(std::abs(coordinate) <= std::numeric_limits<float>::max())) {  // NaN fails too
            return body.error("vertex " + std::to_string(instance) + " has a coordinate that is not a finite float32",
                              start);
          }
        }
        mesh.add_vertex(static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2]));
      } else if (&element == face_element) {
        if (polygon.size() < 3) {
          return body.error("face " + std::to_string(instance) + ": expected at least 3 vertices, got " +
                                std::to_string(polygon.size()),
                            start);
        }
        mesh.add_polygon(polygon);
      }
    }
  }
  ANIMSPACE_RETURN_IF_ERROR(body.expect_end());
  if (mesh.vertex_count() == 0) return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": no vertices");
  return mesh.build();
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

}  // namespace animspace::mesh_io
