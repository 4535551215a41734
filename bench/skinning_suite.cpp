// The skinning suite: a mesh sequence turned into a skinned character (issue #23), and animation
// space against linear blend skinning on a given rig (issue #4; Merry 2007 Table 8.2 compares
// fits, Table 8.9 evaluation speed).
//
//   horse-gallop  no skeleton. (a) Fitted on all 48 frames at 10, 20, 30 bones and measured on
//                 them (the protocol of the published SSDR and Hyperspectral Inverse Skinning
//                 tables; `e_rms` is their E_RMS). (b) Fitted on the even frames at 16, 24, 32
//                 bones and tested on the odd ones with the test frames' bone motions solved and
//                 the model fixed (Dem Bones' protocol, bone_motions.h solve_pose).
//   crane         (b) at 24 bones.
//   both          (c) held-out blocks at 24 bones: blocks of ⌈F/8⌉ consecutive frames alternate
//                 between training and test, so the test frames are motion the fit never saw.
//   cow-rig       the ground-truth LBS rig posed in 50 random poses (each joint rotated about a
//                 random axis by up to kCowMaxJointAngle); both models are fitted to 40 of them with
//                 the true bone transforms and the rig's influence sets, and tested on 10. The data
//                 is exactly LBS with known influences, so nothing needs regularising (δ = 0): the
//                 rows check that both fitters recover the rig and generalise from 40 poses.
//
// Every sequence row comes twice: `fit` = "decomposition" (the alternating optimisation,
// fit_sequence.h) and `fit` = "first_pass" (segmentation, §4.1.4 skeleton, one least-squares
// solve: the pipeline before it), the baseline measured in the same run on the same frames.
// `lbs` is the linear blend model, `animspace` the animation-space refit on the same skeleton.
#include <algorithm>
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

#include "bench/skinning_anchors.h"
#include "bench/suites.h"
#include "core/animspace/bone_motions.h"
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

// A sequence without a skeleton: frames split into training and test rows (test may be empty).
struct Sequence {
  std::string dataset;
  TriangleMesh reference;
  FrameMatrix train, test;
  std::string protocol;  // "all_frames", "even_odd" or "blocks"
};

enum class Protocol { kAllFrames, kEvenOdd, kBlocks };

// Which split a frame belongs to: every frame trains (all frames); even frames train, odd test
// (interleaved); or blocks of ⌈F/8⌉ consecutive frames alternate, so that the test frames are
// stretches of motion the fit never saw, not neighbours of training frames.
bool is_training_frame(Protocol protocol, Eigen::Index frame, Eigen::Index frames) {
  switch (protocol) {
    case Protocol::kAllFrames: return true;
    case Protocol::kEvenOdd: return frame % 2 == 0;
    case Protocol::kBlocks: return (frame / ((frames + 7) / 8)) % 2 == 0;
  }
  return true;
}

std::optional<Sequence> load_sequence(const std::filesystem::path& data, const std::string& dataset, Protocol protocol) {
  auto sequence = mesh_io::load_sequence(data / dataset);
  if (!sequence) {
    std::printf("%s: %s (skipped)\n", dataset.c_str(), sequence.error().message.c_str());
    return std::nullopt;
  }
  Sequence out;
  out.dataset = dataset;
  out.reference = sequence->reference;
  out.protocol = protocol == Protocol::kAllFrames ? "all_frames" : protocol == Protocol::kEvenOdd ? "even_odd" : "blocks";
  const FrameMatrix& frames = sequence->frames.samples;
  std::vector<Eigen::Index> train, test;
  for (Eigen::Index f = 0; f < frames.rows(); ++f) (is_training_frame(protocol, f, frames.rows()) ? train : test).push_back(f);
  out.train.resize(static_cast<Eigen::Index>(train.size()), frames.cols());
  out.test.resize(static_cast<Eigen::Index>(test.size()), frames.cols());
  for (size_t k = 0; k < train.size(); ++k) out.train.row(static_cast<Eigen::Index>(k)) = frames.row(train[k]);
  for (size_t k = 0; k < test.size(); ++k) out.test.row(static_cast<Eigen::Index>(k)) = frames.row(test[k]);
  return out;
}

// E_RMS of the Hyperspectral Inverse Skinning authors: 1000 · √(Σ‖v − v'‖² / (3·N·F)) / r, r half the
// rest pose's bounding-box diagonal; `rms` is √(Σ‖v − v'‖² / (N·F)).
double e_rms(double rms, double diagonal) { return 1000.0 * rms / std::sqrt(3.0) / (0.5 * diagonal); }

nlohmann::json run_sequence(const Sequence& c, int bones, bool decompose, const SkinningSuiteOptions& suite,
                            const FitOptions& fit, int repetitions) {
  SequenceFitOptions options;
  options.segmentation.bone_count = bones;
  options.fit = fit;
  options.decompose = decompose;
  options.decomposition.weights.max_influences = suite.max_influences;
  options.decomposition.candidate_hops = suite.candidate_hops;
  options.influences.max_influences = suite.max_influences;
  SequenceFitReport report;
  auto start = std::chrono::steady_clock::now();
  auto skeleton = fit_sequence_skeleton(c.reference, c.train, options, &report);
  if (!skeleton) {
    std::printf("%s: skeleton fitting failed: %s\n", c.dataset.c_str(), skeleton.error().message.c_str());
    return nlohmann::json::array();
  }
  const double skeleton_seconds = seconds_since(start);
  start = std::chrono::steady_clock::now();
  auto lbs = fit_sequence_linear_blend(c.reference, c.train, *skeleton, options.fit, nullptr);
  const double lbs_seconds = seconds_since(start);
  start = std::chrono::steady_clock::now();
  std::vector<TransformList> as_poses = skeleton->training_poses;
  auto as = fit_sequence_model(c.reference, c.train, *skeleton, options.fit, nullptr);
  if (as && decompose) as = refine_animation_space(c.train, std::move(*as), as_poses, options.fit, options.refinement_rounds);
  const double as_seconds = seconds_since(start);
  if (!as || !lbs) {
    std::printf("%s: fit failed: %s\n", c.dataset.c_str(), (!as ? as.error() : lbs.error()).message.c_str());
    return nlohmann::json::array();
  }
  const double diagonal = diagonal_of(c.reference.V);
  const char* fit_name = decompose ? "decomposition" : "first_pass";
  const int iterations = static_cast<int>(report.decomposition.iterations.size());
  nlohmann::json rows = nlohmann::json::array();
  auto row = [&](const char* method, const auto& model, const std::vector<TransformList>& train_poses,
                 double fit_seconds) {
    std::vector<TransformList> test_poses;
    for (Eigen::Index f = 0; f < c.test.rows(); ++f) test_poses.push_back(solve_pose(model, c.test.row(f)));
    const ReconstructionError train = reconstruction_error(model, train_poses, c.train);
    const ReconstructionError test = test_poses.empty() ? ReconstructionError{} : reconstruction_error(model, test_poses, c.test);
    nlohmann::json r = {{"dataset", c.dataset},
                        {"protocol", c.protocol},
                        {"fit", fit_name},
                        {"method", method},
                        {"bones", bones},
                        {"influences_per_vertex",
                         static_cast<double>(model.influences.influence_count()) / model.influences.vertex_count()},
                        {"max_influences", suite.max_influences},
                        {"candidate_hops", suite.candidate_hops},
                        {"train_poses", c.train.rows()},
                        {"test_poses", c.test.rows()},
                        {"fit_seconds", skeleton_seconds + fit_seconds},
                        {"iterations", iterations},
                        {"edge_regularisation", options.fit.edge_regularisation},
                        {"vertex_regularisation", options.fit.vertex_regularisation},
                        {"e_rms", e_rms(train.rms, diagonal)},
                        {"rmse_over_diag_train", train.rms / diagonal}};
    if (!test_poses.empty()) {
      r["rmse_over_diag_test"] = test.rms / diagonal;
      r["max_error_over_diag_test"] = test.max / diagonal;
    }
    std::vector<TransformList> speed_poses = test_poses.empty() ? train_poses : test_poses;
    r["eval_vertices_per_second"] = vertices_per_second(model, speed_poses, repetitions);
    std::printf("%-13s %-10s %-13s %-9s %5d %5ld %5ld %8.2f %4d %8.3f %10.4f %10.4f %10.4f\n", c.dataset.c_str(),
                c.protocol.c_str(), fit_name, method, bones, static_cast<long>(c.train.rows()),
                static_cast<long>(c.test.rows()), skeleton_seconds + fit_seconds, iterations, e_rms(train.rms, diagonal),
                100 * train.rms / diagonal, test_poses.empty() ? 0.0 : 100 * test.rms / diagonal,
                test_poses.empty() ? 0.0 : 100 * test.max / diagonal);
    std::fflush(stdout);
    rows.push_back(r);
  };
  row("lbs", *lbs, skeleton->training_poses, lbs_seconds);
  row("animspace", *as, decompose ? as_poses : skeleton->training_poses, lbs_seconds + as_seconds);
  return rows;
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
  const auto has = [&](const char* dataset) {
    return std::find(suite.skinning.datasets.begin(), suite.skinning.datasets.end(), dataset) != suite.skinning.datasets.end();
  };
  RowProgress progress("skinning");
  for (const std::string& dataset : suite.skinning.datasets) {
    progress.starting(dataset);
    if (dataset != "horse-gallop" && dataset != "crane" && dataset != "cow-rig") {
      std::printf("%s: unknown dataset (skipped)\n", dataset.c_str());
    }
  }
  std::printf("%-13s %-10s %-13s %-9s %5s %5s %5s %8s %4s %8s %10s %10s %10s\n", "dataset", "protocol", "fit", "method",
              "bones", "train", "test", "fit_s", "iter", "E_RMS", "rmse%d_tr", "rmse%d_te", "max%d_te");
  const auto sequence_rows = [&](const std::string& dataset, Protocol protocol, const std::vector<int>& bone_counts) {
    const std::optional<Sequence> sequence = load_sequence(*suite.data, dataset, protocol);
    if (!sequence) return;
    for (int bones : bone_counts) {
      for (bool decompose : {false, true}) {
        for (auto& row : run_sequence(*sequence, bones, decompose, suite.skinning, options, suite.repetitions)) {
          results.push_back(row);
        }
      }
    }
  };
  if (has("horse-gallop")) {
    sequence_rows("horse-gallop", Protocol::kAllFrames, suite.skinning.all_frames_bones);
    sequence_rows("horse-gallop", Protocol::kEvenOdd, suite.skinning.split_bones);
    sequence_rows("horse-gallop", Protocol::kBlocks, suite.skinning.crane_bones);
  }
  if (has("crane")) {
    sequence_rows("crane", Protocol::kEvenOdd, suite.skinning.crane_bones);
    sequence_rows("crane", Protocol::kBlocks, suite.skinning.crane_bones);
  }
  std::printf("%%d: percent of the reference mesh's bounding-box diagonal; E_RMS: 1000·RMS per coordinate / half "
              "the diagonal (training frames). Test poses solved with the model fixed. δ = %g, λ = %g (unit-box "
              "units, §4.1.2); K = %d, candidates within %d parts.\n",
              options.edge_regularisation, options.vertex_regularisation, suite.skinning.max_influences,
              suite.skinning.candidate_hops);
  if (has("horse-gallop") || has("crane")) print_anchor_table(compare_with_anchors(results));
  if (has("cow-rig")) {
    std::printf("%-13s %-9s %5s %5s %5s %8s %8s %10s %10s %10s %12s %12s\n", "dataset", "method", "bones", "train",
                "test", "fit_s", "solve_s", "rmse%d_tr", "rmse%d_te", "max%d_te", "eval_v/s", "lbs_eval_v/s");
    if (std::optional<Case> c = cow_case(*suite.data, options)) {
      for (auto& row : run_case(*c, suite.repetitions)) results.push_back(row);
    }
  }
  return results;
}

}  // namespace animspace::bench
