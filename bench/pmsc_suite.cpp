// The pmsc suite (issue #3): PMSC / KPSA on real captured sequences. For each dataset, split and
// alignment setting: train on the training frames, then pose every test frame from its key
// points alone and compare with the captured frame. Timings are set against a plain Eigen float
// matrix–vector product of the same basis size, measured in the same run.
//
// Issue #35: every row compares the error estimators a verdict can use, each calibrated on the
// same model's held-out samples at the same δ (calibration.h): `key_bad_frames` (issue #22's
// rule: e_key against the held-out frames over the tolerance on their own — the rule before),
// `key` (e_key, extrapolated rule), `check` (e_check alone), `worse` (max(w·e_key, e_check), the
// model's verdict) and `geometric` (e_key^a·e_check^(1−a), a fitted by least squares of log e_max
// on the samples: a regression of the true max error on both). Splits: interleaved, contiguous,
// blocks, and leave-one-block-out (four blocks, each tested by a model trained on the other
// three; one row), each for the linear kind (unaligned and aligned) and the articulated kind, the
// latter also with its calibration cross-fitted (issue #52: the option's hits on real captures).
// The cow rig rows train on random joint rotations up to one angle and test on
// thousands of fresh poses up to wider ones, with the false-hit rate among bad poses against δ.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/cow_rig.h"
#include "bench/suites.h"
#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/quantile.h"
#include "core/animspace/import.h"
#include "core/animspace/secondary_motion.h"
#include "core/animspace/skeleton.h"
#include "core/mesh_io/sequence_io.h"
#include "core/pmsc/calibration.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/subspace.h"
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

// Leave-one-block-out (issue #35): four blocks of consecutive frames, each the test set of a
// model trained on the other three.
constexpr int kLeftOutBlocks = 4;
std::vector<Split> leave_one_block_out(int frames) {
  std::vector<Split> splits;
  for (int b = 0; b < kLeftOutBlocks; ++b) {
    Split split{"leave-one-block-out", {}, {}};
    for (int f = 0; f < frames; ++f) (f * kLeftOutBlocks / frames == b ? split.test : split.train).push_back(f);
    splits.push_back(std::move(split));
  }
  return splits;
}

// One test frame as the soft cache sees it: its e_key, e_check, per-region errors, and the truth.
struct TestFrame {
  double key_point_error = 0;
  double key_point_max_error = 0;  // the worst key's residual (issue #52)
  double check_point_error = 0;
  double error_estimate = 0;  // the model's verdict estimate, max(w·e_key, e_check)
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

// What a verdict can see of a pose: e_key, the worst key's residual, e_check.
struct Observed {
  double key = 0, key_max = 0, check = 0;
};

// An estimator: what it makes of what a pose shows.
using Estimator = std::function<double(const Observed&)>;

Estimator key_estimator() {
  return [](const Observed& o) { return o.key; };
}

// The estimate the model's own verdict compares with its ε (pmsc::estimate_coordinates).
Estimator served_estimator(const pmsc::PmscModel& model) {
  const bool worst_point = model.estimator == pmsc::ErrorEstimator::kWorstPoint;
  if (model.check_points.empty()) {
    return [worst_point](const Observed& o) { return worst_point ? o.key_max : o.key; };
  }
  const double w = model.key_weight;
  return [w, worst_point](const Observed& o) {
    return pmsc::combined_error_estimate(w, worst_point ? o.key_max : o.key, o.check);
  };
}

Verdicts verdicts(const std::vector<TestFrame>& frames, double epsilon_min, double tolerance_diag,
                  const Estimator& estimator = key_estimator()) {
  Verdicts v;
  for (const TestFrame& t : frames) {
    const bool hit = estimator({t.key_point_error, t.key_point_max_error, t.check_point_error}) <= epsilon_min;
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

// The exponent a of the geometric estimator e_key^a·e_check^(1−a): least squares of
// log(e_max / e_check) on log(e_key / e_check) with an intercept, over the usable samples
// (homogeneous of degree one, so the extrapolated rule applies to it unchanged).
double geometric_exponent(const pmsc::CalibrationSamples& samples, double tolerance) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0, n = 0;
  for (long i = 0; i < samples.size(); ++i) {
    const double key = samples.key_point_errors(i), check = samples.check_point_errors(i), max = samples.max_errors(i);
    if (!(key > 0 && check > 0 && max >= pmsc::kCalibrationNoiseFraction * tolerance)) continue;
    const double x = std::log(key / check), y = std::log(max / check);
    sx += x, sy += y, sxx += x * x, sxy += x * y, n += 1;
  }
  const double variance = sxx - sx * sx / std::max(n, 1.0);
  return n > 2 && variance > 0 ? std::clamp((sxy - sx * sy / n) / variance, 0.0, 1.0) : 1.0;
}

struct NamedEstimator {
  std::string name;
  Estimator estimator;
  double epsilon_min = 0;
  long bad_samples = 0;
};

// Every estimator of the header, calibrated on the model's samples at its δ.
std::vector<NamedEstimator> calibrated_estimators(const pmsc::PmscModel& model, double tolerance) {
  const pmsc::CalibrationSamples& samples = model.calibration.samples;
  const double delta = model.calibration.false_hit_rate;
  std::vector<NamedEstimator> out;
  // Issue #22's rule on the families it had (interleaved, blocks).
  {
    std::vector<long> kept;
    for (long i = 0; i < samples.size(); ++i) {
      if (samples.fold_family[static_cast<size_t>(i)] != pmsc::kSparseFold) kept.push_back(i);
    }
    Eigen::VectorXd key(static_cast<long>(kept.size())), max(static_cast<long>(kept.size()));
    std::vector<char> family;
    for (size_t k = 0; k < kept.size(); ++k) {
      key(static_cast<long>(k)) = samples.key_point_errors(kept[k]);
      max(static_cast<long>(k)) = samples.max_errors(kept[k]);
      family.push_back(samples.fold_family[static_cast<size_t>(kept[k])]);
    }
    const pmsc::CalibratedEpsilon c = pmsc::calibrate_epsilon_min(key, max, family, tolerance, delta);
    out.push_back({"key_bad_frames", key_estimator(), c.epsilon_min, c.over_tolerance});
  }
  const bool has_key_max = samples.key_point_max_errors.size() == samples.size();
  const auto add = [&](const std::string& name, const Estimator& estimator) {
    Eigen::VectorXd estimates(samples.size());
    for (long i = 0; i < samples.size(); ++i) {
      estimates(i) = estimator({samples.key_point_errors(i), has_key_max ? samples.key_point_max_errors(i) : 0.0,
                                samples.checked() ? samples.check_point_errors(i) : 0.0});
    }
    const pmsc::ExtrapolatedEpsilon c = pmsc::calibrate_extrapolated(estimates, samples.max_errors, tolerance, delta);
    out.push_back({name, estimator, c.epsilon_min, c.bad_samples});
  };
  add("key", key_estimator());
  if (has_key_max) add("key_max", [](const Observed& o) { return o.key_max; });
  if (!samples.checked()) return out;
  add("check", [](const Observed& o) { return o.check; });
  // Issue #35's estimator, its weight chosen on e_key as its models chose it.
  const double w = pmsc::choose_key_weight(samples, tolerance);
  add("worse", [w](const Observed& o) { return pmsc::combined_error_estimate(w, o.key, o.check); });
  const double a = geometric_exponent(samples, tolerance);
  add("geometric", [a](const Observed& o) {
    return std::pow(std::max(o.key, 1e-30), a) * std::pow(std::max(o.check, 1e-30), 1 - a);
  });
  if (has_key_max) {
    // The worst observed point: the worst key's residual, weighted as e_key is, against e_check.
    pmsc::CalibrationSamples worst = samples;
    worst.key_point_errors = samples.key_point_max_errors;
    const double w_max = pmsc::choose_key_weight(worst, tolerance);
    add("worst_point", [w_max](const Observed& o) { return pmsc::combined_error_estimate(w_max, o.key_max, o.check); });
  }
  return out;
}

// The table's label of an estimator.
const char* short_name(const std::string& name) {
  return name == "key_bad_frames" ? "k22"
         : name == "key"         ? "key"
         : name == "key_max"     ? "kmx"
         : name == "check"       ? "chk"
         : name == "worse"       ? "wor"
         : name == "worst_point" ? "wpt"
                                 : "geo";
}

nlohmann::json estimator_json(const NamedEstimator& e, const Verdicts& v, double test_count, int check_points,
                              int key_points) {
  return {{"estimator", e.name},
          {"epsilon_min", e.epsilon_min},
          {"calibration_bad_samples", e.bad_samples},
          {"hit_rate", v.hits / test_count},
          {"miss_recall_at_1pct", optional_ratio(v.bad_flagged, v.bad)},
          {"false_hit_rate_among_bad", optional_ratio(v.false_hits, v.bad)},
          {"false_hits", v.false_hits},
          {"false_hit_worst_error_over_tolerance", v.false_hit_worst},
          {"extra_client_points_over_keys",
           e.name == "key" || e.name == "key_bad_frames" ? 0.0 : static_cast<double>(check_points) / key_points}};
}

// The server's runtime of a trained model (core/pmsc/subspace.h): what every timing and every
// verdict below goes through, as in the daemon.
std::shared_ptr<const pmsc::Subspace> served_runtime(const pmsc::PmscModel& model) {
  auto runtime = pmsc::make_subspace(std::make_shared<const pmsc::PmscModel>(model));
  if (!runtime) {
    std::fprintf(stderr, "pmsc: a trained model has no runtime: %s\n", runtime.error().message.c_str());
    std::abort();
  }
  return *runtime;
}

// Eq. 2 for each column of `keys`, then one reconstruction of them all, as a server's batch.
void serve_batch(const pmsc::Subspace& runtime, const Eigen::MatrixXf& keys, std::vector<pmsc::PoseEstimate>& estimates,
                 Eigen::MatrixXf& points) {
  const long B = keys.cols();
  estimates.resize(static_cast<size_t>(B));
  points.resize(runtime.model().mean.size(), B);
  std::vector<const pmsc::PoseEstimate*> inputs(static_cast<size_t>(B));
  std::vector<float*> destinations(static_cast<size_t>(B));
  for (long b = 0; b < B; ++b) {
    runtime.estimate(keys.col(b), Eigen::VectorXf(), estimates[static_cast<size_t>(b)]);
    inputs[static_cast<size_t>(b)] = &estimates[static_cast<size_t>(b)];
    destinations[static_cast<size_t>(b)] = points.col(b).data();
  }
  runtime.reconstruct(inputs, destinations);
}

// Poses test frames from their key and check points through the model's runtime.
TestFrame measure_frame(const pmsc::Subspace& runtime, const Eigen::VectorXf& truth, pmsc::PoseEstimate& estimate) {
  const pmsc::PmscModel& model = runtime.model();
  runtime.estimate(pmsc::gather_key_values(model, truth), pmsc::gather_check_values(model, truth), estimate);
  Eigen::VectorXf points(model.mean.size());
  const pmsc::PoseEstimate* input = &estimate;
  float* destination = points.data();
  runtime.reconstruct({&input, 1}, {&destination, 1});
  TestFrame t;
  const Eigen::VectorXf residual = truth - points;
  t.point_errors = Eigen::Map<const Eigen::Matrix3Xf>(residual.data(), 3, model.point_count).colwise().norm();
  t.key_point_error = estimate.key_point_error;
  t.key_point_max_error = estimate.key_point_max_error;
  t.check_point_error = estimate.check_point_error;
  t.error_estimate = estimate.error_estimate;
  t.max_error = t.point_errors.maxCoeff();
  t.diagonal = pmsc::bounding_box_diagonal(truth);
  t.region_errors = estimate.region_errors;
  return t;
}

// A served pose (estimate, then reconstruct) timed as a pass over the test poses' key values
// (at least 64 poses), seconds a pose.
double pass_seconds(const pmsc::Subspace& runtime, const std::vector<Eigen::VectorXf>& keys, Eigen::VectorXf& served) {
  const long poses = std::max<long>(64, static_cast<long>(keys.size()));
  served.resize(runtime.model().mean.size());
  pmsc::PoseEstimate estimate;
  return median_seconds(1, [&] {
    for (long i = 0; i < poses; ++i) {
      runtime.estimate(keys[static_cast<size_t>(i % static_cast<long>(keys.size()))], Eigen::VectorXf(), estimate);
      const pmsc::PoseEstimate* input = &estimate;
      float* destination = served.data();
      runtime.reconstruct({&input, 1}, {&destination, 1});
      do_not_optimize(served.data());
    }
  }) / static_cast<double>(poses);
}

// The unaligned linear row of a split, kept for the articulated row of the same split: its
// runtime is timed again there, pass for pass beside the articulated one, so that the ratio of
// the two kinds' CPU a pose (issue #51) is measured under the same load.
struct LinearPairing {
  std::shared_ptr<const pmsc::Subspace> runtime;
  std::vector<Eigen::VectorXf> test_keys;
};

// The table's "al" column: the linear kind with or without rigid alignment, or the articulated
// kind (issue #51, which carries rigid motion in its bones and is never aligned).
const char* configuration_label(bool aligned, pmsc::SubspaceKind kind, bool cross_fitted) {
  if (kind == pmsc::SubspaceKind::kArticulated) return cross_fitted ? "artx" : "art";
  return aligned ? "yes" : "no";
}

nlohmann::json run_one(const std::string& dataset, const mesh_io::LoadedSequence& sequence, const Split& split,
                       bool aligned, pmsc::SubspaceKind kind, bool cross_fitted, const SuiteOptions& suite,
                       LinearPairing& pairing) {
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
  options.held_out_key_slack = suite.held_out_key_slack;
  options.remove_rigid_motion = aligned;
  options.subspace_kind = kind;
  options.cross_fitted_calibration = cross_fitted ? 1 : 0;
  if (kind == pmsc::SubspaceKind::kArticulated) options.faces = sequence.reference.F;
  pmsc::TrainingReport report;
  auto model = pmsc::train(train_frames, options, &report);
  if (!model) {
    std::fprintf(stderr, "%s/%s: training failed: %s\n", dataset.c_str(), split.name.c_str(),
                 model.error().message.c_str());
    return {{"dataset", dataset},
            {"split", split.name},
            {"aligned", aligned},
            {"subspace_kind", pmsc::subspace_kind_name(kind)},
            {"error", model.error().message}};
  }

  // Accuracy: each test frame posed from its key points; errors relative to the frame's own
  // bounding-box diagonal (the 2007 paper's "1% of the diagonal").
  std::vector<double> max_error_over_diag;
  std::vector<TestFrame> frames;
  std::vector<Eigen::VectorXf> test_keys;
  pmsc::PoseEstimate estimate;
  const auto runtime = served_runtime(*model);
  for (int f : split.test) {
    const Eigen::VectorXf truth = all.row(f).transpose();
    test_keys.push_back(pmsc::gather_key_values(*model, truth));
    frames.push_back(measure_frame(*runtime, truth, estimate));
    max_error_over_diag.push_back(frames.back().max_error / frames.back().diagonal);
  }
  const double test_count = static_cast<double>(split.test.size());
  const double tolerance_diag = suite.tolerance_diag;
  int under_1pct = 0;
  for (const TestFrame& t : frames) under_1pct += t.max_error < tolerance_diag * t.diagonal ? 1 : 0;
  const Verdicts calibrated = verdicts(frames, model->epsilon.epsilon_min, tolerance_diag, served_estimator(*model));
  // The same verdicts judged against the model's own tolerance (1% of the reference mesh's
  // diagonal: what the HIT's guarantee is stated for) instead of 1% of each frame's diagonal.
  std::vector<TestFrame> at_model_tolerance = frames;
  for (TestFrame& t : at_model_tolerance) t.diagonal = diagonal;
  const Verdicts calibrated_model_tolerance =
      verdicts(at_model_tolerance, model->epsilon.epsilon_min, tolerance_diag, served_estimator(*model));
  nlohmann::json estimators = nlohmann::json::array();
  std::string estimator_text;
  for (const NamedEstimator& e : calibrated_estimators(*model, options.error_tolerance)) {
    const Verdicts v = verdicts(frames, e.epsilon_min, tolerance_diag, e.estimator);
    estimators.push_back(estimator_json(e, v, static_cast<double>(split.test.size()), model->check_point_count(),
                                        model->key_point_count()));
    char cell[64];
    std::snprintf(cell, sizeof cell, " %s:%.2f/%s/%.2f", short_name(e.name), v.hits / static_cast<double>(split.test.size()),
                  v.bad > 0 ? (std::to_string(v.bad_flagged) + "of" + std::to_string(v.bad)).c_str() : "-",
                  v.false_hit_worst);
    estimator_text += cell;
  }

  // The baseline, measured on the same model and folds: the pre-#22 rule, ε_min = tolerance / the
  // largest max-error/e_key ratio over the interleaved folds' held-out frames.
  double worst_ratio = 0;
  const pmsc::CalibrationSamples& samples = model->calibration.samples;
  for (long i = 0; i < samples.size(); ++i) {
    if (samples.fold_family[static_cast<size_t>(i)] != pmsc::kInterleavedFold ||
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
    const Verdicts v = verdicts(frames, variant.epsilon.epsilon_min, tolerance_diag, served_estimator(variant));
    curve.push_back({{"false_hit_rate", rate},
                     {"false_hit_rate_among_bad", optional_ratio(v.false_hits, v.bad)},
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
    const bool flagged = t.error_estimate > model->epsilon.epsilon_min;
    const double tolerance = tolerance_diag * t.diagonal;
    all_bad_points += static_cast<double>((t.point_errors.array() > tolerance).count());
    if (!flagged) continue;
    std::vector<char> local(static_cast<size_t>(model->point_count), 0);
    for (int i : pmsc::local_fail_through(*model, t.error_estimate, t.region_errors, !model->check_points.empty()).full_points) {
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
  // alternation inside each repetition, so both see the same machine load. A repetition is a pass
  // over every test pose (at least 64), and the row's figure is the fastest pass: the machine is
  // shared, so a slower pass measures its other tenants, and rows of two kinds are timed minutes
  // apart (the median of the passes is kept beside it). So an articulated row also times its
  // split's unaligned linear model in alternation with itself (LinearPairing): the ratio of those
  // two is the one to read for the kinds' CPU a pose.
  const long poses_per_pass = std::max<long>(64, static_cast<long>(test_keys.size()));
  const Eigen::VectorXf x = Eigen::VectorXf::Random(model->basis_size());
  Eigen::VectorXf y(model->basis.rows());
  std::vector<double> reconstruct_times, estimate_times, gemv_times, paired_linear_times;
  const bool paired = kind == pmsc::SubspaceKind::kArticulated && pairing.runtime;
  Eigen::VectorXf served;
  for (int repetition = 0; repetition < std::max(repetitions, 5); ++repetition) {
    reconstruct_times.push_back(pass_seconds(*runtime, test_keys, served));
    if (paired) paired_linear_times.push_back(pass_seconds(*pairing.runtime, pairing.test_keys, served));
    // The estimate alone (eq. 2 and the errors), so that the row says where a pose's time goes.
    estimate_times.push_back(median_seconds(1, [&] {
      for (long i = 0; i < poses_per_pass; ++i) {
        runtime->estimate(test_keys[static_cast<size_t>(i % static_cast<long>(test_keys.size()))], Eigen::VectorXf(),
                          estimate);
        do_not_optimize(estimate.coordinates.data());
      }
    }) / static_cast<double>(poses_per_pass));
    gemv_times.push_back(median_seconds(1, [&] {
      for (long i = 0; i < poses_per_pass; ++i) {
        y.noalias() = model->basis * x;
        do_not_optimize(y.data());
      }
    }) / static_cast<double>(poses_per_pass));
  }
  const double reconstruct_seconds = *std::min_element(reconstruct_times.begin(), reconstruct_times.end());
  const double reconstruct_median_seconds = tools::quantile(reconstruct_times, 0.5);
  const double estimate_seconds = *std::min_element(estimate_times.begin(), estimate_times.end());
  const double paired_linear_seconds =
      paired ? *std::min_element(paired_linear_times.begin(), paired_linear_times.end()) : 0.0;
  if (kind == pmsc::SubspaceKind::kLinear && !aligned) pairing = {runtime, test_keys};
  const double gemv_seconds = *std::min_element(gemv_times.begin(), gemv_times.end());
  Eigen::MatrixXf batch_keys(model->key_mean.size(), 64);
  for (long b = 0; b < 64; ++b) batch_keys.col(b) = test_keys[static_cast<size_t>(b) % test_keys.size()];
  Eigen::MatrixXf batch_points;
  std::vector<pmsc::PoseEstimate> batch_estimates;
  const double batch_seconds = median_seconds(std::max(3, repetitions / 3), [&] {
    serve_batch(*runtime, batch_keys, batch_estimates, batch_points);
    do_not_optimize(batch_points.data());
  });

  nlohmann::json row = {
      {"dataset", dataset},
      {"split", split.name},
      {"aligned", aligned},
      {"subspace_kind", pmsc::subspace_kind_name(model->subspace_kind)},
      {"calibration", cross_fitted ? "cross_fitted" : "served_keys"},
      {"bones", model->bone_count},
      {"residual_components", model->residual_components},
      {"skinning_rms_over_diag", report.skinning_rms / diagonal},
      {"skinning_seconds", report.skinning_seconds},
      {"basis", model->basis_size()},
      {"key_points", model->key_point_count()},
      {"held_out_key_slack", options.held_out_key_slack},
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
      {"false_hit_rate_among_bad", optional_ratio(calibrated.false_hits, calibrated.bad)},
      {"model_tolerance_frames_over", calibrated_model_tolerance.bad},
      {"model_tolerance_miss_recall", optional_ratio(calibrated_model_tolerance.bad_flagged, calibrated_model_tolerance.bad)},
      {"model_tolerance_false_hit_worst", calibrated_model_tolerance.false_hit_worst},
      {"check_points", model->check_point_count()},
      {"key_weight", model->key_weight},
      {"calibration_bad_samples", model->calibration.bad_samples},
      {"calibration_real_bad_samples", model->calibration.over_tolerance},
      {"estimator", pmsc::error_estimator_name(model->estimator)},
      {"calibration_guarantee_holds", pmsc::calibration_guarantee_holds(*model)},
      {"estimators", estimators},
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
      {"estimate_us_per_pose", 1e6 * estimate_seconds},
      // Articulated rows: the split's unaligned linear model timed pass for pass beside this one.
      {"paired_linear_reconstruct_us_per_pose", paired ? nlohmann::json(1e6 * paired_linear_seconds) : nlohmann::json()},
      {"reconstruct_over_paired_linear", paired ? nlohmann::json(reconstruct_seconds / paired_linear_seconds)
                                                : nlohmann::json()},
      {"reconstruct_us_per_pose_median", 1e6 * reconstruct_median_seconds},
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
              dataset.c_str(), split.name.c_str(), configuration_label(aligned, kind, cross_fitted), model->basis_size(), model->key_point_count(),
              report.seconds, report.calibration_seconds, split.test.size(), 100 * tools::quantile(max_error_over_diag, 0.5),
              100 * tools::quantile(max_error_over_diag, 0.95), under_1pct / test_count, floor_under_1pct / test_count,
              calibrated.hits / test_count, text(row["miss_recall_at_1pct"]).c_str(), calibrated.false_hits,
              calibrated.false_hit_worst, baseline.hits / test_count, text(row["baseline_miss_recall_at_1pct"]).c_str(),
              baseline.false_hits, baseline.false_hit_worst, text(row["local_over_global_full_points"]).c_str(),
              text(row["local_point_recall_at_1pct"]).c_str(),
              text(row["oracle_local_over_global_full_points"]).c_str(), 1e6 * reconstruct_seconds, 1e6 * gemv_seconds,
              64.0 / batch_seconds);
  std::printf("    C=%d w=%.3g bad samples=%ld%s | at the model's tolerance: %d over, %d flagged, worst FH %.2f |%s\n",
              model->check_point_count(), model->key_weight, model->calibration.bad_samples,
              pmsc::calibration_guarantee_holds(*model) ? "" : " (no guarantee)", calibrated_model_tolerance.bad,
              calibrated_model_tolerance.bad_flagged, calibrated_model_tolerance.false_hit_worst, estimator_text.c_str());
  if (paired) {
    std::printf("    estimate %.1f us of %.1f; the linear kind timed beside it %.1f us: %.2fx\n", 1e6 * estimate_seconds,
                1e6 * reconstruct_seconds, 1e6 * paired_linear_seconds, reconstruct_seconds / paired_linear_seconds);
  }
  std::fflush(stdout);
  return row;
}

// The cow rig (issue #35): truth without limit. Trained on kCowTrainPoses random joint rotations up
// to kCowTrainAngle, tested on kCowTestPoses fresh poses at each of kCowTestAngles (the wider ones
// extrapolate past every training pose); tolerance 1% of the rest pose's diagonal.
constexpr int kCowTrainPoses = 200;
constexpr int kCowTestPoses = 1000;
constexpr double kCowTrainAngle = 30;
constexpr double kCowTestAngles[] = {15, 30, 45, 60};

FrameMatrix cow_frames(const animation_space::LinearBlendModel& rig, int count, double max_degrees, uint64_t seed) {
  const auto poses = animation_space::random_joint_rotation_poses(rig.skeleton, count, max_degrees * std::numbers::pi / 180,
                                                                  seed);
  FrameMatrix frames(count, 3L * rig.vertex_count());
  PointMatrix posed;
  for (int p = 0; p < count; ++p) {
    animation_space::evaluate(rig, poses[static_cast<size_t>(p)], posed);
    frames.row(p) = Eigen::Map<const Eigen::RowVectorXf>(posed.data(), posed.size());
  }
  return frames;
}

// The cow is linear blend skinning by construction, so the articulated kind should be near exact
// on every angle: a correctness check of it, not a result.
//
// With `secondary` (issue #52), every training and test pose also gets localised secondary motion
// at a random place (animation_space::add_secondary_motion): the blind spot by construction,
// where a pose is bad only where no key point may be — dataset "cow-rig-secondary".
//
// With `cross_fitted`, the model's calibration judges each held-out frame with keys and check
// points chosen without it (TrainingOptions::cross_fitted_calibration): rows say which.
std::vector<nlohmann::json> run_cow_extrapolation(const std::filesystem::path& data, pmsc::SubspaceKind kind,
                                                  bool secondary, bool cross_fitted, const SuiteOptions& suite) {
  std::vector<nlohmann::json> rows;
  auto rig = read_cow_rig(data);
  if (!rig) return rows;
  const Eigen::VectorXf rest = Eigen::Map<const Eigen::VectorXf>(
      Eigen::MatrixXf(rig->model.rest_points.cast<float>()).data(), rig->model.rest_points.size());
  const double diagonal = pmsc::bounding_box_diagonal(rest);
  const std::string dataset = secondary ? "cow-rig-secondary" : "cow-rig";
  const PointMatrix rest_points = rig->model.rest_points.transpose().cast<float>();  // N × 3
  const auto posed = [&](int count, double max_degrees, uint64_t seed) {
    FrameMatrix frames = cow_frames(rig->model, count, max_degrees, seed);
    if (secondary) animation_space::add_secondary_motion(rest_points, {}, seed + 7919, frames);
    return frames;
  };
  pmsc::TrainingOptions options;
  options.error_bound = suite.error_bound_diag * diagonal;
  options.error_tolerance = suite.tolerance_diag * diagonal;
  options.max_key_points = 200;
  options.held_out_key_slack = suite.held_out_key_slack;
  options.subspace_kind = kind;
  options.cross_fitted_calibration = cross_fitted ? 1 : 0;
  if (kind == pmsc::SubspaceKind::kArticulated) options.faces = rig->model.faces;
  pmsc::TrainingReport report;
  auto model = pmsc::train(posed(kCowTrainPoses, kCowTrainAngle, 35), options, &report);
  if (!model) {
    std::printf("%s: training failed: %s\n", dataset.c_str(), model.error().message.c_str());
    return rows;
  }
  std::printf("%s (%s, %s calibration): trained on %d poses up to %.0f°: M %d (%d bones, %d residual components), %d keys, %d "
              "check points, w %.3g, %ld bad samples, %.1f s (%.1f s calibration)\n",
              dataset.c_str(), pmsc::subspace_kind_name(kind), cross_fitted ? "cross-fitted" : "served-keys", kCowTrainPoses, kCowTrainAngle, model->basis_size(),
              model->bone_count,
              model->residual_components, model->key_point_count(), model->check_point_count(), model->key_weight,
              model->calibration.bad_samples, report.seconds, report.calibration_seconds);
  std::printf("  %6s %5s %6s %5s | per estimator: hit rate / flagged of bad / false-hit rate among bad / worst false hit\n",
              "angle", "poses", "oracle", "bad");
  const double tolerance_diag = options.error_tolerance / diagonal;
  std::vector<TestFrame> pooled;
  const std::vector<NamedEstimator> estimators = calibrated_estimators(*model, options.error_tolerance);
  const auto runtime = served_runtime(*model);
  uint64_t seed = 3500;
  for (double angle : kCowTestAngles) {
    const FrameMatrix test = posed(kCowTestPoses, angle, ++seed);
    std::vector<TestFrame> frames;
    pmsc::PoseEstimate estimate;
    for (long f = 0; f < test.rows(); ++f) {
      frames.push_back(measure_frame(*runtime, test.row(f).transpose(), estimate));
      frames.back().diagonal = diagonal;  // one tolerance for every pose: 1% of the rest diagonal
      frames.back().point_errors.resize(0);
    }
    int oracle = 0;
    for (const TestFrame& t : frames) oracle += t.max_error <= options.error_tolerance ? 1 : 0;
    const double count = static_cast<double>(frames.size());
    nlohmann::json row = {{"dataset", dataset},
                          {"split", "rotations-" + std::to_string(static_cast<int>(kCowTrainAngle)) + "-to-" +
                                        std::to_string(static_cast<int>(angle))},
                          {"train_max_angle_degrees", kCowTrainAngle},
                          {"test_max_angle_degrees", angle},
                          {"train_frames", kCowTrainPoses},
                          {"test_frames", frames.size()},
                          {"subspace_kind", pmsc::subspace_kind_name(kind)},
                          {"bones", model->bone_count},
                          {"residual_components", model->residual_components},
                          {"train_seconds", report.seconds},
                          {"basis", model->basis_size()},
                          {"key_points", model->key_point_count()},
                          {"held_out_key_slack", options.held_out_key_slack},
                          {"check_points", model->check_point_count()},
                          {"key_weight", model->key_weight},
                          {"calibration_bad_samples", model->calibration.bad_samples},
                          {"calibration_real_bad_samples", model->calibration.over_tolerance},
                          {"calibration", cross_fitted ? "cross_fitted" : "served_keys"},
                          {"estimator", pmsc::error_estimator_name(model->estimator)},
                          {"false_hit_rate", model->calibration.false_hit_rate},
                          {"oracle_hit_rate", oracle / count}};
    nlohmann::json compared = nlohmann::json::array();
    std::string text;
    for (const NamedEstimator& e : estimators) {
      const Verdicts v = verdicts(frames, e.epsilon_min, tolerance_diag, e.estimator);
      compared.push_back(estimator_json(e, v, count, model->check_point_count(), model->key_point_count()));
      if (e.name == (model->estimator == pmsc::ErrorEstimator::kWorstPoint ? "worst_point" : "worse")) {
        row["hit_rate"] = v.hits / count;
        row["miss_recall_at_1pct"] = optional_ratio(v.bad_flagged, v.bad);
        row["false_hit_rate_among_bad"] = optional_ratio(v.false_hits, v.bad);
        row["false_hit_worst_error_over_tolerance"] = v.false_hit_worst;
        row["frames_over_1pct"] = v.bad;
      }
      char cell[96];
      std::snprintf(cell, sizeof cell, " %s %.3f/%d of %d/%.3f/%.2f", short_name(e.name), v.hits / count,
                    v.bad_flagged, v.bad, v.bad > 0 ? static_cast<double>(v.false_hits) / v.bad : 0.0, v.false_hit_worst);
      text += cell;
    }
    row["estimators"] = compared;
    std::printf("  %6.0f %5zu %6.3f %5d |%s\n", angle, frames.size(), oracle / count,
                static_cast<int>(frames.size()) - oracle, text.c_str());
    rows.push_back(std::move(row));
    pooled.insert(pooled.end(), std::make_move_iterator(frames.begin()), std::make_move_iterator(frames.end()));
  }
  // The false-hit rate among bad poses against δ, over every test pose.
  nlohmann::json curve = nlohmann::json::array();
  std::printf("  false-hit rate among the %zu test poses over the tolerance, against δ:", pooled.size());
  for (double rate : pmsc::default_false_hit_rates()) {
    pmsc::PmscModel variant = *model;
    variant.calibration.false_hit_rate = rate;
    if (!pmsc::apply_calibration(variant, options.error_tolerance, options.blend_zone_ratio).ok()) continue;
    const Verdicts v = verdicts(pooled, variant.epsilon.epsilon_min, tolerance_diag, served_estimator(variant));
    curve.push_back({{"false_hit_rate", rate},
                     {"false_hit_rate_among_bad", optional_ratio(v.false_hits, v.bad)},
                     {"bad", v.bad},
                     {"hit_rate", v.hits / static_cast<double>(pooled.size())},
                     {"false_hit_worst_error_over_tolerance", v.false_hit_worst}});
    std::printf(" δ %.3g: %.4f (%d of %d)", rate, v.bad > 0 ? static_cast<double>(v.false_hits) / v.bad : 0.0,
                v.false_hits, v.bad);
  }
  std::printf("\n");
  for (nlohmann::json& row : rows) row["false_hit_rate_curve_all_angles"] = curve;
  std::fflush(stdout);
  return rows;
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
  RowProgress progress("pmsc");
  for (const std::string& dataset : options.datasets) {
    if (dataset == "cow-rig") continue;  // a rig, not a sequence: its own rows below
    auto sequence = mesh_io::load_sequence(*options.data / dataset);
    if (!sequence) {
      std::printf("%s: %s (skipped)\n", dataset.c_str(), sequence.error().message.c_str());
      continue;
    }
    std::vector<Split> splits = splits_for(sequence->frames.num_frames());
    int left_out = 0;
    for (Split& split : leave_one_block_out(sequence->frames.num_frames())) {
      split.name = "lobo-" + std::to_string(++left_out);
      splits.push_back(std::move(split));
    }
    for (const auto& split : splits) {
      LinearPairing pairing;
      for (bool aligned : {false, true}) {
        progress.starting(dataset + " " + split.name + (aligned ? " linear, aligned" : " linear"));
        results.push_back(
            run_one(dataset, *sequence, split, aligned, pmsc::SubspaceKind::kLinear, false, options, pairing));
      }
      for (bool cross_fitted : {false, true}) {
        progress.starting(dataset + " " + split.name + " articulated" + (cross_fitted ? ", cross-fitted" : ""));
        results.push_back(
            run_one(dataset, *sequence, split, false, pmsc::SubspaceKind::kArticulated, cross_fitted, options, pairing));
      }
    }
  }
  if (std::find(options.datasets.begin(), options.datasets.end(), "cow-rig") != options.datasets.end()) {
    for (pmsc::SubspaceKind kind : {pmsc::SubspaceKind::kLinear, pmsc::SubspaceKind::kArticulated}) {
      for (bool secondary : {false, true}) {
        for (bool cross_fitted : {false, true}) {
          progress.starting(std::string("cow-rig ") + pmsc::subspace_kind_name(kind) +
                            (secondary ? ", secondary motion" : "") + (cross_fitted ? ", cross-fitted" : ""));
          for (nlohmann::json& row : run_cow_extrapolation(*options.data, kind, secondary, cross_fitted, options)) {
            results.push_back(std::move(row));
          }
        }
      }
    }
  }
  std::printf(
      "train: seconds in all, cal s: of which the ε calibration. %%dg: max point error over the frame's bounding-box "
      "diagonal, percent. al: the linear kind without (no) or with (yes) rigid alignment, or the articulated kind "
      "(art, issue #51; artx: its calibration cross-fitted, issue #52). oracle: test frames truly under the tolerance (1%%). floor: the same for the full training "
      "basis with every point known. hit/recall/FH/worst: the calibrated soft cache (δ = the trainer's default) — hit "
      "rate, blend-or-miss among test frames over tolerance, false hits and the worst false hit's error over the "
      "tolerance; b.*: the same for the pre-#22 rule (worst ratio of the interleaved folds) on the same model. "
      "loc/gl: points needing the full calculation with per-region vs whole-pose fail-through on flagged frames; "
      "l.rec: of their points over tolerance, the fraction the local path recomputes; or/gl: the points truly over "
      "tolerance there, the least any local rule must recompute. Second line: C check points, w the weight of e_key "
      "in the verdict's estimate, the extrapolated bad samples ε rests on, and per estimator (key_bad_frames = issue "
      "#22's rule, key, check, worse = the verdict's, geometric) hit rate/flagged of bad/worst false hit over the "
      "tolerance on the test frames.\n");
  return results;
}

}  // namespace animspace::bench
