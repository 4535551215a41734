// The pmsc suite (issue #3): PMSC / KPSA on real captured sequences. For each dataset, split and
// alignment setting: train on the training frames, then pose every test frame from its key
// points alone and compare with the captured frame. Timings are set against a plain Eigen float
// matrix–vector product of the same basis size, measured in the same run.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/suites.h"
#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/quantile.h"
#include "core/mesh_io/sequence_io.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/train.h"

namespace animspace::bench {
namespace {

struct Split {
  std::string name;
  std::vector<int> train, test;
};

std::vector<Split> splits_for(int frames) {
  Split interleaved{"interleaved", {}, {}};
  for (int f = 0; f < frames; ++f) (f % 2 == 0 ? interleaved.train : interleaved.test).push_back(f);
  Split contiguous{"contiguous", {}, {}};
  const int cut = static_cast<int>(std::floor(0.6 * frames));
  for (int f = 0; f < frames; ++f) (f < cut ? contiguous.train : contiguous.test).push_back(f);
  // Held-out blocks of motion (issue #22): 10-frame blocks, every other one held out.
  Split blocks{"blocks", {}, {}};
  for (int f = 0; f < frames; ++f) ((f / 10) % 2 == 0 ? blocks.train : blocks.test).push_back(f);
  return {interleaved, contiguous, blocks};
}

// One test frame as the soft cache sees it: its e_key, per-region errors, and the truth.
struct TestFrame {
  double key_point_error = 0;
  double max_error = 0;       // true max point error, model units
  double diagonal = 0;        // the frame's bounding-box diagonal
  std::vector<double> region_errors;
  Eigen::VectorXf point_errors;  // N, each point's true error
};

// What a set of thresholds gives on the test frames. "Bad" frames have a max point error over the
// tolerance (1% of the frame's diagonal, the papers' measure).
struct Verdicts {
  int hits = 0, bad = 0, bad_flagged = 0, false_hits = 0;
  double false_hit_worst = 0;  // max over frames called HIT of max error / tolerance (0 when none)
};

Verdicts verdicts(const std::vector<TestFrame>& frames, double epsilon_min, double tolerance_diag) {
  Verdicts v;
  for (const TestFrame& t : frames) {
    const bool hit = t.key_point_error <= epsilon_min;
    const double tolerance = tolerance_diag * t.diagonal;
    v.hits += hit ? 1 : 0;
    if (hit) v.false_hit_worst = std::max(v.false_hit_worst, t.max_error / tolerance);
    if (t.max_error > tolerance) {
      ++v.bad;
      v.bad_flagged += hit ? 0 : 1;
      v.false_hits += hit ? 1 : 0;
    }
  }
  if (v.false_hits == 0) v.false_hit_worst = 0;
  return v;
}

nlohmann::json optional_ratio(double numerator, double denominator) {
  return denominator > 0 ? nlohmann::json(numerator / denominator) : nlohmann::json();
}

nlohmann::json run_one(const std::string& dataset, const mesh_io::LoadedSequence& sequence, const Split& split,
                       bool aligned, const SuiteOptions& suite) {
  const int repetitions = suite.repetitions;
  const FrameMatrix& all = sequence.frames.samples;
  const FrameMatrix train_frames = tools::select_rows(all, split.train);
  const Eigen::VectorXf reference =
      Eigen::Map<const Eigen::VectorXf>(sequence.reference.V.data(), sequence.reference.V.size());
  const double diagonal = pmsc::bounding_box_diagonal(reference);

  pmsc::TrainingOptions options;
  options.error_bound = suite.error_bound_diag * diagonal;
  options.error_tolerance = suite.tolerance_diag * diagonal;
  options.max_key_points = 200;
  options.remove_rigid_motion = aligned;
  pmsc::TrainingReport report;
  auto model = pmsc::train(train_frames, options, &report);
  if (!model) {
    std::fprintf(stderr, "%s/%s: training failed: %s\n", dataset.c_str(), split.name.c_str(),
                 model.error().message.c_str());
    return {{"dataset", dataset}, {"split", split.name}, {"aligned", aligned}, {"error", model.error().message}};
  }

  // Accuracy: each test frame posed from its key points; errors relative to the frame's own
  // bounding-box diagonal (the 2007 paper's "1% of the diagonal").
  std::vector<double> max_error_over_diag;
  std::vector<TestFrame> frames;
  std::vector<Eigen::VectorXf> test_keys;
  pmsc::PoseEstimate estimate;
  for (int f : split.test) {
    const Eigen::VectorXf truth = all.row(f).transpose();
    test_keys.push_back(pmsc::gather_key_values(*model, truth));
    pmsc::evaluate(*model, test_keys.back(), estimate);
    TestFrame t;
    const Eigen::VectorXf residual = truth - estimate.points;
    t.point_errors = Eigen::Map<const Eigen::Matrix3Xf>(residual.data(), 3, model->point_count).colwise().norm();
    t.key_point_error = estimate.key_point_error;
    t.max_error = t.point_errors.maxCoeff();
    t.diagonal = pmsc::bounding_box_diagonal(truth);
    t.region_errors = estimate.region_errors;
    max_error_over_diag.push_back(t.max_error / t.diagonal);
    frames.push_back(std::move(t));
  }
  const double test_count = static_cast<double>(split.test.size());
  const double tolerance_diag = suite.tolerance_diag;
  int under_1pct = 0;
  for (const TestFrame& t : frames) under_1pct += t.max_error < tolerance_diag * t.diagonal ? 1 : 0;
  const Verdicts calibrated = verdicts(frames, model->epsilon.epsilon_min, tolerance_diag);

  // The baseline, measured on the same model and folds: the pre-#22 rule, ε_min = tolerance / the
  // largest max-error/e_key ratio over the interleaved folds' held-out frames.
  double worst_ratio = 0;
  const pmsc::CalibrationSamples& samples = model->calibration.samples;
  for (long i = 0; i < samples.size(); ++i) {
    if (samples.from_block_fold[static_cast<size_t>(i)] ||
        samples.key_point_errors(i) < pmsc::kCalibrationNoiseFraction * options.error_tolerance) {
      continue;
    }
    worst_ratio = std::max(worst_ratio, samples.max_errors(i) / samples.key_point_errors(i));
  }
  const double baseline_epsilon_min = options.error_tolerance / std::max(worst_ratio, 1.0);
  const Verdicts baseline = verdicts(frames, baseline_epsilon_min, tolerance_diag);

  // The operating curve on the test frames: each offered δ applied to the stored samples.
  nlohmann::json curve = nlohmann::json::array();
  for (double rate : pmsc::default_false_hit_rates()) {
    pmsc::PmscModel variant = *model;
    variant.calibration.false_hit_rate = rate;
    if (!pmsc::apply_calibration(variant, options.error_tolerance, options.blend_zone_ratio).ok()) continue;
    const Verdicts v = verdicts(frames, variant.epsilon.epsilon_min, tolerance_diag);
    curve.push_back({{"false_hit_rate", rate},
                     {"error_ratio", variant.calibration.error_ratio},
                     {"hit_rate", v.hits / test_count},
                     {"miss_recall_at_1pct", optional_ratio(v.bad_flagged, v.bad)},
                     {"false_hits", v.false_hits},
                     {"false_hit_worst_error_over_tolerance", v.false_hit_worst}});
  }

  // Local fail-through on the frames the soft cache flags (blend or miss): the points whose
  // blend weight α_i is above zero (pmsc/local_fail_through.h: calibrated region verdicts spread
  // by soft memberships) vs every point (whole-pose fail-through); and of the points over the
  // tolerance in those frames, the fraction the local path recomputes.
  double local_full_points = 0, global_full_points = 0, bad_points = 0, bad_points_local = 0;
  double all_bad_points = 0, all_bad_points_flagged = 0;
  for (const TestFrame& t : frames) {
    const bool flagged = t.key_point_error > model->epsilon.epsilon_min;
    const double tolerance = tolerance_diag * t.diagonal;
    all_bad_points += static_cast<double>((t.point_errors.array() > tolerance).count());
    if (!flagged) continue;
    std::vector<char> local(static_cast<size_t>(model->point_count), 0);
    for (int i : pmsc::local_fail_through(*model, t.key_point_error, t.region_errors).full_points) {
      local[static_cast<size_t>(i)] = 1;
    }
    for (int i = 0; i < model->point_count; ++i) {
      const bool bad = t.point_errors(i) > tolerance;
      local_full_points += local[static_cast<size_t>(i)];
      global_full_points += 1;
      bad_points += bad ? 1 : 0;
      bad_points_local += bad && local[static_cast<size_t>(i)] ? 1 : 0;
      all_bad_points_flagged += bad ? 1 : 0;
    }
  }
  // The floor: every point of the test frame projected onto the full PCA basis of the training
  // frames (F − 1 vectors, no key points, no alignment) — the best any linear subspace of these
  // training frames can do.
  int floor_under_1pct = 0;
  {
    const Eigen::MatrixXd T = train_frames.transpose().cast<double>();
    const Eigen::VectorXd mean = T.rowwise().mean();
    const pmsc::PcaBasis full = pmsc::thin_pca(T.colwise() - mean, static_cast<int>(T.cols()) - 1);
    for (int f : split.test) {
      const Eigen::VectorXd x = all.row(f).transpose().cast<double>() - mean;
      const Eigen::VectorXd residual = x - full.basis * (full.basis.transpose() * x);
      const Eigen::VectorXf truth = all.row(f).transpose();
      floor_under_1pct += pmsc::max_point_error(residual, 3) < 0.01 * pmsc::bounding_box_diagonal(truth) ? 1 : 0;
    }
  }

  // Speed: one pose at a time, against y = A x on the same float basis. The two are timed in
  // alternation inside each repetition, so both see the same machine load.
  long next = 0;
  const Eigen::VectorXf x = Eigen::VectorXf::Random(model->basis_size());
  Eigen::VectorXf y(model->basis.rows());
  std::vector<double> reconstruct_times, gemv_times;
  for (int repetition = 0; repetition < repetitions; ++repetition) {
    reconstruct_times.push_back(median_seconds(1, [&] {
      for (int i = 0; i < 16; ++i) {
        pmsc::evaluate(*model, test_keys[static_cast<size_t>(next++ % static_cast<long>(test_keys.size()))], estimate);
        do_not_optimize(estimate.points.data());
      }
    }) / 16);
    gemv_times.push_back(median_seconds(1, [&] {
      for (int i = 0; i < 16; ++i) {
        y.noalias() = model->basis * x;
        do_not_optimize(y.data());
      }
    }) / 16);
  }
  const double reconstruct_seconds = tools::quantile(reconstruct_times, 0.5);
  const double gemv_seconds = tools::quantile(gemv_times, 0.5);
  Eigen::MatrixXf batch_keys(model->key_mean.size(), 64);
  for (long b = 0; b < 64; ++b) batch_keys.col(b) = test_keys[static_cast<size_t>(b) % test_keys.size()];
  Eigen::MatrixXf batch_points;
  Eigen::VectorXd batch_errors;
  const double batch_seconds = median_seconds(std::max(3, repetitions / 3), [&] {
    pmsc::evaluate_batch(*model, batch_keys, batch_points, batch_errors);
    do_not_optimize(batch_points.data());
  });

  nlohmann::json row = {
      {"dataset", dataset},
      {"split", split.name},
      {"aligned", aligned},
      {"basis", model->basis_size()},
      {"key_points", model->key_point_count()},
      {"train_seconds", report.seconds},
      {"calibration_seconds", report.calibration_seconds},
      {"train_frames", split.train.size()},
      {"test_frames", split.test.size()},
      {"max_error_over_diag_p50", tools::quantile(max_error_over_diag, 0.50)},
      {"max_error_over_diag_p95", tools::quantile(max_error_over_diag, 0.95)},
      {"frac_frames_max_error_under_1pct", under_1pct / test_count},
      {"oracle_hit_rate", under_1pct / test_count},
      {"projection_floor_frac_under_1pct", floor_under_1pct / test_count},
      {"miss_recall_at_1pct", optional_ratio(calibrated.bad_flagged, calibrated.bad)},
      {"frames_over_1pct", calibrated.bad},
      {"hit_rate", calibrated.hits / test_count},
      {"false_hits", calibrated.false_hits},
      {"false_hit_worst_error_over_tolerance", calibrated.false_hit_worst},
      {"epsilon_min", model->epsilon.epsilon_min},
      {"epsilon_max", model->epsilon.epsilon_max},
      {"false_hit_rate", model->calibration.false_hit_rate},
      {"error_ratio", model->calibration.error_ratio},
      {"calibration_frames", report.calibration_frames},
      {"calibration_folds", options.calibration_folds},
      {"calibration_block_frames", model->calibration.block_frames},
      {"baseline_epsilon_min", baseline_epsilon_min},
      {"baseline_hit_rate", baseline.hits / test_count},
      {"baseline_miss_recall_at_1pct", optional_ratio(baseline.bad_flagged, baseline.bad)},
      {"baseline_false_hits", baseline.false_hits},
      {"baseline_false_hit_worst_error_over_tolerance", baseline.false_hit_worst},
      {"operating_curve", curve},
      {"reconstruct_us_per_pose", 1e6 * reconstruct_seconds},
      {"gemv_baseline_us", 1e6 * gemv_seconds},
      {"batch64_poses_per_second", 64.0 / batch_seconds},
      {"key_selection_converged", report.converged},
      {"condition_number", report.condition_number},
      {"regions", model->region_count},
      {"local_full_point_fraction", local_full_points / (test_count * model->point_count)},
      {"global_full_point_fraction", global_full_points / (test_count * model->point_count)},
      {"local_over_global_full_points", optional_ratio(local_full_points, global_full_points)},
      // The least any local rule could recompute: the points truly over the tolerance.
      {"oracle_local_over_global_full_points", optional_ratio(bad_points, global_full_points)},
      {"local_point_recall_at_1pct", optional_ratio(bad_points_local, bad_points)},
      {"global_point_recall_at_1pct", optional_ratio(all_bad_points_flagged, all_bad_points)},
  };
  auto text = [](const nlohmann::json& value) {
    char buffer[16];
    if (value.is_null()) return std::string("n/a");
    std::snprintf(buffer, sizeof buffer, "%.3f", value.get<double>());
    return std::string(buffer);
  };
  std::printf("%-13s %-11s %-4s %4d %4d %6.2f %5.2f %4zu %7.3f %7.3f %6.3f %6.3f | %6.3f %6s %3d %5.2f | %6.3f %6s %3d %5.2f "
              "| %6s %6s %6s | %8.1f %8.1f %9.0f\n",
              dataset.c_str(), split.name.c_str(), aligned ? "yes" : "no", model->basis_size(), model->key_point_count(),
              report.seconds, report.calibration_seconds, split.test.size(), 100 * tools::quantile(max_error_over_diag, 0.5),
              100 * tools::quantile(max_error_over_diag, 0.95), under_1pct / test_count, floor_under_1pct / test_count,
              calibrated.hits / test_count, text(row["miss_recall_at_1pct"]).c_str(), calibrated.false_hits,
              calibrated.false_hit_worst, baseline.hits / test_count, text(row["baseline_miss_recall_at_1pct"]).c_str(),
              baseline.false_hits, baseline.false_hit_worst, text(row["local_over_global_full_points"]).c_str(),
              text(row["local_point_recall_at_1pct"]).c_str(),
              text(row["oracle_local_over_global_full_points"]).c_str(), 1e6 * reconstruct_seconds, 1e6 * gemv_seconds,
              64.0 / batch_seconds);
  std::fflush(stdout);
  return row;
}

}  // namespace

nlohmann::json run_pmsc_suite(const SuiteOptions& options) {
  nlohmann::json results = nlohmann::json::array();
  if (!options.data) {
    std::printf("pmsc: ../shared/data is absent; nothing to measure\n");
    return results;
  }
  std::printf("%-13s %-11s %-4s %4s %4s %6s %5s %4s %7s %7s %6s %6s | %6s %6s %3s %5s | %6s %6s %3s %5s | %6s %6s %6s | %8s "
              "%8s %9s\n",
              "dataset", "split", "al", "M", "keys", "train", "cal s", "test", "p50 %dg", "p95 %dg", "oracle", "floor",
              "hit", "recall", "FH", "worst", "b.hit", "b.rec", "bFH", "worst", "loc/gl", "l.rec", "or/gl", "recon us",
              "gemv us", "batch64/s");
  for (const std::string& dataset : options.datasets) {
    auto sequence = mesh_io::load_sequence(*options.data / dataset);
    if (!sequence) {
      std::printf("%s: %s (skipped)\n", dataset.c_str(), sequence.error().message.c_str());
      continue;
    }
    for (const auto& split : splits_for(sequence->frames.num_frames())) {
      for (bool aligned : {false, true}) {
        results.push_back(run_one(dataset, *sequence, split, aligned, options));
      }
    }
  }
  std::printf(
      "train: seconds in all, cal s: of which the ε calibration. %%dg: max point error over the frame's bounding-box "
      "diagonal, percent. oracle: test frames truly under the tolerance (1%%). floor: the same for the full training "
      "basis with every point known. hit/recall/FH/worst: the calibrated soft cache (δ = the trainer's default) — hit "
      "rate, blend-or-miss among test frames over tolerance, false hits and the worst false hit's error over the "
      "tolerance; b.*: the same for the pre-#22 rule (worst ratio of the interleaved folds) on the same model. "
      "loc/gl: points needing the full calculation with per-region vs whole-pose fail-through on flagged frames; "
      "l.rec: of their points over tolerance, the fraction the local path recomputes; or/gl: the points truly over "
      "tolerance there, the least any local rule must recompute.\n");
  return results;
}

}  // namespace animspace::bench
