#include "clients/cpp/cli/output.h"

#include "core/pmsc/pmsc_io.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <vector>

#include <google/protobuf/util/json_util.h>

namespace animspace::cli {

void print_json(const nlohmann::json& document) { std::cout << document.dump(2) << '\n' << std::flush; }

namespace {

std::string format_fixed(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3f", value);
  return text;
}

std::vector<double> offered_false_hit_rates(const pmsc::PmscModel& model) {
  std::vector<double> rates = pmsc::default_false_hit_rates();
  if (std::find(rates.begin(), rates.end(), model.calibration.false_hit_rate) == rates.end()) {
    rates.push_back(model.calibration.false_hit_rate);
    std::sort(rates.begin(), rates.end());
  }
  return rates;
}

}  // namespace

void print_operating_curve(const pmsc::PmscModel& model, double tolerance, int folds) {
  const pmsc::CalibrationSamples samples = pmsc::estimator_samples(model);
  const long over = pmsc::operating_point(samples, model.key_weight, model.calibration.false_hit_rate, tolerance).over_tolerance;
  std::printf("operating curve on %ld held-out frames (every %dth frame, sparser training, blocks of %d, %d and %d; "
              "each predicted by a model trained without it; %ld over the tolerance on their own, every one "
              "extrapolated past it; * = this model's δ):\n",
              samples.size(), folds, model.calibration.block_frames, 2 * model.calibration.block_frames,
              4 * model.calibration.block_frames, over);
  std::printf("  %8s %8s %11s %9s %12s %15s\n", "δ", "ratio q", "ε_min", "hit rate", "miss recall",
              "worst hit/tol");
  for (double rate : offered_false_hit_rates(model)) {
    const pmsc::OperatingPoint p = pmsc::operating_point(samples, model.key_weight, rate, tolerance);
    std::printf("%s %8.3g %8.3g %11.4g %9.3f %12s %15.3f\n", rate == model.calibration.false_hit_rate ? "*" : " ",
                rate, p.error_ratio, p.epsilon_min, p.hit_rate,
                p.over_tolerance > 0 ? format_fixed(p.miss_recall).c_str() : "n/a", p.worst_hit_error);
  }
}

nlohmann::json operating_curve_json(const pmsc::PmscModel& model, double tolerance) {
  const pmsc::CalibrationSamples samples = pmsc::estimator_samples(model);
  nlohmann::json curve = nlohmann::json::array();
  for (double rate : offered_false_hit_rates(model)) {
    const pmsc::OperatingPoint p = pmsc::operating_point(samples, model.key_weight, rate, tolerance);
    curve.push_back({{"false_hit_rate", rate},
                     {"error_ratio", p.error_ratio},
                     {"epsilon_min", p.epsilon_min},
                     {"hit_rate", p.hit_rate},
                     {"miss_recall", p.over_tolerance > 0 ? nlohmann::json(p.miss_recall) : nlohmann::json()},
                     {"over_tolerance", p.over_tolerance},
                     {"worst_hit_error_over_tolerance", p.worst_hit_error},
                     {"chosen", rate == model.calibration.false_hit_rate}});
  }
  return curve;
}

std::string calibration_label(const google::protobuf::Map<std::string, std::string>& metadata) {
  const auto value = [&](const char* key) {
    const auto found = metadata.find(key);
    return found == metadata.end() ? std::string() : found->second;
  };
  const std::string delta = value(pmsc::kFalseHitRateKey);
  if (delta.empty()) {
    return "worst ratio of max point error to e_key over held-out frames (pmsc format 1, trained before the "
           "conformal calibration: no stated false-hit rate; retrain to get one)";
  }
  char ratio[32] = "?";
  if (const std::string text = value(pmsc::kErrorRatioKey); !text.empty()) {
    std::snprintf(ratio, sizeof ratio, "%.3g", std::strtod(text.c_str(), nullptr));
  }
  return "conformal, false-hit rate δ = " + delta + ": of held-out training poses over the tolerance "
         "(pmsc.options.error_tolerance), at most a fraction δ would be called HIT (" +
         value(pmsc::kOverToleranceKey) + " such poses; ε_min = tolerance / " + ratio + ")";
}

nlohmann::json proto_json(const google::protobuf::Message& message) {
  std::string text;
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  (void)google::protobuf::util::MessageToJsonString(message, &text, options);
  return nlohmann::json::parse(text);
}

ProgressBar::ProgressBar(std::string label, uint64_t total)
    : label_(std::move(label)),
      total_(total),
      enabled_(isatty(STDERR_FILENO) == 1),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_ - std::chrono::seconds(1)) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(uint64_t done, const std::string& detail) {
  done_ = done;
  if (!enabled_ || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_draw_ < std::chrono::milliseconds(100) && done != total_) return;
  last_draw_ = now;
  draw(detail);
}

void ProgressBar::finish() {
  if (!enabled_ || finished_) return;
  finished_ = true;
  std::fputc('\n', stderr);
}

void ProgressBar::draw(const std::string& detail) {
  constexpr int kWidth = 30;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double fraction = total_ == 0 ? 0.0 : std::min(1.0, double(done_) / double(total_));
  const int filled = static_cast<int>(fraction * kWidth);
  std::string bar(static_cast<size_t>(filled), '#');
  bar.resize(kWidth, '.');
  std::string eta;
  if (done_ > 0 && done_ < total_) {
    eta = ", ~" + std::to_string(static_cast<long>(seconds * double(total_ - done_) / double(done_))) + " s left";
  }
  // \r and clear-to-end-of-line: the bar rewrites itself in place.
  std::fprintf(stderr, "\r%s [%s] %llu/%llu %3.0f%% %.1f s%s%s%s\033[K", label_.c_str(), bar.c_str(),
               static_cast<unsigned long long>(done_), static_cast<unsigned long long>(total_), 100.0 * fraction,
               seconds, eta.c_str(), detail.empty() ? "" : "  ", detail.c_str());
  std::fflush(stderr);
}

ProgressCallback progress_bars(const std::string& command) {
  struct Stages {
    std::string stage;
    std::unique_ptr<ProgressBar> bar;
  };
  auto stages = std::make_shared<Stages>();
  return [command, stages](std::string_view stage, int64_t done, int64_t total) {
    if (!stages->bar || stages->stage != stage) {
      stages->stage = std::string(stage);
      stages->bar = std::make_unique<ProgressBar>(command + ": " + stages->stage, static_cast<uint64_t>(total));
    }
    stages->bar->set_total(static_cast<uint64_t>(total));
    stages->bar->update(static_cast<uint64_t>(done));
  };
}

void print_soft_cache_change(double previous_epsilon_min, double epsilon_min, double previous_epsilon_max,
                             double epsilon_max, long training_frames, double previous_hit_rate, double hit_rate) {
  std::printf("  soft cache: ε_min %.4g → %.4g, ε_max %.4g → %.4g (recalibrated on held-out training frames)\n",
              previous_epsilon_min, epsilon_min, previous_epsilon_max, epsilon_max);
  std::printf("  hit rate on these %ld training frames: %.1f%% with the version retrained from, %.1f%% with the "
              "new one\n",
              training_frames, 100 * previous_hit_rate, 100 * hit_rate);
}

}  // namespace animspace::cli
