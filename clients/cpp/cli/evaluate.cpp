#include "clients/cpp/cli/evaluate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/frame_selection.h"
#include "clients/cpp/tools/sequence_frames.h"
#include "core/mesh_io/pc2.h"

namespace animspace::cli {

CLI::App* add_evaluate(CLI::App& app, EvaluateArgs& a) {
  auto* cmd = app.add_subcommand(
      "evaluate",
      "Evaluate a sequence's key points on a PMSC model in batches (EvaluateKeyPoints) and report, per frame, the "
      "soft cache's verdict and the error of the returned points against the frame itself");
  cmd->add_option("model", a.model, "Model name")->required();
  cmd->add_option("sequence", a.sequence,
                  "Folder with reference.obj + frames.pc2 (or OBJ frames), a mesh file with --pc2, or a model.anim "
                  "holding sequence.frames")
      ->required();
  cmd->add_option("--pc2", a.pc2, "Point cache when SEQUENCE is a mesh file");
  cmd->add_option("--version", a.version, "Model version (default: the served one)");
  cmd->add_option("--select", a.select, "Frames as a slice start:stop:step (e.g. 1::2 for the odd frames)")
      ->capture_default_str();
  cmd->add_option("--batch", a.batch, "Poses per EvaluateKeyPoints call")
      ->check(CLI::Range(1u, 1u << 20))
      ->capture_default_str();
  cmd->add_flag("--region-errors", a.region_errors, "Print per-region key-point errors (models with regions)");
  cmd->add_flag("--local-fail-through", a.local_fail_through,
                "On a blend or miss, list the points that need the full calculation (those of the failing regions)");
  cmd->add_flag("--without-check-points", a.without_check_points,
                "Send the key values only, as a client from before check points: the verdict then rests on e_key "
                "alone, against the model's key-only thresholds");
  cmd->add_flag("-q,--quiet", a.quiet, "Print the summary only, not one line per frame");
  cmd->add_flag("-v,--verbose", a.verbose, "One line per frame (the default; kept for older scripts)");
  cmd->add_option("-o,--output", a.output,
                  "Write the returned points of every frame as a point cache (.pc2; other extensions are refused)");
  return cmd;
}

int run_evaluate(const EvaluateArgs& a, Client& client, bool json) {
  if (!a.output.empty()) {
    if (const std::string bad = check_output_extension(a.output, {".pc2"}, "evaluate writes a point cache");
        !bad.empty()) {
      return fail("evaluate", bad);
    }
  }
  auto frames = tools::load_sequence_frames(a.sequence, a.pc2);
  if (!frames) return fail("evaluate", frames.error().message);
  std::string error;
  const auto selected = tools::parse_frame_selection(a.select, static_cast<int>(frames->rows()), &error);
  if (selected.empty()) return fail("evaluate", error);
  const KeyPoints keys = client.describe_key_points(a.model, a.version);
  if (frames->cols() != static_cast<long>(keys.control_point_count) * keys.channel_count) {
    return fail("evaluate", "the sequence has " + std::to_string(frames->cols() / std::max(1u, keys.channel_count)) +
                                " points per frame, model '" + a.model + "' expects " +
                                std::to_string(keys.control_point_count));
  }
  auto frame_values = [&](int frame) {
    return std::span<const float>(frames->row(frame).data(), static_cast<size_t>(frames->cols()));
  };

  EvaluateOptions options;
  options.version = keys.model_version;
  options.include_region_errors = a.region_errors;
  options.local_fail_through = a.local_fail_through;
  mesh_io::PointCache returned;
  nlohmann::json per_frame = nlohmann::json::array();
  uint64_t counts[4] = {0, 0, 0, 0};
  double worst = 0;
  bool comparable_all = true;
  ProgressBar progress("evaluate " + a.model, selected.size());
  for (size_t first = 0; first < selected.size(); first += a.batch) {
    const size_t count = std::min<size_t>(a.batch, selected.size() - first);
    // Check points are computed like key points (here: read from the frame) and sent beside them.
    std::vector<std::vector<float>> values, checks;
    std::vector<KeyPointPose> poses;
    for (size_t i = 0; i < count; ++i) {
      values.push_back(keys.gather(frame_values(selected[first + i])));
      checks.push_back(a.without_check_points ? std::vector<float>()
                                              : keys.gather_check_values(frame_values(selected[first + i])));
    }
    for (size_t i = 0; i < count; ++i) {
      KeyPointPose pose{values[i], keys.channel_count};
      pose.check_values = checks[i];
      poses.push_back(pose);
    }
    const std::vector<PoseResult> results = client.evaluate_key_points_batch(a.model, poses, options);
    for (size_t i = 0; i < count; ++i) {
      const PoseResult& r = results[i];
      const auto truth = frame_values(selected[first + i]);
      // The error actually made: the largest per-point distance from the frame. Cross-PMSC models
      // return a different point set (seed 001 §3.1), which the frame cannot check.
      const bool comparable =
          keys.fail_through != v1::FAIL_THROUGH_IMPOSSIBLE && r.points.values.size() == truth.size();
      comparable_all = comparable_all && comparable;
      double max_distance = 0;
      for (uint32_t p = 0; comparable && p < r.points.point_count; ++p) {
        double squared = 0;
        for (uint32_t c = 0; c < r.points.channel_count; ++c) {
          const double d = r.points.point(p)[c] - truth[size_t{p} * keys.channel_count + c];
          squared += d * d;
        }
        max_distance = std::max(max_distance, std::sqrt(squared));
      }
      worst = std::max(worst, max_distance);
      counts[r.status] += 1;
      nlohmann::json row = {{"frame", selected[first + i]},
                            {"status", cache_status_name(r.status)},
                            {"key_point_error", r.key_point_error},
                            {"check_point_error", r.check_point_error},
                            {"key_point_max_error", r.key_point_max_error},
                            {"error_estimate", r.error_estimate},
                            {"checked", r.checked},
                            {"blend_weight", r.blend_weight},
                            {"full_evaluation_needed", r.full_evaluation_needed},
                            {"max_point_error", comparable ? nlohmann::json(max_distance) : nlohmann::json()}};
      if (a.region_errors) {
        row["regions"] = nlohmann::json::array();
        for (const auto& region : r.region_errors) {
          row["regions"].push_back({{"region", region.region},
                                    {"key_point_error", region.key_point_error},
                                    {"status", cache_status_name(region.status)}});
        }
      }
      if (a.local_fail_through) {
        row["full_points"] = r.full_points;
        row["full_point_blend_weights"] = r.full_point_blend_weights;
      }
      if (!a.quiet && !json) {
        char error_text[32] = "n/a";
        if (comparable) std::snprintf(error_text, sizeof error_text, "%.6g", max_distance);
        char check_text[64] = "";
        if (r.checked) {
          std::snprintf(check_text, sizeof check_text, "  e_check %.6g  e %.6g", r.check_point_error, r.error_estimate);
        }
        std::printf("frame %5d  %-5s  e_key %.6g%s  alpha %.3f  max point error %s%s\n", selected[first + i],
                    cache_status_name(r.status), r.key_point_error, check_text, r.blend_weight, error_text,
                    r.full_evaluation_needed ? "  (estimate: full values needed)" : "");
        if (a.local_fail_through && r.status != v1::CACHE_STATUS_HIT) {
          std::printf("         full points: %zu of %u\n", r.full_points.size(), r.points.point_count);
        }
        for (const auto& region : r.region_errors) {
          std::printf("         region %u: %-5s e_key %.6g\n", region.region, cache_status_name(region.status),
                      region.key_point_error);
        }
      }
      per_frame.push_back(std::move(row));
      if (!a.output.empty()) {
        const auto width = static_cast<Eigen::Index>(r.points.values.size());
        if (returned.samples.size() == 0) {
          returned.num_points = static_cast<int>(r.points.point_count);
          returned.samples.resize(static_cast<Eigen::Index>(selected.size()), width);
        }
        returned.samples.row(static_cast<Eigen::Index>(first + i)) =
            Eigen::Map<const Eigen::RowVectorXf>(r.points.values.data(), width);
      }
    }
    progress.update(first + count);
  }
  progress.finish();
  if (!a.output.empty()) {
    if (auto written = mesh_io::write_pc2(a.output, returned); !written.ok()) {
      return fail("evaluate", written.error().message);
    }
  }
  const uint64_t total = counts[1] + counts[2] + counts[3];
  if (json) {
    print_json({{"model", a.model},
                {"version", keys.model_version},
                {"frames", total},
                {"hits", counts[1]},
                {"blends", counts[2]},
                {"misses", counts[3]},
                {"hit_rate", total ? double(counts[1]) / double(total) : 0.0},
                {"max_point_error", comparable_all ? nlohmann::json(worst) : nlohmann::json()},
                {"results", per_frame},
                {"output", a.output}});
    return 0;
  }
  std::printf("%s version %llu: %llu frames: hits %llu, blends %llu, misses %llu (hit rate %.1f%%)\n",
              a.model.c_str(), static_cast<unsigned long long>(keys.model_version),
              static_cast<unsigned long long>(total), static_cast<unsigned long long>(counts[1]),
              static_cast<unsigned long long>(counts[2]), static_cast<unsigned long long>(counts[3]),
              total ? 100.0 * double(counts[1]) / double(total) : 0.0);
  if (comparable_all) {
    std::printf("  largest distance of a returned point from its frame: %.6g\n", worst);
  } else {
    std::printf("  the model returns another point set than the frames (cross-PMSC): no error against them\n");
  }
  if (!a.output.empty()) std::printf("wrote %s\n", a.output.c_str());
  return 0;
}

}  // namespace animspace::cli
