// How noisy and how smooth in the light's position the final gather is (issue #38): measured on
// a fixed sample of points, against itself with another seed, against a many-ray reference, and
// along a line of light positions.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/illumination/gather.h"

namespace animspace::illumination {

// `count` points spread evenly over the vertex indices by a fixed rule: point k is
// ⌊(k + ½)·N / count⌋ (all N points when count ≥ N). The Cornell box's vertices are numbered face
// by face, row by row, so this spreads them over every face in proportion to its points.
std::vector<int> spread_points(int point_count, int count);

// rms over points and channels of (estimate − reference) ÷ mean of the reference (both 3·P,
// point-major RGB; 0 when the reference's mean is not > 0).
double relative_rms_difference(const Eigen::VectorXf& estimate, const Eigen::VectorXf& reference);

// max over points of ‖estimate − reference‖ ÷ max over points of ‖reference‖ (RGB norms).
double max_error_over_max(const Eigen::VectorXf& estimate, const Eigen::VectorXf& reference);

// Roughness of the gather in the light's position: the light moved along `step` (metres) to
// `count` ≥ 3 positions centred on `light`, the gather at `points` for each, and the rms over
// interior positions, points and channels of the second difference f(x−δ) − 2f(x) + f(x+δ),
// ÷ the mean radiance over all positions. A gather that is a smooth function of the light has a
// roughness of order ‖δ‖²·curvature; each visibility step that a shadow ray takes between
// neighbouring positions adds its full height.
double light_roughness(const IlluminationEngine& engine, const PointLight& light, const Eigen::Vector3d& step,
                       int count, const GatherOptions& gather, const std::vector<int>& points);

}  // namespace animspace::illumination
