#include "clients/cpp/cli/subdivide.h"

#include <chrono>
#include <cstdio>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "core/container/model_container.h"
#include "core/subdivision/subdivide_model.h"

namespace animspace::cli {

CLI::App* add_subdivide(CLI::App& app, SubdivideArgs& a) {
  auto* cmd = app.add_subcommand(
      "subdivide",
      "Offline: subdivide an animation-space model in animation space (P' = P S, Merry 2007 §4.2; Loop for "
      "triangles, or Catmull-Clark) — posing the result equals subdividing the posed mesh, in every pose, with the "
      "limit surface's normals — and write a model version");
  cmd->add_option("input", a.input, "An animation-space model.anim (from fit or import-rig)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--levels", a.levels,
                  "Subdivision steps, 1 … " + std::to_string(subdivision::kMaxLevels) +
                      " (each multiplies the faces by 4)")
      ->capture_default_str();
  cmd->add_option("--scheme", a.scheme,
                  "auto (Loop: the model is triangles), loop, or catmull-clark (its quads are stored as two "
                  "triangles each)")
      ->capture_default_str();
  cmd->add_option("--max-vertices", a.max_vertices,
                  "Refuse an output with more vertices than this (default " +
                      std::to_string(subdivision::kDefaultMaxVertices) + ")");
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_subdivide(const SubdivideArgs& a, bool json) {
  // 1. The flags, before any work.
  if (a.levels < 1 || a.levels > subdivision::kMaxLevels) {
    return fail("subdivide", "--levels: expected 1 … " + std::to_string(subdivision::kMaxLevels) + ", got " +
                                 std::to_string(a.levels));
  }
  auto scheme = subdivision::parse_scheme(a.scheme, "--scheme");
  if (!scheme) return fail("subdivide", scheme.error().message);
  if (a.max_vertices < 0) {
    return fail("subdivide", "--max-vertices: expected a positive count, got " + std::to_string(a.max_vertices));
  }
  subdivision::SubdivisionOptions options;
  options.levels = a.levels;
  options.scheme = *scheme;
  if (a.max_vertices > 0) options.max_vertices = a.max_vertices;

  // 2. Subdivide and write.
  auto in = container::read_file(a.input);
  if (!in) return fail("subdivide", in.error().message);
  const auto start = std::chrono::steady_clock::now();
  subdivision::SubdivisionReport report;
  auto out = subdivision::subdivide_container(*in, a.input, options, &report);
  if (!out) {
    // The one refusal that is about the flags: say which.
    if (out.error().code == ErrorCode::kResourceExhausted) {
      return fail("subdivide", "--levels " + std::to_string(a.levels) + ": " + out.error().message +
                                   " (or raise --max-vertices)");
    }
    return fail("subdivide", out.error().message);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, *out); !written.ok()) return fail("subdivide", written.error().message);

  if (json) {
    print_json({{"output", path.string()},
                {"scheme", subdivision::scheme_name(report.scheme)},
                {"levels", report.levels},
                {"control_vertices", report.control_vertices},
                {"vertices", report.vertices},
                {"faces", report.faces},
                {"control_influences", report.control_influences},
                {"influences", report.influences},
                {"metrics_kept", report.metrics_kept},
                {"frames_subdivided", report.frames_subdivided},
                {"dropped_sections", report.dropped_sections},
                {"seconds", seconds}});
  } else {
    std::printf("%d step%s of %s subdivision in animation space in %.2f s: %d → %d vertices, %lld triangles, "
                "%.2f → %.2f influences per vertex\n",
                report.levels, report.levels == 1 ? "" : "s", subdivision::scheme_name(report.scheme), seconds,
                report.control_vertices, report.vertices, static_cast<long long>(report.faces),
                static_cast<double>(report.control_influences) / report.control_vertices,
                static_cast<double>(report.influences) / report.vertices);
    std::printf("metrics and bounding sphere %s; training frames %s\n",
                report.metrics_kept ? "kept" : "none stored (build-lod needs --sample-poses)",
                report.frames_subdivided ? "subdivided" : "none stored");
    if (!report.dropped_sections.empty()) {
      // Levels of detail come as many sections; count them rather than list them.
      std::string names;
      int lod_sections = 0;
      for (const std::string& name : report.dropped_sections) {
        if (name.rfind("lod.", 0) == 0) {
          ++lod_sections;
        } else {
          names += " " + name;
        }
      }
      if (lod_sections > 0) names += " lod.* (" + std::to_string(lod_sections) + " sections: rebuild with build-lod)";
      std::printf("not carried over (tied to the control mesh):%s\n", names.c_str());
    }
    std::printf("wrote %s\n", path.c_str());
    print_serving_hint(a.model);
  }
  return 0;
}

}  // namespace animspace::cli
