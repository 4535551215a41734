// The atlas suite (issue #37): a texture atlas balanced across poses (Merry 2007 ch. 5) against
// the rest-pose atlas and Blender's own unwrappers, judged by texture stretch on poses none of
// them saw.
//
//   cow-rig             the ground-truth LBS rig converted to animation space (§3.1). P from 200
//                       random poses (every joint turned about a random axis by up to 35°, as
//                       the lod suite); stretch on 200 other random poses (another seed). The
//                       rig's own 7 poses are not used: the cow is posed exactly for any joint
//                       rotations, so random rotations are held-out poses of the same kind.
//   horse-gallop-block  the animation-space horse fitted to the gallop (fit_sequence.h, as the lod
//                       suite); P from the first three quarters of the fitted poses, stretch on
//                       the last quarter (a contiguous block of motion none of the methods saw).
//
// Methods:
//   animspace-atlas            ours: charts, flattening and balance under P (core/atlas)
//   rest-pose-atlas            the same code with the rest pose's P (what a static unwrap gives)
//   rest-pose-flattening-our-charts   our charts, flattened and balanced with the rest pose's P
//                              (isolates the flattening: the same charts as animspace-atlas)
//   blender-smart-project      Blender's bpy.ops.uv.smart_project (its own charts), rest pose
//   blender-abf-our-charts     Blender's bpy.ops.uv.unwrap(method='ANGLE_BASED') with our charts'
//                              borders marked as seams (same charts, Blender's flattening and packing)
// Blender (Debian's blender, headless: bench/blender_unwrap.py) imports the rest pose as OBJ; a
// machine without it skips those rows. Every method's stretch comes from one routine
// (atlas::stretch_across_poses: each held-out pose posed by the model, Sander 2001's normalised
// L2 and L∞ stretch on it, RMS / max over poses); utilisation is the charts' UV area over the
// atlas's (1).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/cow_rig.h"
#include "bench/scratch_directory.h"
#include "bench/suites.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/import.h"
#include "core/animspace/metrics.h"
#include "core/atlas/atlas.h"
#include "core/atlas/stretch.h"
#include "core/mesh_io/sequence_io.h"
#include "harness/build_tree.h"

namespace animspace::bench {

namespace {

namespace as = animation_space;

constexpr double kMaxJointAngle = 35.0 * std::numbers::pi / 180.0;
constexpr int kCowPoses = 200;
constexpr double kGutter = 1.0 / 512;

struct Dataset {
  std::string name;
  as::AnimationSpaceModel model;
  as::AnimationSpaceMetrics metrics;   // from the training poses only
  std::vector<PointMatrix> held_out;   // posed meshes of the held-out poses
  size_t training_poses = 0;
};

std::vector<PointMatrix> pose_all(const as::AnimationSpaceModel& model, const std::vector<as::TransformList>& poses) {
  std::vector<PointMatrix> out(poses.size());
  for (size_t i = 0; i < poses.size(); ++i) as::evaluate(model, poses[i], out[i]);
  return out;
}

std::optional<Dataset> cow_dataset(const std::filesystem::path& data) {
  auto rig = read_cow_rig(data);
  if (!rig) return std::nullopt;
  Dataset d;
  d.name = "cow-rig";
  d.model = as::from_linear_blend(rig->model);
  const auto training = as::random_joint_rotation_poses(d.model.skeleton, kCowPoses, kMaxJointAngle, 7);
  auto metrics = as::metrics_from_poses(d.model.skeleton, training);
  if (!metrics) {
    std::printf("cow-rig: %s (skipped)\n", metrics.error().message.c_str());
    return std::nullopt;
  }
  d.metrics = std::move(*metrics);
  d.training_poses = training.size();
  d.held_out = pose_all(d.model, as::random_joint_rotation_poses(d.model.skeleton, kCowPoses, kMaxJointAngle, 2026));
  return d;
}

std::optional<Dataset> horse_block_dataset(const std::filesystem::path& data, const SkinningSuiteOptions& skinning) {
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
  // The fit sees only the training block: the held-out block's frames are neither fitted nor in P.
  const Eigen::Index seen = frames.rows() - (frames.rows() + 3) / 4;
  const FrameMatrix training = frames.topRows(seen);
  auto skeleton = as::fit_sequence_skeleton(sequence->reference, training, options, nullptr);
  if (!skeleton) {
    std::printf("horse-gallop: %s (skipped)\n", skeleton.error().message.c_str());
    return std::nullopt;
  }
  auto model = as::fit_sequence_model(sequence->reference, training, *skeleton, options.fit, nullptr);
  if (!model) {
    std::printf("horse-gallop: %s (skipped)\n", model.error().message.c_str());
    return std::nullopt;
  }
  Dataset d;
  d.name = "horse-gallop-block";
  d.model = std::move(*model);
  d.model.faces = sequence->reference.F;
  auto metrics = as::metrics_from_poses(d.model.skeleton, skeleton->training_poses);
  if (!metrics) {
    std::printf("horse-gallop: %s (skipped)\n", metrics.error().message.c_str());
    return std::nullopt;
  }
  d.metrics = std::move(*metrics);
  d.training_poses = skeleton->training_poses.size();
  // Held out: the captured frames themselves (not the model's reconstruction of them), so the
  // stretch is that of the real surface in motion the atlas never saw.
  const auto V = static_cast<Eigen::Index>(sequence->reference.V.rows());
  for (Eigen::Index f = seen; f < frames.rows(); ++f) {
    PointMatrix points(V, 3);
    for (Eigen::Index v = 0; v < V; ++v) points.row(v) = frames.block(f, 3 * v, 1, 3);
    d.held_out.push_back(std::move(points));
  }
  return d;
}

struct Row {
  std::string method;
  atlas::Stretch poses;
  atlas::Stretch rest;
  int charts = 0;
  double utilisation = 0;
  double seconds = 0;
};

// Charts of a UV map: faces joined across an edge whose two corners have the same UVs on both sides.
int uv_islands(const FaceMatrix& faces, const atlas::CornerUvs& uvs) {
  const auto adjacency = atlas::face_adjacency(faces);
  std::vector<int> parent(static_cast<size_t>(faces.rows()));
  for (size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  const auto find = [&](int x) {
    while (parent[static_cast<size_t>(x)] != x) x = parent[static_cast<size_t>(x)] = parent[static_cast<size_t>(parent[static_cast<size_t>(x)])];
    return x;
  };
  const auto corner_of = [&](Eigen::Index f, int32_t v) {
    for (int k = 0; k < 3; ++k) {
      if (faces(f, k) == v) return Eigen::Vector2d(uvs.row(3 * f + k).transpose());
    }
    return Eigen::Vector2d(-1, -1);
  };
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t g = adjacency(f, k);
      if (g < 0) continue;
      const int32_t a = faces(f, k), b = faces(f, (k + 1) % 3);
      if ((corner_of(f, a) - corner_of(g, a)).norm() < 1e-7 && (corner_of(f, b) - corner_of(g, b)).norm() < 1e-7) {
        parent[static_cast<size_t>(find(static_cast<int>(f)))] = find(g);
      }
    }
  }
  std::set<int> roots;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) roots.insert(find(static_cast<int>(f)));
  return static_cast<int>(roots.size());
}

double uv_area(const atlas::CornerUvs& uvs) {
  double area = 0;
  for (Eigen::Index f = 0; f < uvs.rows() / 3; ++f) {
    const Eigen::Vector2d a = uvs.row(3 * f), b = uvs.row(3 * f + 1), c = uvs.row(3 * f + 2);
    area += 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
  }
  return area;
}

// Blender's unwrap of the rest pose; nullopt (with a message) when Blender is absent or fails.
std::optional<atlas::CornerUvs> blender_unwrap(const Dataset& d, const std::string& method,
                                               const std::vector<int32_t>* charts, double* seconds) {
  ScratchDirectory scratch("atlas");
  const auto obj = scratch.path() / "rest.obj", out = scratch.path() / "uv.txt", seams = scratch.path() / "seams.txt";
  {
    PointMatrix rest;
    as::evaluate(d.model, d.model.skeleton.rest, rest);
    std::ofstream file(obj);
    file.precision(9);
    for (Eigen::Index v = 0; v < rest.rows(); ++v) file << "v " << rest(v, 0) << ' ' << rest(v, 1) << ' ' << rest(v, 2) << '\n';
    for (Eigen::Index f = 0; f < d.model.faces.rows(); ++f) {
      file << "f " << d.model.faces(f, 0) + 1 << ' ' << d.model.faces(f, 1) + 1 << ' ' << d.model.faces(f, 2) + 1 << '\n';
    }
  }
  std::string command = "blender -b --factory-startup --python '" +
                        (harness::source_dir() / "bench" / "blender_unwrap.py").string() + "' -- '" +
                        obj.string() + "' '" + out.string() + "' " + method + " " + std::to_string(kGutter);
  if (charts) {
    const auto adjacency = atlas::face_adjacency(d.model.faces);
    std::ofstream file(seams);
    for (Eigen::Index f = 0; f < d.model.faces.rows(); ++f) {
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency(f, k);
        if (g > f && (*charts)[static_cast<size_t>(f)] != (*charts)[static_cast<size_t>(g)]) {
          file << d.model.faces(f, k) << ' ' << d.model.faces(f, (k + 1) % 3) << '\n';
        }
      }
    }
    command += " '" + seams.string() + "'";
  }
  command += " > '" + (scratch.path() / "blender.log").string() + "' 2>&1";
  const auto start = std::chrono::steady_clock::now();
  const int rc = std::system(command.c_str());
  *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::ifstream in(out);
  if (rc != 0 || !in) {
    std::printf("%s: blender %s failed or is not installed (rc %d; skipped)\n", d.name.c_str(), method.c_str(), rc);
    return std::nullopt;
  }
  atlas::CornerUvs uvs(3 * d.model.faces.rows(), 2);
  std::string line;
  for (Eigen::Index f = 0; f < d.model.faces.rows(); ++f) {
    if (!std::getline(in, line)) {
      std::printf("%s: blender %s wrote fewer faces than the mesh has (skipped)\n", d.name.c_str(), method.c_str());
      return std::nullopt;
    }
    std::istringstream fields(line);
    int32_t v[3];
    double uv[6];
    fields >> v[0] >> v[1] >> v[2] >> uv[0] >> uv[1] >> uv[2] >> uv[3] >> uv[4] >> uv[5];
    // Blender may rotate a triangle's corner list: match corners by vertex.
    for (int k = 0; k < 3; ++k) {
      int j = 0;
      while (j < 3 && v[j] != d.model.faces(f, k)) ++j;
      if (!fields || j == 3) {
        std::printf("%s: blender %s changed face %ld (skipped)\n", d.name.c_str(), method.c_str(), static_cast<long>(f));
        return std::nullopt;
      }
      uvs.row(3 * f + k) << uv[2 * j], uv[2 * j + 1];
    }
  }
  return uvs;
}

nlohmann::json run_dataset(const Dataset& d) {
  std::printf("\n%s: %d vertices, %ld faces, %d bones; P from %zu poses, stretch on %zu held-out poses\n", d.name.c_str(),
              d.model.vertex_count(), static_cast<long>(d.model.faces.rows()), d.model.bone_count(), d.training_poses,
              d.held_out.size());
  PointMatrix rest;
  as::evaluate(d.model, d.model.skeleton.rest, rest);
  std::vector<Row> rows;
  const auto measure = [&](Row row, const atlas::CornerUvs& uvs) {
    row.poses = atlas::stretch_across_poses(d.held_out, d.model.faces, uvs);
    row.rest = atlas::stretch_across_poses({rest}, d.model.faces, uvs);
    rows.push_back(row);
  };
  std::optional<std::vector<int32_t>> our_charts;
  for (const bool poses : {true, false}) {
    atlas::AtlasOptions options;
    options.pack.gutter = kGutter;
    const auto start = std::chrono::steady_clock::now();
    auto metrics = poses ? Result<as::AnimationSpaceMetrics>(d.metrics) : atlas::rest_pose_metrics(d.model.skeleton);
    if (!metrics) {
      std::printf("%s: %s\n", d.name.c_str(), metrics.error().message.c_str());
      continue;
    }
    auto built = atlas::build_atlas(d.model, *metrics, options);
    if (!built) {
      std::printf("%s: %s\n", d.name.c_str(), built.error().message.c_str());
      continue;
    }
    Row row;
    row.method = poses ? "animspace-atlas" : "rest-pose-atlas";
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    row.charts = built->atlas.chart_count;
    row.utilisation = built->utilisation;
    std::printf("  %s: segment %.2f s, flatten %.2f s, pack %.2f s, %d charts started from Tutte, %d split rounds\n",
                row.method.c_str(), built->segment_seconds, built->flatten_seconds, built->pack_seconds,
                built->tutte_charts, built->split_rounds);
    if (poses) our_charts = built->atlas.chart_of_face;
    measure(row, built->atlas.uvs);
  }
  if (our_charts) {
    // The same charts as ours, flattened for the rest pose only.
    const auto start = std::chrono::steady_clock::now();
    auto rest_metrics = atlas::rest_pose_metrics(d.model.skeleton);
    auto g = rest_metrics ? atlas::face_metrics(d.model, *rest_metrics) : Result<atlas::FaceMetrics>(rest_metrics.error());
    atlas::AtlasOptions options;
    options.pack.gutter = kGutter;
    auto built = g ? atlas::flatten_and_pack(d.model.faces, *g, *our_charts, options) : Result<atlas::AtlasReport>(g.error());
    if (built) {
      Row row;
      row.method = "rest-pose-flattening-our-charts";
      row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      row.charts = built->atlas.chart_count;
      row.utilisation = built->utilisation;
      measure(row, built->atlas.uvs);
    } else {
      std::printf("%s: %s\n", d.name.c_str(), built.error().message.c_str());
    }
  }
  const auto blender_row = [&](const std::string& name, const std::string& method, const std::vector<int32_t>* charts) {
    Row row;
    row.method = name;
    auto uvs = blender_unwrap(d, method, charts, &row.seconds);
    if (!uvs) return;
    row.charts = uv_islands(d.model.faces, *uvs);
    row.utilisation = uv_area(*uvs);
    measure(row, *uvs);
  };
  blender_row("blender-smart-project", "smart", nullptr);
  if (our_charts) blender_row("blender-abf-our-charts", "angle", &*our_charts);

  std::printf("%-32s %10s %10s %10s %8s %7s %12s %11s %9s\n", "method", "L2 poses", "Linf poses", "L2 rest", "flipped",
              "charts", "utilisation", "efficiency", "seconds");
  nlohmann::json out = nlohmann::json::array();
  for (const Row& r : rows) {
    const double efficiency = r.utilisation / (r.poses.l2 * r.poses.l2);  // thesis Table 8.6's texture efficiency
    std::printf("%-32s %10.4f %10.3f %10.4f %8ld %7d %12.3f %11.3f %9.2f\n", r.method.c_str(), r.poses.l2, r.poses.linf,
                r.rest.l2, static_cast<long>(r.poses.flipped), r.charts, r.utilisation, efficiency, r.seconds);
    out.push_back({{"method", r.method},
                   {"dataset", d.name},
                   {"l2_stretch_poses", r.poses.l2},
                   {"linf_stretch_poses", r.poses.linf},
                   {"l2_stretch_rest", r.rest.l2},
                   {"flipped_faces", r.poses.flipped},
                   {"charts", r.charts},
                   {"utilisation", r.utilisation},
                   {"texture_efficiency", efficiency},
                   {"seconds", r.seconds},
                   {"held_out_poses", d.held_out.size()},
                   {"training_poses", d.training_poses}});
  }
  return out;
}

}  // namespace

nlohmann::json run_atlas_suite(const SuiteOptions& suite) {
  nlohmann::json rows = nlohmann::json::array();
  if (!suite.data) {
    std::printf("atlas: needs --data (cow-rig, horse-gallop); skipped\n");
    return rows;
  }
  RowProgress progress("atlas");
  for (const std::string& name : suite.atlas_datasets) {
    progress.starting(name);
    std::optional<Dataset> d = name == "cow-rig"              ? cow_dataset(*suite.data)
                               : name == "horse-gallop-block" ? horse_block_dataset(*suite.data, suite.skinning)
                                                              : std::nullopt;
    if (!d) {
      if (name != "cow-rig" && name != "horse-gallop-block") std::printf("%s: unknown dataset (skipped)\n", name.c_str());
      continue;
    }
    for (auto& r : run_dataset(*d)) rows.push_back(r);
  }
  return rows;
}

}  // namespace animspace::bench
