#include "core/pmsc/skinned_basis.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/common/kernels.h"
#include "core/common/sha256.h"
#include "core/container/crc32.h"
#include "core/pmsc/articulated.h"

namespace animspace::pmsc {
namespace {

std::string number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", value);
  return text;
}

// A slot whose four terms are 0 stands for nothing (the padding of a point with fewer bones).
bool padding(const SkinnedBasis& b, size_t slot) {
  const float* h = b.terms.data() + 4 * slot;
  return h[0] == 0 && h[1] == 0 && h[2] == 0 && h[3] == 0;
}

// Calls `take(column)` with each column of the dense basis the skinned form expands to, in order
// (N·3 floats each): bone j's 12 from its slots, then the residual columns.
template <typename Take>
void for_each_dense_column(const SkinnedBasis& b, Take&& take) {
  const long rows = 3 * b.point_count;
  const auto slots = b.bones.size();
  // The slots of each bone, so that a column costs its own entries and one clearing.
  std::vector<std::vector<size_t>> slots_of(static_cast<size_t>(b.bone_count));
  for (size_t s = 0; s < slots; ++s) {
    if (padding(b, s)) continue;
    slots_of[static_cast<size_t>(b.bones[s])].push_back(s);
  }
  std::vector<float> column(static_cast<size_t>(rows), 0.0f);
  for (int j = 0; j < b.bone_count; ++j) {
    for (int a = 0; a < 3; ++a) {
      for (int c = 0; c < 4; ++c) {
        for (const size_t s : slots_of[static_cast<size_t>(j)]) {
          column[3 * (s / static_cast<size_t>(b.influences)) + static_cast<size_t>(a)] = b.terms[4 * s + static_cast<size_t>(c)];
        }
        take(std::span<const float>(column));
        for (const size_t s : slots_of[static_cast<size_t>(j)]) {
          column[3 * (s / static_cast<size_t>(b.influences)) + static_cast<size_t>(a)] = 0.0f;
        }
      }
    }
  }
  for (long k = 0; k < b.residuals.cols(); ++k) {
    take(std::span<const float>(b.residuals.col(k).data(), static_cast<size_t>(rows)));
  }
}

}  // namespace

Result<SkinningTerms> read_skinning_terms(const PmscModel& m) {
  if (m.channel_count != 3 || m.bone_count < 0 || m.basis_size() < static_cast<long>(kBoneCoordinates) * m.bone_count) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pmsc model: an articulated basis has 3 channels and at least 12·B = " +
                          std::to_string(12L * m.bone_count) + " columns; this one has " +
                          std::to_string(m.channel_count) + " and " + std::to_string(m.basis_size()));
  }
  SkinningTerms out;
  out.offsets.reserve(static_cast<size_t>(m.point_count) + 1);
  out.offsets.push_back(0);
  for (long i = 0; i < m.point_count; ++i) {
    for (int j = 0; j < m.bone_count; ++j) {
      const auto block = m.basis.block(3 * i, static_cast<long>(kBoneCoordinates) * j, 3, kBoneCoordinates);
      const Eigen::RowVector4f h = block.block<1, 4>(0, 0);
      bool skinning_form = true;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < kBoneCoordinates; ++c) {
          const float expected = c / 4 == r ? h(c % 4) : 0.0f;
          skinning_form = skinning_form && block(r, c) == expected;
        }
      }
      if (!skinning_form) {
        return make_error(ErrorCode::kInvalidArgument,
                          "pmsc model: an articulated basis's bone columns must have the skinning form "
                          "(w·(p̂ − c, 1) in each row's four columns of the bone, 0 elsewhere); point " +
                              std::to_string(i) + ", bone " + std::to_string(j) + " does not");
      }
      if ((h.array() == 0.0f).all()) continue;  // exactly: a weight of 1e-6 is still a term
      out.bones.push_back(j);
      out.terms.insert(out.terms.end(), h.data(), h.data() + 4);
    }
    out.offsets.push_back(static_cast<int32_t>(out.bones.size()));
  }
  return out;
}

Result<SkinnedBasis> skinned_basis(const PmscModel& m) {
  if (m.subspace_kind != SubspaceKind::kArticulated || m.cross || m.channel_count != 3) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "the skinned layout is an articulated model's (subspace_kind articulated, 3 channels); this "
                      "one is " + std::string(subspace_kind_name(m.subspace_kind)));
  }
  SkinnedBasis b;
  b.point_count = m.point_count;
  b.bone_count = m.bone_count;
  b.mean = m.mean;
  auto read = read_skinning_terms(m);
  if (!read) return make_error(ErrorCode::kFailedPrecondition, read.error().message);
  const SkinningTerms& terms = *read;
  b.residuals = m.basis.rightCols(m.basis_size() - static_cast<long>(kBoneCoordinates) * m.bone_count);
  for (size_t i = 0; i < static_cast<size_t>(b.point_count); ++i) {
    b.influences = std::max(b.influences, terms.offsets[i + 1] - terms.offsets[i]);
  }
  // K slots a point, its own bones first and padding after.
  const auto K = static_cast<size_t>(b.influences);
  b.bones.assign(static_cast<size_t>(b.point_count) * K, 0);
  b.terms.assign(4 * b.bones.size(), 0.0f);
  for (long i = 0; i < b.point_count; ++i) {
    const auto first = static_cast<size_t>(terms.offsets[static_cast<size_t>(i)]);
    const auto count = static_cast<size_t>(terms.offsets[static_cast<size_t>(i) + 1]) - first;
    const size_t s = static_cast<size_t>(i) * K;
    std::copy_n(terms.bones.begin() + static_cast<long>(first), count, b.bones.begin() + static_cast<long>(s));
    std::copy_n(terms.terms.begin() + static_cast<long>(4 * first), 4 * count,
                b.terms.begin() + static_cast<long>(4 * s));
  }
  // The same values, or no skinned form: compared column by column, bit for bit.
  long column = 0;
  std::string differs;
  for_each_dense_column(b, [&](std::span<const float> values) {
    if (differs.empty() && std::memcmp(values.data(), m.basis.col(column).data(), values.size_bytes()) != 0) {
      long row = 0;
      while (std::memcmp(&values[static_cast<size_t>(row)], &m.basis(row, column), sizeof(float)) == 0) ++row;
      differs = "basis value " + std::to_string(row) + " of column " + std::to_string(column) + " is " +
                number(m.basis(row, column)) + ", its skinned form gives " + number(values[static_cast<size_t>(row)]);
    }
    ++column;
  });
  if (!differs.empty()) {
    return make_error(ErrorCode::kFailedPrecondition, "the basis is not of the skinning form: " + differs);
  }
  return b;
}

std::vector<float> skinned_slot_values(const SkinnedBasis& b) {
  std::vector<float> values;
  values.reserve(kSlotValues * b.bones.size());
  for (size_t s = 0; s < b.bones.size(); ++s) {
    values.push_back(static_cast<float>(b.bones[s]));
    values.insert(values.end(), b.terms.begin() + static_cast<long>(4 * s), b.terms.begin() + static_cast<long>(4 * s + 4));
  }
  return values;
}

std::vector<float> skinned_values(const SkinnedBasis& b) {
  std::vector<float> values(b.mean.data(), b.mean.data() + b.mean.size());
  const std::vector<float> slots = skinned_slot_values(b);
  values.insert(values.end(), slots.begin(), slots.end());
  values.insert(values.end(), b.residuals.data(), b.residuals.data() + b.residuals.size());
  return values;
}

Result<SkinnedBasis> skinned_basis_from_values(std::span<const float> values, long point_count, int bone_count,
                                               int influences, long basis_size) {
  const long residuals = basis_size - 12L * bone_count;
  if (point_count < 1 || bone_count < 1 || influences < 1 || residuals < 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "skinned basis: N = " + std::to_string(point_count) + ", B = " + std::to_string(bone_count) +
                          ", K = " + std::to_string(influences) + " and M = " + std::to_string(basis_size) +
                          ": expected N, B, K ≥ 1 and M ≥ 12·B");
  }
  const auto slots = static_cast<size_t>(point_count) * static_cast<size_t>(influences);
  const size_t rows = 3 * static_cast<size_t>(point_count);
  const size_t expected = rows * static_cast<size_t>(residuals + 1) + kSlotValues * slots;
  if (values.size() != expected) {
    return make_error(ErrorCode::kInvalidArgument, "skinned basis: " + std::to_string(values.size()) +
                                                       " values, expected N·3·(r + 1) + 5·N·K = " +
                                                       std::to_string(expected));
  }
  SkinnedBasis b;
  b.point_count = point_count;
  b.bone_count = bone_count;
  b.influences = influences;
  b.mean = Eigen::Map<const Eigen::VectorXf>(values.data(), static_cast<long>(rows));
  b.bones.resize(slots);
  b.terms.resize(4 * slots);
  const float* slot = values.data() + rows;
  for (size_t s = 0; s < slots; ++s, slot += kSlotValues) {
    const float j = slot[0];
    if (!(j >= 0 && j < static_cast<float>(bone_count) && j == std::floor(j))) {
      return make_error(ErrorCode::kInvalidArgument,
                        "skinned basis: slot " + std::to_string(s % static_cast<size_t>(influences)) + " of point " +
                            std::to_string(s / static_cast<size_t>(influences)) + " names bone " + number(j) +
                            ", expected an integer in [0, " + std::to_string(bone_count) + ")");
    }
    b.bones[s] = static_cast<int32_t>(j);
    std::copy(slot + 1, slot + kSlotValues, b.terms.begin() + static_cast<long>(4 * s));
  }
  // A bone in two live slots of a point would be added twice by the reconstruction but expand to
  // one column entry: the digests could not vouch for the answers.
  for (size_t i = 0; i < static_cast<size_t>(point_count); ++i) {
    const size_t first = i * static_cast<size_t>(influences);
    for (size_t s = first; s < first + static_cast<size_t>(influences); ++s) {
      if (padding(b, s)) continue;
      for (size_t t = first; t < s; ++t) {
        if (!padding(b, t) && b.bones[t] == b.bones[s]) {
          return make_error(ErrorCode::kInvalidArgument,
                            "skinned basis: point " + std::to_string(i) + " names bone " + std::to_string(b.bones[s]) +
                                " in slots " + std::to_string(t - first) + " and " + std::to_string(s - first));
        }
      }
    }
  }
  b.residuals = Eigen::Map<const Eigen::MatrixXf>(slot, static_cast<long>(rows), residuals);
  return b;
}

uint64_t basis_checksum(const SkinnedBasis& b) {
  uint32_t crc = 0;
  for_each_dense_column(b, [&](std::span<const float> column) { crc = container::crc32_update(crc, std::as_bytes(column)); });
  const uint32_t mean = container::crc32_update(
      0, std::as_bytes(std::span<const float>(b.mean.data(), static_cast<size_t>(b.mean.size()))));
  return (uint64_t{mean} << 32) | crc;
}

std::string basis_sha256(const SkinnedBasis& b) {
  Sha256 digest;
  digest.update(std::as_bytes(std::span<const float>(b.mean.data(), static_cast<size_t>(b.mean.size()))));
  for_each_dense_column(b, [&](std::span<const float> column) { digest.update(std::as_bytes(column)); });
  return digest.digest();
}

void reconstruct_coordinates(const SkinnedBasis& b, const float* p, const FloatAlignment* alignment, float* out) {
  const long rows = 3 * b.point_count;
  std::copy(b.mean.data(), b.mean.data() + rows, out);
  const long skinning = 12L * b.bone_count;
  if (b.residuals.cols() > 0) {
    gemm(rows, b.residuals.cols(), 1, b.residuals.data(), rows, p + skinning, b.residuals.cols(), 1.0f, out, rows);
  }
  const auto K = static_cast<size_t>(b.influences);
  for (long i = 0; i < b.point_count; ++i) {
    float* point = out + 3 * i;
    for (size_t k = 0; k < K; ++k) {
      const size_t s = static_cast<size_t>(i) * K + k;
      const float* h = b.terms.data() + 4 * s;
      const float* M = p + 12L * b.bones[s];  // row-major 3 × 4
      for (int a = 0; a < 3; ++a) {
        point[a] += M[4 * a] * h[0] + M[4 * a + 1] * h[1] + M[4 * a + 2] * h[2] + M[4 * a + 3] * h[3];
      }
    }
  }
  if (alignment != nullptr) to_world(*alignment, b.point_count, out);
}

}  // namespace animspace::pmsc
