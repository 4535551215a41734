#include "core/animspace/fit.h"
#include "core/geometry/edges.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

using testing::random_model;
using testing::random_pose;
using testing::random_rotation;
using testing::random_skeleton;

// A generic rigid pose: every non-root bone gets an arbitrary rotation and translation (no
// hierarchy), so the examples determine every vertex's p uniquely (no null vectors, B.3).
TransformList generic_pose(int bones, std::mt19937_64& engine) {
  std::normal_distribution<double> normal;
  TransformList pose(static_cast<size_t>(bones), Transform::Identity());
  for (int j = 1; j < bones; ++j) {
    pose[static_cast<size_t>(j)] = make_transform(random_rotation(engine), Eigen::Vector3d(normal(engine), normal(engine), normal(engine)));
  }
  return pose;
}

// v^k_i = Σ_j G^k_j p_j in double, then stored as float like real example data.
FitExamples examples_of(const AnimationSpaceModel& model, const std::vector<TransformList>& poses) {
  FitExamples examples;
  examples.poses = poses;
  examples.meshes.resize(static_cast<Eigen::Index>(poses.size()), 3L * model.vertex_count());
  for (size_t k = 0; k < poses.size(); ++k) {
    for (int i = 0; i < model.vertex_count(); ++i) {
      Eigen::Vector4d v = Eigen::Vector4d::Zero();
      for (int e = model.influences.begin(i); e < model.influences.end(i); ++e) {
        v += poses[k][static_cast<size_t>(model.influences.bones[static_cast<size_t>(e)])] * model.positions.col(e);
      }
      for (int c = 0; c < 3; ++c) examples.meshes(static_cast<Eigen::Index>(k), 3L * i + c) = static_cast<float>(v(c));
    }
  }
  return examples;
}

// A rows × columns grid of vertices in the plane z = 0, unit spacing, two triangles per cell.
FaceMatrix grid_faces(int rows, int columns) {
  FaceMatrix faces(2 * (rows - 1) * (columns - 1), 3);
  int f = 0;
  for (int r = 0; r + 1 < rows; ++r) {
    for (int c = 0; c + 1 < columns; ++c) {
      const int v = r * columns + c;
      faces.row(f++) << v, v + 1, v + columns + 1;
      faces.row(f++) << v, v + columns + 1, v + columns;
    }
  }
  return faces;
}

// Every vertex influenced by the same bones.
InfluenceSets uniform_sets(int vertices, const std::vector<int32_t>& bones) {
  InfluenceSets sets;
  for (int i = 0; i < vertices; ++i) {
    sets.bones.insert(sets.bones.end(), bones.begin(), bones.end());
    sets.offsets.push_back(static_cast<int32_t>(sets.bones.size()));
  }
  return sets;
}

// Σ over edges of ‖p_a − p_b‖² with absent bones as zero (the quantity eq. 4.4 penalises, without
// the 1/ℓ weights), from dense positions computed independently of the fit.
double edge_roughness(const AnimationSpaceModel& model) {
  double sum = 0;
  for (const auto& [a, b] : geometry::unique_edges(model.faces)) sum += (dense_position(model, a) - dense_position(model, b)).squaredNorm();
  return sum;
}

// A smooth field of SSD-like positions on the grid with per-example noise, so that no model fits
// exactly and the regularisers have something to trade against.
struct NoisyGridProblem {
  Skeleton skeleton;
  FitExamples examples;
  FaceMatrix faces;
  InfluenceSets influences;
};

NoisyGridProblem noisy_grid_problem(double scale = 1.0) {
  NoisyGridProblem problem;
  const int rows = 8, columns = 12, V = rows * columns;
  problem.skeleton = random_skeleton(3, 21);
  problem.faces = grid_faces(rows, columns);
  problem.influences = uniform_sets(V, {0, 1, 2});
  AnimationSpaceModel truth;
  truth.skeleton = problem.skeleton;
  truth.influences = problem.influences;
  truth.positions.resize(4, 3L * V);
  std::mt19937_64 engine(22);
  std::normal_distribution<double> normal;
  for (int i = 0; i < V; ++i) {
    const Eigen::Vector4d rest(0.3 * (i % columns), 0.3 * (i / columns), 0, 1);
    const double t = static_cast<double>(i % columns) / (columns - 1);
    const double w[3] = {0.2, 0.8 * (1 - t), 0.8 * t};
    for (int j = 0; j < 3; ++j) {
      truth.positions.col(3L * i + j) = w[j] * (affine_inverse(problem.skeleton.rest[static_cast<size_t>(j)]) * rest);
    }
  }
  std::vector<TransformList> poses;
  for (int k = 0; k < 6; ++k) poses.push_back(random_pose(problem.skeleton, engine, 0.8));
  problem.examples = examples_of(truth, poses);
  for (Eigen::Index k = 0; k < problem.examples.meshes.rows(); ++k) {
    for (Eigen::Index c = 0; c < problem.examples.meshes.cols(); ++c) problem.examples.meshes(k, c) += static_cast<float>(0.02 * normal(engine));
  }
  // Scale the whole problem: points and pose translations together.
  problem.examples.meshes *= static_cast<float>(scale);
  for (auto& pose : problem.examples.poses) {
    for (auto& G : pose) G.topRightCorner<3, 1>() *= scale;
  }
  for (auto& G : problem.skeleton.rest) G.topRightCorner<3, 1>() *= scale;
  return problem;
}

TEST(FitTest, RecoversKnownAnimationSpaceModelFromItsOwnPoses) {
  const Skeleton skeleton = random_skeleton(6, 1);
  const AnimationSpaceModel truth = random_model(skeleton, 300, 2);
  std::mt19937_64 engine(3);
  std::vector<TransformList> poses;
  for (int k = 0; k < 10; ++k) poses.push_back(generic_pose(skeleton.bone_count(), engine));
  FitOptions options;
  options.vertex_regularisation = 0;
  FitReport report;
  const auto fitted = fit_animation_space(skeleton, examples_of(truth, poses), FaceMatrix(), truth.influences, options, &report);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  ASSERT_TRUE(validate(*fitted, 1e-12).ok());
  EXPECT_FALSE(report.coupled);
  EXPECT_LT(report.residual_rms, 1e-6);
  // The data are float (6e-8 relative), so the recovered p agree to a few 1e-7.
  EXPECT_LT((fitted->positions - truth.positions).cwiseAbs().maxCoeff(), 2e-6);
}

// Poses of the "rotations with fixed translations" family leave null vectors (thesis App. B.3:
// p_j = e_w, p_φ(j) = −(t_j, 1)), so p is not unique; vertex regularisation picks one, and any
// choice reproduces new poses of the same family.
TEST(FitTest, GeneralisesToNewPosesWhenPositionsAreNotUnique) {
  const Skeleton skeleton = random_skeleton(5, 4);
  const AnimationSpaceModel truth = random_model(skeleton, 200, 5);
  std::mt19937_64 engine(6);
  std::vector<TransformList> poses;
  for (int k = 0; k < 12; ++k) poses.push_back(random_pose(skeleton, engine, 2.0));
  FitOptions options;
  options.vertex_regularisation = 1e-8;
  const auto fitted = fit_animation_space(skeleton, examples_of(truth, poses), FaceMatrix(), truth.influences, options);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  for (int k = 0; k < 5; ++k) {
    const TransformList pose = random_pose(skeleton, engine, 2.0);
    PointMatrix expected, actual;
    evaluate(truth, pose, expected);
    evaluate(*fitted, pose, actual);
    EXPECT_LT((expected - actual).cwiseAbs().maxCoeff(), 2e-5) << "new pose " << k;
  }
}

// Regularisation pulls p towards 0 and so against p̲ = 1 (§4.1.3); the elimination must keep it
// exact anyway, in both solve paths.
TEST(FitTest, WeightIsExactlyOneEvenUnderHeavyRegularisation) {
  NoisyGridProblem problem = noisy_grid_problem();
  for (const double delta : {0.0, 1.0}) {
    FitOptions options;
    options.vertex_regularisation = 10;
    options.edge_regularisation = delta;
    const auto fitted = fit_animation_space(problem.skeleton, problem.examples, problem.faces, problem.influences, options);
    ASSERT_TRUE(fitted.ok()) << fitted.error().message;
    const Eigen::VectorXd weights = vertex_weights(*fitted);
    EXPECT_LT((weights.array() - 1).abs().maxCoeff(), 1e-12) << "δ = " << delta;
    // The regulariser really was strong: the unconstrained weights would have shrunk.
    EXPECT_LT(fitted->positions.row(3).cwiseAbs().maxCoeff(), 1.0) << "δ = " << delta;
  }
}

TEST(FitTest, LinearBlendRecoversKnownWeights) {
  const Skeleton skeleton = random_skeleton(5, 7);
  std::mt19937_64 engine(8);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.1, 1.0);
  LinearBlendModel truth;
  truth.skeleton = skeleton;
  const int V = 150;
  truth.rest_points.resize(3, V);
  for (int i = 0; i < V; ++i) {
    truth.rest_points.col(i) = Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    std::vector<int32_t> bones;
    const int count = 1 + i % 4;
    for (int j = 0; bones.size() < static_cast<size_t>(count); ++j) bones.push_back((i + 2 * j) % skeleton.bone_count());
    std::sort(bones.begin(), bones.end());
    bones.erase(std::unique(bones.begin(), bones.end()), bones.end());
    double sum = 0;
    const Eigen::Index first = truth.weights.size();
    truth.weights.conservativeResize(first + static_cast<Eigen::Index>(bones.size()));
    for (size_t k = 0; k < bones.size(); ++k) sum += truth.weights(first + static_cast<Eigen::Index>(k)) = uniform(engine);
    truth.weights.tail(static_cast<Eigen::Index>(bones.size())) /= sum;
    truth.influences.bones.insert(truth.influences.bones.end(), bones.begin(), bones.end());
    truth.influences.offsets.push_back(static_cast<int32_t>(truth.influences.bones.size()));
  }
  ASSERT_TRUE(validate(truth).ok());
  FitExamples examples;
  for (int k = 0; k < 8; ++k) examples.poses.push_back(generic_pose(skeleton.bone_count(), engine));
  // SSD examples computed here in double: v = Σ_j w_j G_j Ĝ_j⁻¹ v̂.
  examples.meshes.resize(8, 3L * V);
  for (int k = 0; k < 8; ++k) {
    for (int i = 0; i < V; ++i) {
      Eigen::Vector4d v = Eigen::Vector4d::Zero();
      for (int e = truth.influences.begin(i); e < truth.influences.end(i); ++e) {
        const size_t j = static_cast<size_t>(truth.influences.bones[static_cast<size_t>(e)]);
        v += truth.weights(e) * (examples.poses[static_cast<size_t>(k)][j] * affine_inverse(skeleton.rest[j]) * truth.rest_points.col(i).homogeneous());
      }
      for (int c = 0; c < 3; ++c) examples.meshes(k, 3L * i + c) = static_cast<float>(v(c));
    }
  }
  const PointMatrix rest_points = truth.rest_points.transpose().cast<float>();
  FitOptions options;
  options.vertex_regularisation = 1e-10;
  FitReport report;
  const auto fitted = fit_linear_blend(skeleton, rest_points, examples, FaceMatrix(), truth.influences, options, &report);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  ASSERT_TRUE(validate(*fitted).ok());
  EXPECT_EQ(report.unknowns, truth.influences.influence_count() - V);  // one weight eliminated per vertex
  // The rest points went through float, so the weights agree to float-level precision.
  EXPECT_LT((fitted->weights - truth.weights).cwiseAbs().maxCoeff(), 1e-5);
  for (int i = 0; i < V; ++i) {
    EXPECT_NEAR(fitted->weights.segment(fitted->influences.begin(i), fitted->influences.end(i) - fitted->influences.begin(i)).sum(), 1.0, 1e-12);
  }
}

// The model keeps exactly the sets it was given, also when they exclude the root and are smaller
// than the bones that really moved the data; and p of one vertex only depends on the bones in
// its set (a set-respecting fit of a vertex is unchanged by what other vertices may use).
TEST(FitTest, VerticesOnlyUseBonesOfTheirInfluenceSets) {
  const Skeleton skeleton = random_skeleton(5, 9);
  const AnimationSpaceModel truth = random_model(skeleton, 100, 10);
  std::mt19937_64 engine(11);
  std::vector<TransformList> poses;
  for (int k = 0; k < 6; ++k) poses.push_back(generic_pose(skeleton.bone_count(), engine));
  const FitExamples examples = examples_of(truth, poses);
  InfluenceSets restricted;
  for (int i = 0; i < truth.vertex_count(); ++i) {
    const int32_t bones[2] = {static_cast<int32_t>(1 + i % 4), static_cast<int32_t>(1 + (i + 1) % 4)};
    restricted.bones.push_back(std::min(bones[0], bones[1]));
    restricted.bones.push_back(std::max(bones[0], bones[1]));
    restricted.offsets.push_back(static_cast<int32_t>(restricted.bones.size()));
  }
  FitOptions options;
  options.edge_regularisation = 0.01;  // couples vertices whose sets differ
  FitReport report;
  const auto fitted = fit_animation_space(skeleton, examples, grid_faces(10, 10), restricted, options, &report);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  EXPECT_TRUE(report.coupled);
  EXPECT_EQ(fitted->influences.offsets, restricted.offsets);
  EXPECT_EQ(fitted->influences.bones, restricted.bones);
  EXPECT_EQ(fitted->positions.cols(), restricted.influence_count());
  for (int i = 0; i < truth.vertex_count(); ++i) {
    const Eigen::VectorXd p = dense_position(*fitted, i);
    EXPECT_EQ(p.segment<4>(0).squaredNorm(), 0.0) << "vertex " << i << " uses the root";
  }
}

// Eq. 4.4: as δ grows the fit trades training error for smoothness, monotonically (the standard
// property of minimisers of f + δ g), and a huge δ makes neighbouring p equal.
TEST(FitTest, EdgeRegularisationTradesErrorForSmoothnessMonotonically) {
  const NoisyGridProblem problem = noisy_grid_problem();
  double previous_error = 0, previous_roughness = std::numeric_limits<double>::infinity(), roughness_at_zero = 0;
  for (const double delta : {0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e4}) {
    FitOptions options;
    options.vertex_regularisation = 1e-9;
    options.edge_regularisation = delta;
    FitReport report;
    const auto fitted = fit_animation_space(problem.skeleton, problem.examples, problem.faces, problem.influences, options, &report);
    ASSERT_TRUE(fitted.ok()) << fitted.error().message;
    EXPECT_EQ(report.coupled, delta > 0);
    EXPECT_TRUE(report.converged);
    const double roughness = edge_roughness(*fitted);
    if (delta == 0) roughness_at_zero = roughness;
    EXPECT_GT(report.residual_rms, previous_error) << "δ = " << delta;
    EXPECT_LT(roughness, previous_roughness) << "δ = " << delta;
    previous_error = report.residual_rms;
    previous_roughness = roughness;
  }
  EXPECT_LT(previous_roughness, 1e-6 * roughness_at_zero);
}

// The coupled fit is the minimiser of eq. 4.4 (+ 4.3) subject to p̲ = 1, here computed
// independently: dense p over all bones of every influence set, the objective written out term by
// term, the constraints by Lagrange multipliers (KKT) instead of elimination.
TEST(FitTest, CoupledFitMinimisesEquation44SubjectToUnitWeight) {
  const Skeleton skeleton = random_skeleton(4, 23);
  const int rows = 4, columns = 5, V = rows * columns;
  const FaceMatrix faces = grid_faces(rows, columns);
  InfluenceSets sets;  // vary the sets across the grid so that edges join different sets
  for (int i = 0; i < V; ++i) {
    const int c = i % columns;
    const std::vector<int32_t> bones = c < 2 ? std::vector<int32_t>{0, 1} : c < 4 ? std::vector<int32_t>{1, 2, 3} : std::vector<int32_t>{3};
    sets.bones.insert(sets.bones.end(), bones.begin(), bones.end());
    sets.offsets.push_back(static_cast<int32_t>(sets.bones.size()));
  }
  std::mt19937_64 engine(24);
  std::normal_distribution<double> normal;
  FitExamples examples;
  const int n = 4;
  examples.meshes.resize(n, 3L * V);
  for (int k = 0; k < n; ++k) {
    examples.poses.push_back(generic_pose(skeleton.bone_count(), engine));
    for (int i = 0; i < V; ++i) {
      const Eigen::Vector3d v = Eigen::Vector3d(i % columns, i / columns, 0) + 0.3 * Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
      for (int c = 0; c < 3; ++c) examples.meshes(k, 3L * i + c) = static_cast<float>(v(c));
    }
  }
  const double lambda = 0.01, delta = 0.2;

  // Unknowns: p_ij for every influence (4 each) and one multiplier per vertex.
  const int I = sets.influence_count();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(4 * I, 4 * I);  // objective = xᵀHx − 2 gᵀx + const
  Eigen::VectorXd g = Eigen::VectorXd::Zero(4 * I);
  for (int i = 0; i < V; ++i) {
    for (int k = 0; k < n; ++k) {
      Eigen::MatrixXd A(3, 4 * I);  // v_fit = A x
      A.setZero();
      for (int e = sets.begin(i); e < sets.end(i); ++e) {
        A.middleCols<4>(4 * e) = examples.poses[static_cast<size_t>(k)][static_cast<size_t>(sets.bones[static_cast<size_t>(e)])].topRows<3>();
      }
      const Eigen::Vector3d v = examples.meshes.block<1, 3>(k, 3L * i).transpose().cast<double>();
      H += A.transpose() * A;
      g += A.transpose() * v;
    }
  }
  H += lambda * Eigen::MatrixXd::Identity(4 * I, 4 * I);
  for (const auto& [a, b] : geometry::unique_edges(faces)) {
    double length = 0;
    for (int k = 0; k < n; ++k) {
      length += (examples.meshes.block<1, 3>(k, 3L * a) - examples.meshes.block<1, 3>(k, 3L * b)).cast<double>().norm();
    }
    length /= n;
    // D x = p_a − p_b over the union of the two sets, one 4-block per bone.
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(4 * skeleton.bone_count(), 4 * I);
    for (int e = sets.begin(a); e < sets.end(a); ++e) D.block<4, 4>(4 * sets.bones[static_cast<size_t>(e)], 4 * e) += Eigen::Matrix4d::Identity();
    for (int e = sets.begin(b); e < sets.end(b); ++e) D.block<4, 4>(4 * sets.bones[static_cast<size_t>(e)], 4 * e) -= Eigen::Matrix4d::Identity();
    H += (delta / length) * D.transpose() * D;
  }
  Eigen::MatrixXd KKT = Eigen::MatrixXd::Zero(4 * I + V, 4 * I + V);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(4 * I + V);
  KKT.topLeftCorner(4 * I, 4 * I) = H;
  rhs.head(4 * I) = g;
  for (int i = 0; i < V; ++i) {
    for (int e = sets.begin(i); e < sets.end(i); ++e) KKT(4 * I + i, 4 * e + 3) = KKT(4 * e + 3, 4 * I + i) = 1;
    rhs(4 * I + i) = 1;
  }
  const Eigen::VectorXd expected = KKT.fullPivLu().solve(rhs).head(4 * I);

  FitOptions options;
  options.normalise_scale = false;  // λ and δ in model units, as written above
  options.vertex_regularisation = lambda;
  options.edge_regularisation = delta;
  for (const FitSolver solver : {FitSolver::kDirect, FitSolver::kConjugateGradient}) {
    options.solver = solver;
    const auto fitted = fit_animation_space(skeleton, examples, faces, sets, options);
    ASSERT_TRUE(fitted.ok()) << fitted.error().message;
    const Eigen::VectorXd actual = Eigen::Map<const Eigen::VectorXd>(fitted->positions.data(), 4 * I);
    EXPECT_LT((actual - expected).cwiseAbs().maxCoeff(), 1e-8) << (solver == FitSolver::kDirect ? "direct" : "CG");
  }
}

TEST(FitTest, ConjugateGradientAgreesWithDirectSolve) {
  const NoisyGridProblem problem = noisy_grid_problem();
  FitOptions options;
  options.vertex_regularisation = 1e-6;
  options.edge_regularisation = 0.01;
  options.solver = FitSolver::kDirect;
  const auto direct = fit_animation_space(problem.skeleton, problem.examples, problem.faces, problem.influences, options);
  options.solver = FitSolver::kConjugateGradient;
  FitReport report;
  const auto iterative = fit_animation_space(problem.skeleton, problem.examples, problem.faces, problem.influences, options, &report);
  ASSERT_TRUE(direct.ok() && iterative.ok());
  EXPECT_TRUE(report.converged);
  EXPECT_GT(report.iterations, 0);
  EXPECT_LT((direct->positions - iterative->positions).cwiseAbs().maxCoeff(), 1e-7);
}

// §4.1.2: with normalisation the fit of a scaled problem is the scaled fit (same relative error,
// p's xyz scaled, weights unchanged); without it λ and δ mean different things at each scale.
TEST(FitTest, ScaleNormalisationMakesTheFitScaleInvariant) {
  FitOptions options;
  options.vertex_regularisation = 1e-3;
  options.edge_regularisation = 1e-2;
  const NoisyGridProblem unit = noisy_grid_problem(1.0);
  FitReport unit_report;
  const auto reference = fit_animation_space(unit.skeleton, unit.examples, unit.faces, unit.influences, options, &unit_report);
  ASSERT_TRUE(reference.ok());
  for (const double scale : {1e-3, 1e3}) {
    const NoisyGridProblem scaled = noisy_grid_problem(scale);
    FitReport report;
    const auto fitted = fit_animation_space(scaled.skeleton, scaled.examples, scaled.faces, scaled.influences, options, &report);
    ASSERT_TRUE(fitted.ok());
    EXPECT_NEAR(report.residual_rms / scale, unit_report.residual_rms, 1e-5 * unit_report.residual_rms) << scale;
    EXPECT_LT((fitted->positions.topRows<3>() / scale - reference->positions.topRows<3>()).cwiseAbs().maxCoeff(), 1e-5) << scale;
    EXPECT_LT((fitted->positions.row(3) - reference->positions.row(3)).cwiseAbs().maxCoeff(), 1e-5) << scale;

    FitOptions raw = options;
    raw.normalise_scale = false;
    FitReport raw_report;
    ASSERT_TRUE(fit_animation_space(scaled.skeleton, scaled.examples, scaled.faces, scaled.influences, raw, &raw_report).ok());
    EXPECT_GT(std::abs(raw_report.residual_rms / scale - unit_report.residual_rms), 0.01 * unit_report.residual_rms) << scale;
  }
}

TEST(FitTest, UndeterminedVertexWithoutRegularisationIsReported) {
  const Skeleton skeleton = random_skeleton(3, 12);
  const AnimationSpaceModel truth = random_model(skeleton, 20, 13);
  std::mt19937_64 engine(14);
  // One example cannot determine a vertex with two or more influences.
  const FitExamples examples = examples_of(truth, {generic_pose(3, engine)});
  FitOptions options;
  options.vertex_regularisation = 0;
  const auto fitted = fit_animation_space(skeleton, examples, FaceMatrix(), truth.influences, options);
  ASSERT_FALSE(fitted.ok());
  EXPECT_EQ(fitted.error().code, ErrorCode::kFailedPrecondition);
  options.vertex_regularisation = 1e-6;
  EXPECT_TRUE(fit_animation_space(skeleton, examples, FaceMatrix(), truth.influences, options).ok());
}

TEST(FitTest, RejectsMalformedInputNamingIt) {
  const Skeleton skeleton = random_skeleton(3, 15);
  const AnimationSpaceModel truth = random_model(skeleton, 10, 16);
  std::mt19937_64 engine(17);
  const FitExamples good = examples_of(truth, {generic_pose(3, engine), generic_pose(3, engine)});
  struct Case {
    const char* name;
    std::function<void(FitExamples&, FaceMatrix&, FitOptions&)> damage;
    const char* message;
  };
  const std::vector<Case> cases = {
      {"mesh columns", [](FitExamples& e, FaceMatrix&, FitOptions&) { e.meshes.conservativeResize(2, 27); }, "example meshes"},
      {"NaN", [](FitExamples& e, FaceMatrix&, FitOptions&) { e.meshes(1, 4) = std::nanf(""); }, "NaN"},
      {"pose count", [](FitExamples& e, FaceMatrix&, FitOptions&) { e.poses[1].pop_back(); }, "example pose 1"},
      {"face index", [](FitExamples&, FaceMatrix& f, FitOptions&) { f = FaceMatrix(1, 3); f << 0, 1, 10; }, "face 0"},
      {"negative λ", [](FitExamples&, FaceMatrix&, FitOptions& o) { o.vertex_regularisation = -1; }, "vertex_regularisation"},
      {"negative δ", [](FitExamples&, FaceMatrix&, FitOptions& o) { o.edge_regularisation = -1; }, "edge_regularisation"},
  };
  for (const Case& c : cases) {
    FitExamples examples = good;
    FaceMatrix faces;
    FitOptions options;
    c.damage(examples, faces, options);
    const auto fitted = fit_animation_space(skeleton, examples, faces, truth.influences, options);
    ASSERT_FALSE(fitted.ok()) << c.name;
    EXPECT_EQ(fitted.error().code, ErrorCode::kInvalidArgument) << c.name;
    EXPECT_NE(fitted.error().message.find(c.message), std::string::npos) << c.name << ": " << fitted.error().message;
  }
}

// Labels on a 1 × 6 strip of quads (vertices 0–13, two rows of 7): bones 1 | 2 | 3 by column.
TEST(GrowInfluenceSetsTest, GrowsByRingsAddsParentAndCaps) {
  Skeleton skeleton = random_skeleton(4, 18);
  skeleton.parents = {-1, 0, 1, 2};  // a chain: 0 → 1 → 2 → 3
  const int columns = 7;
  const FaceMatrix faces = grid_faces(2, columns);
  std::vector<int32_t> labels(2 * columns);
  for (int i = 0; i < 2 * columns; ++i) labels[static_cast<size_t>(i)] = 1 + std::min(2, (i % columns) / 3);  // columns 0-2 → 1, 3-5 → 2, 6 → 3
  const auto bones_of = [](const InfluenceSets& sets, int vertex) {
    return std::vector<int32_t>(sets.bones.begin() + sets.begin(vertex), sets.bones.begin() + sets.end(vertex));
  };

  InfluenceGrowthOptions options;
  options.rings = 0;
  auto sets = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_TRUE(sets.ok()) << sets.error().message;
  ASSERT_TRUE(validate(*sets, 4).ok());
  EXPECT_EQ(bones_of(*sets, 0), (std::vector<int32_t>{0, 1}));  // own bone 1 and its parent, the root
  EXPECT_EQ(bones_of(*sets, 6), (std::vector<int32_t>{2, 3}));

  options.rings = 1;
  options.include_parent = false;
  sets = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_TRUE(sets.ok());
  EXPECT_EQ(bones_of(*sets, 0), (std::vector<int32_t>{1}));     // interior of bone 1
  EXPECT_EQ(bones_of(*sets, 2), (std::vector<int32_t>{1, 2}));  // next to column 3
  EXPECT_EQ(bones_of(*sets, 3), (std::vector<int32_t>{1, 2}));

  options.rings = 4;
  options.include_parent = true;
  options.max_influences = 2;  // vertex 5 (bone 2) sees 1 and 3 in range; the parent 1 wins by rule
  sets = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_TRUE(sets.ok());
  EXPECT_EQ(bones_of(*sets, 5), (std::vector<int32_t>{1, 2}));
  options.include_parent = false;  // now the nearer bone 3 (one ring away) beats bone 1 (three)
  sets = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_TRUE(sets.ok());
  EXPECT_EQ(bones_of(*sets, 5), (std::vector<int32_t>{2, 3}));
  options.include_parent = true;
  options.max_influences = 1;  // vertex 6's parent bone 2 owns more vertices in range, but own comes first
  sets = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_TRUE(sets.ok());
  EXPECT_EQ(bones_of(*sets, 6), (std::vector<int32_t>{3}));

  labels[4] = 9;
  const auto bad = grow_influence_sets(skeleton, labels, faces, options);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("vertex 4"), std::string::npos) << bad.error().message;
}

}  // namespace
}  // namespace animspace::animation_space
