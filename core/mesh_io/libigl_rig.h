// A linear-blend-skinned rig in libigl's file formats (Jacobson et al., libigl: igl::readTGF,
// igl::readDMAT / igl::writeDMAT; described in ../shared/data/README.md):
//
// - TGF, the skeleton: one line per joint `index x y z` (index 1, 2, … in order), a line starting
//   with '#', one line per bone `parent child` (1-based joint indices; libigl may append flag
//   columns "is bone / is pseudo-edge / is cage-edge", which are ignored), optionally a second
//   '#' and a third section, which libigl ignores and so do we.
// - DMAT, a dense matrix: first line `cols rows`, then the rows·cols values in column-major order
//   (all of column 0 first), whitespace separated. For skinning weights it is #V by #B: entry
//   (v, j) is the weight of bone j on vertex v. libigl's binary variant is also read: a `0 0`
//   line, a `cols rows` line, then rows·cols little endian float64 values, column-major.
// - Tmat, per-bone transforms: for each bone a block of 4 rows × 3 columns in row-vector form,
//   posed_v = Σ_j w_vj · [v_x v_y v_z 1] · T_j (rows 0–2: linear part, row 3: translation).
//
// Text parse errors are kInvalidArgument and read `file:line: expected …, got …`; files are
// written atomically (write_file_atomically) with the shortest decimals that read back to the
// same float64 (at most 17 significant digits), so writing then reading is exact.
#pragma once

#include <filesystem>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"

namespace animspace::mesh_io {

struct TgfSkeleton {
  Eigen::MatrixX3d joints;  // #J by 3 joint positions, in the rig's units (the mesh's)
  Eigen::MatrixX2i bones;   // #B by 2 zero-based (parent joint, child joint)
};

// Errors: kInvalidArgument for a malformed line, a joint index out of order, a bone joint outside
// 1..#J or equal to its parent, or no joints; kNotFound / kIo from the read.
Result<TgfSkeleton> read_tgf(const std::filesystem::path& path);
// Errors: kInvalidArgument for no joints, a non-finite joint, or a bone whose joints are outside
// [0, #J) or equal; kIo.
Status write_tgf(const std::filesystem::path& path, const TgfSkeleton& skeleton);

// Returns the rows by cols matrix. Errors: kInvalidArgument for a malformed header or value,
// fewer or more values than the header says, or a non-finite value; kDataLoss for a binary
// payload of the wrong size; kNotFound / kIo from the read.
Result<Eigen::MatrixXd> read_dmat(const std::filesystem::path& path);
// Writes the text variant. Errors: kInvalidArgument for a non-finite value; kIo.
Status write_dmat(const std::filesystem::path& path, const Eigen::MatrixXd& matrix);

// One 4 by 3 transform per bone, in file order. Errors: kInvalidArgument for a line without
// exactly 3 numbers, a row count that is not a positive multiple of 4; kNotFound / kIo.
Result<std::vector<Eigen::Matrix<double, 4, 3>>> read_tmat(const std::filesystem::path& path);
// Errors: kInvalidArgument for no transforms or a non-finite value; kIo.
Status write_tmat(const std::filesystem::path& path, const std::vector<Eigen::Matrix<double, 4, 3>>& transforms);

// Parsers of file contents: read_tgf, read_dmat and read_tmat are the file read plus these.
// `source` (usually the file name) prefixes every error. Errors: those of the read_* functions
// other than kNotFound / kIo, and kResourceExhausted when memory runs out.
Result<TgfSkeleton> parse_tgf(std::string_view text, std::string_view source);
Result<Eigen::MatrixXd> parse_dmat(std::string_view bytes, std::string_view source);  // text or binary
Result<std::vector<Eigen::Matrix<double, 4, 3>>> parse_tmat(std::string_view text, std::string_view source);

}  // namespace animspace::mesh_io
