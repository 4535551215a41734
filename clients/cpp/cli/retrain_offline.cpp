#include "clients/cpp/cli/retrain_offline.h"

#include <cstdio>
#include <filesystem>
#include <map>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "core/container/model_container.h"
#include "core/model/repository.h"
#include "core/pmsc/pmsc_io.h"
#include "core/misslog/miss_frames.h"
#include "core/pmsc/retrain.h"

namespace animspace::cli {

CLI::App* add_retrain_offline(CLI::App& app, RetrainOfflineArgs& a) {
  auto* cmd = app.add_subcommand(
      "retrain-offline",
      "Offline: retrain a PMSC model in a repository on its training frames plus the completed misses of every "
      "replica's miss log under --miss-logs, and publish the next version atomically (replicas pick it up by "
      "polling) — the nightly job of a scaled-out deployment");
  cmd->add_option("--repository", a.repository, "Model repository (<repository>/<model>/<version>/model.anim)")
      ->required()
      ->check(CLI::ExistingDirectory);
  cmd->add_option("--model", a.model, "Model name")->required();
  cmd->add_option("--version", a.version, "Version to start from (default: the newest)");
  cmd->add_option("--miss-logs", a.miss_logs,
                  "Root searched recursively for <model>.misses (one per replica's --miss-log-dir)")
      ->required()
      ->check(CLI::ExistingDirectory);
  cmd->add_option("--error-bound", a.error_bound, "New bound on the max per-point training error, model units");
  cmd->add_option("--max-key-points", a.max_key_points, "New key point budget");
  cmd->add_option("--min-misses", a.min_misses, "Publish only when at least this many new completed misses exist")
      ->capture_default_str();
  cmd->add_flag("--dry-run", a.dry_run, "Train and report, but publish nothing");
  return cmd;
}

int run_retrain_offline(const RetrainOfflineArgs& a, bool json) {
  const char* command = "retrain-offline";
  if (auto valid = model::validate_model_name(a.model, "--model"); !valid.ok()) return fail(command, valid.error().message);
  auto versions = model::list_versions(a.repository, a.model);
  if (!versions) return fail(command, versions.error().message);
  if (versions->empty()) return fail(command, "model '" + a.model + "' has no versions in " + a.repository);
  const uint64_t start = a.version == 0 ? versions->back() : a.version;
  const auto path = std::filesystem::path(a.repository) / a.model / std::to_string(start) / model::kModelFileName;
  auto current = container::read_file(path);
  if (!current) return fail(command, current.error().message);
  auto loaded = pmsc::load(*current, path.string());
  if (!loaded) return fail(command, loaded.error().message);
  const long width = static_cast<long>(loaded->point_count) * loaded->channel_count;

  // Every replica's log of this model, each read after its own watermark.
  const std::string log_name = a.model + ".misses";
  std::map<std::string, misslog::MissFrames> logs;  // by path relative to the root: stable across runs
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(a.miss_logs, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec) || it->path().filename() != log_name) continue;
    const std::string relative = std::filesystem::relative(it->path(), a.miss_logs).generic_string();
    auto read = misslog::read_miss_frames(it->path(), pmsc::misses_through_log(*current, relative), *loaded, start);
    if (!read) return fail(command, read.error().message);
    logs.emplace(relative, std::move(*read));
  }
  if (ec) return fail(command, "cannot search " + a.miss_logs + ": " + ec.message());
  long rows = 0;
  uint64_t skipped = 0;
  uint64_t inconsistent = 0;
  for (const auto& [name, log] : logs) {
    rows += log.frames.rows();
    skipped += log.skipped;
    inconsistent += log.inconsistent;
  }
  FrameMatrix misses(rows, width);
  long row = 0;
  for (const auto& [name, log] : logs) {
    misses.middleRows(row, log.frames.rows()) = log.frames;
    row += log.frames.rows();
  }

  nlohmann::json report = {{"model", a.model},
                           {"from_version", start},
                           {"logs", logs.size()},
                           {"misses", rows},
                           {"skipped_without_full_values", skipped},
                           {"skipped_inconsistent", inconsistent},
                           {"published_version", nullptr}};
  if (static_cast<uint64_t>(rows) < a.min_misses) {
    if (json) {
      report["reason"] = "fewer new completed misses than --min-misses";
      print_json(report);
    } else {
      std::printf("%s version %llu: %ld new completed misses in %zu logs (%llu without full values), fewer than "
                  "--min-misses %llu: nothing to publish\n",
                  a.model.c_str(), static_cast<unsigned long long>(start), rows, logs.size(),
                  static_cast<unsigned long long>(skipped), static_cast<unsigned long long>(a.min_misses));
    }
    return 0;
  }

  pmsc::RetrainOptions options;
  options.error_bound = a.error_bound;
  options.max_key_points = a.max_key_points;
  // --min-misses 0 with the options the version was trained with would publish a copy of it.
  auto changes = pmsc::retrain_changes_anything(*current, rows, options, path.string());
  if (!changes) return fail(command, changes.error().message);
  if (!*changes && !a.dry_run) {
    if (json) {
      report["reason"] = "no new completed miss and no option changed: a retrain would publish a copy";
      print_json(report);
    } else {
      std::printf("%s version %llu: no new completed miss and no option changed, so a retrain would publish a copy "
                  "of it: nothing to publish\n",
                  a.model.c_str(), static_cast<unsigned long long>(start));
    }
    return 0;
  }
  auto result = pmsc::retrain(*current, start, misses, pmsc::misses_through(*current), options, path.string());
  if (!result) return fail(command, result.error().message);
  for (const auto& [name, log] : logs) pmsc::advance_misses_through_log(result->container, name, log.last_sequence);
  report["training_frames"] = result->training_frames;
  report["basis"] = result->report.basis_size;
  report["key_points"] = result->report.key_points;
  report["max_training_error"] = result->report.max_training_error;
  report["seconds"] = result->report.seconds;
  report["previous_epsilon_min"] = result->previous_epsilon.epsilon_min;
  report["previous_epsilon_max"] = result->previous_epsilon.epsilon_max;
  report["epsilon_min"] = result->epsilon.epsilon_min;
  report["epsilon_max"] = result->epsilon.epsilon_max;
  report["previous_hit_rate"] = result->previous_hit_rate;
  report["hit_rate"] = result->hit_rate;
  if (!a.dry_run) {
    auto published = model::publish_version(a.repository, a.model, result->container);
    if (!published) return fail(command, published.error().message);
    report["published_version"] = *published;
  }
  if (json) {
    print_json(report);
    return 0;
  }
  std::printf("%s version %llu + %ld completed misses from %zu logs → %d training frames, basis %d, %d key points, "
              "max training error %.4g (%.2f s)\n",
              a.model.c_str(), static_cast<unsigned long long>(start), rows, logs.size(), result->training_frames,
              result->report.basis_size, result->report.key_points, result->report.max_training_error,
              result->report.seconds);
  print_soft_cache_change(result->previous_epsilon.epsilon_min, result->epsilon.epsilon_min,
                          result->previous_epsilon.epsilon_max, result->epsilon.epsilon_max, result->training_frames,
                          result->previous_hit_rate, result->hit_rate);
  if (inconsistent > 0) {
    std::printf("  %llu logged misses left out: their full values do not repeat their key values\n",
                static_cast<unsigned long long>(inconsistent));
  }
  if (a.dry_run) {
    std::printf("dry run: nothing published\n");
  } else {
    std::printf("published %s version %llu; replicas polling the repository load it\n", a.model.c_str(),
                static_cast<unsigned long long>(report["published_version"].get<uint64_t>()));
  }
  return 0;
}

}  // namespace animspace::cli
