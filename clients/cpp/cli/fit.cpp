#include "clients/cpp/cli/fit.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/number_checks.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/bone_motions.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/import.h"
#include "core/animspace/rig_export.h"
#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"
#include "core/mesh_io/gltf_skin_writer.h"
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
      "Offline: fit a skinned character to a mesh sequence — near-rigid parts, then the skinning decomposition "
      "(alternating rigid bone motions and sparse non-negative weights, SSDR), joints and hierarchy, then the "
      "animation-space refit with edge regularisation (Merry 2007 §4.1) — and write a model version; --export also "
      "writes the linear blend rig as glTF 2.0 with the sequence as its animation");
  cmd->add_option("sequence", a.sequence, "Folder with reference.obj + frames.pc2 (or OBJ frames), or a mesh file")
      ->required();
  cmd->add_option("--pc2", a.pc2, "Point cache when SEQUENCE is a mesh file");
  cmd->add_option("--select", a.select, "Example frames as a slice start:stop:step (e.g. ::2)")->capture_default_str();
  cmd->add_option("--test-select", a.test_select,
                  "Held-out frames as a slice (e.g. 1::2, or 60: after --select :60): report the error on frames the fit "
                  "did not see, each frame's bone motions solved with the model fixed");
  cmd->add_option("--bones", a.bones, "Rigid parts to find (bones besides the fixed root)")
      ->check(CLI::Range(1, 500))
      ->capture_default_str();
  cmd->add_option("--edge-regularisation", a.edge_regularisation,
                  "δ of eq. 4.4 in unit-box units (0.005 horse, 0.02 arm in the thesis; 0 = off)")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  cmd->add_option("--vertex-regularisation", a.vertex_regularisation, "λ of eq. 4.3 in unit-box units")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  cmd->add_option("--rings", a.rings, "--first-pass influence sets: bones of parts within this many edges")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  cmd->add_option("--max-influences", a.max_influences, "At most this many bones per vertex (K)")
      ->check(CLI::Range(1, 32))
      ->capture_default_str();
  cmd->add_option("--iterations", a.iterations, "Skinning decomposition: at most this many alternations")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  cmd->add_option("--smoothness", a.smoothness, "Skinning decomposition: μ, pull of each weight towards its neighbours'")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  cmd->add_option("--refinement-rounds", a.refinement_rounds,
                  "Animation space: rounds of {bone motions, model} after the refit")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  cmd->add_flag("--first-pass", a.first_pass,
                "The pipeline before the skinning decomposition (one least-squares solve on §4.1.4's skeleton), as a "
                "baseline");
  cmd->add_option("--fps", a.frames_per_second, "--export: frames per second of the animation")
      ->check(tools::kPositive)
      ->capture_default_str();
  cmd->add_option("--export", a.export_path,
                  "Also write the linear blend rig as a glTF 2.0 skinned mesh (.glb or .gltf) with the fitted frames as "
                  "its animation");
  cmd->add_flag("--linear-blend", a.linear_blend,
                "Fit linear blend skinning weights only (the baseline of thesis Table 8.2), stored in animation-space "
                "form");
  cmd->add_option("--description", a.description, "One-line description stored in the model");
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_fit(const FitArgs& a, bool json) {
  const std::filesystem::path export_path(a.export_path);
  if (!a.export_path.empty()) {
    std::string extension = export_path.extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
    if (extension != ".glb" && extension != ".gltf") {
      return fail("fit", "--export " + a.export_path + ": " +
                             (extension.empty() ? "no extension" : "unknown extension '" + extension + "'") +
                             "; --export writes a glTF 2.0 skinned character: .glb, .gltf");
    }
  }
  auto sequence = mesh_io::load_sequence(a.sequence, a.pc2);
  if (!sequence) return fail("fit", sequence.error().message);
  std::string error;
  const auto selected = tools::parse_frame_selection(a.select, sequence->frames.num_frames(), &error);
  if (selected.empty()) return fail("fit", error);
  const FrameMatrix frames = tools::select_rows(sequence->frames.samples, selected);
  std::vector<int> test_selected;
  if (!a.test_select.empty()) {
    test_selected = tools::parse_frame_selection(a.test_select, sequence->frames.num_frames(), &error);
    if (test_selected.empty()) return fail("fit", "--test-select: " + error);
    // A frame in both would be a training error reported as a held-out one.
    std::vector<char> training(static_cast<size_t>(sequence->frames.num_frames()), 0);
    for (int f : selected) training[static_cast<size_t>(f)] = 1;
    for (int f : test_selected) {
      if (training[static_cast<size_t>(f)]) {
        return fail("fit", "--test-select " + a.test_select + ": frame " + std::to_string(f) +
                               " is also a training frame (--select " + a.select + "); held-out frames must be ones "
                               "the fit does not see");
      }
    }
  }

  animation_space::SequenceFitOptions options;
  options.segmentation.bone_count = a.bones;
  options.influences.rings = a.rings;
  options.influences.max_influences = a.max_influences;
  options.fit.edge_regularisation = a.edge_regularisation;
  options.fit.vertex_regularisation = a.vertex_regularisation;
  options.decompose = !a.first_pass;
  options.decomposition.iterations = a.iterations;
  options.decomposition.weights.max_influences = a.max_influences;
  options.decomposition.weights.smoothness = a.smoothness;
  options.refinement_rounds = a.refinement_rounds;
  animation_space::SequenceFitReport report;
  // One bar per stage, each with its own count and time left (issue #55 item 15: one bar of three
  // stages sat at 0/3 through the decomposition, most of the time, and its estimate rose after).
  // The core reports the decomposition and the refinement; the other stages are one step each.
  std::optional<ProgressCallback> progress(progress_bars("fit"));
  const ProgressCallback& on_progress = *progress;
  auto skeleton = animation_space::fit_sequence_skeleton(sequence->reference, frames, options, &report, on_progress);
  if (!skeleton) return fail("fit", skeleton.error().message);
  const char* model_stage = a.linear_blend ? "linear blend weights" : "animation space model";
  on_progress(model_stage, 0, 1);
  const auto start = std::chrono::steady_clock::now();
  auto lbs = animation_space::fit_sequence_linear_blend(sequence->reference, frames, *skeleton, options.fit,
                                                        a.linear_blend ? &report.fit : nullptr);
  if (!lbs) return fail("fit", lbs.error().message);
  std::vector<animation_space::TransformList> poses = skeleton->training_poses;
  Result<animation_space::AnimationSpaceModel> model = make_error(ErrorCode::kInternal, "not fitted");
  if (a.linear_blend) {
    model = animation_space::from_linear_blend(*lbs);
  } else {
    model = animation_space::fit_sequence_model(sequence->reference, frames, *skeleton, options.fit, &report.fit);
    if (model && options.decompose && options.refinement_rounds > 0) {
      on_progress(model_stage, 1, 1);
      model = animation_space::refine_animation_space(frames, std::move(*model), poses, options.fit,
                                                      options.refinement_rounds, &report.fit, on_progress);
    }
  }
  if (!model) return fail("fit", model.error().message);
  report.fit_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  on_progress("tangent planes and metrics", 0, 1);
  if (auto added = add_tangents(*model); !added.ok()) return fail("fit", added.error().message);

  const auto training_error = animation_space::reconstruction_error(*model, poses, frames);
  const double rms = training_error.rms, max_error = training_error.max;
  const double diagonal =
      (sequence->reference.V.colwise().maxCoeff() - sequence->reference.V.colwise().minCoeff()).cast<double>().norm();

  auto metrics = animation_space::stored_metrics_from_poses(*model, poses);
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
    bone_rows.row(f) = animation_space::pose_row(poses[static_cast<size_t>(f)]);
  }
  out.set_matrix(container::sections::kSequenceBoneTransforms, bone_rows);
  on_progress("tangent planes and metrics", 1, 1);
  // Held-out frames: each one's bone motions solved with the model fixed (bone_motions.h, Dem
  // Bones' protocol, as `animspace-bench skinning` measures generalisation).
  std::optional<animation_space::ReconstructionError> test_error;
  if (!test_selected.empty()) {
    const FrameMatrix test_frames = tools::select_rows(sequence->frames.samples, test_selected);
    std::vector<animation_space::TransformList> test_poses;
    for (Eigen::Index f = 0; f < test_frames.rows(); ++f) {
      on_progress("held-out frames", f, test_frames.rows());
      test_poses.push_back(animation_space::solve_pose(*model, test_frames.row(f)));
    }
    on_progress("held-out frames", test_frames.rows(), test_frames.rows());
    test_error = animation_space::reconstruction_error(*model, test_poses, test_frames);
  }
  progress.reset();  // ends the last bar's line before anything else is printed
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, out); !written.ok()) return fail("fit", written.error().message);
  // glTF skins are linear blend skinning (§3.7.3), so the rig exported is the linear blend one,
  // posed in every frame by the motions it was fitted with.
  const auto lbs_error = animation_space::reconstruction_error(*lbs, skeleton->training_poses, frames);
  if (!a.export_path.empty()) {
    auto character = animation_space::skinned_character(*lbs, skeleton->training_poses, a.frames_per_second);
    if (!character) return fail("fit", character.error().message);
    character->name = a.model.empty() ? model_name_of(path) : a.model;
    if (auto written = mesh_io::write_skinned_character(export_path, *character); !written.ok()) {
      return fail("fit", written.error().message);
    }
  }

  const double total = report.segmentation_seconds + report.skeleton_seconds + report.fit_seconds;
  // E_RMS as the skinning-decomposition literature reports it (Tan et al. 2020): 1000 · RMS per
  // coordinate / half the diagonal.
  const auto e_rms = [&](double value) { return 1000.0 * value / std::sqrt(3.0) / (0.5 * diagonal); };
  const auto& iterations = report.decomposition.iterations;
  if (json) {
    nlohmann::json per_iteration = nlohmann::json::array();
    for (const auto& it : iterations) {
      per_iteration.push_back({{"rms_over_diagonal", it.rms / diagonal},
                               {"seconds", it.seconds},
                               {"influences_per_vertex", it.influences_per_vertex}});
    }
    print_json({{"output", path.string()},
                {"frames", frames.rows()},
                {"bones", model->bone_count() - 1},
                {"influences_per_vertex", double(model->influences.influence_count()) / model->vertex_count()},
                {"rms_error", rms},
                {"max_error", max_error},
                {"rms_over_diagonal", rms / diagonal},
                {"e_rms", e_rms(rms)},
                {"lbs_rms_over_diagonal", lbs_error.rms / diagonal},
                {"test_frames", test_selected.size()},
                {"test_rms_error", test_error ? nlohmann::json(test_error->rms) : nlohmann::json(nullptr)},
                {"test_max_error", test_error ? nlohmann::json(test_error->max) : nlohmann::json(nullptr)},
                {"test_rms_over_diagonal",
                 test_error ? nlohmann::json(test_error->rms / diagonal) : nlohmann::json(nullptr)},
                {"segmentation_seconds", report.segmentation_seconds},
                {"skeleton_seconds", report.skeleton_seconds},
                {"fit_seconds", report.fit_seconds},
                {"seconds", total},
                {"initial_rms_over_diagonal", a.first_pass ? nlohmann::json(nullptr)
                                                           : nlohmann::json(report.decomposition.initial_rms / diagonal)},
                {"iterations", per_iteration},
                {"converged", report.decomposition.converged},
                {"export", a.export_path.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.export_path)}});
  } else {
    std::printf("fitted %d frames in %.2f s (parts %.2f s, %s %.2f s, %s %.2f s)\n", static_cast<int>(frames.rows()),
                total, report.segmentation_seconds, a.first_pass ? "skeleton" : "decomposition and joints",
                report.skeleton_seconds, a.first_pass ? "least squares" : "model fit", report.fit_seconds);
    if (!a.first_pass) {
      std::printf("skinning decomposition (RMS, %% of the diagonal): rigid parts %.4f%%", 100 * report.decomposition.initial_rms / diagonal);
      for (size_t k = 0; k < iterations.size(); ++k) {
        std::printf("%s%zu: %.4f%%", k % 6 == 0 ? "\n  " : "  ", k + 1, 100 * iterations[k].rms / diagonal);
      }
      std::printf("\n  %s after %zu iterations\n", report.decomposition.converged ? "converged" : "stopped", iterations.size());
    }
    std::printf("%d bones + root, %.2f influences per vertex, %s\n", model->bone_count() - 1,
                static_cast<double>(model->influences.influence_count()) / model->vertex_count(),
                a.linear_blend ? "linear blend weights" : "animation space");
    std::printf("training error: RMS %.4g (%.3f%% of the diagonal, E_RMS %.2f), max %.4g (%.3f%%)\n", rms,
                100 * rms / diagonal, e_rms(rms), max_error, 100 * max_error / diagonal);
    if (test_error) {
      std::printf("held-out error on %zu frames the fit did not see (--test-select %s): RMS %.4g (%.3f%% of the "
                  "diagonal, E_RMS %.2f), max %.4g (%.3f%%)\n",
                  test_selected.size(), a.test_select.c_str(), test_error->rms, 100 * test_error->rms / diagonal,
                  e_rms(test_error->rms), test_error->max, 100 * test_error->max / diagonal);
    }
    std::printf("wrote %s\n", path.c_str());
    print_serving_hint(a.model);
    if (!a.export_path.empty()) {
      std::printf("wrote %s (linear blend rig, %d joints, %d frames; RMS %.3f%% of the diagonal)\n", a.export_path.c_str(),
                  lbs->skeleton.bone_count(), static_cast<int>(frames.rows()), 100 * lbs_error.rms / diagonal);
    }
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
  cmd->add_option("--drop-weights", a.drop_weights,
                  "Drop each vertex's smallest weights up to this total and renormalise the rest: a vertex then "
                  "moves by at most this fraction of the distance between where its bones carry it, whatever "
                  "the character's size; 0 keeps every non-zero weight, exact to the file")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  add_model_output_options(cmd, a.output, a.model, a.version);
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
    animation_space::WeightOptions weights;
    weights.drop_budget = a.drop_weights;
    auto read = animation_space::read_libigl_rig(a.mesh, a.tgf, a.dmat, weights);
    if (!read) return fail("import-rig", read.error().message);
    rig = std::move(*read);
  } else {
    animation_space::GltfImportOptions options;
    options.weights.drop_budget = a.drop_weights;
    auto read = animation_space::read_gltf_rig(a.gltf, options);
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
                {"influences", model.influences.influence_count()},
                {"dropped_weights", rig.dropped_weights},
                {"max_dropped_weight_sum", rig.max_dropped_weight_sum}});
  } else {
    std::printf("imported %d vertices, %d bones + root, %d influences (%.2f per vertex)\n", model.vertex_count(),
                model.bone_count() - 1, model.influences.influence_count(),
                static_cast<double>(model.influences.influence_count()) / model.vertex_count());
    if (rig.dropped_weights > 0) {
      std::printf("dropped %lld negligible weights (at most %.3g of one vertex's weight, --drop-weights %g) and "
                  "renormalised the rest\n",
                  static_cast<long long>(rig.dropped_weights), rig.max_dropped_weight_sum, a.drop_weights);
    }
    std::printf("wrote %s\n", path.c_str());
    print_serving_hint(a.model);
  }
  return 0;
}

}  // namespace animspace::cli
