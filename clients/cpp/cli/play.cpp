#include "clients/cpp/cli/play.h"

#include <chrono>
#include <cstdio>
#include <thread>

#include "clients/cpp/cli/key_frames.h"
#include "clients/cpp/cli/offline_common.h"

namespace animspace::cli {

CLI::App* add_play(CLI::App& app, PlayArgs& a) {
  auto* cmd = app.add_subcommand(
      "play", "Stream a sequence's key points to a PMSC model and report hits, blends and misses");
  cmd->add_option("model", a.model, "Model name")->required();
  cmd->add_option("sequence", a.sequence,
                  "Folder with reference.obj + frames.pc2 (or OBJ frames), a mesh file with --pc2, or a model.anim "
                  "holding sequence.frames")
      ->required();
  cmd->add_option("--pc2", a.pc2, "Point cache when SEQUENCE is a mesh file");
  cmd->add_option("--version", a.version, "Model version (default: the served one, pinned for the stream)");
  cmd->add_option("--select", a.select, "Frames as a slice start:stop:step (e.g. 1::2 for the odd frames)")
      ->capture_default_str();
  cmd->add_flag("--complete", a.complete,
                "Complete every blend or miss with the frame's full values (logs it for retraining)");
  cmd->add_flag("-v,--verbose", a.verbose, "One line per frame");
  return cmd;
}

int run_play(const PlayArgs& a, Client& client, bool json) {
  auto frames = load_sequence_frames(a.sequence, a.pc2);
  if (!frames) return fail("play", frames.error().message);
  std::string error;
  const auto selected = parse_frame_selection(a.select, static_cast<int>(frames->rows()), &error);
  if (selected.empty()) return fail("play", error);

  const auto keys = client.describe_key_points(a.model, a.version);
  const long D = keys.channel_count();
  if (frames->cols() != static_cast<long>(keys.control_point_count()) * D) {
    return fail("play", "the sequence has " + std::to_string(frames->cols() / std::max(1L, D)) +
                            " points per frame, model '" + a.model + "' expects " +
                            std::to_string(keys.control_point_count()));
  }
  const auto K = static_cast<uint32_t>(keys.key_point_indices_size());
  auto gather = [&](int frame) { return gather_key_values(*frames, frame, keys); };

  auto stub = v1::PoseService::NewStub(client.channel());
  grpc::ClientContext context;
  client.authorize(&context);  // the stream runs as long as the sequence: no per-call deadline
  const auto start = std::chrono::steady_clock::now();
  auto stream = stub->StreamKeyPoints(&context);
  std::thread writer([&] {
    for (size_t i = 0; i < selected.size(); ++i) {
      v1::KeyPointFrame frame;
      if (i == 0) {
        frame.mutable_model()->set_name(a.model);
        frame.mutable_model()->set_version(keys.model_version());
      }
      frame.set_sequence(static_cast<uint64_t>(selected[i]));
      frame.set_omit_points(true);
      const Eigen::VectorXf values = gather(selected[i]);
      *frame.mutable_pose()->mutable_key_values() = make_point_array(values.data(), K, static_cast<uint32_t>(D));
      if (!stream->Write(frame)) break;
    }
    stream->WritesDone();
  });
  uint64_t counts[4] = {0, 0, 0, 0};
  double sum_error = 0, max_error = 0;
  uint64_t completed = 0;
  v1::PoseResult result;
  std::vector<uint64_t> to_complete;
  while (stream->Read(&result)) {
    counts[result.status()] += 1;
    sum_error += result.key_point_error();
    max_error = std::max(max_error, double(result.key_point_error()));
    if (result.full_evaluation_needed()) to_complete.push_back(result.sequence());
    if (a.verbose) {
      std::printf("frame %5llu  %-5s  e_key %.6g  alpha %.3f\n", static_cast<unsigned long long>(result.sequence()),
                  v1::CacheStatus_Name(result.status()).substr(13).c_str(), result.key_point_error(),
                  result.blend_weight());
    }
  }
  writer.join();
  const grpc::Status status = stream->Finish();
  if (!status.ok()) throw RpcError("StreamKeyPoints", status);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  if (a.complete) {
    for (uint64_t frame : to_complete) {
      v1::CompleteMissRequest request;
      request.mutable_model()->set_name(a.model);
      request.mutable_model()->set_version(keys.model_version());
      const Eigen::VectorXf values = gather(static_cast<int>(frame));
      *request.mutable_key_values() = make_point_array(values.data(), K, static_cast<uint32_t>(D));
      *request.mutable_full_values() =
          make_point_array(frames->row(static_cast<long>(frame)).data(), keys.control_point_count(),
                           static_cast<uint32_t>(D));
      completed += client.complete_miss(request).logged() ? 1 : 0;
    }
  }
  const uint64_t played = counts[1] + counts[2] + counts[3];
  const double hit_rate = played == 0 ? 0.0 : double(counts[1]) / double(played);
  if (json) {
    std::printf("{\"model\": \"%s\", \"version\": %llu, \"frames\": %llu, \"hits\": %llu, \"blends\": %llu, "
                "\"misses\": %llu, \"hit_rate\": %.6f, \"mean_key_point_error\": %.6g, \"max_key_point_error\": %.6g, "
                "\"poses_per_second\": %.1f, \"completed\": %llu}\n",
                a.model.c_str(), static_cast<unsigned long long>(keys.model_version()),
                static_cast<unsigned long long>(played), static_cast<unsigned long long>(counts[1]),
                static_cast<unsigned long long>(counts[2]), static_cast<unsigned long long>(counts[3]), hit_rate,
                played ? sum_error / double(played) : 0.0, max_error, double(played) / seconds,
                static_cast<unsigned long long>(completed));
    return 0;
  }
  std::printf("%s version %llu: %llu frames in %.2f s (%.0f poses/s)\n", a.model.c_str(),
              static_cast<unsigned long long>(keys.model_version()), static_cast<unsigned long long>(played), seconds,
              double(played) / seconds);
  std::printf("  hits %llu, blends %llu, misses %llu: hit rate %.1f%%; e_key mean %.4g, max %.4g\n",
              static_cast<unsigned long long>(counts[1]), static_cast<unsigned long long>(counts[2]),
              static_cast<unsigned long long>(counts[3]), 100.0 * hit_rate, played ? sum_error / double(played) : 0.0,
              max_error);
  if (a.complete) {
    std::printf("  completed %llu blends/misses with full values (logged for `animspace retrain %s`)\n",
                static_cast<unsigned long long>(completed), a.model.c_str());
  } else if (!to_complete.empty()) {
    std::printf("  %zu frames needed the full calculation (--complete sends it)\n", to_complete.size());
  }
  return 0;
}

}  // namespace animspace::cli
