// Retraining from logged misses ("train each night, better tomorrow"), the persisted training
// options it needs, and PMSC containers that carry a posing engine for server fail-through.
#include "core/pmsc/retrain.h"

#include <cmath>
#include <iterator>
#include <limits>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/lod/lod_io.h"
#include "core/model/model_info.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/pmsc_io.h"
#include "tests/support/test_support.h"

namespace animspace::pmsc {
namespace {

// A bending, twisting sheet: a grid over x ∈ [0, 2], z ∈ [−½, ½] whose centre line is bent into
// a circular arc of curvature `bend` (in the x-y plane) and whose cross-lines are twisted about
// the arc's tangent by `twist`·x/2. Non-linear in both parameters, so a PCA subspace only covers
// the parameter ranges it was trained on.
constexpr int kColumns = 14;  // along x
constexpr int kRows = 10;     // along z
constexpr int kPoints = kColumns * kRows;

Eigen::VectorXf sheet(double bend, double twist) {
  Eigen::VectorXf frame(3 * kPoints);
  for (int r = 0; r < kRows; ++r) {
    for (int c = 0; c < kColumns; ++c) {
      const double x = 2.0 * c / (kColumns - 1);
      const double z = -0.5 + static_cast<double>(r) / (kRows - 1);
      const double angle = bend * x;
      // Arc point and its in-plane normal; bend → 0 is the flat line (x, 0).
      const double cx = bend == 0 ? x : std::sin(angle) / bend;
      const double cy = bend == 0 ? 0 : (1 - std::cos(angle)) / bend;
      const double nx = -std::sin(angle), ny = std::cos(angle);
      const double phi = 0.5 * twist * x;
      const int i = r * kColumns + c;
      frame(3 * i + 0) = static_cast<float>(cx + z * std::sin(phi) * nx);
      frame(3 * i + 1) = static_cast<float>(cy + z * std::sin(phi) * ny);
      frame(3 * i + 2) = static_cast<float>(z * std::cos(phi));
    }
  }
  return frame;
}

TriangleMesh sheet_mesh() {
  TriangleMesh mesh;
  const Eigen::VectorXf flat = sheet(0, 0);
  mesh.V = Eigen::Map<const PointMatrix>(flat.data(), kPoints, 3);
  mesh.F.resize(2 * (kRows - 1) * (kColumns - 1), 3);
  int f = 0;
  for (int r = 0; r + 1 < kRows; ++r) {
    for (int c = 0; c + 1 < kColumns; ++c) {
      const int i = r * kColumns + c;
      mesh.F.row(f++) << i, i + kColumns, i + 1;
      mesh.F.row(f++) << i + 1, i + kColumns, i + kColumns + 1;
    }
  }
  return mesh;
}

// Training set: the bend swept over [0, 1.2] with no twist.
FrameMatrix bend_only_frames(int count = 24) {
  FrameMatrix frames(count, 3 * kPoints);
  for (int f = 0; f < count; ++f) frames.row(f) = sheet(1.2 * f / (count - 1), 0).transpose();
  return frames;
}

double sheet_diagonal() { return bounding_box_diagonal(sheet(0, 0)); }

TrainingOptions sheet_options() {
  TrainingOptions o;
  o.error_bound = 0.001 * sheet_diagonal();
  o.error_tolerance = 0.01 * sheet_diagonal();
  o.region_count = 4;
  return o;
}

// A servable pmsc container for the sheet with its options stored, as the CLI writes it.
container::ModelContainer sheet_container(const FrameMatrix& frames, const TrainingOptions& options) {
  TrainingReport report;
  auto model = train(frames, options, &report);
  EXPECT_TRUE(model.ok()) << model.error().message;
  auto out = make_container(sheet_mesh(), frames, nullptr, *model, report, "bending sheet");
  store_training_options(options, out);
  out.metadata()["generator"] = "retrain_test";
  out.metadata()["units"] = "metres";
  return out;
}

// The sheet's points as a one-bone animation-space model: every point rides the root, p = (v̂, 1).
animation_space::AnimationSpaceModel sheet_engine(int points = kPoints) {
  animation_space::AnimationSpaceModel engine;
  engine.skeleton = animation_space::root_only_skeleton();
  const TriangleMesh mesh = sheet_mesh();
  engine.positions.resize(4, points);
  for (int i = 0; i < points; ++i) {
    engine.influences.bones.push_back(0);
    engine.influences.offsets.push_back(i + 1);
    engine.positions.col(i) << mesh.V.row(i % kPoints).transpose().cast<double>(), 1.0;
  }
  if (points == kPoints) engine.faces = mesh.F;
  return engine;
}

container::ModelContainer round_trip(const container::ModelContainer& in) {
  auto parsed = container::parse(container::serialize(in), "round trip");
  EXPECT_TRUE(parsed.ok()) << parsed.error().message;
  return *parsed;
}

// ---------------------------------------------------------------------------------------------
// Training options

TEST(PmscTrainingOptions, EveryFieldRoundTripsBitExactly) {
  TrainingOptions o;
  o.channel_count = 2;
  o.error_bound = 0.1 + 0.2;  // 0.30000000000000004: needs all 17 digits
  o.basis_size = 7;
  o.max_basis = 99;
  o.max_basis_fraction = 1.0 / 3;
  o.block_size = 13;
  o.max_key_points = 77;
  o.fiducial_points = {5, 0, 1234};
  o.grid_cells = 4;
  o.remove_rigid_motion = true;
  o.error_tolerance = 3e-300;
  o.calibration_folds = 6;
  o.blend_zone_ratio = std::nextafter(1.5, 2.0);
  o.region_count = 3;
  o.false_hit_rate = 0.1 + 0.2;
  o.calibration_block_frames = 7;
  o.held_out_key_slack = 0.1 + 0.2;
  o.positions = PointMatrix::Ones(2, 3);  // not persisted

  container::ModelContainer c;
  store_training_options(o, c);
  auto loaded = load_training_options(round_trip(c), "m");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->channel_count, 2);
  EXPECT_EQ(loaded->error_bound, 0.1 + 0.2);
  EXPECT_EQ(loaded->basis_size, 7);
  EXPECT_EQ(loaded->max_basis, 99);
  EXPECT_EQ(loaded->max_basis_fraction, 1.0 / 3);
  EXPECT_EQ(loaded->block_size, 13);
  EXPECT_EQ(loaded->max_key_points, 77);
  EXPECT_EQ(loaded->fiducial_points, o.fiducial_points);
  EXPECT_EQ(loaded->grid_cells, 4);
  EXPECT_TRUE(loaded->remove_rigid_motion);
  EXPECT_EQ(loaded->error_tolerance, 3e-300);
  EXPECT_EQ(loaded->calibration_folds, 6);
  EXPECT_EQ(loaded->blend_zone_ratio, std::nextafter(1.5, 2.0));
  EXPECT_EQ(loaded->region_count, 3);
  EXPECT_EQ(loaded->false_hit_rate, 0.1 + 0.2);
  EXPECT_EQ(loaded->calibration_block_frames, 7);
  EXPECT_EQ(loaded->held_out_key_slack, 0.1 + 0.2);
  EXPECT_EQ(loaded->positions.rows(), 0);
  EXPECT_EQ(c.metadata_value("pmsc.options.fiducial_points"), "5,0,1234");

  // The defaults, with no fiducials and rigid motion kept.
  container::ModelContainer d;
  store_training_options(TrainingOptions{}, d);
  auto defaults = load_training_options(d, "m");
  ASSERT_TRUE(defaults.ok()) << defaults.error().message;
  EXPECT_TRUE(defaults->fiducial_points.empty());
  EXPECT_FALSE(defaults->remove_rigid_motion);
  EXPECT_EQ(defaults->max_basis_fraction, TrainingOptions{}.max_basis_fraction);
}

// Issue #52 item 2: a model trained before the held-out key budget stores no slack; its budget
// was max_key_points alone, and a retrain keeps it so (slack 0).
TEST(PmscTrainingOptions, AModelFromBeforeTheHeldOutKeyBudgetRetrainsWithItsFixedBudget) {
  TrainingOptions o;
  o.held_out_key_slack = 0.05;
  container::ModelContainer c;
  store_training_options(o, c);
  ASSERT_EQ(c.metadata().erase("pmsc.options.held_out_key_slack"), 1u);
  auto loaded = load_training_options(round_trip(c), "old");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->held_out_key_slack, 0);
  EXPECT_EQ(loaded->max_key_points, TrainingOptions{}.max_key_points);
}

TEST(PmscTrainingOptions, AbsentOptionsAreAFailedPrecondition) {
  container::ModelContainer c;
  c.metadata()["pmsc.channels"] = "3";
  auto loaded = load_training_options(c, "arm/1");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_EQ(loaded.error().message,
            "arm/1: model was trained before training options were stored (no pmsc.options.*); retrain it from "
            "the CLI");
}

TEST(PmscTrainingOptions, BadValuesNameTheKey) {
  struct Case {
    const char* key;
    const char* value;  // nullptr: remove the key
  };
  const Case cases[] = {
      {"pmsc.options.error_bound", "0.1x"},  {"pmsc.options.error_bound", "nan"},
      {"pmsc.options.block_size", "12.5"},   {"pmsc.options.block_size", " 12"},
      {"pmsc.options.fiducial_points", "1,,2"}, {"pmsc.options.fiducial_points", "1,"},
      {"pmsc.options.remove_rigid_motion", "yes"}, {"pmsc.options.region_count", nullptr},
      {"pmsc.options.frobnicate", "1"},
  };
  for (const Case& c : cases) {
    container::ModelContainer container;
    store_training_options(TrainingOptions{}, container);
    if (c.value) {
      container.metadata()[c.key] = c.value;
    } else {
      container.metadata().erase(c.key);
    }
    auto loaded = load_training_options(container, "m");
    ASSERT_FALSE(loaded.ok()) << c.key;
    EXPECT_EQ(loaded.error().code, ErrorCode::kInvalidArgument) << c.key;
    EXPECT_NE(loaded.error().message.find(std::string("'") + c.key + "'"), std::string::npos) << loaded.error().message;
  }
}

// ---------------------------------------------------------------------------------------------
// Retraining

TEST(PmscRetrain, WithoutMissesItIsTrainOnTheSameFramesAndOptions) {
  const FrameMatrix frames = bend_only_frames();
  const TrainingOptions options = sheet_options();
  const container::ModelContainer current = round_trip(sheet_container(frames, options));

  auto retrained = retrain(current, 3, FrameMatrix(), 0, {}, "sheet/3");
  ASSERT_TRUE(retrained.ok()) << retrained.error().message;
  EXPECT_EQ(retrained->training_frames, frames.rows());
  EXPECT_EQ(retrained->misses_used, 0);
  auto model = load(retrained->container, "retrained");
  ASSERT_TRUE(model.ok()) << model.error().message;

  // The independent computation: train() called directly.
  TrainingReport report;
  auto expected = train(frames, options, &report);
  ASSERT_TRUE(expected.ok()) << expected.error().message;
  EXPECT_EQ(model->key_points, expected->key_points);
  EXPECT_EQ(model->basis_size(), expected->basis_size());
  EXPECT_DOUBLE_EQ(model->epsilon.epsilon_min, expected->epsilon.epsilon_min);
  EXPECT_DOUBLE_EQ(model->epsilon.epsilon_max, expected->epsilon.epsilon_max);
  EXPECT_EQ(retrained->report.key_points, report.key_points);

  // Reconstructions of an unseen pose agree (bases may differ in sign, the estimate may not).
  const Eigen::VectorXf unseen = sheet(0.55, 0);
  PoseEstimate a, b;
  evaluate(*model, gather_key_values(*model, unseen), a);
  evaluate(*expected, gather_key_values(*expected, unseen), b);
  EXPECT_LT((a.points - b.points).cwiseAbs().maxCoeff(), 1e-5 * sheet_diagonal());
  EXPECT_NEAR(a.key_point_error, b.key_point_error, 1e-6 * sheet_diagonal());

  // The training set is unchanged and the container is servable.
  auto stored = retrained->container.float_matrix("sequence.frames");
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(*stored, frames);
  auto info = model::describe(retrained->container, "retrained");
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, container::ModelKind::kPmsc);
  EXPECT_EQ(info->fail_through, model::FailThrough::kClient);
  EXPECT_EQ(info->frame_count, frames.rows());
}

// The cycle the server repeats over gRPC: a pose outside the training range misses; its full
// values, logged, are folded in by a retrain; the same pose then hits.
TEST(PmscRetrain, AMissFoldedInBecomesAHit) {
  const FrameMatrix frames = bend_only_frames();
  const container::ModelContainer current = sheet_container(frames, sheet_options());
  auto before = load(current, "before");
  ASSERT_TRUE(before.ok()) << before.error().message;

  const Eigen::VectorXf twisted = sheet(0.6, 0.8);  // twist was never trained
  CachedPose cached;
  evaluate_cached(*before, gather_key_values(*before, twisted), &twisted, cached);
  ASSERT_EQ(cached.status, CacheStatus::kMiss) << "e_key " << cached.key_point_error << " vs ε_max "
                                               << before->epsilon.epsilon_max;
  PoseEstimate estimate;
  evaluate(*before, gather_key_values(*before, twisted), estimate);
  ASSERT_GT(max_point_error((twisted - estimate.points).cast<double>(), 3), 0.01 * sheet_diagonal());

  // The control: retraining on the old frames alone learns nothing about the twist.
  auto unchanged = retrain(current, 1, FrameMatrix(), 0, {}, "sheet/1");
  ASSERT_TRUE(unchanged.ok()) << unchanged.error().message;
  auto same = load(unchanged->container, "same");
  ASSERT_TRUE(same.ok()) << same.error().message;
  evaluate_cached(*same, gather_key_values(*same, twisted), &twisted, cached);
  EXPECT_EQ(cached.status, CacheStatus::kMiss);

  FrameMatrix misses(1, 3 * kPoints);
  misses.row(0) = twisted.transpose();
  auto retrained = retrain(current, 1, misses, 17, {}, "sheet/1");
  ASSERT_TRUE(retrained.ok()) << retrained.error().message;
  EXPECT_EQ(retrained->training_frames, frames.rows() + 1);
  EXPECT_EQ(retrained->misses_used, 1);
  auto after = load(round_trip(retrained->container), "after");
  ASSERT_TRUE(after.ok()) << after.error().message;

  evaluate_cached(*after, gather_key_values(*after, twisted), &twisted, cached);
  EXPECT_EQ(cached.status, CacheStatus::kHit) << "e_key " << cached.key_point_error << " vs ε_min "
                                              << after->epsilon.epsilon_min;
  evaluate(*after, gather_key_values(*after, twisted), estimate);
  EXPECT_LT(max_point_error((twisted - estimate.points).cast<double>(), 3), 0.01 * sheet_diagonal());
  // And the bend-only poses it knew are still hits.
  const Eigen::VectorXf known = sheet(0.55, 0);
  evaluate_cached(*after, gather_key_values(*after, known), &known, cached);
  EXPECT_EQ(cached.status, CacheStatus::kHit);

  // The new training set is the old one followed by the miss, exactly.
  auto stored = retrained->container.float_matrix("sequence.frames");
  ASSERT_TRUE(stored.ok());
  ASSERT_EQ(stored->rows(), frames.rows() + 1);
  EXPECT_EQ(FrameMatrix(stored->topRows(frames.rows())), frames);
  EXPECT_EQ(FrameMatrix(stored->bottomRows(1)), misses);

  // What changed for the soft cache (issue #21): both versions' ε, and the share of the new
  // training set each answers as a hit, counted here frame by frame through evaluate_cached.
  EXPECT_EQ(retrained->previous_epsilon.epsilon_min, before->epsilon.epsilon_min);
  EXPECT_EQ(retrained->previous_epsilon.epsilon_max, before->epsilon.epsilon_max);
  EXPECT_EQ(retrained->epsilon.epsilon_min, after->epsilon.epsilon_min);
  EXPECT_EQ(retrained->epsilon.epsilon_max, after->epsilon.epsilon_max);
  auto hits_of = [&](const PmscModel& model) {
    int hits = 0;
    for (Eigen::Index f = 0; f < stored->rows(); ++f) {
      const Eigen::VectorXf frame = stored->row(f).transpose();
      evaluate_cached(model, gather_key_values(model, frame), nullptr, cached);
      hits += cached.status == CacheStatus::kHit ? 1 : 0;
    }
    return hits;
  };
  const double rows = static_cast<double>(stored->rows());
  EXPECT_DOUBLE_EQ(retrained->previous_hit_rate, hits_of(*before) / rows);
  EXPECT_DOUBLE_EQ(retrained->hit_rate, hits_of(*after) / rows);
  EXPECT_LT(retrained->previous_hit_rate, 1.0) << "the old version misses the twisted frame";
  EXPECT_DOUBLE_EQ(retrained->hit_rate, 1.0);
}

// Issue #53: the daemon holds a version's large sections on disk (container::ReadOptions). A
// retrain of such a container reads the training frames from the file and writes a new version
// byte for byte equal to the retrain of the same file read whole.
TEST(PmscRetrain, AContainerWhoseSectionsWereLeftOnDiskRetrainsAsTheWholeFile) {
  testing::TempDir dir;
  const auto path = dir.path() / "model.anim";
  ASSERT_TRUE(container::write_file(path, sheet_container(bend_only_frames(), sheet_options())).ok());
  auto whole = container::read_file(path);
  auto on_disk = container::read_file(path, container::ReadOptions{0});
  ASSERT_TRUE(whole.ok() && on_disk.ok());
  ASSERT_TRUE(on_disk->sections().at("sequence.frames").on_disk);
  ASSERT_EQ(whole->bytes_on_disk(), 0U);

  FrameMatrix misses(1, 3 * kPoints);
  misses.row(0) = sheet(0.6, 0.8).transpose();
  auto from_whole = retrain(*whole, 1, misses, 17, {}, "sheet/1");
  auto from_disk = retrain(*on_disk, 1, misses, 17, {}, "sheet/1");
  ASSERT_TRUE(from_whole.ok()) << from_whole.error().message;
  ASSERT_TRUE(from_disk.ok()) << from_disk.error().message;
  EXPECT_GT(from_disk->container.bytes_on_disk(), 0U) << "sections carried over stay on disk until written";
  for (auto* result : {&*from_whole, &*from_disk}) {
    ASSERT_TRUE(result->container.load_sections().ok());
    auto& metadata = result->container.metadata();
    std::erase_if(metadata, [](const auto& entry) { return entry.first.find("seconds") != std::string::npos; });
  }
  EXPECT_EQ(container::serialize(from_whole->container), container::serialize(from_disk->container));
}

TEST(PmscRetrain, KeepsMetadataAndRecordsWhereTheMissLogWasRead) {
  container::ModelContainer current = sheet_container(bend_only_frames(), sheet_options());
  // Per-frame data beside the frames (as the engine demo keeps its poses).
  current.set_matrix("sequence.bone_transforms", container::Float64Matrix(container::Float64Matrix::Zero(24, 16)));
  current.metadata()["up_axis"] = "y";
  EXPECT_EQ(misses_through(current), 0u);

  RetrainOptions overrides;
  overrides.max_key_points = 40;
  overrides.error_bound = 0.002 * sheet_diagonal();
  FrameMatrix misses(2, 3 * kPoints);
  misses.row(0) = sheet(0.3, 0.2).transpose();
  misses.row(1) = sheet(0.9, -0.2).transpose();
  auto first = retrain(current, 4, misses, 42, overrides, "sheet/4");
  ASSERT_TRUE(first.ok()) << first.error().message;
  const container::ModelContainer& c = first->container;
  EXPECT_EQ(c.metadata_value("description"), "bending sheet");
  EXPECT_EQ(c.metadata_value("generator"), "retrain_test");
  EXPECT_EQ(c.metadata_value("units"), "metres");
  EXPECT_EQ(c.metadata_value("up_axis"), "y");
  EXPECT_EQ(c.metadata_value("kind"), "pmsc");
  EXPECT_EQ(c.metadata_value("pmsc.retrained_from"), "4");
  EXPECT_EQ(c.metadata_value("pmsc.training_frames"), "26");
  EXPECT_EQ(misses_through(c), 42u);
  EXPECT_TRUE(c.has_section("mesh.faces"));
  // The poses no longer match the frames row for row.
  EXPECT_FALSE(c.has_section("sequence.bone_transforms"));
  // The options used are stored, overrides included, for the next retrain.
  auto stored = load_training_options(c, "c");
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  EXPECT_EQ(stored->max_key_points, 40);
  EXPECT_EQ(stored->error_bound, 0.002 * sheet_diagonal());
  EXPECT_EQ(stored->region_count, 4);
  EXPECT_LE(first->report.key_points, 40);

  // Retraining again without misses neither forgets nor rewinds the miss-log position.
  auto second = retrain(c, 5, FrameMatrix(), 0, {}, "sheet/5");
  ASSERT_TRUE(second.ok()) << second.error().message;
  EXPECT_EQ(misses_through(second->container), 42u);
  EXPECT_EQ(second->container.metadata_value("pmsc.retrained_from"), "5");
  EXPECT_EQ(second->training_frames, 26);

  container::ModelContainer garbled;
  garbled.metadata()["pmsc.misses_through"] = "12a";
  EXPECT_EQ(misses_through(garbled), 0u);
}

TEST(PmscRetrain, RefusesBadMissFramesAndModelsItCannotRetrain) {
  const container::ModelContainer current = sheet_container(bend_only_frames(), sheet_options());
  const int width = 3 * kPoints;

  FrameMatrix narrow = FrameMatrix::Zero(1, width - 1);
  auto result = retrain(current, 1, narrow, 1, {}, "sheet/1");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(result.error().message, "sheet/1: miss frames have the wrong width (expected N·D = " +
                                        std::to_string(width) + ", got " + std::to_string(width - 1) + ")");

  FrameMatrix bad(2, width);
  bad.row(0) = sheet(0.1, 0).transpose();
  bad.row(1) = sheet(0.2, 0).transpose();
  bad(1, 7) = std::numeric_limits<float>::quiet_NaN();
  result = retrain(current, 1, bad, 1, {}, "sheet/1");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(result.error().message, "sheet/1: miss frame 1 holds NaN or Inf values");
  bad(1, 7) = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(retrain(current, 1, bad, 1, {}, "sheet/1").ok());

  // A model trained before options were stored.
  container::ModelContainer old = current;
  for (auto it = old.metadata().begin(); it != old.metadata().end();) {
    it = it->first.rfind("pmsc.options.", 0) == 0 ? old.metadata().erase(it) : std::next(it);
  }
  result = retrain(old, 1, FrameMatrix(), 0, {}, "old/1");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(result.error().message.find("no pmsc.options.*"), std::string::npos) << result.error().message;

  // A model without its training frames.
  container::ModelContainer frameless;
  copy_sections(current, [](const std::string& name) { return name != "sequence.frames"; }, frameless);
  frameless.metadata() = current.metadata();
  result = retrain(frameless, 1, FrameMatrix(), 0, {}, "frameless/1");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(result.error().message.find("sequence.frames"), std::string::npos) << result.error().message;

  // Cross-PMSC: the flat sheet's keys drive the bent one; nothing computes the bent sheet.
  FrameMatrix control(8, width), output(8, width);
  for (int f = 0; f < 8; ++f) {
    control.row(f) = sheet(0, 0.1 * f).transpose();
    output.row(f) = sheet(0.15 * f, 0.1 * f).transpose();
  }
  TrainingOptions options = sheet_options();
  TrainingReport report;
  auto cross = train_cross(control, output, options, &report);
  ASSERT_TRUE(cross.ok()) << cross.error().message;
  auto cross_container = make_container(sheet_mesh(), output, &control, *cross, report, "cross sheet");
  store_training_options(options, cross_container);
  result = retrain(cross_container, 1, FrameMatrix(), 0, {}, "cross/1");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_EQ(result.error().message, "cross/1: cross-PMSC models have no full values to learn from");
  EXPECT_EQ(attach_posing_engine(sheet_engine(), cross_container).error().code, ErrorCode::kFailedPrecondition);

  // Something that is not a PMSC model at all.
  container::ModelContainer sequence;
  sequence.metadata()["kind"] = "mesh_sequence";
  EXPECT_EQ(retrain(sequence, 1, FrameMatrix(), 0, {}, "seq/1").error().code, ErrorCode::kFailedPrecondition);
}

// ---------------------------------------------------------------------------------------------
// Posing engine

TEST(PmscPosingEngine, MakesFailThroughServerSideAndSurvivesRetraining) {
  container::ModelContainer c = sheet_container(bend_only_frames(), sheet_options());
  auto before = model::describe(c, "sheet");
  ASSERT_TRUE(before.ok()) << before.error().message;
  EXPECT_EQ(before->fail_through, model::FailThrough::kClient);
  EXPECT_FALSE(has_posing_engine(c));

  const animation_space::AnimationSpaceModel engine = sheet_engine();
  const Status attached = attach_posing_engine(engine, c);
  ASSERT_TRUE(attached.ok()) << attached.error().message;
  EXPECT_TRUE(has_posing_engine(c));
  c = round_trip(c);
  auto info = model::describe(c, "sheet");
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, container::ModelKind::kPmsc);
  EXPECT_EQ(info->fail_through, model::FailThrough::kServer);
  EXPECT_EQ(info->bone_count, 1);
  EXPECT_EQ(info->point_count, kPoints);
  EXPECT_EQ(c.metadata_value("kind"), "pmsc");

  // What the server does with it: load the engine and the soft cache from the same container.
  auto loaded = animation_space::load(c, "sheet");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->vertex_count(), kPoints);
  EXPECT_EQ(loaded->positions, engine.positions);
  EXPECT_TRUE(load(c, "sheet").ok());
  auto levels = lod::load_levels(c, *loaded, "sheet");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  EXPECT_EQ(levels->count(), 1);
  // A rigid motion G of the root moves every point by G (p = (v̂, 1)): computed by hand.
  animation_space::Transform G = animation_space::Transform::Identity();
  G.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()).toRotationMatrix();
  G.block<3, 1>(0, 3) << 1, 2, 3;
  PointMatrix posed;
  animation_space::evaluate(*loaded, {G}, posed);
  const TriangleMesh mesh = sheet_mesh();
  for (int i = 0; i < kPoints; i += 13) {
    const Eigen::Vector3d rest = mesh.V.row(i).transpose().cast<double>();
    const Eigen::Vector3d expected = G.block<3, 3>(0, 0) * rest + G.block<3, 1>(0, 3);
    EXPECT_LT((posed.row(i).transpose().cast<double>() - expected).norm(), 1e-5);
  }

  // Retraining keeps the engine.
  FrameMatrix misses(1, 3 * kPoints);
  misses.row(0) = sheet(0.6, 0.8).transpose();
  auto retrained = retrain(c, 2, misses, 5, {}, "sheet/2");
  ASSERT_TRUE(retrained.ok()) << retrained.error().message;
  EXPECT_TRUE(has_posing_engine(retrained->container));
  auto after = model::describe(retrained->container, "sheet/3");
  ASSERT_TRUE(after.ok()) << after.error().message;
  EXPECT_EQ(after->fail_through, model::FailThrough::kServer);
  EXPECT_TRUE(animation_space::load(retrained->container, "sheet/3").ok());
}

TEST(PmscPosingEngine, RefusesAnEngineOfOtherPointsAndDescribeRefusesMismatchedSections) {
  container::ModelContainer c = sheet_container(bend_only_frames(), sheet_options());
  const Status wrong = attach_posing_engine(sheet_engine(kPoints + 1), c);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(wrong.error().message.find(std::to_string(kPoints + 1) + " vertices"), std::string::npos)
      << wrong.error().message;
  EXPECT_FALSE(has_posing_engine(c));

  // Sections that disagree with N are refused by describe, not served as kClient.
  ASSERT_TRUE(attach_posing_engine(sheet_engine(), c).ok());
  c.set_matrix("animspace.influence_offsets", container::Int32Matrix(container::Int32Matrix::Zero(kPoints, 1)));
  auto info = model::describe(c, "sheet");
  ASSERT_FALSE(info.ok());
  EXPECT_EQ(info.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(info.error().message.find("animspace.influence_offsets"), std::string::npos) << info.error().message;
}

}  // namespace
}  // namespace animspace::pmsc
