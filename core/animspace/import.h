// Importing linear-blend-skinned rigs into animation space (Merry 2007 §2.2, §3.1).
//
// A linear-blend (SSD) rig poses vertex v̂ as v = Σ_j w_j G_j Ĝ_j⁻¹ v̂ (eq. 2.2). Merging the
// static part into the vertex, p_j = w_j Ĝ_j⁻¹ v̂, gives the animation-space form v = Σ_j G_j p_j
// (eq. 3.1): from_linear_blend does exactly that, so an imported rig poses identically.
//
// Rig files become a LinearBlendModel first, with the two rules every importer here shares:
// - Skeleton: bone 0 is a fixed super-root (§2.1: "a new bone to act as a super-root", G_0 = I)
//   carrying no weight; the file's bones follow in an order where parents precede children, and
//   ImportedRig::bone_of_source maps the file's bone numbers to ours.
// - Weights: every vertex's weights must sum to 1 within WeightOptions::sum_tolerance (else an
//   error naming the file and the row / vertex); exact zeros are not influences; the weights
//   kept are rescaled to sum to 1 in double precision (a change of at most the tolerance).
//
// Formats:
// - libigl (mesh_io/libigl_rig.h): OBJ rest mesh, TGF joints and bones, DMAT #V by #B weights,
//   Tmat poses. A TGF bone (parent joint → child joint) becomes a bone whose frame sits at its
//   parent joint with the model's axes (Ĝ a pure translation); its parent is the bone that
//   ends at its parent joint, or the super-root when none does.
// - glTF 2.0 (Khronos, "glTF 2.0 Specification" §3.7.3 Skins), .gltf or .glb, read by
//   mesh_io/gltf_skin.h: a node's mesh (all triangle primitives, concatenated) and skin. Skin joint j
//   has bind transform Ĝ_j = inverseBindMatrices[j]⁻¹ and posed transform G_j = the joint
//   node's global transform, so that G_j Ĝ_j⁻¹ is the spec's joint matrix; its parent is the
//   nearest ancestor node that is also a joint of the skin, else the super-root.
//
// Every function returns errors as values (kInvalidArgument naming the file and the offending
// row, bone, accessor or primitive; kNotFound / kIo from reads); none throws.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/common/types.h"
#include "core/mesh_io/libigl_rig.h"

namespace animspace::animation_space {

// p_j = w_j Ĝ_j⁻¹ v̂ for every influence with w_j ≠ 0 (Merry 2007 §3.1); the influence sets are
// those of `model` less its exact-zero weights, and skeleton and faces are copied. Evaluating
// the result in any pose equals evaluate(model, …) up to rounding (both in double precision).
// Precondition (asserted): validate(model).ok().
AnimationSpaceModel from_linear_blend(const LinearBlendModel& model);

// How a file's weights become influences.
struct WeightOptions {
  // Influences with |w| < drop_below are dropped before the remaining weights are rescaled to
  // sum to 1. The default 0 drops only exact zeros, so the conversion is exact to the file.
  // A vertex then moves by at most (dropped weight) × (the spread of its bones' skinning
  // transforms), e.g. cow-rig: 1e-6 drops 42 118 of 80 150 non-zeros, at most 3.1e-6 of weight
  // per vertex.
  double drop_below = 0.0;
  // Then each vertex's smallest remaining weights are dropped while their sum stays ≤ drop_budget
  // (never the last). Renormalising the rest moves the vertex by (dropped sum) × the distance
  // between where its dropped and its kept bones carry it, so the budget bounds that move as a
  // fraction of the bones' spread whatever the character's size — the rule `import-rig` applies
  // (its --drop-weights; issue #55 item 11: the cow carried 6.87 influences per vertex where
  // 3.26 were above 1e-6). 0: none.
  double drop_budget = 0.0;
  // Allowed |Σ_j w_j − 1| per vertex, checked on the file's weights before anything is dropped.
  double sum_tolerance = 1e-6;
};

// A rig read from a file.
struct ImportedRig {
  LinearBlendModel model;  // bone 0 the super-root, no influence on bone 0
  // bone_of_source[b]: our bone for the file's bone b (TGF bone line b, glTF skin joint b).
  std::vector<int32_t> bone_of_source;
  int64_t dropped_weights = 0;        // non-zero weights dropped by WeightOptions::drop_below
  double max_dropped_weight_sum = 0;  // the largest Σ|w| dropped from one vertex
};

// Names of the three parts of a libigl rig, for error messages (usually their paths).
struct LibiglSources {
  std::string mesh = "rest mesh";
  std::string skeleton = "TGF skeleton";
  std::string weights = "DMAT weights";
};

// A libigl rig from memory. `rest` is the rest mesh (#V vertices), `skeleton` the TGF joints and
// bones (#B bones), `weights` the #V by #B DMAT matrix (entry (v, b): weight of TGF bone b on
// vertex v). Errors (kInvalidArgument): sizes that disagree, a joint that ends two bones, a cycle
// of bones, a non-finite weight, a row whose weights do not sum to 1 ("cow.DMAT: row 17
// (vertex 17): weights sum to 0.98, expected 1 (±1e-06)"), or a vertex left without influence.
Result<ImportedRig> rig_from_libigl(const TriangleMesh& rest, const mesh_io::TgfSkeleton& skeleton,
                                    const Eigen::MatrixXd& weights, const LibiglSources& sources = {},
                                    const WeightOptions& options = {});

// Reads `mesh` (OBJ/PLY/OFF rest mesh), `tgf` and `dmat`, then rig_from_libigl.
Result<ImportedRig> read_libigl_rig(const std::filesystem::path& mesh, const std::filesystem::path& tgf,
                                    const std::filesystem::path& dmat, const WeightOptions& options = {});

// A libigl pose: one 4 by 3 row-vector transform T_b per file bone (posed = [v̂ 1] T_b), as the
// global transforms of `rig`'s skeleton: the column-vector skinning matrix of bone j = bone of
// file bone b is S = [T_bᵀ; 0 0 0 1] = G_j Ĝ_j⁻¹, so G_j = T_bᵀ Ĝ_j; G_0 = I. Errors
// (kInvalidArgument, naming `source`): a transform count other than the rig's bone count, a
// non-finite entry.
Result<TransformList> pose_from_tmat(const ImportedRig& rig, const std::vector<Eigen::Matrix<double, 4, 3>>& transforms,
                                     const std::string& source);

// read_tmat then pose_from_tmat.
Result<TransformList> read_tmat_pose(const ImportedRig& rig, const std::filesystem::path& tmat);

struct GltfImportOptions {
  // The node whose mesh and skin are imported; -1: the first node that has both.
  int node = -1;
  // glTF weights are float32 or 8/16-bit normalised integers, so the sum check is looser than
  // for DMAT text; a normalised integer type adds its quantisation (slots · ½ / max) on top.
  WeightOptions weights{.drop_below = 0.0, .sum_tolerance = 1e-4};
};

struct GltfRig {
  ImportedRig rig;
  // The pose of the file's nodes (their matrix or TRS): G_j = global transform of the joint
  // node of bone j, G_0 = I. Equals skeleton.rest when the nodes are in the bind pose.
  TransformList pose;
  // Rest normals from the NORMAL attribute (#V by 3, as stored), or empty when any primitive
  // lacks it.
  Eigen::MatrixX3d rest_normals;
};

// Reads a .gltf (JSON, buffers embedded as data URIs or in files next to it) or .glb file.
// Accepted: triangle primitives (mode 4) with POSITION (float VEC3), optional NORMAL (float
// VEC3), optional indices (unsigned byte / short / int scalars; absent: consecutive triangles),
// JOINTS_n (unsigned byte / short VEC4) and WEIGHTS_n (float, or normalised unsigned byte /
// short, VEC4) for n = 0, 1, … in pairs; the skin's joints and inverseBindMatrices (float MAT4,
// affine; absent means identity). Repeated joints within a vertex are merged by adding their
// weights. Errors (kInvalidArgument, naming the file and the node, skin, mesh, primitive or
// accessor): a file tinygltf cannot parse, missing or sparse accessors, unsupported component
// types, out-of-bounds accessors, joint indices outside the skin, weights not summing to 1, a
// singular or non-affine inverse bind matrix, a node graph that is not a forest.
Result<GltfRig> read_gltf_rig(const std::filesystem::path& file, const GltfImportOptions& options = {});

}  // namespace animspace::animation_space
