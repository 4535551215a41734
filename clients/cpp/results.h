// Plain results of animspace::Client's pose calls, decoded from the wire once so that callers
// work with contiguous float arrays rather than protobuf bytes.
//
// Every point array is N×D float32, point-major (row-major), ready for Eigen without a copy:
//   Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>> v(
//       result.points.values.data(), result.points.point_count, 3);
// The client library itself does not depend on Eigen (it links only the generated stubs).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "animspace/v1/common.pb.h"
#include "animspace/v1/poses.pb.h"
#include "animspace/v1/skinning.pb.h"

namespace animspace {

// N points × D channels, point-major (PointArray's field names).
struct Points {
  uint32_t point_count = 0;    // N
  uint32_t channel_count = 0;  // D
  std::vector<float> values;   // N·D, float32 whatever the wire's PointEncoding
  // For points that travelled in a 16-bit encoding (EvaluateOptions::points_encoding): the largest
  // |decoded − float32 value| over the array, as the server measured it; 0 for float32.
  float max_error = 0;

  bool empty() const { return point_count == 0; }
  // The D channels of point i.
  std::span<const float> point(uint32_t i) const {
    return {values.data() + size_t{i} * channel_count, channel_count};
  }
};

// The key points a PMSC model needs (PoseService.DescribeKeyPoints).
struct KeyPoints {
  uint64_t model_version = 0;
  // Zero-based indices into the full (or, for cross-PMSC, control) point set, in the order key
  // values must be sent.
  std::vector<uint32_t> indices;
  uint32_t channel_count = 0;
  uint32_t control_point_count = 0;
  // Region of each key point for models with regions (local fail-through), else empty.
  std::vector<uint32_t> regions;
  v1::FailThrough fail_through = v1::FAIL_THROUGH_UNSPECIFIED;
  // Check points (issue #35): C more indices into the same point set, computed like key points
  // and sent as KeyPointPose::check_values in this order; the server measures the estimate's
  // error there, and a HIT the key points alone would give can become BLEND or MISS. Empty for
  // models without check points.
  std::vector<uint32_t> check_point_indices;
  std::vector<uint32_t> check_point_regions;  // region of each check point, when the model has regions
  // The version's subspace as GetBasis names it (0 and empty without one): a cached basis is
  // checked against basis_sha256 before it is used (issue #54 item 8).
  uint64_t basis_checksum = 0;
  std::string basis_sha256;

  // Gathers a frame's key values from its N×D point-major values (`frame` holds every point).
  std::vector<float> gather(std::span<const float> frame) const;
  // The same for the check values (C×D; empty for a model without check points).
  std::vector<float> gather_check_values(std::span<const float> frame) const;
};

// A skeleton pose: for each bone in model order, the top three rows of its 4×4 affine matrix,
// row-major (12 floats per bone).
struct SkeletonPose {
  v1::SkeletonPose::Space space = v1::SkeletonPose::SPACE_LOCAL;
  std::vector<float> transforms;  // B·12
};

// A point light for an illumination model (v1.PointLight): position in the model's units, RGB
// radiant intensity in W/sr (empty: the model's training intensity).
struct PointLight {
  std::array<double, 3> position{};
  std::vector<double> intensity;
};

// One key-point pose to evaluate: K×D values in DescribeKeyPoints order, and optionally the
// engine input it came from so that a server engine can complete a blend or miss — the skeleton
// pose (animation space) or the lights (illumination). With lights and no key values, an
// illumination model's server gathers the key values itself. `check_values` (C×D in
// KeyPoints::check_point_indices order, KeyPoints::gather_check_values) lets the server check the
// estimate where the key points are blind; empty: the verdict rests on e_key alone.
struct KeyPointPose {
  std::span<const float> key_values;
  uint32_t channel_count = 3;
  const SkeletonPose* skeleton_pose = nullptr;
  std::span<const PointLight> lights = {};
  std::span<const float> check_values = {};
};

struct RegionError {
  uint32_t region = 0;
  float key_point_error = 0;  // the region's error estimate (with its check points, when sent)
  v1::CacheStatus status = v1::CACHE_STATUS_UNSPECIFIED;
};

// An answer as subspace coordinates (points_encoding POINT_ENCODING_COORDINATES, poses.proto
// SubspaceCoordinates): f̂_i = R (mean_i + Σ_j A_ij p_j) + t with the basis PoseService.GetBasis
// sends; clients/cpp/coordinates.h reconstructs it.
struct SubspaceCoordinates {
  bool present = false;
  std::vector<float> p;         // M
  uint64_t basis_checksum = 0;  // the basis p belongs to (BasisData::basis_checksum)
  std::vector<float> rotation;  // aligned models: R row-major (9), else empty
  std::vector<float> translation;  // aligned models: t (3), else empty
};

// The soft cache's answer for one pose (Meyer & Anderson 2006 §5).
struct PoseResult {
  Points points;  // empty when points were omitted
  v1::CacheStatus status = v1::CACHE_STATUS_UNSPECIFIED;
  float key_point_error = 0;  // e_key
  float key_point_max_error = 0;  // the worst key point's residual (issue #52)
  // e_check = max over check points of ‖f_c − f̂_c‖ (0 unless `checked`), and the error estimate
  // the verdict compared with ε: max(w·k, e_check) when checked, else k — k the worst key's
  // residual (models trained since issue #52) or e_key (before).
  float check_point_error = 0;
  float error_estimate = 0;
  bool checked = false;       // the pose was sent with check values and the model has check points
  // A model with ModelVersion.relative_tolerance (issue #38): S, the pose's RMS point norm that the
  // errors above are fractions of; 0 when they are in model units.
  float pose_scale = 0;
  float blend_weight = 0;     // α
  uint64_t model_version = 0;
  bool full_evaluation_needed = false;
  std::vector<RegionError> region_errors;
  uint64_t sequence = 0;  // streams: the frame this answers
  // Local fail-through (requested; blend or miss): the points that need the full calculation,
  // ascending — send their values with complete_miss(…, full_points) — and the blend weight α_i of
  // each. Empty when every region is within tolerance: `points` is the answer.
  std::vector<uint32_t> full_points;
  std::vector<float> full_point_blend_weights;
  // Asked for as coordinates and reconstructible by the client (a HIT, or a blend or miss with
  // full_evaluation_needed): `points` stays empty until reconstructed.
  SubspaceCoordinates coordinates;
};

struct CompletedMiss {
  PoseResult result;
  bool logged = false;  // appended to the model's miss log for retraining
  std::string not_logged_reason;  // why a blend or miss was not (e.g. the log's disk is full)
};

struct SkinnedPose {
  Points points;
  Points normals;  // empty unless requested
};

struct SkinningResult {
  uint64_t model_version = 0;
  std::vector<SkinnedPose> poses;
};

// Options shared by the key-point evaluations (unary, batch and stream).
struct EvaluateOptions {
  uint64_t version = 0;  // 0: the served default
  bool omit_points = false;
  bool include_region_errors = false;
  // Local fail-through: on a blend or miss, PoseResult::full_points names the points that need
  // the full calculation (those of the failing regions); the rest of the answer is already right.
  bool local_fail_through = false;
  // How the answers' points travel: float32 (unset), FLOAT16 or FIXED16 — half the bytes, decoded
  // to float32 by decode_points, Points::max_error saying what was lost (common.proto) — or
  // COORDINATES: M values instead of N·D, reconstructed by the caller (clients/cpp/coordinates.h).
  v1::PointEncoding points_encoding = v1::POINT_ENCODING_UNSPECIFIED;
  // Test traffic (load tests, benchmarks): blends and misses are served but kept out of the
  // model's miss log, and so out of retraining.
  bool skip_miss_log = false;
};

struct SkinningOptions {
  uint64_t version = 0;
  bool include_normals = false;
  uint32_t lod_level = 0;
};

// "HIT", "BLEND", "MISS" (or "UNSPECIFIED").
const char* cache_status_name(v1::CacheStatus status);

// Wire conversions, shared by the unary calls and the stream session. decode_points reads every
// PointEncoding (std::runtime_error for a malformed array or an encoding this client does not know).
Points decode_points(const v1::PointArray& array);
PoseResult decode_pose_result(const v1::PoseResult& result);
v1::KeyPointPose encode_key_point_pose(const KeyPointPose& pose);
v1::SkeletonPose encode_skeleton_pose(const SkeletonPose& pose);

}  // namespace animspace
