#include "core/illumination/illumination_model.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/common/format.h"
#include "core/common/timing.h"
#include "core/pmsc/pmsc_io.h"

namespace animspace::illumination {

FrameMatrix gather_frames(const IlluminationEngine& engine, const std::vector<PointLight>& lights,
                          const GatherOptions& gather, const ProgressCallback& progress, const SurfaceFilter* filter) {
  FrameMatrix frames;
  engine.indirect_frames(lights, gather, frames, progress);
  if (filter != nullptr && filter->enabled()) {
    Eigen::VectorXf frame, filtered;
    for (Eigen::Index f = 0; f < frames.rows(); ++f) {
      frame = frames.row(f).transpose();
      surface_filter_apply(*filter, frame, filtered);
      frames.row(f) = filtered.transpose();
    }
  }
  return frames;
}

namespace {

// The median over frames of `of_frame` (each frame's points as a 3 × N map); frames for which it
// returns NaN are left out. 0 for no frames.
template <typename OfFrame>
double median_over_frames(const FrameMatrix& frames, OfFrame of_frame) {
  std::vector<double> values;
  for (long f = 0; f < frames.rows() && frames.cols() >= 3; ++f) {
    const double value = of_frame(Eigen::Map<const Eigen::Matrix3Xf>(frames.row(f).data(), 3, frames.cols() / 3));
    if (!std::isnan(value)) values.push_back(value);
  }
  if (values.empty()) return 0;
  auto middle = values.begin() + static_cast<long>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace

double radiance_scale(const FrameMatrix& frames) {
  return median_over_frames(frames, [](const Eigen::Map<const Eigen::Matrix3Xf>& points) {
    return static_cast<double>(points.colwise().norm().maxCoeff());
  });
}

double peak_to_rms_ratio(const FrameMatrix& frames) {
  return median_over_frames(frames, [](const Eigen::Map<const Eigen::Matrix3Xf>& points) {
    const Eigen::ArrayXd norms = points.colwise().norm().transpose().cast<double>().array();
    const double rms = std::sqrt(norms.square().mean());
    return rms > 0 ? norms.maxCoeff() / rms : std::nan("");
  });
}

Result<container::ModelContainer> train_illumination(const IlluminationEngine& engine,
                                                     const IlluminationTrainingOptions& options,
                                                     const std::string& description,
                                                     IlluminationTrainingReport* report) {
  ANIMSPACE_RETURN_IF_ERROR(check_lights(options.lights, "lights", static_cast<int>(options.lights.size())));
  ANIMSPACE_RETURN_IF_ERROR(check_gather_options(options.gather));
  if (options.key_samples < 0) {
    return make_error(ErrorCode::kInvalidArgument, "key_samples must be ≥ 0 (0: gather.samples), got " +
                                                       std::to_string(options.key_samples));
  }
  auto filter = surface_filter_precompute(engine.surface(), options.filter, "filter");
  if (!filter) return filter.error();
  if (!(options.tolerance_fraction > 0) || !(options.error_bound_fraction > 0)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "tolerance_fraction and error_bound_fraction must be > 0, got " +
                          format_number(options.tolerance_fraction) + " and " +
                          format_number(options.error_bound_fraction));
  }
  IlluminationTrainingReport local;
  IlluminationTrainingReport& r = report != nullptr ? *report : local;

  const auto gather_start = std::chrono::steady_clock::now();
  const FrameMatrix frames = gather_frames(engine, options.lights, options.gather, options.pmsc.progress, &*filter);
  r.gather_seconds = seconds_since(gather_start);
  r.radiance_scale = radiance_scale(frames);
  if (!(r.radiance_scale > 0)) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "no training light reaches a surface twice: every training frame's indirect radiance is 0");
  }

  pmsc::TrainingOptions trainer = options.pmsc;
  trainer.channel_count = 3;
  trainer.relative_tolerance = options.relative_tolerance;
  if (options.relative_tolerance) {
    r.peak_to_rms_ratio = peak_to_rms_ratio(frames);
    trainer.error_tolerance = options.tolerance_fraction * r.peak_to_rms_ratio;
  } else {
    trainer.error_tolerance = options.tolerance_fraction * r.radiance_scale;
  }
  trainer.error_bound = options.error_bound_fraction * r.radiance_scale;
  trainer.positions = engine.surface().vertices;  // grid seeds over the surface, not over colours
  trainer.remove_rigid_motion = false;            // colours have no rigid motion
  auto model = pmsc::train(frames, trainer, &r.pmsc);
  if (!model) return model.error();

  container::ModelContainer out;
  pmsc::store(*model, out);
  out.metadata()["description"] = description;
  pmsc::store_training_report(r.pmsc, out);
  trainer.progress = nullptr;
  pmsc::store_training_options(trainer, out);
  out.metadata()["illumination.radiance_scale"] = format_number(r.radiance_scale);
  out.metadata()["illumination.gather_seconds"] = format_number(r.gather_seconds);
  if (options.relative_tolerance) {
    out.metadata()["illumination.peak_to_rms_ratio"] = format_number(r.peak_to_rms_ratio);
  }
  out.metadata()["units"] = "radiance (W/(sr·m²)); positions in metres";
  IlluminationSetup setup;
  setup.surface = engine.surface();
  setup.gather = options.gather;
  setup.training_lights = options.lights;
  setup.view = options.view;
  setup.filter = options.filter;
  setup.key_samples = options.key_samples;
  attach_illumination(out, setup);
  return out;
}

}  // namespace animspace::illumination
