#include "core/pmsc/pmsc_io.h"


namespace animspace::pmsc {
namespace {

using container::Float64Matrix;

Error with_source(const Error& e, const std::string& source) {
  return make_error(e.code, source + ": " + e.message);
}

}  // namespace

void store(const PmscModel& m, container::ModelContainer& out) {
  out.metadata()["kind"] = m.cross ? "cross_pmsc" : "pmsc";
  out.metadata()["pmsc.channels"] = std::to_string(m.channels);
  out.metadata()["pmsc.cross"] = m.cross ? "1" : "0";
  out.metadata()["pmsc.aligned"] = m.aligned ? "1" : "0";
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
}

Result<PmscModel> load(const container::ModelContainer& in, const std::string& source) {
  PmscModel m;
  auto channels = in.metadata_int("pmsc.channels");
  if (!channels) return with_source(channels.error(), source);
  auto control = in.metadata_int("pmsc.control_point_count");
  if (!control) return with_source(control.error(), source);
  auto regions = in.metadata_int("pmsc.region_count");
  if (!regions) return with_source(regions.error(), source);
  m.channels = *channels;
  m.control_point_count = *control;
  m.region_count = *regions;
  m.cross = in.metadata_value("pmsc.cross") == "1";
  m.aligned = in.metadata_value("pmsc.aligned") == "1";
  if (m.channels < 1) return make_error(ErrorCode::kInvalidArgument, source + ": pmsc.channels must be ≥ 1");

  auto mean = in.float_matrix("pmsc.mean");
  if (!mean) return mean.error();
  if (mean->rows() != 1 || mean->cols() % m.channels != 0) {
    return make_error(ErrorCode::kInvalidArgument, source + ": section 'pmsc.mean' should be 1 × N·" +
                                                       std::to_string(m.channels) + ", got " +
                                                       std::to_string(mean->rows()) + "×" + std::to_string(mean->cols()));
  }
  m.mean = mean->row(0).transpose();
  m.point_count = static_cast<int>(mean->cols() / m.channels);
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
  if (auto prepared = prepare_projection(m); !prepared.ok()) return with_source(prepared.error(), source);
  return m;
}

container::ModelContainer make_container(const TriangleMesh& mesh, const FrameMatrix& training_frames,
                                         const FrameMatrix* control_frames, const PmscModel& model,
                                         const TrainingReport& report, const std::string& description) {
  container::ModelContainer out;
  store(model, out);
  out.metadata()["description"] = description;
  out.metadata()["pmsc.training_frames"] = std::to_string(report.frames);
  out.metadata()["pmsc.max_training_error"] = std::to_string(report.max_training_error);
  out.metadata()["pmsc.condition_number"] = std::to_string(report.condition_number);
  out.metadata()["pmsc.error_ratio"] = std::to_string(report.error_ratio);
  out.metadata()["pmsc.training_seconds"] = std::to_string(report.seconds);
  out.set_points("mesh.rest_points", mesh.V);
  if (mesh.F.rows() > 0) out.set_faces("mesh.faces", mesh.F);
  out.set_matrix("sequence.frames", training_frames);
  if (control_frames) out.set_matrix("sequence.control_frames", *control_frames);
  return out;
}

}  // namespace animspace::pmsc
