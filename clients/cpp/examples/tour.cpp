// The README's "Query it from C++", compiled and run by the tests against a real daemon so that
// the snippet a newcomer pastes keeps working: key points (and check points) in and the whole
// pose out, a HIT of the key points alone overturned by the check points, a miss completed with
// the real full pose, then with the failing regions' points only, a sequence streamed with
// back-pressure, a skeleton pose, a LOD mesh and a thumbnail. "Your posing engine" is the demo's expensive arm rig (core/demo), the one
// the demo's arm-pmsc model was trained on.
//
//   build/bin/animspace-client-tour [SERVER [PNG]]   (default server 127.0.0.1:50051; the
//                                                     thumbnail is saved only when PNG is given)
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "clients/cpp/client.h"
#include "clients/cpp/coordinates.h"
#include "core/demo/bending_arm.h"

namespace {

constexpr const char* kUsage =
    "usage: animspace-client-tour [SERVER [PNG]]\n"
    "  Runs the README's C++ tour against a daemon serving the demo repository (make run).\n"
    "  SERVER  host:port of animspaced (default 127.0.0.1:50051)\n"
    "  PNG     where to save the thumbnail; without it nothing is written\n";

// Your posing engine's full pose, N×3 row-major float32: here the demo's expensive rig.
std::vector<float> full_pose(const animspace::demo::ArmRig& rig, const animspace::demo::ArmPose& pose) {
  const animspace::PointMatrix points = animspace::demo::pose_expensive(pose, rig);
  return {points.data(), points.data() + points.size()};
}

}  // namespace

int main(int argc, char** argv) try {
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (arg.size() > 1 && arg[0] == '-') {
      std::fprintf(stderr, "animspace-client-tour: unknown option '%s'\n%s", argv[i], kUsage);
      return 2;
    }
  }
  if (argc > 3) {
    std::fprintf(stderr, "animspace-client-tour: expected at most 2 arguments, got %d\n%s", argc - 1, kUsage);
    return 2;
  }
  const std::string server = argc > 1 ? argv[1] : "127.0.0.1:50051";
  const std::string png_path = argc > 2 ? argv[2] : "";
  animspace::ClientOptions options;  // deadline (10 s), token, TLS
  animspace::Client client(server, options);

  // The key points arm-pmsc needs, in order, and a pose your engine is asked for: the shoulder
  // swung three times further than the animation the model was trained on.
  const animspace::KeyPoints keys = client.describe_key_points("arm-pmsc");
  const animspace::demo::ArmRig rig = animspace::demo::make_arm_rig();
  animspace::demo::ArmPose unseen;
  unseen.elbow_angle_rad = 1.0;
  unseen.shoulder_angle_rad = 3 * animspace::demo::kDemoShoulderSwingRad;
  const std::vector<float> full = full_pose(rig, unseen);
  // A real engine computes only the key points and the check points (keys.check_point_indices:
  // points the projection never uses, where the server measures the estimate's error itself);
  // the demo rig computes all and picks them.
  const std::vector<float> values = keys.gather(full);
  const std::vector<float> checks = keys.gather_check_values(full);  // empty for a model without check points
  const animspace::KeyPointPose posed_keys{.key_values = values, .channel_count = keys.channel_count,
                                           .check_values = checks};
  const animspace::PoseResult result = client.evaluate_key_points("arm-pmsc", posed_keys);
  std::printf("%s e_key %.4g e_check %.4g alpha %.3f: %u points\n", animspace::cache_status_name(result.status),
              result.key_point_error, result.check_point_error, result.blend_weight, result.points.point_count);

  // What the check points are for: a dent the training never saw (a trained pose pressed in 0.05
  // deep around the first check point, as a collision might, and between the key points: no key
  // is moved) leaves the key points where the subspace puts them. From the key points alone (a
  // client from before check points) it is a HIT; with its check values the server measures the
  // dent and overturns it.
  if (!keys.check_point_indices.empty()) {
    const std::vector<float> trained = full_pose(rig, animspace::demo::demo_pose(14.0 / 120));  // an even frame
    std::vector<float> dented = trained;
    const float* centre = &trained[3 * size_t{keys.check_point_indices[0]}];
    const auto distance = [&](size_t i) {
      return std::hypot(trained[3 * i] - centre[0], trained[3 * i + 1] - centre[1], trained[3 * i + 2] - centre[2]);
    };
    float radius = 0.08f;
    for (uint32_t k : keys.indices) radius = std::min(radius, 0.9f * distance(k));
    for (size_t i = 0; i < dented.size() / 3; ++i) dented[3 * i + 2] -= 0.05f * std::max(0.0f, 1 - distance(i) / radius);
    const std::vector<float> dent_keys = keys.gather(dented), dent_checks = keys.gather_check_values(dented);
    const animspace::PoseResult alone = client.evaluate_key_points("arm-pmsc", {dent_keys, keys.channel_count});
    const animspace::PoseResult checked = client.evaluate_key_points(
        "arm-pmsc", {.key_values = dent_keys, .channel_count = keys.channel_count, .check_values = dent_checks});
    std::printf("dent: %s from the key points alone (e_key %.3g), %s with its check points (e_check %.3g)\n",
                animspace::cache_status_name(alone.status), alone.key_point_error,
                animspace::cache_status_name(checked.status), checked.check_point_error);
  }
  // result.points.values is N×3 row-major float32, e.g.
  //   Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>> v(
  //       result.points.values.data(), result.points.point_count, 3);

  // Half the bytes on the wire: the answer's points as per-channel 16-bit fixed point (or FLOAT16),
  // decoded to float32 by the client; points.max_error is what the encoding lost, measured by the
  // server. The verdict is the float32 one.
  animspace::EvaluateOptions compact_options;
  compact_options.points_encoding = animspace::v1::POINT_ENCODING_FIXED16;
  const animspace::PoseResult compact =
      client.evaluate_key_points("arm-pmsc", posed_keys, compact_options);
  std::printf("fixed16: %s, %u points within %.3g of float32\n", animspace::cache_status_name(compact.status),
              compact.points.point_count, compact.points.max_error);

  // Ten times the poses per core: the answer as its subspace coordinates p (M values instead of
  // N·D points), reconstructed here (clients/cpp/coordinates.h) from the basis GetBasis sent once
  // and the cache keeps on disk by model, version and checksum ($ANIMSPACE_BASIS_CACHE, else
  // ~/.cache/animspace/bases): the float32 answer within float rounding.
  animspace::BasisCache bases;
  animspace::EvaluateOptions coordinate_options;
  coordinate_options.points_encoding = animspace::v1::POINT_ENCODING_COORDINATES;
  animspace::PoseResult answer = client.evaluate_key_points("arm-pmsc", posed_keys, coordinate_options);
  const size_t sent = answer.coordinates.p.size();
  bases.reconstruct(client, "arm-pmsc", answer);
  const animspace::PoseResult float32 = client.evaluate_key_points("arm-pmsc", posed_keys);
  float largest = 0;
  for (size_t i = 0; i < answer.points.values.size(); ++i) {
    largest = std::max(largest, std::abs(answer.points.values[i] - float32.points.values[i]));
  }
  std::printf("coordinates: %s, %zu values reconstructed into %u points, within %.3g of float32\n",
              animspace::cache_status_name(answer.status), sent, answer.points.point_count, largest);

  // A studio character's basis is hundreds of megabytes: fetched in float16 it is half the bytes,
  // each value within 2^-11 of its size from float32, and the answer within about
  // 2^-11·(|mean_i| + Σ_j |A_ij p_j|) more (poses.proto states it exactly).
  const animspace::Basis half = animspace::make_basis(
      "arm-pmsc", client.get_basis("arm-pmsc", 0, {}, animspace::v1::POINT_ENCODING_FLOAT16));
  animspace::PoseResult half_answer = client.evaluate_key_points("arm-pmsc", posed_keys, coordinate_options);
  animspace::reconstruct(half, half_answer, half_answer.points);
  float half_largest = 0;
  for (size_t i = 0; i < half_answer.points.values.size(); ++i) {
    half_largest = std::max(half_largest, std::abs(half_answer.points.values[i] - float32.points.values[i]));
  }
  std::printf("float16 basis: each value within %.3g, the answer within %.3g of float32\n",
              static_cast<double>(half.values_max_error), static_cast<double>(half_largest));

  // Two kinds of subspace (issue #51): arm-articulated was trained on the same frames as arm-pmsc,
  // but its basis is the arm's skinning — its coordinates are the bones' affine transforms, 12
  // numbers each, then residual components — so the unseen swing stays inside it. Its answer is
  // reconstructed exactly as arm-pmsc's; here both are set against the rig's full pose.
  const animspace::v1::ModelVersion articulated = client.describe_model("arm-articulated").versions(0);
  const animspace::KeyPoints articulated_keys = client.describe_key_points("arm-articulated");
  const std::vector<float> articulated_values = articulated_keys.gather(full);
  const std::vector<float> articulated_checks = articulated_keys.gather_check_values(full);
  const animspace::KeyPointPose articulated_pose{.key_values = articulated_values,
                                                 .channel_count = articulated_keys.channel_count,
                                                 .check_values = articulated_checks};
  animspace::PoseResult articulated_answer =
      client.evaluate_key_points("arm-articulated", articulated_pose, coordinate_options);
  const size_t articulated_sent = articulated_answer.coordinates.p.size();
  bases.reconstruct(client, "arm-articulated", articulated_answer);
  const auto farthest = [&](const std::vector<float>& points) {
    float worst = 0;
    for (size_t i = 0; i + 2 < points.size(); i += 3) {
      const float dx = points[i] - full[i], dy = points[i + 1] - full[i + 1], dz = points[i + 2] - full[i + 2];
      worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
    }
    return worst;
  };
  // Its basis is mostly zeros (12 columns a bone, nonzero where the bone moves a point): the cache
  // fetched it SKINNED — each point's bones and terms, then the residual columns — the same basis
  // by its digests in a fraction of the bytes, reconstructed without the zeros.
  const auto articulated_basis = bases.get(client, "arm-articulated", articulated_answer.model_version,
                                           articulated_answer.coordinates.basis_checksum);
  std::printf("arm-articulated's basis: %s, %zu bytes held\n", articulated_basis->skinned ? "skinned" : "dense",
              articulated_basis->bytes());
  std::printf("articulated: %u bones + %u residual components, %zu coordinates: %s, largest error %.3g "
              "(arm-pmsc's estimate: %.3g)\n",
              articulated.subspace_bone_count(), articulated.residual_components(), articulated_sent,
              animspace::cache_status_name(articulated_answer.status), farthest(articulated_answer.points.values),
              farthest(answer.points.values));

  // On a blend or miss the client's own engine supplies the full pose (client fail-through); the
  // server checks it repeats the key values, answers with it and logs it for retraining. The pose
  // repeats its check values, so the verdict (and α) is the one evaluated.
  if (result.full_evaluation_needed) {
    const auto completed = client.complete_miss("arm-pmsc", result.model_version, posed_keys, full);
    std::printf("completed: %s, logged for retraining: %s\n", animspace::cache_status_name(completed.result.status),
                completed.logged ? "yes" : "no");
  }

  // Local fail-through: a trained pose with the forearm twisted half as far again, the upper
  // arm as trained. The server names the points whose regions' key points fail (the others are
  // already right), so the engine computes and sends only those; the answer is blended point by
  // point and the partial frame is logged for retraining.
  animspace::demo::ArmPose twisted = animspace::demo::demo_pose(0.3);
  twisted.forearm_twist_rad *= 1.5;
  const std::vector<float> bent = full_pose(rig, twisted);
  const std::vector<float> bent_keys = keys.gather(bent);
  const std::vector<float> bent_checks = keys.gather_check_values(bent);
  const animspace::KeyPointPose bent_pose{.key_values = bent_keys, .channel_count = keys.channel_count,
                                          .check_values = bent_checks};
  animspace::EvaluateOptions local_options;
  local_options.local_fail_through = true;
  const animspace::PoseResult local = client.evaluate_key_points("arm-pmsc", bent_pose, local_options);
  if (!local.full_points.empty()) {
    std::vector<float> needed;  // a real engine evaluates just these points
    for (uint32_t i : local.full_points) {
      needed.insert(needed.end(), bent.begin() + 3 * i, bent.begin() + 3 * (i + 1));
    }
    const auto completed = client.complete_miss("arm-pmsc", local.model_version, bent_pose, needed, local.full_points);
    std::printf("local fail-through: %zu of %u points computed, logged for retraining: %s\n",
                local.full_points.size(), local.points.point_count, completed.logged ? "yes" : "no");
  }

  // A sequence: one writer thread, results read in order; write() blocks while `window` results
  // are unread, so a slow reader holds the writer back instead of buffering the sequence.
  animspace::StreamOptions stream_options;
  stream_options.version = keys.model_version;  // the version the key points belong to
  stream_options.omit_points = true;            // verdicts only
  auto stream = client.open_stream("arm-pmsc", stream_options);
  std::thread writer([&] {
    for (uint64_t frame = 0; frame < 100; ++frame) {
      const auto posed = full_pose(rig, animspace::demo::demo_pose(static_cast<double>(frame) / 100));
      const std::vector<float> frame_keys = keys.gather(posed), frame_checks = keys.gather_check_values(posed);
      if (!stream->write({.key_values = frame_keys, .channel_count = keys.channel_count, .check_values = frame_checks},
                         frame)) {
        break;
      }
    }
    stream->writes_done();
  });
  int hits = 0, frames = 0;
  while (auto r = stream->read()) {
    hits += r->status == animspace::v1::CACHE_STATUS_HIT;
    ++frames;
  }
  writer.join();
  stream->finish();  // throws animspace::RpcError if the stream failed
  std::printf("streamed %d frames, %d hits\n", frames, hits);

  // A skeleton pose through the animation-space model: 12 floats per bone (rows 0–2 of G_j).
  animspace::SkeletonPose pose;
  pose.space = animspace::v1::SkeletonPose::SPACE_LOCAL;  // joint transforms, composed by the server
  const uint32_t bones = client.describe_model("arm-animspace").versions(0).bone_count();
  for (uint32_t b = 0; b < bones; ++b) {
    pose.transforms.insert(pose.transforms.end(), {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0});
  }
  animspace::SkinningOptions skinning;
  skinning.include_normals = true;
  const auto skinned = client.evaluate_skeleton_pose("arm-animspace", std::span(&pose, 1), skinning);
  std::printf("skinned %u vertices with normals\n", skinned.poses[0].points.point_count);

  // A level of detail under a vertex budget, streamed and reassembled into flat arrays.
  animspace::v1::GetLodRequest lod;
  lod.mutable_model()->set_name("arm-animspace");
  lod.mutable_budget()->set_max_vertices(300);
  lod.set_form(animspace::v1::GetLodRequest::FORM_POSED);
  const animspace::LodMesh mesh = client.get_lod(lod);
  std::printf("LOD level %u: %u vertices, %u faces\n", mesh.header.level(), mesh.header.vertex_count(),
              mesh.header.face_count());

  // Indirect illumination (the demo's cornell, Meyer & Anderson 2007 §3.2): a light moved along a
  // path under the ceiling, each frame answered from the key points the server gathers for it; a
  // light at floor level is one the training never covered, completed by the server's full gather.
  for (const std::array<double, 3> position : {std::array{0.15, 0.44, 0.45}, std::array{0.30, 0.44, 0.45},
                                               std::array{0.45, 0.44, 0.45}, std::array{0.28, 0.05, 0.5}}) {
    const std::vector<animspace::PointLight> light{{position, {}}};  // {}: the training intensity
    animspace::KeyPointPose lit;
    lit.lights = light;
    const animspace::PoseResult frame = client.evaluate_key_points("cornell", lit);
    std::printf("relit by a light at (%.2f, %.2f, %.2f): %s, %u points × %u channels (RGB radiance)\n", position[0],
                position[1], position[2], animspace::cache_status_name(frame.status), frame.points.point_count,
                frame.points.channel_count);
    // The tolerance is relative to each frame's own radiance (issue #38): the same light ten
    // times brighter gets the same verdict, its errors fractions of a scale ten times larger.
    const std::vector<animspace::PointLight> brighter{{position, {10.0, 10.0, 10.0}}};
    lit.lights = brighter;
    const animspace::PoseResult bright = client.evaluate_key_points("cornell", lit);
    std::printf("  ten times brighter: %s, error estimate %.4g of its scale %.4g (%.4g at the training intensity)\n",
                animspace::cache_status_name(bright.status), bright.error_estimate, bright.pose_scale,
                frame.pose_scale);
  }

  // A thumbnail, drawn headless by the daemon; UNAVAILABLE on a daemon without a renderer.
  animspace::v1::RenderThumbnailRequest thumbnail;
  thumbnail.mutable_model()->set_name("arm-animspace");
  thumbnail.set_width_px(256);
  thumbnail.set_height_px(256);
  try {
    const animspace::Thumbnail png = client.render_thumbnail(thumbnail);
    std::printf("thumbnail %u×%u, %zu bytes", png.width_px, png.height_px, png.png.size());
    if (!png_path.empty()) {
      std::ofstream(png_path, std::ios::binary) << png.png;
      std::printf(", written to %s", png_path.c_str());
    }
    std::printf("\n");
  } catch (const animspace::RpcError& error) {
    if (error.code() != grpc::StatusCode::UNAVAILABLE) throw;
    std::printf("no thumbnail: %s\n", error.server_message().c_str());
  }
  return 0;
} catch (const animspace::RpcError& error) {
  // error.code() is the gRPC status; error.server_message() names the field that was wrong.
  std::fprintf(stderr, "%s\n", error.what());
  return 1;
}
