#include "core/common/kernels.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <Eigen/QR>

#include <gtest/gtest.h>

#include "core/common/parallel.h"

namespace animspace {
namespace {

// Restores the process's kernel after a test that switches it.
class KernelTest : public ::testing::Test {
 protected:
  void TearDown() override {
    use_kernel(saved_);
    set_thread_limit(0);
  }
  Kernel saved_ = active_kernel();
};

// C = A·B + beta·C by the definition, in long double, for strided column-major operands.
template <typename T>
std::vector<long double> reference(long rows, long inner, long columns, const std::vector<T>& a, long lda,
                                   const std::vector<T>& b, long ldb, T beta, const std::vector<T>& c, long ldc) {
  std::vector<long double> out(static_cast<size_t>(ldc * columns));
  for (long j = 0; j < columns; ++j) {
    for (long i = 0; i < rows; ++i) {
      long double sum = beta * static_cast<long double>(c[static_cast<size_t>(i + j * ldc)]);
      for (long k = 0; k < inner; ++k) {
        sum += static_cast<long double>(a[static_cast<size_t>(i + k * lda)]) * b[static_cast<size_t>(k + j * ldb)];
      }
      out[static_cast<size_t>(i + j * ldc)] = sum;
    }
  }
  return out;
}

// Checks a product `out` (rows × columns, leading dimension ldc) against the exact `expected`: every
// value within `tolerance`, and the padding below row `rows` as it was in `c`.
template <typename T>
void expect_product(const std::vector<T>& out, const std::vector<T>& c, const std::vector<long double>& expected,
                    long rows, long columns, long ldc, double tolerance, const std::string& what) {
  for (long j = 0; j < columns; ++j) {
    for (long i = 0; i < ldc; ++i) {
      const auto at = static_cast<size_t>(i + j * ldc);
      if (i >= rows) {
        EXPECT_EQ(out[at], c[at]) << what << ": padding below row " << rows << " was written";
      } else {
        EXPECT_NEAR(out[at], static_cast<double>(expected[at]), tolerance) << what << " at " << i << "," << j;
      }
    }
  }
}

template <typename T>
void check_products(Kernel kernel, double relative) {
  use_kernel(kernel);
  std::mt19937 random(7);
  std::uniform_real_distribution<double> value(-1, 1);
  // Column counts on both sides of the BLAS kernel's switch from gemv to gemm.
  for (long columns : {1L, 2L, kBlasGemmMinColumns - 1, kBlasGemmMinColumns, 9L, 64L}) {
    for (T beta : {T(0), T(1)}) {
      const long rows = 37, inner = 11, lda = rows + 3, ldb = inner + 2, ldc = rows + 5;
      std::vector<T> a(static_cast<size_t>(lda * inner)), b(static_cast<size_t>(ldb * columns)),
          c(static_cast<size_t>(ldc * columns));
      for (T& x : a) x = static_cast<T>(value(random));
      for (T& x : b) x = static_cast<T>(value(random));
      for (T& x : c) x = static_cast<T>(value(random));
      const std::vector<long double> expected = reference(rows, inner, columns, a, lda, b, ldb, beta, c, ldc);
      std::vector<T> out = c;
      gemm(rows, inner, columns, a.data(), lda, b.data(), ldb, beta, out.data(), ldc);
      // |a·b| ≤ 1 per term: the sum of inner + 1 terms is within (inner + 1)·ε of exact.
      expect_product(out, c, expected, rows, columns, ldc, relative * (inner + 1),
                     kernel_name(kernel) + " columns " + std::to_string(columns) + " beta " + std::to_string(beta));
    }
  }
}

TEST_F(KernelTest, BothKernelsComputeTheProductOfTheDefinition) {
  for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
    check_products<float>(kernel, 2e-7);
    check_products<double>(kernel, 4e-16);
  }
}

// Issue #38 item 3: a product large enough to split its rows across threads (the size of a
// 20000-point illumination model's reconstruction, one pose and a batch) gives, on one thread and
// on two, every value within the float rounding bound of the exact product: n = inner + 1 terms
// (beta·c included), each rounded once and summed, are within γ_n = n·u/(1 − n·u) of the exact
// sum relative to Σ|terms| (Higham, Accuracy and Stability, §3.1), u = 2⁻²⁴. The two runs may
// differ from each other only within that bound too (a kernel rounds the rows at a block's edge
// its own way), and rows the product does not own are never written.
TEST_F(KernelTest, ARowSplitProductIsWithinFloatRoundingOfTheExactProduct) {
  const long inner = 101, lda = 60011, rows = 60001, ldb = inner + 1, ldc = rows + 7;
  ASSERT_GE(rows * inner, 2 * kParallelProductMinMultiplies) << "the test must be large enough to split";
  std::mt19937 random(11);
  std::uniform_real_distribution<double> value(-1, 1);
  for (long columns : {1L, kBlasGemmMinColumns}) {
    std::vector<float> a(static_cast<size_t>(lda * inner)), b(static_cast<size_t>(ldb * columns)),
        c(static_cast<size_t>(ldc * columns));
    for (float& x : a) x = static_cast<float>(value(random));
    for (float& x : b) x = static_cast<float>(value(random));
    for (float& x : c) x = static_cast<float>(value(random));
    const float beta = 1.0f;
    std::vector<double> exact(c.size()), magnitude(c.size());
    for (long j = 0; j < columns; ++j) {
      for (long i = 0; i < rows; ++i) {
        const auto at = static_cast<size_t>(i + j * ldc);
        double sum = beta * static_cast<double>(c[at]), abs_sum = std::abs(sum);
        for (long k = 0; k < inner; ++k) {
          const double term = static_cast<double>(a[static_cast<size_t>(i + k * lda)]) * b[static_cast<size_t>(k + j * ldb)];
          sum += term;
          abs_sum += std::abs(term);
        }
        exact[at] = sum;
        magnitude[at] = abs_sum;
      }
    }
    const double n_u = static_cast<double>(inner + 1) * std::ldexp(1.0, -24);
    const double gamma = n_u / (1 - n_u);
    for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
      use_kernel(kernel);
      std::vector<std::vector<float>> outputs;
      for (int threads : {1, 2}) {
        set_thread_limit(threads);
        std::vector<float> out = c;
        gemm(rows, inner, columns, a.data(), lda, b.data(), ldb, beta, out.data(), ldc);
        outputs.push_back(out);
      }
      for (long j = 0; j < columns; ++j) {
        for (long i = 0; i < ldc; ++i) {
          const auto at = static_cast<size_t>(i + j * ldc);
          for (size_t run = 0; run < outputs.size(); ++run) {
            if (i >= rows) {
              ASSERT_EQ(outputs[run][at], c[at]) << "padding below row " << rows << " was written";
            } else {
              // The double reference itself is within inner · 2⁻⁵³ · Σ|terms|, negligible here.
              ASSERT_LE(std::abs(static_cast<double>(outputs[run][at]) - exact[at]), gamma * magnitude[at] + 1e-30)
                  << kernel_name(kernel) << " " << (run + 1) << " thread(s), columns " << columns << " at " << i << ","
                  << j;
            }
          }
        }
      }
    }
  }
}

// Products called from two threads at once (the server's callers, the calibration folds) each
// equal the same product computed alone, bit for bit. Debian's serial OpenBLAS failed this: it
// hands out its packing buffers without a lock, and 4-9% of the products came back wrong once two
// threads had taken the same buffer. The sizes are the calibration's (R × F by F × M): large
// enough that OpenBLAS packs rather than taking its small-matrix path.
TEST_F(KernelTest, ConcurrentProductsFromTwoThreadsEqualEachProductAlone) {
  constexpr long rows = 3000, inner = 60, columns = 16;
  constexpr int kCalls = 20000;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> value(-1, 1);
  struct Operands {
    std::vector<float> a, b, alone;
    long wrong = 0;
  };
  std::vector<Operands> operands(2);
  for (Operands& o : operands) {
    o.a.resize(rows * inner);
    o.b.resize(inner * columns);
    for (float& x : o.a) x = value(rng);
    for (float& x : o.b) x = value(rng);
    o.alone.assign(rows * columns, 0.0f);
    gemm_serial(rows, inner, columns, o.a.data(), rows, o.b.data(), inner, 0.0f, o.alone.data(), rows);
  }
  std::vector<std::thread> threads;
  for (Operands& o : operands) {
    threads.emplace_back([&o] {
      std::vector<float> c(rows * columns);
      for (int call = 0; call < kCalls; ++call) {
        gemm_serial(rows, inner, columns, o.a.data(), rows, o.b.data(), inner, 0.0f, c.data(), rows);
        if (c != o.alone) ++o.wrong;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(operands[0].wrong, 0) << "of " << kCalls << " products on the first thread";
  EXPECT_EQ(operands[1].wrong, 0) << "of " << kCalls << " products on the second thread";
}

// The Gram matrices of the PMSC's PCA: the lower triangle of XᵀX against the definition in long
// double, within (rows + 1)·ε·Σ|terms| (Higham §3.1, as above), and the strict upper triangle
// untouched.
template <typename T>
void check_gram(Kernel kernel, double epsilon) {
  use_kernel(kernel);
  std::mt19937 random(5);
  std::uniform_real_distribution<double> value(-1, 1);
  for (long columns : {1L, 3L, 17L}) {
    const long rows = 213, ldx = rows + 4, ldo = columns + 2;
    std::vector<T> x(static_cast<size_t>(ldx * columns));
    for (T& v : x) v = static_cast<T>(value(random));
    const T sentinel = T(1234.5);
    std::vector<T> out(static_cast<size_t>(ldo * columns), sentinel);
    gram_lower_serial(rows, columns, x.data(), ldx, out.data(), ldo);
    for (long j = 0; j < columns; ++j) {
      for (long i = 0; i < ldo; ++i) {
        const T got = out[static_cast<size_t>(i + j * ldo)];
        if (i < j || i >= columns) {
          EXPECT_EQ(got, sentinel) << "outside the lower triangle, at " << i << "," << j;
          continue;
        }
        long double exact = 0, magnitude = 0;
        for (long r = 0; r < rows; ++r) {
          const long double term =
              static_cast<long double>(x[static_cast<size_t>(r + i * ldx)]) * x[static_cast<size_t>(r + j * ldx)];
          exact += term;
          magnitude += term < 0 ? -term : term;
        }
        EXPECT_NEAR(got, static_cast<double>(exact), epsilon * static_cast<double>(rows + 1) * static_cast<double>(magnitude))
            << kernel_name(kernel) << " columns " << columns << " at " << i << "," << j;
      }
    }
  }
}

TEST_F(KernelTest, BothKernelsComputeTheGramMatrixOfTheDefinition) {
  for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
    check_gram<float>(kernel, 2e-7);
    check_gram<double>(kernel, 4e-16);
  }
}

// Aᵀ·B + beta·C against the definition: the reference above with A's transpose written out.
TEST_F(KernelTest, BothKernelsComputeTheTransposedProductOfTheDefinition) {
  for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
    use_kernel(kernel);
    std::mt19937 random(11);
    std::uniform_real_distribution<double> value(-1, 1);
    for (long columns : {1L, 5L, 40L}) {
      for (double beta : {0.0, 1.0}) {
        const long rows = 19, inner = 53, lda = inner + 3, ldb = inner + 2, ldc = rows + 4;
        std::vector<double> a(static_cast<size_t>(lda * rows)), b(static_cast<size_t>(ldb * columns)),
            c(static_cast<size_t>(ldc * columns));
        for (double& x : a) x = value(random);
        for (double& x : b) x = value(random);
        for (double& x : c) x = value(random);
        std::vector<double> transposed(static_cast<size_t>(rows * inner));  // rows × inner, leading dimension rows
        for (long i = 0; i < rows; ++i) {
          for (long k = 0; k < inner; ++k) transposed[static_cast<size_t>(i + k * rows)] = a[static_cast<size_t>(k + i * lda)];
        }
        const std::vector<long double> expected = reference(rows, inner, columns, transposed, rows, b, ldb, beta, c, ldc);
        std::vector<double> out = c;
        gemm_transposed_serial(rows, inner, columns, a.data(), lda, b.data(), ldb, beta, out.data(), ldc);
        expect_product(out, c, expected, rows, columns, ldc, 4e-16 * (inner + 1),
                       kernel_name(kernel) + " columns " + std::to_string(columns) + " beta " + std::to_string(beta));
      }
    }
  }
}

// The thin SVD of a matrix made with known singular values, A = Q₁ diag(σ) Q₂ᵀ (Q from the QR of
// random matrices), tall and wide, with padded leading dimensions: s is σ in descending order, U
// and V have orthonormal columns, U diag(s) Vᵀ is A again, and no padding is written.
TEST_F(KernelTest, BothKernelsComputeTheThinSvdOfAMatrixWithKnownSingularValues) {
  for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
    use_kernel(kernel);
    std::mt19937 random(13);
    std::uniform_real_distribution<double> value(-1, 1);
    for (const auto& [rows, columns] : {std::pair{37L, 11L}, std::pair{11L, 37L}, std::pair{20L, 20L}}) {
      const long k = std::min(rows, columns);
      const auto orthonormal = [&](long n) {
        Eigen::MatrixXd X(n, k);
        for (long j = 0; j < X.size(); ++j) X.data()[j] = value(random);
        return Eigen::MatrixXd(Eigen::HouseholderQR<Eigen::MatrixXd>(X).householderQ() * Eigen::MatrixXd::Identity(n, k));
      };
      Eigen::VectorXd sigma(k);
      for (long i = 0; i < k; ++i) sigma(i) = std::pow(10.0, -6.0 * static_cast<double>(i) / static_cast<double>(k));
      const Eigen::MatrixXd A = orthonormal(rows) * sigma.asDiagonal() * orthonormal(columns).transpose();
      const long lda = rows + 3, ldu = rows + 2, ldvt = k + 1;
      const double pad = -7;
      Eigen::MatrixXd a = Eigen::MatrixXd::Constant(lda, columns, pad), u = Eigen::MatrixXd::Constant(ldu, k, pad),
                      vt = Eigen::MatrixXd::Constant(ldvt, columns, pad);
      a.topRows(rows) = A;
      Eigen::VectorXd s(k);
      thin_svd_serial(rows, columns, a.data(), lda, s.data(), u.data(), ldu, vt.data(), ldvt);
      const std::string what = kernel_name(kernel) + " " + std::to_string(rows) + " × " + std::to_string(columns);
      EXPECT_LE((s - sigma).cwiseAbs().maxCoeff(), 1e-13) << what;
      const Eigen::MatrixXd U = u.topRows(rows), Vt = vt.topRows(k);
      EXPECT_LE((U.transpose() * U - Eigen::MatrixXd::Identity(k, k)).cwiseAbs().maxCoeff(), 1e-12) << what;
      EXPECT_LE((Vt * Vt.transpose() - Eigen::MatrixXd::Identity(k, k)).cwiseAbs().maxCoeff(), 1e-12) << what;
      EXPECT_LE((U * s.asDiagonal() * Vt - A).cwiseAbs().maxCoeff(), 1e-13) << what;
      EXPECT_TRUE((a.bottomRows(lda - rows).array() == pad).all()) << what << ": A's padding";
      EXPECT_TRUE((u.bottomRows(ldu - rows).array() == pad).all()) << what << ": U's padding";
      EXPECT_TRUE((vt.bottomRows(ldvt - k).array() == pad).all()) << what << ": Vᵀ's padding";
    }
  }
}

TEST_F(KernelTest, TheBlasKernelNamesTheCoreItDispatchedTo) {
  const std::string blas = kernel_name(Kernel::kBlas);
  ASSERT_EQ(blas.rfind("openblas:", 0), 0u) << blas;
  EXPECT_GT(blas.size(), std::string("openblas:").size());
  EXPECT_EQ(kernel_name(Kernel::kPortable).rfind("eigen:", 0), 0u);
}

TEST_F(KernelTest, FlagValuesParse) {
  Kernel kernel = Kernel::kBlas;
  ASSERT_TRUE(parse_kernel("portable", kernel));
  EXPECT_EQ(kernel, Kernel::kPortable);
  ASSERT_TRUE(parse_kernel("blas", kernel));
  EXPECT_EQ(kernel, Kernel::kBlas);
  EXPECT_FALSE(parse_kernel("avx512", kernel));
  EXPECT_FALSE(parse_kernel("", kernel));
}

}  // namespace
}  // namespace animspace
