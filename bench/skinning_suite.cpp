// The skinning suite (issue #4): animation space against linear blend skinning (Merry 2007
// Table 8.2 compares fits, Table 8.9 evaluation speed) on the reference data.
//
//   horse-gallop  no skeleton: the automatic pipeline (fit_sequence.h) segments the even frames
//                 into rigid parts, fits the skeleton and both models on them; the odd frames are
//                 posed by each bone's rigid fit to its core vertices (§8.2) and compared.
//   cow-rig       the ground-truth LBS rig posed in 50 random poses (each joint rotated about a
//                 random axis by up to kCowMaxJointAngle); both models are fitted to 40 of them with
//                 the true bone transforms and the rig's influence sets, and tested on 10. The data
//                 is exactly LBS with known influences, so nothing needs regularising (δ = 0): the
//                 rows check that both fitters recover the rig and generalise from 40 poses.
//
// Both methods share the skeleton, influence sets and regularisation, so the rows differ only in
// the model (4 free coordinates per influence vs one weight). Evaluation speed is the same
// posing on the same influence sets, measured in the same run.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "bench/suites.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/import.h"
#include "core/common/timing.h"
#include "core/mesh_io/sequence_io.h"

namespace animspace::bench {
namespace {

using namespace animation_space;

constexpr double kCowMaxJointAngle = 35.0 * std::numbers::pi / 180.0;
constexpr int kCowPoses = 50;
constexpr int kCowTrainPoses = 40;

double diagonal_of(const PointMatrix& points) {
  return (points.colwise().maxCoeff() - points.colwise().minCoeff()).cast<double>().norm();
}

template <typename Model>
double vertices_per_second(const Model& model, const std::vector<TransformList>& poses, int repetitions) {
  PointMatrix posed;
  size_t next = 0;
  const double seconds = median_seconds(repetitions, [&] {
    evaluate(model, poses[next++ % poses.size()], posed);
    do_not_optimize(posed.data());
  });
  return model.vertex_count() / seconds;
}

struct Case {
  std::string dataset;
  Skeleton skeleton;
  TriangleMesh reference;
  InfluenceSets influences;
  FrameMatrix train, test;
  std::vector<TransformList> train_poses, test_poses;
  double skeleton_seconds = 0;  // shared by both methods (0 when the skeleton is given)
  FitOptions options;
};

nlohmann::json run_case(const Case& c, int repetitions) {
  const FitOptions& options = c.options;
  const double diagonal = diagonal_of(c.reference.V);
  FitExamples examples;
  examples.poses = c.train_poses;
  examples.meshes = c.train;

  FitReport as_report, lbs_report;
  auto start = std::chrono::steady_clock::now();
  auto as = fit_animation_space(c.skeleton, examples, c.reference.F, c.influences, options, &as_report);
  const double as_seconds = seconds_since(start);
  start = std::chrono::steady_clock::now();
  auto lbs = fit_linear_blend(c.skeleton, c.reference.V, examples, c.reference.F, c.influences, options, &lbs_report);
  const double lbs_seconds = seconds_since(start);
  if (!as || !lbs) {
    std::printf("%s: fit failed: %s\n", c.dataset.c_str(), (!as ? as.error() : lbs.error()).message.c_str());
    return nlohmann::json::array();
  }
  // Speed on the same influence sets, interleaved so that drift hits both alike.
  const double as_speed = vertices_per_second(*as, c.test_poses, repetitions);
  const double lbs_speed = vertices_per_second(*lbs, c.test_poses, repetitions);

  nlohmann::json rows = nlohmann::json::array();
  auto row = [&](const char* method, const auto& model, double fit_seconds, const FitReport& report) {
    const ReconstructionError train = reconstruction_error(model, c.train_poses, c.train);
    const ReconstructionError test = reconstruction_error(model, c.test_poses, c.test);
    const nlohmann::json r = {{"dataset", c.dataset},
                              {"method", method},
                              {"bones", c.skeleton.bone_count() - 1},
                              {"influences_per_vertex", static_cast<double>(c.influences.influence_count()) /
                                                            c.influences.vertex_count()},
                              {"train_poses", c.train_poses.size()},
                              {"test_poses", c.test_poses.size()},
                              {"fit_seconds", c.skeleton_seconds + fit_seconds},
                              {"skeleton_seconds", c.skeleton_seconds},
                              {"solve_seconds", fit_seconds},
                              {"unknowns", report.unknowns},
                              {"edge_regularisation", options.edge_regularisation},
                              {"vertex_regularisation", options.vertex_regularisation},
                              {"rmse_over_diag_train", train.rms / diagonal},
                              {"rmse_over_diag_test", test.rms / diagonal},
                              {"max_error_over_diag_test", test.max / diagonal},
                              {"eval_vertices_per_second", std::string(method) == "animspace" ? as_speed : lbs_speed},
                              {"lbs_eval_vertices_per_second", lbs_speed}};
    std::printf("%-13s %-9s %5d %5zu %5zu %8.2f %8.2f %10.5f %10.5f %10.4f %12.3g %12.3g\n", c.dataset.c_str(), method,
                c.skeleton.bone_count() - 1, c.train_poses.size(), c.test_poses.size(), c.skeleton_seconds + fit_seconds,
                fit_seconds, 100 * train.rms / diagonal, 100 * test.rms / diagonal, 100 * test.max / diagonal,
                r["eval_vertices_per_second"].get<double>(), lbs_speed);
    rows.push_back(r);
  };
  row("animspace", *as, as_seconds, as_report);
  row("lbs", *lbs, lbs_seconds, lbs_report);
  return rows;
}

std::optional<Case> horse_case(const std::filesystem::path& data, const SkinningSuiteOptions& options,
                               const FitOptions& fit) {
  auto sequence = mesh_io::load_sequence(data / "horse-gallop");
  if (!sequence) {
    std::printf("horse-gallop: %s (skipped)\n", sequence.error().message.c_str());
    return std::nullopt;
  }
  Case c;
  c.dataset = "horse-gallop";
  c.options = fit;
  c.reference = sequence->reference;
  const FrameMatrix& all = sequence->frames.samples;
  std::vector<int> train, test;
  for (int f = 0; f < all.rows(); ++f) (f % 2 == 0 ? train : test).push_back(f);
  c.train.resize(static_cast<Eigen::Index>(train.size()), all.cols());
  c.test.resize(static_cast<Eigen::Index>(test.size()), all.cols());
  for (size_t i = 0; i < train.size(); ++i) c.train.row(static_cast<Eigen::Index>(i)) = all.row(train[i]);
  for (size_t i = 0; i < test.size(); ++i) c.test.row(static_cast<Eigen::Index>(i)) = all.row(test[i]);

  SequenceFitOptions fit_options;
  fit_options.segmentation.bone_count = options.bones;
  fit_options.fit = fit;
  SequenceFitReport report;
  const auto start = std::chrono::steady_clock::now();
  auto skeleton = fit_sequence_skeleton(c.reference, c.train, fit_options, &report);
  if (!skeleton) {
    std::printf("horse-gallop: skeleton fitting failed: %s\n", skeleton.error().message.c_str());
    return std::nullopt;
  }
  c.skeleton_seconds = seconds_since(start);
  c.skeleton = skeleton->skeleton;
  c.influences = skeleton->influences;
  c.train_poses = skeleton->training_poses;
  for (Eigen::Index f = 0; f < c.test.rows(); ++f) c.test_poses.push_back(estimate_pose(*skeleton, c.reference.V, c.test.row(f)));
  return c;
}

std::optional<Case> cow_case(const std::filesystem::path& data, const FitOptions& fit) {
  const std::filesystem::path dir = data / "cow-rig";
  auto rig = read_libigl_rig(dir / "cow.obj", dir / "cow.tgf", dir / "cow.DMAT");
  if (!rig) {
    std::printf("cow-rig: %s (skipped)\n", rig.error().message.c_str());
    return std::nullopt;
  }
  Case c;
  c.dataset = "cow-rig";
  c.options = fit;
  c.options.edge_regularisation = 0;
  c.skeleton = rig->model.skeleton;
  c.influences = rig->model.influences;
  c.reference.F = rig->model.faces;
  c.reference.V = rig->model.rest_points.transpose().cast<float>();
  // Random poses of the ground-truth rig, posed by the rig itself.
  const std::vector<TransformList> poses = random_joint_rotation_poses(c.skeleton, kCowPoses, kCowMaxJointAngle, 2026);
  const int vertices = rig->model.vertex_count();
  c.train.resize(kCowTrainPoses, 3L * vertices);
  c.test.resize(kCowPoses - kCowTrainPoses, 3L * vertices);
  PointMatrix posed;
  for (int p = 0; p < kCowPoses; ++p) {
    const TransformList& globals = poses[static_cast<size_t>(p)];
    evaluate(rig->model, globals, posed);
    const Eigen::Map<const Eigen::RowVectorXf> flat(posed.data(), posed.size());
    if (p < kCowTrainPoses) {
      c.train.row(p) = flat;
      c.train_poses.push_back(globals);
    } else {
      c.test.row(p - kCowTrainPoses) = flat;
      c.test_poses.push_back(globals);
    }
  }
  return c;
}

}  // namespace

nlohmann::json run_skinning_suite(const SuiteOptions& suite) {
  nlohmann::json results = nlohmann::json::array();
  if (!suite.data) {
    std::printf("skinning: ../shared/data is absent; nothing to measure\n");
    return results;
  }
  FitOptions options;
  options.edge_regularisation = suite.skinning.edge_regularisation;
  options.vertex_regularisation = suite.skinning.vertex_regularisation;
  std::printf("%-13s %-9s %5s %5s %5s %8s %8s %10s %10s %10s %12s %12s\n", "dataset", "method", "bones", "train",
              "test", "fit_s", "solve_s", "rmse%d_tr", "rmse%d_te", "max%d_te", "eval_v/s", "lbs_eval_v/s");
  for (const std::string& dataset : suite.skinning.datasets) {
    std::optional<Case> c = dataset == "horse-gallop" ? horse_case(*suite.data, suite.skinning, options)
                            : dataset == "cow-rig"    ? cow_case(*suite.data, options)
                                                      : std::nullopt;
    if (!c) {
      if (dataset != "horse-gallop" && dataset != "cow-rig") std::printf("%s: unknown dataset (skipped)\n", dataset.c_str());
      continue;
    }
    for (auto& row : run_case(*c, suite.repetitions)) results.push_back(row);
  }
  std::printf("%%d: percent of the reference mesh's bounding-box diagonal. fit_s: skeleton (shared) + least "
              "squares; δ = %g (cow-rig: 0), λ = %g (unit-box units, §4.1.2).\n",
              options.edge_regularisation, options.vertex_regularisation);
  return results;
}

}  // namespace animspace::bench
