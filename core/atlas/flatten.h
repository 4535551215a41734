// Flattening one chart onto the plane minimising L2 stretch across poses (Merry 2007 §5.3, §5.3.1;
// Sander, Snyder, Gortler & Hoppe 2001 §4), keeping the map one-to-one.
//
// The chart is known only through its triangles' Gram matrices g (stretch.h): from P they are
// the expected first fundamental form over the pose distribution, from one pose that pose's.
//   1. Initial map. Least squares conformal maps (Lévy et al. 2002) with the triangles laid out in
//      the plane from g (so LSCM too is computed in the metric), two border vertices pinned. If it
//      has a flipped triangle or its border crosses itself, Tutte's embedding instead (uniform
//      weights, border on a circle by edge length): one-to-one by Tutte's / Floater's theorem.
//   2. Stretch optimisation (Sander 2001 §4, the thesis's §5.3.1): vertices in order of their
//      neighbourhood's stretch, each moved by a line search along its descent direction (numerical
//      gradient of the chart's normalised L2², the border free) within the interval where none of
//      its triangles flips; a border vertex's move is also refused if its border edges would cross
//      another border edge. Every accepted map is therefore one-to-one. Sweeps stop when one
//      improves L2² by less than `tolerance` (relative) or after `max_sweeps`.
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "core/atlas/stretch.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::atlas {

struct FlattenOptions {
  int max_sweeps = 200;
  double tolerance = 1e-4;
  bool optimise_stretch = true;  // false: the initial map only
};

struct ChartMap {
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> uv;  // #V_chart × 2, chart-local vertices
  double l2 = 0;        // normalised L2 stretch of the chart on `metrics`
  double linf = 0;      // normalised L∞
  double uv_area = 0;   // Σ UV area (the map is scaled so that it equals the surface area)
  double surface_area = 0;
  bool used_tutte = false;
  int sweeps = 0;
};

// Flattens a chart given as faces over local vertex indices 0 … vertex_count−1 (every one used),
// a topological disc, counter-clockwise, with g per face (#F × 3).
// Errors: kInvalidArgument for a chart that is not a disc (no single border loop), a triangle
// with a degenerate metric (det g ≤ 0), or a map that stays invalid after Tutte's embedding.
Result<ChartMap> flatten_chart(const FaceMatrix& faces, int vertex_count, const FaceMetrics& metrics,
                               const FlattenOptions& options);

}  // namespace animspace::atlas
