#include "core/render/png.h"

#include <png.h>

#include <csetjmp>
#include <cstdint>
#include <cstring>
#include <string>

namespace animspace::render {

namespace {

// Decoding refuses images above this many pixels (1 GiB of RGBA) before allocating: a few bytes
// of PNG header can claim 2³¹ × 2³¹ pixels.
constexpr uint64_t kMaxDecodedPixels = uint64_t{1} << 28;

// State shared with libpng's callbacks. Plain data only: libpng reports errors by longjmp, which
// must not cross anything with a destructor (nor may a C++ exception cross libpng's C frames).
struct WriteContext {
  std::string* out = nullptr;
  bool out_of_memory = false;
  char message[256] = {};
};

void on_error(png_structp png, png_const_charp message) {
  auto* context = static_cast<WriteContext*>(png_get_error_ptr(png));
  std::strncpy(context->message, message, sizeof context->message - 1);
  png_longjmp(png, 1);
}

void on_warning(png_structp, png_const_charp) {}

void on_write(png_structp png, png_bytep data, png_size_t length) {
  auto* context = static_cast<WriteContext*>(png_get_io_ptr(png));
  try {
    context->out->append(reinterpret_cast<const char*>(data), length);
  } catch (...) {
    context->out_of_memory = true;
  }
  // Outside the catch block: png_error longjmps.
  if (context->out_of_memory) png_error(png, "out of memory for the encoded PNG");
}

void on_flush(png_structp) {}

// The classic write API, because the simplified one (png_image_write_to_memory) has no
// compression level, and zlib's level is most of the encode time of a thumbnail. Returns false
// with context.message set on failure. Only trivially destructible locals between setjmp and
// the end of the function.
bool write_png(const Image& image, int compression_level, WriteContext& context) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &context, on_error, on_warning);
  if (png == nullptr) {
    std::strncpy(context.message, "png_create_write_struct failed", sizeof context.message - 1);
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, &context, on_write, on_flush);
  png_set_compression_level(png, compression_level);
  // The fast levels skip row filtering: libpng's adaptive filter choice tries all five filters
  // on every row and was most of the encode time of a render (256² at level 3: 7.2 ms with
  // adaptive filtering, 2.6 ms without, for 14 % more bytes; renders are mostly flat background
  // and smooth shading, which deflate handles well unfiltered). Levels 4–9 ask for size and
  // keep the adaptive filters.
  if (compression_level <= 3) png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
               PNG_COLOR_TYPE_RGB_ALPHA, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_write_info(png, info);
  const size_t stride = 4 * static_cast<size_t>(image.width);
  for (int y = 0; y < image.height; ++y) png_write_row(png, image.rgba.data() + stride * static_cast<size_t>(y));
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

Result<std::string> encode_png(const Image& image, int compression_level) {
  if (image.width < 1 || image.height < 1) {
    return make_error(ErrorCode::kInvalidArgument, "image: empty (" + std::to_string(image.width) + " × " +
                                                       std::to_string(image.height) + " pixels)");
  }
  const uint64_t expected = 4 * static_cast<uint64_t>(image.width) * static_cast<uint64_t>(image.height);
  if (image.rgba.size() != expected) {
    return make_error(ErrorCode::kInvalidArgument, "image.rgba: expected " + std::to_string(expected) +
                                                       " bytes for " + std::to_string(image.width) + " × " +
                                                       std::to_string(image.height) + " RGBA, got " +
                                                       std::to_string(image.rgba.size()));
  }
  if (compression_level < 0 || compression_level > 9) {
    return make_error(ErrorCode::kInvalidArgument,
                      "compression_level: expected 0–9, got " + std::to_string(compression_level));
  }
  std::string out;
  WriteContext context;
  context.out = &out;
  if (!write_png(image, compression_level, context)) {
    return make_error(context.out_of_memory ? ErrorCode::kResourceExhausted : ErrorCode::kInternal,
                      std::string("PNG encoding failed: ") + context.message);
  }
  return out;
}

Result<Image> decode_png(const std::string& bytes, const std::string& source) {
  // The simplified read API handles libpng's longjmp internally and converts any PNG (palette,
  // grey, 16-bit, with or without alpha) to 8-bit RGBA.
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  const auto failed = [&](const std::string& what) {
    const std::string message = source + ": not a readable PNG (" + what + ": " + png.message + ")";
    png_image_free(&png);
    return make_error(ErrorCode::kInvalidArgument, message);
  };
  if (!png_image_begin_read_from_memory(&png, bytes.data(), bytes.size())) return failed("header");
  if (static_cast<uint64_t>(png.width) * png.height > kMaxDecodedPixels) {
    const std::string message = source + ": PNG of " + std::to_string(png.width) + " × " +
                                std::to_string(png.height) + " pixels is larger than the decoder accepts";
    png_image_free(&png);
    return make_error(ErrorCode::kInvalidArgument, message);
  }
  png.format = PNG_FORMAT_RGBA;
  Image image;
  image.width = static_cast<int>(png.width);
  image.height = static_cast<int>(png.height);
  image.rgba.resize(PNG_IMAGE_SIZE(png));
  if (!png_image_finish_read(&png, nullptr, image.rgba.data(), 0, nullptr)) return failed("pixels");
  return image;
}

}  // namespace animspace::render
