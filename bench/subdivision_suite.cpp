// The subdivide suite: subdivision in animation space (Merry 2007 §4.2, P' = P S; issue #37)
// against refining every posed mesh at run time, and against the linear blend alternative.
//
// For each dataset and k = 1 … 3 Loop steps:
//   vertices, influences_per_vertex   the subdivided model's size (its tangents' wider support
//                                     adds influences: subdivide_model.h);
//   eval_us                           posing the subdivided model, v = Σ_j G_j p'_j (eq. 3.1);
//   runtime_refine_us                 the baseline, measured in the same run: posing the control
//                                     model and refining the posed mesh with OpenSubdiv's own
//                                     runtime path (Far::StencilTable::UpdateValues, the stencils
//                                     precomputed once), spread over the same threads as evaluate;
//   max_error_over_diag               over held-out poses, the largest distance from the posed
//                                     mesh refined by that stencil table, over the rest mesh's
//                                     bounding-box diagonal: "animspace" (P S, exact to float
//                                     rounding) and "ssd" (the rest pose and the linear blend
//                                     weights subdivided apart, then skinned: not exact).
//
//   cow-rig       the ground-truth linear blend rig (§3.1 converts it exactly), posed by random
//                 rotations of every joint (it poses exactly for any), 20 held-out poses.
//   arm           the demo's fitted animation-space arm (`animspace demo-repository`; no linear
//                 blend form, so no "ssd" row), posed by random joint rotations as well.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opensubdiv/far/stencilTable.h>
#include <opensubdiv/far/stencilTableFactory.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>

#include "bench/cow_rig.h"
#include "bench/scratch_directory.h"
#include "bench/suites.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/import.h"
#include "core/common/parallel.h"
#include "core/common/timing.h"
#include "core/subdivision/subdivide_model.h"
#include "harness/build_tree.h"

namespace animspace::bench {
namespace {

namespace as = animation_space;
namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

constexpr double kMaxJointAngle = 35.0 * std::numbers::pi / 180.0;
constexpr int kHeldOutPoses = 20;
constexpr int kMaxLevels = 3;

struct Dataset {
  std::string name;
  as::AnimationSpaceModel model;
  std::optional<as::LinearBlendModel> lbs;  // the rig the model came from, when it is one
};

// A point for OpenSubdiv's stencil evaluation, in float as a renderer's vertex buffer.
struct Vertex {
  float x[3];
  void Clear() { x[0] = x[1] = x[2] = 0; }
  void AddWithWeight(const Vertex& source, float weight) {
    x[0] += weight * source.x[0];
    x[1] += weight * source.x[1];
    x[2] += weight * source.x[2];
  }
};

// The run-time refinement: OpenSubdiv's stencil table for k Loop steps of the control mesh, built
// from its own factory (independently of core/subdivision), with the same boundary rule.
class RuntimeRefiner {
 public:
  RuntimeRefiner(const FaceMatrix& faces, int vertex_count, int levels) {
    std::vector<int> sizes(static_cast<size_t>(faces.rows()), 3);
    Far::TopologyDescriptor descriptor;
    descriptor.numVertices = vertex_count;
    descriptor.numFaces = static_cast<int>(faces.rows());
    descriptor.numVertsPerFace = sizes.data();
    descriptor.vertIndicesPerFace = faces.data();
    Sdc::Options sdc;
    sdc.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
    using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
    std::unique_ptr<Far::TopologyRefiner> refiner(Factory::Create(descriptor, Factory::Options(Sdc::SCHEME_LOOP, sdc)));
    refiner->RefineUniform(Far::TopologyRefiner::UniformOptions(levels));
    Far::StencilTableFactory::Options options;
    options.generateIntermediateLevels = false;
    options.generateOffsets = true;
    table_.reset(Far::StencilTableFactory::Create(*refiner, options));
  }

  int vertex_count() const { return table_->GetNumStencils(); }

  // `posed` (#V_0 × 3) refined into `out` (#V_k × 3), over the threads evaluate would use.
  void refine(const PointMatrix& posed, PointMatrix& out) const {
    out.resize(vertex_count(), 3);
    const auto* source = reinterpret_cast<const Vertex*>(posed.data());
    auto* destination = reinterpret_cast<Vertex*>(out.data());
    parallel_for_chunks(vertex_count(), 4096, [&](int64_t begin, int64_t end) {
      table_->UpdateValues(source, destination, static_cast<int>(begin), static_cast<int>(end));
    });
  }

 private:
  std::unique_ptr<const Far::StencilTable> table_;
};

double max_distance(const PointMatrix& a, const PointMatrix& b) {
  return (a - b).rowwise().norm().maxCoeff();
}

std::optional<Dataset> cow_dataset(const std::filesystem::path& data) {
  auto rig = read_cow_rig(data);
  if (!rig) return std::nullopt;
  return Dataset{"cow-rig", as::from_linear_blend(rig->model), rig->model};
}

// The demo's arm as `animspace demo-repository` writes it (the bench does not link the demo).
std::optional<Dataset> arm_dataset() {
  const ScratchDirectory scratch("subdivide");
  const std::string command =
      harness::program_path("animspace").string() + " demo-repository " + (scratch.path() / "repo").string() + " > /dev/null";
  if (std::system(command.c_str()) != 0) {
    std::printf("arm: '%s' failed (skipped)\n", command.c_str());
    return std::nullopt;
  }
  const std::filesystem::path file = scratch.path() / "repo" / "arm-animspace" / "1" / "model.anim";
  auto container = container::read_file(file);
  if (!container) {
    std::printf("arm: %s (skipped)\n", container.error().message.c_str());
    return std::nullopt;
  }
  auto model = as::load(*container, file.string());
  if (!model) {
    std::printf("arm: %s (skipped)\n", model.error().message.c_str());
    return std::nullopt;
  }
  return Dataset{"arm", std::move(*model), std::nullopt};
}

nlohmann::json run_dataset(const Dataset& d, int repetitions) {
  const std::vector<as::TransformList> poses =
      as::random_joint_rotation_poses(d.model.skeleton, kHeldOutPoses, kMaxJointAngle, 2026);
  PointMatrix rest;
  as::evaluate(d.model, as::rest_pose(d.model.skeleton), rest);
  const double diagonal = (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).cast<double>().norm();
  const double control_influences =
      static_cast<double>(d.model.influences.influence_count()) / d.model.vertex_count();

  nlohmann::json rows = nlohmann::json::array();
  for (int levels = 1; levels <= kMaxLevels; ++levels) {
    // Offline: S and the subdivided model (and the linear blend alternative).
    auto start = std::chrono::steady_clock::now();
    subdivision::SubdivisionOptions options;
    options.levels = levels;
    auto matrices = subdivision::subdivision_matrices(
        subdivision::triangle_topology(d.model.faces, d.model.vertex_count()), options);
    if (!matrices) {
      std::printf("%s: %s (skipped)\n", d.name.c_str(), matrices.error().message.c_str());
      break;
    }
    const as::AnimationSpaceModel refined = subdivision::apply(d.model, *matrices);
    const double build_seconds = seconds_since(start);
    std::optional<as::LinearBlendModel> refined_lbs;
    if (d.lbs) refined_lbs = subdivision::subdivide_linear_blend(*d.lbs, *matrices);
    const RuntimeRefiner runtime(d.model.faces, d.model.vertex_count(), levels);

    // Errors over the held-out poses, against the posed control mesh refined at run time.
    double exact_error = 0, ssd_error = 0;
    PointMatrix control, reference, posed;
    for (const as::TransformList& pose : poses) {
      as::evaluate(d.model, pose, control);
      runtime.refine(control, reference);
      as::evaluate(refined, pose, posed);
      exact_error = std::max(exact_error, max_distance(posed, reference));
      if (refined_lbs) {
        as::evaluate(*refined_lbs, pose, posed);
        ssd_error = std::max(ssd_error, max_distance(posed, reference));
      }
    }

    // Speed, interleaved pose by pose so that drift hits both alike.
    size_t next = 0;
    const double eval_us = 1e6 * median_seconds(repetitions, [&] {
      as::evaluate(refined, poses[next++ % poses.size()], posed);
      do_not_optimize(posed.data());
    });
    const double refine_us = 1e6 * median_seconds(repetitions, [&] {
      as::evaluate(d.model, poses[next++ % poses.size()], control);
      runtime.refine(control, reference);
      do_not_optimize(reference.data());
    });
    const double control_us = 1e6 * median_seconds(repetitions, [&] {
      as::evaluate(d.model, poses[next++ % poses.size()], control);
      do_not_optimize(control.data());
    });
    double ssd_us = 0;
    if (refined_lbs) {
      ssd_us = 1e6 * median_seconds(repetitions, [&] {
        as::evaluate(*refined_lbs, poses[next++ % poses.size()], posed);
        do_not_optimize(posed.data());
      });
    }

    const double influences = static_cast<double>(refined.influences.influence_count()) / refined.vertex_count();
    const auto row = [&](const char* method, double error, double us, double per_vertex) {
      rows.push_back({{"dataset", d.name},
                      {"method", method},
                      {"levels", levels},
                      {"control_vertices", d.model.vertex_count()},
                      {"vertices", refined.vertex_count()},
                      {"control_influences_per_vertex", control_influences},
                      {"influences_per_vertex", per_vertex},
                      {"max_error_over_diag", error / diagonal},
                      {"eval_us", us},
                      {"runtime_refine_us", refine_us},
                      {"control_eval_us", control_us},
                      {"build_seconds", build_seconds},
                      {"held_out_poses", poses.size()}});
      std::printf("%-8s %-9s %2d %8d %7.2f %12.3g %10.0f %12.0f %10.0f %8.3f\n", d.name.c_str(), method, levels,
                  refined.vertex_count(), per_vertex, error / diagonal, us, refine_us, control_us, build_seconds);
    };
    row("animspace", exact_error, eval_us, influences);
    if (refined_lbs) {
      row("ssd", ssd_error, ssd_us,
          static_cast<double>(refined_lbs->influences.influence_count()) / refined_lbs->vertex_count());
    }
  }
  return rows;
}

}  // namespace

nlohmann::json run_subdivision_suite(const SuiteOptions& options) {
  std::vector<Dataset> datasets;
  if (options.data) {
    if (auto cow = cow_dataset(*options.data)) datasets.push_back(std::move(*cow));
  } else {
    std::printf("subdivide: no --data: cow-rig skipped\n");
  }
  if (auto arm = arm_dataset()) datasets.push_back(std::move(*arm));
  std::printf("Loop subdivision in animation space (P' = P S) vs refining each posed mesh at run time "
              "(OpenSubdiv stencils); %d held-out poses, joints up to %.0f°; %u threads\n",
              kHeldOutPoses, kMaxJointAngle * 180 / std::numbers::pi, std::thread::hardware_concurrency());
  std::printf("%-8s %-9s %2s %8s %7s %12s %10s %12s %10s %8s\n", "dataset", "method", "k", "vertices", "infl/v",
              "max err/diag", "eval µs", "refine µs", "ctrl µs", "build s");
  nlohmann::json rows = nlohmann::json::array();
  RowProgress progress("subdivide");
  for (const Dataset& d : datasets) {
    progress.starting(d.name);
    for (auto& row : run_dataset(d, options.repetitions)) rows.push_back(std::move(row));
  }
  std::printf("eval: the subdivided model posed. refine: the control model posed, then OpenSubdiv's stencils applied "
              "to the posed mesh (the baseline). ctrl: the control model posed alone.\n"
              "animspace: P S (exact to float rounding); ssd: rest pose and weights subdivided apart, then "
              "skinned (Merry 2007 §4.2: not exact).\n");
  return rows;
}

}  // namespace animspace::bench
