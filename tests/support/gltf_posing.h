// Posing a skinned glTF 2.0 document from the file alone, with tinygltf and the specification's
// formulas (Khronos glTF 2.0 §3.7.3 Skins, §3.11 Animations, Appendix C), independently of the
// library's reader (core/mesh_io/gltf_skin.h): the check that what a writer produced plays back as
// the character it was given. Mismatches in the file's layout are reported as test failures.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include "tests/support/tiny_gltf.h"

#include "core/mesh_io/gltf_skin.h"  // Matrix4dList

namespace animspace::testing {

using mesh_io::Matrix4dList;

inline bool skip_gltf_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*,
                            int, void*) {
  return true;
}

struct LoadedGltf {
  tinygltf::Model model;
  bool ok = false;
  std::string error;
};

// `bytes`: a .glb (binary) or a .gltf with its buffers embedded.
inline LoadedGltf load_gltf(const std::string& bytes, bool binary) {
  LoadedGltf loaded;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_gltf_image, nullptr);
  std::string warning;
  loaded.ok = binary ? loader.LoadBinaryFromMemory(&loaded.model, &loaded.error, &warning,
                                                   reinterpret_cast<const unsigned char*>(bytes.data()),
                                                   static_cast<unsigned int>(bytes.size()), "")
                     : loader.LoadASCIIFromString(&loaded.model, &loaded.error, &warning, bytes.data(),
                                                  static_cast<unsigned int>(bytes.size()), "");
  return loaded;
}

// An accessor's elements (tightly packed, as written), with its type checked.
template <typename T>
std::vector<T> accessor_values(const tinygltf::Model& model, int index, int component_type, int type) {
  const tinygltf::Accessor& accessor = model.accessors.at(static_cast<size_t>(index));
  EXPECT_EQ(accessor.componentType, component_type) << "accessor " << index;
  EXPECT_EQ(accessor.type, type) << "accessor " << index;
  EXPECT_FALSE(accessor.sparse.isSparse);
  const tinygltf::BufferView& view = model.bufferViews.at(static_cast<size_t>(accessor.bufferView));
  EXPECT_EQ(view.byteStride, 0u);
  const tinygltf::Buffer& buffer = model.buffers.at(static_cast<size_t>(view.buffer));
  const size_t count =
      accessor.count * static_cast<size_t>(tinygltf::GetNumComponentsInType(static_cast<uint32_t>(type)));
  const size_t offset = view.byteOffset + accessor.byteOffset;
  EXPECT_EQ(offset % sizeof(T), 0u) << "accessor " << index << " is not aligned to its component size";
  EXPECT_LE(count * sizeof(T), view.byteLength);
  EXPECT_LE(offset + count * sizeof(T), buffer.data.size());
  std::vector<T> values(count);
  if (offset + count * sizeof(T) <= buffer.data.size())
    std::memcpy(values.data(), buffer.data.data() + offset, count * sizeof(T));
  return values;
}

enum class Rotations { kSpecSlerp, kNaiveNlerp };

// A LINEAR sampler's value at time t (clamped outside the inputs, §3.11). Rotations follow
// Appendix C's slerp (short arc whatever the signs), or — kNaiveNlerp — a client that lerps the
// four components and normalises, trusting the file's signs.
inline Eigen::VectorXd sample_at(const tinygltf::Model& model, const tinygltf::AnimationSampler& sampler, double t,
                                 Rotations rotations) {
  EXPECT_EQ(sampler.interpolation, "LINEAR");
  const std::vector<float> times =
      accessor_values<float>(model, sampler.input, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR);
  const tinygltf::Accessor& output = model.accessors.at(static_cast<size_t>(sampler.output));
  const int width = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(output.type));
  const std::vector<float> values =
      accessor_values<float>(model, sampler.output, TINYGLTF_COMPONENT_TYPE_FLOAT, output.type);
  const auto key = [&](size_t k) {
    Eigen::VectorXd value(width);
    for (int c = 0; c < width; ++c) value(c) = values[k * static_cast<size_t>(width) + static_cast<size_t>(c)];
    return value;
  };
  if (t <= times.front()) return key(0);
  if (t >= times.back()) return key(times.size() - 1);
  size_t k = 0;
  while (!(t >= times[k] && t < times[k + 1])) ++k;
  const double u = (t - times[k]) / (static_cast<double>(times[k + 1]) - times[k]);
  const Eigen::VectorXd a = key(k), b = key(k + 1);
  if (width != 4) return (1 - u) * a + u * b;
  if (rotations == Rotations::kNaiveNlerp) return ((1 - u) * a + u * b).normalized();
  const double dot = a.dot(b);
  const double angle = std::acos(std::min(1.0, std::abs(dot)));
  if (angle < 1e-9) return a;
  const double sign = dot < 0 ? -1 : 1;
  return std::sin(angle * (1 - u)) / std::sin(angle) * a + sign * std::sin(angle * u) / std::sin(angle) * b;
}

// Every node's global transform at time t (no animation: the nodes' own TRS), composed from the
// scene's roots down through `children`; every node must be reached exactly once.
inline Matrix4dList node_globals(const tinygltf::Model& model, const tinygltf::Animation* animation, double t,
                                 Rotations rotations) {
  const size_t count = model.nodes.size();
  std::vector<Eigen::Vector3d> translation(count, Eigen::Vector3d::Zero());
  std::vector<Eigen::Quaterniond> rotation(count, Eigen::Quaterniond::Identity());
  std::vector<Eigen::Vector3d> scale(count, Eigen::Vector3d::Ones());
  for (size_t n = 0; n < count; ++n) {
    const tinygltf::Node& node = model.nodes[n];
    EXPECT_TRUE(node.matrix.empty()) << "node " << n;
    if (node.translation.size() == 3)
      translation[n] = Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]);
    if (node.rotation.size() == 4)
      rotation[n] = Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    if (node.scale.size() == 3) scale[n] = Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]);
  }
  if (animation != nullptr) {
    for (const tinygltf::AnimationChannel& channel : animation->channels) {
      const size_t n = static_cast<size_t>(channel.target_node);
      const Eigen::VectorXd value =
          sample_at(model, animation->samplers.at(static_cast<size_t>(channel.sampler)), t, rotations);
      if (channel.target_path == "translation") {
        translation.at(n) = value;
      } else if (channel.target_path == "rotation") {
        rotation.at(n) = Eigen::Quaterniond(value(3), value(0), value(1), value(2));
      } else if (channel.target_path == "scale") {
        scale.at(n) = value;
      } else if (channel.target_path == "weights") {
        continue;  // morph weights: morph_weights_at
      } else {
        ADD_FAILURE() << "unexpected channel path " << channel.target_path;
      }
    }
  }
  Matrix4dList globals(count, Eigen::Matrix4d::Zero());
  std::vector<int> visits(count, 0);
  std::function<void(int, const Eigen::Matrix4d&)> visit = [&](int n, const Eigen::Matrix4d& parent) {
    const size_t i = static_cast<size_t>(n);
    ++visits.at(i);
    Eigen::Matrix4d local = Eigen::Matrix4d::Identity();
    local.topLeftCorner<3, 3>() = rotation[i].normalized().toRotationMatrix() * scale[i].asDiagonal();
    local.topRightCorner<3, 1>() = translation[i];
    globals[i] = parent * local;
    for (const int child : model.nodes[i].children) visit(child, globals[i]);
  };
  for (const int root : model.scenes.at(0).nodes) visit(root, Eigen::Matrix4d::Identity());
  for (size_t n = 0; n < count; ++n) EXPECT_EQ(visits[n], 1) << "node " << n;
  return globals;
}

// The skinned mesh's morph weights at time t (§3.7.2.2, §3.11): the animation's "weights"
// channel, LINEAR between keyframes — its output holds every target's weight of a keyframe in
// turn — or the mesh's default weights (0 for each target when it has none).
inline std::vector<double> morph_weights_at(const tinygltf::Model& model, const tinygltf::Animation* animation,
                                            double t) {
  const auto mesh_node = std::find_if(model.nodes.begin(), model.nodes.end(),
                                      [](const tinygltf::Node& n) { return n.mesh >= 0 && n.skin >= 0; });
  if (mesh_node == model.nodes.end()) return {};
  const tinygltf::Mesh& mesh = model.meshes.at(static_cast<size_t>(mesh_node->mesh));
  const size_t targets = mesh.primitives.empty() ? 0 : mesh.primitives[0].targets.size();
  std::vector<double> weights(targets, 0.0);
  if (mesh.weights.size() == targets) weights = mesh.weights;
  if (animation == nullptr) return weights;
  for (const tinygltf::AnimationChannel& channel : animation->channels) {
    if (channel.target_path != "weights") continue;
    EXPECT_EQ(channel.target_node, static_cast<int>(mesh_node - model.nodes.begin()));
    const tinygltf::AnimationSampler& sampler = animation->samplers.at(static_cast<size_t>(channel.sampler));
    EXPECT_EQ(sampler.interpolation, "LINEAR");
    const std::vector<float> times =
        accessor_values<float>(model, sampler.input, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR);
    const std::vector<float> values =
        accessor_values<float>(model, sampler.output, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR);
    EXPECT_EQ(values.size(), times.size() * targets);
    if (values.size() != times.size() * targets || times.empty()) return weights;
    size_t k = 0;
    double u = 0;
    if (t >= times.back()) {
      k = times.size() - 1;
    } else if (t > times.front()) {
      while (!(t >= times[k] && t < times[k + 1])) ++k;
      u = (t - times[k]) / (static_cast<double>(times[k + 1]) - times[k]);
    }
    for (size_t target = 0; target < targets; ++target) {
      const double a = values[k * targets + target];
      const double b = k + 1 < times.size() ? values[(k + 1) * targets + target] : a;
      weights[target] = (1 - u) * a + u * b;
    }
  }
  return weights;
}

// Linear blend skinning as §3.7.3.3 defines it, from the file alone: joint matrix = global of
// the joint's node · its inverse bind matrix, v = Σ over every JOINTS_n / WEIGHTS_n slot of
// w · M_joint · (v̂ + Σ_k weight_k · target_k) (the morph targets' POSITION offsets added before
// skinning, §3.7.2.2; the skinned mesh node's own transform ignored, §3.7.3.2).
inline Eigen::MatrixX3d skin_from_file(const tinygltf::Model& model, const Matrix4dList& globals,
                                       const std::vector<double>& morph_weights = {}) {
  const auto mesh_node = std::find_if(model.nodes.begin(), model.nodes.end(),
                                      [](const tinygltf::Node& n) { return n.mesh >= 0 && n.skin >= 0; });
  if (mesh_node == model.nodes.end()) {
    ADD_FAILURE() << "no skinned mesh node";
    return {};
  }
  const tinygltf::Skin& skin = model.skins.at(static_cast<size_t>(mesh_node->skin));
  const std::vector<float> inverse_binds =
      accessor_values<float>(model, skin.inverseBindMatrices, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_MAT4);
  Matrix4dList joint_matrices;
  for (size_t j = 0; j < skin.joints.size(); ++j) {
    Eigen::Matrix4d inverse_bind;
    for (int e = 0; e < 16; ++e) inverse_bind(e % 4, e / 4) = inverse_binds.at(16 * j + static_cast<size_t>(e));
    joint_matrices.push_back(globals.at(static_cast<size_t>(skin.joints[j])) * inverse_bind);
  }
  const tinygltf::Mesh& mesh = model.meshes.at(static_cast<size_t>(mesh_node->mesh));
  EXPECT_EQ(mesh.primitives.size(), 1u);
  const tinygltf::Primitive& primitive = mesh.primitives.at(0);
  const std::vector<float> positions = accessor_values<float>(model, primitive.attributes.at("POSITION"),
                                                              TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3);
  const size_t vertex_count = positions.size() / 3;
  std::vector<double> morphed(positions.begin(), positions.end());
  EXPECT_TRUE(morph_weights.empty() || morph_weights.size() == primitive.targets.size());
  for (size_t k = 0; k < primitive.targets.size() && k < morph_weights.size(); ++k) {
    const std::vector<float> offsets = accessor_values<float>(model, primitive.targets[k].at("POSITION"),
                                                              TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3);
    EXPECT_EQ(offsets.size(), positions.size());
    for (size_t e = 0; e < offsets.size() && e < morphed.size(); ++e) morphed[e] += morph_weights[k] * offsets[e];
  }
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(static_cast<Eigen::Index>(vertex_count), 3);
  for (int set = 0; primitive.attributes.count("JOINTS_" + std::to_string(set)) != 0; ++set) {
    const std::vector<uint16_t> joints =
        accessor_values<uint16_t>(model, primitive.attributes.at("JOINTS_" + std::to_string(set)),
                                  TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_VEC4);
    const std::vector<float> weights =
        accessor_values<float>(model, primitive.attributes.at("WEIGHTS_" + std::to_string(set)),
                               TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC4);
    EXPECT_EQ(joints.size(), 4 * vertex_count);
    EXPECT_EQ(weights.size(), 4 * vertex_count);
    for (size_t v = 0; v < vertex_count; ++v) {
      const Eigen::Vector4d rest(morphed[3 * v], morphed[3 * v + 1], morphed[3 * v + 2], 1);
      for (size_t slot = 4 * v; slot < 4 * v + 4; ++slot) {
        const Eigen::Vector4d moved = weights[slot] * (joint_matrices.at(joints[slot]) * rest);
        out.row(static_cast<Eigen::Index>(v)) += moved.head<3>().transpose();
      }
    }
  }
  return out;
}

// The document's one animation (a failure, and nullptr, when there is not exactly one).
inline const tinygltf::Animation* only_animation(const tinygltf::Model& model) {
  EXPECT_EQ(model.animations.size(), 1u);
  return model.animations.size() != 1 ? nullptr : &model.animations[0];
}

// The keyframe times of an animation whose samplers share one input (what a sequence exported
// frame by frame has): the times of its first sampler.
inline std::vector<float> keyframe_times(const tinygltf::Model& model, const tinygltf::Animation& animation) {
  if (animation.samplers.empty()) {
    ADD_FAILURE() << "animation without samplers";
    return {};
  }
  for (const tinygltf::AnimationSampler& sampler : animation.samplers)
    EXPECT_EQ(sampler.input, animation.samplers[0].input) << "samplers with different times";
  return accessor_values<float>(model, animation.samplers[0].input, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                TINYGLTF_TYPE_SCALAR);
}

// The largest distance between corresponding rows (infinity, and a failure, when the counts differ).
inline double max_distance(const Eigen::MatrixX3d& a, const Eigen::MatrixX3d& b) {
  EXPECT_EQ(a.rows(), b.rows());
  if (a.rows() != b.rows()) return std::numeric_limits<double>::infinity();
  return (a - b).rowwise().norm().maxCoeff();
}

}  // namespace animspace::testing
