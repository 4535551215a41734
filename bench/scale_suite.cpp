// The scale suite (issue #53 item 1): what a studio-sized character costs, measured rather than
// estimated, with the small character it is made from measured in the same run as its baseline.
//
// Data with unlimited truth: the cow rig (../shared/data/cow-rig) imported to animation space with
// `animspace import-rig` (or, --scale-character horse-gallop, horse-gallop's `animspace fit`),
// subdivided in animation space with `animspace subdivide` (Loop; level
// L has about 4^L times the rig's 11,666 points: 46.7k and 186k at 1 and 2), and posed
// in-process at --scale-frames random joint rotations (every joint up to kMaxJointAngle). The
// poses are streamed to a point cache one frame at a time, so the bench never holds the sequence.
//
// Each level runs the user's commands as child processes, timed from the outside with the child's
// own peak resident memory (wait4):
//   train-pmsc (each --scale-kinds)  train_seconds, peak_rss_bytes against input_bytes (the .pc2)
//   build-lod (P from kLodSamplePoses   lod_build_seconds, beside meshopt_simplify in-process on the
//   random poses, as the lod suite)
//                                    rest pose to the same levels' vertex counts (meshopt_seconds)
//   animspaced                       --scale-models copies of the trained model served from one
//                                    repository: registry_rss_bytes (VmRSS once SERVING),
//                                    get_basis_bytes (one GetBasis as received) and
//                                    client_reconstruct_us (the C++ client's reconstruction of one
//                                    answer sent as coordinates, median), thumbnail_p50_ms (a
//                                    256² thumbnail of a stored frame drawn by the daemon), and
//                                    get_lod_bytes / get_lod_chunks / get_lod_ms (GetLod of
//                                    build-lod's level 0 in animation-space form, median),
//                                    get_basis_float16_bytes, get_basis_compact_bytes,
//                                    basis_compact_layout and client_reconstruct_compact_us (the
//                                    COMPACT layout: SKINNED for an articulated model), and a second
//                                    daemon whose --memory-budget holds 3 copies serving every copy in turn
//                                    (budget_peak_rss_bytes, budget_reload_ms)
//   the error across 20 other random poses of build-lod's level nearest a tenth of the vertices
//   and of meshoptimizer's rest-pose simplification to as many (lod_rms_error_over_diag, …)
// Level 0 is the baseline: every figure of a larger level is also printed as a ratio to it.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "bench/child_process.h"
#include "bench/lod_comparison.h"
#include "bench/scratch_directory.h"
#include "bench/serving.h"
#include "bench/suites.h"
#include "clients/cpp/client.h"
#include "clients/cpp/coordinates.h"
#include "clients/cpp/tools/quantile.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/container/model_container.h"
#include "core/lod/lod_io.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "core/pmsc/pmsc_io.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"

namespace animspace::bench {
namespace {

namespace as = animation_space;

constexpr double kMaxJointAngle = 45;  // degrees: the pmsc suite's cow rows test up to 60
constexpr uint64_t kPoseSeed = 53;
constexpr int kLodSamplePoses = 200;
constexpr uint32_t kThumbnailPx = 256;

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

uint64_t file_bytes(const std::filesystem::path& path) {
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  return error ? 0 : static_cast<uint64_t>(size);
}

// A memory figure of a running process from /proc/<pid>/status, bytes: VmRSS (resident now) or
// VmHWM (its peak); 0 when it cannot be read.
uint64_t process_memory_bytes(pid_t pid, const std::string& field = "VmRSS") {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.starts_with(field + ":")) return static_cast<uint64_t>(std::stoll(line.substr(field.size() + 1))) * 1024;
  }
  return 0;
}

// MemAvailable of this machine, bytes.
uint64_t available_memory_bytes() {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.starts_with("MemAvailable:")) return static_cast<uint64_t>(std::stoll(line.substr(13))) * 1024;
  }
  return 0;
}

// Runs one of the CLI's commands; prints its log's tail and returns nullopt when it fails.
std::optional<ChildRun> run_cli(const std::vector<std::string>& arguments, const std::filesystem::path& log,
                                const std::string& what) {
  std::vector<std::string> argv{harness::program_path("animspace").string()};
  argv.insert(argv.end(), arguments.begin(), arguments.end());
  const ChildRun run = run_program(argv, log);
  if (run.exit_status == 0) return run;
  std::string text = read_text(log);
  if (text.size() > 2000) text = "…" + text.substr(text.size() - 2000);
  std::printf("scale: %s exited with %d after %.1f s (peak %.2f GB):\n%s\n", what.c_str(), run.exit_status, run.seconds,
              static_cast<double>(run.peak_rss_bytes) / 1e9, text.c_str());
  return std::nullopt;
}

// The level's character: the model file and the animation-space model in it.
struct Character {
  std::filesystem::path file;
  as::AnimationSpaceModel model;
};

std::optional<Character> read_character(const std::filesystem::path& file) {
  auto container = container::read_file(file);
  if (!container) {
    std::printf("scale: %s\n", container.error().message.c_str());
    return std::nullopt;
  }
  auto model = as::load(*container, file.string());
  if (!model) {
    std::printf("scale: %s\n", model.error().message.c_str());
    return std::nullopt;
  }
  return Character{file, std::move(*model)};
}

// reference.obj (the rest pose) and frames.pc2 (`frames` random poses, streamed) under `folder`:
// the sequence folder train-pmsc reads. Returns false after printing why.
bool write_sequence(const as::AnimationSpaceModel& model, int frames, const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  PointMatrix posed;
  as::evaluate(model, as::rest_pose(model.skeleton), posed);
  if (const Status written = mesh_io::write_triangle_mesh(folder / "reference.obj", TriangleMesh{posed, model.faces});
      !written.ok()) {
    std::printf("scale: %s\n", written.error().message.c_str());
    return false;
  }
  const auto poses =
      as::random_joint_rotation_poses(model.skeleton, frames, kMaxJointAngle * std::numbers::pi / 180, kPoseSeed);
  std::ofstream out(folder / "frames.pc2", std::ios::binary);
  const std::string header = mesh_io::pc2_header(model.vertex_count(), frames);
  out.write(header.data(), static_cast<std::streamsize>(header.size()));
  for (const as::TransformList& pose : poses) {
    as::evaluate(model, pose, posed);
    out.write(reinterpret_cast<const char*>(posed.data()), static_cast<std::streamsize>(sizeof(float) * posed.size()));
  }
  out.close();
  if (!out) {
    std::printf("scale: writing %s failed\n", (folder / "frames.pc2").string().c_str());
    return false;
  }
  return true;
}

// meshopt_simplify from the full rest pose to each vertex count in turn (what a user of that
// library runs to get the same levels), seconds in all. It targets an index count: ask for the
// triangles a closed mesh of that many vertices has, with an unlimited error.
double meshopt_seconds(const as::AnimationSpaceModel& model, const std::vector<int>& vertex_counts) {
  PointMatrix rest;
  as::evaluate(model, as::rest_pose(model.skeleton), rest);
  const std::vector<unsigned int> indices(model.faces.data(), model.faces.data() + model.faces.size());
  const double face_ratio = static_cast<double>(model.faces.rows()) / model.vertex_count();
  std::vector<unsigned int> out(indices.size());
  const auto start = std::chrono::steady_clock::now();
  for (const int target : vertex_counts) {
    const size_t target_indices = 3 * static_cast<size_t>(std::lround(face_ratio * target));
    const size_t count = meshopt_simplify(out.data(), indices.data(), indices.size(), rest.data(),
                                          static_cast<size_t>(rest.rows()), sizeof(float) * 3, target_indices, 1e9f);
    do_not_optimize(count);
  }
  return seconds_since(start);
}

// Every level's vertex count but level 0's, read back from build-lod's output.
std::vector<int> level_vertex_counts(const std::filesystem::path& file) {
  std::vector<int> counts;
  auto container = container::read_file(file);
  if (!container) return counts;
  auto model = as::load(*container, file.string());
  if (!model) return counts;
  auto levels = lod::load_levels(*container, *model, file.string());
  if (!levels) return counts;
  for (int l = 1; l < levels->count(); ++l) counts.push_back(levels->levels[static_cast<size_t>(l)].model.vertex_count());
  return counts;
}

// The error across poses (Merry 2007 §8.5) of build-lod's level nearest a tenth of the vertices
// and of meshoptimizer's rest-pose simplification to the same vertex count, over kErrorPoses
// random poses that build-lod's own sample poses are not (another seed): the lod suite's measure.
constexpr int kErrorPoses = 20;

struct LodError {
  int vertices = 0;  // of the level compared
  int meshopt_vertices = 0;
  SurfaceError lod;
  SurfaceError meshopt;
};

std::optional<LodError> lod_error(const as::AnimationSpaceModel& character, const std::filesystem::path& lod_file) {
  auto container = container::read_file(lod_file);
  if (!container) return std::nullopt;
  auto model = as::load(*container, lod_file.string());
  if (!model) return std::nullopt;
  auto levels = lod::load_levels(*container, *model, lod_file.string());
  if (!levels || levels->count() < 2) return std::nullopt;
  const int target = character.vertex_count() / 10;
  int nearest = 1;
  for (int l = 1; l < levels->count(); ++l) {
    const auto distance = [&](int at) { return std::abs(levels->levels[static_cast<size_t>(at)].model.vertex_count() - target); };
    if (distance(l) < distance(nearest)) nearest = l;
  }
  const as::AnimationSpaceModel& level = levels->levels[static_cast<size_t>(nearest)].model;
  const auto poses = as::random_joint_rotation_poses(character.skeleton, kErrorPoses,
                                                     kMaxJointAngle * std::numbers::pi / 180, kPoseSeed + 2);
  const double diagonal = rest_diagonal(character);
  const Simplified meshopt = meshoptimizer_rest(character, level.vertex_count());
  LodError error;
  error.vertices = level.vertex_count();
  error.meshopt_vertices = meshopt.model.vertex_count();
  error.lod = measure_across_poses(character, level, poses, diagonal);
  error.meshopt = measure_across_poses(character, meshopt.model, poses, diagonal);
  return error;
}

// What serving `models` copies of one trained model costs.
struct Serving {
  uint64_t registry_rss_bytes = 0;
  uint64_t get_basis_bytes = 0;
  double get_basis_seconds = 0;
  double client_reconstruct_us = 0;
  // The same basis asked for in float16, and the largest difference it makes to the answer's
  // reconstruction, over the rest pose's diagonal.
  uint64_t get_basis_float16_bytes = 0;
  double float16_reconstruct_max_error_over_diag = -1;
  // The basis asked for COMPACT (issue #51 item 4): an articulated model's comes SKINNED. Its bytes,
  // the layout that came, and the same answer's reconstruction with it (median).
  uint64_t get_basis_compact_bytes = 0;
  std::string basis_compact_layout;
  double client_reconstruct_compact_us = 0;
  // The copies served again by a daemon with --memory-budget of kBudgetVersions versions' resident
  // bytes: its peak RSS (VmHWM) over the whole round, and the median time of a call that finds
  // its version evicted and loads it again (< 0: not measured, budget_status says why).
  uint64_t memory_budget_bytes = 0;
  uint64_t budget_peak_rss_bytes = 0;
  double budget_reload_ms = -1;
  std::string budget_status;
  double thumbnail_p50_ms = -1;  // < 0: not drawn (no renderer), thumbnail_status says why
  std::string thumbnail_status;
  // GetLod of the levels build-lod made, level 0 (every vertex) in animation-space form.
  uint64_t get_lod_bytes = 0;
  uint64_t get_lod_chunks = 0;
  double get_lod_ms = -1;  // < 0: not measured, get_lod_status says why
  std::string get_lod_status;
  std::string status;  // "" when measured, else why not
};

// Versions a budget holds in the memory-budget round: a render farm's working set, smaller than
// the copies served.
constexpr int kBudgetVersions = 3;

// The copies of `repository` (scale-00 …) served by a daemon whose --memory-budget holds
// kBudgetVersions of them (issue #53; `one_version`: a copy's resident bytes as a daemon without a
// budget measured them): one call to each copy in turn, every one of which finds its version
// evicted and loads it again.
void measure_budget(const std::filesystem::path& repository, int models, uint64_t one_version,
                    const std::filesystem::path& work, Serving& serving) {
  if (models <= kBudgetVersions) {
    serving.budget_status = "not measured: " + std::to_string(models) + " copies fit a budget of " +
                            std::to_string(kBudgetVersions);
    return;
  }
  std::filesystem::remove_all(repository / "scale-lod");
  serving.memory_budget_bytes = kBudgetVersions * one_version;
  std::filesystem::create_directories(work / "budget");
  harness::DaemonProcess daemon({"--model-repository", repository.string(), "--log-level", "warn",
                                 "--poll-interval-s", "0", "--memory-budget", std::to_string(serving.memory_budget_bytes)},
                                work / "budget");
  if (!wait_until_serving(daemon.address(), std::chrono::seconds(1800))) {
    serving.budget_status = "the daemon never answered SERVING:\n" + daemon.log();
    return;
  }
  ClientOptions options;
  options.deadline = std::chrono::minutes(10);
  Client client(daemon.address(), options);
  std::vector<double> reload_ms;
  char name[32];
  try {
    for (int m = 0; m < models; ++m) {  // the first kBudgetVersions by name were evicted at start-up
      std::snprintf(name, sizeof name, "scale-%02d", m);
      const auto start = std::chrono::steady_clock::now();
      client.describe_key_points(name);
      reload_ms.push_back(1e3 * seconds_since(start));
    }
  } catch (const std::exception& e) {
    serving.budget_status = std::string("serving under the budget failed: ") + e.what();
    return;
  }
  serving.budget_peak_rss_bytes = process_memory_bytes(daemon.pid(), "VmHWM");
  serving.budget_reload_ms = tools::quantile(std::move(reload_ms), 0.5);
}

// The daemon holds a version's runtime (about twice its basis), not its training frames, which
// stay on disk (--resident-section-bytes): `frames_bytes` of the file are not counted.
Serving measure_serving(const std::filesystem::path& model_file, uint64_t frames_bytes, const Character& character,
                        const std::filesystem::path& lod_file, int models, int repetitions,
                        const std::filesystem::path& work) {
  Serving serving;
  const uint64_t file = file_bytes(model_file);
  const uint64_t needed = 2 * (file - std::min(file, frames_bytes)) * static_cast<uint64_t>(models);
  if (const uint64_t available = available_memory_bytes(); needed > available / 10 * 8) {
    serving.status = "not measured: " + std::to_string(models) + " copies of a model whose runtime is about " +
                     std::to_string(needed / static_cast<uint64_t>(models) >> 20) + " MiB exceed 80% of the " +
                     std::to_string(available >> 20) + " MiB this machine has available";
    return serving;
  }
  const auto repository = work / "repository";
  char name[32];
  for (int m = 0; m < models; ++m) {
    std::snprintf(name, sizeof name, "scale-%02d", m);
    std::filesystem::create_directories(repository / name / "1");
    std::filesystem::create_hard_link(model_file, repository / name / "1" / "model.anim");
  }
  std::unique_ptr<harness::DaemonProcess> daemon;
  try {
    daemon = std::make_unique<harness::DaemonProcess>(
        std::vector<std::string>{"--model-repository", repository.string(), "--log-level", "warn", "--poll-interval-s",
                                 "0"},
        work);
  } catch (const std::exception& e) {
    serving.status = std::string("the daemon did not start: ") + e.what();
    return serving;
  }
  if (!wait_until_serving(daemon->address(), std::chrono::seconds(1800))) {
    serving.status = "the daemon never answered SERVING:\n" + daemon->log();
    return serving;
  }
  serving.registry_rss_bytes = process_memory_bytes(daemon->pid());
  // Every copy must be served for the figure to mean what it says.
  int served = 0;
  uint64_t one_version = 0;  // the heap one copy holds, as the daemon measured it
  for (const auto& summary : Client(daemon->address()).list_models()) {
    served += summary.default_version() != 0 ? 1 : 0;
    for (const auto& version : summary.versions()) one_version = std::max(one_version, version.resident_bytes());
  }
  if (served != models) {
    serving.status = "only " + std::to_string(served) + " of " + std::to_string(models) + " copies loaded:\n" +
                     daemon->log();
    return serving;
  }

  ClientOptions client_options;
  client_options.deadline = std::chrono::minutes(10);
  client_options.max_receive_message_bytes = 256 << 20;
  Client client(daemon->address(), client_options);
  try {
    const auto start = std::chrono::steady_clock::now();
    BasisData data = client.get_basis("scale-00");
    serving.get_basis_seconds = seconds_since(start);
    serving.get_basis_bytes = data.bytes_received;
    const Basis basis = make_basis("scale-00", std::move(data));
    // One fresh pose (not a training frame), answered as coordinates.
    const KeyPoints keys = client.describe_key_points("scale-00");
    const auto pose = as::random_joint_rotation_poses(character.model.skeleton, 1,
                                                      kMaxJointAngle * std::numbers::pi / 180, kPoseSeed + 1);
    PointMatrix posed;
    as::evaluate(character.model, pose[0], posed);
    const std::span<const float> frame(posed.data(), static_cast<size_t>(posed.size()));
    const std::vector<float> key_values = keys.gather(frame);
    const std::vector<float> check_values = keys.gather_check_values(frame);
    EvaluateOptions evaluate;
    evaluate.points_encoding = v1::POINT_ENCODING_COORDINATES;
    evaluate.skip_miss_log = true;
    KeyPointPose key_pose;
    key_pose.key_values = key_values;
    key_pose.check_values = check_values;
    const PoseResult result = client.evaluate_key_points("scale-00", key_pose, evaluate);
    if (!result.coordinates.present) {
      serving.status = std::string("the answer (") + cache_status_name(result.status) + ") carried no coordinates";
      return serving;
    }
    Points points;
    serving.client_reconstruct_us = 1e6 * median_seconds(repetitions, [&] {
                                      reconstruct(basis, result, points);
                                      do_not_optimize(points.values.data());
                                    });
    // Half the bytes: the float16 basis, and what it changes in this answer.
    BasisData half = client.get_basis("scale-00", 0, {}, v1::POINT_ENCODING_FLOAT16);
    serving.get_basis_float16_bytes = half.bytes_received;
    Points half_points;
    reconstruct(make_basis("scale-00", std::move(half)), result, half_points);
    double largest = 0;
    for (size_t i = 0; i < points.values.size(); ++i) {
      largest = std::max(largest, std::abs(static_cast<double>(half_points.values[i]) - points.values[i]));
    }
    serving.float16_reconstruct_max_error_over_diag = largest / rest_diagonal(character.model);
    BasisData compact = client.get_basis("scale-00", 0, {}, v1::POINT_ENCODING_FLOAT32, v1::BASIS_LAYOUT_COMPACT);
    serving.get_basis_compact_bytes = compact.bytes_received;
    serving.basis_compact_layout = compact.layout == v1::BASIS_LAYOUT_SKINNED ? "skinned" : "dense";
    const Basis compact_basis = make_basis("scale-00", std::move(compact));
    serving.client_reconstruct_compact_us = 1e6 * median_seconds(repetitions, [&] {
                                              reconstruct(compact_basis, result, half_points);
                                              do_not_optimize(half_points.values.data());
                                            });
  } catch (const std::exception& e) {
    serving.status = std::string("serving failed: ") + e.what();
    return serving;
  }
  // A 256² thumbnail of a stored frame, drawn by the daemon (its one row read from the file).
  v1::RenderThumbnailRequest thumbnail;
  thumbnail.mutable_model()->set_name("scale-00");
  thumbnail.set_width_px(kThumbnailPx);
  thumbnail.set_height_px(kThumbnailPx);
  thumbnail.set_sequence_frame(0);
  std::vector<double> thumbnail_ms;
  try {
    for (int i = 0; i <= repetitions; ++i) {  // the first draws the mesh into the renderer's caches
      const auto start = std::chrono::steady_clock::now();
      const Thumbnail drawn = client.render_thumbnail(thumbnail);
      if (i > 0) thumbnail_ms.push_back(1e3 * seconds_since(start));
      do_not_optimize(drawn.png.size());
    }
    serving.thumbnail_p50_ms = tools::quantile(std::move(thumbnail_ms), 0.5);
  } catch (const std::exception& e) {
    serving.thumbnail_status = e.what();
  }
  // The levels of detail, loaded after the RSS above was read (they are not one of the copies).
  if (!std::filesystem::exists(lod_file)) {
    serving.get_lod_status = "build-lod made no levels";
    return serving;
  }
  std::filesystem::create_directories(repository / "scale-lod" / "1");
  std::filesystem::create_hard_link(lod_file, repository / "scale-lod" / "1" / "model.anim");
  try {
    client.load_model("scale-lod");
    v1::GetLodRequest request;
    request.mutable_model()->set_name("scale-lod");
    request.set_level(0);
    request.set_form(v1::GetLodRequest::FORM_ANIMATION_SPACE);
    LodMesh mesh;
    serving.get_lod_ms = 1e3 * median_seconds(repetitions, [&] { mesh = client.get_lod(request); });
    serving.get_lod_bytes = mesh.bytes_received;
    serving.get_lod_chunks = mesh.chunk_count;
  } catch (const std::exception& e) {
    serving.get_lod_status = e.what();
  }
  measure_budget(repository, models, one_version, work, serving);
  return serving;
}

double gb(uint64_t bytes) { return static_cast<double>(bytes) / 1e9; }

}  // namespace

nlohmann::json run_scale_suite(const SuiteOptions& options) {
  nlohmann::json results = nlohmann::json::array();
  if (!options.data) {
    std::printf("scale: no reference data (skipped)\n");
    return results;
  }
  const ScaleSuiteOptions& scale = options.scale;
  ScratchDirectory scratch("scale");
  RowProgress progress("scale");
  const auto control = scratch.path() / "level-0.anim";
  if (scale.character == "horse-gallop") {
    // A captured character: its animation-space fit (the project's defaults) is the truth its
    // subdivisions and random poses are measured against.
    progress.starting("fit of horse-gallop");
    if (!run_cli({"fit", (*options.data / "horse-gallop").string(), "-o", control.string()}, scratch.path() / "fit.txt",
                 "fit")) {
      return results;
    }
  } else {
    const std::filesystem::path rig = *options.data / "cow-rig";
    progress.starting("import-rig of the cow");
    if (!run_cli({"import-rig", "--mesh", (rig / "cow.obj").string(), "--tgf", (rig / "cow.tgf").string(), "--dmat",
                  (rig / "cow.DMAT").string(), "-o", control.string()},
                 scratch.path() / "import-rig.txt", "import-rig")) {
      return results;
    }
  }

  std::vector<int> levels = scale.levels;
  if (std::find(levels.begin(), levels.end(), 0) == levels.end()) levels.insert(levels.begin(), 0);  // the baseline
  std::sort(levels.begin(), levels.end());
  std::printf("scale: %s subdivided in animation space, %d random poses (joints up to %g°), %d served copies\n",
              scale.character == "horse-gallop" ? "horse-gallop's fit" : "the cow rig", scale.frames, kMaxJointAngle,
              scale.models);
  std::printf("\n%-6s %-12s %8s %6s %9s %9s %9s %7s %9s %9s %9s %10s %10s %9s %9s\n", "level", "kind", "points",
              "frames", "input GB", "train s", "peak GB", "peak/in", "lod s", "meshopt s", "basis MB", "recon us",
              "serve GB", "thumb ms", "×base");
  nlohmann::json baseline;
  for (const int level : levels) {
    const auto work = scratch.path() / ("level-" + std::to_string(level));
    std::filesystem::create_directories(work);
    std::filesystem::path character_file = control;
    if (level > 0) {
      progress.starting("subdivide --levels " + std::to_string(level));
      character_file = scratch.path() / ("level-" + std::to_string(level) + ".anim");
      if (!run_cli({"subdivide", control.string(), "--levels", std::to_string(level), "-o", character_file.string()},
                   work / "subdivide.txt", "subdivide")) {
        continue;
      }
    }
    auto character = read_character(character_file);
    if (!character) continue;
    const int points = character->model.vertex_count();
    progress.starting("level " + std::to_string(level) + ": posing " + std::to_string(scale.frames) + " frames of " +
                      std::to_string(points) + " points");
    const auto sequence = work / "sequence";
    if (!write_sequence(character->model, scale.frames, sequence)) continue;
    const uint64_t input_bytes = file_bytes(sequence / "frames.pc2");

    progress.starting("level " + std::to_string(level) + ": build-lod");
    nlohmann::json lod = nullptr;
    double meshopt = 0;
    std::optional<LodError> lod_across_poses;
    if (auto built = run_cli({"build-lod", character_file.string(), "--sample-poses", std::to_string(kLodSamplePoses), "-o", (work / "lod.anim").string()},
                             work / "build-lod.txt", "build-lod")) {
      lod = built->seconds;
      meshopt = meshopt_seconds(character->model, level_vertex_counts(work / "lod.anim"));
      progress.starting("level " + std::to_string(level) + ": LOD error across " + std::to_string(kErrorPoses) +
                        " poses, build-lod and meshoptimizer");
      lod_across_poses = lod_error(character->model, work / "lod.anim");
      if (lod_across_poses) {
        std::printf("%-6d LOD error across %d poses at %d vertices (RMS, max over the diagonal): build-lod %.5f, %.5f; "
                    "meshoptimizer (rest pose, %d vertices) %.5f, %.5f\n",
                    level, kErrorPoses, lod_across_poses->vertices, lod_across_poses->lod.rms, lod_across_poses->lod.max,
                    lod_across_poses->meshopt_vertices, lod_across_poses->meshopt.rms, lod_across_poses->meshopt.max);
      }
    }

    for (const std::string& kind : scale.kinds) {
      progress.starting("level " + std::to_string(level) + ": train-pmsc --subspace " + kind);
      const auto model_file = work / ("pmsc-" + kind + ".anim");
      nlohmann::json row{{"character", scale.character},
                         {"level", level},
                         {"points", points},
                         {"faces", character->model.faces.rows()},
                         {"frames", scale.frames},
                         {"subspace_kind", kind},
                         {"input_bytes", input_bytes},
                         {"lod_build_seconds", lod},
                         {"meshopt_seconds", lod.is_null() ? nlohmann::json(nullptr) : nlohmann::json(meshopt)},
                         {"models", scale.models},
                         {"baseline", level == 0}};
      if (lod_across_poses) {
        row["lod_error_poses"] = kErrorPoses;
        row["lod_error_vertices"] = lod_across_poses->vertices;
        row["lod_rms_error_over_diag"] = lod_across_poses->lod.rms;
        row["lod_max_error_over_diag"] = lod_across_poses->lod.max;
        row["meshopt_error_vertices"] = lod_across_poses->meshopt_vertices;
        row["meshopt_rms_error_over_diag"] = lod_across_poses->meshopt.rms;
        row["meshopt_max_error_over_diag"] = lod_across_poses->meshopt.max;
      }
      const auto trained = run_cli({"train-pmsc", sequence.string(), "--subspace", kind, "-o", model_file.string()},
                                   work / ("train-" + kind + ".txt"), "train-pmsc");
      if (!trained) {
        row["train_status"] = "failed";
        results.push_back(row);
        continue;
      }
      row["train_seconds"] = trained->seconds;
      row["peak_rss_bytes"] = trained->peak_rss_bytes;
      row["model_bytes"] = file_bytes(model_file);
      if (auto container = container::read_file(model_file)) {
        if (auto model = pmsc::load(*container, model_file.string())) {
          row["basis_size"] = model->basis_size();
          row["key_points"] = model->key_point_count();
        }
      }
      progress.starting("level " + std::to_string(level) + ": serving " + std::to_string(scale.models) + " copies");
      const auto serve_work = work / ("serve-" + kind);
      std::filesystem::create_directories(serve_work);
      const Serving serving =
          measure_serving(model_file, input_bytes, *character, work / "lod.anim", scale.models, options.repetitions,
                          serve_work);
      if (serving.status.empty()) {
        row["registry_rss_bytes"] = serving.registry_rss_bytes;
        row["get_basis_bytes"] = serving.get_basis_bytes;
        row["get_basis_seconds"] = serving.get_basis_seconds;
        row["client_reconstruct_us"] = serving.client_reconstruct_us;
        row["get_basis_float16_bytes"] = serving.get_basis_float16_bytes;
        row["float16_reconstruct_max_error_over_diag"] = serving.float16_reconstruct_max_error_over_diag;
        row["get_basis_compact_bytes"] = serving.get_basis_compact_bytes;
        row["basis_compact_layout"] = serving.basis_compact_layout;
        row["client_reconstruct_compact_us"] = serving.client_reconstruct_compact_us;
        if (serving.budget_reload_ms >= 0) {
          row["memory_budget_bytes"] = serving.memory_budget_bytes;
          row["budget_peak_rss_bytes"] = serving.budget_peak_rss_bytes;
          row["budget_reload_ms"] = serving.budget_reload_ms;
        } else {
          row["budget_status"] = serving.budget_status;
        }
        if (serving.thumbnail_p50_ms >= 0) {
          row["thumbnail_p50_ms"] = serving.thumbnail_p50_ms;
        } else {
          row["thumbnail_status"] = serving.thumbnail_status;
          std::printf("scale: level %d: no thumbnail: %s\n", level, serving.thumbnail_status.c_str());
        }
        if (serving.get_lod_ms >= 0) {
          row["get_lod_bytes"] = serving.get_lod_bytes;
          row["get_lod_chunks"] = serving.get_lod_chunks;
          row["get_lod_ms"] = serving.get_lod_ms;
        } else {
          row["get_lod_status"] = serving.get_lod_status;
          std::printf("scale: level %d: no GetLod: %s\n", level, serving.get_lod_status.c_str());
        }
      } else {
        row["serving_status"] = serving.status;
        std::printf("scale: level %d: %s\n", level, serving.status.c_str());
      }
      const auto number = [&row](const char* key) { return row.value(key, nlohmann::json(nullptr)); };
      const auto value = [&](const char* key) {
        const nlohmann::json v = number(key);
        return v.is_number() ? v.get<double>() : std::nan("");
      };
      const double peak_over_input =
          input_bytes > 0 ? value("peak_rss_bytes") / static_cast<double>(input_bytes) : std::nan("");
      row["peak_rss_over_input"] = peak_over_input;
      if (level == 0 && kind == scale.kinds.front()) baseline = row;
      const double base_train = baseline.is_object() ? baseline.value("train_seconds", std::nan("")) : std::nan("");
      std::printf("%-6d %-12s %8d %6d %9.3f %9.1f %9.3f %7.2f %9.2f %9.3f %9.1f %10.1f %10.3f %9.1f %9.1f\n", level,
                  kind.c_str(), points, scale.frames, gb(input_bytes), value("train_seconds"),
                  value("peak_rss_bytes") / 1e9, peak_over_input, value("lod_build_seconds"), value("meshopt_seconds"),
                  value("get_basis_bytes") / 1e6, value("client_reconstruct_us"), value("registry_rss_bytes") / 1e9,
                  value("thumbnail_p50_ms"), value("train_seconds") / base_train);
      if (row.contains("get_basis_float16_bytes")) {
        std::printf("%-6s GetBasis float16: %.1f MB, the answer within %.2g of the diagonal of float32's\n", "",
                    value("get_basis_float16_bytes") / 1e6, value("float16_reconstruct_max_error_over_diag"));
      }
      if (row.contains("get_basis_compact_bytes")) {
        std::printf("%-6s GetBasis COMPACT: %s, %.1f MB (%.3f of dense), the answer reconstructed in %.1f us\n", "",
                    row["basis_compact_layout"].get<std::string>().c_str(), value("get_basis_compact_bytes") / 1e6,
                    value("get_basis_compact_bytes") / value("get_basis_bytes"), value("client_reconstruct_compact_us"));
      }
      if (row.contains("budget_reload_ms")) {
        std::printf("%-6s --memory-budget %.2f GB (%d versions) serving %d copies in turn: peak RSS %.2f GB, a call "
                    "that loads its version again %.0f ms (median)\n",
                    "", value("memory_budget_bytes") / 1e9, kBudgetVersions, scale.models,
                    value("budget_peak_rss_bytes") / 1e9, value("budget_reload_ms"));
      }
      if (row.contains("get_lod_ms")) {
        std::printf("%-6s GetLod level 0 (animation space, %d vertices): %.1f MB in %lu chunks, %.1f ms\n", "",
                    points, value("get_lod_bytes") / 1e6, static_cast<unsigned long>(row["get_lod_chunks"].get<uint64_t>()),
                    value("get_lod_ms"));
      }
      std::fflush(stdout);
      results.push_back(row);
    }
    std::filesystem::remove_all(sequence);  // the largest files first: the next level needs the disk
  }
  std::printf("(×base: training time over level 0's, the baseline measured in this run; peak/in: the training's peak\n"
              " resident memory over the point cache's size; serve GB: animspaced's VmRSS serving %d copies)\n",
              scale.models);
  return results;
}

}  // namespace animspace::bench
