// The dense products the hot paths spend their time in, run by the kernel the process selected.
//
// The build targets baseline x86-64 (SSE2), so that `make run` and the container image work on
// any x86-64; Eigen's products are then compiled for SSE2 alone. Debian's OpenBLAS is built for
// every x86-64 too, but picks the code for the CPU it runs on when it loads (AVX2/FMA, AVX-512):
// the speed of the machine without giving up portability (issue #25). Both kernels compute the
// same products; only the order of the float additions differs.
//
// Measured on the 2-core AVX-512 development machine, crane's reconstruction (30006 × 61 float
// basis): one pose, sgemv 123 µs vs Eigen/SSE2 167 µs; OpenBLAS's sgemm is slower than one sgemv
// per pose below about 4 poses (444 µs for 1, 240 µs/pose for 2), faster from 4 on (65 µs/pose at
// 64): `kBlasGemmMinColumns`.
#pragma once

#include <string>

namespace animspace {

enum class Kernel {
  kPortable,  // Eigen, as compiled (baseline x86-64)
  kBlas,      // OpenBLAS, dispatched at load time to the CPU it runs on
};

// The kernel every product below uses. Process-wide, like the CPU it describes: set once at start
// (animspaced --kernel, a tool's flag) before any thread evaluates. Default: kBlas.
Kernel active_kernel();
void use_kernel(Kernel kernel);

// "openblas:<core>" (the core OpenBLAS chose for this CPU, e.g. "openblas:haswell") or
// "eigen:sse2" (the instruction set Eigen was compiled for).
std::string kernel_name(Kernel kernel);

// Parses "portable" / "blas" (a flag's value); false for anything else.
bool parse_kernel(const std::string& text, Kernel& out);

// Fewer columns than this: the BLAS kernel multiplies one column at a time (gemv).
inline constexpr long kBlasGemmMinColumns = 4;

// Products of at least this many multiplies per thread split the rows of C across the cores
// (parallel.h: a thread per kParallelProductMinMultiplies, at most one per core; issue #38 item 3).
// Measured on the 2-core development VM, one float sgemv of rows × M, best of 21 with the second
// core free: 1M multiplies 0.71× (starting a thread, ~20 µs, is not repaid), 1.8M 0.82×, 3M
// 1.13–1.15×, 6M 1.41×, 10M 1.65×, 30M (the papers' 300k × 100 illumination basis, memory-bound)
// 1.28×. So the split starts at 2 × 2M multiplies. On a shared machine whose other core is busy,
// the median gain is nil and a pose may wait a scheduler slice for the second thread.
inline constexpr long kParallelProductMinMultiplies = 2L << 20;
// Rows per unit of that split: a cache line of doubles, so two threads never write one line.
inline constexpr long kParallelProductRowGrain = 64;

// C = A·B + beta·C, column-major, A rows × inner (leading dimension lda), B inner × columns
// (ldb), C rows × columns (ldc). beta is 0 or 1.
void gemm(long rows, long inner, long columns, const float* a, long lda, const float* b, long ldb, float beta,
          float* c, long ldc);
void gemm(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb, double beta,
          double* c, long ldc);

// The same products on the calling thread alone, whatever their size: for results that must not
// depend on the machine's cores (the rows at a split's edge may round differently), e.g. a
// training whose model is the same on one thread and on two.
void gemm_serial(long rows, long inner, long columns, const float* a, long lda, const float* b, long ldb, float beta,
                 float* c, long ldc);
void gemm_serial(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb,
                 double beta, double* c, long ldc);

// C = Aᵀ·B + beta·C with A stored inner × rows (leading dimension lda), B inner × columns, C
// rows × columns: the coefficients of B's columns on A's columns (the PMSC's projections onto a
// basis, issue #38), on the calling thread alone like gemm_serial. beta is 0 or 1.
void gemm_transposed_serial(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb,
                            double beta, double* c, long ldc);

// The lower triangle (diagonal included) of XᵀX into `out` (columns × columns, leading dimension
// ldo; the strict upper triangle is left as it was), X rows × columns column-major (leading
// dimension ldx): the Gram matrices of the PMSC's PCA, on the calling thread alone like
// gemm_serial (issue #38: the key selection forms one per iteration).
void gram_lower_serial(long rows, long columns, const float* x, long ldx, float* out, long ldo);
void gram_lower_serial(long rows, long columns, const double* x, long ldx, double* out, long ldo);

// The thin SVD A = U diag(s) Vᵀ of A (rows × columns, column-major, leading dimension lda), k =
// min(rows, columns): s (k, descending), U (rows × k, leading dimension ldu) and Vᵀ (k × columns,
// ldvt), on the calling thread. The BLAS kernel runs LAPACK's divide and conquer (dgesdd, in
// OpenBLAS); the portable one Eigen's (BDCSVD, SSE2 alone): an articulated model's key basis is
// 1,900 × 425 on crane, decomposed at every key-selection step and calibration fold (issue #51),
// where Eigen's was a quarter of the training's time. Should LAPACK report no convergence, Eigen's
// is taken.
void thin_svd_serial(long rows, long columns, const double* a, long lda, double* s, double* u, long ldu, double* vt,
                     long ldvt);

}  // namespace animspace
