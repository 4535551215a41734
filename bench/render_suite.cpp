// The render suite (issue #7): thumbnails and LOD meshes as a render-farm node sees them, from a
// real animspaced on loopback.
//
// Models, written to a temporary repository at the start:
//   cow     the cow rig converted to animation space (`animspace import-rig`) with levels of detail
//           (`animspace build-lod`, Merry 2007 ch. 6) — drawn at its rest pose
//   horse   horse-gallop as a mesh sequence — drawn at a stored frame
//   crane   crane as a mesh sequence — drawn at a stored frame
//
// Thumbnails: RenderThumbnail at 256² and 1024² (multisampling 4, Blinn-Phong, auto-framed), one
// call after another on a warm daemon; the client's wall time per call, PNG encoding and the
// round trip included. Baseline, same run: the same scene drawn and encoded in this process
// with the same renderer (core/render) — what the service adds on top of drawing.
//
// LOD streaming: GetLod of the cow's full-detail level in both forms, with the default chunk
// size and with small chunks, in MB/s of payload received and reassembled. Baseline, same run:
// EvaluateSkeletonPose of the same level at its rest pose — the same vertices in one unary
// message.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "animspace/v1/skinning.grpc.pb.h"
#include "bench/scratch_directory.h"
#include "bench/serving.h"
#include "bench/suites.h"
#include "clients/cpp/client.h"
#include "clients/cpp/tools/quantile.h"
#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/mesh_io/sequence_io.h"
#include "core/container/sections.h"
#include "core/render/png.h"
#include "core/render/renderer.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"

namespace animspace::bench {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kWarmup = 3;
constexpr int kThumbnails256 = 40;
constexpr int kThumbnails1024 = 15;
constexpr int kLodRepetitions = 8;
// horse-gallop and crane are drawn at this stored frame (a pose, not the reference).
constexpr uint32_t kFrame = 10;

struct Mesh {
  std::string name;
  PointMatrix points;  // what the thumbnail draws, for the in-process baseline
  FaceMatrix faces;
  PointMatrix normals;
};

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// A mesh sequence as the daemon serves one: rest points (the reference), faces, frames.
std::optional<Mesh> write_sequence_model(const std::filesystem::path& data, const std::string& dataset,
                                         const std::string& name, const std::filesystem::path& repository) {
  auto sequence = mesh_io::load_sequence(data / dataset);
  if (!sequence) {
    std::printf("render: %s: %s (skipped)\n", dataset.c_str(), sequence.error().message.c_str());
    return std::nullopt;
  }
  container::ModelContainer model;
  model.metadata()["kind"] = container::kind_name(container::ModelKind::kMeshSequence);
  model.metadata()["description"] = dataset + " (animspace-bench render)";
  model.set_points(container::sections::kRestPoints, sequence->reference.V);
  model.set_faces(container::sections::kFaces, sequence->reference.F);
  model.set_matrix(container::sections::kSequenceFrames, FrameMatrix(sequence->frames.samples));
  const auto dir = repository / name / "1";
  std::filesystem::create_directories(dir);
  if (auto written = container::write_file(dir / "model.anim", model); !written.ok()) {
    std::printf("render: %s\n", written.error().message.c_str());
    return std::nullopt;
  }
  Mesh mesh{name, {}, sequence->reference.F, {}};
  mesh.points = Eigen::Map<const PointMatrix>(sequence->frames.samples.row(kFrame).data(),
                                              sequence->reference.V.rows(), 3);
  return mesh;
}

// The cow through the command line a person would use: import-rig, then build-lod.
std::optional<Mesh> write_cow_model(const std::filesystem::path& data, const std::filesystem::path& scratch,
                                    const std::filesystem::path& repository) {
  const auto dir = data / "cow-rig";
  const std::string cli = harness::program_path("animspace").string();
  const auto imported = scratch / "cow-imported.anim";
  const std::string import = cli + " import-rig --mesh " + (dir / "cow.obj").string() + " --tgf " +
                             (dir / "cow.tgf").string() + " --dmat " + (dir / "cow.DMAT").string() + " -o " +
                             imported.string() + " > /dev/null";
  // Every level, as a person would build them (the suite draws and streams level 0).
  const std::string build = cli + " build-lod " + imported.string() + " --sample-poses 16 -o " +
                            repository.string() + " --model cow --version 1 > /dev/null";
  const auto t0 = Clock::now();
  if (std::system(import.c_str()) != 0 || std::system(build.c_str()) != 0) {
    std::printf("render: building the cow model failed (%s)\n", cli.c_str());
    return std::nullopt;
  }
  std::printf("render: cow imported and its levels built in %.1f s\n", ms_since(t0) / 1000);
  auto stored = container::read_file(repository / "cow" / "1" / "model.anim");
  if (!stored) return std::nullopt;
  auto model = animation_space::load(*stored, "cow");
  if (!model) return std::nullopt;
  Mesh mesh{"cow", {}, model->faces, {}};
  const auto rest = animation_space::rest_pose(model->skeleton);
  animation_space::evaluate(*model, rest, mesh.points);
  if (model->has_tangents()) animation_space::evaluate_normals(*model, rest, mesh.normals);
  return mesh;
}

v1::RenderThumbnailRequest thumbnail_request(const std::string& model, int size) {
  v1::RenderThumbnailRequest request;
  request.mutable_model()->set_name(model);
  request.set_width_px(static_cast<uint32_t>(size));
  request.set_height_px(static_cast<uint32_t>(size));
  if (model != "cow") request.set_sequence_frame(kFrame);
  return request;
}

// Drawn and encoded in this process: the baseline of each thumbnail row.
std::vector<double> in_process_ms(render::Renderer& renderer, const Mesh& mesh, int size, int count) {
  render::Scene scene;
  scene.width = scene.height = size;
  scene.points = mesh.points;
  scene.faces = mesh.faces;
  scene.normals = mesh.normals;
  std::vector<double> times;
  for (int i = 0; i < kWarmup + count; ++i) {
    const auto t0 = Clock::now();
    auto image = renderer.render(scene);
    if (!image) {
      std::printf("render: in process: %s\n", image.error().message.c_str());
      return {};
    }
    auto png = render::encode_png(*image);
    if (i >= kWarmup) times.push_back(ms_since(t0));
  }
  return times;
}

void thumbnails(Client& client, render::Renderer* renderer, const std::vector<Mesh>& meshes, nlohmann::json& out) {
  std::printf("\n%-6s %6s %9s %9s %11s %12s %12s %9s\n", "mesh", "size", "p50_ms", "p99_ms", "server_p50",
              "in_proc_p50", "in_proc_p99", "png_kB");
  for (const Mesh& mesh : meshes) {
    for (int size : {256, 1024}) {
      const int count = size == 256 ? kThumbnails256 : kThumbnails1024;
      std::vector<double> wall, server;
      size_t png_bytes = 0;
      std::string error;
      for (int i = 0; i < kWarmup + count && error.empty(); ++i) {
        const auto t0 = Clock::now();
        try {
          const auto response = client.render_thumbnail(thumbnail_request(mesh.name, size));
          if (i < kWarmup) continue;
          wall.push_back(ms_since(t0));
          server.push_back(response.render_ms);
          png_bytes = response.png.size();
        } catch (const RpcError& e) {
          error = e.what();
        }
      }
      const auto baseline = renderer != nullptr ? in_process_ms(*renderer, mesh, size, count) : std::vector<double>{};
      nlohmann::json row{{"mesh", mesh.name},
                         {"width", size},
                         {"height", size},
                         {"vertices", mesh.points.rows()},
                         {"faces", mesh.faces.rows()},
                         {"count", wall.size()},
                         {"p50_ms", tools::quantile(wall, 0.5)},
                         {"p99_ms", tools::quantile(wall, 0.99)},
                         {"server_render_p50_ms", tools::quantile(server, 0.5)},
                         {"in_process_p50_ms", tools::quantile(baseline, 0.5)},
                         {"in_process_p99_ms", tools::quantile(baseline, 0.99)},
                         {"png_bytes", png_bytes}};
      if (!error.empty()) row["error"] = error;
      std::printf("%-6s %6d %9.1f %9.1f %11.1f %12.1f %12.1f %9.1f%s\n", mesh.name.c_str(), size,
                  tools::quantile(wall, 0.5), tools::quantile(wall, 0.99), tools::quantile(server, 0.5), tools::quantile(baseline, 0.5),
                  tools::quantile(baseline, 0.99), double(png_bytes) / 1024, error.empty() ? "" : (" ERROR " + error).c_str());
      std::fflush(stdout);
      out.push_back(row);
    }
  }
}

size_t payload_bytes(const LodMesh& mesh) {
  return 4 * (mesh.positions.size() + mesh.influence_offsets.size() + mesh.bone_indices.size() +
              mesh.animation_positions.size() + mesh.geomorph_delta.size() + mesh.indices.size());
}

void lod_streaming(Client& client, nlohmann::json& out) {
  std::printf("\n%-34s %10s %9s %9s %9s\n", "cow level 0", "MB", "p50_ms", "MB/s", "vs unary");
  // Baseline: the same level's vertices in one unary message.
  auto bones = client.describe_model("cow").versions(0).bone_count();
  v1::EvaluateSkeletonPoseRequest unary;
  unary.mutable_model()->set_name("cow");
  auto* pose = unary.add_poses();
  pose->set_space(v1::SkeletonPose::SPACE_LOCAL);
  pose->set_bone_count(bones);
  // Local identity transforms: the rest pose.
  std::string transforms;
  for (uint32_t j = 0; j < bones; ++j) {
    const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    transforms.append(reinterpret_cast<const char*>(identity), sizeof(identity));
  }
  pose->set_transforms(transforms);
  std::vector<double> unary_ms;
  size_t unary_bytes = 0;
  for (int i = 0; i < kWarmup + kLodRepetitions; ++i) {
    const auto t0 = Clock::now();
    grpc::ClientContext context;
    client.authorize(&context);
    v1::EvaluateSkeletonPoseResponse response;
    const auto status =
        v1::SkinningService::NewStub(client.channel())->EvaluateSkeletonPose(&context, unary, &response);
    if (!status.ok()) {
      std::printf("render: EvaluateSkeletonPose: %s\n", status.error_message().c_str());
      return;
    }
    if (i >= kWarmup) unary_ms.push_back(ms_since(t0));
    unary_bytes = response.poses(0).points().data().size();
  }
  const double unary_rate = double(unary_bytes) / 1e6 / (tools::quantile(unary_ms, 0.5) / 1000);
  std::printf("%-34s %10.2f %9.1f %9.1f %9s\n", "baseline: EvaluateSkeletonPose", double(unary_bytes) / 1e6,
              tools::quantile(unary_ms, 0.5), unary_rate, "1.00");
  out.push_back({{"mode", "unary_evaluate_skeleton_pose"}, {"bytes", unary_bytes},
                 {"p50_ms", tools::quantile(unary_ms, 0.5)}, {"mb_per_s", unary_rate}});

  struct Variant {
    const char* label;
    v1::GetLodRequest::Form form;
    uint32_t vertices_per_chunk;
  };
  for (const Variant& v : {Variant{"posed, default chunks", v1::GetLodRequest::FORM_POSED, 0},
                           Variant{"posed, 1024-vertex chunks", v1::GetLodRequest::FORM_POSED, 1024},
                           Variant{"animation space, default chunks", v1::GetLodRequest::FORM_ANIMATION_SPACE, 0},
                           Variant{"animation space, 1024-vertex chunks", v1::GetLodRequest::FORM_ANIMATION_SPACE,
                                   1024}}) {
    v1::GetLodRequest request;
    request.mutable_model()->set_name("cow");
    request.set_level(0);
    request.set_form(v.form);
    request.set_vertices_per_chunk(v.vertices_per_chunk);
    std::vector<double> times;
    size_t bytes = 0;
    std::string error;
    for (int i = 0; i < kWarmup + kLodRepetitions && error.empty(); ++i) {
      const auto t0 = Clock::now();
      try {
        const LodMesh mesh = client.get_lod(request);
        if (i >= kWarmup) times.push_back(ms_since(t0));
        bytes = payload_bytes(mesh);
      } catch (const std::exception& e) {
        error = e.what();
      }
    }
    const double rate = times.empty() ? 0 : double(bytes) / 1e6 / (tools::quantile(times, 0.5) / 1000);
    nlohmann::json row{{"mode", std::string("get_lod ") + v.label},
                       {"bytes", bytes},
                       {"p50_ms", tools::quantile(times, 0.5)},
                       {"mb_per_s", rate},
                       {"ratio_to_unary", unary_rate > 0 ? rate / unary_rate : 0}};
    if (!error.empty()) row["error"] = error;
    std::printf("%-34s %10.2f %9.1f %9.1f %9.2f%s\n", v.label, double(bytes) / 1e6, tools::quantile(times, 0.5), rate,
                unary_rate > 0 ? rate / unary_rate : 0.0, error.empty() ? "" : (" ERROR " + error).c_str());
    out.push_back(row);
  }
}

}  // namespace

nlohmann::json run_render_suite(const SuiteOptions& options) {
  nlohmann::json results = nlohmann::json::object();
  if (!options.data) {
    std::printf("render: needs --data (cow-rig, horse-gallop, crane); skipped\n");
    return results;
  }
  const ScratchDirectory scratch_directory("render");
  const std::filesystem::path& scratch = scratch_directory.path();
  const auto repository = scratch / "repository";
  std::filesystem::create_directories(repository);

  std::vector<Mesh> meshes;
  if (auto cow = write_cow_model(*options.data, scratch, repository)) meshes.push_back(std::move(*cow));
  if (auto horse = write_sequence_model(*options.data, "horse-gallop", "horse", repository)) {
    meshes.push_back(std::move(*horse));
  }
  if (auto crane = write_sequence_model(*options.data, "crane", "crane", repository)) {
    meshes.push_back(std::move(*crane));
  }

  std::unique_ptr<harness::DaemonProcess> daemon;
  try {
    daemon = std::make_unique<harness::DaemonProcess>(
        std::vector<std::string>{"--model-repository", repository.string(), "--log-level", "warn", "--miss-log-dir",
                                 scratch.string()},
        scratch);
  } catch (const std::exception& e) {
    std::printf("render: the daemon did not start: %s\n", e.what());
    return results;
  }
  Client client(daemon->address());
  if (!wait_until_serving(daemon->address(), std::chrono::seconds(30))) {
    std::printf("render: the daemon never reported SERVING\n%s\n", daemon->log().c_str());
    return results;
  }
  const auto info = client.server_info();
  std::printf("render: daemon renderer: %s\n", info.renderer().c_str());
  results["daemon_renderer"] = info.renderer();

  // The in-process baseline draws with the same platform the daemon chose.
  auto renderer = render::make_egl_renderer(render::EglPlatform::kAuto);
  if (!renderer) std::printf("render: no in-process renderer: %s\n", renderer.error().message.c_str());
  if (renderer) results["in_process_renderer"] = (*renderer)->description();

  results["thumbnails"] = nlohmann::json::array();
  thumbnails(client, renderer ? renderer->get() : nullptr, meshes, results["thumbnails"]);
  results["lod_streaming"] = nlohmann::json::array();
  if (!meshes.empty() && meshes.front().name == "cow") lod_streaming(client, results["lod_streaming"]);

  daemon.reset();  // before the scratch directory it runs in goes
  return results;
}

}  // namespace animspace::bench
