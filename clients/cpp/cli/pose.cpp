#include "clients/cpp/cli/pose.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/pose_file.h"
#include "core/mesh_io/posed_mesh.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/text_io.h"

namespace animspace::cli {
namespace {

PointMatrix as_matrix(const Points& points) {
  return Eigen::Map<const PointMatrix>(points.values.data(), points.point_count, 3);
}

}  // namespace

CLI::App* add_pose(CLI::App& app, PoseArgs& a) {
  auto* cmd = app.add_subcommand(
      "pose",
      "Evaluate skeleton poses through a served animation-space model (SkinningService.EvaluateSkeletonPose) and "
      "write them as a point cache (.pc2, every pose) or one mesh with normals (.obj, .ply, .glb, .gltf)");
  cmd->add_option("model", a.model, "Model name (animation-space, or a PMSC model with a posing engine)")->required();
  cmd->add_option("--version", a.version, "Model version (default: the served one)");
  cmd->add_option("--pose-file", a.pose_file,
                  "Poses: for each pose, B × 12 numbers, each bone's top three matrix rows ('#' comments)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--pose-space", a.pose_space, "The file's matrices: global G_j or local (joint) L_j")
      ->check(CLI::IsMember({"global", "local"}))
      ->capture_default_str();
  cmd->add_option("--lod-level", a.lod_level, "Evaluate this level of detail (0 = full detail)")
      ->capture_default_str();
  cmd->add_flag("--normals", a.normals,
                "Also evaluate normals from the tangent planes (§3.5), written to the mesh: OBJ vn, PLY nx ny nz, "
                "glTF NORMAL (a .pc2 point cache holds positions only: refused)");
  cmd->add_option("-o,--output", a.output, "Write .pc2 (every pose), or .obj/.ply/.glb/.gltf (one pose)");
  return cmd;
}

int run_pose(const PoseArgs& a, Client& client, bool json) {
  // Refused before any call: a file named for a format the command does not write, and normals
  // asked for a file that cannot hold them.
  const bool point_cache = mesh_io::lowercase_extension(a.output) == ".pc2";
  if (!a.output.empty()) {
    if (const std::string bad = check_output_extension(
            a.output, {".pc2", ".obj", ".ply", ".glb", ".gltf"},
            "pose writes a point cache (every pose) or a mesh (one pose)");
        !bad.empty()) {
      return fail("pose", bad);
    }
    if (point_cache && a.normals) {
      return fail("pose", "--normals with -o " + a.output +
                              ": a .pc2 point cache holds positions only; write a mesh (.obj, .ply, .glb, .gltf) "
                              "for normals, or drop --normals");
    }
  }
  const v1::ModelSummary model = client.describe_model(a.model, a.version);
  uint32_t bones = 0;
  for (const auto& v : model.versions()) {
    if (a.version == 0 ? v.version() == model.default_version() : v.version() == a.version) bones = v.bone_count();
  }
  if (bones == 0) return fail("pose", "model '" + a.model + "' has no skeleton to pose");
  auto poses = tools::read_pose_file(a.pose_file, tools::pose_space(a.pose_space), bones);
  if (!poses) return fail("pose", "--pose-file: " + poses.error().message);

  SkinningOptions options;
  options.version = a.version;
  options.include_normals = a.normals;
  options.lod_level = a.lod_level;
  const SkinningResult result = client.evaluate_skeleton_pose(a.model, *poses, options);
  const uint32_t points = result.poses.front().points.point_count;

  if (point_cache) {
    mesh_io::PointCache cache;
    cache.num_points = static_cast<int>(points);
    cache.samples.resize(static_cast<Eigen::Index>(result.poses.size()), Eigen::Index{points} * 3);
    for (size_t p = 0; p < result.poses.size(); ++p) {
      cache.samples.row(static_cast<Eigen::Index>(p)) =
          Eigen::Map<const Eigen::RowVectorXf>(result.poses[p].points.values.data(), Eigen::Index{points} * 3);
    }
    if (auto written = mesh_io::write_pc2(a.output, cache); !written.ok()) return fail("pose", written.error().message);
  } else if (!a.output.empty()) {
    if (result.poses.size() != 1) {
      return fail("pose", "-o " + a.output + ": a mesh holds one pose, the file has " +
                              std::to_string(result.poses.size()) + " (write .pc2 for a sequence)");
    }
    // The faces of this level, from the LOD service (at rest: only its indices are used).
    v1::GetLodRequest request;
    request.mutable_model()->set_name(a.model);
    request.mutable_model()->set_version(result.model_version);
    request.set_level(a.lod_level);
    request.set_form(v1::GetLodRequest::FORM_POSED);
    const LodMesh faces = client.get_lod(request);
    mesh_io::PosedMesh mesh;
    mesh.points = as_matrix(result.poses.front().points);
    mesh.faces = Eigen::Map<const Eigen::Matrix<uint32_t, Eigen::Dynamic, 3, Eigen::RowMajor>>(
                     faces.indices.data(), faces.header.face_count(), 3)
                     .cast<int32_t>();
    if (a.normals) mesh.normals = as_matrix(result.poses.front().normals);
    if (auto written = mesh_io::write_posed_mesh(a.output, mesh); !written.ok()) {
      return fail("pose", written.error().message);
    }
  }

  // Each pose's bounding box: what a caller checks first when a pose looks wrong.
  nlohmann::json boxes = nlohmann::json::array();
  for (const auto& pose : result.poses) {
    const PointMatrix p = as_matrix(pose.points);
    const Eigen::RowVector3f lo = p.colwise().minCoeff(), hi = p.colwise().maxCoeff();
    boxes.push_back({{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}});
  }
  if (json) {
    print_json({{"model", a.model},
                {"version", result.model_version},
                {"poses", result.poses.size()},
                {"points", points},
                {"lod_level", a.lod_level},
                {"normals", a.normals},
                {"bounds", boxes},
                {"output", a.output}});
    return 0;
  }
  std::printf("%s version %llu, level %u: %zu pose%s × %u points%s\n", a.model.c_str(),
              static_cast<unsigned long long>(result.model_version), a.lod_level, result.poses.size(),
              result.poses.size() == 1 ? "" : "s", points,
              a.normals ? " with normals" : "");
  for (size_t p = 0; p < boxes.size(); ++p) {
    const auto& lo = boxes[p]["min"];
    const auto& hi = boxes[p]["max"];
    std::printf("  pose %zu: bounds (%.4g, %.4g, %.4g) – (%.4g, %.4g, %.4g)\n", p, lo[0].get<double>(),
                lo[1].get<double>(), lo[2].get<double>(), hi[0].get<double>(), hi[1].get<double>(),
                hi[2].get<double>());
  }
  if (!a.output.empty()) std::printf("wrote %s\n", a.output.c_str());
  return 0;
}

}  // namespace animspace::cli
