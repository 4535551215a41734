// Writes glTF 2.0 files from scratch, independently of tinygltf (the importer's reader), for the
// import tests (tests/core/animspace/import_test.cpp) and the glTF fuzzer's seeds
// (fuzz/make_seed_corpus.cpp): one buffer, one buffer view per accessor, and the three ways a
// buffer reaches a reader — a .bin file next to the .gltf, a base64 data URI inside it, or the
// BIN chunk of a .glb (glTF 2.0 §4.4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace animspace::testing {

// RFC 4648 base64 with padding, as data URIs carry binary buffers.
inline std::string base64(const std::string& bytes) {
  static const char* const kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t n = (static_cast<uint8_t>(bytes[i]) << 16) | (static_cast<uint8_t>(bytes[i + 1]) << 8) |
                       static_cast<uint8_t>(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(n >> s) & 63];
  }
  if (i < bytes.size()) {
    uint32_t n = static_cast<uint8_t>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) n |= static_cast<uint8_t>(bytes[i + 1]) << 8;
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

// Assembles a glTF document: one buffer, one buffer view per accessor.
struct GltfBuilder {
  nlohmann::json doc = {{"asset", {{"version", "2.0"}}},
                        {"bufferViews", nlohmann::json::array()},
                        {"accessors", nlohmann::json::array()}};
  std::string bin;

  // Appends `values` (4-byte aligned) as a new buffer view and an accessor of `count` elements of
  // `type` ("SCALAR", "VEC3", "MAT4", …) and `component_type` (5121 UNSIGNED_BYTE, 5123
  // UNSIGNED_SHORT, 5125 UNSIGNED_INT, 5126 FLOAT); returns the accessor's index.
  template <typename T>
  int add(const std::vector<T>& values, int component_type, const std::string& type, size_t count,
          bool normalized = false) {
    while (bin.size() % 4 != 0) bin += '\0';
    const size_t offset = bin.size();
    bin.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
    doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", values.size() * sizeof(T)}});
    nlohmann::json accessor = {{"bufferView", doc["bufferViews"].size() - 1},
                               {"componentType", component_type},
                               {"count", count},
                               {"type", type}};
    if (normalized) accessor["normalized"] = true;
    doc["accessors"].push_back(accessor);
    return static_cast<int>(doc["accessors"].size()) - 1;
  }

  enum class Layout { kExternalBin, kDataUri, kGlb };

  // The bytes of a .gltf (kDataUri; kExternalBin, whose buffer is the file `bin_name`) or .glb
  // (kGlb: 12-byte header, JSON chunk padded with spaces, BIN chunk; glTF 2.0 §4.4.3).
  std::string serialize(Layout layout, const std::string& bin_name = "") {
    nlohmann::json out = doc;
    while (bin.size() % 4 != 0) bin += '\0';
    if (layout == Layout::kExternalBin) {
      out["buffers"] = {{{"byteLength", bin.size()}, {"uri", bin_name}}};
    } else if (layout == Layout::kDataUri) {
      out["buffers"] = {{{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + base64(bin)}}};
    } else {
      out["buffers"] = {{{"byteLength", bin.size()}}};
    }
    std::string text = out.dump();
    if (layout != Layout::kGlb) return text;
    while (text.size() % 4 != 0) text += ' ';
    std::string glb;
    const auto u32 = [&glb](uint32_t value) { glb.append(reinterpret_cast<const char*>(&value), 4); };
    glb += "glTF";
    u32(2);
    u32(static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
    u32(static_cast<uint32_t>(text.size()));
    u32(0x4E4F534A);  // JSON
    glb += text;
    u32(static_cast<uint32_t>(bin.size()));
    u32(0x004E4942);  // BIN
    glb += bin;
    return glb;
  }

  // Writes serialize(layout) to `path`, and for kExternalBin the buffer to <stem>.bin beside it.
  void write(const std::filesystem::path& path, Layout layout) {
    const std::string bin_name = path.stem().string() + ".bin";
    const std::string bytes = serialize(layout, bin_name);
    if (layout == Layout::kExternalBin) std::ofstream(path.parent_path() / bin_name, std::ios::binary) << bin;
    std::ofstream(path, std::ios::binary) << bytes;
  }
};

}  // namespace animspace::testing
