#include "core/atlas/atlas.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>

#include <Eigen/Eigenvalues>

#include "core/animspace/animspace_io.h"
#include "core/common/parallel.h"

namespace animspace::atlas {

namespace as = animation_space;

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

Status check_inputs(const as::AnimationSpaceModel& model, const as::AnimationSpaceMetrics& metrics) {
  if (auto valid = as::validate(model); !valid.ok()) return valid;
  if (metrics.P.rows() != 4 * model.bone_count() || metrics.P.cols() != 4 * model.bone_count()) {
    return make_error(ErrorCode::kInvalidArgument, "atlas: P is " + std::to_string(metrics.P.rows()) + " × " +
                                                       std::to_string(metrics.P.cols()) + ", expected " +
                                                       std::to_string(4 * model.bone_count()) + " square (4b)");
  }
  return Status();
}

// W = Λ^½ Vᵀ over P's non-null eigenvectors: (W s)·(W t) = sᵀPt, in as few dimensions as P's
// rank (the rest pose's P has rank ≤ 4, a sampled one ≤ 4b).
Result<Eigen::MatrixXd> normalising_rows(const Eigen::MatrixXd& P) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(0.5 * (P + P.transpose()));
  if (eigen.info() != Eigen::Success) return make_error(ErrorCode::kInvalidArgument, "atlas: P has no eigendecomposition");
  const double largest = eigen.eigenvalues().cwiseAbs().maxCoeff();
  if (eigen.eigenvalues().minCoeff() < -1e-9 * largest) {
    return make_error(ErrorCode::kInvalidArgument, "atlas: P is not positive semi-definite");
  }
  std::vector<Eigen::Index> kept;
  for (Eigen::Index i = 0; i < eigen.eigenvalues().size(); ++i) {
    if (eigen.eigenvalues()(i) > 1e-12 * largest) kept.push_back(i);
  }
  Eigen::MatrixXd W(static_cast<Eigen::Index>(kept.size()), P.rows());
  for (size_t r = 0; r < kept.size(); ++r) {
    W.row(static_cast<Eigen::Index>(r)) =
        std::sqrt(eigen.eigenvalues()(kept[r])) * eigen.eigenvectors().col(kept[r]).transpose();
  }
  return W;
}

// W p_i for every vertex (r × V).
Eigen::MatrixXd normalised_vertices(const as::AnimationSpaceModel& model, const Eigen::MatrixXd& W) {
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(W.rows(), model.vertex_count());
  for (int v = 0; v < model.vertex_count(); ++v) {
    for (int k = model.influences.begin(v); k < model.influences.end(v); ++k) {
      const int j = model.influences.bones[static_cast<size_t>(k)];
      out.col(v).noalias() += W.middleCols(4 * j, 4) * model.positions.col(k);
    }
  }
  return out;
}

NormalisedFaces normalised_faces(const FaceMatrix& faces, const Eigen::MatrixXd& vertices) {
  NormalisedFaces nf;
  nf.edge1.resize(vertices.rows(), faces.rows());
  nf.edge2.resize(vertices.rows(), faces.rows());
  nf.centroid.resize(vertices.rows(), faces.rows());
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const auto p0 = vertices.col(faces(f, 0)), p1 = vertices.col(faces(f, 1)), p2 = vertices.col(faces(f, 2));
    nf.edge1.col(f) = p1 - p0;
    nf.edge2.col(f) = p2 - p0;
    nf.centroid.col(f) = (p0 + p1 + p2) / 3;
  }
  return nf;
}

FaceMetrics grams(const NormalisedFaces& nf) {
  FaceMetrics g(nf.edge1.cols(), 3);
  for (Eigen::Index f = 0; f < g.rows(); ++f) {
    g.row(f) << nf.edge1.col(f).squaredNorm(), nf.edge1.col(f).dot(nf.edge2.col(f)), nf.edge2.col(f).squaredNorm();
  }
  return g;
}

}  // namespace

int default_chart_count(const as::AnimationSpaceModel& model) { return std::max(4, 2 * (model.bone_count() - 1)); }

Result<as::AnimationSpaceMetrics> rest_pose_metrics(const as::Skeleton& skeleton) {
  return as::metrics_from_poses(skeleton, {as::rest_pose(skeleton)});
}

Result<FaceMetrics> face_metrics(const as::AnimationSpaceModel& model, const as::AnimationSpaceMetrics& metrics) {
  if (auto ok = check_inputs(model, metrics); !ok.ok()) return ok.error();
  auto W = normalising_rows(metrics.P);
  if (!W) return W.error();
  return grams(normalised_faces(model.faces, normalised_vertices(model, *W)));
}

namespace {

struct LocalChart {
  std::vector<int32_t> members;  // global face ids
  FaceMatrix faces;              // over local vertices
  FaceMetrics metrics;
  int vertex_count = 0;
};

LocalChart local_chart(const FaceMatrix& faces, const FaceMetrics& metrics, std::vector<int32_t> members) {
  LocalChart lc;
  lc.members = std::move(members);
  std::unordered_map<int32_t, int32_t> index;
  lc.faces.resize(static_cast<Eigen::Index>(lc.members.size()), 3);
  lc.metrics.resize(lc.faces.rows(), 3);
  for (size_t i = 0; i < lc.members.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      lc.faces(static_cast<Eigen::Index>(i), k) =
          index.try_emplace(faces(lc.members[i], k), static_cast<int32_t>(index.size())).first->second;
    }
    lc.metrics.row(static_cast<Eigen::Index>(i)) = metrics.row(lc.members[i]);
  }
  lc.vertex_count = static_cast<int>(index.size());
  return lc;
}

// Flattens the charts (splitting those over the stretch bound when `normalised` is given), then
// balances and packs them.
Result<AtlasReport> flatten_split_pack(const FaceMatrix& faces, const FaceMetrics& metrics,
                                       std::vector<int32_t> chart_of_face, const AtlasOptions& options,
                                       const NormalisedFaces* normalised) {
  if (chart_of_face.size() != static_cast<size_t>(faces.rows()) || metrics.rows() != faces.rows() || faces.rows() == 0) {
    return make_error(ErrorCode::kInvalidArgument, "atlas: expected one chart and one metric per face");
  }
  for (size_t f = 0; f < chart_of_face.size(); ++f) {
    if (chart_of_face[f] < 0) return make_error(ErrorCode::kInvalidArgument, "atlas: face " + std::to_string(f) + " has no chart");
  }
  int32_t charts = 1 + *std::max_element(chart_of_face.begin(), chart_of_face.end());
  AtlasReport report;
  auto start = std::chrono::steady_clock::now();
  std::vector<LocalChart> local;
  std::vector<std::optional<ChartMap>> maps;
  std::vector<std::string> failures;
  std::vector<int32_t> todo(static_cast<size_t>(charts));
  for (int32_t c = 0; c < charts; ++c) todo[static_cast<size_t>(c)] = c;
  for (int round = 0;; ++round) {
    // Local meshes of the charts to (re)flatten.
    std::vector<std::vector<int32_t>> members(static_cast<size_t>(charts));
    for (size_t f = 0; f < chart_of_face.size(); ++f) members[static_cast<size_t>(chart_of_face[f])].push_back(static_cast<int32_t>(f));
    local.resize(static_cast<size_t>(charts));
    maps.resize(static_cast<size_t>(charts));
    failures.resize(static_cast<size_t>(charts));
    for (int32_t c : todo) {
      if (members[static_cast<size_t>(c)].empty()) {
        return make_error(ErrorCode::kInvalidArgument, "atlas: chart " + std::to_string(c) + " has no faces (ids must be dense)");
      }
      local[static_cast<size_t>(c)] = local_chart(faces, metrics, std::move(members[static_cast<size_t>(c)]));
    }
    const char* stage = round == 0 ? "flatten charts" : "flatten split charts";
    const auto to_flatten = static_cast<int64_t>(todo.size());
    int64_t flattened = 0;
    std::mutex progress_mutex;  // one report at a time (core/common/progress.h)
    report_progress(options.progress, stage, 0, to_flatten);
    parallel_for_chunks(to_flatten, 1, [&](int64_t begin, int64_t end) {
      for (int64_t i = begin; i < end; ++i) {
        const auto c = static_cast<size_t>(todo[static_cast<size_t>(i)]);
        auto map = flatten_chart(local[c].faces, local[c].vertex_count, local[c].metrics, options.flatten);
        maps[c].reset();
        failures[c].clear();
        if (map) {
          maps[c] = std::move(*map);
        } else {
          failures[c] = map.error().message;
        }
        if (options.progress) {
          std::lock_guard lock(progress_mutex);
          options.progress(stage, ++flattened, to_flatten);
        }
      }
    });
    // §5.3's fallback for a chart that cannot be laid out well is a split (the thesis splits on
    // border self-intersections); here also a chart over the stretch bound.
    std::vector<int32_t> split;
    for (int32_t c : todo) {
      const auto& map = maps[static_cast<size_t>(c)];
      if (!map || (map->l2 > 1 + options.split_stretch &&
                   local[static_cast<size_t>(c)].faces.rows() >= options.min_split_faces)) {
        split.push_back(c);
      }
    }
    todo.clear();
    if (split.empty() || normalised == nullptr || round == options.max_split_rounds) break;
    for (int32_t c : split) {
      for (int32_t id : split_chart(faces, *normalised, chart_of_face, c, charts)) todo.push_back(id);
    }
    ++report.split_rounds;
  }
  for (int32_t c = 0; c < charts; ++c) {
    if (!maps[static_cast<size_t>(c)]) {
      return make_error(ErrorCode::kInternal, "atlas: chart " + std::to_string(c) + ": " + failures[static_cast<size_t>(c)]);
    }
  }
  report.flatten_seconds = seconds_since(start);

  // Balance (Sander 2001 §5): with chart i's UV area normalised to its surface area A_i and its
  // stretch L_i, the atlas's normalised L2² is (Σ A_i L_i² / x_i)(Σ A_i x_i) / (Σ A_i)² when chart
  // i is scaled by √x_i; Cauchy–Schwarz puts the minimum at x_i ∝ L_i.
  start = std::chrono::steady_clock::now();
  std::vector<ChartUv> uv(static_cast<size_t>(charts));
  std::vector<FaceMatrix> local_faces(static_cast<size_t>(charts));
  for (int32_t c = 0; c < charts; ++c) {
    const ChartMap& m = *maps[static_cast<size_t>(c)];
    report.tutte_charts += m.used_tutte ? 1 : 0;
    const double to_surface = std::sqrt(m.surface_area / m.uv_area);
    uv[static_cast<size_t>(c)] = m.uv * (to_surface * std::sqrt(std::max(m.l2, 1.0)));
    local_faces[static_cast<size_t>(c)] = local[static_cast<size_t>(c)].faces;
  }
  report_progress(options.progress, "pack charts", 0, 1);
  auto packed = pack_charts(uv, local_faces, options.pack);
  if (!packed) return packed.error();
  report_progress(options.progress, "pack charts", 1, 1);
  report.pack_seconds = seconds_since(start);
  report.utilisation = packed->utilisation;

  Atlas& atlas = report.atlas;
  atlas.chart_of_face = std::move(chart_of_face);
  atlas.chart_count = charts;
  atlas.uvs.resize(3 * faces.rows(), 2);
  for (int32_t c = 0; c < charts; ++c) {
    const LocalChart& lc = local[static_cast<size_t>(c)];
    for (size_t i = 0; i < lc.members.size(); ++i) {
      for (int k = 0; k < 3; ++k) {
        atlas.uvs.row(3 * lc.members[i] + k) = uv[static_cast<size_t>(c)].row(lc.faces(static_cast<Eigen::Index>(i), k));
      }
    }
  }
  const Stretch s = stretch(metrics, atlas.uvs);
  report.l2 = s.l2;
  report.linf = s.linf;
  return report;
}

}  // namespace

Result<AtlasReport> flatten_and_pack(const FaceMatrix& faces, const FaceMetrics& metrics,
                                     const std::vector<int32_t>& chart_of_face, const AtlasOptions& options) {
  return flatten_split_pack(faces, metrics, chart_of_face, options, nullptr);
}

Result<AtlasReport> build_atlas(const as::AnimationSpaceModel& model, const as::AnimationSpaceMetrics& metrics,
                                const AtlasOptions& options) {
  if (auto ok = check_inputs(model, metrics); !ok.ok()) return ok.error();
  if (model.faces.rows() == 0) return make_error(ErrorCode::kInvalidArgument, "atlas: the model has no faces");
  if (options.chart_count < 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "atlas: chart count should be ≥ 0 (0: the default), got " + std::to_string(options.chart_count));
  }
  auto start = std::chrono::steady_clock::now();
  auto W = normalising_rows(metrics.P);
  if (!W) return W.error();
  const NormalisedFaces nf = normalised_faces(model.faces, normalised_vertices(model, *W));
  ChartOptions chart_options = options.charts;
  chart_options.chart_count = options.chart_count > 0 ? options.chart_count : default_chart_count(model);
  report_progress(options.progress, "segment charts", 0, 1);
  auto charts = segment_charts(model.faces, nf, chart_options);
  if (!charts) return charts.error();
  report_progress(options.progress, "segment charts", 1, 1);
  const double segment_seconds = seconds_since(start);
  auto report = flatten_split_pack(model.faces, grams(nf), std::move(*charts), options, &nf);
  if (!report) return report.error();
  report->segment_seconds = segment_seconds;
  return report;
}

}  // namespace animspace::atlas
