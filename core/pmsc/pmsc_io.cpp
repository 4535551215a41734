#include "core/pmsc/pmsc_io.h"

#include <charconv>
#include <cmath>
#include <set>
#include <system_error>

#include "core/animspace/animspace_io.h"
#include "core/common/format.h"
#include "core/container/sections.h"

namespace animspace::pmsc {
namespace {

using container::Float64Matrix;

Error with_source(const Error& e, const std::string& source) {
  return make_error(e.code, source + ": " + e.message);
}

// The persisted TrainingOptions fields, one table for writing and reading so the two cannot
// drift apart. `positions` is deliberately absent (see store_training_options).
// `optional`: added after models were first written (issue #22); a model without it was trained
// before the option existed and is retrained with its default.
struct IntOption {
  const char* name;
  int TrainingOptions::*member;
  bool optional = false;
};
struct DoubleOption {
  const char* name;
  double TrainingOptions::*member;
  bool optional = false;
};
constexpr IntOption kIntOptions[] = {
    {"channels", &TrainingOptions::channel_count},  // metadata pmsc.options.channels, as written since release 0.1
    {"basis_size", &TrainingOptions::basis_size},
    {"max_basis", &TrainingOptions::max_basis},
    {"block_size", &TrainingOptions::block_size},
    {"max_key_points", &TrainingOptions::max_key_points},
    {"grid_cells", &TrainingOptions::grid_cells},
    {"calibration_folds", &TrainingOptions::calibration_folds},
    {"region_count", &TrainingOptions::region_count},
    {"calibration_block_frames", &TrainingOptions::calibration_block_frames, true},
    {"bone_count", &TrainingOptions::bone_count, true},                    // issue #51
    {"residual_components", &TrainingOptions::residual_components, true},  // issue #51
    {"cross_fitted_calibration", &TrainingOptions::cross_fitted_calibration, true},  // issue #52
};
constexpr DoubleOption kDoubleOptions[] = {
    {"error_bound", &TrainingOptions::error_bound},
    {"max_basis_fraction", &TrainingOptions::max_basis_fraction},
    {"error_tolerance", &TrainingOptions::error_tolerance},
    {"blend_zone_ratio", &TrainingOptions::blend_zone_ratio},
    {"false_hit_rate", &TrainingOptions::false_hit_rate, true},
    {"check_point_fraction", &TrainingOptions::check_point_fraction, true},  // issue #35
    {"held_out_basis_slack", &TrainingOptions::held_out_basis_slack, true},  // issue #38
    {"held_out_key_slack", &TrainingOptions::held_out_key_slack, true},      // issue #52
};
constexpr const char* kFiducialPoints = "fiducial_points";
constexpr const char* kRemoveRigidMotion = "remove_rigid_motion";
constexpr const char* kRelativeTolerance = "relative_tolerance";  // absent before issue #38: 0
constexpr const char* kRelativeToleranceKey = "pmsc.relative_tolerance";
// Issue #51: absent in models written before it, which are all linear.
constexpr const char* kSubspaceKind = "subspace_kind";
constexpr const char* kSubspaceKindKey = "pmsc.subspace_kind";
constexpr const char* kBoneCountKey = "pmsc.bone_count";
constexpr const char* kResidualComponentsKey = "pmsc.residual_components";

Result<SubspaceKind> parse_subspace_kind(const std::string& source, const std::string& key, const std::string& text) {
  for (SubspaceKind kind : {SubspaceKind::kLinear, SubspaceKind::kArticulated}) {
    if (text == subspace_kind_name(kind)) return kind;
  }
  return make_error(ErrorCode::kInvalidArgument,
                    source + ": metadata '" + key + "' should be linear or articulated, got '" + text + "'");
}

std::string option_key(const char* name) { return std::string(kOptionsPrefix) + name; }

// Whole-string parses: no leading '+' or spaces, no trailing characters.
template <typename T>
bool parse_exactly(const std::string& text, T& value) {
  if (text.empty()) return false;
  const char* end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, value);
  return error == std::errc() && stop == end;
}

Error unparsable(const std::string& source, const std::string& key, const std::string& expected,
                 const std::string& text) {
  return make_error(ErrorCode::kInvalidArgument,
                    source + ": metadata '" + key + "' should be " + expected + ", got '" + text + "'");
}

// The calibration (issue #22, pmsc format 2): how ε was chosen and the held-out samples it came
// from, so that `describe` can state its meaning and an operator can pick another δ without
// retraining. Absent in models of format 1, whose ε was the worst held-out ratio's.
void store_calibration(const PmscModel& m, container::ModelContainer& out) {
  const PmscModel::Calibration& c = m.calibration;
  if (c.samples.size() == 0) return;
  out.metadata()[kFormatVersionKey] = std::to_string(kFormatVersion);
  out.metadata()[kFalseHitRateKey] = format_number(c.false_hit_rate);
  out.metadata()[kErrorRatioKey] = format_number(c.error_ratio);
  out.metadata()[kBlockFramesKey] = std::to_string(c.block_frames);
  out.metadata()[kOverToleranceKey] = std::to_string(c.over_tolerance);
  out.metadata()[kBadSamplesKey] = std::to_string(c.bad_samples);
  const long n = c.samples.size();
  const long R = c.samples.region_key_point_errors.cols();
  Float64Matrix samples(n, 3 + 2 * R);
  for (long i = 0; i < n; ++i) samples(i, 0) = c.samples.fold_family[static_cast<size_t>(i)];
  samples.col(1) = c.samples.key_point_errors;
  samples.col(2) = c.samples.max_errors;
  if (R > 0) {
    samples.middleCols(3, R) = c.samples.region_key_point_errors;
    samples.middleCols(3 + R, R) = c.samples.region_max_errors;
  }
  out.set_matrix(kCalibrationSamplesSection, samples);
  if (c.samples.key_point_max_errors.size() == n) {
    out.set_matrix(kCalibrationKeyMaxErrorsSection, Float64Matrix(c.samples.key_point_max_errors));
  }
  if (c.samples.checked()) {
    const long check_regions = c.samples.region_check_point_errors.cols();
    Float64Matrix check(n, 1 + check_regions);
    check.col(0) = c.samples.check_point_errors;
    if (check_regions > 0) check.rightCols(check_regions) = c.samples.region_check_point_errors;
    out.set_matrix(kCalibrationCheckErrorsSection, check);
  }
  if (!m.region_epsilon.empty()) {
    Float64Matrix region_epsilon(static_cast<long>(m.region_epsilon.size()), 2);
    for (size_t r = 0; r < m.region_epsilon.size(); ++r) {
      region_epsilon.row(static_cast<long>(r)) << m.region_epsilon[r].epsilon_min, m.region_epsilon[r].epsilon_max;
    }
    out.set_matrix(kRegionEpsilonSection, region_epsilon);
  }
}

Status load_calibration(const container::ModelContainer& in, const std::string& source, PmscModel& m) {
  if (!in.has_section(kCalibrationSamplesSection)) return Status::Ok();  // format 1
  auto samples = in.double_matrix(kCalibrationSamplesSection);
  if (!samples) return with_source(samples.error(), source);
  const long R = m.region_count;
  if (samples->cols() != 3 && samples->cols() != 3 + 2 * R) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": section '" + kCalibrationSamplesSection + "' should have 3 or " +
                          std::to_string(3 + 2 * R) + " columns (fold family, e_key, max error, 2 per region), got " +
                          std::to_string(samples->cols()));
  }
  if (!samples->allFinite() || (samples->size() > 0 && samples->minCoeff() < 0)) {
    return make_error(ErrorCode::kInvalidArgument, source + ": section '" +
                                                       kCalibrationSamplesSection +
                                                       "' holds negative, NaN or Inf errors");
  }
  PmscModel::Calibration& c = m.calibration;
  for (long i = 0; i < samples->rows(); ++i) {
    const double family = (*samples)(i, 0);
    if (family != kInterleavedFold && family != kBlockFold && family != kSparseFold) {
      return make_error(ErrorCode::kInvalidArgument, source + ": section '" + kCalibrationSamplesSection + "' row " +
                                                         std::to_string(i) + ": fold family should be 0, 1 or 2, got " +
                                                         format_number(family));
    }
    c.samples.fold_family.push_back(static_cast<char>(family));
  }
  c.samples.key_point_errors = samples->col(1);
  c.samples.max_errors = samples->col(2);
  const long sample_regions = (samples->cols() - 3) / 2;
  c.samples.region_key_point_errors = samples->middleCols(3, sample_regions);
  c.samples.region_max_errors = samples->middleCols(3 + sample_regions, sample_regions);
  for (const char* key : {kFalseHitRateKey, kErrorRatioKey}) {
    double value = 0;
    const std::string text = in.metadata_value(key);
    if (!parse_exactly(text, value) || !std::isfinite(value)) {
      return unparsable(source, key, "a finite decimal number", text);
    }
    (key == kFalseHitRateKey ? c.false_hit_rate : c.error_ratio) = value;
  }
  if (!parse_exactly(in.metadata_value(kBlockFramesKey), c.block_frames)) {
    return unparsable(source, kBlockFramesKey, "a decimal integer", in.metadata_value(kBlockFramesKey));
  }
  if (!parse_exactly(in.metadata_value(kOverToleranceKey), c.over_tolerance)) {
    return unparsable(source, kOverToleranceKey, "a decimal integer", in.metadata_value(kOverToleranceKey));
  }
  // Format 3 (issue #35): the extrapolated bad samples and the check points' errors.
  if (!in.metadata_value(kBadSamplesKey).empty() && !parse_exactly(in.metadata_value(kBadSamplesKey), c.bad_samples)) {
    return unparsable(source, kBadSamplesKey, "a decimal integer", in.metadata_value(kBadSamplesKey));
  }
  if (in.has_section(kCalibrationKeyMaxErrorsSection)) {
    auto key_max = in.double_matrix(kCalibrationKeyMaxErrorsSection);
    if (!key_max) return with_source(key_max.error(), source);
    if (key_max->rows() != samples->rows() || key_max->cols() != 1) {
      return container::section_shape_error(source, kCalibrationKeyMaxErrorsSection,
                                            std::to_string(samples->rows()) + "×1 (one worst key error per sample)",
                                            key_max->rows(), key_max->cols());
    }
    if (!key_max->allFinite() || (key_max->size() > 0 && key_max->minCoeff() < 0)) {
      return make_error(ErrorCode::kInvalidArgument, source + ": section '" + kCalibrationKeyMaxErrorsSection +
                                                         "' holds negative, NaN or Inf errors");
    }
    c.samples.key_point_max_errors = key_max->col(0);
  }
  if (in.has_section(kCalibrationCheckErrorsSection)) {
    auto check = in.double_matrix(kCalibrationCheckErrorsSection);
    if (!check) return with_source(check.error(), source);
    const long check_regions = c.samples.region_key_point_errors.cols();
    if (check->rows() != samples->rows() || check->cols() != 1 + check_regions) {
      return container::section_shape_error(source, kCalibrationCheckErrorsSection,
                                            std::to_string(samples->rows()) + "×" + std::to_string(1 + check_regions) +
                                                " (samples × e_check and one per region)",
                                            check->rows(), check->cols());
    }
    if (!check->allFinite() || (check->size() > 0 && check->minCoeff() < 0)) {
      return make_error(ErrorCode::kInvalidArgument, source + ": section '" + kCalibrationCheckErrorsSection +
                                                         "' holds negative, NaN or Inf errors");
    }
    c.samples.check_point_errors = check->col(0);
    c.samples.region_check_point_errors = check->rightCols(check_regions);
  }
  if (in.has_section(kRegionEpsilonSection)) {
    auto region_epsilon = in.double_matrix(kRegionEpsilonSection, 2);
    if (!region_epsilon) return with_source(region_epsilon.error(), source);
    for (long r = 0; r < region_epsilon->rows(); ++r) {
      m.region_epsilon.push_back({(*region_epsilon)(r, 0), (*region_epsilon)(r, 1)});
    }
  }
  return Status::Ok();  // prepare_projection checks region_epsilon against region_count
}

// Local fail-through's soft memberships (local_fail_through.h) are an optional section: a model
// written before it has hard regions (PmscModel::region_weights left empty).
void store_region_weights(const PmscModel& m, container::ModelContainer& out) {
  if (m.region_weights.size() > 0) out.set_matrix(kRegionWeightsSection, Float64Matrix(m.region_weights));
}

Status load_region_weights(const container::ModelContainer& in, const std::string& source, PmscModel& m) {
  if (m.region_count == 0 || !in.has_section(kRegionWeightsSection)) return Status::Ok();
  auto weights = in.double_matrix(kRegionWeightsSection);
  if (!weights) return weights.error();
  if (weights->rows() != m.point_count || weights->cols() != m.region_count) {
    return container::section_shape_error(source, kRegionWeightsSection,
                                          std::to_string(m.point_count) + "×" + std::to_string(m.region_count) +
                                              " (points × regions)",
                                          weights->rows(), weights->cols());
  }
  m.region_weights = *weights;
  return Status::Ok();
}

}  // namespace

void store(const PmscModel& m, container::ModelContainer& out) {
  out.metadata()["kind"] = m.cross ? "cross_pmsc" : "pmsc";
  out.metadata()["pmsc.channels"] = std::to_string(m.channel_count);
  out.metadata()["pmsc.cross"] = m.cross ? "1" : "0";
  out.metadata()["pmsc.aligned"] = m.aligned ? "1" : "0";
  out.metadata()[kRelativeToleranceKey] = m.relative_tolerance ? "1" : "0";
  out.metadata()[kSubspaceKindKey] = subspace_kind_name(m.subspace_kind);
  out.metadata()[kEstimatorKey] = error_estimator_name(m.estimator);
  if (m.subspace_kind == SubspaceKind::kArticulated) {
    out.metadata()[kBoneCountKey] = std::to_string(m.bone_count);
    out.metadata()[kResidualComponentsKey] = std::to_string(m.residual_components);
  }
  out.metadata()["pmsc.control_point_count"] = std::to_string(m.control_point_count);
  out.metadata()["pmsc.region_count"] = std::to_string(m.region_count);
  out.set_matrix("pmsc.mean", FrameMatrix(m.mean.transpose()));
  out.set_matrix("pmsc.basis", FrameMatrix(m.basis));
  out.set_matrix("pmsc.key_points", container::as_column(m.key_points));
  out.set_matrix("pmsc.key_mean", Float64Matrix(m.key_mean.transpose()));
  out.set_matrix("pmsc.key_basis", Float64Matrix(m.key_basis));
  Float64Matrix epsilon(1, 2);
  epsilon << m.epsilon.epsilon_min, m.epsilon.epsilon_max;
  out.set_matrix("pmsc.epsilon", epsilon);
  if (m.region_count > 0) {
    out.set_matrix("pmsc.point_regions", container::as_column(m.point_regions));
    out.set_matrix("pmsc.key_regions", container::as_column(m.key_regions));
  }
  if (!m.check_points.empty()) {
    out.set_matrix(kCheckPointsSection, container::as_column(m.check_points));
    if (!m.check_regions.empty()) out.set_matrix(kCheckRegionsSection, container::as_column(m.check_regions));
    out.metadata()[kKeyWeightKey] = format_number(m.key_weight);
    Float64Matrix key_only(1, 2);
    key_only << m.key_only_epsilon.epsilon_min, m.key_only_epsilon.epsilon_max;
    out.set_matrix(kKeyOnlyEpsilonSection, key_only);
  }
  store_calibration(m, out);
  store_region_weights(m, out);
}

Result<PmscModel> load(const container::ModelContainer& in, const std::string& source) {
  PmscModel m;
  auto channels = in.metadata_int("pmsc.channels");
  if (!channels) return with_source(channels.error(), source);
  auto control = in.metadata_int("pmsc.control_point_count");
  if (!control) return with_source(control.error(), source);
  auto regions = in.metadata_int("pmsc.region_count");
  if (!regions) return with_source(regions.error(), source);
  m.channel_count = *channels;
  m.control_point_count = *control;
  m.region_count = *regions;
  m.cross = in.metadata_value("pmsc.cross") == "1";
  m.aligned = in.metadata_value("pmsc.aligned") == "1";
  // Absent in models written before issue #38: errors in model units.
  if (in.metadata().contains(kRelativeToleranceKey)) {
    const std::string relative = in.metadata_value(kRelativeToleranceKey);
    if (relative != "0" && relative != "1") {
      return make_error(ErrorCode::kInvalidArgument, source + ": metadata '" + std::string(kRelativeToleranceKey) +
                                                         "' should be 0 or 1, got '" + relative + "'");
    }
    m.relative_tolerance = relative == "1";
  }
  if (in.metadata().contains(kSubspaceKindKey)) {
    auto kind = parse_subspace_kind(source, kSubspaceKindKey, in.metadata_value(kSubspaceKindKey));
    if (!kind) return kind.error();
    m.subspace_kind = *kind;
  }
  if (in.metadata().contains(kEstimatorKey)) {
    const std::string estimator = in.metadata_value(kEstimatorKey);
    if (estimator == error_estimator_name(ErrorEstimator::kWorstPoint)) {
      m.estimator = ErrorEstimator::kWorstPoint;
    } else if (estimator != error_estimator_name(ErrorEstimator::kKeyRms)) {
      return make_error(ErrorCode::kInvalidArgument, source + ": metadata '" + std::string(kEstimatorKey) +
                                                         "' should be key_rms or worst_point, got '" + estimator + "'");
    }
  }
  if (m.subspace_kind == SubspaceKind::kArticulated) {
    auto bones = in.metadata_int(kBoneCountKey);
    if (!bones) return with_source(bones.error(), source);
    auto residuals = in.metadata_int(kResidualComponentsKey);
    if (!residuals) return with_source(residuals.error(), source);
    m.bone_count = *bones;
    m.residual_components = *residuals;  // prepare_projection checks both against the basis
  }
  if (m.channel_count < 1) return make_error(ErrorCode::kInvalidArgument, source + ": pmsc.channels must be ≥ 1");

  auto mean = in.float_matrix("pmsc.mean");
  if (!mean) return mean.error();
  if (mean->rows() != 1 || mean->cols() % m.channel_count != 0) {
    return make_error(ErrorCode::kInvalidArgument, source + ": section 'pmsc.mean' should be 1 × N·" +
                                                       std::to_string(m.channel_count) + ", got " +
                                                       std::to_string(mean->rows()) + "×" + std::to_string(mean->cols()));
  }
  m.mean = mean->row(0).transpose();
  m.point_count = static_cast<int>(mean->cols() / m.channel_count);
  auto basis = in.float_matrix("pmsc.basis");
  if (!basis) return basis.error();
  m.basis = *basis;
  auto keys = in.int_matrix("pmsc.key_points", 1);
  if (!keys) return keys.error();
  m.key_points.assign(keys->data(), keys->data() + keys->size());
  auto key_mean = in.double_matrix("pmsc.key_mean");
  if (!key_mean) return key_mean.error();
  m.key_mean = Eigen::Map<const Eigen::VectorXd>(key_mean->data(), key_mean->size());
  auto key_basis = in.double_matrix("pmsc.key_basis");
  if (!key_basis) return key_basis.error();
  m.key_basis = *key_basis;
  auto epsilon = in.double_matrix("pmsc.epsilon", 2);
  if (!epsilon) return epsilon.error();
  if (epsilon->rows() != 1) {
    return make_error(ErrorCode::kInvalidArgument, source + ": section 'pmsc.epsilon' should be 1×2");
  }
  m.epsilon = {(*epsilon)(0, 0), (*epsilon)(0, 1)};
  if (m.region_count > 0) {
    auto point_regions = in.int_matrix("pmsc.point_regions", 1);
    if (!point_regions) return point_regions.error();
    auto key_regions = in.int_matrix("pmsc.key_regions", 1);
    if (!key_regions) return key_regions.error();
    m.point_regions.assign(point_regions->data(), point_regions->data() + point_regions->size());
    m.key_regions.assign(key_regions->data(), key_regions->data() + key_regions->size());
  }
  if (in.has_section(kCheckPointsSection)) {  // format 3 (issue #35)
    auto check_points = in.int_matrix(kCheckPointsSection, 1);
    if (!check_points) return with_source(check_points.error(), source);
    m.check_points.assign(check_points->data(), check_points->data() + check_points->size());
    if (in.has_section(kCheckRegionsSection)) {
      auto check_regions = in.int_matrix(kCheckRegionsSection, 1);
      if (!check_regions) return with_source(check_regions.error(), source);
      m.check_regions.assign(check_regions->data(), check_regions->data() + check_regions->size());
    }
    const std::string weight = in.metadata_value(kKeyWeightKey);
    if (!parse_exactly(weight, m.key_weight) || !std::isfinite(m.key_weight)) {
      return unparsable(source, kKeyWeightKey, "a finite decimal number", weight);
    }
    auto key_only = in.double_matrix(kKeyOnlyEpsilonSection, 2);
    if (!key_only) return with_source(key_only.error(), source);
    if (key_only->rows() != 1) {
      return container::section_shape_error(source, kKeyOnlyEpsilonSection, "1×2", key_only->rows(), key_only->cols());
    }
    m.key_only_epsilon = {(*key_only)(0, 0), (*key_only)(0, 1)};
  }
  if (auto calibration = load_calibration(in, source, m); !calibration.ok()) return calibration.error();
  if (m.estimator == ErrorEstimator::kWorstPoint && m.calibration.samples.size() > 0 &&
      m.calibration.samples.key_point_max_errors.size() != m.calibration.samples.size()) {
    return make_error(ErrorCode::kInvalidArgument, source + ": metadata '" + std::string(kEstimatorKey) +
                                                       "' is worst_point but section '" +
                                                       kCalibrationKeyMaxErrorsSection + "' is absent");
  }
  ANIMSPACE_RETURN_IF_ERROR(load_region_weights(in, source, m));
  if (auto prepared = prepare_projection(m); !prepared.ok()) return with_source(prepared.error(), source);
  return m;
}

container::ModelContainer make_container(const TriangleMesh& mesh, FrameMatrix training_frames,
                                         const FrameMatrix* control_frames, const PmscModel& model,
                                         const TrainingReport& report, const std::string& description) {
  container::ModelContainer out;
  store(model, out);
  out.metadata()["description"] = description;
  store_training_report(report, out);
  out.set_points("mesh.rest_points", mesh.V);
  if (mesh.F.rows() > 0) out.set_faces("mesh.faces", mesh.F);
  out.set_matrix("sequence.frames", std::move(training_frames));
  if (control_frames) out.set_matrix("sequence.control_frames", *control_frames);
  return out;
}

void store_training_report(const TrainingReport& report, container::ModelContainer& out) {
  out.metadata()["pmsc.training_frames"] = std::to_string(report.frames);
  out.metadata()["pmsc.max_training_error"] = format_number(report.max_training_error);
  out.metadata()["pmsc.condition_number"] = format_number(report.condition_number);
  out.metadata()["pmsc.error_ratio"] = format_number(report.error_ratio);
  out.metadata()["pmsc.training_seconds"] = format_number(report.seconds);
}

void store_training_options(const TrainingOptions& options, container::ModelContainer& out) {
  auto& metadata = out.metadata();
  for (const IntOption& option : kIntOptions) {
    metadata[option_key(option.name)] = std::to_string(options.*option.member);
  }
  for (const DoubleOption& option : kDoubleOptions) {
    metadata[option_key(option.name)] = format_number(options.*option.member);
  }
  std::string fiducials;
  for (size_t k = 0; k < options.fiducial_points.size(); ++k) {
    if (k > 0) fiducials += ',';
    fiducials += std::to_string(options.fiducial_points[k]);
  }
  metadata[option_key(kFiducialPoints)] = fiducials;
  metadata[option_key(kRemoveRigidMotion)] = options.remove_rigid_motion ? "1" : "0";
  metadata[option_key(kRelativeTolerance)] = options.relative_tolerance ? "1" : "0";
  metadata[option_key(kSubspaceKind)] = subspace_kind_name(options.subspace_kind);
}

Result<TrainingOptions> load_training_options(const container::ModelContainer& in, const std::string& source) {
  const auto& metadata = in.metadata();
  const std::string prefix = kOptionsPrefix;
  const auto first = metadata.lower_bound(prefix);
  if (first == metadata.end() || first->first.compare(0, prefix.size(), prefix) != 0) {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": model was trained before training options were stored (no pmsc.options.*); "
                               "retrain it from the CLI");
  }
  std::set<std::string> known;
  auto value_of = [&](const char* name) -> Result<std::string> {
    const std::string key = option_key(name);
    known.insert(key);
    const auto found = metadata.find(key);
    if (found == metadata.end()) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata '" + key + "' is missing (the other training options are stored)");
    }
    return found->second;
  };

  TrainingOptions options;
  const auto absent = [&](const char* name, bool optional) {
    known.insert(option_key(name));
    return optional && !metadata.contains(option_key(name));
  };
  for (const IntOption& option : kIntOptions) {
    if (absent(option.name, option.optional)) continue;
    auto text = value_of(option.name);
    if (!text) return text.error();
    if (!parse_exactly(*text, options.*option.member)) {
      return unparsable(source, option_key(option.name), "a decimal integer", *text);
    }
  }
  for (const DoubleOption& option : kDoubleOptions) {
    if (absent(option.name, option.optional)) continue;
    auto text = value_of(option.name);
    if (!text) return text.error();
    if (!parse_exactly(*text, options.*option.member) || !std::isfinite(options.*option.member)) {
      return unparsable(source, option_key(option.name), "a finite decimal number", *text);
    }
  }
  auto fiducials = value_of(kFiducialPoints);
  if (!fiducials) return fiducials.error();
  for (size_t begin = 0; begin < fiducials->size();) {
    size_t end = fiducials->find(',', begin);
    if (end == std::string::npos) end = fiducials->size();
    int index = 0;
    if (!parse_exactly(fiducials->substr(begin, end - begin), index)) {
      return unparsable(source, option_key(kFiducialPoints), "comma-separated point indices", *fiducials);
    }
    options.fiducial_points.push_back(index);
    // A trailing comma would leave an empty last index: refuse it rather than drop it.
    if (end + 1 == fiducials->size()) {
      return unparsable(source, option_key(kFiducialPoints), "comma-separated point indices", *fiducials);
    }
    begin = end + 1;
  }
  auto rigid = value_of(kRemoveRigidMotion);
  if (!rigid) return rigid.error();
  if (*rigid != "0" && *rigid != "1") return unparsable(source, option_key(kRemoveRigidMotion), "0 or 1", *rigid);
  options.remove_rigid_motion = *rigid == "1";
  if (!absent(kRelativeTolerance, true)) {
    auto relative = value_of(kRelativeTolerance);
    if (!relative) return relative.error();
    if (*relative != "0" && *relative != "1") {
      return unparsable(source, option_key(kRelativeTolerance), "0 or 1", *relative);
    }
    options.relative_tolerance = *relative == "1";
  }
  if (!absent(kSubspaceKind, true)) {
    auto kind = parse_subspace_kind(source, option_key(kSubspaceKind), metadata.at(option_key(kSubspaceKind)));
    if (!kind) return kind.error();
    options.subspace_kind = *kind;
  }

  for (auto it = first; it != metadata.end() && it->first.compare(0, prefix.size(), prefix) == 0; ++it) {
    if (!known.contains(it->first)) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata '" + it->first +
                            "' is not a training option this version knows; retraining without it would not "
                            "reproduce the model's training");
    }
  }
  return options;
}

bool has_posing_engine(const container::ModelContainer& in) {
  return in.has_section(container::sections::kSkeletonParents) &&
         in.has_section(animation_space::sections::kInfluenceOffsets);
}

Status attach_posing_engine(const animation_space::AnimationSpaceModel& engine, container::ModelContainer& out) {
  const std::string kind = out.metadata_value("kind");
  if (kind != container::kind_name(container::ModelKind::kPmsc) || out.metadata_value("pmsc.cross") == "1") {
    const std::string why = kind == "cross_pmsc" ? " (cross-PMSC outputs have no full calculation)" : "";
    return make_error(ErrorCode::kFailedPrecondition,
                      "a posing engine computes the full values of a pmsc model's own points; this container has "
                      "kind '" + kind + "'" + why);
  }
  auto channels = out.metadata_int("pmsc.channels");
  if (!channels) return channels.error();
  if (*channels != 3) {
    return make_error(ErrorCode::kInvalidArgument, "a posing engine makes positions, so pmsc.channels must be 3, got " +
                                                       std::to_string(*channels));
  }
  if (const Status valid = animation_space::validate(engine); !valid.ok()) {
    return make_error(ErrorCode::kInvalidArgument, "posing engine: " + valid.error().message);
  }
  auto rest = out.points(container::sections::kRestPoints);
  if (!rest) return rest.error();
  if (engine.vertex_count() != rest->rows()) {
    return make_error(ErrorCode::kInvalidArgument,
                      "posing engine has " + std::to_string(engine.vertex_count()) + " vertices, expected the PMSC "
                      "model's N = " + std::to_string(rest->rows()) + " points");
  }
  if (out.has_section(container::sections::kSequenceBoneTransforms)) {
    auto bones = out.double_matrix(container::sections::kSequenceBoneTransforms);
    if (!bones) return bones.error();
    if (bones->cols() != 16L * engine.bone_count()) {
      return make_error(ErrorCode::kInvalidArgument,
                        "section 'sequence.bone_transforms' has " + std::to_string(bones->cols()) +
                            " columns, expected 16·B = " + std::to_string(16 * engine.bone_count()) +
                            " for the posing engine's bones");
    }
  }
  // A previous engine's tangents would outlive an engine without them; the container cannot
  // remove a section, so rebuild it without the stale one.
  const std::string stale_tangents = animation_space::sections::kTangents;
  if (!engine.has_tangents() && out.has_section(stale_tangents)) {
    container::ModelContainer rebuilt;
    rebuilt.metadata() = out.metadata();
    copy_sections(out, [&](const std::string& name) { return name != stale_tangents; }, rebuilt);
    out = std::move(rebuilt);
  }
  animation_space::store_skeleton(engine.skeleton, out);
  animation_space::store_influences(engine, animation_space::sections::kModelPrefix, out);
  if (!out.has_section(container::sections::kFaces) && engine.faces.rows() > 0) {
    out.set_faces(container::sections::kFaces, engine.faces);
  }
  return Status::Ok();
}

void copy_sections(const container::ModelContainer& in, const std::function<bool(const std::string&)>& keep,
                   container::ModelContainer& out) {
  for (const auto& [name, section] : in.sections()) {
    if (keep(name)) out.copy_section(in, name);
  }
}

}  // namespace animspace::pmsc
