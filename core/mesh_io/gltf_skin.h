// Reading one skinned mesh from a glTF 2.0 file (Khronos, "glTF 2.0 Specification" §3.7.3
// Skins), .gltf (buffers embedded as data URIs or in files next to it) or .glb, through tinygltf
// (compiled once, in tiny_gltf_impl.cpp).
//
// This is the file as it stands, checked so that every read is in bounds and every number is
// usable: no rig convention is applied. animspace/import.h turns a GltfSkin into a linear-blend
// rig (super-root, parents-first bone order, the weight rules shared with the libigl reader).
// The writers of glTF files are posed_mesh.h (a posed mesh) and gltf_skin_writer.h (a skinned,
// animated character).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/StdVector>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::mesh_io {

using Matrix4dList = std::vector<Eigen::Matrix4d, Eigen::aligned_allocator<Eigen::Matrix4d>>;

struct GltfSkin {
  std::string file;  // as given, for messages
  int node = -1;     // the node whose mesh and skin these are
  int mesh = -1;
  int skin = -1;

  // The skin's joints j = 0 … J−1, in the skin's order.
  std::vector<int32_t> joint_parents;  // the joint whose node is the nearest joint ancestor, or -1
  std::vector<std::string> joint_names;  // the node's name, or "node N" when it has none
  // inverseBindMatrices[j] (identity when the skin has none): finite, affine (last row exactly
  // 0 0 0 1 after float rounding is removed) and non-singular.
  Matrix4dList inverse_bind_matrices;
  Matrix4dList joint_node_transforms;  // global transform of joint j's node (matrix or T·R·S)

  // Every triangle primitive of the mesh, concatenated: #V vertices, #F faces.
  Eigen::MatrixX3d points;   // #V × 3, finite
  FaceMatrix faces;          // #F × 3, indices in [0, #V)
  Eigen::MatrixX3d normals;  // #V × 3 as stored, or empty when a primitive has no NORMAL

  // The JOINTS_n / WEIGHTS_n slots of each vertex as stored, four per attribute pair, zeros and
  // repeated joints included: vertex v's are [slot_offsets[v], slot_offsets[v + 1]). Joints are
  // < J; weights are as stored (normalised integers already divided by their maximum), unchecked.
  std::vector<int64_t> slot_offsets;  // #V + 1
  std::vector<int32_t> slot_joints;
  std::vector<double> slot_weights;

  struct Primitive {
    int64_t first_vertex = 0;
    int64_t vertex_count = 0;
    // How far integer weights may sum from 1 by their quantisation alone: ½ / (2ⁿ − 1) per slot
    // of an n-bit normalised integer, 0 for float weights.
    double weight_quantisation = 0;
  };
  std::vector<Primitive> primitives;
};

// Reads node `node` (−1: the first node with both a mesh and a skin). Accepted: triangle
// primitives (mode 4) with POSITION (float VEC3), optional NORMAL (float VEC3), optional indices
// (unsigned byte / short / int scalars; absent: consecutive triangles), JOINTS_n (unsigned byte /
// short VEC4) and WEIGHTS_n (float, or normalised unsigned byte / short, VEC4) in pairs; the
// skin's joints and inverseBindMatrices (float MAT4).
// Errors (kInvalidArgument naming the file and the node, skin, mesh, primitive or accessor): a
// file tinygltf cannot parse, missing or sparse accessors, unsupported component types,
// out-of-bounds accessors, joint indices outside the skin, a singular or non-affine inverse bind
// matrix, a node graph that is not a forest; kNotFound / kIo from the read; kResourceExhausted
// for a file over 4 GiB or out of memory. Never throws.
Result<GltfSkin> read_gltf_skin(const std::filesystem::path& file, int node = -1);

}  // namespace animspace::mesh_io
