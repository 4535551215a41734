// Point multiplication on the client (issue #36): a pose sent as its coordinates and
// reconstructed by whoever holds the basis is the server's float32 answer up to the stated float
// rounding — exactly when both reconstruct one pose with the same kernel — and the checksum names
// the mean and the basis, each in its half.
#include <random>
#include <span>

#include <gtest/gtest.h>

#include "core/common/kernels.h"
#include "core/common/point_codec.h"
#include "core/common/sha256.h"
#include "core/container/crc32.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/pmsc_model.h"
#include "tests/support/pmsc_fixtures.h"

namespace animspace::pmsc {
namespace {

class CoordinatesTest : public ::testing::TestWithParam<Kernel> {
 protected:
  void SetUp() override { use_kernel(GetParam()); }
  void TearDown() override { use_kernel(saved_); }
  Kernel saved_ = active_kernel();
};

// What a client does with an answer: p as float (the wire's precision) and the alignment as float.
Eigen::VectorXf client_reconstruction(const PmscModel& m, const PoseEstimate& estimate) {
  const Eigen::VectorXf p = estimate.coordinates.cast<float>();
  const FloatAlignment alignment = float_alignment(estimate.alignment);
  Eigen::VectorXf out(m.mean.size());
  reconstruct_coordinates(m.mean, m.basis, p.data(), m.aligned ? &alignment : nullptr, out.data());
  return out;
}

TEST_P(CoordinatesTest, AClientReconstructionIsTheServersAnswerWithinTheStatedBound) {
  std::mt19937 random(36);
  for (bool aligned : {false, true}) {
    const PmscModel m = testing::random_model(random, 400, 12, 40, aligned);
    ASSERT_GT(m.projection.size(), 0);
    std::vector<PoseEstimate> estimates(9);
    std::vector<Eigen::VectorXf> batched(estimates.size(), Eigen::VectorXf(m.mean.size()));
    std::vector<const PoseEstimate*> inputs;
    std::vector<float*> destinations;
    for (size_t b = 0; b < estimates.size(); ++b) {
      estimate_coordinates(m, testing::random_keys(random, m), estimates[b]);
      inputs.push_back(&estimates[b]);
      destinations.push_back(batched[b].data());
    }
    reconstruct(m, inputs, destinations);  // the server's batched float32 answers
    for (size_t b = 0; b < estimates.size(); ++b) {
      const Eigen::VectorXf client = client_reconstruction(m, estimates[b]);
      // Alone, the server runs the client's code on the client's inputs: the same bits.
      Eigen::VectorXf alone(m.mean.size());
      const PoseEstimate* input = &estimates[b];
      float* destination = alone.data();
      reconstruct(m, {&input, 1}, {&destination, 1});
      EXPECT_EQ(client, alone) << "pose " << b;
      // In a batch, only the order of the float additions differs.
      const Eigen::VectorXd tolerance = testing::reconstruction_tolerance(m, estimates[b].coordinates);
      for (long i = 0; i < client.size(); ++i) {
        double allowed = tolerance(i);
        if (aligned) {
          // The rotation keeps the error's size: the point's whole error, plus both rotations' rounding.
          const long point = i / 3;
          allowed = tolerance.segment(3 * point, 3).norm() +
                    aligned_rounding_bound() *
                        (batched[b].segment(3 * point, 3).cast<double>() - estimates[b].alignment.translation).norm() +
                    translation_rounding_bound() * std::abs(static_cast<double>(batched[b](i)));
        }
        ASSERT_LE(std::abs(static_cast<double>(client(i)) - batched[b](i)), allowed)
            << "pose " << b << " value " << i << (aligned ? " (aligned)" : "");
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Kernels, CoordinatesTest, ::testing::Values(Kernel::kPortable, Kernel::kBlas),
                         [](const ::testing::TestParamInfo<Kernel>& parameter) {
                           return parameter.param == Kernel::kBlas ? std::string("Blas") : std::string("Portable");
                         });

TEST(BasisChecksum, NamesTheMeanInTheHighHalfAndTheBasisInTheLowHalf) {
  std::mt19937 random(7);
  const PmscModel m = testing::random_model(random, 50, 4, 10, false);
  const auto bytes = [](const float* values, long count) {
    return std::span<const std::byte>(reinterpret_cast<const std::byte*>(values),
                                      static_cast<size_t>(count) * sizeof(float));
  };
  const uint64_t checksum = basis_checksum(m.mean, m.basis);
  EXPECT_EQ(checksum >> 32, container::crc32_update(0, bytes(m.mean.data(), m.mean.size())));
  EXPECT_EQ(checksum & 0xffffffffu, container::crc32_update(0, bytes(m.basis.data(), m.basis.size())));
  // One value changed anywhere changes it.
  Eigen::MatrixXf other = m.basis;
  other(17, 3) = std::nextafter(other(17, 3), 1.0f);
  EXPECT_NE(basis_checksum(m.mean, other), checksum);
  Eigen::VectorXf mean = m.mean;
  mean(0) += 1;
  EXPECT_NE(basis_checksum(mean, m.basis), checksum);
}

// Issue #53: the float16 form GetBasis sends — each value rounded to the nearest binary16, named
// by the SHA-256 of those bytes, with the largest rounding error — and a value binary16 cannot
// hold named by where it lies.
TEST(Float16Basis, IsNamedByItsBytesAndCarriesItsLargestRoundingError) {
  std::mt19937 random(11);
  const PmscModel m = testing::random_model(random, 40, 3, 6, false);
  auto half = float16_basis(m.mean, m.basis);
  ASSERT_TRUE(half.ok()) << half.error().message;
  std::string bytes;
  double largest = 0;
  std::vector<float> values(m.mean.data(), m.mean.data() + m.mean.size());  // mean, then basis by column
  values.insert(values.end(), m.basis.data(), m.basis.data() + m.basis.size());
  {
    for (const float v : values) {
      const uint16_t h = point_codec::float_to_half(v);
      bytes.push_back(static_cast<char>(h & 0xff));  // little-endian
      bytes.push_back(static_cast<char>(h >> 8));
      largest = std::max(largest, std::abs(static_cast<double>(point_codec::half_to_float(h)) - v));
    }
  }
  EXPECT_EQ(half->sha256, sha256(bytes));
  EXPECT_EQ(half->max_error, static_cast<float>(largest));
  EXPECT_GT(half->max_error, 0.0f);

  Eigen::MatrixXf big = m.basis;
  big(5, 2) = 70000.0f;
  auto refused = float16_basis(m.mean, big);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kOutOfRange);
  EXPECT_NE(refused.error().message.find("basis value 5 of column 2 is 70000"), std::string::npos)
      << refused.error().message;
  Eigen::VectorXf mean = m.mean;
  mean(7) = -1e6f;
  EXPECT_NE(float16_basis(mean, m.basis).error().message.find("mean value 7 is -1000000"), std::string::npos);
}

}  // namespace
}  // namespace animspace::pmsc
