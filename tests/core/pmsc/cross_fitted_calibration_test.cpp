// Cross-fitted calibration (issue #52; TrainingOptions::cross_fitted_calibration): a held-out
// frame is judged with keys that never saw it. Frames with smooth motion, each with a spike at a
// point of its own that no other frame moves: the served keys are drawn to every frame's spike,
// so a held-out frame's spike sits under a key and its worst key residual shows it; the keys of
// the other half of the frames never saw it, and it is hidden — as a new shot's would be.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/train.h"

namespace animspace::pmsc {
namespace {

constexpr int kPoints = 300;
constexpr int kFrames = 40;
constexpr float kSpike = 1.0f;

int spike_point(int frame) { return 7 + 7 * frame; }

FrameMatrix spiked_frames() {
  FrameMatrix frames(kFrames, 3 * kPoints);
  for (int f = 0; f < kFrames; ++f) {
    const double t = 2 * std::numbers::pi * f / kFrames;
    for (int i = 0; i < kPoints; ++i) {
      const double x = static_cast<double>(i) / kPoints;
      frames(f, 3 * i) = static_cast<float>(x);
      frames(f, 3 * i + 1) = static_cast<float>(0.2 * std::sin(t) * std::sin(std::numbers::pi * x) +
                                                0.1 * std::cos(2 * t) * std::sin(2 * std::numbers::pi * x));
      frames(f, 3 * i + 2) = static_cast<float>(0.05 * std::sin(3 * t) * x);
    }
    frames(f, 3 * spike_point(f) + 2) += kSpike;
  }
  return frames;
}

// The fraction of held-out samples whose frame's spike (a max error of about kSpike) showed in
// the worst key residual.
double spikes_seen(const PmscModel& model) {
  const CalibrationSamples& s = model.calibration.samples;
  long spiked = 0, seen = 0;
  for (long i = 0; i < s.size(); ++i) {
    if (s.max_errors(i) < 0.9 * kSpike) continue;
    ++spiked;
    seen += s.key_point_max_errors(i) > 0.5 * kSpike ? 1 : 0;
  }
  EXPECT_GT(spiked, kFrames) << "every frame is held out at least once, each with its spike unexplained";
  return spiked > 0 ? static_cast<double>(seen) / static_cast<double>(spiked) : 0.0;
}

TrainingOptions spike_options() {
  TrainingOptions options;
  options.error_bound = 1e-3;
  options.error_tolerance = 0.1;
  options.max_key_points = 80;
  // The three smooth modes only: a spike is never in the basis, so no key is needed to fix its
  // coordinate, and a key lies under it only because the selection saw its residual.
  options.basis_size = 3;
  options.region_count = 0;
  return options;
}

TEST(CrossFittedCalibration, HeldOutFramesAreJudgedWithKeysThatNeverSawThem) {
  const FrameMatrix frames = spiked_frames();
  TrainingOptions options = spike_options();
  auto served = train(frames, options, nullptr);
  ASSERT_TRUE(served.ok()) << served.error().message;
  // The served keys sit on the spikes: each held-out frame's own spike is under a key.
  int keyed_spikes = 0;
  for (int f = 0; f < kFrames; ++f) {
    keyed_spikes += std::count(served->key_points.begin(), served->key_points.end(), spike_point(f)) > 0 ? 1 : 0;
  }
  ASSERT_GE(keyed_spikes, kFrames * 3 / 4) << "the fixture should draw the keys to the spikes";
  EXPECT_GT(spikes_seen(*served), 0.7);

  options.cross_fitted_calibration = 1;
  auto cross_fitted = train(frames, options, nullptr);
  ASSERT_TRUE(cross_fitted.ok()) << cross_fitted.error().message;
  EXPECT_LT(spikes_seen(*cross_fitted), 0.3) << "the other half's keys never saw these spikes";
  // The served model is the same either way: only its calibration changed.
  EXPECT_EQ(cross_fitted->key_points, served->key_points);
  EXPECT_TRUE(cross_fitted->basis == served->basis);
}

TEST(CrossFittedCalibration, TheOptionIsKeptForRetrainingAndCheckedByName) {
  TrainingOptions options = spike_options();
  options.cross_fitted_calibration = 1;
  container::ModelContainer container;
  store_training_options(options, container);
  auto loaded = load_training_options(container, "spikes");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->cross_fitted_calibration, 1);

  options.cross_fitted_calibration = 2;
  const auto refused = train(spiked_frames(), options, nullptr);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("cross_fitted_calibration must be 0 or 1, got 2"), std::string::npos)
      << refused.error().message;
}

}  // namespace
}  // namespace animspace::pmsc
