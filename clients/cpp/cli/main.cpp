// animspace: the command line for animspaced (queries) and for offline work on model files.
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "clients/cpp/cli/fit.h"
#include "clients/cpp/cli/evaluate.h"
#include "clients/cpp/cli/export_rig.h"
#include "clients/cpp/cli/lod.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/cli/play.h"
#include "clients/cpp/cli/pose.h"
#include "clients/cpp/cli/retrain_offline.h"
#include "clients/cpp/cli/subdivide.h"
#include "clients/cpp/cli/atlas.h"
#include "clients/cpp/cli/calibrate.h"
#include "clients/cpp/cli/relight.h"
#include "clients/cpp/cli/thumbnail.h"
#include "clients/cpp/cli/train_illumination.h"
#include "clients/cpp/cli/train_pmsc.h"
#include "clients/cpp/client.h"
#include "core/common/atomic_file.h"
#include "core/common/nearest_names.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/model/model_info.h"

namespace {

struct Globals {
  std::string server = "127.0.0.1:50051";
  int deadline_ms = 10000;
  bool json = false;
  std::string token_file;
  bool tls = false;
  std::string tls_ca;
  std::string tls_cert;
  std::string tls_key;
  std::string tls_server_name;
};

// Contents of a file named by a flag; exits with a message naming the flag when unreadable.
std::string read_flag_file(const char* flag, const std::string& path) {
  auto text = animspace::read_whole_file(path);
  if (!text) {
    std::fprintf(stderr, "animspace: %s: %s\n", flag, text.error().message.c_str());
    std::exit(2);
  }
  return *text;
}

animspace::Client connect(const Globals& g) {
  animspace::ClientOptions options;
  options.deadline = std::chrono::milliseconds(g.deadline_ms);
  if (const char* token = std::getenv("ANIMSPACE_TOKEN"); token != nullptr) options.token = token;
  if (!g.token_file.empty()) {
    options.token = read_flag_file("--token-file", g.token_file);
    while (!options.token.empty() && std::isspace(static_cast<unsigned char>(options.token.back()))) {
      options.token.pop_back();
    }
  }
  options.tls = g.tls || !g.tls_ca.empty() || !g.tls_cert.empty();
  if (!g.tls_ca.empty()) options.tls_root_certificates = read_flag_file("--tls-ca", g.tls_ca);
  if (!g.tls_cert.empty()) options.tls_client_certificate = read_flag_file("--tls-cert", g.tls_cert);
  if (!g.tls_key.empty()) options.tls_client_key = read_flag_file("--tls-key", g.tls_key);
  options.tls_server_name = g.tls_server_name;
  return animspace::Client(g.server, options);
}

std::string kind_label(animspace::v1::ModelKind kind) {
  std::string name = animspace::v1::ModelKind_Name(kind);
  const std::string prefix = "MODEL_KIND_";
  return name.rfind(prefix, 0) == 0 ? name.substr(prefix.size()) : name;
}

// `value` with `decimals` fixed decimals, for table cells.
std::string fixed(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

// "SERVER (the server completes a blend or miss with its posing engine)".
std::string fail_through_label(animspace::v1::FailThrough fail_through, animspace::v1::ServerEngine engine) {
  std::string name = animspace::v1::FailThrough_Name(fail_through);
  const std::string prefix = "FAIL_THROUGH_";
  if (name.rfind(prefix, 0) == 0) name = name.substr(prefix.size());
  switch (fail_through) {
    case animspace::v1::FAIL_THROUGH_SERVER:
      return name + (engine == animspace::v1::SERVER_ENGINE_ILLUMINATION
                         ? " (the server completes a blend or miss with its illumination engine, for the lights a "
                           "request sends)"
                         : " (the server completes a blend or miss with its posing engine)");
    case animspace::v1::FAIL_THROUGH_CLIENT:
      return name + " (a blend or miss asks the caller for the full values)";
    case animspace::v1::FAIL_THROUGH_IMPOSSIBLE:
      return name + " (cross-PMSC: a miss cannot be completed)";
    default:
      return name;
  }
}

void print_summary(const animspace::v1::ModelSummary& model) {
  std::printf("%s (default version %llu)\n", model.name().c_str(),
              static_cast<unsigned long long>(model.default_version()));
  for (const auto& v : model.versions()) {
    if (v.state() == animspace::v1::VERSION_STATE_FAILED) {
      std::printf("  version %llu  REFUSED: %s\n", static_cast<unsigned long long>(v.version()), v.error().c_str());
      continue;
    }
    if (v.state() == animspace::v1::VERSION_STATE_EVICTED) {
      std::printf("  version %llu  EVICTED (%.1f MiB when loaded; unloaded under the server's --memory-budget, loaded "
                  "again by the next request for it)\n",
                  static_cast<unsigned long long>(v.version()), static_cast<double>(v.resident_bytes()) / (1 << 20));
    }
    std::printf("  version %llu  %s  %u points × %u channels, %u faces, %u bones, %u frames", 
                static_cast<unsigned long long>(v.version()), kind_label(v.kind()).c_str(), v.point_count(),
                v.channel_count(), v.face_count(), v.bone_count(), v.frame_count());
    if (v.key_point_count() > 0) std::printf(", %u key points, basis %u", v.key_point_count(), v.basis_size());
    if (v.lod_level_count() > 0) std::printf(", %u LOD levels", v.lod_level_count());
    std::printf("\n");
    if (!v.description().empty()) std::printf("    %s\n", v.description().c_str());
  }
}

int run_list(const Globals& g) {
  auto client = connect(g);
  auto models = client.list_models();
  if (g.json) {
    animspace::v1::ListModelsResponse response;
    for (auto& m : models) *response.add_models() = m;
    animspace::cli::print_json(animspace::cli::proto_json(response));
    return 0;
  }
  if (models.empty()) std::printf("no models loaded\n");
  for (const auto& m : models) print_summary(m);
  return 0;
}

int run_describe(const Globals& g, const std::string& name, uint64_t version) {
  auto client = connect(g);
  auto model = client.describe_model(name, version);
  if (g.json) {
    animspace::cli::print_json(animspace::cli::proto_json(model));
    return 0;
  }
  print_summary(model);
  for (const auto& v : model.versions()) {
    if (v.state() != animspace::v1::VERSION_STATE_AVAILABLE) continue;
    if (v.key_point_count() > 0) {
      // What --json says too: the soft cache's thresholds on the error estimate and who computes a miss.
      const std::string estimate =
          v.check_point_count() > 0
              ? "error estimate max(w·e_key, e_check) of a pose sent with its " +
                    std::to_string(v.check_point_count()) + " check points"
              : std::string("RMS key-point error e_key");
      std::printf("  version %llu soft cache: ε_min %.6g, ε_max %.6g (%s, model units: hit below ε_min, miss above "
                  "ε_max, blend between); fail-through %s\n",
                  static_cast<unsigned long long>(v.version()), static_cast<double>(v.epsilon_min()),
                  static_cast<double>(v.epsilon_max()), estimate.c_str(),
                  fail_through_label(v.fail_through(), v.server_engine()).c_str());
      if (v.check_point_count() > 0) {
        std::printf("  version %llu check points: %u (computed and sent like key points; a pose sent without them is "
                    "judged on e_key against stricter key-only thresholds)\n",
                    static_cast<unsigned long long>(v.version()), v.check_point_count());
      }
      // The server's own sentence; a server from before issue #35 sends none, and the model's
      // metadata says what it can.
      const std::string calibration = v.calibration_statement().empty()
                                          ? animspace::cli::calibration_label(v.metadata())
                                          : v.calibration_statement();
      std::printf("  version %llu calibration: %s\n", static_cast<unsigned long long>(v.version()),
                  calibration.c_str());
      if (v.subspace_kind() == animspace::v1::SUBSPACE_KIND_ARTICULATED) {
        std::printf("  version %llu subspace: articulated, %u bones (12 coordinates each: the bone's affine transform "
                    "about its rest centre) + %u residual components = M %u\n",
                    static_cast<unsigned long long>(v.version()), v.subspace_bone_count(), v.residual_components(),
                    v.basis_size());
      } else if (v.subspace_kind() == animspace::v1::SUBSPACE_KIND_LINEAR) {
        std::printf("  version %llu subspace: linear, M %u principal components of the training frames\n",
                    static_cast<unsigned long long>(v.version()), v.basis_size());
      }
    }
    std::printf("  version %llu metadata:\n", static_cast<unsigned long long>(v.version()));
    std::map<std::string, std::string> sorted(v.metadata().begin(), v.metadata().end());
    for (const auto& [key, value] : sorted) std::printf("    %s = %s\n", key.c_str(), value.c_str());
    std::printf("  sections:");
    for (const auto& s : v.sections()) std::printf(" %s", s.c_str());
    std::printf("\n");
  }
  return 0;
}

int run_health(const Globals& g) {
  auto client = connect(g);
  const auto status = client.health();
  const std::string name = grpc::health::v1::HealthCheckResponse::ServingStatus_Name(status);
  if (g.json) {
    animspace::cli::print_json({{"status", name}});
  } else {
    std::printf("%s\n", name.c_str());
  }
  return status == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

int run_server_info(const Globals& g) {
  auto client = connect(g);
  auto info = client.server_info();
  if (g.json) {
    animspace::cli::print_json(animspace::cli::proto_json(info));
    return 0;
  }
  std::printf("animspaced %s (%s), renderer %s\n", info.server_version().c_str(), info.api().c_str(),
              info.renderer().c_str());
  std::printf("limits: message %llu bytes, batch %u poses, thumbnail %u px, %u concurrent calls, ",
              static_cast<unsigned long long>(info.max_message_bytes()), info.max_batch_poses(),
              info.max_thumbnail_px(), info.max_concurrent_calls());
  if (info.grpc_memory_bytes() == 0) {
    std::printf("requests arriving unbounded\n");
  } else {
    std::printf("requests arriving %llu bytes\n", static_cast<unsigned long long>(info.grpc_memory_bytes()));
  }
  std::printf("kernel %s; batching up to %u poses, delay %llu µs\n", info.kernel().c_str(), info.max_batch_size(),
              static_cast<unsigned long long>(info.batch_delay_us()));
  std::printf("implemented:\n");
  for (const auto& rpc : info.implemented_rpcs()) std::printf("  %s\n", rpc.c_str());
  return 0;
}

int run_stats(const Globals& g, const std::string& model, bool reset) {
  auto client = connect(g);
  auto stats = client.stats(model, reset);
  if (g.json) {
    animspace::cli::print_json(animspace::cli::proto_json(stats));
    return 0;
  }
  // Latency: the mean is exact (the histogram's sum / count); p50 and p99 are estimated inside the
  // histogram bucket that holds them, so they are marked "~" and explained under the table.
  std::printf("%-24s %9s %7s %9s %9s %9s %9s %7s %9s %9s %9s\n", "model", "requests", "errors", "poses", "hits",
              "blends", "misses", "hit%", "mean ms", "~p50 ms", "~p99 ms");
  for (const auto& s : stats.models()) {
    const uint64_t verdicts = s.hits() + s.blends() + s.misses();
    // Only poses through a soft cache have a verdict: '-' for a model that had none.
    const std::string hit_rate =
        verdicts == 0 ? "-" : fixed(100.0 * static_cast<double>(s.hits()) / static_cast<double>(verdicts), 1) + "%";
    const auto& latency = s.latency_seconds();
    const std::string mean =
        latency.total_count() == 0 ? "-"
                                   : fixed(1e3 * latency.sum() / static_cast<double>(latency.total_count()), 3);
    const auto ms = [&latency](double seconds) {
      return latency.total_count() == 0 ? std::string("-") : fixed(1e3 * seconds, 3);
    };
    std::printf("%-24s %9llu %7llu %9llu %9llu %9llu %9llu %7s %9s %9s %9s\n", s.model().c_str(),
                static_cast<unsigned long long>(s.requests()), static_cast<unsigned long long>(s.errors()),
                static_cast<unsigned long long>(s.poses()), static_cast<unsigned long long>(s.hits()),
                static_cast<unsigned long long>(s.blends()), static_cast<unsigned long long>(s.misses()),
                hit_rate.c_str(), mean.c_str(), ms(s.latency_p50_s()).c_str(), ms(s.latency_p99_s()).c_str());
  }
  std::printf("poses: key-point poses through the soft cache and skeleton poses; hit%% of the poses with a verdict.\n"
              "latency: per request on the server, milliseconds; mean exact, ~p50/~p99 interpolated inside the "
              "latency histogram's bucket\n(bounds 0.05 ms … 10 s, about ×2.5 apart), so they lie between bucket "
              "bounds rather than being measured values.\n");
  return 0;
}

int run_keys(const Globals& g, const std::string& model, uint64_t version) {
  auto client = connect(g);
  const animspace::KeyPoints keys = client.describe_key_points(model, version);
  const std::string fail_through = animspace::v1::FailThrough_Name(keys.fail_through);
  if (g.json) {
    animspace::cli::print_json({{"model", model},
                                {"model_version", keys.model_version},
                                {"key_point_indices", keys.indices},
                                {"key_point_regions", keys.regions},
                                {"check_point_indices", keys.check_point_indices},
                                {"check_point_regions", keys.check_point_regions},
                                {"channel_count", keys.channel_count},
                                {"control_point_count", keys.control_point_count},
                                {"fail_through", fail_through}});
    return 0;
  }
  std::printf("%s version %llu: %zu key points × %u channels out of %u control points, fail-through %s\n",
              model.c_str(), static_cast<unsigned long long>(keys.model_version), keys.indices.size(), keys.channel_count,
              keys.control_point_count, fail_through.c_str());
  for (size_t k = 0; k < keys.indices.size(); ++k) {
    std::printf("%s%u", k == 0 ? "  " : (k % 16 == 0 ? "\n  " : " "), keys.indices[k]);
  }
  std::printf("\n");
  if (!keys.check_point_indices.empty()) {
    std::printf("%zu check points (computed and sent like key points; the projection never uses them):\n",
                keys.check_point_indices.size());
    for (size_t c = 0; c < keys.check_point_indices.size(); ++c) {
      std::printf("%s%u", c == 0 ? "  " : (c % 16 == 0 ? "\n  " : " "), keys.check_point_indices[c]);
    }
    std::printf("\n");
  }
  return 0;
}

int run_retrain(const Globals& g, const animspace::v1::RetrainRequest& request, int deadline_s) {
  auto client = connect(g);
  const auto result = client.retrain(request, std::chrono::seconds(deadline_s));
  if (g.json) {
    animspace::cli::print_json(animspace::cli::proto_json(result));
    return 0;
  }
  if (request.dry_run()) {
    std::printf("dry run: nothing written%s\n",
                result.unchanged() ? " (and nothing would change: no new completed miss and no option changed — "
                                     "a retrain would be refused)"
                                   : "");
  } else {
    std::printf("%s: version %llu published and serving\n", request.model().name().c_str(),
                static_cast<unsigned long long>(result.new_version()));
  }
  std::printf("  %u training frames (%u from logged misses), basis %u, %u key points\n", result.training_frames(),
              result.misses_used(), result.basis_size(), result.key_point_count());
  std::printf("  max training error %.6g, condition number %.3g, %.2f s\n", result.max_training_error(),
              result.condition_number(), result.training_seconds());
  animspace::cli::print_soft_cache_change(result.previous_epsilon_min(), result.epsilon_min(),
                                          result.previous_epsilon_max(), result.epsilon_max(),
                                          result.training_frames(), result.previous_hit_rate(), result.hit_rate());
  if (result.misses_inconsistent() > 0) {
    std::printf("  %u logged misses left out: their full values do not repeat their key values\n",
                result.misses_inconsistent());
  }
  return 0;
}

int run_load(const Globals& g, const std::string& model, uint64_t version, bool unload) {
  auto client = connect(g);
  if (unload) {
    client.unload_model(model, version);
    if (g.json) {
      animspace::cli::print_json({{"model", model}, {"version", version}, {"unloaded", true}});
      return 0;
    }
    std::printf("%s%s unloaded\n", model.c_str(),
                version == 0 ? "" : (" version " + std::to_string(version)).c_str());
    return 0;
  }
  const auto summary = client.load_model(model, version);
  if (g.json) {
    animspace::cli::print_json(animspace::cli::proto_json(summary));
    return 0;
  }
  print_summary(summary);
  return 0;
}

int run_inspect(const Globals& g, const std::string& path) {
  auto container = animspace::container::read_file(path);
  if (!container) {
    std::fprintf(stderr, "animspace inspect: %s\n", container.error().message.c_str());
    return 2;
  }
  auto info = animspace::model::describe(*container, path);
  if (g.json) {
    nlohmann::json sections = nlohmann::json::array();
    for (const auto& [name, section] : container->sections()) {
      sections.push_back({{"name", name}, {"rows", section.rows}, {"cols", section.cols}, {"bytes", section.size()}});
    }
    animspace::cli::print_json({{"file", path},
                                {"metadata", container->metadata()},
                                {"sections", sections},
                                {"loadable", info.ok()},
                                {"error", info.ok() ? "" : info.error().message}});
  } else {
    std::printf("%s\n", path.c_str());
    for (const auto& [key, value] : container->metadata()) std::printf("  %s = %s\n", key.c_str(), value.c_str());
    for (const auto& [name, section] : container->sections()) {
      std::printf("  section %-32s %8u × %-6u %10zu bytes\n", name.c_str(), section.rows, section.cols,
                  section.size());
    }
  }
  if (!info) {
    std::fprintf(stderr, "animspace inspect: the daemon would refuse it: %s\n", info.error().message.c_str());
    return 1;
  }
  return 0;
}

int run_demo_repository(const std::string& dir) {
  std::optional<animspace::ProgressCallback> progress(animspace::cli::progress_bars("demo-repository"));
  const animspace::Status status = animspace::demo::write_bundled_demo(dir, *progress);
  progress.reset();  // ends the bar's line before the report
  if (!status.ok()) {
    std::fprintf(stderr, "animspace demo-repository: %s\n", status.error().message.c_str());
    return 2;
  }
  std::printf("wrote the demo model repository to %s\n", dir.c_str());
  return 0;
}

std::string subcommand_list(const CLI::App& app) {
  std::string list;
  for (const CLI::App* command : app.get_subcommands([](const CLI::App*) { return true; })) {
    list += "\n  " + command->get_name();
    list.append(command->get_name().size() < 18 ? 18 - command->get_name().size() : 1, ' ');
    std::string description = command->get_description();
    if (const size_t stop = description.find_first_of(".:("); stop != std::string::npos && stop > 20) {
      description = description.substr(0, stop);
    }
    while (!description.empty() && description.back() == ' ') description.pop_back();
    if (description.size() > 90) description = description.substr(0, 87) + "...";
    list += description;
  }
  return list;
}

// 0 when exactly one subcommand was parsed and nothing was left over; else the usage error
// (exit 2) naming what was wrong, with the subcommands listed.
int check_subcommand(const CLI::App& app) {
  const std::vector<std::string> extras = app.remaining();
  if (app.get_subcommands().empty()) {
    if (!extras.empty()) {
      std::vector<std::string> names;
      for (const CLI::App* command : app.get_subcommands([](const CLI::App*) { return true; })) {
        names.push_back(command->get_name());
      }
      std::string suggestion;
      for (const std::string& near : animspace::nearest_names(extras.front(), names)) {
        suggestion += (suggestion.empty() ? "; did you mean '" : "' or '") + near;
      }
      if (!suggestion.empty()) suggestion += "'?";
      std::fprintf(stderr, "animspace: unknown subcommand '%s'%s; the subcommands are:%s\n", extras.front().c_str(),
                   suggestion.c_str(), subcommand_list(app).c_str());
    } else {
      std::fprintf(stderr, "animspace: a subcommand is required:%s\nRun 'animspace --help' for the global options, "
                           "'animspace <subcommand> --help' for each.\n",
                   subcommand_list(app).c_str());
    }
    return 2;
  }
  if (!extras.empty()) {
    std::string words;
    for (const std::string& word : extras) words += " '" + word + "'";
    std::fprintf(stderr, "animspace %s: unexpected argument%s%s (see 'animspace %s --help')\n",
                 app.get_subcommands().front()->get_name().c_str(), extras.size() == 1 ? "" : "s", words.c_str(),
                 app.get_subcommands().front()->get_name().c_str());
    return 2;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Globals g;
  CLI::App app{"animspace — query animspaced, and work on model files offline"};
  // At most one; none, or a word that names none, is reported below with the list.
  app.require_subcommand(0, 1);
  app.add_option("-s,--server", g.server, "animspaced address (gRPC target)")->capture_default_str();
  app.add_option("--deadline-ms", g.deadline_ms, "Deadline for each call")->capture_default_str();
  app.add_flag("--json", g.json, "Print JSON for scripts instead of tables");
  app.add_option("--token-file", g.token_file,
                 "File holding the bearer token for servers started with --auth-token-file "
                 "(or set ANIMSPACE_TOKEN)");
  app.add_flag("--tls", g.tls, "Connect with TLS, trusting the system's CAs");
  app.add_option("--tls-ca", g.tls_ca, "Connect with TLS, trusting this CA bundle (PEM)");
  app.add_option("--tls-cert", g.tls_cert, "TLS client certificate (PEM), for servers that require one");
  app.add_option("--tls-key", g.tls_key, "TLS client private key (PEM)");
  app.add_option("--tls-server-name", g.tls_server_name, "Name the server certificate must carry, if not the host");

  auto* list = app.add_subcommand("list", "List the models the server serves, with their versions");
  auto* health = app.add_subcommand("health", "grpc.health.v1 status of the server (exit 0 when SERVING)");
  auto* info = app.add_subcommand("server-info", "Server version, limits and implemented RPCs");

  std::string model;
  uint64_t version = 0;
  auto* describe = app.add_subcommand("describe", "Describe one model: versions, sizes, metadata, sections");
  describe->add_option("model", model, "Model name")->required();
  describe->add_option("--version", version, "One version (default: all)");

  bool reset = false;
  auto* stats = app.add_subcommand("stats", "Per-model soft-cache hit rates and latency");
  stats->add_option("model", model, "Model name (default: every model)");
  stats->add_flag("--reset", reset, "Zero the counters after reading");

  auto* keys = app.add_subcommand("keys", "The key points a PMSC model needs, in the order evaluation expects");
  keys->add_option("model", model, "Model name")->required();
  keys->add_option("--version", version, "Version (default: the one served for version 0)");

  animspace::v1::RetrainRequest retrain_request;
  std::string retrain_model;
  uint64_t retrain_version = 0;
  bool exclude_misses = false;
  bool dry_run = false;
  float error_bound = 0;
  uint32_t max_key_points = 0;
  int retrain_deadline_s = 1800;
  auto* retrain = app.add_subcommand(
      "retrain",
      "Admin: retrain a PMSC model on its training frames plus the logged misses that carry full values, "
      "publish it as the next version and hot-swap it in (calls in flight finish on the old one)");
  retrain->add_option("model", retrain_model, "Model name")->required();
  retrain->add_option("--version", retrain_version, "Version to start from (default: the served one)");
  retrain->add_flag("--exclude-misses", exclude_misses, "Ignore the miss log (retrain with new options only)");
  retrain->add_option("--error-bound", error_bound, "New bound on the max per-point training error, model units");
  retrain->add_option("--max-key-points", max_key_points, "New key point budget");
  retrain->add_flag("--dry-run", dry_run, "Train and report, but write nothing");
  retrain->add_option("--deadline-s", retrain_deadline_s, "Deadline for the retrain call")->capture_default_str();

  animspace::cli::EvaluateArgs evaluate_args;
  auto* evaluate = animspace::cli::add_evaluate(app, evaluate_args);
  animspace::cli::PlayArgs play_args;
  auto* play = animspace::cli::add_play(app, play_args);
  animspace::cli::PoseArgs pose_args;
  auto* pose = animspace::cli::add_pose(app, pose_args);
  animspace::cli::LodArgs lod_args;
  auto* lod = animspace::cli::add_lod(app, lod_args);
  animspace::cli::ThumbnailArgs thumbnail_args;
  auto* thumbnail = animspace::cli::add_thumbnail(app, thumbnail_args);
  animspace::cli::RelightArgs relight_args;
  auto* relight = animspace::cli::add_relight(app, relight_args);

  auto* load = app.add_subcommand("load", "Admin: (re)load a model, or one version, from the repository");
  load->add_option("model", model, "Model name")->required();
  load->add_option("--version", version, "One version (default: every version found)");
  auto* unload = app.add_subcommand("unload", "Admin: stop serving a model, or one version");
  unload->add_option("model", model, "Model name")->required();
  unload->add_option("--version", version, "One version (default: all)");

  std::string path;
  auto* inspect = app.add_subcommand("inspect", "Offline: print a model file's metadata and sections and check it");
  inspect->add_option("file", path, "model.anim file")->required()->check(CLI::ExistingFile);

  auto* demo = app.add_subcommand("demo-repository", "Offline: write the bundled demo model repository");
  demo->add_option("directory", path, "Repository directory to create")->required();

  animspace::cli::TrainPmscArgs train_pmsc_args;
  auto* train_pmsc = animspace::cli::add_train_pmsc(app, train_pmsc_args);
  animspace::cli::TrainIlluminationArgs train_illumination_args;
  auto* train_illumination = animspace::cli::add_train_illumination(app, train_illumination_args);
  animspace::cli::FitArgs fit_args;
  auto* fit = animspace::cli::add_fit(app, fit_args);
  animspace::cli::ImportRigArgs import_rig_args;
  auto* import_rig = animspace::cli::add_import_rig(app, import_rig_args);
  animspace::cli::BuildLodArgs build_lod_args;
  auto* build_lod = animspace::cli::add_build_lod(app, build_lod_args);
  animspace::cli::ExportLodArgs export_lod_args;
  auto* export_lod = animspace::cli::add_export_lod(app, export_lod_args);
  animspace::cli::ExportRigArgs export_rig_args;
  auto* export_rig = animspace::cli::add_export_rig(app, export_rig_args);
  animspace::cli::AtlasArgs atlas_args;
  auto* atlas = animspace::cli::add_atlas(app, atlas_args);
  animspace::cli::RetrainOfflineArgs retrain_offline_args;
  auto* retrain_offline = animspace::cli::add_retrain_offline(app, retrain_offline_args);
  animspace::cli::CalibrateArgs calibrate_args;
  auto* calibrate = animspace::cli::add_calibrate(app, calibrate_args);
  animspace::cli::SubdivideArgs subdivide_args;
  auto* subdivide = animspace::cli::add_subdivide(app, subdivide_args);

  // Extras at the top level only (set after the subcommands, which would inherit it): a word
  // that is no subcommand lands in remaining() and is named below instead of CLI11's "A
  // subcommand is required".
  app.allow_extras();
  CLI11_PARSE(app, argc, argv);
  if (const int usage = check_subcommand(app); usage != 0) return usage;
  try {
    if (*train_pmsc) return animspace::cli::run_train_pmsc(train_pmsc_args, g.json);
    if (*train_illumination) return animspace::cli::run_train_illumination(train_illumination_args, g.json);
    if (*fit) return animspace::cli::run_fit(fit_args, g.json);
    if (*import_rig) return animspace::cli::run_import_rig(import_rig_args, g.json);
    if (*build_lod) return animspace::cli::run_build_lod(build_lod_args, g.json);
    if (*export_lod) return animspace::cli::run_export_lod(export_lod_args, g.json);
    if (*export_rig) return animspace::cli::run_export_rig(export_rig_args, g.json);
    if (*atlas) return animspace::cli::run_atlas(atlas_args, g.json);
    if (*retrain_offline) return animspace::cli::run_retrain_offline(retrain_offline_args, g.json);
    if (*calibrate) return animspace::cli::run_calibrate(calibrate_args, g.json);
    if (*subdivide) return animspace::cli::run_subdivide(subdivide_args, g.json);
    if (*list) return run_list(g);
    if (*health) return run_health(g);
    if (*info) return run_server_info(g);
    if (*describe) return run_describe(g, model, version);
    if (*stats) return run_stats(g, model, reset);
    if (*keys) return run_keys(g, model, version);
    if (*evaluate) {
      auto client = connect(g);
      return animspace::cli::run_evaluate(evaluate_args, client, g.json);
    }
    if (*pose) {
      auto client = connect(g);
      return animspace::cli::run_pose(pose_args, client, g.json);
    }
    if (*play) {
      auto client = connect(g);
      return animspace::cli::run_play(play_args, client, g.json);
    }
    if (*lod) {
      auto client = connect(g);
      return animspace::cli::run_lod(lod_args, client, g.json);
    }
    if (*thumbnail) {
      auto client = connect(g);
      return animspace::cli::run_thumbnail(thumbnail_args, client, g.json);
    }
    if (*relight) {
      auto client = connect(g);
      return animspace::cli::run_relight(relight_args, client, g.json);
    }
    if (*retrain) {
      retrain_request.mutable_model()->set_name(retrain_model);
      retrain_request.mutable_model()->set_version(retrain_version);
      retrain_request.set_exclude_misses(exclude_misses);
      retrain_request.set_error_bound(error_bound);
      retrain_request.set_max_key_points(max_key_points);
      retrain_request.set_dry_run(dry_run);
      return run_retrain(g, retrain_request, retrain_deadline_s);
    }
    if (*load) return run_load(g, model, version, false);
    if (*unload) return run_load(g, model, version, true);
    if (*inspect) return run_inspect(g, path);
    if (*demo) return run_demo_repository(path);
  } catch (const animspace::RpcError& error) {
    std::fprintf(stderr, "animspace: %s\n", error.what());
    return 3;
  }
  return 0;
}
