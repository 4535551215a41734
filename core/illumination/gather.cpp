// Direct and one-bounce indirect diffuse illumination by final gather, on Embree 3.
//
// Papers and notes this file follows:
//   - Meyer & Anderson 2007 §3.2: one-bounce indirect illumination of a room lit by a point light.
//   - Pharr, Jakob & Humphreys, "Physically Based Rendering" 3rd ed. §13.6.3: cosine-weighted
//     hemisphere sampling (Malley's method, here in its polar form).
//   - Hammersley point set with a Cranley–Patterson rotation (Cranley & Patterson 1976) per point:
//     one low-discrepancy set of S directions, rotated by a hash of (seed, point).
//   - Duff et al. 2017, "Building an Orthonormal Basis, Revisited" (JCGT 6(1)): the tangent frame.
//   - Halton 1960: the cell average's ray origins (GatherOptions::cell_average) take the radical
//     inverses in bases 3, 5 and 7 of the sample's index, the next dimensions after the
//     Hammersley directions' (s/S, base 2), so that origins and directions cover their 4-D domain
//     together; rotated per point like the directions.
//
// Determinism: everything a point's value depends on — its rotation, its frame, its ray origin,
// the order of its sums — is a function of the point alone, and its rays are traced in packets of
// its own consecutive samples (rtcIntersect16 / rtcOccluded16; a point never shares a packet with
// another), so the value does not depend on the batch, the order or the thread that computes it.
#include "core/illumination/gather.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <utility>

#include <Eigen/Geometry>
#include <embree3/rtcore.h>

#include "core/common/format.h"
#include "core/common/parallel.h"
#include "core/illumination/hit_sums.h"

namespace animspace::illumination {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Ray origins sit this far (× the scene's bounding-box diagonal) off the surface, along the
// normal and into the face, so that a vertex on a crease sees neither its own face nor, through
// the crease, the back of its neighbour.
constexpr double kOffsetPerSceneSize = 1e-4;
// Shadow rays stop this fraction short of the light.
constexpr double kShadowShortening = 1e-4;
// Salts the hash of a vertex's cell shadow rays, so that their points are not its hemisphere's.
constexpr uint64_t kCellShadowStream = 0xC3A5C85C97CB3127ull;
// Points per thread below which threads do not pay (a point costs ~S µs indirect, ~1 µs direct).
constexpr int64_t kIndirectPointsPerThread = 16;
constexpr int64_t kDirectPointsPerThread = 1024;
// The interpolated sums cost ~3·S lookups per point and block of lights.
constexpr int64_t kInterpolatedPointsPerThread = 64;
// Points per grain of work a thread takes at a time (parallel_for_grains): a point's cost depends
// on where its rays go, so contiguous halves of the points finished minutes apart at 100k points.
constexpr int64_t kIndirectPointsPerGrain = 32;
constexpr int64_t kDirectPointsPerGrain = 1024;
constexpr int64_t kInterpolatedPointsPerGrain = 256;

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

std::string vector_text(const Eigen::Vector3d& v) {
  return "(" + format_number(v.x()) + ", " + format_number(v.y()) + ", " + format_number(v.z()) + ")";
}

// splitmix64's output function (Steele, Lea & Flood 2014): a bijective 64-bit mix.
uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

double unit_interval(uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }  // [0, 1)

// Van der Corput in base 2: the second coordinate of the Hammersley set.
double radical_inverse_base2(uint32_t s) {
  s = (s << 16) | (s >> 16);
  s = ((s & 0x00FF00FFu) << 8) | ((s & 0xFF00FF00u) >> 8);
  s = ((s & 0x0F0F0F0Fu) << 4) | ((s & 0xF0F0F0F0u) >> 4);
  s = ((s & 0x33333333u) << 2) | ((s & 0xCCCCCCCCu) >> 2);
  s = ((s & 0x55555555u) << 1) | ((s & 0xAAAAAAAAu) >> 1);
  return static_cast<double>(s) * 0x1.0p-32;
}

double fractional(double x) { return x - std::floor(x); }

// Van der Corput in `Base` (Halton's coordinates past the first two).
template <uint32_t Base>
double radical_inverse(uint32_t s) {
  double inverse = 0, digit = 1.0 / Base;
  for (; s > 0; s /= Base, digit /= Base) inverse += digit * (s % Base);
  return inverse;
}

// The cell average's coordinates of samples 0 … S − 1 (radical inverses in bases 3, 5, 7), the
// same for every point (each rotates them by its own hash): computed once per thread and S, as
// they cost more than the rest of a ray's set-up.
const std::vector<std::array<double, 3>>& halton_cell_points(int samples) {
  thread_local std::vector<std::array<double, 3>> points;
  if (points.size() != static_cast<size_t>(samples)) {
    points.resize(static_cast<size_t>(samples));
    for (int s = 0; s < samples; ++s) {
      const auto index = static_cast<uint32_t>(s);
      points[static_cast<size_t>(s)] = {radical_inverse<3>(index), radical_inverse<5>(index), radical_inverse<7>(index)};
    }
  }
  return points;
}

constexpr double kGoldenFraction = 0.6180339887498949;  // (√5 − 1)/2: spreads the shadow rays' angles

// Duff et al. 2017, Listing 3: t, b with (t, b, n) right-handed and orthonormal.
void orthonormal_basis(const Eigen::Vector3d& n, Eigen::Vector3d& t, Eigen::Vector3d& b) {
  const double sign = std::copysign(1.0, n.z());
  const double a = -1.0 / (sign + n.z());
  const double c = n.x() * n.y() * a;
  t = Eigen::Vector3d(1.0 + sign * n.x() * n.x() * a, sign * c, -sign * n.x());
  b = Eigen::Vector3d(c, sign + n.y() * n.y() * a, -n.y());
}

RTCRay make_ray(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, float tfar) {
  RTCRay ray;
  ray.org_x = static_cast<float>(origin.x());
  ray.org_y = static_cast<float>(origin.y());
  ray.org_z = static_cast<float>(origin.z());
  ray.tnear = 0.0f;
  ray.dir_x = static_cast<float>(direction.x());
  ray.dir_y = static_cast<float>(direction.y());
  ray.dir_z = static_cast<float>(direction.z());
  ray.time = 0.0f;
  ray.tfar = tfar;
  ray.mask = std::numeric_limits<unsigned>::max();
  ray.id = 0;
  ray.flags = 0;
  return ray;
}

// Ray k of a packet of kPacket rays (an RTCRay16, or the ray of an RTCRayHit16), as make_ray.
constexpr int kPacket = 16;
void set_ray(RTCRay16& packet, int k, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, float tfar) {
  packet.org_x[k] = static_cast<float>(origin.x());
  packet.org_y[k] = static_cast<float>(origin.y());
  packet.org_z[k] = static_cast<float>(origin.z());
  packet.tnear[k] = 0.0f;
  packet.dir_x[k] = static_cast<float>(direction.x());
  packet.dir_y[k] = static_cast<float>(direction.y());
  packet.dir_z[k] = static_cast<float>(direction.z());
  packet.time[k] = 0.0f;
  packet.tfar[k] = tfar;
  packet.mask[k] = std::numeric_limits<unsigned>::max();
  packet.id[k] = 0;
  packet.flags[k] = 0;
}

// The lit hits of a list of points' rays, in blocks of kPointsPerHitBlock points that the threads
// fill independently: point p's hits are blocks[p / kPointsPerHitBlock][ends[p − 1] .. ends[p]),
// ends counted within the block. Blocks rather than one array, so that the largest (the papers'
// 100k points × 2,048 rays: 2.5 GB) is never held twice while it is joined.
constexpr int64_t kPointsPerHitBlock = 256;
struct PointHits {
  std::vector<std::vector<VertexHit>> blocks;
  std::vector<int64_t> ends;
  const VertexHit* begin(int64_t p) const {
    return blocks[static_cast<size_t>(p / kPointsPerHitBlock)].data() +
           (p % kPointsPerHitBlock == 0 ? 0 : ends[static_cast<size_t>(p - 1)]);
  }
  const VertexHit* end(int64_t p) const {
    return blocks[static_cast<size_t>(p / kPointsPerHitBlock)].data() + ends[static_cast<size_t>(p)];
  }
};

// Calls body(p, v, context) for every position p of `points` (v = points[p]) on the threads, a
// grain of points at a time, each with its own Embree intersection context.
template <typename Body>
void for_each_point(const std::vector<int>& points, int64_t min_per_thread, int64_t grain, Body&& body) {
  parallel_for_grains(static_cast<int64_t>(points.size()), min_per_thread, grain, [&](int64_t begin, int64_t end) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    for (int64_t p = begin; p < end; ++p) body(p, points[static_cast<size_t>(p)], context);
  });
}

// L_i at vertex v from its sum of L_d over S hits: ρ(v) ⊙ sum / S, rounded to float.
template <typename Sum>
void store_indirect(const SurfaceMesh& surface, int v, const Sum* sums, int samples, float* out) {
  for (int c = 0; c < 3; ++c) {
    out[c] = static_cast<float>(static_cast<double>(surface.albedo(v, c)) * sums[c] / samples);
  }
}

const char* embree_error_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "no error";
    case RTC_ERROR_UNKNOWN: return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
  }
  return "unrecognised error";
}

void record_embree_error(void* user, RTCError, const char* message) {
  auto* first = static_cast<std::string*>(user);
  if (first->empty() && message != nullptr) *first = message;
}

}  // namespace

Status check_gather_options(const GatherOptions& options) {
  if (options.samples < 1) return invalid("samples must be ≥ 1, got " + std::to_string(options.samples));
  if (options.shadow_rays < 1) return invalid("shadow_rays must be ≥ 1, got " + std::to_string(options.shadow_rays));
  if (!std::isfinite(options.light_radius) || options.light_radius < 0) {
    return invalid("light_radius must be finite and ≥ 0, got " + format_number(options.light_radius));
  }
  if (options.direct_from_vertices && options.light_radius != 0) {
    return invalid("light_radius must be 0 with direct_from_vertices (the vertices' direct light is a point light's), "
                   "got " + format_number(options.light_radius));
  }
  if (options.cell_shadow_rays < 0) {
    return invalid("cell_shadow_rays must be ≥ 0 (0: one from the vertex), got " + std::to_string(options.cell_shadow_rays));
  }
  if (options.cell_shadow_rays > 0 && !options.direct_from_vertices) {
    return invalid("cell_shadow_rays must be 0 without direct_from_vertices (they make the vertices' stored direct "
                   "light), got " + std::to_string(options.cell_shadow_rays));
  }
  if (options.sampling != HemisphereSampling::kHammersley && options.sampling != HemisphereSampling::kStratified) {
    return invalid("sampling " + std::to_string(static_cast<int>(options.sampling)) + " is not a known sampling");
  }
  return Status::Ok();
}

Status check_lights(const std::vector<PointLight>& lights, const std::string& name, int max_lights) {
  if (lights.empty() || lights.size() > static_cast<size_t>(std::max(max_lights, 0))) {
    return invalid(name + " has " + std::to_string(lights.size()) + " lights; 1 to " + std::to_string(max_lights) +
                   " are allowed");
  }
  for (size_t l = 0; l < lights.size(); ++l) {
    const std::string field = name + "[" + std::to_string(l) + "]";
    if (!lights[l].position.allFinite()) {
      return invalid(field + ".position " + vector_text(lights[l].position) + " is not finite");
    }
    const Eigen::Vector3d& intensity = lights[l].intensity;
    if (!intensity.allFinite() || (intensity.array() < 0.0).any()) {
      return invalid(field + ".intensity " + vector_text(intensity) + " must be finite and ≥ 0 in each channel");
    }
  }
  return Status::Ok();
}

// The Embree scene, and what the gather derives once from the surface: where each vertex's rays
// start and each triangle's lit-side normal.
struct IlluminationEngine::Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::string first_error;  // Embree's message for the first error it reported

  double offset = 0;                               // metres, see kOffsetPerSceneSize
  std::vector<Eigen::Vector3d> vertex_normals;     // unit, double
  std::vector<Eigen::Vector3d> ray_origins;        // per vertex
  std::vector<Eigen::Vector3d> triangle_normals;   // unit, lit side; zero for a degenerate triangle
  // Each vertex's triangles (fan_faces[fan_offsets[v] .. fan_offsets[v + 1])) with the running
  // fraction of the fan's area up to and including each: where a cell-averaged gather picks the
  // triangle of a ray's origin.
  std::vector<int64_t> fan_offsets;
  std::vector<int32_t> fan_faces;
  std::vector<double> fan_area_fraction;
  const SurfaceMesh* mesh = nullptr;  // the engine's, for the cells' corners

  Embree() = default;
  Embree(const Embree&) = delete;
  Embree& operator=(const Embree&) = delete;
  ~Embree() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }

  // Casts vertex v's S hemisphere rays and calls on_packet(packet, directions, first, count, hash)
  // after each intersection. The rays go in packets of kPacket consecutive samples (always the
  // same packets for the same point, whatever the batch): they share an origin, which Embree's
  // packet traversal turns into shared work near it. `hash` is the point's, for per-sample jitter.
  template <typename OnPacket>
  void cast_hemisphere(int v, const GatherOptions& options, RTCIntersectContext& context, OnPacket&& on_packet) const {
    const auto vs = static_cast<size_t>(v);
    const int samples = options.samples;
    const bool stratified = options.sampling == HemisphereSampling::kStratified;
    const int rows = std::max(1, static_cast<int>(std::floor(std::sqrt(static_cast<double>(samples)))));
    // The point's Cranley–Patterson rotation of the Hammersley set.
    const uint64_t hash = splitmix64(splitmix64(options.seed) ^ static_cast<uint64_t>(v));
    const double rotation_1 = unit_interval(hash);
    const double rotation_2 = unit_interval(splitmix64(hash));
    const Eigen::Vector3d& normal = vertex_normals[vs];
    Eigen::Vector3d tangent, bitangent;
    orthonormal_basis(normal, tangent, bitangent);
    const Eigen::Vector3d& origin = ray_origins[vs];
    const bool cell = options.cell_average && fan_offsets[vs + 1] > fan_offsets[vs];
    const std::array<double, 3>* cell_points = cell ? halton_cell_points(samples).data() : nullptr;
    const uint64_t cell_hash = splitmix64(hash ^ 0x9e3779b97f4a7c15ull);
    const double cell_rotation[3] = {unit_interval(cell_hash), unit_interval(splitmix64(cell_hash)),
                                     unit_interval(splitmix64(splitmix64(cell_hash)))};
    for (int first = 0; first < samples; first += kPacket) {
      const int count = std::min(kPacket, samples - first);
      alignas(64) int valid[kPacket];
      alignas(64) RTCRayHit16 packet;
      Eigen::Vector3d directions[kPacket];
      for (int k = 0; k < kPacket; ++k) {
        valid[k] = k < count ? -1 : 0;
        packet.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        packet.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
        if (k >= count) continue;
        const int s = first + k;
        // Cosine-weighted direction (pdf cos θ / π): r = √u₁ on the unit disc, lifted to the
        // hemisphere.
        double u1, u2;
        if (stratified) {
          // Cell s of `rows` rows; row i holds the cells s ∈ [a, b) = [⌈i·S/rows⌉, ⌈(i+1)·S/rows⌉)
          // (so s is in row ⌊s·rows/S⌋) and spans u₁ ∈ [a/S, b/S): every cell has area 1/S,
          // which the plain average over samples needs to be unbiased when rows differ in count.
          const int row = static_cast<int>(static_cast<int64_t>(s) * rows / samples);
          const int row_first = static_cast<int>((static_cast<int64_t>(row) * samples + rows - 1) / rows);
          const int row_end = static_cast<int>((static_cast<int64_t>(row + 1) * samples + rows - 1) / rows);
          const uint64_t bits = splitmix64(hash ^ (0x5bd1e995ull * static_cast<uint64_t>(s + 1)));
          u1 = (row_first + unit_interval(bits) * (row_end - row_first)) / samples;
          u2 = (s - row_first + unit_interval(splitmix64(bits))) / (row_end - row_first);
        } else {
          u1 = fractional(static_cast<double>(s) / samples + rotation_1);
          u2 = fractional(radical_inverse_base2(static_cast<uint32_t>(s)) + rotation_2);
        }
        const double radius = std::sqrt(u1);
        const double phi = 2.0 * kPi * u2;
        directions[k] = (radius * std::cos(phi)) * tangent + (radius * std::sin(phi)) * bitangent +
                        std::sqrt(std::max(0.0, 1.0 - u1)) * normal;
        const Eigen::Vector3d ray_origin =
            cell ? Eigen::Vector3d(origin + cell_offset(v, {fractional(cell_points[static_cast<size_t>(s)][0] + cell_rotation[0]),
                                                            fractional(cell_points[static_cast<size_t>(s)][1] + cell_rotation[1]),
                                                            fractional(cell_points[static_cast<size_t>(s)][2] + cell_rotation[2])}))
                 : origin;
        set_ray(packet.ray, k, ray_origin, directions[k], std::numeric_limits<float>::infinity());
      }
      rtcIntersect16(valid, scene, &context, &packet);
      on_packet(packet, directions, first, count, hash);
    }
  }

  // A uniform point of vertex v's cell — the part of its triangles where its barycentric weight is
  // the largest (a third of each) — minus the vertex, from u ∈ [0, 1)³: u₀ picks the triangle by
  // area, (u₁, u₂) a uniform point of it (barycentrics (1 − √u₁, √u₁ (1 − u₂), √u₁ u₂)), and the
  // largest barycentric is swapped onto v. Each of the three regions where one barycentric is the
  // largest is the image of the others under a swap of two coordinates, an area-preserving map,
  // so the swapped point is uniform on v's region.
  Eigen::Vector3d cell_offset(int v, const std::array<double, 3>& u) const {
    const auto vs = static_cast<size_t>(v);
    int64_t i = fan_offsets[vs];
    while (i + 1 < fan_offsets[vs + 1] && fan_area_fraction[static_cast<size_t>(i)] <= u[0]) ++i;
    const int32_t f = fan_faces[static_cast<size_t>(i)];
    const double root = std::sqrt(u[1]);
    double weights[3] = {1.0 - root, root * (1.0 - u[2]), root * u[2]};
    int mine = 0;
    for (int c = 1; c < 3; ++c) mine = mesh->faces(f, c) == v ? c : mine;
    const int largest = weights[0] >= weights[1] ? (weights[0] >= weights[2] ? 0 : 2) : (weights[1] >= weights[2] ? 1 : 2);
    std::swap(weights[largest], weights[mine]);
    Eigen::Vector3d from_vertex = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) {
      const int32_t corner = mesh->faces(f, c);
      if (corner != v) from_vertex += weights[c] * (mesh->vertices.row(corner) - mesh->vertices.row(v)).cast<double>().transpose();
    }
    return from_vertex;
  }

  // The fraction of `rays` shadow rays to `light` that arrive from points of vertex v's cell: the
  // cell points of cast_hemisphere (halton_cell_points), rotated per (seed, v) from their own
  // stream, each moved off the surface as ray_origins[v] is.
  double cell_visibility(int v, const Eigen::Vector3d& light, int rays, uint64_t seed, RTCIntersectContext& context) const {
    const uint64_t hash = splitmix64(splitmix64(seed ^ kCellShadowStream) ^ static_cast<uint64_t>(v));
    const double rotation[3] = {unit_interval(hash), unit_interval(splitmix64(hash)),
                                unit_interval(splitmix64(splitmix64(hash)))};
    const std::vector<std::array<double, 3>>& points = halton_cell_points(rays);
    const Eigen::Vector3d& origin = ray_origins[static_cast<size_t>(v)];
    int arrived = 0;
    for (int first = 0; first < rays; first += kPacket) {
      const int count = std::min(kPacket, rays - first);
      alignas(64) int valid[kPacket];
      alignas(64) RTCRay16 shadow;
      for (int k = 0; k < kPacket; ++k) {
        valid[k] = 0;
        if (k >= count) continue;
        const std::array<double, 3>& u = points[static_cast<size_t>(first + k)];
        const Eigen::Vector3d from = origin + cell_offset(v, {fractional(u[0] + rotation[0]), fractional(u[1] + rotation[1]),
                                                              fractional(u[2] + rotation[2])});
        const Eigen::Vector3d to = light - from;
        const double distance = to.norm();
        if (!(distance > 0)) continue;
        set_ray(shadow, k, from, to / distance, static_cast<float>(distance * (1.0 - kShadowShortening)));
        valid[k] = -1;
      }
      rtcOccluded16(valid, scene, &context, &shadow);
      for (int k = 0; k < count; ++k) {
        if (valid[k] != 0 && shadow.tfar[k] >= 0) ++arrived;  // Embree sets tfar to −∞ when blocked
      }
    }
    return static_cast<double>(arrived) / rays;
  }

  // Whether ray k of the packet hit a triangle from its lit side (a ray that left the scene, a
  // hit on the unlit side or on a degenerate triangle adds nothing to the gather).
  bool lit_hit(const RTCRayHit16& packet, int k, const Eigen::Vector3d& direction) const {
    if (packet.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID) return false;
    return triangle_normals[static_cast<size_t>(packet.hit.primID[k])].dot(direction) < 0;
  }

  // The lit hits of each point's rays, in the order of `points` and of the samples.
  PointHits vertex_hits(const std::vector<int>& points, const GatherOptions& options) const {
    const auto count = static_cast<int64_t>(points.size());
    PointHits hits;
    hits.blocks.resize(static_cast<size_t>((count + kPointsPerHitBlock - 1) / kPointsPerHitBlock));
    hits.ends.assign(points.size(), 0);
    parallel_for_grains(static_cast<int64_t>(hits.blocks.size()), 1, 1, [&](int64_t begin, int64_t end) {
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      for (int64_t b = begin; b < end; ++b) {
        std::vector<VertexHit>& out = hits.blocks[static_cast<size_t>(b)];
        out.reserve(static_cast<size_t>(kPointsPerHitBlock * options.samples));
        for (int64_t p = b * kPointsPerHitBlock; p < std::min(count, (b + 1) * kPointsPerHitBlock); ++p) {
          const int v = points[static_cast<size_t>(p)];
          assert(v >= 0 && static_cast<size_t>(v) < vertex_normals.size());
          cast_hemisphere(v, options, context, [&](const RTCRayHit16& packet, const Eigen::Vector3d* directions,
                                                   int, int packet_count, uint64_t) {
            for (int k = 0; k < packet_count; ++k) {
              if (lit_hit(packet, k, directions[k])) out.push_back({packet.hit.primID[k], packet.hit.u[k], packet.hit.v[k]});
            }
          });
          hits.ends[static_cast<size_t>(p)] = static_cast<int64_t>(out.size());
        }
        out.shrink_to_fit();
      }
    });
    return hits;
  }

  // What x (normal n) receives from a point light: max(0, n·ω) / r² per unit intensity, and
  // whether one shadow ray from `origin` (x moved off the surface) reaches it.
  struct LightAtPoint {
    enum Seen : uint8_t { kFacingAway, kBlocked, kLit };
    double received = 0;  // set unless kFacingAway
    Seen seen = kFacingAway;
  };
  LightAtPoint light_at(const Eigen::Vector3d& x, const Eigen::Vector3d& n, const Eigen::Vector3d& origin,
                        const Eigen::Vector3d& light, RTCIntersectContext& context) const {
    LightAtPoint at;
    const Eigen::Vector3d to_light = light - x;
    const double n_dot = n.dot(to_light);
    if (!(n_dot > 0)) return at;
    const double r2 = to_light.squaredNorm();
    const Eigen::Vector3d shadow = light - origin;
    const double distance = shadow.norm();
    if (!(distance > 0)) return at;
    at.received = n_dot / (std::sqrt(r2) * r2);
    RTCRay ray = make_ray(origin, shadow / distance, static_cast<float>(distance * (1.0 - kShadowShortening)));
    rtcOccluded1(scene, &context, &ray);
    at.seen = ray.tfar < 0 ? LightAtPoint::kBlocked : LightAtPoint::kLit;  // Embree sets tfar to −∞ when blocked
    return at;
  }

  // Σ_l I_l · max(0, n·ω_l) / r_l² · V: the irradiance at x (normal n) from the lights, with
  // shadow rays leaving from `origin`. Channels in `sum`.
  void add_irradiance(const Eigen::Vector3d& x, const Eigen::Vector3d& n, const Eigen::Vector3d& origin,
                      const std::vector<PointLight>& lights, RTCIntersectContext& context, Eigen::Vector3d& sum) const {
    for (const PointLight& light : lights) {
      const LightAtPoint at = light_at(x, n, origin, light.position, context);
      if (at.seen == LightAtPoint::kLit) sum += light.intensity * at.received;
    }
  }

  // Whether vertex v's fan has a corner whose light differs from v's (lit against blocked), the
  // corners facing away aside.
  bool fan_straddles_a_shadow(int v, const std::vector<LightAtPoint>& at) const {
    const auto vs = static_cast<size_t>(v);
    for (int64_t i = fan_offsets[vs]; i < fan_offsets[vs + 1]; ++i) {
      const int32_t f = fan_faces[static_cast<size_t>(i)];
      for (int c = 0; c < 3; ++c) {
        const LightAtPoint::Seen corner = at[static_cast<size_t>(mesh->faces(f, c))].seen;
        if (corner != LightAtPoint::kFacingAway && corner != at[vs].seen) return true;
      }
    }
    return false;
  }

  // add_irradiance for the hits of one packet (`lit` marks the hits that count): per light, one
  // packet of shadow rays from each hit moved off its surface. irradiance[k] gains what hit k
  // receives, lights in order, as add_irradiance would add it. With radius > 0 each light is a
  // disc of that radius facing the hit: `shadow_rays` packets, ray j of hit k aimed at the disc
  // point (r, φ) = (radius·√((j + u)/J), 2π(j·φ_golden + v)) with (u, v) drawn from jitter[k]
  // and j, and the hit receives the fraction of them that arrive.
  void add_irradiance_packet(const Eigen::Vector3d* x, const Eigen::Vector3d* n, const bool* lit, int count,
                             const std::vector<PointLight>& lights, double radius, int shadow_rays,
                             const uint64_t* jitter, RTCIntersectContext& context, Eigen::Vector3d* irradiance) const {
    const int rays = radius > 0 ? shadow_rays : 1;
    for (const PointLight& light : lights) {
      double received[kPacket];
      int arrived[kPacket] = {};
      bool facing[kPacket] = {};
      Eigen::Vector3d origins[kPacket], across_1[kPacket], across_2[kPacket];
      for (int k = 0; k < count; ++k) {
        if (!lit[k]) continue;
        const Eigen::Vector3d to_light = light.position - x[k];
        const double n_dot = n[k].dot(to_light);
        if (!(n_dot > 0)) continue;
        const double r2 = to_light.squaredNorm();
        received[k] = n_dot / (std::sqrt(r2) * r2);
        origins[k] = x[k] + offset * n[k];
        if (radius > 0) {
          const Eigen::Vector3d axis = to_light / std::sqrt(r2);
          orthonormal_basis(axis, across_1[k], across_2[k]);
        }
        facing[k] = true;
      }
      for (int j = 0; j < rays; ++j) {
        alignas(64) int valid[kPacket];
        alignas(64) RTCRay16 shadow;
        for (int k = 0; k < kPacket; ++k) {
          valid[k] = 0;
          if (k >= count || !facing[k]) continue;
          Eigen::Vector3d target = light.position;
          if (radius > 0) {
            const uint64_t bits = splitmix64(jitter[k] ^ (0xA5A5A5A5ull + static_cast<uint64_t>(j)));
            const double r = radius * std::sqrt((j + unit_interval(bits)) / rays);
            const double phi = 2.0 * kPi * fractional(j * kGoldenFraction + unit_interval(splitmix64(bits)));
            target += (r * std::cos(phi)) * across_1[k] + (r * std::sin(phi)) * across_2[k];
          }
          const Eigen::Vector3d to = target - origins[k];
          const double distance = to.norm();
          if (!(distance > 0)) continue;
          set_ray(shadow, k, origins[k], to / distance, static_cast<float>(distance * (1.0 - kShadowShortening)));
          valid[k] = -1;
        }
        rtcOccluded16(valid, scene, &context, &shadow);
        for (int k = 0; k < count; ++k) {
          // Embree sets tfar to −∞ when the ray is blocked.
          if (valid[k] != 0 && shadow.tfar[k] >= 0) ++arrived[k];
        }
      }
      for (int k = 0; k < count; ++k) {
        if (arrived[k] > 0) irradiance[k] += light.intensity * (received[k] * arrived[k] / rays);
      }
    }
  }
};

IlluminationEngine::IlluminationEngine(SurfaceMesh surface) : surface_(std::move(surface)) {}
IlluminationEngine::~IlluminationEngine() = default;

Result<std::unique_ptr<IlluminationEngine>> IlluminationEngine::create(SurfaceMesh surface) {
  ANIMSPACE_RETURN_IF_ERROR(check_surface(surface, "surface"));
  std::unique_ptr<IlluminationEngine> engine(new IlluminationEngine(std::move(surface)));
  const SurfaceMesh& mesh = engine->surface_;
  engine->embree_ = std::make_unique<Embree>();
  Embree& e = *engine->embree_;
  const Eigen::Index n = mesh.vertices.rows();
  const Eigen::Index t = mesh.faces.rows();

  // 1. The per-vertex and per-triangle data of the gather.
  e.vertex_normals.resize(static_cast<size_t>(n));
  for (Eigen::Index v = 0; v < n; ++v) {
    e.vertex_normals[static_cast<size_t>(v)] = mesh.normals.row(v).cast<double>().transpose().normalized();
  }
  e.triangle_normals.resize(static_cast<size_t>(t));
  std::vector<Eigen::Index> first_triangle(static_cast<size_t>(n), -1);
  for (Eigen::Index f = 0; f < t; ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.faces(f, 0)).cast<double>();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.faces(f, 1)).cast<double>();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.faces(f, 2)).cast<double>();
    Eigen::Vector3d normal = (b - a).cross(c - a);
    Eigen::Vector3d vertex_normal_sum = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) {
      const auto v = static_cast<size_t>(mesh.faces(f, k));
      vertex_normal_sum += e.vertex_normals[v];
      if (first_triangle[v] < 0) first_triangle[v] = f;
    }
    if (normal.dot(vertex_normal_sum) < 0) normal = -normal;  // the side the surface calls lit
    const double length = normal.norm();
    e.triangle_normals[static_cast<size_t>(f)] = length > 0 ? Eigen::Vector3d(normal / length) : Eigen::Vector3d::Zero();
  }
  if (n > 0) {
    const Eigen::Vector3f extent = mesh.vertices.colwise().maxCoeff() - mesh.vertices.colwise().minCoeff();
    e.offset = kOffsetPerSceneSize * extent.cast<double>().norm();
  }
  // Off the surface along the normal, and into the vertex's first triangle (towards its
  // centroid, in the tangent plane): a vertex on a crease then starts inside its own face.
  e.ray_origins.resize(static_cast<size_t>(n));
  for (Eigen::Index v = 0; v < n; ++v) {
    const Eigen::Vector3d x = mesh.vertices.row(v).cast<double>();
    const Eigen::Vector3d& normal = e.vertex_normals[static_cast<size_t>(v)];
    Eigen::Vector3d origin = x + e.offset * normal;
    if (const Eigen::Index f = first_triangle[static_cast<size_t>(v)]; f >= 0) {
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) centroid += mesh.vertices.row(mesh.faces(f, k)).cast<double>();
      Eigen::Vector3d inward = centroid / 3.0 - x;
      inward -= inward.dot(normal) * normal;
      const double length = inward.norm();
      if (length > 0) origin += (e.offset / length) * inward;
    }
    e.ray_origins[static_cast<size_t>(v)] = origin;
  }
  // Each vertex's fan, for the cell-averaged gather.
  e.mesh = &mesh;
  e.fan_offsets.assign(static_cast<size_t>(n) + 1, 0);
  for (Eigen::Index f = 0; f < t; ++f) {
    for (int k = 0; k < 3; ++k) ++e.fan_offsets[static_cast<size_t>(mesh.faces(f, k)) + 1];
  }
  std::partial_sum(e.fan_offsets.begin(), e.fan_offsets.end(), e.fan_offsets.begin());
  e.fan_faces.resize(static_cast<size_t>(e.fan_offsets.back()));
  e.fan_area_fraction.resize(e.fan_faces.size());
  {
    std::vector<int64_t> next(e.fan_offsets.begin(), e.fan_offsets.end() - 1);
    for (Eigen::Index f = 0; f < t; ++f) {
      const Eigen::Vector3d a = mesh.vertices.row(mesh.faces(f, 0)).cast<double>();
      const Eigen::Vector3d b = mesh.vertices.row(mesh.faces(f, 1)).cast<double>();
      const Eigen::Vector3d c = mesh.vertices.row(mesh.faces(f, 2)).cast<double>();
      const double area = 0.5 * (b - a).cross(c - a).norm();
      for (int k = 0; k < 3; ++k) {
        const auto at = static_cast<size_t>(next[static_cast<size_t>(mesh.faces(f, k))]++);
        e.fan_faces[at] = static_cast<int32_t>(f);
        e.fan_area_fraction[at] = area;
      }
    }
  }
  for (Eigen::Index v = 0; v < n; ++v) {
    const auto begin = static_cast<size_t>(e.fan_offsets[static_cast<size_t>(v)]);
    const auto end = static_cast<size_t>(e.fan_offsets[static_cast<size_t>(v) + 1]);
    const double total = std::accumulate(e.fan_area_fraction.begin() + static_cast<long>(begin),
                                         e.fan_area_fraction.begin() + static_cast<long>(end), 0.0);
    double running = 0;
    for (size_t i = begin; i < end; ++i) {
      running += e.fan_area_fraction[i];
      // A fan of degenerate triangles: uniform over them (their points are the vertex anyway).
      e.fan_area_fraction[i] = total > 0 ? running / total : static_cast<double>(i + 1 - begin) / static_cast<double>(end - begin);
    }
  }

  // 2. The Embree scene: one triangle geometry over the surface, built once.
  e.device = rtcNewDevice(nullptr);
  if (e.device == nullptr) {
    return make_error(ErrorCode::kInternal,
                      std::string("Embree could not create a device: ") + embree_error_name(rtcGetDeviceError(nullptr)));
  }
  rtcSetDeviceErrorFunction(e.device, record_embree_error, &e.first_error);
  e.scene = rtcNewScene(e.device);
  if (e.scene != nullptr) {
    rtcSetSceneFlags(e.scene, RTC_SCENE_FLAG_ROBUST);  // watertight: no rays through shared edges
    rtcSetSceneBuildQuality(e.scene, RTC_BUILD_QUALITY_HIGH);
    if (t > 0) {
      RTCGeometry geometry = rtcNewGeometry(e.device, RTC_GEOMETRY_TYPE_TRIANGLE);
      auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                                   RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                                   static_cast<size_t>(n)));
      auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
                                                                     RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                                     static_cast<size_t>(t)));
      if (vertices != nullptr && indices != nullptr) {
        std::copy(mesh.vertices.data(), mesh.vertices.data() + 3 * n, vertices);
        for (Eigen::Index i = 0; i < 3 * t; ++i) indices[i] = static_cast<unsigned>(mesh.faces.data()[i]);
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(e.scene, geometry);
      }
      rtcReleaseGeometry(geometry);
    }
    rtcCommitScene(e.scene);
  }
  if (const RTCError code = rtcGetDeviceError(e.device); code != RTC_ERROR_NONE || e.scene == nullptr) {
    return make_error(ErrorCode::kInternal, std::string("Embree could not build the scene of ") + std::to_string(t) +
                                                " triangles: " + embree_error_name(code) +
                                                (e.first_error.empty() ? "" : " (" + e.first_error + ")"));
  }
  return engine;
}

void IlluminationEngine::direct(const std::vector<PointLight>& lights, const std::vector<int>& points,
                                Eigen::VectorXf& out) const {
  out.resize(3 * static_cast<Eigen::Index>(points.size()));
  const Embree& e = *embree_;
  for_each_point(points, kDirectPointsPerThread, kDirectPointsPerGrain, [&](int64_t p, int v, RTCIntersectContext& context) {
    assert(v >= 0 && v < point_count());
    const auto vs = static_cast<size_t>(v);
    Eigen::Vector3d irradiance = Eigen::Vector3d::Zero();
    e.add_irradiance(surface_.vertices.row(v).cast<double>(), e.vertex_normals[vs], e.ray_origins[vs], lights, context,
                     irradiance);
    const Eigen::Vector3d radiance = surface_.albedo.row(v).cast<double>().transpose().cwiseProduct(irradiance) / kPi;
    out.segment<3>(3 * p) = radiance.cast<float>();
  });
}

void IlluminationEngine::vertex_direct(const std::vector<PointLight>& lights, const GatherOptions& options,
                                       Eigen::VectorXf& out) const {
  const std::vector<int> points = all_points();
  if (options.cell_shadow_rays <= 0) {
    direct(lights, points, out);
    return;
  }
  // Per light: the vertex's own shadow ray everywhere (as direct()), then the cell's rays where
  // the fan straddles the shadow's edge; the cos θ / r² factor is the vertex's either way, so a
  // cell all lit gives direct()'s value bit for bit.
  const Embree& e = *embree_;
  using LightAtPoint = Embree::LightAtPoint;
  const auto n = static_cast<size_t>(point_count());
  std::vector<Eigen::Vector3d> irradiance(n, Eigen::Vector3d::Zero());
  std::vector<LightAtPoint> at(n);
  for (const PointLight& light : lights) {
    for_each_point(points, kDirectPointsPerThread, kDirectPointsPerGrain, [&](int64_t, int v, RTCIntersectContext& context) {
      const auto vs = static_cast<size_t>(v);
      at[vs] = e.light_at(surface_.vertices.row(v).cast<double>(), e.vertex_normals[vs], e.ray_origins[vs], light.position,
                          context);
    });
    for_each_point(points, kDirectPointsPerThread, kDirectPointsPerGrain, [&](int64_t, int v, RTCIntersectContext& context) {
      const auto vs = static_cast<size_t>(v);
      if (at[vs].seen == LightAtPoint::kFacingAway) return;
      double fraction = at[vs].seen == LightAtPoint::kLit ? 1.0 : 0.0;
      if (e.fan_straddles_a_shadow(v, at)) {
        fraction = e.cell_visibility(v, light.position, options.cell_shadow_rays, options.seed, context);
      }
      if (fraction > 0) irradiance[vs] += light.intensity * (at[vs].received * fraction);
    });
  }
  out.resize(3 * static_cast<Eigen::Index>(n));
  for (Eigen::Index v = 0; v < static_cast<Eigen::Index>(n); ++v) {
    const Eigen::Vector3d rho = surface_.albedo.row(v).cast<double>().transpose();
    out.segment<3>(3 * v) = (rho.cwiseProduct(irradiance[static_cast<size_t>(v)]) / kPi).cast<float>();
  }
}

void IlluminationEngine::indirect(const std::vector<PointLight>& lights, const GatherOptions& options,
                                  const std::vector<int>& points, Eigen::VectorXf& out) const {
  assert(options.samples >= 1);
  out.resize(3 * static_cast<Eigen::Index>(points.size()));
  const Embree& e = *embree_;
  if (options.direct_from_vertices) {
    // L_d at every vertex (vertex_direct: one shadow ray per vertex and light, a cell's more at a
    // shadow's edge; at 100k points about what 50 of the points' 2,048 rays cost), then each
    // point's hits summed as its packets come back, in the order of its samples — the terms and
    // order of indirect_frames, so that a point's value does not depend on how it was computed,
    // and no hit is stored.
    Eigen::VectorXf stored_direct;
    vertex_direct(lights, options, stored_direct);
    for_each_point(points, kIndirectPointsPerThread, kIndirectPointsPerGrain, [&](int64_t p, int v, RTCIntersectContext& context) {
      assert(v >= 0 && v < point_count());
      float sums[3] = {0, 0, 0};
      e.cast_hemisphere(v, options, context, [&](const RTCRayHit16& packet, const Eigen::Vector3d* directions, int,
                                                 int count, uint64_t) {
        VertexHit hits[kPacket];
        int lit = 0;
        for (int k = 0; k < count; ++k) {
          if (e.lit_hit(packet, k, directions[k])) hits[lit++] = {packet.hit.primID[k], packet.hit.u[k], packet.hit.v[k]};
        }
        sum_interpolated(surface_.faces.data(), hits, hits + lit, stored_direct.data(), 1, sums);
      });
      store_indirect(surface_, v, sums, options.samples, out.data() + 3 * p);
    });
    return;
  }
  for_each_point(points, kIndirectPointsPerThread, kIndirectPointsPerGrain, [&](int64_t p, int v, RTCIntersectContext& context) {
    assert(v >= 0 && v < point_count());
    double sums[3] = {0, 0, 0};  // Σ_s L_d(y_s), in the order of s
    e.cast_hemisphere(v, options, context, [&](const RTCRayHit16& packet, const Eigen::Vector3d* directions,
                                               int first, int count, uint64_t hash) {
      // Each hit's point, normal and albedo (Embree: p = (1−u−v)·v₀ + u·v₁ + v·v₂); hits on
      // the unlit side (or a degenerate triangle) and rays that left the scene add nothing.
      // The packet's shadow rays, one per hit and light, go as a packet too.
      bool lit[kPacket] = {};
      uint64_t jitter[kPacket];
      Eigen::Vector3d hits[kPacket], hit_normals[kPacket], albedos[kPacket], irradiance[kPacket];
      for (int k = 0; k < count; ++k) {
        if (!e.lit_hit(packet, k, directions[k])) continue;
        const auto f = static_cast<Eigen::Index>(packet.hit.primID[k]);
        hit_normals[k] = e.triangle_normals[static_cast<size_t>(f)];
        const double bu = packet.hit.u[k];
        const double bv = packet.hit.v[k];
        const double bw = 1.0 - bu - bv;
        const int i0 = surface_.faces(f, 0);
        const int i1 = surface_.faces(f, 1);
        const int i2 = surface_.faces(f, 2);
        hits[k] = bw * surface_.vertices.row(i0).cast<double>() + bu * surface_.vertices.row(i1).cast<double>() +
                  bv * surface_.vertices.row(i2).cast<double>();
        albedos[k] = bw * surface_.albedo.row(i0).cast<double>() + bu * surface_.albedo.row(i1).cast<double>() +
                     bv * surface_.albedo.row(i2).cast<double>();
        irradiance[k].setZero();
        jitter[k] = splitmix64(hash + static_cast<uint64_t>(first + k));
        lit[k] = true;
      }
      e.add_irradiance_packet(hits, hit_normals, lit, count, lights, options.light_radius, options.shadow_rays, jitter,
                              context, irradiance);
      for (int k = 0; k < count; ++k) {
        if (!lit[k]) continue;
        const Eigen::Vector3d radiance = albedos[k].cwiseProduct(irradiance[k]) / kPi;
        for (int c = 0; c < 3; ++c) sums[c] += radiance(c);
      }
    });
    store_indirect(surface_, v, sums, options.samples, out.data() + 3 * p);
  });
}

void IlluminationEngine::indirect_frames(const std::vector<PointLight>& lights, const GatherOptions& options,
                                         FrameMatrix& frames, const ProgressCallback& progress) const {
  const std::vector<int> points = all_points();
  const auto light_count = static_cast<int64_t>(lights.size());
  frames.resize(static_cast<Eigen::Index>(light_count), 3 * static_cast<Eigen::Index>(points.size()));
  if (!options.direct_from_vertices) {
    Eigen::VectorXf frame;
    for (int64_t l = 0; l < light_count; ++l) {
      indirect({lights[static_cast<size_t>(l)]}, options, points, frame);
      frames.row(static_cast<Eigen::Index>(l)) = frame.transpose();
      report_progress(progress, "gather", l + 1, light_count);
    }
    return;
  }
  // The rays once for every light; then, a block of lights at a time, L_d of each at every vertex
  // (vertex-major, the block's lights side by side so that one hit reads them together) and every
  // point's sums for the block.
  const PointHits hits = embree_->vertex_hits(points, options);
  const int64_t n = point_count();
  std::vector<float> block_direct;
  Eigen::VectorXf light_direct;
  for (int64_t first = 0; first < light_count; first += kLightsPerBlock) {
    const int block = static_cast<int>(std::min<int64_t>(kLightsPerBlock, light_count - first));
    // Always kLightsPerBlock lights per vertex (a short last block padded with zeros).
    block_direct.assign(3 * static_cast<size_t>(kLightsPerBlock) * static_cast<size_t>(n), 0.0f);
    for (int b = 0; b < block; ++b) {
      vertex_direct({lights[static_cast<size_t>(first + b)]}, options, light_direct);
      for (int64_t v = 0; v < n; ++v) {
        for (int c = 0; c < 3; ++c) {
          block_direct[static_cast<size_t>((v * kLightsPerBlock + b) * 3 + c)] = light_direct(3 * v + c);
        }
      }
    }
    parallel_for_grains(n, kInterpolatedPointsPerThread, kInterpolatedPointsPerGrain, [&](int64_t begin, int64_t end) {
      float sums[3 * kLightsPerBlock];
      float out[3];
      for (int64_t p = begin; p < end; ++p) {
        std::fill(std::begin(sums), std::end(sums), 0.0f);
        sum_interpolated(surface_.faces.data(), hits.begin(p), hits.end(p), block_direct.data(), kLightsPerBlock, sums);
        for (int b = 0; b < block; ++b) {
          store_indirect(surface_, static_cast<int>(p), sums + 3 * b, options.samples, out);
          for (int c = 0; c < 3; ++c) frames(static_cast<Eigen::Index>(first + b), 3 * p + c) = out[c];
        }
      }
    });
    report_progress(progress, "gather", first + block, light_count);
  }
}

std::vector<int> IlluminationEngine::all_points() const {
  std::vector<int> points(static_cast<size_t>(point_count()));
  std::iota(points.begin(), points.end(), 0);
  return points;
}

}  // namespace animspace::illumination
