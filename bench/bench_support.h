// Shared helpers for animspace-bench suites: timing and where the reference data lives.
#pragma once

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "clients/cpp/tools/quantile.h"

namespace animspace::bench {

// Median wall time of `repetitions` ≥ 1 runs of `work`, seconds: the nearest-rank p50 of
// clients/cpp/tools/quantile.h, as every quantile the bench prints (for an odd count, the middle run).
inline double median_seconds(int repetitions, const std::function<void()>& work) {
  std::vector<double> times;
  for (int i = 0; i < repetitions; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    work();
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return tools::quantile(std::move(times), 0.5);
}

// One line on stderr as each row (or dataset) of a suite starts: what runs, the rows started and
// how long the suite has run (issue #55 item 15: suites were silent for minutes). The table stays
// on stdout, so `> table.txt` still captures only the table.
class RowProgress {
 public:
  explicit RowProgress(std::string suite) : suite_(std::move(suite)), start_(std::chrono::steady_clock::now()) {}
  void starting(const std::string& row) {
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    std::fprintf(stderr, "animspace-bench %s: %d. %s (%.0f s in)\n", suite_.c_str(), ++rows_, row.c_str(), seconds);
    std::fflush(stderr);
  }

 private:
  std::string suite_;
  std::chrono::steady_clock::time_point start_;
  int rows_ = 0;
};

// Keeps the optimiser from discarding a computed value.
template <typename T>
inline void do_not_optimize(const T& value) {
  asm volatile("" : : "r,m"(value) : "memory");
}

// skinning: datasets and the fitting settings shared by both methods.
struct SkinningSuiteOptions {
  std::vector<std::string> datasets{"horse-gallop", "crane", "cow-rig"};
  int bones = 24;                       // lod: rigid parts found automatically (horse-gallop)
  // skinning (issue #23): horse-gallop fitted on all its frames at these bone counts (the published
  // SSDR / Hyperspectral Inverse Skinning tables), and even → odd at these (Dem Bones' protocol).
  std::vector<int> all_frames_bones{10, 20, 30};
  std::vector<int> split_bones{16, 24, 32};
  std::vector<int> crane_bones{24};        // also the held-out-blocks rows of both sequences
  int max_influences = 4;               // K of the decomposition
  int candidate_hops = 2;               // the decomposition's candidate bones
  double edge_regularisation = 0.005;   // δ, Merry 2007 §8.2's horse
  double vertex_regularisation = 1e-6;  // λ
};

// illumination (issue #24): the scene's size and the gather's, and the novel lights tested.
struct IlluminationSuiteOptions {
  int points = 100000;   // surface sample points of the Cornell box
  int samples = 0;       // final-gather rays per point, the full gather's and the keys' (0: the training's default)
  int inside = 24;       // novel lights inside the training grid's hull
  int outside = 12;      // novel lights well outside it (walls, floor level)
  double drop = 0;       // the training grid's drop below the ceiling (0: LightGrid's default)
  std::string figure;    // when set: a PNG of full / subspace / error for a few novel lights
  // The gather the model is trained on and judged against (issue #38; the defaults are the
  // original gather): "hammersley" or "stratified", the light's radius in metres, shadow rays.
  std::string sampling = "hammersley";
  double light_radius = 0;
  int shadow_rays = 1;
  // The soft cache's tolerance in radiance units (models before issue #38) instead of relative
  // to each frame's radiance.
  bool absolute_tolerance = false;
  // 0: no gather study; 1: the gather study (noise by two seeds, error against a 4096-ray
  // reference, roughness in the light's position, per candidate gather) and then the suite;
  // 2: the study only.
  int gather_study = 0;
  // Issue #38 item 3: pmsc::TrainingOptions::held_out_basis_slack (0: M from the error bound);
  // < 0: the illumination training's default.
  double basis_slack = -1;
  // Issue #38 item 1: the surface filter's expected neighbour count k for the training frames and
  // the full calculation (0: unfiltered), the rays per key point (0: samples), and the ray count
  // of the "converged full calculation" baseline (timed and judged against the reference).
  int filter_neighbours = -1;  // < 0: the illumination training's default
  bool filter_linear = false;
  int key_samples = 0;
  int converged_samples = 1024;
  // Issue #38, an experiment for the next step: with the training unfiltered, the surface filter
  // (this k; 0: off) applied to the subspace's reconstruction instead, measured against the
  // filtered full calculation and the reference.
  int post_filter_neighbours = 0;
  // GatherOptions::direct_from_vertices for the training and the full calculation: 0 a shadow ray
  // from every hit, 1 the direct light read from the hit triangle's vertices; < 0: the training's
  // default.
  int direct_from_vertices = -1;
  // GatherOptions::cell_average for the training, the full calculation and the reference: 0 rays
  // from the vertex, 1 from its cell; < 0: the training's default.
  int cell_average = -1;
  // GatherOptions::cell_shadow_rays for the training and the full calculation (with the direct
  // light read from the vertices): 0 the vertex's own shadow ray; < 0: the training's default.
  int cell_shadow_rays = -1;
  // pmsc::TrainingOptions::max_key_points (0: the training's default).
  int max_key_points = 0;
  // IlluminationTrainingOptions::error_bound_fraction, where the key selection stops (0: the
  // training's default).
  double error_bound = 0;
  // Training lights per side of the grid (n × n; 0: LightGrid's default, 18 × 18).
  int grid = 0;
};

// scale (issue #53): the cow rig at studio sizes.
struct ScaleSuiteOptions {
  std::vector<int> levels{0, 1, 2};  // subdivision levels (0, the baseline, always runs)
  int frames = 2000;                 // random poses per level
  int models = 20;                   // copies of each trained model one daemon serves
  std::vector<std::string> kinds{"linear"};
  // What is subdivided: "cow-rig" (imported, exact at any joint rotation) or "horse-gallop" (fitted
  // to the capture with `animspace fit`, then exact for its own bones at any rotation).
  std::string character = "cow-rig";
};

struct SuiteOptions {
  std::optional<std::filesystem::path> data;  // ../shared/data, when present
  int repetitions = 21;
  // pmsc: key-selection bound and soft-cache tolerance, fractions of the bounding-box diagonal.
  double error_bound_diag = 0.0025;
  double tolerance_diag = 0.01;
  // pmsc: TrainingOptions::held_out_key_slack (issue #52 item 2; 0: 200 keys at most).
  double held_out_key_slack = 0;
  std::vector<std::string> datasets{"crane", "horse-gallop", "cow-rig"};
  SkinningSuiteOptions skinning;
  // lod: datasets (the horse is fitted with the skinning options above).
  std::vector<std::string> lod_datasets{"cow-rig", "horse-gallop", "horse-gallop-block"};
  // lod: only these methods (rows named as printed); empty: every one.
  std::vector<std::string> lod_methods;
  // atlas: datasets (the horse is fitted with the skinning options above, on its training block).
  std::vector<std::string> atlas_datasets{"cow-rig", "horse-gallop-block"};
  IlluminationSuiteOptions illumination;
  ScaleSuiteOptions scale;
};

}  // namespace animspace::bench
