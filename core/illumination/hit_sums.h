// The final gather's sums when the direct light at its hits is read from the triangles' vertices
// (GatherOptions::direct_from_vertices): for each lit hit, the barycentric interpolant of the
// vertices' L_d, for one light or for a block of lights whose L_d sit side by side per vertex.
//
// These sums are the training's largest cost at the papers' size (100k points × 2,048 hits × 144
// lights), so they run on the widest vector unit the CPU has, chosen once per process like the
// products' kernels (core/common/kernels.h). Every element's arithmetic is the same on every
// instruction set and for one light or a block: float multiplies and adds in a fixed order, and
// this file is compiled without contracting them into fused multiply-adds. So a frame does not
// depend on the CPU, nor on whether its light was gathered alone (the daemon's full calculation)
// or with others (the training's).
#pragma once

#include <cstdint>

namespace animspace::illumination {

// A hemisphere ray's lit hit: the triangle, and Embree's barycentric weights u, v of its vertices
// 1 and 2 (vertex 0 weighs 1 − u − v).
struct VertexHit {
  uint32_t face;
  float u;
  float v;
};

// Lights per block of the training's shared-ray gather: 48 floats (three cache lines) per vertex,
// 19 MB for the papers' 100k vertices, within the development machine's 32 MB L3.
inline constexpr int kLightsPerBlock = 16;

// sums[j] += Σ over [first, last) of ((1 − u − v)·d₀[j] + u·d₁[j]) + v·d₂[j] for j < 3·lights,
// in the order of the hits, where dₖ = direct + 3·lights·(vertex k of the hit's face) and `faces`
// holds three vertex indices per face. `lights` is 1 or kLightsPerBlock.
void sum_interpolated(const int32_t* faces, const VertexHit* first, const VertexHit* last, const float* direct,
                      int lights, float* sums);

// The instruction sets a block's sums have code for, widest first.
enum class HitSumsIsa { kAvx512f, kAvx2, kSse2 };

// The instruction set a block's sums run on in this process (the widest the CPU has) and its name
// ("avx512f", "avx2", "sse2").
HitSumsIsa hit_sums_isa();
const char* hit_sums_isa_name(HitSumsIsa isa);
// Whether this CPU runs `isa`'s code.
bool hit_sums_isa_supported(HitSumsIsa isa);

// sum_interpolated for a block (kLightsPerBlock lights) on `isa`'s code, which this CPU must run
// (hit_sums_isa_supported): for tests that every instruction set adds the same.
void sum_interpolated_block_on(HitSumsIsa isa, const int32_t* faces, const VertexHit* first, const VertexHit* last,
                               const float* direct, float* sums);

}  // namespace animspace::illumination
