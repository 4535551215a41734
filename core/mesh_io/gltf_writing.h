// What the glTF 2.0 writers of core/mesh_io share (posed_mesh.cpp, gltf_skin_writer.cpp): a
// document with one buffer, one tightly packed buffer view per accessor, and its serialisation as
// .glb or as .gltf JSON with the buffer embedded as a base64 data URI, through tinygltf.
// Internal to mesh_io: it exposes tinygltf types, which no public header of the library does.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

#include <tiny_gltf.h>

#include "core/common/result.h"

namespace animspace::mesh_io::gltf_writing {

// Sizes in a .glb header are uint32 (glTF 2.0 §4.4.3) and tinygltf keeps some offsets in int;
// a document's buffer stays well inside both.
inline constexpr size_t kMaxBufferBytes = size_t{std::numeric_limits<int32_t>::max()} - (size_t{1} << 20);

// An empty glTF 2.0 document (asset version "2.0", generator "animspace") with one empty buffer.
tinygltf::Model new_document();

// Appends `byte_length` bytes to buffer 0, first padding it to a multiple of 4 so that every
// accessor starts aligned to its component size and every vertex attribute to 4 bytes (glTF 2.0
// §3.6.2.4 Data Alignment), then a buffer view over exactly those bytes (`target` 0 for none:
// animation and skin data have no GPU binding, §3.6.2.1) and an accessor of `count` elements on
// it. Returns the accessor's index.
int append_accessor(tinygltf::Model& model, const void* bytes, size_t byte_length, int target, int component_type,
                    int type, size_t count);

// The document as .glb bytes (`binary`) or as pretty-printed .gltf JSON whose buffer is a data
// URI. `kind` prefixes the messages. Errors: kInternal when tinygltf fails, kResourceExhausted
// when memory runs out; never throws.
Result<std::string> serialize_document(const tinygltf::Model& model, bool binary, const std::string& kind);

}  // namespace animspace::mesh_io::gltf_writing
