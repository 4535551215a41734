// Automatic rigid segmentation of a mesh sequence: what the user would otherwise mark by hand
// before skeleton fitting (Merry 2007 §4.1.4: "the user creates a skeleton, and marks a set of
// core vertices associated with each bone").
//
// Given a plain mesh sequence (no skeleton), the vertices are partitioned into B parts that
// each move almost rigidly over the whole sequence (clustering by rigid motion: James & Twigg
// 2005 §3; Le & Deng 2012, SSDR §4.1; Le & Deng 2014, the cluster-splitting initialisation of
// Dem Bones), kept spatially coherent: each part is one connected piece of mesh. From the parts
// come a bone hierarchy, core vertices, initial joint positions u_j and the per-frame rigid
// motion of every part — the inputs of skeleton_fit (§4.1.4), which refines the motions and
// joints, and of the least-squares model fit (§4.1.1), which grows influence sets from the
// per-vertex labels.
//
// Cost: O(#V · #frames) per iteration, a few dozen iterations; on horse-gallop (8431 vertices,
// 48 frames) about 2 s for B = 20 on two cores.
//
// Bones: bone 0 is a super-root (model space, identity in every frame, owns no vertices); the
// parts are bones 1 … B, numbered so that a parent precedes its children (φ(j) < j), as
// skeleton.h requires.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

struct SegmentationOptions {
  // B, the number of rigid parts (bones other than the super-root); 1 ≤ B ≤ #V.
  int bone_count = 20;
  // Upper bound on the refinement iterations (fit motions → reassign vertices) after the parts
  // have been created, and after each merge–split move; the loop stops earlier when no vertex
  // changes part. ≥ 0.
  int iterations = 30;
  // Refinement iterations after each round of part splitting during initialisation. ≥ 0.
  int init_iterations = 5;
  // The refinement also stops once three iterations in a row have lowered the total squared
  // trajectory error by less than this fraction; the best parts seen are returned. A merge–split
  // move must lower the error by at least this fraction to be kept. ≥ 0.
  double tolerance = 1e-3;
  // Merge–split moves tried after refinement to leave a local optimum (two adjacent parts that
  // one motion fits almost as well are merged, the worst-fitting part is split, and the result
  // is refined again); the first move that does not lower the error ends them. ≥ 0.
  int merge_split_attempts = 3;
  // Core vertices stay at least this many mesh edges away from any other part: 1 drops the
  // vertices adjacent to another part, 2 also their neighbours. ≥ 0. Relaxed ring by ring for
  // a part too small to keep 3 non-collinear core vertices.
  int core_erosion_rings = 1;
  // Core vertices also fit their part's motion well: RMS error ≤ this factor × the part's
  // median RMS error (plus 1e-6 of the bounding-box diagonal, so that exactly rigid parts keep
  // all their vertices). > 0 and finite.
  double core_error_factor = 2.0;
};

struct RigidSegmentation {
  // φ(j): B + 1 entries, parents[0] == -1, 0 ≤ parents[j] < j otherwise. The parts become a
  // tree by a maximum spanning tree of part adjacency (weight = mesh edges across the shared
  // boundary), rooted at the part that minimises Σ_parts size · tree distance (the "median" part,
  // e.g. a torso); that root's parent is bone 0. A mesh in several pieces gives a forest: one
  // child of bone 0 per piece.
  std::vector<int32_t> parents;
  // #V: the bone (1 … B) whose part owns each vertex.
  std::vector<int32_t> labels;
  // B + 1 lists of vertex indices (ascending); [0] is empty. Vertices of the part that are away
  // from its boundary and fit its rigid motion well (see SegmentationOptions); at least 3 and
  // not collinear whenever the part itself has 3 non-collinear vertices, otherwise the whole part.
  std::vector<std::vector<int32_t>> core_vertices;
  // B + 1 by 3, rest-pose model space: the initial joint position u_j (§4.1.4) of each bone —
  // the centroid of the midpoints of the mesh edges between the part and its parent's part, or
  // for a part directly under bone 0 the centroid of its vertices. Row 0 (the super-root) is 0.
  Eigen::MatrixX3d joint_positions;
  // #frames lists of B + 1 rigid transforms M_j^k: rest pose → frame k, model space, so that a
  // vertex v̂ of part j is approximated by M_j^k v̂ in frame k (the "M" of §4.1.4 restricted to
  // rotation + translation). transforms[k][0] == I.
  std::vector<TransformList> transforms;
  // #V: RMS over frames of ‖M_j^k v̂_i − v_i^k‖ for the vertex's own bone j, model units.
  Eigen::VectorXd fit_error;
  // RMS over all vertices and frames of the same residual, model units.
  double rms_error = 0.0;
  // Refinement iterations run after initialisation, merge–split refinements included.
  int iterations = 0;

  int bone_count() const { return static_cast<int>(parents.size()); }  // B + 1
};

// Segments a mesh sequence into options.bone_count near-rigid parts and derives a skeleton for
// them (see the file comment).
//   rest:   #V by 3, the rest pose (normally the first frame of the training set); the
//           transforms map it to each frame.
//   faces:  #F by 3 indices into rest; may be empty (then every vertex is its own piece of mesh
//           and parts are not spatially coherent). Mesh edges give part adjacency and
//           connectivity: each part is one connected component of the mesh, unless the mesh
//           itself has several components.
//   frames: #frames (≥ 1) by 3·#V, row k = x0 y0 z0 x1 … of frame k, same vertex order.
// Precision: inputs are float; all fitting is in double. Deterministic (no random choices).
// Errors: kInvalidArgument naming the field, expected vs actual: bone_count outside [1, #V],
// frames width ≠ 3·#V or no frames, a face index outside [0, #V), a non-finite coordinate,
// an option out of range.
Result<RigidSegmentation> segment_rigid_parts(const PointMatrix& rest, const FaceMatrix& faces,
                                              const FrameMatrix& frames, const SegmentationOptions& options = {});

}  // namespace animspace::animation_space
