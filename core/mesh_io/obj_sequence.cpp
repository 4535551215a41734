#include "core/mesh_io/obj_sequence.h"

#include <algorithm>
#include <cctype>
#include <new>
#include <string>
#include <string_view>
#include <system_error>

#include "core/common/atomic_file.h"
#include "core/mesh_io/text_io.h"
#include "core/mesh_io/triangle_mesh_io.h"

namespace animspace::mesh_io {
namespace {

bool is_digit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// Three-way natural comparison: digit runs compare by value (leading zeros aside), everything
// else byte by byte.
int natural_compare(std::string_view a, std::string_view b) {
  size_t i = 0;
  size_t j = 0;
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      while (i < a.size() && a[i] == '0') ++i;
      while (j < b.size() && b[j] == '0') ++j;
      size_t end_a = i;
      size_t end_b = j;
      while (end_a < a.size() && is_digit(a[end_a])) ++end_a;
      while (end_b < b.size() && is_digit(b[end_b])) ++end_b;
      // Without leading zeros, the longer run is the larger number.
      if (end_a - i != end_b - j) return end_a - i < end_b - j ? -1 : 1;
      if (const int order = a.substr(i, end_a - i).compare(b.substr(j, end_b - j)); order != 0) return order;
      i = end_a;
      j = end_b;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]) ? -1 : 1;
      ++i;
      ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j ? -1 : 1;
  return 0;
}

std::string describe_triangle(const FaceMatrix& F, Eigen::Index f) {
  return "(" + std::to_string(F(f, 0)) + " " + std::to_string(F(f, 1)) + " " + std::to_string(F(f, 2)) + ")";
}

// Why `F` is not the same connectivity as `first`, or an empty string.
std::string connectivity_difference(const FaceMatrix& F, const FaceMatrix& first) {
  if (F.rows() != first.rows()) {
    return "has " + std::to_string(F.rows()) + " triangles, expected " + std::to_string(first.rows());
  }
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    if (F.row(f) != first.row(f)) {
      return "triangle " + std::to_string(f) + " has vertices " + describe_triangle(F, f) + ", expected " +
             describe_triangle(first, f) + " (zero-based)";
    }
  }
  return {};
}

}  // namespace

Result<MeshSequence> read_obj_sequence(const std::vector<std::filesystem::path>& files) {
  if (files.empty()) return make_error(ErrorCode::kInvalidArgument, "an OBJ sequence needs at least one file");
  MeshSequence sequence;
  try {
    for (size_t i = 0; i < files.size(); ++i) {
      const auto text = read_whole_file(files[i]);
      if (!text.ok()) return text.error();
      const auto mesh = parse_obj(*text, files[i].string());
      if (!mesh.ok()) return mesh.error();
      if (i == 0) {
        sequence.F = mesh->F;
        sequence.frames.num_points = static_cast<int>(mesh->V.rows());
        sequence.frames.samples.resize(static_cast<Eigen::Index>(files.size()), mesh->V.size());
      } else {
        const std::string against = " as in " + files[0].string();
        if (mesh->V.rows() != sequence.frames.num_points) {
          return make_error(ErrorCode::kInvalidArgument,
                            files[i].string() + ": has " + std::to_string(mesh->V.rows()) + " vertices, expected " +
                                std::to_string(sequence.frames.num_points) + against);
        }
        if (const std::string difference = connectivity_difference(mesh->F, sequence.F); !difference.empty()) {
          return make_error(ErrorCode::kInvalidArgument, files[i].string() + ": " + difference + against);
        }
      }
      // V is row-major, so its memory is exactly one sample row x0 y0 z0 x1 ….
      sequence.frames.samples.row(static_cast<Eigen::Index>(i)) =
          Eigen::Map<const Eigen::RowVectorXf>(mesh->V.data(), mesh->V.size());
    }
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted,
                      "out of memory reading an OBJ sequence of " + std::to_string(files.size()) + " files");
  }
  return sequence;
}

Result<std::vector<std::filesystem::path>> list_obj_sequence(const std::filesystem::path& directory) {
  std::error_code error;
  if (!std::filesystem::is_directory(directory, error)) {
    return make_error(ErrorCode::kNotFound, directory.string() + ": not a directory");
  }
  std::vector<std::filesystem::path> files;
  try {
    for (std::filesystem::directory_iterator it(directory, error), end; !error && it != end; it.increment(error)) {
      if (lowercase_extension(it->path()) == ".obj" && it->is_regular_file(error)) files.push_back(it->path());
    }
  } catch (const std::exception& e) {  // path conversions; the iterator itself reports through `error`
    return make_error(ErrorCode::kIo, directory.string() + ": cannot list: " + e.what());
  }
  if (error) return make_error(ErrorCode::kIo, directory.string() + ": cannot list: " + error.message());
  if (files.empty()) return make_error(ErrorCode::kNotFound, directory.string() + ": no *.obj files");
  std::sort(files.begin(), files.end(), [](const std::filesystem::path& a, const std::filesystem::path& b) {
    const std::string name_a = a.filename().string();
    const std::string name_b = b.filename().string();
    const int order = natural_compare(name_a, name_b);
    return order != 0 ? order < 0 : name_a < name_b;  // "f01" vs "f1": any fixed order
  });
  return files;
}

}  // namespace animspace::mesh_io
