#include "core/mesh_io/libigl_rig.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>
#include <string_view>

#include "core/common/atomic_file.h"
#include "core/mesh_io/text_io.h"

namespace animspace::mesh_io {
namespace {

static_assert(std::endian::native == std::endian::little,
              "binary DMAT is read by copying little endian float64 memory");

// Appends `values` as one line of numbers.
template <typename Derived>
void append_line(std::string& out, const Eigen::DenseBase<Derived>& values) {
  for (Eigen::Index k = 0; k < values.size(); ++k) {
    if (k > 0) out += ' ';
    append_number(out, static_cast<double>(values.derived()(k)));
  }
  out += '\n';
}

template <typename Derived>
Status check_finite(const Eigen::MatrixBase<Derived>& values, std::string_view source, std::string_view what) {
  if (values.size() == 0) return Status::Ok();  // not one turn per column of a 0-row matrix
  for (Eigen::Index j = 0; j < values.cols(); ++j) {
    for (Eigen::Index i = 0; i < values.rows(); ++i) {
      if (!std::isfinite(values(i, j))) {
        return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": " + std::string(what) + " (" +
                                                           std::to_string(i) + ", " + std::to_string(j) +
                                                           ") is not finite");
      }
    }
  }
  return Status::Ok();
}

// Runs `parse` on the file's contents.
template <typename T, typename Parse>
Result<T> parse_file(const std::filesystem::path& path, Parse parse) {
  const auto text = read_whole_file(path);
  if (!text.ok()) return text.error();
  const std::string source = path.string();
  return parse(std::string_view(*text), std::string_view(source));
}

// A DMAT `cols rows` line (the reader is on it): both non-negative, nothing after them.
struct DmatShape {
  int cols = 0;
  int rows = 0;
};

Result<DmatShape> read_dmat_shape(TextReader& in) {
  const auto cols = in.read<int>("a column count");
  if (!cols.ok()) return cols.error();
  const auto rows = in.read<int>("a row count");
  if (!rows.ok()) return rows.error();
  if (const std::string_view extra = in.next_token(); !extra.empty()) return in.error("end of line after `cols rows`", extra);
  if (*cols < 0 || *rows < 0) return in.error("non-negative `cols rows`", std::to_string(*cols) + " " + std::to_string(*rows));
  return DmatShape{*cols, *rows};
}

// libigl's binary DMAT: after the `0 0` line, a `cols rows` line and the raw float64 payload.
Result<Eigen::MatrixXd> parse_binary_dmat(TextReader& in, std::string_view text, std::string_view source) {
  const auto shape = read_dmat_shape(in);
  if (!shape.ok()) return shape.error();
  const int cols = shape->cols;
  const int rows = shape->rows;
  const std::string_view payload = in.rest_after_line();
  const size_t offset = text.size() - payload.size();
  const uint64_t count = static_cast<uint64_t>(rows) * static_cast<uint64_t>(cols);
  if (count > payload.size() / sizeof(double) || count * sizeof(double) != payload.size()) {
    return make_error(ErrorCode::kDataLoss, std::string(source) + ": byte " + std::to_string(offset) + ": " +
                                                std::to_string(rows) + " × " + std::to_string(cols) +
                                                " float64 values need " + std::to_string(count) + " × 8 bytes, got " +
                                                std::to_string(payload.size()));
  }
  Eigen::MatrixXd matrix(rows, cols);
  // An empty matrix has no storage (data() is null), and memcpy may not be handed null.
  if (count > 0) std::memcpy(matrix.data(), payload.data(), payload.size());  // both column-major
  ANIMSPACE_RETURN_IF_ERROR(check_finite(matrix, source, "entry"));
  return matrix;
}

}  // namespace

Result<TgfSkeleton> parse_tgf(std::string_view text, std::string_view source) try {
  enum class Section { kJoints, kBones, kIgnored };
  Section section = Section::kJoints;
  std::vector<double> joints;  // x y z per joint
  std::vector<int> bones;      // parent child per bone, zero-based
  TextReader in(text, source);
  while (in.next_line()) {
    const std::string_view first = in.next_token();
    if (first.empty()) continue;
    if (first.front() == '#') {
      section = section == Section::kJoints ? Section::kBones : Section::kIgnored;
      continue;
    }
    if (section == Section::kJoints) {
      // libigl ignores the index; bones refer to joints by position, so it must match.
      const auto joint_count = static_cast<int>(joints.size() / 3);
      const auto index = in.parse<int>(first, "a joint index");
      if (!index.ok()) return index.error();
      if (*index != joint_count + 1) return in.error("joint index " + std::to_string(joint_count + 1), first);
      for (int axis = 0; axis < 3; ++axis) {
        const auto coordinate = in.read<double>("a joint coordinate");
        if (!coordinate.ok()) return coordinate.error();
        joints.push_back(*coordinate);
      }
      if (const std::string_view extra = in.next_token(); !extra.empty()) {
        return in.error("end of line after `index x y z`", extra);
      }
    } else if (section == Section::kBones) {
      const auto joint_count = static_cast<int>(joints.size() / 3);
      const std::string range = "a joint index in 1.." + std::to_string(joint_count);
      const std::string_view parent_token = first;
      const std::string_view child_token = in.next_token();
      const auto parent = in.parse<int>(parent_token, range);
      if (!parent.ok()) return parent.error();
      const auto child = in.parse<int>(child_token, range);
      if (!child.ok()) return child.error();
      if (*parent < 1 || *parent > joint_count) return in.error(range + " (parent)", parent_token);
      if (*child < 1 || *child > joint_count) return in.error(range + " (child)", child_token);
      if (*child == *parent) return in.error("a child joint other than the parent", child_token);
      bones.insert(bones.end(), {*parent - 1, *child - 1});
      // Any further columns are libigl's edge flags.
    }
  }
  if (joints.empty()) {
    return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": no joints (`index x y z` lines)");
  }
  TgfSkeleton skeleton;
  skeleton.joints = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(
      joints.data(), static_cast<Eigen::Index>(joints.size() / 3), 3);
  skeleton.bones = Eigen::Map<const Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>>(
      bones.data(), static_cast<Eigen::Index>(bones.size() / 2), 2);
  return skeleton;
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

Result<Eigen::MatrixXd> parse_dmat(std::string_view text, std::string_view source) try {
  TextReader in(text, source);
  if (!in.next_line()) return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": empty file, expected `cols rows`");
  const auto shape = read_dmat_shape(in);
  if (!shape.ok()) return shape.error();
  const int cols = shape->cols;
  const int rows = shape->rows;
  if (cols == 0 && rows == 0) {
    // libigl writes an empty matrix as a lone `0 0` and a binary one as `0 0` + binary header.
    if (in.rest_after_line().find_first_not_of(" \t\r\n") == std::string_view::npos) return Eigen::MatrixXd();
    in.next_line();
    return parse_binary_dmat(in, text, source);
  }
  // Every value takes at least one character and a separator: refuse a header claiming more
  // values than the file could hold before allocating for them.
  const int64_t count = int64_t{rows} * cols;
  if (count > static_cast<int64_t>(text.size())) {
    return in.error("at most " + std::to_string(text.size()) + " values for a file of that size",
                    std::to_string(cols) + " " + std::to_string(rows));
  }
  Eigen::MatrixXd matrix(rows, cols);
  // Value k in file order is entry k of the column-major storage. Counting values, not columns,
  // keeps an empty matrix of 2^31 - 1 columns from costing 2^31 loop turns (found by fuzzing).
  for (int64_t k = 0; k < count; ++k) {
    const std::string_view token = in.next_token_any_line();
    if (token.empty()) {
      return in.error("expected " + std::to_string(count) + " values (" + std::to_string(rows) + " rows × " +
                      std::to_string(cols) + " columns, column-major), got end of file after " + std::to_string(k));
    }
    const auto value = in.parse<double>(token, "a number");
    if (!value.ok()) return value.error();
    matrix.data()[k] = *value;
  }
  if (const std::string_view extra = in.next_token_any_line(); !extra.empty()) {
    return in.error("end of file after " + std::to_string(count) + " values", extra);
  }
  return matrix;
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

Result<std::vector<Eigen::Matrix<double, 4, 3>>> parse_tmat(std::string_view text, std::string_view source) try {
  std::vector<double> values;  // 3 per row
  TextReader in(text, source);
  while (in.next_line()) {
    std::string_view token = in.next_token();
    if (token.empty()) continue;
    for (int column = 0; column < 3; ++column, token = in.next_token()) {
      const auto value = in.parse<double>(token, "3 numbers per row");
      if (!value.ok()) return value.error();
      values.push_back(*value);
    }
    if (!token.empty()) return in.error("end of line after 3 numbers", token);
  }
  const size_t row_count = values.size() / 3;
  if (row_count == 0 || row_count % 4 != 0) {
    return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": expected a positive multiple of 4 rows (4 per bone), got " +
                                                       std::to_string(row_count));
  }
  std::vector<Eigen::Matrix<double, 4, 3>> transforms(row_count / 4);
  for (size_t bone = 0; bone < transforms.size(); ++bone) {
    transforms[bone] = Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(values.data() + 12 * bone);
  }
  return transforms;
} catch (const std::bad_alloc&) {
  return out_of_memory_reading(source);
}

Result<TgfSkeleton> read_tgf(const std::filesystem::path& path) { return parse_file<TgfSkeleton>(path, parse_tgf); }

Status write_tgf(const std::filesystem::path& path, const TgfSkeleton& skeleton) {
  // Refuse what read_tgf would refuse.
  if (skeleton.joints.rows() == 0) return make_error(ErrorCode::kInvalidArgument, path.string() + ": no joints to write");
  ANIMSPACE_RETURN_IF_ERROR(check_finite(skeleton.joints, path.string(), "joint coordinate"));
  for (Eigen::Index b = 0; b < skeleton.bones.rows(); ++b) {
    const auto bone = skeleton.bones.row(b);
    if (bone.minCoeff() < 0 || bone.maxCoeff() >= skeleton.joints.rows() || bone(0) == bone(1)) {
      return make_error(ErrorCode::kInvalidArgument,
                        path.string() + ": bone " + std::to_string(b) + " (" + std::to_string(bone(0)) + ", " +
                            std::to_string(bone(1)) + ") needs two different joints in 0.." +
                            std::to_string(skeleton.joints.rows() - 1));
    }
  }
  std::string text;
  for (Eigen::Index j = 0; j < skeleton.joints.rows(); ++j) {
    text += std::to_string(j + 1) + ' ';
    append_line(text, skeleton.joints.row(j));
  }
  text += "#\n";
  for (Eigen::Index b = 0; b < skeleton.bones.rows(); ++b) {
    text += std::to_string(skeleton.bones(b, 0) + 1) + ' ' + std::to_string(skeleton.bones(b, 1) + 1) + '\n';
  }
  text += "#\n";
  return write_file_atomically(path, text);
}

Result<Eigen::MatrixXd> read_dmat(const std::filesystem::path& path) {
  return parse_file<Eigen::MatrixXd>(path, parse_dmat);
}

Status write_dmat(const std::filesystem::path& path, const Eigen::MatrixXd& matrix) {
  ANIMSPACE_RETURN_IF_ERROR(check_finite(matrix, path.string(), "entry"));
  std::string text = std::to_string(matrix.cols()) + ' ' + std::to_string(matrix.rows()) + '\n';
  // Column-major, one value per line, as igl::writeDMAT.
  for (Eigen::Index j = 0; j < matrix.cols(); ++j) {
    for (Eigen::Index i = 0; i < matrix.rows(); ++i) {
      append_number(text, matrix(i, j));
      text += '\n';
    }
  }
  return write_file_atomically(path, text);
}

Result<std::vector<Eigen::Matrix<double, 4, 3>>> read_tmat(const std::filesystem::path& path) {
  return parse_file<std::vector<Eigen::Matrix<double, 4, 3>>>(path, parse_tmat);
}

Status write_tmat(const std::filesystem::path& path, const std::vector<Eigen::Matrix<double, 4, 3>>& transforms) {
  if (transforms.empty()) return make_error(ErrorCode::kInvalidArgument, path.string() + ": no transforms to write");
  std::string text;
  for (size_t bone = 0; bone < transforms.size(); ++bone) {
    ANIMSPACE_RETURN_IF_ERROR(check_finite(transforms[bone], path.string(), "bone " + std::to_string(bone) + " entry"));
    for (int row = 0; row < 4; ++row) append_line(text, transforms[bone].row(row));
  }
  return write_file_atomically(path, text);
}

}  // namespace animspace::mesh_io
