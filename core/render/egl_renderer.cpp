// The EGL + OpenGL ES 3 renderer: no window, no X or Wayland; everything is drawn into
// framebuffer objects and read back. On a machine without a GPU this is Mesa's surfaceless
// platform with llvmpipe; with a GPU, the EGL device platform.
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl3.h>
#include <dlfcn.h>
#include <link.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "core/render/camera.h"
#include "core/common/format.h"
#include "core/geometry/bounding_sphere.h"
#include "core/geometry/edges.h"
#include "core/geometry/normals.h"
#include "core/render/renderer.h"

namespace animspace::render {

namespace {

// ---------------------------------------------------------------------------------------------
// Scene validation: pure CPU, so that a refused scene never touches GL state.

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

std::string row_text(const PointMatrix& m, Eigen::Index row) {
  return "(" + format_number(m(row, 0)) + ", " + format_number(m(row, 1)) + ", " + format_number(m(row, 2)) + ")";
}

Status require_finite(const Eigen::Ref<const Eigen::VectorXf>& values, const std::string& field) {
  if (values.allFinite()) return Status::Ok();
  return invalid(field + ": not finite");
}

Status require_non_negative(float value, const std::string& field) {
  if (std::isfinite(value) && value >= 0) return Status::Ok();
  return invalid(field + ": expected a finite value ≥ 0, got " + format_number(value));
}

Status validate_scene(const Scene& scene) {
  if (scene.width < 1) return invalid("width: expected ≥ 1, got " + std::to_string(scene.width));
  if (scene.height < 1) return invalid("height: expected ≥ 1, got " + std::to_string(scene.height));
  if (scene.samples != 1 && scene.samples != 2 && scene.samples != 4 && scene.samples != 8) {
    return invalid("samples: expected 1, 2, 4 or 8, got " + std::to_string(scene.samples));
  }
  const Eigen::Index n = scene.points.rows();
  if (n == 0) return invalid("points: the mesh has no points");
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!scene.points.row(i).allFinite()) {
      return invalid("points: point " + std::to_string(i) + " is not finite " + row_text(scene.points, i));
    }
  }
  for (Eigen::Index f = 0; f < scene.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t v = scene.faces(f, k);
      if (v < 0 || v >= n) {
        return invalid("faces: face " + std::to_string(f) + " references vertex " + std::to_string(v) +
                       ", the mesh has " + std::to_string(n) + " points");
      }
    }
  }
  if (scene.normals.rows() != 0) {
    if (scene.normals.rows() != n) {
      return invalid("normals: expected " + std::to_string(n) + " rows (one per point) or none, got " +
                     std::to_string(scene.normals.rows()));
    }
    for (Eigen::Index i = 0; i < n; ++i) {
      if (!scene.normals.row(i).allFinite()) {
        return invalid("normals: normal " + std::to_string(i) + " is not finite " + row_text(scene.normals, i));
      }
    }
  }
  if (scene.camera) ANIMSPACE_RETURN_IF_ERROR(validate_camera(*scene.camera, "camera"));
  ANIMSPACE_RETURN_IF_ERROR(require_finite(scene.background, "background"));
  ANIMSPACE_RETURN_IF_ERROR(require_finite(scene.material.albedo, "material.albedo"));
  ANIMSPACE_RETURN_IF_ERROR(require_non_negative(scene.material.ambient, "material.ambient"));
  ANIMSPACE_RETURN_IF_ERROR(require_non_negative(scene.material.diffuse, "material.diffuse"));
  ANIMSPACE_RETURN_IF_ERROR(require_non_negative(scene.material.specular, "material.specular"));
  ANIMSPACE_RETURN_IF_ERROR(require_non_negative(scene.material.shininess, "material.shininess"));
  for (size_t k = 0; k < scene.key_points.size(); ++k) {
    const int32_t v = scene.key_points[k];
    if (v < 0 || v >= n) {
      return invalid("key_points[" + std::to_string(k) + "]: vertex " + std::to_string(v) + " out of range (" +
                     std::to_string(n) + " points)");
    }
  }
  if (!(std::isfinite(scene.key_point_radius_px) && scene.key_point_radius_px > 0)) {
    return invalid("key_point_radius_px: expected > 0, got " + format_number(scene.key_point_radius_px));
  }
  ANIMSPACE_RETURN_IF_ERROR(require_finite(scene.key_point_colour, "key_point_colour"));
  if (scene.heat.size() != 0) {
    if (scene.heat.size() != n) {
      return invalid("heat: expected " + std::to_string(n) + " values (one per point), got " +
                     std::to_string(scene.heat.size()));
    }
    for (Eigen::Index i = 0; i < n; ++i) {
      ANIMSPACE_RETURN_IF_ERROR(require_non_negative(scene.heat[i], "heat[" + std::to_string(i) + "]"));
    }
  }
  if (!std::isfinite(scene.heat_max)) return invalid("heat_max: not finite");
  if (scene.vertex_colours.rows() != 0) {
    if (scene.vertex_colours.rows() != n) {
      return invalid("vertex_colours: expected " + std::to_string(n) + " rows (one per point) or none, got " +
                     std::to_string(scene.vertex_colours.rows()));
    }
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto colour = scene.vertex_colours.row(i);
      if (!(colour.allFinite() && (colour.array() >= 0).all())) {
        return invalid("vertex_colours: colour " + std::to_string(i) + ": expected finite values ≥ 0, got " +
                       row_text(scene.vertex_colours, i));
      }
    }
    if (scene.heat.size() != 0) {
      return invalid("vertex_colours: set together with heat; the surface takes its colour from one of them");
    }
  }
  if (!(std::isfinite(scene.exposure) && scene.exposure > 0)) {
    return invalid("exposure: expected a finite value > 0, got " + format_number(scene.exposure));
  }
  ANIMSPACE_RETURN_IF_ERROR(require_finite(scene.wireframe_colour, "wireframe_colour"));
  if (scene.corner_uvs.rows() != 0) {
    if (scene.corner_uvs.rows() != 3 * scene.faces.rows()) {
      return invalid("corner_uvs: expected " + std::to_string(3 * scene.faces.rows()) +
                     " rows (3 per face) or none, got " + std::to_string(scene.corner_uvs.rows()));
    }
    for (Eigen::Index c = 0; c < scene.corner_uvs.rows(); ++c) {
      if (!scene.corner_uvs.row(c).allFinite()) {
        return invalid("corner_uvs: corner " + std::to_string(c % 3) + " of face " + std::to_string(c / 3) +
                       " is not finite (" + format_number(scene.corner_uvs(c, 0)) + ", " +
                       format_number(scene.corner_uvs(c, 1)) + ")");
      }
    }
    if (scene.heat.size() != 0 || scene.vertex_colours.rows() != 0) {
      return invalid(std::string("corner_uvs: set together with ") +
                     (scene.heat.size() != 0 ? "heat" : "vertex_colours") +
                     "; the surface takes its colour from one of them");
    }
    const Checker& checker = scene.checker;
    if (!(std::isfinite(checker.squares_per_uv) && checker.squares_per_uv > 0)) {
      return invalid("checker.squares_per_uv: expected a finite value > 0, got " +
                     format_number(checker.squares_per_uv));
    }
    ANIMSPACE_RETURN_IF_ERROR(require_finite(checker.even, "checker.even"));
    ANIMSPACE_RETURN_IF_ERROR(require_finite(checker.odd, "checker.odd"));
    ANIMSPACE_RETURN_IF_ERROR(require_finite(checker.chart_border_colour, "checker.chart_border_colour"));
  } else if (scene.checker.chart_borders) {
    return invalid("checker.chart_borders: needs corner_uvs (the borders are where they disagree)");
  }
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// Geometry prepared on the CPU.

// Each undirected edge once (geometry::unique_edges), flattened into index pairs for GL_LINES.
std::vector<int32_t> line_indices(const FaceMatrix& faces) {
  const std::vector<std::pair<int32_t, int32_t>> edges = geometry::unique_edges(faces);
  std::vector<int32_t> indices;
  indices.reserve(2 * edges.size());
  for (const auto& [a, b] : edges) {
    indices.push_back(a);
    indices.push_back(b);
  }
  return indices;
}

// The seams of a per-corner UV map as index pairs for GL_LINES: each undirected edge unless exactly
// two faces share it and give each of its ends the same (u, v) (Scene::Checker::chart_borders).
// Exact comparison: within a chart the corners of a vertex are copies of one coordinate.
std::vector<int32_t> seam_line_indices(const FaceMatrix& faces,
                                       const Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor>& corner_uvs) {
  // (lower vertex, higher vertex) → the corners (rows of corner_uvs) at those ends, per face.
  struct Side {
    Eigen::Index low_corner, high_corner;
  };
  std::map<std::pair<int32_t, int32_t>, std::vector<Side>> sides;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int kn = (k + 1) % 3;
      Eigen::Index a = 3 * f + k, b = 3 * f + kn;
      int32_t va = faces(f, k), vb = faces(f, kn);
      if (va > vb) {
        std::swap(va, vb);
        std::swap(a, b);
      }
      sides[{va, vb}].push_back({a, b});
    }
  }
  std::vector<int32_t> indices;
  for (const auto& [edge, at] : sides) {
    const bool shared = at.size() == 2 && corner_uvs.row(at[0].low_corner) == corner_uvs.row(at[1].low_corner) &&
                        corner_uvs.row(at[0].high_corner) == corner_uvs.row(at[1].high_corner);
    if (shared) continue;
    indices.push_back(edge.first);
    indices.push_back(edge.second);
  }
  return indices;
}

// ---------------------------------------------------------------------------------------------
// EGL plumbing.

std::string hex(unsigned value) {
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "0x%04X", value);
  return buffer;
}

const char* egl_error_name(EGLint code) {
  switch (code) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_CURRENT_SURFACE: return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_NATIVE_PIXMAP: return "EGL_BAD_NATIVE_PIXMAP";
    case EGL_BAD_NATIVE_WINDOW: return "EGL_BAD_NATIVE_WINDOW";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    case EGL_CONTEXT_LOST: return "EGL_CONTEXT_LOST";
    default: return "unknown EGL error";
  }
}

// "eglInitialize failed (EGL error 0x3001 EGL_NOT_INITIALIZED)", reading (and clearing) the
// thread's EGL error.
std::string egl_failure(const std::string& call) {
  const EGLint code = eglGetError();
  return call + " failed (EGL error " + hex(static_cast<unsigned>(code)) + " " + egl_error_name(code) + ")";
}

Error egl_error(const std::string& platform, const std::string& what) {
  return make_error(ErrorCode::kFailedPrecondition, "EGL " + platform + ": " + what);
}

// Whether the space-separated extension list `extensions` (may be null) names `name`.
bool has_extension(const char* extensions, std::string_view name) {
  if (extensions == nullptr) return false;
  const std::string_view list(extensions);
  for (size_t start = 0; start < list.size();) {
    const size_t end = std::min(list.find(' ', start), list.size());
    if (list.substr(start, end - start) == name) return true;
    start = end + 1;
  }
  return false;
}

// EGL displays are per-process singletons (the same platform and native display give the same
// handle), and eglTerminate is not reference counted: count here, so that one renderer going away
// does not pull the display from under another.
struct DisplayRegistry {
  std::mutex mutex;
  std::map<EGLDisplay, int> references;
};

DisplayRegistry& display_registry() {
  static DisplayRegistry registry;
  return registry;
}

Status acquire_display(EGLDisplay display, const std::string& platform) {
  DisplayRegistry& registry = display_registry();
  const std::lock_guard lock(registry.mutex);
  int& count = registry.references[display];
  if (count == 0 && eglInitialize(display, nullptr, nullptr) != EGL_TRUE) {
    registry.references.erase(display);
    return egl_error(platform, egl_failure("eglInitialize"));
  }
  ++count;
  return Status::Ok();
}

#if defined(__SANITIZE_ADDRESS__)
#define ANIMSPACE_LEAK_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ANIMSPACE_LEAK_SANITIZER 1
#endif
#endif

// Mesa's DRI driver (llvmpipe's swrast_dri.so) leaks 112 bytes in eglTerminate and is then
// unloaded, so LeakSanitizer reports the leak at exit from "<unknown module>", which nothing can
// suppress. Under ASan only, keep every loaded DRI driver mapped (RTLD_NODELETE): the leak is then
// attributed to the driver and tests/lsan.supp names it. Release builds let Mesa unload it.
void keep_dri_drivers_mapped_for_leak_sanitizer() {
#ifdef ANIMSPACE_LEAK_SANITIZER
  std::vector<std::string> drivers;
  dl_iterate_phdr(
      [](dl_phdr_info* info, size_t, void* out) {
        const std::string_view name = info->dlpi_name != nullptr ? info->dlpi_name : "";
        if (name.ends_with("_dri.so")) static_cast<std::vector<std::string>*>(out)->emplace_back(name);
        return 0;
      },
      &drivers);
  for (const std::string& driver : drivers) dlopen(driver.c_str(), RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE);
#endif
}

void release_display(EGLDisplay display) {
  DisplayRegistry& registry = display_registry();
  const std::lock_guard lock(registry.mutex);
  const auto it = registry.references.find(display);
  if (it == registry.references.end()) return;
  if (--it->second == 0) {
    keep_dri_drivers_mapped_for_leak_sanitizer();
    eglTerminate(display);
    registry.references.erase(it);
  }
}

// An initialised display and the platform it came from ("surfaceless", "device").
struct OpenDisplay {
  EGLDisplay display = EGL_NO_DISPLAY;
  std::string platform;
};

Result<OpenDisplay> open_surfaceless() {
  const std::string platform = "surfaceless";
  if (!has_extension(eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS), "EGL_MESA_platform_surfaceless")) {
    return egl_error(platform, "the EGL client does not offer EGL_MESA_platform_surfaceless");
  }
  const EGLDisplay display = eglGetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (display == EGL_NO_DISPLAY) return egl_error(platform, egl_failure("eglGetPlatformDisplay"));
  ANIMSPACE_RETURN_IF_ERROR(acquire_display(display, platform));
  return OpenDisplay{display, platform};
}

// The first EGL device that is not a software rasteriser (Mesa lists llvmpipe as a device with
// EGL_MESA_device_software; rendering on it through the device platform gains nothing over
// surfaceless).
Result<OpenDisplay> open_device() {
  const std::string platform = "device";
  const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  const auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  const auto query_device_string =
      reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(eglGetProcAddress("eglQueryDeviceStringEXT"));
  const auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!has_extension(client, "EGL_EXT_platform_device") || query_devices == nullptr ||
      query_device_string == nullptr || get_platform_display == nullptr) {
    return egl_error(platform, "the EGL client does not offer EGL_EXT_platform_device with device enumeration");
  }
  EGLint count = 0;
  if (query_devices(0, nullptr, &count) != EGL_TRUE) return egl_error(platform, egl_failure("eglQueryDevicesEXT"));
  std::vector<EGLDeviceEXT> devices(static_cast<size_t>(std::max(count, 0)));
  if (count > 0 && query_devices(count, devices.data(), &count) != EGL_TRUE) {
    return egl_error(platform, egl_failure("eglQueryDevicesEXT"));
  }
  devices.resize(static_cast<size_t>(std::max(count, 0)));
  std::string failures;
  int software = 0;
  for (EGLDeviceEXT device : devices) {
    if (has_extension(query_device_string(device, EGL_EXTENSIONS), "EGL_MESA_device_software")) {
      ++software;
      continue;
    }
    const EGLDisplay display = get_platform_display(EGL_PLATFORM_DEVICE_EXT, device, nullptr);
    if (display == EGL_NO_DISPLAY) {
      failures += "; " + egl_failure("eglGetPlatformDisplayEXT");
      continue;
    }
    const Status acquired = acquire_display(display, platform);
    if (acquired.ok()) return OpenDisplay{display, platform};
    failures += "; " + acquired.error().message;
  }
  return egl_error(platform, "no usable hardware device among " + std::to_string(devices.size()) + " EGL devices (" +
                                 std::to_string(software) + " software)" + failures);
}

// ---------------------------------------------------------------------------------------------
// Shaders (GLSL ES 3.00). The shading model is the one documented in scene.h, evaluated per
// fragment in object space: the headlight direction l = v = normalise(eye − p), so the
// Blinn-Phong half vector h = normalise(l + v) is l itself and n·h = n·l.

constexpr const char* kSurfaceVertexShader = R"(#version 300 es
uniform mat4 u_mvp;
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in float a_heat;
layout(location = 3) in vec3 a_colour;
layout(location = 4) in vec2 a_uv;
out vec3 v_position;
out vec3 v_normal;
out float v_heat;
out vec3 v_colour;
out vec2 v_uv;
void main() {
  v_position = a_position;
  v_normal = a_normal;
  v_heat = a_heat;
  v_colour = a_colour;
  v_uv = a_uv;
  gl_Position = u_mvp * vec4(a_position, 1.0);
}
)";

constexpr const char* kSurfaceFragmentShader = R"(#version 300 es
precision highp float;
uniform vec3 u_eye;
uniform vec3 u_albedo;
uniform bool u_use_heat;
uniform float u_heat_scale;
uniform bool u_use_colours;
uniform float u_exposure;
uniform vec4 u_material;  // ambient, diffuse, specular, shininess
uniform int u_shading;    // 0 Lambert, 1 Blinn-Phong, 2 unlit
uniform bool u_srgb;
uniform bool u_use_checker;
uniform float u_checker_squares;  // per unit of u and of v
uniform vec3 u_checker_even;
uniform vec3 u_checker_odd;
in vec3 v_position;
in vec3 v_normal;
in float v_heat;
in vec3 v_colour;
in vec2 v_uv;
out vec4 o_colour;

// Square (i, j) = floor(N·uv); `even` when i + j is even (scene.h, Checker). mod() of a float is
// x − 2·floor(x/2): 0 or 1 for negative sums too.
vec3 checker_colour(vec2 uv) {
  vec2 square = floor(u_checker_squares * uv);
  return mod(square.x + square.y, 2.0) < 0.5 ? u_checker_even : u_checker_odd;
}

// Heat map (thesis Fig. 8.6): 0 blue, 1/3 green, 2/3 yellow, 1 red, linear in between. The heat
// value is interpolated and mapped per fragment, so a face between blue and red passes through
// green and yellow rather than purple.
vec3 heat_colour(float t) {
  t = 3.0 * clamp(t, 0.0, 1.0);
  if (t < 1.0) return mix(vec3(0.0, 0.0, 1.0), vec3(0.0, 1.0, 0.0), t);
  if (t < 2.0) return mix(vec3(0.0, 1.0, 0.0), vec3(1.0, 1.0, 0.0), t - 1.0);
  return mix(vec3(1.0, 1.0, 0.0), vec3(1.0, 0.0, 0.0), t - 2.0);
}

// IEC 61966-2-1 on c in [0, 1].
vec3 srgb_encode(vec3 c) {
  vec3 low = 12.92 * c;
  vec3 high = 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055;
  return mix(high, low, vec3(lessThanEqual(c, vec3(0.0031308))));
}

void main() {
  vec3 l = normalize(u_eye - v_position);
  // A zero normal (an isolated vertex) is lit head-on rather than producing NaN.
  vec3 n = dot(v_normal, v_normal) > 0.0 ? normalize(v_normal) : l;
  // Two-sided: a normal facing away from the eye is flipped, so max(n·l, 0) = |n·l|.
  float nl = abs(dot(n, l));
  vec3 albedo = u_use_heat ? heat_colour(v_heat * u_heat_scale)
               : u_use_colours ? u_exposure * v_colour
               : u_use_checker ? checker_colour(v_uv)
               : u_albedo;
  vec3 c = u_shading == 2 ? albedo : albedo * (u_material.x + u_material.y * nl);
  if (u_shading == 1 && nl > 0.0) c += vec3(u_material.z * pow(nl, u_material.w));
  c = clamp(c, 0.0, 1.0);
  o_colour = vec4(u_srgb ? srgb_encode(c) : c, 1.0);
}
)";

// Flat-coloured overlays: wireframe lines and key-point dots (round by discarding the corners of
// the square point sprite).
constexpr const char* kOverlayVertexShader = R"(#version 300 es
uniform mat4 u_mvp;
uniform float u_point_size;
layout(location = 0) in vec3 a_position;
void main() {
  gl_Position = u_mvp * vec4(a_position, 1.0);
  gl_PointSize = u_point_size;
}
)";

constexpr const char* kOverlayFragmentShader = R"(#version 300 es
precision highp float;
uniform vec3 u_colour;
uniform bool u_round;
out vec4 o_colour;
void main() {
  if (u_round) {
    vec2 d = 2.0 * gl_PointCoord - 1.0;
    if (dot(d, d) > 1.0) discard;
  }
  o_colour = vec4(u_colour, 1.0);
}
)";

// u_shading in kSurfaceFragmentShader.
GLint shading_index(Shading shading) {
  switch (shading) {
    case Shading::kLambert: return 0;
    case Shading::kBlinnPhong: return 1;
    case Shading::kUnlit: return 2;
  }
  return 0;
}

const char* gl_error_name(GLenum code) {
  switch (code) {
    case GL_INVALID_ENUM: return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE: return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION: return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION: return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY: return "GL_OUT_OF_MEMORY";
    default: return "unknown GL error";
  }
}

// The first pending GL error (GL_NO_ERROR if none), clearing all of them.
GLenum take_gl_error() {
  const GLenum first = glGetError();
  if (first != GL_NO_ERROR) {
    // Implementations may queue several flags; a bounded loop in case of a lost context.
    for (int k = 0; k < 16 && glGetError() != GL_NO_ERROR; ++k) {
    }
  }
  return first;
}

Error gl_failure(const std::string& what, GLenum code) {
  return make_error(code == GL_OUT_OF_MEMORY ? ErrorCode::kResourceExhausted : ErrorCode::kInternal,
                    "GL error " + hex(code) + " " + gl_error_name(code) + " " + what);
}

Result<GLuint> compile_shader(GLenum type, const char* source) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok == GL_TRUE) return shader;
  char log[1024] = {};
  glGetShaderInfoLog(shader, sizeof log, nullptr, log);
  glDeleteShader(shader);
  return make_error(ErrorCode::kInternal, std::string("shader compilation failed: ") + log);
}

Result<GLuint> link_program(const char* vertex_source, const char* fragment_source) {
  Result<GLuint> vertex = compile_shader(GL_VERTEX_SHADER, vertex_source);
  if (!vertex.ok()) return vertex.error();
  Result<GLuint> fragment = compile_shader(GL_FRAGMENT_SHADER, fragment_source);
  if (!fragment.ok()) {
    glDeleteShader(*vertex);
    return fragment.error();
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, *vertex);
  glAttachShader(program, *fragment);
  glLinkProgram(program);
  glDeleteShader(*vertex);  // flagged; freed with the program
  glDeleteShader(*fragment);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok == GL_TRUE) return program;
  char log[1024] = {};
  glGetProgramInfoLog(program, sizeof log, nullptr, log);
  glDeleteProgram(program);
  return make_error(ErrorCode::kInternal, std::string("shader linking failed: ") + log);
}

// The largest sample count the implementation supports for a renderbuffer format (counts are
// listed in descending order).
GLint max_samples_for(GLenum format) {
  GLint count = 0;
  glGetInternalformativ(GL_RENDERBUFFER, format, GL_NUM_SAMPLE_COUNTS, 1, &count);
  if (count <= 0) return 1;
  GLint largest = 1;
  glGetInternalformativ(GL_RENDERBUFFER, format, GL_SAMPLES, 1, &largest);
  return std::max(largest, 1);
}

// The most samples (width · height · samples) one render may allocate: 4096² at 8 samples, about
// 1 GiB of colour and depth. Beyond it a software rasteriser would be killed by the kernel
// rather than report GL_OUT_OF_MEMORY (Linux overcommits).
constexpr int64_t kMaxTotalSamples = int64_t{4096} * 4096 * 8;

class EglRenderer final : public Renderer {
 public:
  explicit EglRenderer(OpenDisplay display) : display_(std::move(display)) {}
  EglRenderer(const EglRenderer&) = delete;
  EglRenderer& operator=(const EglRenderer&) = delete;
  ~EglRenderer() override;

  // Creates the context and the GL objects; on failure the destructor releases what was made.
  Status init();
  Result<Image> render(const Scene& scene) override;
  std::string description() const override { return description_; }

 private:
  // Render targets, kept between calls: reallocated only when the size or sample count changes.
  struct Targets {
    int width = 0, height = 0, samples = 0;
    GLuint multisample_fbo = 0, multisample_colour = 0, multisample_depth = 0;
    GLuint fbo = 0, colour = 0, depth = 0;  // single-sample: the resolve target, or drawn into when samples == 1
  };
  struct Limits {
    int max_width = 0, max_height = 0, max_samples = 1;
    float min_point_size = 1, max_point_size = 1;
    int64_t max_vertices = 0;
  };
  struct SurfaceUniforms {
    GLint mvp = -1, eye = -1, albedo = -1, use_heat = -1, heat_scale = -1, use_colours = -1, exposure = -1,
          material = -1, shading = -1, srgb = -1, use_checker = -1, checker_squares = -1, checker_even = -1,
          checker_odd = -1;
  };
  struct OverlayUniforms {
    GLint mvp = -1, point_size = -1, colour = -1, round = -1;
  };
  enum Buffer { kPositions, kNormals, kHeat, kColours, kUvs, kElements, kBufferCount };

  Status make_current(const std::string& why) const;
  Status check_limits(const Scene& scene) const;
  Status ensure_targets(int width, int height, int samples);
  void release_targets();
  Status draw(const Scene& scene, const Camera& camera);
  Image read_back(int width, int height);

  OpenDisplay display_;
  EGLContext context_ = EGL_NO_CONTEXT;
  std::string description_;
  Limits limits_;
  GLuint surface_program_ = 0, overlay_program_ = 0, vao_ = 0;
  GLuint buffers_[kBufferCount] = {};
  SurfaceUniforms surface_uniforms_;
  OverlayUniforms overlay_uniforms_;
  Targets targets_;
};

EglRenderer::~EglRenderer() {
  if (context_ != EGL_NO_CONTEXT) {
    if (make_current("").ok()) {
      release_targets();
      glDeleteBuffers(kBufferCount, buffers_);
      glDeleteVertexArrays(1, &vao_);
      glDeleteProgram(surface_program_);
      glDeleteProgram(overlay_program_);
    }
    eglMakeCurrent(display_.display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display_.display, context_);
  }
  release_display(display_.display);
}

Status EglRenderer::make_current(const std::string& why) const {
  if (eglGetCurrentContext() == context_) return Status::Ok();
  if (eglMakeCurrent(display_.display, EGL_NO_SURFACE, EGL_NO_SURFACE, context_) == EGL_TRUE) return Status::Ok();
  return make_error(ErrorCode::kInternal, "EGL " + display_.platform + ": " + egl_failure("eglMakeCurrent") + why);
}

Status EglRenderer::init() {
  const std::string& platform = display_.platform;
  const EGLDisplay display = display_.display;
  if (eglBindAPI(EGL_OPENGL_ES_API) != EGL_TRUE) return egl_error(platform, egl_failure("eglBindAPI"));
  const char* extensions = eglQueryString(display, EGL_EXTENSIONS);
  if (!has_extension(extensions, "EGL_KHR_surfaceless_context")) {
    return egl_error(platform, "the display does not offer EGL_KHR_surfaceless_context (needed to draw without a window)");
  }
  // Any ES 3 config: nothing is drawn to an EGL surface, so its surface type and colour sizes
  // do not matter (EGL_SURFACE_TYPE 0 requires no bits).
  const EGLint config_attributes[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, 0, EGL_NONE};
  EGLConfig config = EGL_NO_CONFIG_KHR;
  EGLint config_count = 0;
  if (eglChooseConfig(display, config_attributes, &config, 1, &config_count) != EGL_TRUE || config_count < 1) {
    if (!has_extension(extensions, "EGL_KHR_no_config_context")) {
      return egl_error(platform, "no EGL config renders OpenGL ES 3 (" + egl_failure("eglChooseConfig") + ")");
    }
    config = EGL_NO_CONFIG_KHR;
  }
  const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0, EGL_NONE};
  context_ = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attributes);
  if (context_ == EGL_NO_CONTEXT) return egl_error(platform, egl_failure("eglCreateContext (OpenGL ES 3.0)"));
  if (eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context_) != EGL_TRUE) {
    return egl_error(platform, egl_failure("eglMakeCurrent"));
  }

  const auto gl_string = [](GLenum name) {
    const GLubyte* text = glGetString(name);
    return text == nullptr ? std::string("?") : std::string(reinterpret_cast<const char*>(text));
  };
  description_ = "EGL " + platform + " — " + gl_string(GL_RENDERER) + ", " + gl_string(GL_VERSION);

  GLint renderbuffer_size = 0, viewport[2] = {0, 0}, max_samples = 1;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &renderbuffer_size);
  glGetIntegerv(GL_MAX_VIEWPORT_DIMS, viewport);
  glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
  limits_.max_width = std::min(renderbuffer_size, viewport[0]);
  limits_.max_height = std::min(renderbuffer_size, viewport[1]);
  limits_.max_samples = std::min({max_samples, max_samples_for(GL_RGBA8), max_samples_for(GL_DEPTH_COMPONENT24)});
  GLfloat point_sizes[2] = {1, 1};
  glGetFloatv(GL_ALIASED_POINT_SIZE_RANGE, point_sizes);
  limits_.min_point_size = point_sizes[0];
  limits_.max_point_size = point_sizes[1];
  GLint64 max_index = 0;
  glGetInteger64v(GL_MAX_ELEMENT_INDEX, &max_index);
  limits_.max_vertices = max_index + 1;

  Result<GLuint> surface = link_program(kSurfaceVertexShader, kSurfaceFragmentShader);
  if (!surface.ok()) return surface.error();
  surface_program_ = *surface;
  Result<GLuint> overlay = link_program(kOverlayVertexShader, kOverlayFragmentShader);
  if (!overlay.ok()) return overlay.error();
  overlay_program_ = *overlay;
  surface_uniforms_ = {glGetUniformLocation(surface_program_, "u_mvp"),
                       glGetUniformLocation(surface_program_, "u_eye"),
                       glGetUniformLocation(surface_program_, "u_albedo"),
                       glGetUniformLocation(surface_program_, "u_use_heat"),
                       glGetUniformLocation(surface_program_, "u_heat_scale"),
                       glGetUniformLocation(surface_program_, "u_use_colours"),
                       glGetUniformLocation(surface_program_, "u_exposure"),
                       glGetUniformLocation(surface_program_, "u_material"),
                       glGetUniformLocation(surface_program_, "u_shading"),
                       glGetUniformLocation(surface_program_, "u_srgb"),
                       glGetUniformLocation(surface_program_, "u_use_checker"),
                       glGetUniformLocation(surface_program_, "u_checker_squares"),
                       glGetUniformLocation(surface_program_, "u_checker_even"),
                       glGetUniformLocation(surface_program_, "u_checker_odd")};
  overlay_uniforms_ = {glGetUniformLocation(overlay_program_, "u_mvp"),
                       glGetUniformLocation(overlay_program_, "u_point_size"),
                       glGetUniformLocation(overlay_program_, "u_colour"),
                       glGetUniformLocation(overlay_program_, "u_round")};

  // One vertex array for both programs: attribute 0 positions, 1 normals, 2 heat, 3 vertex
  // colours, 4 texture coordinates; the element buffer holds triangles, then edges, then key
  // points.
  glGenBuffers(kBufferCount, buffers_);
  glGenVertexArrays(1, &vao_);
  glBindVertexArray(vao_);
  const GLint sizes[] = {3, 3, 1, 3, 2};
  for (GLuint attribute = 0; attribute < 5; ++attribute) {
    glBindBuffer(GL_ARRAY_BUFFER, buffers_[attribute]);
    glVertexAttribPointer(attribute, sizes[attribute], GL_FLOAT, GL_FALSE, 0, nullptr);
  }
  glEnableVertexAttribArray(kPositions);
  glEnableVertexAttribArray(kNormals);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, buffers_[kElements]);
  glBindVertexArray(0);

  if (const GLenum error = take_gl_error(); error != GL_NO_ERROR) {
    return egl_error(platform, gl_failure("while setting up OpenGL ES", error).message);
  }
  return Status::Ok();
}

Status EglRenderer::check_limits(const Scene& scene) const {
  const auto exhausted = [](const std::string& message) {
    return Status(make_error(ErrorCode::kResourceExhausted, message));
  };
  if (scene.width > limits_.max_width) {
    return exhausted("width: " + std::to_string(scene.width) + " exceeds the GL implementation's maximum of " +
                     std::to_string(limits_.max_width));
  }
  if (scene.height > limits_.max_height) {
    return exhausted("height: " + std::to_string(scene.height) + " exceeds the GL implementation's maximum of " +
                     std::to_string(limits_.max_height));
  }
  if (scene.samples > limits_.max_samples) {
    return exhausted("samples: " + std::to_string(scene.samples) + " exceeds the GL implementation's maximum of " +
                     std::to_string(limits_.max_samples));
  }
  const int64_t total = int64_t{scene.width} * scene.height * scene.samples;
  if (total > kMaxTotalSamples) {
    return exhausted("width × height × samples: " + std::to_string(total) + " exceeds the renderer's budget of " +
                     std::to_string(kMaxTotalSamples));
  }
  if (scene.points.rows() > limits_.max_vertices) {
    return exhausted("points: " + std::to_string(scene.points.rows()) + " exceeds the GL implementation's maximum of " +
                     std::to_string(limits_.max_vertices));
  }
  // With texture coordinates each face corner is a vertex of its own, after the points.
  if (scene.corner_uvs.rows() != 0 && scene.points.rows() + scene.corner_uvs.rows() > limits_.max_vertices) {
    return exhausted("corner_uvs: " + std::to_string(scene.points.rows()) + " points and " +
                     std::to_string(scene.corner_uvs.rows()) + " face corners exceed the GL implementation's maximum of " +
                     std::to_string(limits_.max_vertices) + " vertices");
  }
  // Triangle, edge (at most as many as triangle corners) and key-point indices share one
  // element buffer addressed with GLsizei counts and byte offsets.
  const int64_t indices = (scene.checker.chart_borders ? 12 : 6) * static_cast<int64_t>(scene.faces.rows()) +
                          static_cast<int64_t>(scene.key_points.size());
  if (indices > INT_MAX / 4) {
    return exhausted("faces: " + std::to_string(scene.faces.rows()) + " is more than one draw call can index");
  }
  return Status::Ok();
}

void EglRenderer::release_targets() {
  glDeleteFramebuffers(1, &targets_.multisample_fbo);
  glDeleteFramebuffers(1, &targets_.fbo);
  const GLuint renderbuffers[] = {targets_.multisample_colour, targets_.multisample_depth, targets_.colour,
                                  targets_.depth};
  glDeleteRenderbuffers(4, renderbuffers);
  targets_ = Targets{};
}

Status EglRenderer::ensure_targets(int width, int height, int samples) {
  if (targets_.width == width && targets_.height == height && targets_.samples == samples) return Status::Ok();
  release_targets();
  const auto make_framebuffer = [&](GLuint& fbo, GLuint& colour, GLuint* depth, int count) {
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(1, &colour);
    glBindRenderbuffer(GL_RENDERBUFFER, colour);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, count, GL_RGBA8, width, height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour);
    if (depth != nullptr) {
      glGenRenderbuffers(1, depth);
      glBindRenderbuffer(GL_RENDERBUFFER, *depth);
      glRenderbufferStorageMultisample(GL_RENDERBUFFER, count, GL_DEPTH_COMPONENT24, width, height);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, *depth);
    }
    return glCheckFramebufferStatus(GL_FRAMEBUFFER);
  };
  // samples == 1 draws straight into the single-sample framebuffer, which then needs depth;
  // otherwise the multisampled one has depth and the single-sample one only receives the resolve.
  GLenum status = make_framebuffer(targets_.fbo, targets_.colour, samples == 1 ? &targets_.depth : nullptr, 0);
  if (status == GL_FRAMEBUFFER_COMPLETE && samples > 1) {
    status = make_framebuffer(targets_.multisample_fbo, targets_.multisample_colour, &targets_.multisample_depth, samples);
  }
  const std::string size = std::to_string(width) + " × " + std::to_string(height) + " at " + std::to_string(samples) +
                           (samples == 1 ? " sample" : " samples");
  if (const GLenum error = take_gl_error(); error != GL_NO_ERROR) {
    release_targets();
    return gl_failure("allocating render targets of " + size, error);
  }
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    release_targets();
    return make_error(ErrorCode::kInternal, "framebuffer of " + size + " incomplete (status " + hex(status) + ")");
  }
  targets_.width = width;
  targets_.height = height;
  targets_.samples = samples;
  return Status::Ok();
}

Status EglRenderer::draw(const Scene& scene, const Camera& camera) {
  const double aspect = static_cast<double>(scene.width) / scene.height;
  const ClipRange clip = clip_range(camera, geometry::bounding_sphere(scene.points));
  const Eigen::Matrix4f mvp =
      (projection_matrix(camera, aspect, clip.near_distance, clip.far_distance) * view_matrix(camera)).cast<float>();

  // With texture coordinates a vertex's corners may carry different ones (seams), so each face
  // corner becomes a vertex of its own: the vertex arrays hold the #V points, then the 3·#F
  // corners (copies of their points' positions and normals, with the corner's UV), and triangles
  // index the corners while edges and key points keep indexing the points.
  const bool use_checker = scene.corner_uvs.rows() != 0;
  const auto point_count = static_cast<int32_t>(scene.points.rows());
  FaceMatrix corner_faces;
  if (use_checker) {
    corner_faces.resize(scene.faces.rows(), 3);
    for (Eigen::Index c = 0; c < scene.corner_uvs.rows(); ++c) corner_faces.data()[c] = point_count + static_cast<int32_t>(c);
  }
  const FaceMatrix& triangles = use_checker ? corner_faces : scene.faces;

  // Element buffer: triangles, then edges, then seams, then key points. Indices are validated
  // ≥ 0, so int32 data reads the same as GL_UNSIGNED_INT.
  const std::vector<int32_t> edges = scene.wireframe ? line_indices(scene.faces) : std::vector<int32_t>();
  const std::vector<int32_t> seams =
      use_checker && scene.checker.chart_borders ? seam_line_indices(scene.faces, scene.corner_uvs) : std::vector<int32_t>();
  const auto face_bytes = static_cast<GLsizeiptr>(sizeof(int32_t) * static_cast<size_t>(triangles.size()));
  const auto edge_bytes = static_cast<GLsizeiptr>(sizeof(int32_t) * edges.size());
  const auto seam_bytes = static_cast<GLsizeiptr>(sizeof(int32_t) * seams.size());
  const auto key_bytes = static_cast<GLsizeiptr>(sizeof(int32_t) * scene.key_points.size());
  glBindVertexArray(vao_);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, buffers_[kElements]);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, face_bytes + edge_bytes + seam_bytes + key_bytes, nullptr, GL_STREAM_DRAW);
  glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, 0, face_bytes, triangles.data());
  glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, face_bytes, edge_bytes, edges.data());
  glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, face_bytes + edge_bytes, seam_bytes, seams.data());
  glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, face_bytes + edge_bytes + seam_bytes, key_bytes, scene.key_points.data());

  const auto upload = [&](Buffer buffer, const float* data, size_t count) {
    glBindBuffer(GL_ARRAY_BUFFER, buffers_[buffer]);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(sizeof(float) * count), data, GL_STREAM_DRAW);
  };
  // The points, then (with texture coordinates) a copy of each face corner's point.
  const auto with_corners = [&](const PointMatrix& per_point) {
    if (!use_checker) return PointMatrix();
    PointMatrix out(per_point.rows() + scene.corner_uvs.rows(), 3);
    out.topRows(per_point.rows()) = per_point;
    for (Eigen::Index c = 0; c < scene.corner_uvs.rows(); ++c) {
      out.row(per_point.rows() + c) = per_point.row(scene.faces.data()[c]);
    }
    return out;
  };
  // Row-major #V × 3 matrices are already the interleaved x y z layout GL expects.
  const PointMatrix corner_points = with_corners(scene.points);
  const PointMatrix& positions = use_checker ? corner_points : scene.points;
  upload(kPositions, positions.data(), static_cast<size_t>(positions.size()));
  const PointMatrix computed_normals =
      scene.normals.rows() == 0 ? geometry::area_weighted_normals(scene.points, scene.faces) : PointMatrix();
  const PointMatrix& point_normals = scene.normals.rows() == 0 ? computed_normals : scene.normals;
  const PointMatrix corner_normals = with_corners(point_normals);
  const PointMatrix& normals = use_checker ? corner_normals : point_normals;
  upload(kNormals, normals.data(), static_cast<size_t>(normals.size()));
  if (use_checker) {
    // The points themselves are never drawn as surface: their UV is 0.
    Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor> uvs(scene.points.rows() + scene.corner_uvs.rows(), 2);
    uvs.topRows(scene.points.rows()).setZero();
    uvs.bottomRows(scene.corner_uvs.rows()) = scene.corner_uvs;
    upload(kUvs, uvs.data(), static_cast<size_t>(uvs.size()));
    glEnableVertexAttribArray(kUvs);
  } else {
    glDisableVertexAttribArray(kUvs);
    glVertexAttrib2f(kUvs, 0, 0);
  }
  const bool use_heat = scene.heat.size() != 0;
  if (use_heat) {
    upload(kHeat, scene.heat.data(), static_cast<size_t>(scene.heat.size()));
    glEnableVertexAttribArray(kHeat);
  } else {
    glDisableVertexAttribArray(kHeat);
    glVertexAttrib1f(kHeat, 0);
  }
  const bool use_colours = scene.vertex_colours.rows() != 0;
  if (use_colours) {
    upload(kColours, scene.vertex_colours.data(), static_cast<size_t>(scene.vertex_colours.size()));
    glEnableVertexAttribArray(kColours);
  } else {
    glDisableVertexAttribArray(kColours);
    glVertexAttrib3f(kColours, 0, 0, 0);
  }

  const GLuint target = targets_.samples > 1 ? targets_.multisample_fbo : targets_.fbo;
  glBindFramebuffer(GL_FRAMEBUFFER, target);
  glViewport(0, 0, scene.width, scene.height);
  glDisable(GL_BLEND);
  glDisable(GL_SCISSOR_TEST);
  glDepthMask(GL_TRUE);
  glClearColor(scene.background[0], scene.background[1], scene.background[2], scene.background[3]);
  glClearDepthf(1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);

  // Surface. With a wireframe or seams, the filled triangles are pushed back by a polygon offset
  // so that the edges drawn at their exact depth win the depth test.
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  if (scene.wireframe || !seams.empty()) {
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(1, 1);
  } else {
    glDisable(GL_POLYGON_OFFSET_FILL);
  }
  const Material& material = scene.material;
  float heat_max = scene.heat_max;
  if (use_heat && heat_max <= 0) heat_max = scene.heat.maxCoeff();
  glUseProgram(surface_program_);
  glUniformMatrix4fv(surface_uniforms_.mvp, 1, GL_FALSE, mvp.data());
  const Eigen::Vector3f eye = camera.eye.cast<float>();
  glUniform3f(surface_uniforms_.eye, eye.x(), eye.y(), eye.z());
  glUniform3f(surface_uniforms_.albedo, material.albedo.x(), material.albedo.y(), material.albedo.z());
  glUniform1i(surface_uniforms_.use_heat, use_heat ? 1 : 0);
  glUniform1f(surface_uniforms_.heat_scale, heat_max > 0 ? 1 / heat_max : 0);  // all zero: all blue
  glUniform1i(surface_uniforms_.use_colours, use_colours ? 1 : 0);
  glUniform1f(surface_uniforms_.exposure, scene.exposure);
  glUniform4f(surface_uniforms_.material, material.ambient, material.diffuse, material.specular, material.shininess);
  glUniform1i(surface_uniforms_.shading, shading_index(scene.shading));
  glUniform1i(surface_uniforms_.srgb, scene.srgb ? 1 : 0);
  const Checker& checker = scene.checker;
  glUniform1i(surface_uniforms_.use_checker, use_checker ? 1 : 0);
  glUniform1f(surface_uniforms_.checker_squares, checker.squares_per_uv);
  glUniform3f(surface_uniforms_.checker_even, checker.even.x(), checker.even.y(), checker.even.z());
  glUniform3f(surface_uniforms_.checker_odd, checker.odd.x(), checker.odd.y(), checker.odd.z());
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(triangles.size()), GL_UNSIGNED_INT, nullptr);
  glDisable(GL_POLYGON_OFFSET_FILL);

  glUseProgram(overlay_program_);
  glUniformMatrix4fv(overlay_uniforms_.mvp, 1, GL_FALSE, mvp.data());
  // Hidden lines stay hidden (depth test on), without disturbing the depth buffer; seams are drawn
  // after the wireframe, so over it.
  const auto draw_lines = [&](size_t count, GLsizeiptr offset, const Eigen::Vector3f& colour) {
    if (count == 0) return;
    glDepthFunc(GL_LEQUAL);
    glDepthMask(GL_FALSE);
    glUniform3f(overlay_uniforms_.colour, colour.x(), colour.y(), colour.z());
    glUniform1i(overlay_uniforms_.round, 0);
    glUniform1f(overlay_uniforms_.point_size, 1);
    glDrawElements(GL_LINES, static_cast<GLsizei>(count), GL_UNSIGNED_INT, reinterpret_cast<const void*>(offset));
    glDepthMask(GL_TRUE);
  };
  draw_lines(edges.size(), face_bytes, scene.wireframe_colour);
  draw_lines(seams.size(), face_bytes + edge_bytes, checker.chart_border_colour);
  if (!scene.key_points.empty()) {
    // Key points are always visible, also behind the surface, as in Meyer & Anderson 2007,
    // Fig. 1: they are the controls of the pose, not part of the shape.
    glDisable(GL_DEPTH_TEST);
    glUniform3f(overlay_uniforms_.colour, scene.key_point_colour.x(), scene.key_point_colour.y(),
                scene.key_point_colour.z());
    glUniform1i(overlay_uniforms_.round, 1);
    glUniform1f(overlay_uniforms_.point_size,
                std::clamp(2 * scene.key_point_radius_px, limits_.min_point_size, limits_.max_point_size));
    glDrawElements(GL_POINTS, static_cast<GLsizei>(scene.key_points.size()), GL_UNSIGNED_INT,
                   reinterpret_cast<const void*>(face_bytes + edge_bytes + seam_bytes));
  }
  glBindVertexArray(0);

  if (targets_.samples > 1) {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, targets_.multisample_fbo);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, targets_.fbo);
    glBlitFramebuffer(0, 0, scene.width, scene.height, 0, 0, scene.width, scene.height, GL_COLOR_BUFFER_BIT,
                      GL_NEAREST);
  }
  if (const GLenum error = take_gl_error(); error != GL_NO_ERROR) return gl_failure("while drawing", error);
  return Status::Ok();
}

Image EglRenderer::read_back(int width, int height) {
  Image image;
  image.width = width;
  image.height = height;
  const size_t stride = 4 * static_cast<size_t>(width);
  image.rgba.resize(stride * static_cast<size_t>(height));
  glBindFramebuffer(GL_READ_FRAMEBUFFER, targets_.fbo);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, image.rgba.data());
  // GL's rows run bottom to top; the image's (and PNG's) top to bottom.
  for (int y = 0; y < height / 2; ++y) {
    uint8_t* top = image.rgba.data() + stride * static_cast<size_t>(y);
    uint8_t* bottom = image.rgba.data() + stride * static_cast<size_t>(height - 1 - y);
    std::swap_ranges(top, top + stride, bottom);
  }
  return image;
}

Result<Image> EglRenderer::render(const Scene& scene) {
  ANIMSPACE_RETURN_IF_ERROR(validate_scene(scene));
  ANIMSPACE_RETURN_IF_ERROR(check_limits(scene));
  Camera camera;
  if (scene.camera) {
    camera = *scene.camera;
  } else {
    Result<Camera> framed = frame_bounding_box(scene.points, static_cast<double>(scene.width) / scene.height);
    if (!framed.ok()) return framed.error();
    camera = *framed;
  }
  ANIMSPACE_RETURN_IF_ERROR(make_current(" (render() must be called on the thread that created the renderer)"));
  take_gl_error();  // nothing stale may be blamed on this call
  ANIMSPACE_RETURN_IF_ERROR(ensure_targets(scene.width, scene.height, scene.samples));
  if (const Status drawn = draw(scene, camera); !drawn.ok()) {
    // Start the next call from fresh render targets.
    release_targets();
    take_gl_error();
    return drawn.error();
  }
  Image image = read_back(scene.width, scene.height);
  if (const GLenum error = take_gl_error(); error != GL_NO_ERROR) {
    release_targets();
    return gl_failure("while reading the image back", error);
  }
  return image;
}

Result<std::unique_ptr<Renderer>> create_renderer(Result<OpenDisplay> display) {
  if (!display.ok()) return display.error();
  auto renderer = std::make_unique<EglRenderer>(std::move(*display));
  ANIMSPACE_RETURN_IF_ERROR(renderer->init());
  return std::unique_ptr<Renderer>(std::move(renderer));
}

}  // namespace

const char* egl_platform_name(EglPlatform platform) {
  switch (platform) {
    case EglPlatform::kAuto: return "auto";
    case EglPlatform::kSurfaceless: return "surfaceless";
    case EglPlatform::kDevice: return "device";
  }
  return "unknown";
}

Result<EglPlatform> parse_egl_platform(const std::string& name) {
  for (const EglPlatform platform : {EglPlatform::kAuto, EglPlatform::kSurfaceless, EglPlatform::kDevice}) {
    if (name == egl_platform_name(platform)) return platform;
  }
  return make_error(ErrorCode::kInvalidArgument,
                    "EGL platform: expected auto, surfaceless or device, got \"" + name + "\"");
}

Result<std::unique_ptr<Renderer>> make_egl_renderer(EglPlatform platform) {
  switch (platform) {
    case EglPlatform::kSurfaceless: return create_renderer(open_surfaceless());
    case EglPlatform::kDevice: return create_renderer(open_device());
    case EglPlatform::kAuto: break;
  }
  // A GPU device can be listed and still fail later (no surfaceless context, a driver without
  // ES 3): fall back to surfaceless on any failure, and report both if that fails too.
  Result<std::unique_ptr<Renderer>> device = create_renderer(open_device());
  if (device.ok()) return device;
  Result<std::unique_ptr<Renderer>> surfaceless = create_renderer(open_surfaceless());
  if (surfaceless.ok()) return surfaceless;
  return egl_error("auto", device.error().message + "; " + surfaceless.error().message);
}

}  // namespace animspace::render
