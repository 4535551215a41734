// An articulated model's basis as its skinning holds it (issue #51 item 4): what GetBasis sends
// in the SKINNED layout, and what a client reconstructs answers with.
//
// The basis of an articulated model is [L | R] (articulated.h): L's 12 columns of bone j hold, at
// the three rows of point i, I_3 ⊗ h_ijᵀ with h_ij = w_ij (p̂_i − c_j, 1), and are zero where point
// i does not depend on bone j — with four bones a point of 32, seven values in eight. Kept as the
// K bones of each point and their terms, the basis is about a tenth of its dense size, and a
// point's reconstruction is its K bone maps applied to its terms plus its residual rows:
//   f̂_i = mean_i + Σ_{slots (j, h)} M_j h + Σ_k R_ik p_{12B+k},   M_j = p[12j … 12j + 11] (3 × 4)
// — 1 + 4K + r terms per value instead of M + 1, the same rounding bound (coordinates.h).
//
// It is the same basis, not an approximation: skinned_basis() keeps a model's skinned form only
// when it expands to the dense basis's very float32 values, so basis_checksum and basis_sha256
// name both and a client checks a skinned copy by expanding it through the digests.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

// An articulated basis's skinning columns read as terms: point i's bones are
// bones[offsets[i] … offsets[i + 1]) (0-based, columns 12·j …), each with its four numbers
// h = w·(p̂ − c, 1) in terms (4 per influence), so that
//   f̂_i = mean_i + Σ_j M_j h_ij + (residual rows) · p_residual.
// The server's runtime (articulated_subspace.cpp) reconstructs from them; skinned_basis pads them.
struct SkinningTerms {
  std::vector<int32_t> offsets;
  std::vector<int32_t> bones;
  std::vector<float> terms;
};
// Errors: kInvalidArgument naming the point and bone of a basis whose bone columns are not of the
// skinning form (h_ij in each row's four columns of the bone, 0 elsewhere). A corrupt or hand-made
// file would otherwise be reconstructed differently by the server, which reads the terms, and by
// a client, which reads the whole basis.
Result<SkinningTerms> read_skinning_terms(const PmscModel& model);

// Values in one slot as GetBasis sends it: the bone's number, then h's four.
inline constexpr int kSlotValues = 5;

struct SkinnedBasis {
  long point_count = 0;        // N; 3 channels
  int bone_count = 0;          // B
  int influences = 0;          // K, slots per point
  Eigen::VectorXf mean;        // 3N
  std::vector<int32_t> bones;  // N·K: slot k of point i at i·K + k; a padding slot is bone 0 with h = 0
  std::vector<float> terms;    // 4·N·K: h of slot s at 4s … 4s + 3
  Eigen::MatrixXf residuals;   // 3N × r, the basis's last r columns

  long basis_size() const { return 12L * bone_count + residuals.cols(); }  // M
};

// The skinned form of an articulated model's basis. Errors: kFailedPrecondition for a linear or
// cross model, or a basis that does not expand back to its own values (then only the dense
// layout is offered), naming the first value that differs.
Result<SkinnedBasis> skinned_basis(const PmscModel& model);

// Its values in GetBasis's order: the mean, the N·K slots of kSlotValues, the residual columns.
std::vector<float> skinned_values(const SkinnedBasis& basis);
// The slots alone (N·K·kSlotValues values): what a server holds besides the model's own mean and
// residual columns, which it sends from where they lie.
std::vector<float> skinned_slot_values(const SkinnedBasis& basis);
// The inverse, for a client: `values` as skinned_values lays them out for N points, B bones, K
// slots and M = 12B + r. kInvalidArgument naming the count, or the point and slot of a bone
// number that is not an integer in [0, B).
Result<SkinnedBasis> skinned_basis_from_values(std::span<const float> values, long point_count, int bone_count,
                                               int influences, long basis_size);

// basis_checksum and basis_sha256 (coordinates.h) of the dense basis this expands to, computed a
// column at a time: equal to the model's own exactly when the copy is that basis.
uint64_t basis_checksum(const SkinnedBasis& basis);
std::string basis_sha256(const SkinnedBasis& basis);

// f̂ = R (mean + A p) + t for one pose with the skinned form (`p`: M values), into `out` (3N
// floats). Per value within coordinates_rounding_bound(M) · (|mean_i| + Σ_j |A_ij p_j|) of the
// server's dense answer, as reconstruct_coordinates is.
void reconstruct_coordinates(const SkinnedBasis& basis, const float* p, const FloatAlignment* alignment, float* out);

}  // namespace animspace::pmsc
