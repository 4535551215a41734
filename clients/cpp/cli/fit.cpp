#include "clients/cpp/cli/fit.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/frame_selection.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/import.h"
#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"
#include "core/mesh_io/sequence_io.h"
#include "core/container/sections.h"

namespace animspace::cli {
namespace {

// Tangent planes fitted to the geometry (Merry 2007 §4.3.1), so that served poses carry normals.
Status add_tangents(animation_space::AnimationSpaceModel& model) {
  auto planes = animation_space::fit_tangent_planes(model);
  if (!planes) return planes.error();
  model.tangent_s = std::move(planes->s);
  model.tangent_t = std::move(planes->t);
  return Status::Ok();
}

}  // namespace

CLI::App* add_fit(CLI::App& app, FitArgs& a) {
  auto* cmd = app.add_subcommand(
      "fit",
      "Offline: fit an animation-space model to a mesh sequence — skeleton found automatically from near-rigid "
      "parts, then least squares with edge regularisation (Merry 2007 §4.1) — and write a model version");
  cmd->add_option("sequence", a.sequence, "Folder with reference.obj + frames.pc2 (or OBJ frames), or a mesh file")
      ->required();
  cmd->add_option("--pc2", a.pc2, "Point cache when SEQUENCE is a mesh file");
  cmd->add_option("--select", a.select, "Example frames as a slice start:stop:step (e.g. ::2)")->capture_default_str();
  cmd->add_option("--bones", a.bones, "Rigid parts to find (bones besides the fixed root)")
      ->check(CLI::Range(1, 500))
      ->capture_default_str();
  cmd->add_option("--edge-regularisation", a.edge_regularisation,
                  "δ of eq. 4.4 in unit-box units (0.005 horse, 0.02 arm in the thesis; 0 = off)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--vertex-regularisation", a.vertex_regularisation, "λ of eq. 4.3 in unit-box units")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--rings", a.rings, "Influence sets: bones of parts within this many edges")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  cmd->add_option("--max-influences", a.max_influences, "Influence sets: at most this many bones per vertex")
      ->check(CLI::Range(1, 32))
      ->capture_default_str();
  cmd->add_flag("--linear-blend", a.linear_blend,
                "Fit linear blend skinning weights only (the baseline of thesis Table 8.2), stored in animation-space "
                "form");
  cmd->add_option("--description", a.description, "One-line description stored in the model");
  cmd->add_option("-o,--output", a.output, "Output model.anim file, or the repository folder with --model")->required();
  cmd->add_option("--model", a.model, "Model name: write <output>/<model>/<version>/model.anim");
  cmd->add_option("--version", a.version, "Version to write (default: one above the newest)");
  return cmd;
}

int run_fit(const FitArgs& a, bool json) {
  auto sequence = mesh_io::load_sequence(a.sequence, a.pc2);
  if (!sequence) return fail("fit", sequence.error().message);
  std::string error;
  const auto selected = tools::parse_frame_selection(a.select, sequence->frames.num_frames(), &error);
  if (selected.empty()) return fail("fit", error);
  const FrameMatrix frames = tools::select_rows(sequence->frames.samples, selected);

  animation_space::SequenceFitOptions options;
  options.segmentation.bone_count = a.bones;
  options.influences.rings = a.rings;
  options.influences.max_influences = a.max_influences;
  options.fit.edge_regularisation = a.edge_regularisation;
  options.fit.vertex_regularisation = a.vertex_regularisation;
  animation_space::SequenceFitReport report;
  // Three stages, each one call into the core: rigid parts and skeleton (§5), the least-squares
  // fit (§4.1), tangent planes and metrics.
  std::optional<ProgressBar> progress(std::in_place, "fit", 3);
  progress->update(0, "rigid parts and skeleton");
  auto skeleton = animation_space::fit_sequence_skeleton(sequence->reference, frames, options, &report);
  if (!skeleton) return fail("fit", skeleton.error().message);
  progress->update(1, "least squares");
  const auto start = std::chrono::steady_clock::now();
  Result<animation_space::AnimationSpaceModel> model = make_error(ErrorCode::kInternal, "not fitted");
  if (a.linear_blend) {
    auto lbs = animation_space::fit_sequence_linear_blend(sequence->reference, frames, *skeleton, options.fit,
                                                          &report.fit);
    if (!lbs) return fail("fit", lbs.error().message);
    model = animation_space::from_linear_blend(*lbs);
  } else {
    model = animation_space::fit_sequence_model(sequence->reference, frames, *skeleton, options.fit, &report.fit);
  }
  if (!model) return fail("fit", model.error().message);
  report.fit_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  progress->update(2, "tangent planes and metrics");
  if (auto added = add_tangents(*model); !added.ok()) return fail("fit", added.error().message);

  const auto training_error = animation_space::reconstruction_error(*model, skeleton->training_poses, frames);
  const double rms = training_error.rms, max_error = training_error.max;
  const double diagonal =
      (sequence->reference.V.colwise().maxCoeff() - sequence->reference.V.colwise().minCoeff()).cast<double>().norm();

  auto metrics = animation_space::stored_metrics_from_poses(*model, skeleton->training_poses);
  if (!metrics) return fail("fit", metrics.error().message);

  container::ModelContainer out;
  animation_space::store(*model, out);
  animation_space::store_metrics(*metrics, out);
  out.metadata()["description"] =
      a.description.empty() ? std::string(a.linear_blend ? "Linear blend skinning" : "Animation-space") +
                                  " model fitted to " + a.sequence + " (" + std::to_string(frames.rows()) + " frames)"
                            : a.description;
  out.metadata()["generator"] = "animspace fit";
  out.metadata()["animspace.edge_regularisation"] = std::to_string(a.edge_regularisation);
  out.metadata()["animspace.vertex_regularisation"] = std::to_string(a.vertex_regularisation);
  out.metadata()["animspace.fit_rms"] = std::to_string(rms);
  out.set_matrix(container::sections::kSequenceFrames, frames);
  container::Float64Matrix bone_rows(frames.rows(), 16L * model->bone_count());
  for (Eigen::Index f = 0; f < frames.rows(); ++f) {
    bone_rows.row(f) = animation_space::pose_row(skeleton->training_poses[static_cast<size_t>(f)]);
  }
  out.set_matrix(container::sections::kSequenceBoneTransforms, bone_rows);
  progress->update(3);
  progress.reset();
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, out); !written.ok()) return fail("fit", written.error().message);

  const double total = report.segmentation_seconds + report.skeleton_seconds + report.fit_seconds;
  if (json) {
    print_json({{"output", path.string()},
                {"frames", frames.rows()},
                {"bones", model->bone_count() - 1},
                {"influences_per_vertex", double(model->influences.influence_count()) / model->vertex_count()},
                {"rms_error", rms},
                {"max_error", max_error},
                {"rms_over_diagonal", rms / diagonal},
                {"segmentation_seconds", report.segmentation_seconds},
                {"skeleton_seconds", report.skeleton_seconds},
                {"fit_seconds", report.fit_seconds},
                {"seconds", total}});
  } else {
    std::printf("fitted %d frames in %.2f s (parts %.2f s, skeleton %.2f s, least squares %.2f s)\n",
                static_cast<int>(frames.rows()), total, report.segmentation_seconds, report.skeleton_seconds,
                report.fit_seconds);
    std::printf("%d bones + root, %.2f influences per vertex, %s\n", model->bone_count() - 1,
                static_cast<double>(model->influences.influence_count()) / model->vertex_count(),
                a.linear_blend ? "linear blend weights" : "animation space");
    std::printf("training error: RMS %.4g (%.3f%% of the diagonal), max %.4g (%.3f%%)\n", rms, 100 * rms / diagonal,
                max_error, 100 * max_error / diagonal);
    std::printf("wrote %s\n", path.c_str());
  }
  return 0;
}

CLI::App* add_import_rig(CLI::App& app, ImportRigArgs& a) {
  auto* cmd = app.add_subcommand(
      "import-rig",
      "Offline: convert a linear-blend-skinned rig to an animation-space model version, exactly (p_j = w_j Ĝ_j⁻¹ v̂, "
      "Merry 2007 §3.1), with tangent planes from its normals (§4.3.2)");
  cmd->add_option("--mesh", a.mesh, "libigl rig: rest mesh (OBJ, PLY, OFF)");
  cmd->add_option("--tgf", a.tgf, "libigl rig: skeleton (TGF)");
  cmd->add_option("--dmat", a.dmat, "libigl rig: weights (DMAT, #V × #bones)");
  cmd->add_option("--gltf", a.gltf, "A glTF 2.0 file (.gltf or .glb) with a skinned mesh");
  cmd->add_option("--description", a.description, "One-line description stored in the model");
  cmd->add_option("-o,--output", a.output, "Output model.anim file, or the repository folder with --model")->required();
  cmd->add_option("--model", a.model, "Model name: write <output>/<model>/<version>/model.anim");
  cmd->add_option("--version", a.version, "Version to write (default: one above the newest)");
  return cmd;
}

int run_import_rig(const ImportRigArgs& a, bool json) {
  const bool libigl = !a.mesh.empty() || !a.tgf.empty() || !a.dmat.empty();
  if (libigl == !a.gltf.empty()) return fail("import-rig", "give either --gltf, or all of --mesh, --tgf and --dmat");
  if (libigl && (a.mesh.empty() || a.tgf.empty() || a.dmat.empty())) {
    return fail("import-rig", "a libigl rig needs all of --mesh, --tgf and --dmat");
  }
  animation_space::ImportedRig rig;
  Eigen::MatrixX3d normals;
  if (libigl) {
    auto read = animation_space::read_libigl_rig(a.mesh, a.tgf, a.dmat);
    if (!read) return fail("import-rig", read.error().message);
    rig = std::move(*read);
  } else {
    auto read = animation_space::read_gltf_rig(a.gltf);
    if (!read) return fail("import-rig", read.error().message);
    rig = std::move(read->rig);
    normals = std::move(read->rest_normals);
  }
  animation_space::AnimationSpaceModel model = animation_space::from_linear_blend(rig.model);
  if (normals.rows() == 0) normals = geometry::area_weighted_normals(rig.model.rest_points.transpose(), model.faces);
  auto planes = animation_space::tangent_planes_from_normals(model, normals);
  if (!planes) return fail("import-rig", planes.error().message);
  model.tangent_s = std::move(planes->s);
  model.tangent_t = std::move(planes->t);

  container::ModelContainer out;
  animation_space::store(model, out);
  const std::string source = libigl ? a.tgf : a.gltf;
  out.metadata()["description"] =
      a.description.empty() ? "Linear-blend-skinned rig " + source + " in animation space" : a.description;
  out.metadata()["generator"] = "animspace import-rig";
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, out); !written.ok()) return fail("import-rig", written.error().message);
  if (json) {
    print_json({{"output", path.string()},
                {"vertices", model.vertex_count()},
                {"bones", model.bone_count() - 1},
                {"influences", model.influences.influence_count()}});
  } else {
    std::printf("imported %d vertices, %d bones + root, %d influences (%.2f per vertex)\nwrote %s\n",
                model.vertex_count(), model.bone_count() - 1, model.influences.influence_count(),
                static_cast<double>(model.influences.influence_count()) / model.vertex_count(), path.c_str());
  }
  return 0;
}

}  // namespace animspace::cli
