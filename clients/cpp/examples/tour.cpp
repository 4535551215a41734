// The README's "Query it from C++", compiled and run by the tests against a real daemon so that
// the snippet a newcomer pastes keeps working: key points in and the whole pose out, a sequence
// streamed with back-pressure, a miss completed, a skeleton pose, a LOD mesh and a thumbnail.
//
//   build/bin/animspace-client-tour [SERVER [PNG]]   (default 127.0.0.1:50051, /tmp/arm-animspace.png)
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "clients/cpp/client.h"

int main(int argc, char** argv) try {
  const std::string server = argc > 1 ? argv[1] : "127.0.0.1:50051";
  const std::string png_path = argc > 2 ? argv[2] : "/tmp/arm-animspace.png";
  animspace::ClientOptions options;  // deadline (10 s), token, TLS
  animspace::Client client(server, options);

  // The key points arm-pmsc needs, in order, and one pose made of them. A real posing engine
  // computes only these points; here they are a rest-like pose of zeros moved along x.
  const animspace::KeyPoints keys = client.describe_key_points("arm-pmsc");
  std::vector<float> values(keys.indices.size() * keys.channel_count, 0.0f);
  for (size_t k = 0; k < keys.indices.size(); ++k) values[k * keys.channel_count] = 0.1f * static_cast<float>(k);
  const animspace::PoseResult result = client.evaluate_key_points("arm-pmsc", {values, keys.channel_count});
  std::printf("%s e_key %.4g alpha %.3f: %u points\n", animspace::cache_status_name(result.status),
              result.key_point_error, result.blend_weight, result.points.point_count);
  // result.points.values is N×3 row-major float32, e.g.
  //   Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>> v(
  //       result.points.values.data(), result.points.point_count, 3);

  // On a blend or miss the client's own engine supplies the full pose (client fail-through).
  if (result.full_evaluation_needed) {
    const std::vector<float> full(result.points.values.size(), 0.0f);  // your engine's full pose
    const auto completed = client.complete_miss("arm-pmsc", result.model_version, {values, keys.channel_count}, full);
    std::printf("completed: %s, logged for retraining: %s\n", animspace::cache_status_name(completed.result.status),
                completed.logged ? "yes" : "no");
  }

  // A sequence: one writer thread, results read in order; write() blocks while `window` results
  // are unread, so a slow reader holds the writer back instead of buffering the sequence.
  animspace::StreamOptions stream_options;
  stream_options.version = keys.model_version;  // the version the key points belong to
  stream_options.omit_points = true;            // verdicts only
  auto stream = client.open_stream("arm-pmsc", stream_options);
  std::thread writer([&] {
    for (uint64_t frame = 0; frame < 100; ++frame) {
      if (!stream->write({values, keys.channel_count}, frame)) break;
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

  // A thumbnail, drawn headless by the daemon; UNAVAILABLE on a daemon without a renderer.
  animspace::v1::RenderThumbnailRequest thumbnail;
  thumbnail.mutable_model()->set_name("arm-animspace");
  thumbnail.set_width_px(256);
  thumbnail.set_height_px(256);
  try {
    const animspace::Thumbnail png = client.render_thumbnail(thumbnail);
    std::ofstream(png_path, std::ios::binary) << png.png;
    std::printf("thumbnail %u×%u, %zu bytes\n", png.width_px, png.height_px, png.png.size());
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
