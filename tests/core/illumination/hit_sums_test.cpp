#include "core/illumination/hit_sums.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::illumination {
namespace {

// A random "mesh" (faces over `vertices` vertices), a block of lights' L_d per vertex and a
// point's hits: the sums need nothing else.
struct Case {
  int vertices = 500;
  std::vector<int32_t> faces;
  std::vector<float> direct;  // vertices × 3·kLightsPerBlock
  std::vector<VertexHit> hits;
  std::vector<float> start;   // the sums the hits are added to
};

Case random_case(unsigned seed, int hit_count) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> vertex(0, 499);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  Case c;
  for (int f = 0; f < 900; ++f) {
    for (int k = 0; k < 3; ++k) c.faces.push_back(vertex(rng));
  }
  c.direct.resize(static_cast<size_t>(c.vertices) * 3 * kLightsPerBlock);
  for (float& d : c.direct) d = 10.0f * unit(rng) * unit(rng);  // a spread of magnitudes
  std::uniform_int_distribution<uint32_t> face(0, 899);
  for (int h = 0; h < hit_count; ++h) {
    float u = unit(rng), v = unit(rng);
    if (u + v > 1.0f) {
      u = 1.0f - u;
      v = 1.0f - v;
    }
    c.hits.push_back({face(rng), u, v});
  }
  c.start.resize(3 * kLightsPerBlock);
  for (float& s : c.start) s = unit(rng);
  return c;
}

bool bit_equal(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

std::vector<HitSumsIsa> supported_isas() {
  std::vector<HitSumsIsa> out;
  for (HitSumsIsa isa : {HitSumsIsa::kAvx512f, HitSumsIsa::kAvx2, HitSumsIsa::kSse2}) {
    if (hit_sums_isa_supported(isa)) out.push_back(isa);
  }
  return out;
}

// Against the definition in double: a float sum of n terms is within (n + 3)·2⁻²⁴ of the sum
// of the terms' magnitudes (the classic bound for recursive summation, plus the three roundings
// of a term), so a wrong vertex, weight or light shows as an error far above it.
TEST(HitSumsTest, ABlockEqualsTheDefinitionWithinFloatRounding) {
  const Case c = random_case(7, 2048);
  std::vector<float> sums = c.start;
  sum_interpolated(c.faces.data(), c.hits.data(), c.hits.data() + c.hits.size(), c.direct.data(), kLightsPerBlock,
                   sums.data());
  constexpr int kStride = 3 * kLightsPerBlock;
  for (int j = 0; j < kStride; ++j) {
    double exact = c.start[static_cast<size_t>(j)];
    double magnitude = std::abs(exact);
    for (const VertexHit& h : c.hits) {
      const double w = 1.0 - static_cast<double>(h.u) - static_cast<double>(h.v);
      const int32_t* f = c.faces.data() + 3 * static_cast<size_t>(h.face);
      const double term = w * c.direct[static_cast<size_t>(kStride * f[0] + j)] +
                          h.u * static_cast<double>(c.direct[static_cast<size_t>(kStride * f[1] + j)]) +
                          h.v * static_cast<double>(c.direct[static_cast<size_t>(kStride * f[2] + j)]);
      exact += term;
      magnitude += std::abs(term);
    }
    const double bound = (static_cast<double>(c.hits.size()) + 3) * std::ldexp(1.0, -24) * magnitude;
    EXPECT_NEAR(sums[static_cast<size_t>(j)], exact, bound) << "element " << j;
  }
}

// The determinism the gather promises (hit_sums.h): every instruction set this CPU runs adds the
// same bits, and one light's sums alone equal its column of a block.
TEST(HitSumsTest, EveryInstructionSetAndALightAloneAddTheSameBits) {
  const std::vector<HitSumsIsa> isas = supported_isas();
  ASSERT_FALSE(isas.empty());
  EXPECT_TRUE(hit_sums_isa_supported(hit_sums_isa()));
  EXPECT_EQ(hit_sums_isa(), isas.front()) << "the widest the CPU runs";
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const Case c = random_case(seed, 1 + 517 * static_cast<int>(seed));
    std::vector<float> first;
    for (HitSumsIsa isa : isas) {
      std::vector<float> sums = c.start;
      sum_interpolated_block_on(isa, c.faces.data(), c.hits.data(), c.hits.data() + c.hits.size(), c.direct.data(),
                                sums.data());
      if (first.empty()) {
        first = sums;
      } else {
        EXPECT_TRUE(bit_equal(sums, first)) << hit_sums_isa_name(isa) << ", seed " << seed;
      }
    }
    std::vector<float> dispatched = c.start;
    sum_interpolated(c.faces.data(), c.hits.data(), c.hits.data() + c.hits.size(), c.direct.data(), kLightsPerBlock,
                     dispatched.data());
    EXPECT_TRUE(bit_equal(dispatched, first));
    for (int light = 0; light < kLightsPerBlock; ++light) {
      std::vector<float> alone(3 * static_cast<size_t>(c.vertices));
      for (int v = 0; v < c.vertices; ++v) {
        for (int k = 0; k < 3; ++k) {
          alone[static_cast<size_t>(3 * v + k)] = c.direct[static_cast<size_t>((v * kLightsPerBlock + light) * 3 + k)];
        }
      }
      std::vector<float> sums(c.start.begin() + 3 * light, c.start.begin() + 3 * light + 3);
      // In packets, as the daemon's single-light gather adds them.
      for (size_t h = 0; h < c.hits.size(); h += 16) {
        const size_t end = std::min(c.hits.size(), h + 16);
        sum_interpolated(c.faces.data(), c.hits.data() + h, c.hits.data() + end, alone.data(), 1, sums.data());
      }
      const std::vector<float> column(first.begin() + 3 * light, first.begin() + 3 * light + 3);
      EXPECT_TRUE(bit_equal(sums, column)) << "light " << light << ", seed " << seed;
    }
  }
}

TEST(HitSumsTest, NoHitsLeaveTheSumsAsTheyWere) {
  const Case c = random_case(3, 0);
  std::vector<float> sums = c.start;
  sum_interpolated(c.faces.data(), c.hits.data(), c.hits.data(), c.direct.data(), kLightsPerBlock, sums.data());
  EXPECT_TRUE(bit_equal(sums, c.start));
}

}  // namespace
}  // namespace animspace::illumination
