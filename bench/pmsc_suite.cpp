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
  return {interleaved, contiguous};
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
  int under_1pct = 0, bad = 0, bad_flagged = 0, hits = 0;
  // Local fail-through: points whose region is flagged, against all points of flagged frames.
  double local_full_points = 0, global_full_points = 0, bad_points = 0, bad_points_local = 0, bad_points_global = 0;
  std::vector<Eigen::VectorXf> test_keys;
  pmsc::PoseEstimate estimate;
  for (int f : split.test) {
    const Eigen::VectorXf truth = all.row(f).transpose();
    test_keys.push_back(pmsc::gather_key_values(*model, truth));
    pmsc::evaluate(*model, test_keys.back(), estimate);
    const Eigen::MatrixXd residual = (truth - estimate.points).cast<double>();
    const double frame_diagonal = pmsc::bounding_box_diagonal(truth);
    const double relative = pmsc::max_point_error(residual, 3) / frame_diagonal;
    max_error_over_diag.push_back(relative);
    const auto decision = pmsc::decide(estimate.key_point_error, model->epsilon);
    const bool flagged = decision.status != pmsc::CacheStatus::kHit;
    hits += flagged ? 0 : 1;
    under_1pct += relative < 0.01 ? 1 : 0;
    if (relative > 0.01) {
      ++bad;
      bad_flagged += flagged ? 1 : 0;
    }
    for (int i = 0; i < model->point_count; ++i) {
      const bool region_flagged =
          model->region_count > 0 &&
          estimate.region_errors[static_cast<size_t>(model->point_regions[static_cast<size_t>(i)])] >
              model->epsilon.epsilon_min;
      local_full_points += region_flagged ? 1 : 0;
      global_full_points += flagged ? 1 : 0;
      if (residual.col(0).segment(3 * i, 3).norm() > 0.01 * frame_diagonal) {
        bad_points += 1;
        bad_points_local += region_flagged ? 1 : 0;
        bad_points_global += flagged ? 1 : 0;
      }
    }
  }
  const double test_count = static_cast<double>(split.test.size());

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
  const double point_total = test_count * model->point_count;

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
      {"train_frames", split.train.size()},
      {"test_frames", split.test.size()},
      {"max_error_over_diag_p50", tools::quantile(max_error_over_diag, 0.50)},
      {"max_error_over_diag_p95", tools::quantile(max_error_over_diag, 0.95)},
      {"frac_frames_max_error_under_1pct", under_1pct / test_count},
      {"projection_floor_frac_under_1pct", floor_under_1pct / test_count},
      {"miss_recall_at_1pct", bad > 0 ? nlohmann::json(static_cast<double>(bad_flagged) / bad) : nlohmann::json()},
      {"frames_over_1pct", bad},
      {"hit_rate", hits / test_count},
      {"epsilon_min", model->epsilon.epsilon_min},
      {"epsilon_max", model->epsilon.epsilon_max},
      {"reconstruct_us_per_pose", 1e6 * reconstruct_seconds},
      {"gemv_baseline_us", 1e6 * gemv_seconds},
      {"batch64_poses_per_second", 64.0 / batch_seconds},
      {"key_selection_converged", report.converged},
      {"condition_number", report.condition_number},
      {"regions", model->region_count},
      {"local_full_point_fraction", local_full_points / point_total},
      {"global_full_point_fraction", global_full_points / point_total},
      {"local_point_recall_at_1pct", bad_points > 0 ? nlohmann::json(bad_points_local / bad_points) : nlohmann::json()},
      {"global_point_recall_at_1pct", bad_points > 0 ? nlohmann::json(bad_points_global / bad_points) : nlohmann::json()},
  };
  std::printf("%-13s %-11s %-7s %5d %5d %7.2f %5zu %9.4f %9.4f %7.3f %7.3f %7s %6.3f %9.1f %9.1f %10.0f %6.3f %6.3f\n",
              dataset.c_str(), split.name.c_str(), aligned ? "yes" : "no", model->basis_size(),
              model->key_point_count(), report.seconds, split.test.size(), 100 * tools::quantile(max_error_over_diag, 0.5),
              100 * tools::quantile(max_error_over_diag, 0.95), under_1pct / test_count, floor_under_1pct / test_count,
              bad > 0 ? std::to_string(static_cast<double>(bad_flagged) / bad).substr(0, 5).c_str() : "n/a",
              hits / test_count, 1e6 * reconstruct_seconds, 1e6 * gemv_seconds, 64.0 / batch_seconds,
              local_full_points / point_total, global_full_points / point_total);
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
  std::printf("%-13s %-11s %-7s %5s %5s %7s %5s %9s %9s %7s %7s %7s %6s %9s %9s %10s %6s %6s\n", "dataset", "split",
              "aligned", "M", "keys", "train s", "test", "p50 %dg", "p95 %dg", "<1%", "floor", "recall", "hit", "recon us",
              "gemv us", "batch64/s", "local", "global");
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
  std::printf("%%dg: max point error over the frame's bounding-box diagonal, percent. recall: blend-or-miss among "
              "test frames over 1%%. floor: <1%% for the full training basis with every point known. local/global: fraction of points needing the full calculation with per-region "
              "vs whole-pose fail-through.\n");
  return results;
}

}  // namespace animspace::bench
