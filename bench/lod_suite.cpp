// The lod suite (issue #5): animation-space level of detail (Merry 2007 ch. 6) against the
// rest-pose simplifiers people use today, judged across poses (§8.5).
//
//   cow-rig       the ground-truth LBS rig converted to animation space (§3.1). P = E[GᵀG] comes
//                 from 200 random poses of the rig (every joint turned about a random axis by up
//                 to kMaxJointAngle); the error is measured on 200 other random poses, so the
//                 simplifier never sees the poses it is judged on.
//   horse-gallop  the animation-space horse fitted by the automatic pipeline (fit_sequence.h, as
//                 in the skinning suite) to all 48 frames; P from its 48 fitted poses, error on
//                 the same 48 (the only poses there are).
//   horse-gallop-block  the same horse; P from the first three quarters of the gallop, the error
//                 on the last quarter (a held-out block of motion).
//
// Methods, each asked for 50%, 25%, 10% and 5% of the vertices:
//   animspace-lod               the served levels: memoryless APS in animation space + influence
//                               simplification, the cut placed across poses (lod/level_fit.h)
//   animspace-lod-no-influence  the same without influence removals
//   animspace-lod-unplaced[-no-influence]   the same without placement (what was served before)
//   animspace-lod-quadric-unplaced-no-influence   ordered by quadric memory (CollapseCost::kQuadric)
//   animspace-lod-chart-borders the served levels of a model with a texture atlas (issue #37): the
//                               dataset's atlas (atlas::build_atlas under its P, the defaults of
//                               `animspace atlas`), whose chart borders the collapses keep
//                               (lod/chart_atlas.h) — what keeping them costs against animspace-lod
//   openmesh-quadric-rest       OpenMesh's decimater, quadric error (ModQuadric) with its
//                               normal-flip guard, on the rest pose
//   multi-pose-quadric          the same decimater with quadrics summed over the poses P is built
//                               from (Mohr & Gleicher 2003)
//   meshoptimizer-rest          meshopt_simplify on the rest pose
// All keep a subset of the input vertices (half-edge collapses; placement then moves ours), so each
// simplified mesh is posed with its vertices' own skinning (ours possibly influence-simplified). Error: for every
// pose, the distance from each original posed vertex to the posed simplified surface (one
// routine, lod/surface_distance.h, for every method), RMS and max over vertices and poses, over
// the rest pose's bounding-box diagonal.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "bench/cow_rig.h"
#include "bench/lod_comparison.h"
#include "bench/suites.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/import.h"
#include "core/atlas/atlas.h"
#include "core/common/parallel.h"
#include "core/common/timing.h"
#include "core/lod/levels.h"
#include "core/lod/simplify.h"
#include "core/lod/surface_distance.h"
#include "core/mesh_io/sequence_io.h"

namespace animspace::bench {
namespace {

namespace as = animation_space;

constexpr double kMaxJointAngle = 35.0 * std::numbers::pi / 180.0;
constexpr int kCowPoses = 200;
constexpr double kFractions[] = {0.5, 0.25, 0.1, 0.05};

struct Dataset {
  std::string name;
  as::AnimationSpaceModel model;
  as::AnimationSpaceMetrics metrics;
  std::vector<as::TransformList> poses;       // where the error is measured
  std::vector<as::TransformList> statistics;  // the poses P is built from (all a simplifier may see)
  double diagonal = 1;
};

using OpenMeshMesh = OpenMesh::TriMesh_ArrayKernelT<>;

// OpenMesh's decimater on the rest pose: half-edge collapses that keep the surviving vertex where
// it is, with the normal-flipping guard users normally add. `add_cost` adds the cost module to the
// decimater before the guard (the time it takes counts).
template <typename AddCost>
Simplified openmesh_decimate(const as::AnimationSpaceModel& model, int target_vertices, AddCost&& add_cost) {
  using Mesh = OpenMeshMesh;
  const auto start = std::chrono::steady_clock::now();
  const lod::Points3d rest = posed(model, model.skeleton.rest);
  Mesh mesh;
  for (Eigen::Index v = 0; v < rest.rows(); ++v) {
    mesh.add_vertex(
        Mesh::Point(static_cast<float>(rest(v, 0)), static_cast<float>(rest(v, 1)), static_cast<float>(rest(v, 2))));
  }
  for (Eigen::Index f = 0; f < model.faces.rows(); ++f) {
    mesh.add_face(Mesh::VertexHandle(model.faces(f, 0)), Mesh::VertexHandle(model.faces(f, 1)),
                  Mesh::VertexHandle(model.faces(f, 2)));
  }
  mesh.request_face_normals();  // the normal-flipping module reads them
  mesh.update_face_normals();
  OpenMesh::Decimater::DecimaterT<Mesh> decimater(mesh);
  add_cost(decimater);
  OpenMesh::Decimater::ModNormalFlippingT<Mesh>::Handle flipping;
  decimater.add(flipping);
  decimater.initialize();
  decimater.decimate_to(static_cast<size_t>(target_vertices));
  std::vector<int32_t> keep;
  for (const Mesh::VertexHandle v : mesh.vertices()) {
    if (!mesh.status(v).deleted()) keep.push_back(v.idx());
  }
  std::vector<std::array<int32_t, 3>> faces;
  for (const Mesh::FaceHandle f : mesh.faces()) {
    if (mesh.status(f).deleted()) continue;
    std::array<int32_t, 3> corners{};
    int c = 0;
    for (const Mesh::VertexHandle v : mesh.fv_range(f)) corners[static_cast<size_t>(c++)] = v.idx();
    faces.push_back(corners);
  }
  std::sort(keep.begin(), keep.end());
  Simplified s{subset(model, keep, faces), 0};
  s.build_seconds = seconds_since(start);
  return s;
}

// OpenMesh's quadric error (ModQuadric) on the rest pose.
Simplified openmesh_quadric(const as::AnimationSpaceModel& model, int target_vertices) {
  return openmesh_decimate(model, target_vertices, [](OpenMesh::Decimater::DecimaterT<OpenMeshMesh>& decimater) {
    OpenMesh::Decimater::ModQuadricT<OpenMeshMesh>::Handle quadric;
    decimater.add(quadric);
    decimater.module(quadric).unset_max_err();
  });
}

// Deformation-sensitive decimation (Mohr & Gleicher 2003): Garland–Heckbert quadrics summed over
// sampled poses. Every vertex keeps one area-weighted plane quadric per pose (the planes of its
// faces posed by that pose's skinning), a collapse v0 → v1 costs Σ_k (Q_k(v0) + Q_k(v1)) at v1's
// posed positions, and merged vertices add their quadrics — OpenMesh's ModQuadricT with the pose
// sum inside. The poses are the ones P is built from, so it sees what our simplifier sees.
template <class MeshT>
class ModMultiPoseQuadricT : public OpenMesh::Decimater::ModBaseT<MeshT> {
 public:
  DECIMATING_MODULE(ModMultiPoseQuadricT, MeshT, MultiPoseQuadric);

  explicit ModMultiPoseQuadricT(MeshT& mesh) : Base(mesh, false) {}

  // posed[k] is every vertex in pose k (V × 3); set before initialize().
  void set_poses(std::vector<lod::Points3d> posed) { posed_ = std::move(posed); }

  void initialize() override {
    const size_t S = posed_.size();
    const size_t V = Base::mesh().n_vertices();
    quadrics_.assign(V * S, OpenMesh::Geometry::Quadricd());
    for (const typename MeshT::FaceHandle f : Base::mesh().faces()) {
      std::array<int, 3> c{};
      int i = 0;
      for (const typename MeshT::VertexHandle v : Base::mesh().fv_range(f)) c[static_cast<size_t>(i++)] = v.idx();
      for (size_t k = 0; k < S; ++k) {
        const lod::Points3d& x = posed_[k];
        const Eigen::Vector3d a = x.row(c[0]).transpose(), b = x.row(c[1]).transpose(), e = x.row(c[2]).transpose();
        Eigen::Vector3d n = (b - a).cross(e - a);
        const double area = 0.5 * n.norm();
        if (!(area > 0)) continue;
        n.normalize();
        OpenMesh::Geometry::Quadricd q(n.x(), n.y(), n.z(), -n.dot(a));
        q *= area;
        for (const int v : c) quadrics_[static_cast<size_t>(v) * S + k] += q;
      }
    }
  }

  float collapse_priority(const CollapseInfo& ci) override {
    const size_t S = posed_.size();
    const size_t v0 = static_cast<size_t>(ci.v0.idx()), v1 = static_cast<size_t>(ci.v1.idx());
    double error = 0;
    for (size_t k = 0; k < S; ++k) {
      OpenMesh::Geometry::Quadricd q = quadrics_[v0 * S + k];
      q += quadrics_[v1 * S + k];
      const lod::Points3d& x = posed_[k];
      error += q(OpenMesh::Vec3d(x(ci.v1.idx(), 0), x(ci.v1.idx(), 1), x(ci.v1.idx(), 2)));
    }
    return static_cast<float>(error);
  }

  void postprocess_collapse(const CollapseInfo& ci) override {
    const size_t S = posed_.size();
    for (size_t k = 0; k < S; ++k) {
      quadrics_[static_cast<size_t>(ci.v1.idx()) * S + k] += quadrics_[static_cast<size_t>(ci.v0.idx()) * S + k];
    }
  }

 private:
  std::vector<lod::Points3d> posed_;
  std::vector<OpenMesh::Geometry::Quadricd> quadrics_;  // vertex-major, one per pose
};

Simplified multi_pose_quadric(const Dataset& d, int target_vertices) {
  return openmesh_decimate(d.model, target_vertices, [&d](OpenMesh::Decimater::DecimaterT<OpenMeshMesh>& decimater) {
    std::vector<lod::Points3d> posed_statistics;
    posed_statistics.reserve(d.statistics.size());
    for (const as::TransformList& G : d.statistics) posed_statistics.push_back(posed(d.model, G));
    ModMultiPoseQuadricT<OpenMeshMesh>::Handle quadric;
    decimater.add(quadric);
    decimater.module(quadric).set_poses(std::move(posed_statistics));
  });
}

std::optional<Dataset> cow_dataset(const std::filesystem::path& data) {
  auto rig = read_cow_rig(data);
  if (!rig) return std::nullopt;
  Dataset d;
  d.name = "cow-rig";
  d.model = as::from_linear_blend(rig->model);
  const std::vector<as::TransformList> statistics =
      as::random_joint_rotation_poses(d.model.skeleton, kCowPoses, kMaxJointAngle, 7);
  d.poses = as::random_joint_rotation_poses(d.model.skeleton, kCowPoses, kMaxJointAngle, 2026);
  auto metrics = as::metrics_from_poses(d.model.skeleton, statistics);
  if (!metrics) {
    std::printf("cow-rig: %s (skipped)\n", metrics.error().message.c_str());
    return std::nullopt;
  }
  d.metrics = std::move(*metrics);
  d.statistics = statistics;
  d.diagonal = rest_diagonal(d.model);
  return d;
}

// held_out_block: P (all any simplifier sees) from the first three quarters of the gallop, the
// error on the last quarter, a block of motion none of them saw ("horse-gallop-block").
std::optional<Dataset> horse_dataset(const std::filesystem::path& data, const SkinningSuiteOptions& skinning,
                                     bool held_out_block) {
  auto sequence = mesh_io::load_sequence(data / "horse-gallop");
  if (!sequence) {
    std::printf("horse-gallop: %s (skipped)\n", sequence.error().message.c_str());
    return std::nullopt;
  }
  as::SequenceFitOptions options;
  options.segmentation.bone_count = skinning.bones;
  options.fit.edge_regularisation = skinning.edge_regularisation;
  options.fit.vertex_regularisation = skinning.vertex_regularisation;
  const FrameMatrix& frames = sequence->frames.samples;
  auto skeleton = as::fit_sequence_skeleton(sequence->reference, frames, options, nullptr);
  if (!skeleton) {
    std::printf("horse-gallop: %s (skipped)\n", skeleton.error().message.c_str());
    return std::nullopt;
  }
  auto model = as::fit_sequence_model(sequence->reference, frames, *skeleton, options.fit, nullptr);
  if (!model) {
    std::printf("horse-gallop: %s (skipped)\n", model.error().message.c_str());
    return std::nullopt;
  }
  Dataset d;
  d.name = held_out_block ? "horse-gallop-block" : "horse-gallop";
  d.model = std::move(*model);
  d.model.faces = sequence->reference.F;
  d.poses = skeleton->training_poses;
  d.statistics = d.poses;
  if (held_out_block) {
    const auto seen = static_cast<std::ptrdiff_t>(d.poses.size() - (d.poses.size() + 3) / 4);
    d.statistics.assign(d.poses.begin(), d.poses.begin() + seen);
    d.poses.erase(d.poses.begin(), d.poses.begin() + seen);
  }
  auto metrics = as::metrics_from_poses(d.model.skeleton, d.statistics);
  if (!metrics) {
    std::printf("horse-gallop: %s (skipped)\n", metrics.error().message.c_str());
    return std::nullopt;
  }
  d.metrics = std::move(*metrics);
  d.diagonal = rest_diagonal(d.model);
  return d;
}

nlohmann::json run_dataset(const Dataset& d, const std::vector<std::string>& methods) {
  const auto wanted = [&methods](const std::string& method) {
    return methods.empty() || std::find(methods.begin(), methods.end(), method) != methods.end();
  };
  nlohmann::json rows = nlohmann::json::array();
  const int V = d.model.vertex_count();
  std::printf("\n%s: %d vertices, %d influences, %d bones, %zu poses\n", d.name.c_str(), V,
              d.model.influences.influence_count(), d.model.bone_count(), d.poses.size());
  std::printf("%-30s %8s %9s %9s %11s %14s %14s %9s\n", "method", "target", "vertices", "faces", "influences",
              "rms/diag", "max/diag", "build s");
  const auto row = [&](const std::string& method, double fraction, const as::AnimationSpaceModel& m, double seconds) {
    const SurfaceError e = measure_across_poses(d.model, m, d.poses, d.diagonal);
    std::printf("%-30s %7.0f%% %9d %9d %11d %14.6f %14.6f %9.3f\n", method.c_str(), 100 * fraction, m.vertex_count(),
                static_cast<int>(m.faces.rows()), m.influences.influence_count(), e.rms, e.max, seconds);
    std::fflush(stdout);
    rows.push_back({{"dataset", d.name},
                    {"method", method},
                    {"target_fraction", fraction},
                    {"vertices", m.vertex_count()},
                    {"faces", m.faces.rows()},
                    {"influences", m.influences.influence_count()},
                    {"rms_error_over_diag", e.rms},
                    {"max_error_over_diag", e.max},
                    {"build_seconds", seconds}});
  };
  // The served levels are animspace-lod: lod::LevelBuildOptions' defaults (edge collapses in the
  // memoryless order, vertices placed by fit_level, then influences simplified under the exchange
  // rule). The other rows change one of those choices.
  struct Variant {
    const char* method;
    lod::CollapseCost cost;
    bool influences;
    bool placement;
    bool combined_order = false;  // §6.3.1's one order of collapses and removals, then placement
    bool chart_borders = false;   // the dataset's atlas's borders kept
  };
  std::optional<lod::ChartAtlas> charts;
  if (wanted("animspace-lod-chart-borders")) {
    const auto start = std::chrono::steady_clock::now();
    auto built = atlas::build_atlas(d.model, d.metrics, atlas::AtlasOptions{});
    if (built) {
      charts = lod::ChartAtlas{built->atlas.chart_of_face, built->atlas.uvs};
      std::printf("  atlas for animspace-lod-chart-borders: %d charts, built in %.1f s\n", built->atlas.chart_count,
                  seconds_since(start));
    } else {
      std::printf("%s: atlas: %s\n", d.name.c_str(), built.error().message.c_str());
    }
  }
  for (const Variant& variant :
       {Variant{"animspace-lod", lod::CollapseCost::kMemoryless, true, true},
        Variant{"animspace-lod-no-influence", lod::CollapseCost::kMemoryless, false, true},
        Variant{"animspace-lod-combined-order", lod::CollapseCost::kMemoryless, true, true, true},
        Variant{"animspace-lod-unplaced", lod::CollapseCost::kMemoryless, true, false},
        Variant{"animspace-lod-unplaced-no-influence", lod::CollapseCost::kMemoryless, false, false},
        Variant{"animspace-lod-quadric-unplaced-no-influence", lod::CollapseCost::kQuadric, false, false},
        Variant{"animspace-lod-chart-borders", lod::CollapseCost::kMemoryless, true, true, false, true}}) {
    if (!wanted(variant.method) || (variant.chart_borders && !charts)) continue;
    lod::LevelBuildOptions build;
    build.influence_simplification = variant.influences;
    build.placement = variant.placement;
    lod::SimplifyOptions options = lod::progressive_mesh_options(build);
    lod::LevelFitOptions fit_options = lod::level_fit_options(build);
    options.cost = variant.cost;
    if (variant.chart_borders) options.atlas = &*charts;
    if (variant.combined_order) {  // what was served before
      options.influence_simplification = true;
      fit_options.influence_exchange = -1;
    }
    const auto start = std::chrono::steady_clock::now();
    auto pm = lod::build_progressive_mesh(d.model, d.metrics, options);
    const double seconds = seconds_since(start);
    if (!pm) {
      std::printf("%s: %s\n", d.name.c_str(), pm.error().message.c_str());
      continue;
    }
    const lod::LodLevels levels = lod::make_levels(*pm);
    long removals = 0, negligible = 0;
    for (const lod::Simplification& step : pm->steps) {
      if (step.kind != lod::SimplificationKind::kInfluenceRemoval) continue;
      ++removals;
      if (step.cost < 1e-6 * d.diagonal) ++negligible;
    }
    std::printf(
        "  %s: %zu steps (%ld influence removals, %ld of them below 1e-6 of the diagonal), "
        "base %d vertices, %d levels, built in %.3f s\n",
        variant.method, pm->steps.size(), removals, negligible, pm->base.vertex_count(), levels.count(), seconds);
    for (const double fraction : kFractions) {
      const int target = static_cast<int>(std::lround(fraction * V));
      std::vector<int32_t> representative;
      as::AnimationSpaceModel level = lod::simplify_to_vertex_count(*pm, target, nullptr, nullptr, &representative);
      double fit_seconds = 0;
      if (variant.placement) {
        const auto fit_start = std::chrono::steady_clock::now();
        auto fit = lod::fit_level(d.model, d.metrics.P, representative, level, fit_options);
        fit_seconds = seconds_since(fit_start);
        if (!fit) {
          std::printf("%s: %s\n", d.name.c_str(), fit.error().message.c_str());
          continue;
        }
      }
      row(variant.method, fraction, level, seconds + fit_seconds);
    }
  }
  for (const double fraction : kFractions) {
    if (!wanted("openmesh-quadric-rest")) break;
    const int target = static_cast<int>(std::lround(fraction * V));
    const Simplified s = openmesh_quadric(d.model, target);
    row("openmesh-quadric-rest", fraction, s.model, s.build_seconds);
  }
  for (const double fraction : kFractions) {
    if (!wanted("multi-pose-quadric")) break;
    const int target = static_cast<int>(std::lround(fraction * V));
    const Simplified s = multi_pose_quadric(d, target);
    row("multi-pose-quadric", fraction, s.model, s.build_seconds);
  }
  for (const double fraction : kFractions) {
    if (!wanted("meshoptimizer-rest")) break;
    const int target = static_cast<int>(std::lround(fraction * V));
    const Simplified s = meshoptimizer_rest(d.model, target);
    row("meshoptimizer-rest", fraction, s.model, s.build_seconds);
  }
  return rows;
}

}  // namespace

nlohmann::json run_lod_suite(const SuiteOptions& suite) {
  nlohmann::json rows = nlohmann::json::array();
  if (!suite.data) {
    std::printf("lod: needs --data (cow-rig, horse-gallop); skipped\n");
    return rows;
  }
  RowProgress progress("lod");
  for (const std::string& name : suite.lod_datasets) {
    progress.starting(name);
    std::optional<Dataset> d = name == "cow-rig"              ? cow_dataset(*suite.data)
                               : name == "horse-gallop"       ? horse_dataset(*suite.data, suite.skinning, false)
                               : name == "horse-gallop-block" ? horse_dataset(*suite.data, suite.skinning, true)
                                                              : std::nullopt;
    if (!d) {
      if (name != "cow-rig" && name != "horse-gallop" && name != "horse-gallop-block")
        std::printf("%s: unknown dataset (skipped)\n", name.c_str());
      continue;
    }
    for (auto& r : run_dataset(*d, suite.lod_methods)) rows.push_back(r);
  }
  return rows;
}

}  // namespace animspace::bench
