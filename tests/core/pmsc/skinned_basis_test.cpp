// Issue #51 item 4: an articulated model's basis in the skinned layout is the same basis. Built
// here by the definition (column 12j + 4a + c holds h_ij[c] at row 3i + a), its skinned form has
// the dense basis's checksum and SHA-256, round-trips through GetBasis's values, reconstructs the
// exact f̂ = mean + A p within the dense bound, and anything else is refused by name.
#include <random>
#include <set>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/pmsc/coordinates.h"
#include "core/pmsc/skinned_basis.h"

namespace animspace::pmsc {
namespace {

// N points on B bones, 1 to 4 distinct bones a point with random terms (weight > 0), r residual
// columns and a mean: the dense basis written entry by entry.
PmscModel articulated_model(std::mt19937& random, long N, int B, int r) {
  std::uniform_real_distribution<float> value(-2, 2), weight(0.05f, 1);
  std::uniform_int_distribution<int> bones(1, 4), bone(0, B - 1);
  PmscModel m;
  m.subspace_kind = SubspaceKind::kArticulated;
  m.point_count = m.control_point_count = static_cast<int>(N);
  m.bone_count = B;
  m.residual_components = r;
  m.mean = Eigen::VectorXf::NullaryExpr(3 * N, [&] { return value(random); });
  m.basis = Eigen::MatrixXf::Zero(3 * N, 12L * B + r);
  for (long i = 0; i < N; ++i) {
    std::set<int> chosen;
    const int count = bones(random);
    while (static_cast<int>(chosen.size()) < count) chosen.insert(bone(random));
    for (const int j : chosen) {
      const float w = weight(random);
      const float h[4] = {w * value(random), w * value(random), w * value(random), w};
      for (int a = 0; a < 3; ++a) {
        for (int c = 0; c < 4; ++c) m.basis(3 * i + a, 12L * j + 4 * a + c) = h[c];
      }
    }
  }
  m.basis.rightCols(r) = Eigen::MatrixXf::NullaryExpr(3 * N, r, [&] { return value(random); });
  return m;
}

TEST(SkinnedBasis, IsTheDenseBasisByItsDigestsAndRoundTripsThroughItsValues) {
  std::mt19937 random(51);
  const PmscModel m = articulated_model(random, 300, 12, 5);
  auto skinned = skinned_basis(m);
  ASSERT_TRUE(skinned.ok()) << skinned.error().message;
  EXPECT_EQ(skinned->influences, 4);
  EXPECT_EQ(skinned->basis_size(), m.basis_size());
  EXPECT_EQ(basis_checksum(*skinned), basis_checksum(m.mean, m.basis));
  EXPECT_EQ(basis_sha256(*skinned), basis_sha256(m.mean, m.basis));

  const std::vector<float> values = skinned_values(*skinned);
  EXPECT_EQ(values.size(), static_cast<size_t>(3 * 300 * (5 + 1) + kSlotValues * 300 * 4));
  EXPECT_LT(values.size() * 3, static_cast<size_t>(m.mean.size() + m.basis.size())) << "a third of dense at most";
  auto back = skinned_basis_from_values(values, 300, 12, 4, m.basis_size());
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->bones, skinned->bones);
  EXPECT_EQ(back->terms, skinned->terms);
  EXPECT_EQ(basis_checksum(*back), basis_checksum(m.mean, m.basis));
}

TEST(SkinnedBasis, ReconstructsTheExactPoseWithinTheDenseBound) {
  std::mt19937 random(52);
  const PmscModel m = articulated_model(random, 200, 9, 4);
  auto skinned = skinned_basis(m);
  ASSERT_TRUE(skinned.ok()) << skinned.error().message;
  std::normal_distribution<float> normal(0, 1);
  const double u = coordinates_rounding_bound(m.basis_size());
  for (int pose = 0; pose < 5; ++pose) {
    const Eigen::VectorXf p = Eigen::VectorXf::NullaryExpr(m.basis_size(), [&] { return normal(random); });
    const Eigen::VectorXd pd = p.cast<double>();
    const Eigen::VectorXd exact = m.mean.cast<double>() + m.basis.cast<double>() * pd;
    const Eigen::VectorXd size = m.mean.cast<double>().cwiseAbs() + m.basis.cast<double>().cwiseAbs() * pd.cwiseAbs();
    Eigen::VectorXf ours(m.mean.size()), dense(m.mean.size());
    reconstruct_coordinates(*skinned, p.data(), nullptr, ours.data());
    reconstruct_coordinates(m.mean, m.basis, p.data(), nullptr, dense.data());
    for (long i = 0; i < ours.size(); ++i) {
      // Each is within γ of the exact sum (half the client–server bound); together within it.
      ASSERT_LE(std::abs(ours(i) - exact(i)), u / 2 * size(i)) << "pose " << pose << " value " << i;
      ASSERT_LE(std::abs(static_cast<double>(ours(i)) - dense(i)), u * size(i)) << "pose " << pose << " value " << i;
    }
    // Aligned: the same rotation and translation as the dense path applies.
    FloatAlignment alignment;
    alignment.rotation = Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();
    alignment.translation = Eigen::Vector3f(4, -5, 6);
    Eigen::VectorXf world(m.mean.size());
    reconstruct_coordinates(*skinned, p.data(), &alignment, world.data());
    Eigen::Matrix3Xf expected = Eigen::Map<const Eigen::Matrix3Xf>(ours.data(), 3, m.point_count);
    expected = (alignment.rotation * expected).colwise() + alignment.translation;
    EXPECT_TRUE(Eigen::Map<const Eigen::Matrix3Xf>(world.data(), 3, m.point_count).isApprox(expected, 1e-5f));
  }
}

TEST(SkinnedBasis, OnlyASkinnedBasisHasOneAndBadValuesAreRefusedByName) {
  std::mt19937 random(53);
  PmscModel m = articulated_model(random, 50, 6, 2);
  // An entry off the pattern (point 7's y row in bone 0's x columns): no skinned form.
  PmscModel off = m;
  off.basis(3 * 7 + 1, 0) = 0.5f;
  auto refused = skinned_basis(off);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(refused.error().message.find("point 7, bone 0"), std::string::npos) << refused.error().message;
  // A −0 where the pattern has 0: the same basis to the runtime, not to the digests, which name
  // bytes — so no skinned form either, rather than one a client would find forged.
  off = m;
  off.basis(3 * 7 + 1, 0) = -0.0f;
  refused = skinned_basis(off);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("basis value 22 of column 0 is -0"), std::string::npos)
      << refused.error().message;
  PmscModel linear = m;
  linear.subspace_kind = SubspaceKind::kLinear;
  ASSERT_FALSE(skinned_basis(linear).ok());
  EXPECT_NE(skinned_basis(linear).error().message.find("linear"), std::string::npos);

  auto skinned = skinned_basis(m);
  ASSERT_TRUE(skinned.ok());
  const int K = skinned->influences;
  std::vector<float> values = skinned_values(*skinned);
  // Where slot k of a point begins among the values.
  const auto slot = [&](long point, int k) { return static_cast<size_t>(3 * 50 + kSlotValues * (point * K + k)); };
  auto bad = values;
  bad[slot(3, 1)] = 2.5f;
  auto parsed = skinned_basis_from_values(bad, 50, 6, K, m.basis_size());
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(parsed.error().message.find("slot 1 of point 3 names bone 2.5"), std::string::npos)
      << parsed.error().message;
  bad = values;
  bad[slot(4, 0)] = 6;  // B = 6: bones 0 … 5
  EXPECT_FALSE(skinned_basis_from_values(bad, 50, 6, K, m.basis_size()).ok());
  // A point naming one bone in two live slots: refused (it would be added twice).
  long point = 0;
  while (skinned->terms[4 * static_cast<size_t>(point * K + 1) + 3] == 0) ++point;  // a point with two bones
  bad = values;
  bad[slot(point, 1)] = bad[slot(point, 0)];
  parsed = skinned_basis_from_values(bad, 50, 6, K, m.basis_size());
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.error().message.find("point " + std::to_string(point) + " names bone"), std::string::npos)
      << parsed.error().message;
  values.pop_back();
  parsed = skinned_basis_from_values(values, 50, 6, K, m.basis_size());
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.error().message.find("expected N·3·(r + 1) + 5·N·K"), std::string::npos) << parsed.error().message;
}

}  // namespace
}  // namespace animspace::pmsc
