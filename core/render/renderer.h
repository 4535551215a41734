// The renderer behind an interface: the server owns one instance on one thread
// (server/render_thread.h) and never touches GL itself.
#pragma once

#include <memory>
#include <string>

#include "core/common/result.h"
#include "core/render/scene.h"

namespace animspace::render {

class Renderer {
 public:
  virtual ~Renderer() = default;
  // Draws `scene`. Must be called from the thread that created the renderer.
  // Errors: kInvalidArgument naming the field for a bad scene (size < 1, faces out of range,
  // non-finite points, sample count not 1/2/4/8, key point out of range, heat of the wrong
  // length or negative, vertex_colours of the wrong row count, negative, not finite or set
  // together with heat, exposure not finite and > 0, corner_uvs of the wrong row count, not finite
  // or set together with heat or vertex_colours, checker.squares_per_uv not finite and > 0,
  // checker.chart_borders without corner_uvs); kResourceExhausted when the size exceeds
  // what the GL implementation can allocate (its maximum renderbuffer size and sample count, and
  // a budget of width · height · samples ≤ 4096² · 8 that keeps a software rasteriser from being
  // killed for memory); kInternal for a GL failure (the renderer stays usable).
  virtual Result<Image> render(const Scene& scene) = 0;
  // "EGL surfaceless — llvmpipe (LLVM 15.0.6, 256 bits), OpenGL ES 3.2 Mesa 22.3.6".
  virtual std::string description() const = 0;
};

// Which EGL platform to open.
enum class EglPlatform {
  kAuto,         // an EGL device with a GPU when one is present, otherwise Mesa surfaceless
  kSurfaceless,  // EGL_MESA_platform_surfaceless (llvmpipe on machines without a GPU)
  kDevice,       // EGL_EXT_platform_device: the first device that is not software
};
const char* egl_platform_name(EglPlatform platform);  // "auto", "surfaceless", "device"
Result<EglPlatform> parse_egl_platform(const std::string& name);

// Opens an EGL display on `platform` and creates an OpenGL ES 3 context current on the calling
// thread (no window: everything is drawn into framebuffer objects).
// Errors: kFailedPrecondition naming the platform and the EGL error when it cannot be opened.
Result<std::unique_ptr<Renderer>> make_egl_renderer(EglPlatform platform);

}  // namespace animspace::render
