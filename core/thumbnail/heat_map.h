// The heat map of a cache's error (thesis Fig. 8.6 style): per point, how far what the cache
// returned is from the truth, drawn on the surface with a scale a reader can interpret.
#pragma once

#include <string_view>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/render/scene.h"

namespace animspace::thumbnail {

struct HeatScale {
  double largest_error = 0;  // max_i |truth_i − estimate_i|, model units (0 for no points)
  double scale_max = 0;      // the error drawn red (Scene::heat_max)
};

// Sets scene.heat to |truth_i − estimate_i| (N values; both N × 3, asserted) and scene.heat_max
// to the scale: `requested_max` when > 0, else `error_tolerance` when > 0 — the per-point error
// the model's ε was calibrated to flag, so that a hit's errors read as a fraction of what the
// model promises (ε_max itself bounds the RMS key-point error, a far smaller number than a point's
// error, and turned a hit mostly red) — else the largest error. Both ≥ 0 and finite (asserted).
// Errors: kInvalidArgument naming `field` (the truth's, e.g. "full_values") when a distance
// overflows float32.
Result<HeatScale> heat_map(const Eigen::Ref<const PointMatrix>& truth, const Eigen::Ref<const PointMatrix>& estimate,
                           double requested_max, double error_tolerance, std::string_view field, render::Scene& scene);

// A thumbnail whose heat legend is drawn at the image's right edge (render/heat_legend.h) and
// whose camera is not given: its points framed in the columns left of the legend's panel, so that
// the legend covers none of the model. A scene with a camera, or a legend that does not fit the
// image, is left as it is. Errors: render::frame_in_columns's.
Status frame_beside_heat_legend(render::Scene& scene, int width, int height, double heat_max);

}  // namespace animspace::thumbnail
