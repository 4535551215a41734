#include "core/mesh_io/gltf_writing.h"

#include <exception>
#include <new>
#include <sstream>
#include <utility>
#include <vector>

namespace animspace::mesh_io::gltf_writing {

tinygltf::Model new_document() {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "animspace";
  model.buffers.emplace_back();
  return model;
}

int append_accessor(tinygltf::Model& model, const void* bytes, size_t byte_length, int target, int component_type,
                    int type, size_t count) {
  std::vector<unsigned char>& data = model.buffers.at(0).data;
  data.resize((data.size() + 3) / 4 * 4, 0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = data.size();
  view.byteLength = byte_length;
  view.target = target;
  const auto* first = static_cast<const unsigned char*>(bytes);
  data.insert(data.end(), first, first + byte_length);
  model.bufferViews.push_back(std::move(view));
  tinygltf::Accessor accessor;
  accessor.bufferView = static_cast<int>(model.bufferViews.size() - 1);
  accessor.byteOffset = 0;
  accessor.componentType = component_type;
  accessor.type = type;
  accessor.count = count;
  model.accessors.push_back(std::move(accessor));
  return static_cast<int>(model.accessors.size() - 1);
}

Result<std::string> serialize_document(const tinygltf::Model& model, bool binary, const std::string& kind) {
  try {
    tinygltf::TinyGLTF writer;
    std::ostringstream stream(std::ios::out | std::ios::binary);
    if (!writer.WriteGltfSceneToStream(&model, stream, /*prettyPrint=*/!binary, /*writeBinary=*/binary) || !stream) {
      return make_error(ErrorCode::kInternal, kind + ": tinygltf could not serialise the document");
    }
    return std::move(stream).str();
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, kind + ": out of memory while serialising");
  } catch (const std::exception& exception) {
    return make_error(ErrorCode::kInternal, kind + ": tinygltf failed while serialising: " + exception.what());
  }
}

}  // namespace animspace::mesh_io::gltf_writing
