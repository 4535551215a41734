#include "core/subdivision/subdivide_model.h"

#include <algorithm>
#include <cassert>
#include <set>

#include "core/animspace/animspace_io.h"
#include "core/container/sections.h"

namespace animspace::subdivision {

namespace as = animation_space;

namespace {

// Gathers, for one refined vertex, Σ_c A_ic x_c per bone over the influences of the control
// vertices in row i of A, remembering which bones were touched (in first-touch order).
class BoneAccumulator {
 public:
  explicit BoneAccumulator(int bone_count) : touched_(static_cast<size_t>(bone_count), 0) {
    for (auto* sums : {&p_, &s_, &t_}) sums->assign(static_cast<size_t>(bone_count), Eigen::Vector4d::Zero());
  }

  enum Target { kPosition, kTangentS, kTangentT };

  void add_row(const SparseRows& A, int row, const as::InfluenceSets& influences,
               const as::InfluenceVectors& vectors, Target target) {
    auto& sums = target == kPosition ? p_ : target == kTangentS ? s_ : t_;
    for (SparseRows::InnerIterator it(A, row); it; ++it) {
      const int32_t c = it.col();
      for (int k = influences.begin(c); k < influences.end(c); ++k) {
        const int32_t j = influences.bones[static_cast<size_t>(k)];
        touch(j);
        sums[static_cast<size_t>(j)] += it.value() * vectors.col(k);
      }
    }
  }
  // Bones touched but not carried by the vectors (a weights-only row): just the bone.
  void add_bones(const SparseRows& A, int row, const as::InfluenceSets& influences) {
    for (SparseRows::InnerIterator it(A, row); it; ++it) {
      const int32_t c = it.col();
      for (int k = influences.begin(c); k < influences.end(c); ++k) touch(influences.bones[static_cast<size_t>(k)]);
    }
  }

  // The touched bones, ascending; resets them for the next vertex after `emit` saw each.
  template <typename Emit>
  void flush(Emit&& emit) {
    std::sort(bones_.begin(), bones_.end());
    for (const int32_t j : bones_) {
      const auto b = static_cast<size_t>(j);
      emit(j, p_[b], s_[b], t_[b]);
      p_[b].setZero();
      s_[b].setZero();
      t_[b].setZero();
      touched_[b] = 0;
    }
    bones_.clear();
  }

 private:
  void touch(int32_t j) {
    if (touched_[static_cast<size_t>(j)] == 0) {
      touched_[static_cast<size_t>(j)] = 1;
      bones_.push_back(j);
    }
  }

  std::vector<char> touched_;
  std::vector<int32_t> bones_;
  std::vector<Eigen::Vector4d> p_, s_, t_;
};

as::InfluenceVectors to_columns(const std::vector<Eigen::Vector4d>& columns) {
  as::InfluenceVectors out(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) out.col(static_cast<Eigen::Index>(k)) = columns[k];
  return out;
}

template <typename Matrix>
Matrix apply_rows_impl(const SparseRows& S, const Matrix& values) {
  assert(S.cols() == values.rows());
  const Eigen::MatrixXd refined = S * values.template cast<double>();
  return refined.cast<typename Matrix::Scalar>();
}

}  // namespace

FrameMatrix apply_rows(const SparseRows& S, const FrameMatrix& values) { return apply_rows_impl(S, values); }
PointMatrix apply_rows(const SparseRows& S, const PointMatrix& points) { return apply_rows_impl(S, points); }

as::AnimationSpaceModel apply(const as::AnimationSpaceModel& model, const SubdivisionMatrices& matrices) {
  assert(matrices.S.cols() == model.vertex_count());
  const bool tangents = matrices.tangent_u.rows() > 0;
  as::AnimationSpaceModel out;
  out.skeleton = model.skeleton;
  out.faces = triangulate(matrices.refined);
  const auto vertices = static_cast<int>(matrices.S.rows());
  out.influences.offsets.reserve(static_cast<size_t>(vertices) + 1);

  // Per refined vertex: P' = P S on the bones of its rows of S, U and W. A bone only the tangents
  // reach gets p_j = 0 (it adds nothing to the position, and keeps the tangents on the vertex's
  // own influence set). The tangents need no rows of P's tangents: s = P U, t = P W.
  std::vector<Eigen::Vector4d> p, s, t;
  BoneAccumulator sums(model.bone_count());
  for (int i = 0; i < vertices; ++i) {
    sums.add_row(matrices.S, i, model.influences, model.positions, BoneAccumulator::kPosition);
    if (tangents) {
      sums.add_row(matrices.tangent_u, i, model.influences, model.positions, BoneAccumulator::kTangentS);
      sums.add_row(matrices.tangent_v, i, model.influences, model.positions, BoneAccumulator::kTangentT);
    }
    sums.flush([&](int32_t j, const Eigen::Vector4d& pj, const Eigen::Vector4d& sj, const Eigen::Vector4d& tj) {
      out.influences.bones.push_back(j);
      p.push_back(pj);
      if (tangents) {
        s.push_back(sj);
        t.push_back(tj);
      }
    });
    out.influences.offsets.push_back(static_cast<int32_t>(out.influences.bones.size()));
  }
  out.positions = to_columns(p);
  if (tangents) {
    out.tangent_s = to_columns(s);
    out.tangent_t = to_columns(t);
  }
  return out;
}

Result<as::AnimationSpaceModel> subdivide(const as::AnimationSpaceModel& model, const SubdivisionOptions& options) {
  if (auto valid = as::validate(model); !valid.ok()) return valid.error();
  auto matrices = subdivision_matrices(triangle_topology(model.faces, model.vertex_count()), options);
  if (!matrices) return matrices.error();
  return apply(model, *matrices);
}

as::LinearBlendModel subdivide_linear_blend(const as::LinearBlendModel& model, const SubdivisionMatrices& matrices) {
  assert(matrices.S.cols() == model.vertex_count());
  as::LinearBlendModel out;
  out.skeleton = model.skeleton;
  out.faces = triangulate(matrices.refined);
  const Eigen::MatrixX3d rest = model.rest_points.transpose();
  out.rest_points = (matrices.S * rest).transpose();
  // The weights as 4-vectors (w, 0, 0, 0) through the same accumulator.
  as::InfluenceVectors weights = as::InfluenceVectors::Zero(4, model.weights.size());
  weights.row(0) = model.weights.transpose();
  std::vector<double> w;
  BoneAccumulator sums(model.skeleton.bone_count());
  const auto vertices = static_cast<int>(matrices.S.rows());
  for (int i = 0; i < vertices; ++i) {
    sums.add_row(matrices.S, i, model.influences, weights, BoneAccumulator::kPosition);
    sums.flush([&](int32_t j, const Eigen::Vector4d& wj, const Eigen::Vector4d&, const Eigen::Vector4d&) {
      out.influences.bones.push_back(j);
      w.push_back(wj(0));
    });
    out.influences.offsets.push_back(static_cast<int32_t>(out.influences.bones.size()));
  }
  out.weights = Eigen::Map<const Eigen::VectorXd>(w.data(), static_cast<Eigen::Index>(w.size()));
  return out;
}

Result<container::ModelContainer> subdivide_container(const container::ModelContainer& in, const std::string& source,
                                                      const SubdivisionOptions& options, SubdivisionReport* report) {
  // 1. The input must be an animation-space model.
  const std::string kind = in.metadata_value("kind");
  if (kind != container::kind_name(container::ModelKind::kAnimationSpace)) {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": metadata kind: expected '" +
                          container::kind_name(container::ModelKind::kAnimationSpace) + "', got '" + kind +
                          "' (subdivide works on the output of fit or import-rig)");
  }
  auto model = as::load(in, source);
  if (!model) return model.error();

  // 2. S, U, W from its triangles, and the subdivided model.
  auto matrices = subdivision_matrices(triangle_topology(model->faces, model->vertex_count()), options);
  if (!matrices) return make_error(matrices.error().code, source + ": " + matrices.error().message);
  const as::AnimationSpaceModel refined = apply(*model, *matrices);
  container::ModelContainer out;
  as::store(refined, out);

  // 3. Metrics: skeleton-only, and the bounding sphere holds for convex combinations.
  SubdivisionReport r;
  const bool convex = std::all_of(matrices->S.valuePtr(), matrices->S.valuePtr() + matrices->S.nonZeros(),
                                  [](double w) { return w >= 0; });
  auto metrics = as::load_metrics(in, model->bone_count(), source);
  if (!metrics && metrics.error().code != ErrorCode::kNotFound) return metrics.error();
  if (metrics && convex) {
    as::store_metrics(*metrics, out);
    r.metrics_kept = true;
  }

  // 4. The training poses as they are, the training frames refined.
  namespace cs = container::sections;
  if (in.has_section(cs::kSequenceBoneTransforms)) {
    auto poses = in.double_matrix(cs::kSequenceBoneTransforms, 16 * model->bone_count());
    if (!poses) return poses.error();
    out.set_matrix(cs::kSequenceBoneTransforms, *poses);
  }
  if (in.has_section(cs::kSequenceFrames)) {
    auto frames = in.float_matrix(cs::kSequenceFrames, 3 * model->vertex_count());
    if (!frames) return frames.error();
    FrameMatrix refined_frames(frames->rows(), 3 * refined.vertex_count());
    for (Eigen::Index f = 0; f < frames->rows(); ++f) {
      const Eigen::Map<const PointMatrix> points(frames->row(f).data(), model->vertex_count(), 3);
      const PointMatrix subdivided = apply_rows(matrices->S, PointMatrix(points));
      refined_frames.row(f) = Eigen::Map<const Eigen::RowVectorXf>(subdivided.data(), subdivided.size());
    }
    out.set_matrix(cs::kSequenceFrames, refined_frames);
    r.frames_subdivided = true;
  }

  // 5. Metadata: the input's, minus what described the dropped levels, plus what was done.
  for (const auto& [key, value] : in.metadata()) {
    const bool about_levels = key == "lod_levels" || key.rfind("lod.", 0) == 0;
    if (!about_levels && !out.metadata().contains(key)) out.metadata()[key] = value;
  }
  const std::string what = std::to_string(options.levels) + (options.levels == 1 ? " step" : " steps") + " of " +
                           scheme_name(matrices->scheme) + " subdivision in animation space";
  const std::string description = in.metadata_value("description");
  out.metadata()["description"] = description.empty() ? "Model " + source + ", " + what : description + "; " + what;
  out.metadata()["generator"] = "animspace subdivide";
  out.metadata()["subdivision.scheme"] = scheme_name(matrices->scheme);
  out.metadata()["subdivision.levels"] = std::to_string(options.levels);
  out.metadata()["subdivision.control_vertices"] = std::to_string(model->vertex_count());

  r.scheme = matrices->scheme;
  r.levels = options.levels;
  r.control_vertices = model->vertex_count();
  r.control_influences = model->influences.influence_count();
  r.vertices = refined.vertex_count();
  r.faces = refined.faces.rows();
  r.influences = refined.influences.influence_count();
  const std::vector<std::string> written = out.section_names();
  const std::set<std::string> kept(written.begin(), written.end());
  for (const std::string& name : in.section_names()) {
    if (!kept.contains(name)) r.dropped_sections.push_back(name);
  }
  if (report != nullptr) *report = std::move(r);
  return out;
}

}  // namespace animspace::subdivision
