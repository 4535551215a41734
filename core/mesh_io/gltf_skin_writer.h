// Writing a linear-blend-skinned character with one animation as glTF 2.0 (Khronos, "glTF 2.0
// Specification": §3.7.3 Skins, §3.11 Animations), .glb or .gltf with the buffer embedded: the
// file a DCC tool or a game engine imports to play a sequence on the original rig.
//
// The document holds one node per joint (joint j is node j, children by joint_parents), one node
// for the mesh (node J, with the skin; a scene root without a transform, since §3.7.3.2 has the
// skinned mesh node's own transform ignored), and when the joints form several trees an
// untransformed node "skeleton" (node J + 1) above their roots, because §3.7.3.2 requires a
// common root; when there are frames, one animation with a translation and a rotation channel
// per joint. The reader of such files is gltf_skin.h.
//
// Affine joints (a bone that shears or scales, as the articulated subspace's do: pmsc/articulated.h)
// have no single node: §3.5.3 gives a node T · R · S, no shear. Each such joint j is two nodes,
// an outer "shape" node (node J + 2 + j: translation t, rotation U, scale Σ) and the joint node j
// below it (rotation Vᵀ), so that the joint's local transform is T · U Σ Vᵀ for the singular value
// decomposition of its linear part — any invertible affine map, a reflection as a negative last
// scale. Morph targets (§3.7.2.2) are offsets of the bind positions, added before skinning, with
// their weights on the mesh node animated per frame (§3.11 "weights").
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/mesh_io/gltf_skin.h"  // Matrix4dList
#include "core/mesh_io/posed_mesh.h"  // UvMatrix

namespace animspace::mesh_io {

// A linear-blend-skinned character with an animation, as glTF 2.0 represents it (§3.7.3 Skins,
// §3.11 Animations). Transforms are 4 × 4 in double, acting on column vectors (p' = M · [p; 1]),
// model space; every one must be rigid: finite, last row 0 0 0 1, RᵀR within 1e-6 of I (largest
// entry) and det R > 0. Lengths are in the mesh's units; glTF readers take them as metres.
struct SkinnedCharacter {
  Eigen::MatrixX3d bind_points;  // #V × 3, the mesh in the bind pose (model space), finite
  FaceMatrix faces;              // #F × 3, #F ≥ 1, indices in [0, #V)
  // #V × 3 unit normals (length within 1e-3 of 1; normalised in double before writing) in the
  // bind pose, or empty: then the area-weighted normals of the bind pose are written, unless
  // some vertex is in no non-degenerate face, in which case NORMAL is omitted (§3.7.2.1 wants
  // normalized normals, and readers of a mesh without them compute flat ones).
  Eigen::MatrixX3d normals;
  // #V × 2 texture coordinates (u, v with v up, finite), or empty: written as TEXCOORD_0
  // (u, 1 − v). One per vertex: a texture atlas's seams are split first (split_seams below).
  UvMatrix uvs;
  std::vector<int32_t> joint_parents;    // J ≥ 1 entries, parents[j] < j or -1 (a forest, parents first)
  std::vector<std::string> joint_names;  // J names, or empty; an empty name is written "joint_<j>"
  Matrix4dList bind_globals;             // J: joint j's global transform in the bind pose (rigid)
  // Influences, compressed rows: vertex v's joints/weights are [offsets[v], offsets[v+1]).
  // offsets has #V + 1 entries, non-decreasing from 0 to joints.size() == weights.size().
  std::vector<int32_t> offsets, joints;  // joints in [0, J)
  // finite, ≥ 0, each vertex's sum within 1e-6 of 1; a joint at most once per vertex with a
  // non-zero weight (§3.7.3.3)
  std::vector<double> weights;
  // Animation: frame k's global transform of every joint (rigid), sampled at k / frames_per_second
  // seconds. Empty: no animation is written.
  std::vector<Matrix4dList> frame_globals;
  double frames_per_second = 24;  // finite, > 0 (checked only when there are frames)
  std::string animation_name = "sequence";
  // Joints may be any invertible affine map (finite, last row 0 0 0 1, the linear part's smallest
  // singular value above 1e-12 of its largest), not only rigid: written as two nodes each, above.
  // False: every transform must be rigid (checked), one node per joint.
  bool affine_joints = false;
  // Morph targets: each #V × 3 finite position offsets in the bind pose, their names (empty, or
  // one per target), and per frame their weights (frame_globals.size() × targets, finite; empty
  // when there are no frames). Without frames the mesh's default weights are 0.
  std::vector<Eigen::MatrixX3d> morph_targets;
  std::vector<std::string> morph_target_names;
  Eigen::MatrixXd frame_morph_weights;
  // What the character is called (the model's name): its mesh node and mesh carry it, and its
  // skin and joints' root "<name> rig", so that an importer names the objects after the model
  // (Blender 3.4 names the mesh object after the node and the armature after the skin).
  std::string name = "character";
};

// The character with a UV per vertex from UVs per face corner (3·#F × 2, row 3f + k corner k of
// face f): a vertex whose corners carry different UVs (an atlas's seam) becomes one vertex per
// distinct UV, with the same bind position, normal, joints and weights, so it poses exactly as
// the original. Without given normals, the original's area-weighted bind-pose normals are given
// to the copies (so that the split does not crease the shading along seams), when every vertex
// has one. `character` must have no UVs yet and corner_uvs 3·#F rows (asserted).
SkinnedCharacter split_seams(const SkinnedCharacter& character, const UvMatrix& corner_uvs);

// The character as .glb bytes / as .gltf JSON with an embedded base64 buffer.
//
// Written as: POSITION (float32, with min/max), NORMAL and TEXCOORD_0 as above; indices uint32; JOINTS_n
// (UNSIGNED_SHORT) / WEIGHTS_n (FLOAT) in sets of four slots, as many sets as the vertex with the
// most influences needs, influences in the order given (slot s of vertex v is influence
// offsets[v] + s), unused slots and zero weights written as joint 0 weight 0; the skin's
// inverseBindMatrices (float32 MAT4, column-major) = bind_globals⁻¹; each joint node's local
// translation and unit rotation, parent_global⁻¹ · global of the bind pose (no scale); one shared
// time accessor k / fps and per joint LINEAR "translation" and "rotation" channels of the local
// transforms, each quaternion's sign chosen so that it is on the short arc from the previous
// frame's. Affine joints: the inverse bind matrices are general inverses, and each joint's shape
// node has "translation", "rotation" and "scale" channels and its joint node a "rotation" one,
// the decomposition's signs chosen per frame to stay near the previous frame's. Morph targets:
// POSITION offsets (float32, with min/max), mesh weights 0, their names in the mesh's
// extras.targetNames (what Blender and three.js read), and one LINEAR "weights" channel.
// Errors: kInvalidArgument naming the field, the index and what was expected (sizes, non-finite
// values, parents not parents-first, joints out of range, negative weights or sums not 1,
// non-rigid transforms, frames with the wrong joint count, fps ≤ 0 or so large that float32
// frame times coincide, more than 65536 joints, a buffer over 2 GiB); kResourceExhausted when
// out of memory; never throws.
Result<std::string> serialize_skinned_glb(const SkinnedCharacter& character);
Result<std::string> serialize_skinned_gltf(const SkinnedCharacter& character);

// Writes the character to `path` by its extension (.glb or .gltf, any case), atomically.
// Errors: those above, prefixed with the path; kInvalidArgument for another extension; kIo when
// the file cannot be written.
Status write_skinned_character(const std::filesystem::path& path, const SkinnedCharacter& character);

}  // namespace animspace::mesh_io
