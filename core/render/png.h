// PNG encoding and decoding with libpng (Debian's libpng16).
#pragma once

#include <string>

#include "core/common/result.h"
#include "core/render/scene.h"

namespace animspace::render {

// 8-bit RGBA PNG bytes. `compression_level` 0–9 (zlib); thumbnails use a fast level.
// Errors: kInvalidArgument for an empty image or a buffer of the wrong size.
Result<std::string> encode_png(const Image& image, int compression_level = 3);

// Any PNG libpng reads, converted to 8-bit RGBA. Errors: kInvalidArgument naming `source` and
// libpng's message for bytes that are not a PNG.
Result<Image> decode_png(const std::string& bytes, const std::string& source);

}  // namespace animspace::render
