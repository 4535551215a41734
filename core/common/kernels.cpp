#include "core/common/kernels.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cctype>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SVD>
#include <cblas.h>

// OpenBLAS's pthread build exports this (interface of its blas_server.c) but no header declares it.
extern "C" int blas_thread_shutdown_(void);
// LAPACK's divide-and-conquer SVD, which OpenBLAS carries; Debian ships no LAPACKE header with
// it, so the Fortran interface (arguments by reference, the hidden length of the one character
// argument last).
extern "C" void dgesdd_(const char* jobz, const int* m, const int* n, double* a, const int* lda, double* s, double* u,
                        const int* ldu, double* vt, const int* ldvt, double* work, const int* lwork, int* iwork, int* info,
                        size_t jobz_length);

#include "core/common/parallel.h"

namespace animspace {
namespace {

std::atomic<Kernel> active{Kernel::kBlas};

// OpenBLAS multiplies in the thread that calls it: the cores belong to the callers (the server's
// work pool, parallel.h's loops), and a product split again inside OpenBLAS would only add
// threads to share them. Set before main, so every product of the process — those called
// through here and a benchmark's direct cblas anchors alike — runs the same way. The pool that
// the pthread build started when it was loaded is then ended (its exported shutdown, the one it
// runs at exit and before a fork): with one thread it is never used, and its threads, started
// before main could block any signal, were where the kernel delivered the daemon's SIGTERM
// (under TSan, a signal taken there waited forever).
const bool kOneBlasThread = [] {
  openblas_set_num_threads(1);
  blas_thread_shutdown_();
  return true;
}();

template <typename T>
using Matrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>;
template <typename T>
using View = Eigen::Map<const Matrix<T>, 0, Eigen::OuterStride<>>;
template <typename T>
using Target = Eigen::Map<Matrix<T>, 0, Eigen::OuterStride<>>;

template <typename T>
void portable_gemm(long rows, long inner, long columns, const T* a, long lda, const T* b, long ldb, T beta, T* c,
                   long ldc) {
  const View<T> A(a, rows, inner, Eigen::OuterStride<>(lda));
  const View<T> B(b, inner, columns, Eigen::OuterStride<>(ldb));
  Target<T> C(c, rows, columns, Eigen::OuterStride<>(ldc));
  if (beta == T(0)) {
    C.noalias() = A * B;
  } else {
    C.noalias() += A * B;
  }
}

void portable_gemm_transposed(long rows, long inner, long columns, const double* a, long lda, const double* b,
                              long ldb, double beta, double* c, long ldc) {
  const View<double> A(a, inner, rows, Eigen::OuterStride<>(lda));
  const View<double> B(b, inner, columns, Eigen::OuterStride<>(ldb));
  Target<double> C(c, rows, columns, Eigen::OuterStride<>(ldc));
  if (beta == 0.0) {
    C.noalias() = A.transpose() * B;
  } else {
    C.noalias() += A.transpose() * B;
  }
}

template <typename T>
void portable_gram_lower(long rows, long columns, const T* x, long ldx, T* out, long ldo) {
  const View<T> X(x, rows, columns, Eigen::OuterStride<>(ldx));
  Target<T> G(out, columns, columns, Eigen::OuterStride<>(ldo));
  G.template triangularView<Eigen::Lower>().setZero();
  G.template selfadjointView<Eigen::Lower>().rankUpdate(X.transpose());
}

int blas_int(long n) {
  assert(n >= 0 && n <= 0x7fffffff);
  return static_cast<int>(n);
}

}  // namespace

Kernel active_kernel() { return active.load(std::memory_order_relaxed); }

void use_kernel(Kernel kernel) { active.store(kernel, std::memory_order_relaxed); }

std::string kernel_name(Kernel kernel) {
  if (kernel == Kernel::kPortable) {
#if defined(__AVX512F__)
    return "eigen:avx512";
#elif defined(__AVX2__)
    return "eigen:avx2";
#elif defined(__SSE2__)
    return "eigen:sse2";
#else
    return "eigen:scalar";
#endif
  }
  std::string core = openblas_get_corename();
  for (char& ch : core) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return "openblas:" + core;
}

bool parse_kernel(const std::string& text, Kernel& out) {
  if (text == "portable") {
    out = Kernel::kPortable;
  } else if (text == "blas") {
    out = Kernel::kBlas;
  } else {
    return false;
  }
  return true;
}

void gemm_serial(long rows, long inner, long columns, const float* a, long lda, const float* b, long ldb, float beta,
                 float* c, long ldc) {
  if (rows == 0 || columns == 0) return;
  if (active_kernel() == Kernel::kPortable) return portable_gemm(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
  if (columns < kBlasGemmMinColumns) {
    for (long j = 0; j < columns; ++j) {
      cblas_sgemv(CblasColMajor, CblasNoTrans, blas_int(rows), blas_int(inner), 1.0f, a, blas_int(lda), b + j * ldb, 1,
                  beta, c + j * ldc, 1);
    }
    return;
  }
  cblas_sgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, blas_int(rows), blas_int(columns), blas_int(inner), 1.0f, a,
              blas_int(lda), b, blas_int(ldb), beta, c, blas_int(ldc));
}

void gemm_serial(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb,
                 double beta, double* c, long ldc) {
  if (rows == 0 || columns == 0) return;
  if (active_kernel() == Kernel::kPortable) return portable_gemm(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
  if (columns < kBlasGemmMinColumns) {
    for (long j = 0; j < columns; ++j) {
      cblas_dgemv(CblasColMajor, CblasNoTrans, blas_int(rows), blas_int(inner), 1.0, a, blas_int(lda), b + j * ldb, 1,
                  beta, c + j * ldc, 1);
    }
    return;
  }
  cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, blas_int(rows), blas_int(columns), blas_int(inner), 1.0, a,
              blas_int(lda), b, blas_int(ldb), beta, c, blas_int(ldc));
}

void gemm_transposed_serial(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb,
                            double beta, double* c, long ldc) {
  if (rows == 0 || columns == 0) return;
  if (active_kernel() == Kernel::kPortable) {
    return portable_gemm_transposed(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
  }
  if (columns < kBlasGemmMinColumns) {
    for (long j = 0; j < columns; ++j) {
      cblas_dgemv(CblasColMajor, CblasTrans, blas_int(inner), blas_int(rows), 1.0, a, blas_int(lda), b + j * ldb, 1,
                  beta, c + j * ldc, 1);
    }
    return;
  }
  cblas_dgemm(CblasColMajor, CblasTrans, CblasNoTrans, blas_int(rows), blas_int(columns), blas_int(inner), 1.0, a,
              blas_int(lda), b, blas_int(ldb), beta, c, blas_int(ldc));
}

void gram_lower_serial(long rows, long columns, const float* x, long ldx, float* out, long ldo) {
  if (columns == 0) return;
  if (active_kernel() == Kernel::kPortable) return portable_gram_lower(rows, columns, x, ldx, out, ldo);
  cblas_ssyrk(CblasColMajor, CblasLower, CblasTrans, blas_int(columns), blas_int(rows), 1.0f, x, blas_int(ldx), 0.0f,
              out, blas_int(ldo));
}

void gram_lower_serial(long rows, long columns, const double* x, long ldx, double* out, long ldo) {
  if (columns == 0) return;
  if (active_kernel() == Kernel::kPortable) return portable_gram_lower(rows, columns, x, ldx, out, ldo);
  cblas_dsyrk(CblasColMajor, CblasLower, CblasTrans, blas_int(columns), blas_int(rows), 1.0, x, blas_int(ldx), 0.0, out,
              blas_int(ldo));
}

namespace {

// Rows of C split across the cores (issue #38 item 3): every row of C = A·B + beta·C depends on its
// own row of A only, so each thread runs the serial product on its own block of rows. A row's
// value may differ from the one-thread product by float rounding (the kernels treat the rows of
// a block's edges differently), never by more (kernels_test.cpp).
template <typename T>
void gemm_rows_split(long rows, long inner, long columns, const T* a, long lda, const T* b, long ldb, T beta, T* c,
                     long ldc) {
  const long units = (rows + kParallelProductRowGrain - 1) / kParallelProductRowGrain;
  const long per_unit = std::max(1L, kParallelProductRowGrain * inner * columns);
  const long min_units = (kParallelProductMinMultiplies + per_unit - 1) / per_unit;
  parallel_for_chunks(units, std::max(1L, min_units), [&](int64_t first, int64_t last) {
    const long r0 = static_cast<long>(first) * kParallelProductRowGrain;
    const long r1 = std::min(rows, static_cast<long>(last) * kParallelProductRowGrain);
    gemm_serial(r1 - r0, inner, columns, a + r0, lda, b, ldb, beta, c + r0, ldc);
  });
}

}  // namespace

void gemm(long rows, long inner, long columns, const float* a, long lda, const float* b, long ldb, float beta,
          float* c, long ldc) {
  if (rows == 0 || columns == 0) return;
  gemm_rows_split(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
}

void gemm(long rows, long inner, long columns, const double* a, long lda, const double* b, long ldb, double beta,
          double* c, long ldc) {
  if (rows == 0 || columns == 0) return;
  gemm_rows_split(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
}

namespace {

void portable_thin_svd(long rows, long columns, const double* a, long lda, double* s, double* u, long ldu, double* vt,
                       long ldvt) {
  const long k = std::min(rows, columns);
  const Eigen::BDCSVD<Eigen::MatrixXd> svd(View<double>(a, rows, columns, Eigen::OuterStride<>(lda)),
                                           Eigen::ComputeThinU | Eigen::ComputeThinV);
  Eigen::Map<Eigen::VectorXd>(s, k) = svd.singularValues();
  Target<double>(u, rows, k, Eigen::OuterStride<>(ldu)) = svd.matrixU();
  Target<double>(vt, k, columns, Eigen::OuterStride<>(ldvt)) = svd.matrixV().transpose();
}

}  // namespace

void thin_svd_serial(long rows, long columns, const double* a, long lda, double* s, double* u, long ldu, double* vt,
                     long ldvt) {
  if (rows == 0 || columns == 0) return;
  if (active_kernel() == Kernel::kPortable) return portable_thin_svd(rows, columns, a, lda, s, u, ldu, vt, ldvt);
  std::vector<double> copy(static_cast<size_t>(rows * columns));  // dgesdd overwrites its A
  Target<double>(copy.data(), rows, columns, Eigen::OuterStride<>(rows)) =
      View<double>(a, rows, columns, Eigen::OuterStride<>(lda));
  const int m = blas_int(rows), n = blas_int(columns), lda_copy = m, ldu_int = blas_int(ldu), ldvt_int = blas_int(ldvt);
  std::vector<int> iwork(8 * static_cast<size_t>(std::min(rows, columns)));
  int info = 0, query = -1;
  double size = 0;
  dgesdd_("S", &m, &n, copy.data(), &lda_copy, s, u, &ldu_int, vt, &ldvt_int, &size, &query, iwork.data(), &info, 1);
  if (info == 0) {
    std::vector<double> work(static_cast<size_t>(size));
    const int lwork = static_cast<int>(work.size());
    dgesdd_("S", &m, &n, copy.data(), &lda_copy, s, u, &ldu_int, vt, &ldvt_int, work.data(), &lwork, iwork.data(),
            &info, 1);
  }
  if (info != 0) portable_thin_svd(rows, columns, a, lda, s, u, ldu, vt, ldvt);
}

}  // namespace animspace
