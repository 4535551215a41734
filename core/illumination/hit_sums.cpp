// Compiled with -ffp-contract=off (CMakeLists.txt): see hit_sums.h for why.
#include "core/illumination/hit_sums.h"

#include <cassert>
#include <cstddef>
#include <cstring>
#include <initializer_list>

namespace animspace::illumination {

namespace {

// A block's sums as whole vectors of 16 floats (the compiler splits them into the target's
// registers: one zmm, two ymm or four xmm), so that they stay in registers across the hits.
using Lanes = float __attribute__((vector_size(64)));
constexpr int kBlockStride = 3 * kLightsPerBlock;
static_assert(kBlockStride * sizeof(float) % sizeof(Lanes) == 0);

// An unaligned load (a vertex's floats are not aligned to a vector); by reference, as a vector
// returned by value would change the ABI between the targets.
template <typename Value>
__attribute__((always_inline)) inline void load(Value& value, const float* values) {
  std::memcpy(&value, values, sizeof value);
}

// One body for one light (Value = float, 3 per vertex) and for a block (Value = Lanes), with the
// same operations element by element; inlined into each target's entry point below, so that the
// compiler generates it for that target.
template <typename Value, int kStride>
__attribute__((always_inline)) inline void sum_hits(const int32_t* faces, const VertexHit* first,
                                                    const VertexHit* last, const float* direct, float* sums) {
  constexpr int kLanes = static_cast<int>(sizeof(Value) / sizeof(float));
  constexpr int kValues = kStride / kLanes;
  Value acc[kValues];
  for (int k = 0; k < kValues; ++k) load(acc[k], sums + kLanes * k);
  for (const VertexHit* hit = first; hit != last; ++hit) {
    const float u = hit->u;
    const float v = hit->v;
    const float w = 1.0f - u - v;
    const int32_t* face = faces + 3 * static_cast<size_t>(hit->face);
    const float* d0 = direct + kStride * static_cast<size_t>(face[0]);
    const float* d1 = direct + kStride * static_cast<size_t>(face[1]);
    const float* d2 = direct + kStride * static_cast<size_t>(face[2]);
    for (int k = 0; k < kValues; ++k) {
      Value x0, x1, x2;
      load(x0, d0 + kLanes * k);
      load(x1, d1 + kLanes * k);
      load(x2, d2 + kLanes * k);
      acc[k] += (w * x0 + u * x1) + v * x2;
    }
  }
  std::memcpy(sums, acc, sizeof acc);
}

using SumFunction = void (*)(const int32_t*, const VertexHit*, const VertexHit*, const float*, float*);

#if defined(__x86_64__)
__attribute__((target("avx512f"))) void block_avx512(const int32_t* faces, const VertexHit* first,
                                                     const VertexHit* last, const float* direct, float* sums) {
  sum_hits<Lanes, kBlockStride>(faces, first, last, direct, sums);
}
__attribute__((target("avx2"))) void block_avx2(const int32_t* faces, const VertexHit* first, const VertexHit* last,
                                                const float* direct, float* sums) {
  sum_hits<Lanes, kBlockStride>(faces, first, last, direct, sums);
}
#endif
void block_baseline(const int32_t* faces, const VertexHit* first, const VertexHit* last, const float* direct,
                    float* sums) {
  sum_hits<Lanes, kBlockStride>(faces, first, last, direct, sums);
}

SumFunction block_function(HitSumsIsa isa) {
  switch (isa) {
#if defined(__x86_64__)
    case HitSumsIsa::kAvx512f: return block_avx512;
    case HitSumsIsa::kAvx2: return block_avx2;
#else
    case HitSumsIsa::kAvx512f:
    case HitSumsIsa::kAvx2: return nullptr;
#endif
    case HitSumsIsa::kSse2: return block_baseline;
  }
  return nullptr;
}

// The widest, chosen once.
HitSumsIsa widest() {
  for (HitSumsIsa isa : {HitSumsIsa::kAvx512f, HitSumsIsa::kAvx2}) {
    if (hit_sums_isa_supported(isa)) return isa;
  }
  return HitSumsIsa::kSse2;
}

}  // namespace

void sum_interpolated(const int32_t* faces, const VertexHit* first, const VertexHit* last, const float* direct,
                      int lights, float* sums) {
  assert(lights == 1 || lights == kLightsPerBlock);
  // One light: three floats per hit, too few to gain from a wider unit (its cost is the rays).
  if (lights == 1) {
    sum_hits<float, 3>(faces, first, last, direct, sums);
  } else {
    static const SumFunction block = block_function(hit_sums_isa());
    block(faces, first, last, direct, sums);
  }
}

HitSumsIsa hit_sums_isa() {
  static const HitSumsIsa isa = widest();
  return isa;
}

const char* hit_sums_isa_name(HitSumsIsa isa) {
  switch (isa) {
    case HitSumsIsa::kAvx512f: return "avx512f";
    case HitSumsIsa::kAvx2: return "avx2";
    case HitSumsIsa::kSse2: return "sse2";
  }
  return "unknown";
}

bool hit_sums_isa_supported(HitSumsIsa isa) {
  switch (isa) {
#if defined(__x86_64__)
    // These also check that the OS saves the wider registers (XGETBV).
    case HitSumsIsa::kAvx512f: return __builtin_cpu_supports("avx512f");
    case HitSumsIsa::kAvx2: return __builtin_cpu_supports("avx2");
#else
    case HitSumsIsa::kAvx512f:
    case HitSumsIsa::kAvx2: return false;
#endif
    case HitSumsIsa::kSse2: return true;
  }
  return false;
}

void sum_interpolated_block_on(HitSumsIsa isa, const int32_t* faces, const VertexHit* first, const VertexHit* last,
                               const float* direct, float* sums) {
  assert(hit_sums_isa_supported(isa));
  block_function(isa)(faces, first, last, direct, sums);
}

}  // namespace animspace::illumination
