// A texture atlas balanced across poses (issue #37; Merry 2007 ch. 5): the pipeline
//   1. segmentation into disc charts with the L2,2 metric of animation space (charts.h, §5.2);
//   2. flattening of each chart minimising L2 stretch across the pose distribution P
//      (flatten.h, §5.3 — the thesis's own flattening is LSCM with straightened borders; here the
//      stretch optimisation, which it applies after LSCM, is the point, and borders stay free);
//   3. balancing and packing into the unit square (pack.h, §5.4).
// Every step sees the model only through P: the triangles' expected first fundamental forms
// (stretch.h) and normalised animation space (P^½). The rest-pose atlas — what a texture artist
// gets from a static unwrap — is the same code given the metrics of the rest pose alone
// (rest_pose_metrics), not a separate implementation.
#pragma once

#include <cstdint>
#include <vector>

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/atlas/charts.h"
#include "core/atlas/flatten.h"
#include "core/atlas/pack.h"
#include "core/atlas/stretch.h"
#include "core/common/progress.h"
#include "core/common/result.h"

namespace animspace::atlas {

struct Atlas {
  std::vector<int32_t> chart_of_face;  // #F, charts numbered 0 … chart_count−1, each a disc
  CornerUvs uvs;                       // 3·#F × 2, in [0, 1]², one-to-one
  int chart_count = 0;
};

struct AtlasOptions {
  int chart_count = 0;  // seeds; 0: default_chart_count(model)
  ChartOptions charts;  // chart_count there is ignored
  FlattenOptions flatten;
  PackOptions pack;
  // A chart whose L2 stretch (under the metrics the atlas is built for) exceeds 1 + split_stretch
  // after flattening is split in two and both parts flattened again, up to max_split_rounds
  // rounds; charts under min_split_faces faces are kept. A rule in stretch, not in model units,
  // so it means the same for any character; 0.1 = 10 % RMS excess stretch.
  double split_stretch = 0.1;
  int min_split_faces = 16;
  int max_split_rounds = 6;
  // Stages "segment charts", "flatten charts" (per chart; again for each split round) and "pack
  // charts", for a command line's bar (a cow's atlas takes tens of seconds).
  ProgressCallback progress;
};

struct AtlasReport {
  Atlas atlas;
  double l2 = 0;            // normalised L2 stretch of the packed atlas under the metrics it was built for
  double linf = 0;          // normalised L∞
  double utilisation = 0;   // Σ chart UV area / atlas area
  int tutte_charts = 0;     // charts whose LSCM start was invalid and that started from Tutte's map
  int split_rounds = 0;     // rounds in which charts over the stretch bound were split
  double segment_seconds = 0, flatten_seconds = 0, pack_seconds = 0;
};

// The rule for the default number of seeds, for any character: two charts per moving bone (a limb
// segment is roughly a tube, which needs at least two discs), at least four.
int default_chart_count(const animation_space::AnimationSpaceModel& model);

// The metrics of the rest pose alone (P = ĜᵀĜ): stretch measured in the rest pose.
Result<animation_space::AnimationSpaceMetrics> rest_pose_metrics(const animation_space::Skeleton& skeleton);

// g per face under P: g11 = e1ᵀPe1, g12 = e1ᵀPe2, g22 = e2ᵀPe2 with e1 = p1 − p0, e2 = p2 − p0 the
// animation-space edges — the expected first fundamental form over the poses (stretch.h).
// Errors: kInvalidArgument for an invalid model or metrics of another bone count.
Result<FaceMetrics> face_metrics(const animation_space::AnimationSpaceModel& model,
                                 const animation_space::AnimationSpaceMetrics& metrics);

// Builds the atlas of `model` (with faces) for the poses `metrics` describes.
// Errors: kInvalidArgument for an invalid model, a model without faces, metrics of another bone
// count or P not positive semi-definite, options out of range; kInternal when a chart cannot be
// flattened (a numerically degenerate chart).
Result<AtlasReport> build_atlas(const animation_space::AnimationSpaceModel& model,
                                const animation_space::AnimationSpaceMetrics& metrics, const AtlasOptions& options);

// Flattens and packs given charts (the last two steps of build_atlas, without splitting):
// `chart_of_face` numbers each face's chart densely from 0, every chart a disc.
Result<AtlasReport> flatten_and_pack(const FaceMatrix& faces, const FaceMetrics& metrics,
                                     const std::vector<int32_t>& chart_of_face, const AtlasOptions& options);

}  // namespace animspace::atlas
