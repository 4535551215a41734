// The articulated kind's runtime (issue #51; articulated.h): the basis's skinning columns read
// back, once at load, as each point's influences, so that a reconstruction costs a few terms per
// point instead of a row of 12·B mostly-zero columns. The dense product mean + A p
// (pmsc::reconstruct) gives the same points and stays the reference: a client holding the whole
// basis reconstructs that way (coordinates.h).
#include <cassert>
#include <cstdint>
#include <cstring>

#if defined(__x86_64__)
#include <immintrin.h>
#endif
#include <string>
#include <vector>

#include <Eigen/Cholesky>

#include "core/common/kernels.h"
#include "core/pmsc/articulated.h"
#include "core/pmsc/key_projection.h"
#include "core/pmsc/skinned_basis.h"
#include "core/pmsc/subspace.h"

namespace animspace::pmsc {
namespace {

// f_i += Σ_k T_{bone k} h_k over point i's terms, T a bone's transform as four columns of four
// floats: each of h's four numbers broadcast and multiplied by its column. The even terms are
// summed apart from the odd ones and the two sums added at the end, so that AVX takes a pair of
// terms in one register (the next term's h is the next four floats: one load holds both) while
// the baseline keeps two registers; neither has FMA, so both round every product and sum alike
// and a pose is the same on every machine.
#if defined(__x86_64__)
template <int c>
__attribute__((always_inline)) inline __m128 term_column(const float* T, __m128 h) {
  return _mm_mul_ps(_mm_loadu_ps(T + 4 * c), _mm_shuffle_ps(h, h, c * 0x55));
}

__attribute__((always_inline)) inline __m128 term(const float* T, __m128 h) {
  return _mm_add_ps(_mm_add_ps(_mm_add_ps(term_column<0>(T, h), term_column<1>(T, h)), term_column<2>(T, h)),
                    term_column<3>(T, h));
}

void add_skinning_baseline(const SkinningTerms& skinning, const float* transforms, long point_count, float* f) {
  const int32_t* offsets = skinning.offsets.data();
  const int32_t* bones = skinning.bones.data();
  const float* terms = skinning.terms.data();
  for (long i = 0; i < point_count; ++i) {
    __m128 even = _mm_setzero_ps(), odd = _mm_setzero_ps();
    int32_t k = offsets[i];
    const int32_t end = offsets[i + 1];
    for (; k + 1 < end; k += 2) {
      even = _mm_add_ps(even, term(transforms + 16L * bones[k], _mm_loadu_ps(terms + 4L * k)));
      odd = _mm_add_ps(odd, term(transforms + 16L * bones[k + 1], _mm_loadu_ps(terms + 4L * k + 4)));
    }
    if (k < end) even = _mm_add_ps(even, term(transforms + 16L * bones[k], _mm_loadu_ps(terms + 4L * k)));
    alignas(16) float total[4];
    _mm_store_ps(total, _mm_add_ps(even, odd));
    for (int r = 0; r < 3; ++r) f[3 * i + r] += total[r];
  }
}

template <int c>
__attribute__((target("avx"), always_inline)) inline __m256 pair_column(const float* a, const float* b, __m256 h) {
  const __m256 column =
      _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a + 4 * c)), _mm_loadu_ps(b + 4 * c), 1);
  return _mm256_mul_ps(column, _mm256_permute_ps(h, c * 0x55));
}

__attribute__((target("avx"))) void add_skinning_avx(const SkinningTerms& skinning, const float* transforms,
                                                     long point_count, float* f) {
  const int32_t* offsets = skinning.offsets.data();
  const int32_t* bones = skinning.bones.data();
  const float* terms = skinning.terms.data();
  for (long i = 0; i < point_count; ++i) {
    __m256 sums = _mm256_setzero_ps();  // even terms low, odd terms high
    int32_t k = offsets[i];
    const int32_t end = offsets[i + 1];
    for (; k + 1 < end; k += 2) {
      const float* a = transforms + 16L * bones[k];
      const float* b = transforms + 16L * bones[k + 1];
      const __m256 h = _mm256_loadu_ps(terms + 4L * k);
      const __m256 first_two = _mm256_add_ps(pair_column<0>(a, b, h), pair_column<1>(a, b, h));
      const __m256 pair = _mm256_add_ps(_mm256_add_ps(first_two, pair_column<2>(a, b, h)), pair_column<3>(a, b, h));
      sums = _mm256_add_ps(sums, pair);
    }
    __m128 even = _mm256_castps256_ps128(sums);
    const __m128 odd = _mm256_extractf128_ps(sums, 1);
    if (k < end) even = _mm_add_ps(even, term(transforms + 16L * bones[k], _mm_loadu_ps(terms + 4L * k)));
    alignas(16) float total[4];
    _mm_store_ps(total, _mm_add_ps(even, odd));
    for (int r = 0; r < 3; ++r) f[3 * i + r] += total[r];
  }
}

using SkinningFunction = void (*)(const SkinningTerms&, const float*, long, float*);

// The widest the machine has (chosen once) under the BLAS kernel; the baseline under the portable
// one, which promises nothing beyond baseline x86-64 (kernels.h).
void add_skinning(const SkinningTerms& skinning, const float* transforms, long point_count, float* f) {
  static const SkinningFunction widest = __builtin_cpu_supports("avx") ? add_skinning_avx : add_skinning_baseline;
  (active_kernel() == Kernel::kBlas ? widest : add_skinning_baseline)(skinning, transforms, point_count, f);
}
#else
void add_skinning(const SkinningTerms& skinning, const float* transforms, long point_count, float* f) {
  const int32_t* offsets = skinning.offsets.data();
  for (long i = 0; i < point_count; ++i) {
    Eigen::Vector4f even = Eigen::Vector4f::Zero(), odd = Eigen::Vector4f::Zero();
    for (int32_t k = offsets[i]; k < offsets[i + 1]; ++k) {
      const Eigen::Map<const Eigen::Matrix4f> T(transforms + 16L * skinning.bones[static_cast<size_t>(k)]);
      const Eigen::Map<const Eigen::Vector4f> h(skinning.terms.data() + 4L * k);
      ((k - offsets[i]) % 2 == 0 ? even : odd).noalias() += T * h;
    }
    Eigen::Map<Eigen::Vector3f>(f + 3 * i) += (even + odd).head<3>();
  }
}
#endif

// Eq. 2 through the same terms: p = (A_keyᵀ A_key + λI)⁻¹ A_keyᵀ (f_key − key_mean), with
// A_keyᵀ c and A_key p read off each key's few skinning terms and the residual columns, and the
// normal equations solved by blocks formed once at load. Mathematically the dense projection
// (pmsc_model.h: P = V diag(σ/(σ² + λ)) Uᵀ is the same inverse times A_keyᵀ); the normal
// equations lose up to κ² of precision where P loses κ, so only a basis whose A_key has κ up
// to kSparseKeyCondition takes this path (p then within ~1e-8 of P's, relatively).
//
// The blocks. Bone j's transform row ρ (ρ = x, y, z) meets only the key values of coordinate ρ,
// each through the same h_kj, so with the unknowns ordered by ρ the Gram matrix is
//   [ I₃ ⊗ (HᵀH + λI)   C ]      H: K × 4B, row k the h_kj of key k's bones,
//   [ Cᵀ       R + λI     ]      C: 12B × r, the bone rows against the residual columns,
// and the Schur complement S = R + λI − Cᵀ D⁻¹ C (r × r) gives
//   p_res = S⁻¹ (b_res − Wᵀ b_bone),  p_bone = D⁻¹ b_bone − W p_res,  W = D⁻¹ C,
// with D⁻¹ one 4B × 4B inverse used for all three rows. On crane (B = 32, r = 36) that is about
// 80 thousand multiplications and 250 kB read a pose, where the whole M × M inverse (M = 420)
// took 180 thousand and 0.7 MB (docs/BENCHMARKS.md, issue #51's third round).
constexpr double kSparseKeyCondition = 1e4;

class ArticulatedSubspace final : public Subspace {
 public:
  ArticulatedSubspace(std::shared_ptr<const PmscModel> model, SkinningTerms skinning)
      : Subspace(std::move(model)), skinning_(std::move(skinning)) {
    const PmscModel& m = this->model();
    if (m.cross || !(m.condition_number <= kSparseKeyCondition) || !read_key_terms()) return;
    const long K = static_cast<long>(m.key_points.size());
    const long nb = 4L * m.bone_count;
    const long r = m.residual_components;
    const double lambda = m.regularization;
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(K, nb);
    for (long k = 0; k < K; ++k) {
      for (int32_t e = key_offsets_[static_cast<size_t>(k)]; e < key_offsets_[static_cast<size_t>(k) + 1]; ++e) {
        H.row(k).segment<4>(4L * key_bones_[static_cast<size_t>(e)]) =
            Eigen::Map<const Eigen::RowVector4d>(key_terms_.data() + 4L * e);
      }
    }
    Eigen::MatrixXd bone_gram = Eigen::MatrixXd::Zero(nb, nb);
    bone_gram.selfadjointView<Eigen::Lower>().rankUpdate(H.transpose());
    bone_gram.diagonal().array() += lambda;
    bone_inverse_ = bone_gram.selfadjointView<Eigen::Lower>().ldlt().solve(Eigen::MatrixXd::Identity(nb, nb));
    if (r == 0) return;
    const auto residual_columns = m.key_basis.rightCols(r);
    Eigen::MatrixXd schur = residual_columns.transpose() * residual_columns;
    schur.diagonal().array() += lambda;
    coupling_.resize(nb, 3 * r);
    for (long row = 0; row < 3; ++row) {
      const Eigen::MatrixXd rows_of_coordinate = residual_columns(Eigen::seqN(row, K, 3), Eigen::all);
      const Eigen::MatrixXd C = H.transpose() * rows_of_coordinate;
      coupling_.middleCols(row * r, r) = bone_inverse_ * C;
      schur.noalias() -= C.transpose() * coupling_.middleCols(row * r, r);
    }
    schur_inverse_ = schur.selfadjointView<Eigen::Lower>().ldlt().solve(Eigen::MatrixXd::Identity(r, r));
  }

  void estimate(const Eigen::Ref<const Eigen::VectorXf>& key_values, const Eigen::Ref<const Eigen::VectorXf>& check_values,
                PoseEstimate& out) const override {
    if (bone_inverse_.size() == 0) {
      Subspace::estimate(key_values, check_values, out);
      return;
    }
    estimate_coordinates_with(model(), key_values, check_values, out,
                              [this](Eigen::VectorXd centred, Eigen::VectorXd& p) { return project(std::move(centred), p); });
  }

  // The residual columns as the linear kind's product (a block of rows at a time, for the whole
  // batch), then each point's bones from its skinning terms.
  void reconstruct(std::span<const PoseEstimate* const> estimates,
                   std::span<float* const> destinations) const override {
    assert(estimates.size() == destinations.size());
    const PmscModel& m = model();
    const long rows = m.basis.rows();
    const long B = static_cast<long>(estimates.size());
    if (B == 0) return;
    const long skinning = static_cast<long>(kBoneCoordinates) * m.bone_count;
    const long r = m.residual_components;
    Eigen::MatrixXf coordinates(m.basis.cols(), B);
    for (long b = 0; b < B; ++b) coordinates.col(b) = estimates[static_cast<size_t>(b)]->coordinates.cast<float>();
    const long block = std::max(kReconstructionBlockValues / B, 256L);
    const Eigen::MatrixXf residual_coordinates = coordinates.bottomRows(r);
    if (B == 1) {  // one pose (a unary call): the product adds straight onto the mean
      float* f = destinations.front();
      Eigen::Map<Eigen::VectorXf>(f, rows) = m.mean;
      if (r > 0) {
        gemm(rows, r, 1, m.basis.data() + skinning * rows, rows, residual_coordinates.data(), r, 1.0f, f, rows);
      }
    }
    Eigen::MatrixXf scratch(B == 1 ? 0 : std::min(block, rows), B);
    for (long r0 = 0; r0 < rows && B > 1; r0 += block) {
      const long n = std::min(block, rows - r0);
      if (r > 0) {
        gemm(n, r, B, m.basis.data() + skinning * rows + r0, rows, residual_coordinates.data(), r, 0.0f,
             scratch.data(), scratch.rows());
      }
      for (long b = 0; b < B; ++b) {
        Eigen::Map<Eigen::VectorXf> destination(destinations[static_cast<size_t>(b)] + r0, n);
        destination = m.mean.segment(r0, n);
        if (r > 0) destination += scratch.col(b).head(n);
      }
    }
    // Each bone's 3 × 4 transform as four columns of four floats (the fourth row 0).
    std::vector<float> transforms(16 * static_cast<size_t>(m.bone_count));
    for (long b = 0; b < B; ++b) {
      const float* p = coordinates.col(b).data();
      for (int j = 0; j < m.bone_count; ++j) {
        Eigen::Map<Eigen::Matrix4f> T(transforms.data() + 16L * j);
        T.topRows<3>() = Eigen::Map<const Eigen::Matrix<float, 3, 4, Eigen::RowMajor>>(
            p + static_cast<long>(kBoneCoordinates) * j);
        T.row(3).setZero();
      }
      add_skinning(skinning_, transforms.data(), m.point_count, destinations[static_cast<size_t>(b)]);
    }
  }

 private:
  // The key rows' skinning terms as P was made of them: A_key in double (pmsc.key_basis, the
  // training basis before the float32 it is served in), in the form read_skinning_terms checks.
  // False (the dense projection is used) for key rows of any other form.
  bool read_key_terms() {
    const PmscModel& m = model();
    const long K = static_cast<long>(m.key_points.size());
    key_offsets_.assign(1, 0);
    for (long k = 0; k < K; ++k) {
      for (int j = 0; j < m.bone_count; ++j) {
        const auto block = m.key_basis.block(3 * k, static_cast<long>(kBoneCoordinates) * j, 3, kBoneCoordinates);
        const Eigen::RowVector4d h = block.block<1, 4>(0, 0);
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < kBoneCoordinates; ++c) {
            if (block(r, c) != (c / 4 == r ? h(c % 4) : 0.0)) return false;
          }
        }
        if ((h.array() == 0.0).all()) continue;
        key_bones_.push_back(j);
        key_terms_.insert(key_terms_.end(), h.data(), h.data() + 4);
      }
      key_offsets_.push_back(static_cast<int32_t>(key_bones_.size()));
    }
    return true;
  }

  // The key projection above: p from the centred key values, and the key residual.
  Eigen::VectorXd project(Eigen::VectorXd centred, Eigen::VectorXd& p) const {
    const PmscModel& m = model();
    const long M = m.basis.cols();
    const long K = static_cast<long>(m.key_points.size());
    const long r = m.residual_components;
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(M);
    for (long k = 0; k < K; ++k) {
      for (int32_t e = key_offsets_[static_cast<size_t>(k)]; e < key_offsets_[static_cast<size_t>(k) + 1]; ++e) {
        const double* h = key_terms_.data() + 4L * e;
        double* column = rhs.data() + static_cast<long>(kBoneCoordinates) * key_bones_[static_cast<size_t>(e)];
        for (int row = 0; row < 3; ++row) {
          for (int c = 0; c < 4; ++c) column[4 * row + c] += h[c] * centred(3 * k + row);
        }
      }
    }
    // The dense parts through the process's kernel (kernels.h): at M ≈ 425 the M × M product is
    // most of an estimate, and Eigen's is compiled for SSE2 alone.
    const long KD = centred.size();
    const double* residual_block = m.key_basis.data() + (M - r) * KD;
    if (r > 0) gemm_transposed_serial(r, KD, 1, residual_block, KD, centred.data(), KD, 0.0, rhs.data() + (M - r), M);
    // The block solve of the comment above, the bone rows gathered by transform row ρ.
    const long nb = 4L * m.bone_count;
    Eigen::MatrixXd bone_rhs(nb, 3), bone_p(nb, 3);
    for (long j = 0; j < m.bone_count; ++j) {
      for (int row = 0; row < 3; ++row) {
        bone_rhs.col(row).segment<4>(4 * j) = rhs.segment<4>(kBoneCoordinates * j + 4 * row);
      }
    }
    gemm_serial(nb, nb, 3, bone_inverse_.data(), nb, bone_rhs.data(), nb, 0.0, bone_p.data(), nb);
    p.resize(M);
    if (r > 0) {
      Eigen::VectorXd coupled(r);
      for (int row = 0; row < 3; ++row) {
        gemm_transposed_serial(r, nb, 1, coupling_.data() + row * r * nb, nb, bone_rhs.col(row).data(), nb,
                               row == 0 ? 0.0 : 1.0, coupled.data(), r);
      }
      const Eigen::VectorXd reduced = rhs.tail(r) - coupled;
      p.tail(r).noalias() = schur_inverse_ * reduced;
      const Eigen::VectorXd minus_residual = -p.tail(r);
      for (int row = 0; row < 3; ++row) {
        double* bone_row = bone_p.col(row).data();
        gemm_serial(nb, r, 1, coupling_.data() + row * r * nb, nb, minus_residual.data(), r, 1.0, bone_row, nb);
      }
    }
    for (long j = 0; j < m.bone_count; ++j) {
      for (int row = 0; row < 3; ++row) {
        p.segment<4>(kBoneCoordinates * j + 4 * row) = bone_p.col(row).segment<4>(4 * j);
      }
    }
    for (long k = 0; k < K; ++k) {
      for (int32_t e = key_offsets_[static_cast<size_t>(k)]; e < key_offsets_[static_cast<size_t>(k) + 1]; ++e) {
        const double* h = key_terms_.data() + 4L * e;
        const double* M_j = p.data() + static_cast<long>(kBoneCoordinates) * key_bones_[static_cast<size_t>(e)];
        for (int row = 0; row < 3; ++row) {
          double f = 0;
          for (int c = 0; c < 4; ++c) f += h[c] * M_j[4 * row + c];
          centred(3 * k + row) -= f;
        }
      }
    }
    if (r > 0) {
      const Eigen::VectorXd minus_coefficients = -p.tail(r);
      gemm_serial(KD, r, 1, residual_block, KD, minus_coefficients.data(), r, 1.0, centred.data(), KD);
    }
    return centred;
  }

  SkinningTerms skinning_;
  // Key k's bones key_bones_[key_offsets_[k] … key_offsets_[k + 1]) with their h (4 each).
  std::vector<int32_t> key_offsets_, key_bones_;
  std::vector<double> key_terms_;
  // The block solve's D⁻¹ = (HᵀH + λI)⁻¹ (4B × 4B; empty: the dense projection), W = D⁻¹ C for the
  // rows x, y, z side by side (4B × 3r) and S⁻¹ (r × r).
  Eigen::MatrixXd bone_inverse_, coupling_, schur_inverse_;
};

}  // namespace

Result<std::shared_ptr<const Subspace>> make_articulated_subspace(std::shared_ptr<const PmscModel> model) {
  assert(model->subspace_kind == SubspaceKind::kArticulated && !model->aligned);
  auto skinning = read_skinning_terms(*model);
  if (!skinning) return skinning.error();
  return std::shared_ptr<const Subspace>(std::make_shared<ArticulatedSubspace>(std::move(model), std::move(*skinning)));
}

}  // namespace animspace::pmsc
