#include "clients/cpp/cli/play.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/coordinates.h"
#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/quantile.h"
#include "clients/cpp/tools/sequence_frames.h"

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
  cmd->add_flag("--coordinates", a.coordinates,
                "Take the answers as subspace coordinates and reconstruct every pose here (the basis is fetched "
                "once and cached on disk)");
  cmd->add_option("--basis-cache", a.basis_cache,
                  "Folder of cached bases (default: $ANIMSPACE_BASIS_CACHE, else ~/.cache/animspace/bases)");
  cmd->add_flag("-v,--verbose", a.verbose, "One line per frame");
  return cmd;
}

int run_play(const PlayArgs& a, Client& client, bool json) {
  auto frames = tools::load_sequence_frames(a.sequence, a.pc2);
  if (!frames) return fail("play", frames.error().message);
  std::string error;
  const auto selected = tools::parse_frame_selection(a.select, static_cast<int>(frames->rows()), &error);
  if (selected.empty()) return fail("play", error);

  const KeyPoints keys = client.describe_key_points(a.model, a.version);
  const long D = keys.channel_count;
  if (frames->cols() != static_cast<long>(keys.control_point_count) * D) {
    return fail("play", "the sequence has " + std::to_string(frames->cols() / std::max(1L, D)) +
                            " points per frame, model '" + a.model + "' expects " +
                            std::to_string(keys.control_point_count));
  }
  auto frame_values = [&](int frame) {
    return std::span<const float>(frames->row(frame).data(), static_cast<size_t>(frames->cols()));
  };

  // The stream pins the version DescribeKeyPoints answered for, so the key points stay valid
  // even if a retrain publishes a new version mid-sequence.
  StreamOptions options;
  options.version = keys.model_version;
  options.omit_points = !a.coordinates;
  if (a.coordinates) options.points_encoding = v1::POINT_ENCODING_COORDINATES;
  BasisCache bases(a.basis_cache.empty() ? default_basis_cache_directory() : std::filesystem::path(a.basis_cache));
  // With coordinates: the client's reconstruction, µs per pose, and each answer's largest
  // distance from the frame it was played from (what a renderer would draw against the truth).
  std::vector<double> reconstruct_us;
  bool skinned = false;  // the basis came in the SKINNED layout (an articulated model's)
  double max_distance = 0;
  auto stream = client.open_stream(a.model, options);
  const auto start = std::chrono::steady_clock::now();
  std::thread writer([&] {
    for (int frame : selected) {
      const std::vector<float> values = keys.gather(frame_values(frame));
      const std::vector<float> checks = keys.gather_check_values(frame_values(frame));
      KeyPointPose pose{values, keys.channel_count};
      pose.check_values = checks;
      if (!stream->write(pose, static_cast<uint64_t>(frame))) break;
    }
    stream->writes_done();
  });
  ProgressBar progress("play " + a.model, selected.size());
  uint64_t counts[4] = {0, 0, 0, 0};
  double sum_error = 0, max_error = 0;
  std::vector<uint64_t> to_complete;
  try {
    while (auto result = stream->read()) {
      counts[result->status] += 1;
      sum_error += result->key_point_error;
      max_error = std::max(max_error, double(result->key_point_error));
      if (result->full_evaluation_needed) to_complete.push_back(result->sequence);
      if (a.coordinates && result->coordinates.present) {
        const auto t0 = std::chrono::steady_clock::now();
        bases.reconstruct(client, a.model, *result);
        reconstruct_us.push_back(
            1e6 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        skinned = bases.get(client, a.model, result->model_version, result->coordinates.basis_checksum)->skinned != nullptr;
        const auto frame = frame_values(static_cast<int>(result->sequence));
        for (uint32_t i = 0; i < result->points.point_count; ++i) {
          double squared = 0;
          for (long c = 0; c < D; ++c) {
            const double d = result->points.values[i * static_cast<size_t>(D) + static_cast<size_t>(c)] -
                             frame[i * static_cast<size_t>(D) + static_cast<size_t>(c)];
            squared += d * d;
          }
          max_distance = std::max(max_distance, std::sqrt(squared));
        }
      }
      if (a.verbose && !json) {
        char check_text[64] = "";
        if (result->checked) {
          std::snprintf(check_text, sizeof check_text, "  e_check %.6g  e %.6g", result->check_point_error,
                        result->error_estimate);
        }
        std::printf("frame %5llu  %-5s  e_key %.6g%s  alpha %.3f\n", static_cast<unsigned long long>(result->sequence),
                    cache_status_name(result->status), result->key_point_error, check_text, result->blend_weight);
      }
      const uint64_t read = counts[1] + counts[2] + counts[3];
      progress.update(read, "hit rate " + std::to_string(100 * counts[1] / read) + "%");
    }
  } catch (...) {
    stream->cancel();  // releases a writer blocked on the window
    writer.join();
    throw;
  }
  writer.join();
  stream->finish();
  progress.finish();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  uint64_t completed = 0;
  uint64_t not_logged = 0;
  std::string not_logged_reason;  // the first one the server gave
  if (a.complete) {
    ProgressBar completing("complete " + a.model, to_complete.size());
    for (uint64_t frame : to_complete) {
      const auto row = frame_values(static_cast<int>(frame));
      const std::vector<float> values = keys.gather(row);
      const std::vector<float> checks = keys.gather_check_values(row);
      KeyPointPose pose{values, keys.channel_count};
      pose.check_values = checks;  // the same as evaluated, so the verdict repeats
      const CompletedMiss answer = client.complete_miss(a.model, keys.model_version, pose, row);
      if (answer.logged) {
        completed += 1;
      } else if (answer.result.status != v1::CACHE_STATUS_HIT) {
        not_logged += 1;
        if (not_logged_reason.empty()) not_logged_reason = answer.not_logged_reason;
      }
      completing.update(completed + not_logged);
    }
  }
  if (not_logged > 0) {
    // The answers were right; the retraining data is short, and a script must not take it as done.
    std::fprintf(stderr, "error: %llu of %zu completed misses were not logged by the server, so a retrain will "
                         "not see them: %s\n",
                 static_cast<unsigned long long>(not_logged), to_complete.size(),
                 not_logged_reason.empty() ? "(no reason given)" : not_logged_reason.c_str());
  }
  const uint64_t played = counts[1] + counts[2] + counts[3];
  const double hit_rate = played == 0 ? 0.0 : double(counts[1]) / double(played);
  const double mean_error = played ? sum_error / double(played) : 0.0;
  const double reconstruct_p50_us = reconstruct_us.empty() ? 0.0 : tools::quantile(reconstruct_us, 0.5);
  if (json) {
    nlohmann::json coordinates;
    if (a.coordinates) {
      coordinates = {{"reconstructed", reconstruct_us.size()},
                     {"client_reconstruct_us", reconstruct_p50_us},
                     {"max_point_distance", max_distance},
                     {"bases_fetched", bases.fetch_count()},
                     {"basis_layout", skinned ? "skinned" : "dense"},
                     {"basis_bytes", bases.memory_bytes()}};
    }
    print_json({{"model", a.model},
                {"coordinates", coordinates},
                {"version", keys.model_version},
                {"frames", played},
                {"hits", counts[1]},
                {"blends", counts[2]},
                {"misses", counts[3]},
                {"hit_rate", hit_rate},
                {"mean_key_point_error", mean_error},
                {"max_key_point_error", max_error},
                {"poses_per_second", double(played) / seconds},
                {"completed", completed},
                {"not_logged", not_logged},
                {"not_logged_reason", not_logged_reason}});
    return not_logged == 0 ? 0 : 1;
  }
  std::printf("%s version %llu: %llu frames in %.2f s (%.0f poses/s)\n", a.model.c_str(),
              static_cast<unsigned long long>(keys.model_version), static_cast<unsigned long long>(played), seconds,
              double(played) / seconds);
  std::printf("  hits %llu, blends %llu, misses %llu: hit rate %.1f%%; e_key mean %.4g, max %.4g\n",
              static_cast<unsigned long long>(counts[1]), static_cast<unsigned long long>(counts[2]),
              static_cast<unsigned long long>(counts[3]), 100.0 * hit_rate, mean_error, max_error);
  if (a.coordinates) {
    std::printf("  reconstructed %zu answers from coordinates here: %.1f us per pose (median), %llu bases fetched "
                "(%s, %.1f MB held); largest distance from the played frames %.4g\n",
                reconstruct_us.size(), reconstruct_p50_us, static_cast<unsigned long long>(bases.fetch_count()),
                skinned ? "skinned" : "dense", 1e-6 * static_cast<double>(bases.memory_bytes()), max_distance);
  }
  if (a.complete) {
    std::printf("  completed %llu blends/misses with full values (logged for `animspace retrain %s`)\n",
                static_cast<unsigned long long>(completed), a.model.c_str());
  }
  if (not_logged > 0) return 1;
  if (!a.complete && !to_complete.empty()) {
    std::printf("  %zu frames needed the full calculation (--complete sends it)\n", to_complete.size());
  }
  return 0;
}

}  // namespace animspace::cli
