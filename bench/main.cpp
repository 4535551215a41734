// animspace-bench: benchmark suites that print a table and write JSON, each figure next to a
// baseline measured in the same run (these machines are shared and noisy: ratios hold,
// absolute times drift).
#include <cstdio>
#include <fstream>
#include <string>

#include <CLI/CLI.hpp>

#include "bench/suites.h"
#include "clients/cpp/tools/number_checks.h"

int main(int argc, char** argv) {
  std::string suite = "io";
  std::string data_dir = "../shared/data";
  std::string json_path;
  animspace::bench::SuiteOptions options;
  CLI::App app{"animspace-bench — benchmark suites with same-run baselines"};
  app.add_option("suite", suite, "io: file parsing; pmsc: PMSC training, accuracy and speed on real sequences; skinning: animation "
                  "space vs linear blend skinning (fit, accuracy, evaluation speed); lod: animation-space level of detail vs rest-pose "
                  "simplifiers (error across poses); subdivide: subdivision in animation space vs refining each posed mesh at run time (exactness, the linear blend alternative, posing cost); atlas: a texture atlas balanced across poses vs the rest-pose atlas and Blender's unwrappers (stretch on held-out poses); serve: a real animspaced on loopback (unary and streamed PMSC "
                  "poses against in-process evaluation); render: thumbnails and LOD streaming from a real animspaced against "
                  "in-process drawing; loadtest: animspace-loadtest's concurrency sweep and hit rates on crane against in-process evaluation; illumination: the Cornell box's indirect illumination from key points against the full final "
                  "gather (accuracy on novel lights, soft-cache flags, speed-up in process and served); scale: the cow rig "
                  "subdivided to studio sizes and posed at thousands of random rotations (training time and peak memory, LOD "
                  "building against meshoptimizer, many models served, GetBasis and the client's reconstruction)")
      ->check(CLI::IsMember({"io", "pmsc", "skinning", "lod", "subdivide", "atlas", "serve", "render", "loadtest", "illumination", "scale"}))
      ->capture_default_str();
  app.add_option("--data", data_dir, "Reference data folder (../shared/data)")->capture_default_str();
  app.add_option("--json", json_path, "Write results as JSON to this file");
  app.add_option("--repetitions", options.repetitions, "Runs per timing (median reported)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--error-bound-diag", options.error_bound_diag, "pmsc: key selection bound (fraction of diagonal)")
      ->capture_default_str();
  app.add_option("--tolerance-diag", options.tolerance_diag, "pmsc: soft-cache tolerance (fraction of diagonal)")
      ->capture_default_str();
  app.add_option("--held-out-key-slack", options.held_out_key_slack,
                 "pmsc: the held-out key budget's slack, e.g. 0.05 (0: the budget is 200 keys)")
      ->capture_default_str();
  app.add_option("--datasets", options.datasets, "pmsc: datasets under --data")->capture_default_str();
  app.add_option("--skinning-datasets", options.skinning.datasets, "skinning: datasets under --data")
      ->capture_default_str();
  app.add_option("--lod-datasets", options.lod_datasets, "lod: datasets under --data")->capture_default_str();
  app.add_option("--lod-methods", options.lod_methods, "lod: only these methods, as the rows name them (default: all)");
  app.add_option("--atlas-datasets", options.atlas_datasets, "atlas: datasets under --data")->capture_default_str();
  app.add_option("--bones", options.skinning.bones, "lod: rigid parts for sequences without a skeleton (horse-gallop)")
      ->check(CLI::Range(1, 200))
      ->capture_default_str();
  app.add_option("--all-frames-bones", options.skinning.all_frames_bones,
                 "skinning: bone counts for horse-gallop fitted on all frames")
      ->capture_default_str();
  app.add_option("--split-bones", options.skinning.split_bones,
                 "skinning: bone counts for horse-gallop fitted on even frames, tested on odd")
      ->capture_default_str();
  app.add_option("--crane-bones", options.skinning.crane_bones, "skinning: bone counts for crane (even → odd) and the held-out-blocks rows")
      ->capture_default_str();
  app.add_option("--max-influences", options.skinning.max_influences, "skinning: bones per vertex (K)")
      ->check(CLI::Range(1, 32))
      ->capture_default_str();
  app.add_option("--candidate-hops", options.skinning.candidate_hops, "skinning: candidate bones within this many parts")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option("--edge-regularisation", options.skinning.edge_regularisation, "skinning: δ of Merry 2007 eq. 4.4")
      ->check(animspace::tools::kNonNegative)
      ->capture_default_str();
  app.add_option("--vertex-regularisation", options.skinning.vertex_regularisation,
                 "skinning: λ of Merry 2007 eq. 4.3")
      ->check(animspace::tools::kNonNegative)
      ->capture_default_str();
  app.add_option("--illumination-points", options.illumination.points, "illumination: surface sample points")
      ->check(CLI::Range(100, 5000000))
      ->capture_default_str();
  app.add_option("--illumination-samples", options.illumination.samples,
                 "illumination: final-gather rays per point (0: the training's default; the gather study's S: 64)")
      ->check(CLI::Range(0, 65536))
      ->capture_default_str();
  app.add_option("--illumination-drop", options.illumination.drop,
                 "illumination: the training grid's plane below the ceiling, fraction of the room's height (0: the "
                 "default)")
      ->check(CLI::Range(0.0, 0.999))
      ->capture_default_str();
  app.add_option("--illumination-figure", options.illumination.figure,
                 "illumination: write a PNG of full / subspace / error for novel lights");
  app.add_option("--illumination-sampling", options.illumination.sampling,
                 "illumination: hemisphere sampling of the gather (issue #38)")
      ->check(CLI::IsMember({"hammersley", "stratified"}))
      ->capture_default_str();
  app.add_option("--illumination-light-radius", options.illumination.light_radius,
                 "illumination: the lights' radius in metres for the gather's shadow rays (0: point lights)")
      ->check(CLI::Range(0.0, 0.1))
      ->capture_default_str();
  app.add_option("--illumination-shadow-rays", options.illumination.shadow_rays,
                 "illumination: shadow rays per hit and light when the light radius is > 0")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_flag("--illumination-absolute-tolerance", options.illumination.absolute_tolerance,
               "illumination: the soft cache's tolerance in radiance units (before issue #38), not relative to "
               "each frame's radiance");
  app.add_option("--illumination-basis-slack", options.illumination.basis_slack,
                 "illumination: M is the smallest basis whose held-out projection error is within (1 + this) of "
                 "the best (0: M from the error bound; < 0: the training's default; issue #38)");
  app.add_option("--illumination-gather-study", options.illumination.gather_study,
                 "illumination: 1: measure candidate gathers' noise and smoothness first; 2: only that")
      ->check(CLI::Range(0, 2))
      ->capture_default_str();
  app.add_option("--illumination-filter-neighbours", options.illumination.filter_neighbours,
                 "illumination: the surface filter's expected neighbour count k for the training frames and the full "
                 "calculation (0: unfiltered; default: the training's, 32; issue #38 item 1)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  app.add_flag("--illumination-filter-linear", options.illumination.filter_linear,
               "illumination: the surface filter fits a plane to the neighbours' irradiance instead of averaging it");
  app.add_option("--illumination-key-samples", options.illumination.key_samples,
                 "illumination: gather rays per key point, unfiltered (0: the key points' filter support at "
                 "--illumination-samples rays, filtered)")
      ->check(CLI::Range(0, 65536))
      ->capture_default_str();
  app.add_option("--illumination-post-filter", options.illumination.post_filter_neighbours,
                 "illumination: train on the raw gather (with --illumination-filter-neighbours 0) and filter the "
                 "reconstruction with k neighbours instead: an experiment, reported beside the rows (0: off)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  app.add_option("--illumination-direct-from-vertices", options.illumination.direct_from_vertices,
                 "illumination: 1: the gather reads the direct light at its hits from the hit triangle's vertices "
                 "(issue #38); 0: a shadow ray from every hit (default: the training's)")
      ->check(CLI::Range(-1, 1));
  app.add_option("--illumination-cell-average", options.illumination.cell_average,
                 "illumination: 1: a vertex's value is the mean over its cell (its rays leave from all over it; "
                 "issue #38); 0: the value at the vertex (default: the training's)")
      ->check(CLI::Range(-1, 1));
  app.add_option("--illumination-cell-shadow-rays", options.illumination.cell_shadow_rays,
                 "illumination: shadow rays from each vertex's cell for the direct light the gather reads at its hits, "
                 "where a shadow's edge crosses the cell (issue #38); 0: the vertex's own (default: the training's)")
      ->check(CLI::Range(-1, 4096));
  app.add_option("--illumination-max-key-points", options.illumination.max_key_points,
                 "illumination: the key selection's budget K (0: the training's default)")
      ->check(CLI::Range(0, 100000));
  app.add_option("--illumination-error-bound", options.illumination.error_bound,
                 "illumination: the key selection stops when every training point is within this fraction of the "
                 "radiance scale (0: the training's default)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--illumination-grid", options.illumination.grid,
                 "illumination: training lights per side of the grid, n × n over the same rectangle (0: the "
                 "training's default, 18 × 18; the papers': 12)")
      ->check(CLI::Range(0, 64));
  app.add_option("--illumination-converged-samples", options.illumination.converged_samples,
                 "illumination: rays per point of the converged full calculation, the baseline timed beside the "
                 "filtered one")
      ->check(CLI::Range(1, 65536))
      ->capture_default_str();
  app.add_option("--scale-levels", options.scale.levels,
                 "scale: subdivision levels of the cow rig (0: the rig itself, always run as the baseline: 11,666 points; 1 "
                 "and 2: about 47k and 186k)")
      ->check(CLI::Range(0, 4))
      ->capture_default_str();
  app.add_option("--scale-character", options.scale.character,
                 "scale: the character subdivided: cow-rig (import-rig of the rig) or horse-gallop (fit to the capture: "
                 "8,431 points; 1 and 2 levels about 34k and 135k)")
      ->check(CLI::IsMember({"cow-rig", "horse-gallop"}))
      ->capture_default_str();
  app.add_option("--scale-frames", options.scale.frames, "scale: random poses per level (the training sequence)")
      ->check(CLI::Range(2, 1000000))
      ->capture_default_str();
  app.add_option("--scale-models", options.scale.models, "scale: copies of each trained model one animspaced serves")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--scale-kinds", options.scale.kinds, "scale: subspace kinds trained (train-pmsc --subspace)")
      ->check(CLI::IsMember({"linear", "articulated"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  if (std::filesystem::is_directory(data_dir)) {
    options.data = data_dir;
  } else {
    std::printf("note: %s not found; suites that need it use synthetic data or are skipped\n", data_dir.c_str());
  }
  nlohmann::json results = suite == "io"      ? animspace::bench::run_io_suite(options)
                           : suite == "pmsc"  ? animspace::bench::run_pmsc_suite(options)
                           : suite == "lod"   ? animspace::bench::run_lod_suite(options)
                           : suite == "subdivide" ? animspace::bench::run_subdivision_suite(options)
                           : suite == "atlas" ? animspace::bench::run_atlas_suite(options)
                           : suite == "serve" ? animspace::bench::run_serve_suite(options)
                           : suite == "render" ? animspace::bench::run_render_suite(options)
                           : suite == "loadtest" ? animspace::bench::run_loadtest_suite(options)
                           : suite == "illumination" ? animspace::bench::run_illumination_suite(options)
                           : suite == "scale" ? animspace::bench::run_scale_suite(options)
                                              : animspace::bench::run_skinning_suite(options);
  if (!json_path.empty()) {
    std::ofstream json(json_path);
    json << nlohmann::json{{"suite", suite}, {"repetitions", options.repetitions}, {"results", results}}.dump(2)
         << '\n';
  }
  return 0;
}
