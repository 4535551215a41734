// Packing flattened charts into the unit square (Merry 2007 §5.4, after Sander et al. 2001 §5).
//
// Each chart is rotated to its minimum-area bounding rectangle (exactly: the rectangle has a side
// on an edge of the convex hull, so every hull edge is tried — the thesis sampled orientations)
// and laid landscape (width ≥ height). The rectangles go into a skyline packer (each, in either
// orientation, where its top is lowest, then its bottom, then leftmost) in three orders — tallest,
// largest, longest side first (Sander 2001 and the thesis sort by height; the others sometimes
// fit more) and perturbations of the first — and the largest common scale at which they all fit, `gutter` apart and `gutter` from
// the square's sides, is found by bisection for each order; the best order wins. Charts keep
// their relative sizes (the caller balances them, atlas.h).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::atlas {

using ChartUv = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

struct PackOptions {
  double gutter = 1.0 / 512;  // UV units between charts and from the square's sides (2 texels at 1024²)
  int shuffled_orders = 29;   // orders tried besides the three sorted ones (perturbed tallest-first)
};

struct PackResult {
  double scale = 0;        // the common scale applied to every chart
  double utilisation = 0;  // Σ chart UV area / atlas area (1)
};

// Rotates, scales and moves every chart's UVs (each #V_i × 2; `faces[i]` counter-clockwise over
// them, used for the UV area) in place so that they lie in [0, 1]² without overlapping.
// Errors: kInvalidArgument for no charts, a chart with no points, or a non-positive gutter ≥ ¼.
Result<PackResult> pack_charts(std::vector<ChartUv>& charts, const std::vector<FaceMatrix>& faces,
                               const PackOptions& options);

}  // namespace animspace::atlas
