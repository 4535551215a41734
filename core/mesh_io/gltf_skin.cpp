// glTF 2.0 skins through tinygltf: every accessor is checked against its buffer view and buffer
// before a byte is read (the offsets and strides are the file's, so untrusted).
#include "core/mesh_io/gltf_skin.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <new>
#include <optional>
#include <utility>

#include <Eigen/Geometry>
#include <tiny_gltf.h>

#include "core/common/format.h"

namespace animspace::mesh_io {
namespace {

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

// Where we are in the file, for error messages: "box.gltf: mesh 0 primitive 1: accessor 3 (JOINTS_0)".
struct GltfContext {
  const tinygltf::Model& model;
  std::string file;
};

// A validated accessor: element e, component c lives at data + e·stride + c·component_size.
struct AccessorView {
  const unsigned char* data = nullptr;
  size_t stride = 0;
  size_t count = 0;
  int component_type = 0;
  int components = 0;
  bool normalized = false;

  double component(size_t element, int c) const {
    const unsigned char* at = data + element * stride;
    switch (component_type) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
        const double value = at[c];
        return normalized ? value / 255.0 : value;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t value;
        std::memcpy(&value, at + 2 * c, sizeof value);
        return normalized ? value / 65535.0 : value;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t value;
        std::memcpy(&value, at + 4 * c, sizeof value);
        return value;
      }
      case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float value;
        std::memcpy(&value, at + 4 * c, sizeof value);
        return value;
      }
      default:
        assert(false && "component type is checked by accessor_view");
        return 0;
    }
  }
};

const char* component_type_name(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT: return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_INT: return "INT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return "FLOAT";
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: return "DOUBLE";
    default: return "an unknown component type";
  }
}

int components_of_type(int type) {
  const int32_t components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(type));
  return components > 0 ? components : 0;
}

// Checks accessor `index` (type with `components` components, one of `allowed` component types;
// integers must be `normalized` as asked: 1 yes, 0 no, -1 either) against its buffer view and
// buffer, so that every read through the view is in bounds. `what` names the use ("POSITION").
Result<AccessorView> accessor_view(const GltfContext& context, int index, const std::string& where,
                                   const std::string& what, int components, std::initializer_list<int> allowed,
                                   int normalized = -1) {
  const tinygltf::Model& model = context.model;
  const std::string name = where + ": accessor " + std::to_string(index) + " (" + what + ")";
  if (index < 0 || static_cast<size_t>(index) >= model.accessors.size()) {
    return invalid(where + ": " + what + " refers to accessor " + std::to_string(index) + ", but the file has " +
                   std::to_string(model.accessors.size()));
  }
  const tinygltf::Accessor& accessor = model.accessors[static_cast<size_t>(index)];
  if (accessor.sparse.isSparse) return invalid(name + " is sparse, which is not supported");
  if (components_of_type(accessor.type) != components) {
    return invalid(name + " has " + std::to_string(components_of_type(accessor.type)) + " components per element, expected " +
                   std::to_string(components));
  }
  if (std::find(allowed.begin(), allowed.end(), accessor.componentType) == allowed.end()) {
    std::string expected;
    for (const int type : allowed) expected += std::string(expected.empty() ? "" : " or ") + component_type_name(type);
    return invalid(name + " has component type " + component_type_name(accessor.componentType) + ", expected " +
                   expected);
  }
  if (accessor.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT && normalized >= 0 &&
      accessor.normalized != (normalized == 1)) {
    return invalid(name + (normalized == 1 ? " must be normalized" : " must not be normalized"));
  }
  if (accessor.bufferView < 0 || static_cast<size_t>(accessor.bufferView) >= model.bufferViews.size()) {
    return invalid(name + " has no valid bufferView (accessors without data are not supported)");
  }
  const tinygltf::BufferView& view = model.bufferViews[static_cast<size_t>(accessor.bufferView)];
  if (view.buffer < 0 || static_cast<size_t>(view.buffer) >= model.buffers.size()) {
    return invalid(name + ": buffer view " + std::to_string(accessor.bufferView) + " refers to a missing buffer");
  }
  const std::vector<unsigned char>& buffer = model.buffers[static_cast<size_t>(view.buffer)].data;
  const size_t element_size =
      static_cast<size_t>(tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(accessor.componentType))) *
      static_cast<size_t>(components);
  const size_t stride = view.byteStride == 0 ? element_size : view.byteStride;
  if (stride < element_size) {
    return invalid(name + ": byteStride " + std::to_string(stride) + " is smaller than an element (" +
                   std::to_string(element_size) + " bytes)");
  }
  if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset) {
    return invalid(name + ": buffer view " + std::to_string(accessor.bufferView) + " (bytes " +
                   std::to_string(view.byteOffset) + " + " + std::to_string(view.byteLength) + ") exceeds buffer " +
                   std::to_string(view.buffer) + " (" + std::to_string(buffer.size()) + " bytes)");
  }
  if (accessor.count > 0) {
    const size_t needed = accessor.byteOffset + (accessor.count - 1) * stride + element_size;
    if (accessor.byteOffset > view.byteLength || (accessor.count - 1) > (view.byteLength / stride) ||
        needed > view.byteLength) {
      return invalid(name + ": " + std::to_string(accessor.count) + " elements from byte " +
                     std::to_string(accessor.byteOffset) + " exceed buffer view " + std::to_string(accessor.bufferView) +
                     " (" + std::to_string(view.byteLength) + " bytes)");
    }
  }
  AccessorView result;
  result.data = buffer.data() + view.byteOffset + accessor.byteOffset;
  result.stride = stride;
  result.count = accessor.count;
  result.component_type = accessor.componentType;
  result.components = components;
  result.normalized = accessor.normalized;
  return result;
}

// A node's local transform: its matrix (column-major), or T · R · S.
Result<Eigen::Matrix4d> local_transform(const GltfContext& context, size_t node_index) {
  const tinygltf::Node& node = context.model.nodes[node_index];
  const std::string name = context.file + ": node " + std::to_string(node_index);
  Eigen::Matrix4d local = Eigen::Matrix4d::Identity();
  if (!node.matrix.empty()) {
    if (node.matrix.size() != 16) return invalid(name + ": matrix has " + std::to_string(node.matrix.size()) + " entries, expected 16");
    for (int k = 0; k < 16; ++k) local(k % 4, k / 4) = node.matrix[static_cast<size_t>(k)];
    if (!local.allFinite() || local.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
      return invalid(name + ": matrix is not a finite affine transform (last row 0 0 0 1)");
    }
    return local;
  }
  Eigen::Vector3d translation = Eigen::Vector3d::Zero(), scale = Eigen::Vector3d::Ones();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  if (!node.translation.empty()) {
    if (node.translation.size() != 3) return invalid(name + ": translation needs 3 numbers");
    translation = Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]);
  }
  if (!node.scale.empty()) {
    if (node.scale.size() != 3) return invalid(name + ": scale needs 3 numbers");
    scale = Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]);
  }
  if (!node.rotation.empty()) {
    if (node.rotation.size() != 4) return invalid(name + ": rotation needs 4 numbers (x y z w)");
    rotation = Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    // The spec requires a unit quaternion; allow float rounding, refuse anything else.
    if (!std::isfinite(rotation.norm()) || std::abs(rotation.norm() - 1.0) > 1e-3) {
      return invalid(name + ": rotation is not a unit quaternion (norm " + format_number(rotation.norm()) + ")");
    }
    rotation.normalize();
  }
  if (!translation.allFinite() || !scale.allFinite()) return invalid(name + ": translation or scale is not finite");
  local.topLeftCorner<3, 3>() = rotation.toRotationMatrix() * scale.asDiagonal();
  local.topRightCorner<3, 1>() = translation;
  return local;
}

// Parent of every node (-1 for scene roots), checking that the node graph is a forest.
Result<std::vector<int>> node_parents(const GltfContext& context) {
  const auto& nodes = context.model.nodes;
  std::vector<int> parents(nodes.size(), -1);
  for (size_t n = 0; n < nodes.size(); ++n) {
    for (const int child : nodes[n].children) {
      if (child < 0 || static_cast<size_t>(child) >= nodes.size()) {
        return invalid(context.file + ": node " + std::to_string(n) + " has child " + std::to_string(child) +
                       ", which does not exist");
      }
      if (parents[static_cast<size_t>(child)] >= 0 || static_cast<size_t>(child) == n) {
        return invalid(context.file + ": node " + std::to_string(child) + " has more than one parent");
      }
      parents[static_cast<size_t>(child)] = static_cast<int>(n);
    }
  }
  // With at most one parent each, a walk of more than #nodes steps means a cycle.
  for (size_t n = 0; n < nodes.size(); ++n) {
    size_t steps = 0;
    for (int at = parents[n]; at >= 0; at = parents[static_cast<size_t>(at)]) {
      if (++steps > nodes.size()) return invalid(context.file + ": node " + std::to_string(n) + " is in a cycle of nodes");
    }
  }
  return parents;
}

Result<Matrix4dList> node_global_transforms(const GltfContext& context, const std::vector<int>& parents) {
  const size_t count = context.model.nodes.size();
  Matrix4dList locals(count), globals(count);
  for (size_t n = 0; n < count; ++n) {
    auto local = local_transform(context, n);
    if (!local.ok()) return local.error();
    locals[n] = *local;
  }
  std::vector<bool> done(count, false);
  std::vector<size_t> chain;
  for (size_t n = 0; n < count; ++n) {
    chain.clear();
    for (int at = static_cast<int>(n); at >= 0 && !done[static_cast<size_t>(at)]; at = parents[static_cast<size_t>(at)]) {
      chain.push_back(static_cast<size_t>(at));
    }
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      const int parent = parents[*it];
      globals[*it] = parent < 0 ? locals[*it] : Eigen::Matrix4d(globals[static_cast<size_t>(parent)] * locals[*it]);
      done[*it] = true;
    }
  }
  return globals;
}

Result<std::string> read_whole_file(const std::filesystem::path& path) {
  std::error_code code;
  if (!std::filesystem::exists(path, code)) return make_error(ErrorCode::kNotFound, path.string() + ": no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return make_error(ErrorCode::kIo, path.string() + ": cannot open for reading");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return make_error(ErrorCode::kIo, path.string() + ": read failed");
  return bytes;
}

// Images are irrelevant to skinning: accept them without decoding (tinygltf would otherwise
// need stb_image, and fail on embedded images without a loader).
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

Result<tinygltf::Model> load_gltf(const std::filesystem::path& file) {
  auto bytes = read_whole_file(file);
  if (!bytes.ok()) return bytes.error();
  if (bytes->size() > std::numeric_limits<unsigned int>::max()) {
    return make_error(ErrorCode::kResourceExhausted, file.string() + ": larger than 4 GiB");
  }
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  tinygltf::Model model;
  std::string error, warning;
  const std::string base_dir = file.parent_path().string();
  const unsigned int size = static_cast<unsigned int>(bytes->size());
  const bool binary = bytes->size() >= 4 && bytes->compare(0, 4, "glTF") == 0;
  const bool loaded =
      binary ? loader.LoadBinaryFromMemory(&model, &error, &warning, reinterpret_cast<const unsigned char*>(bytes->data()),
                                           size, base_dir)
             : loader.LoadASCIIFromString(&model, &error, &warning, bytes->data(), size, base_dir);
  if (!loaded) {
    while (!error.empty() && (error.back() == '\n' || error.back() == ' ')) error.pop_back();
    for (char& c : error) {
      if (c == '\n') c = ';';
    }
    return invalid(file.string() + ": not a readable glTF 2.0 " + (binary ? "binary (.glb)" : "JSON (.gltf)") +
                   " file: " + (error.empty() ? "tinygltf gave no reason" : error));
  }
  return model;
}

// The primitive's JOINTS_n / WEIGHTS_n sets.
struct SkinAttributeSet {
  AccessorView joints;
  AccessorView weights;
};

Result<GltfSkin> read_gltf_skin_unchecked(const std::filesystem::path& file, int requested_node) {
  auto loaded = load_gltf(file);
  if (!loaded.ok()) return loaded.error();
  const tinygltf::Model& model = *loaded;
  const GltfContext context{model, file.string()};
  GltfSkin out;
  out.file = file.string();

  // 1. The node: the requested one, or the first with a mesh and a skin.
  int node_index = requested_node;
  if (node_index >= 0) {
    if (static_cast<size_t>(node_index) >= model.nodes.size()) {
      return invalid(context.file + ": node " + std::to_string(node_index) + " requested, but the file has " +
                     std::to_string(model.nodes.size()) + " nodes");
    }
  } else {
    for (size_t n = 0; n < model.nodes.size() && node_index < 0; ++n) {
      if (model.nodes[n].mesh >= 0 && model.nodes[n].skin >= 0) node_index = static_cast<int>(n);
    }
    if (node_index < 0) return invalid(context.file + ": no node has both a mesh and a skin");
  }
  const tinygltf::Node& node = model.nodes[static_cast<size_t>(node_index)];
  const std::string node_name = context.file + ": node " + std::to_string(node_index);
  if (node.mesh < 0 || static_cast<size_t>(node.mesh) >= model.meshes.size()) {
    return invalid(node_name + " has no valid mesh");
  }
  if (node.skin < 0 || static_cast<size_t>(node.skin) >= model.skins.size()) {
    return invalid(node_name + " has no valid skin");
  }
  out.node = node_index;
  out.mesh = node.mesh;
  out.skin = node.skin;
  const tinygltf::Skin& skin = model.skins[static_cast<size_t>(node.skin)];
  const std::string skin_name = context.file + ": skin " + std::to_string(node.skin);

  // 2. The joints: bind matrices, hierarchy through the node graph, the nodes' pose.
  auto parents_result = node_parents(context);
  if (!parents_result.ok()) return parents_result.error();
  const std::vector<int>& node_parent = *parents_result;
  const size_t joint_count = skin.joints.size();
  if (joint_count == 0) return invalid(skin_name + " has no joints");
  std::vector<int> joint_of_node(model.nodes.size(), -1);
  for (size_t j = 0; j < joint_count; ++j) {
    const int joint_node = skin.joints[j];
    if (joint_node < 0 || static_cast<size_t>(joint_node) >= model.nodes.size()) {
      return invalid(skin_name + ": joint " + std::to_string(j) + " is node " + std::to_string(joint_node) +
                     ", which does not exist");
    }
    if (joint_of_node[static_cast<size_t>(joint_node)] >= 0) {
      return invalid(skin_name + ": node " + std::to_string(joint_node) + " is listed twice among the joints");
    }
    joint_of_node[static_cast<size_t>(joint_node)] = static_cast<int>(j);
  }
  out.inverse_bind_matrices.assign(joint_count, Eigen::Matrix4d::Identity());
  if (skin.inverseBindMatrices >= 0) {
    auto view = accessor_view(context, skin.inverseBindMatrices, skin_name, "inverseBindMatrices", 16,
                              {TINYGLTF_COMPONENT_TYPE_FLOAT});
    if (!view.ok()) return view.error();
    if (view->count != joint_count) {
      return invalid(skin_name + ": accessor " + std::to_string(skin.inverseBindMatrices) + " (inverseBindMatrices) has " +
                     std::to_string(view->count) + " matrices, expected one per joint (" + std::to_string(joint_count) +
                     ")");
    }
    for (size_t j = 0; j < joint_count; ++j) {
      Eigen::Matrix4d inverse_bind;
      for (int k = 0; k < 16; ++k) inverse_bind(k % 4, k / 4) = view->component(j, k);  // column-major
      const std::string matrix_name = skin_name + ": inverseBindMatrices[" + std::to_string(j) + "]";
      // Stored as float32, so the affine row may carry rounding; anything more is not affine.
      if (!inverse_bind.allFinite() || !inverse_bind.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1), 1e-6)) {
        return invalid(matrix_name + " is not a finite affine matrix (last row 0 0 0 1)");
      }
      inverse_bind.row(3) = Eigen::RowVector4d(0, 0, 0, 1);
      const Eigen::Matrix3d linear = inverse_bind.topLeftCorner<3, 3>();
      const double scale = linear.norm();
      if (!(std::abs(linear.determinant()) > 1e-12 * scale * scale * scale)) {
        return invalid(matrix_name + " is singular");
      }
      out.inverse_bind_matrices[j] = inverse_bind;
    }
  }
  out.joint_parents.assign(joint_count, -1);
  out.joint_names.resize(joint_count);
  for (size_t j = 0; j < joint_count; ++j) {
    const int joint_node = skin.joints[j];
    for (int at = node_parent[static_cast<size_t>(joint_node)]; at >= 0; at = node_parent[static_cast<size_t>(at)]) {
      if (joint_of_node[static_cast<size_t>(at)] >= 0) {
        out.joint_parents[j] = joint_of_node[static_cast<size_t>(at)];
        break;
      }
    }
    const std::string& name = model.nodes[static_cast<size_t>(joint_node)].name;
    out.joint_names[j] = name.empty() ? "node " + std::to_string(joint_node) : name;
  }
  auto node_globals = node_global_transforms(context, node_parent);
  if (!node_globals.ok()) return node_globals.error();
  out.joint_node_transforms.resize(joint_count);
  for (size_t j = 0; j < joint_count; ++j) {
    out.joint_node_transforms[j] = (*node_globals)[static_cast<size_t>(skin.joints[j])];
  }

  // 3. The mesh: every primitive, concatenated.
  const tinygltf::Mesh& mesh = model.meshes[static_cast<size_t>(node.mesh)];
  if (mesh.primitives.empty()) return invalid(context.file + ": mesh " + std::to_string(node.mesh) + " has no primitives");
  std::vector<Eigen::Vector3d> points, normals;
  std::vector<Eigen::Vector3i> faces;
  bool all_have_normals = true;
  out.slot_offsets.push_back(0);
  for (size_t p = 0; p < mesh.primitives.size(); ++p) {
    const tinygltf::Primitive& primitive = mesh.primitives[p];
    const std::string where = context.file + ": mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(p);
    if (primitive.mode != -1 && primitive.mode != TINYGLTF_MODE_TRIANGLES) {
      return invalid(where + " has mode " + std::to_string(primitive.mode) + ", expected 4 (triangles)");
    }
    const auto attribute = [&](const std::string& name) {
      const auto it = primitive.attributes.find(name);
      return it == primitive.attributes.end() ? -1 : it->second;
    };
    if (attribute("POSITION") < 0) return invalid(where + " has no POSITION attribute");
    auto positions = accessor_view(context, attribute("POSITION"), where, "POSITION", 3, {TINYGLTF_COMPONENT_TYPE_FLOAT});
    if (!positions.ok()) return positions.error();
    const size_t count = positions->count;
    const auto check_count = [&](const AccessorView& view, const std::string& name) -> Status {
      if (view.count != count) {
        return invalid(where + ": " + name + " has " + std::to_string(view.count) + " elements, but POSITION has " +
                       std::to_string(count));
      }
      return Status::Ok();
    };
    std::vector<SkinAttributeSet> sets;
    for (int set = 0;; ++set) {
      const std::string joints_name = "JOINTS_" + std::to_string(set), weights_name = "WEIGHTS_" + std::to_string(set);
      const int joints_index = attribute(joints_name), weights_index = attribute(weights_name);
      if (joints_index < 0 && weights_index < 0) break;
      if (joints_index < 0 || weights_index < 0) {
        return invalid(where + " has " + (joints_index < 0 ? weights_name : joints_name) + " without " +
                       (joints_index < 0 ? joints_name : weights_name));
      }
      auto joints = accessor_view(context, joints_index, where, joints_name, 4,
                                  {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT}, 0);
      if (!joints.ok()) return joints.error();
      auto weights = accessor_view(context, weights_index, where, weights_name, 4,
                                   {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                                    TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT},
                                   1);
      if (!weights.ok()) return weights.error();
      ANIMSPACE_RETURN_IF_ERROR(check_count(*joints, joints_name));
      ANIMSPACE_RETURN_IF_ERROR(check_count(*weights, weights_name));
      sets.push_back({*joints, *weights});
    }
    if (sets.empty()) return invalid(where + " has no JOINTS_0 / WEIGHTS_0 attributes (is it skinned?)");

    // Weights stored as n-bit integers are quantised by up to ½ / (2ⁿ − 1) per slot.
    GltfSkin::Primitive info;
    info.first_vertex = static_cast<int64_t>(points.size());
    info.vertex_count = static_cast<int64_t>(count);
    for (const SkinAttributeSet& set : sets) {
      if (set.weights.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) info.weight_quantisation += 4 * 0.5 / 255.0;
      if (set.weights.component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) info.weight_quantisation += 4 * 0.5 / 65535.0;
    }
    out.primitives.push_back(info);

    const size_t first_vertex = points.size();
    std::optional<AccessorView> normal_view;
    if (attribute("NORMAL") >= 0) {
      auto view = accessor_view(context, attribute("NORMAL"), where, "NORMAL", 3, {TINYGLTF_COMPONENT_TYPE_FLOAT});
      if (!view.ok()) return view.error();
      ANIMSPACE_RETURN_IF_ERROR(check_count(*view, "NORMAL"));
      normal_view = *view;
    } else {
      all_have_normals = false;
    }
    for (size_t v = 0; v < count; ++v) {
      const Eigen::Vector3d point(positions->component(v, 0), positions->component(v, 1), positions->component(v, 2));
      if (!point.allFinite()) return invalid(where + ": POSITION " + std::to_string(v) + " is not finite");
      points.push_back(point);
      if (normal_view) {
        normals.emplace_back(normal_view->component(v, 0), normal_view->component(v, 1), normal_view->component(v, 2));
      }
      for (size_t s = 0; s < sets.size(); ++s) {
        for (int slot = 0; slot < 4; ++slot) {
          const double joint = sets[s].joints.component(v, slot);
          if (joint >= static_cast<double>(joint_count)) {
            return invalid(where + ": JOINTS_" + std::to_string(s) + " of vertex " + std::to_string(v) + " (slot " +
                           std::to_string(slot) + ") is joint " + std::to_string(static_cast<int64_t>(joint)) +
                           ", but skin " + std::to_string(node.skin) + " has " + std::to_string(joint_count) +
                           " joints");
          }
          out.slot_joints.push_back(static_cast<int32_t>(joint));
          out.slot_weights.push_back(sets[s].weights.component(v, slot));
        }
      }
      out.slot_offsets.push_back(static_cast<int64_t>(out.slot_joints.size()));
    }

    // Faces: the indices accessor, or consecutive vertex triples.
    if (primitive.indices >= 0) {
      auto indices = accessor_view(context, primitive.indices, where, "indices", 1,
                                   {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                                    TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT},
                                   0);
      if (!indices.ok()) return indices.error();
      if (indices->count % 3 != 0) {
        return invalid(where + ": indices has " + std::to_string(indices->count) + " elements, expected a multiple of 3");
      }
      for (size_t f = 0; f < indices->count / 3; ++f) {
        Eigen::Vector3i face;
        for (int c = 0; c < 3; ++c) {
          const double index = indices->component(3 * f + static_cast<size_t>(c), 0);
          if (index >= static_cast<double>(count)) {
            return invalid(where + ": index " + std::to_string(3 * f + static_cast<size_t>(c)) + " is vertex " +
                           std::to_string(static_cast<int64_t>(index)) + ", but the primitive has " +
                           std::to_string(count) + " vertices");
          }
          face(c) = static_cast<int>(first_vertex + static_cast<size_t>(index));
        }
        faces.push_back(face);
      }
    } else {
      if (count % 3 != 0) {
        return invalid(where + " has no indices and " + std::to_string(count) + " vertices, expected a multiple of 3");
      }
      for (size_t f = 0; f < count / 3; ++f) {
        faces.emplace_back(static_cast<int>(first_vertex + 3 * f), static_cast<int>(first_vertex + 3 * f + 1),
                           static_cast<int>(first_vertex + 3 * f + 2));
      }
    }
  }
  if (points.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max() / 4)) {
    return make_error(ErrorCode::kResourceExhausted, context.file + ": too many vertices");
  }
  out.points.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (size_t v = 0; v < points.size(); ++v) out.points.row(static_cast<Eigen::Index>(v)) = points[v].transpose();
  out.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) out.faces.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  if (all_have_normals) {
    out.normals.resize(static_cast<Eigen::Index>(normals.size()), 3);
    for (size_t v = 0; v < normals.size(); ++v) out.normals.row(static_cast<Eigen::Index>(v)) = normals[v].transpose();
  }
  return out;
}

}  // namespace

Result<GltfSkin> read_gltf_skin(const std::filesystem::path& file, int node) {
  // tinygltf and nlohmann::json may throw (allocation, JSON type errors); nothing escapes core.
  try {
    return read_gltf_skin_unchecked(file, node);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, file.string() + ": out of memory while reading");
  } catch (const std::exception& exception) {
    return invalid(file.string() + ": not a readable glTF file: " + exception.what());
  } catch (...) {
    return make_error(ErrorCode::kInternal, file.string() + ": unknown exception while reading");
  }
}

}  // namespace animspace::mesh_io
