// Rigid segmentation: clustering of vertices by their rigid motion over a sequence.
//
//   James & Twigg 2005, "Skinning mesh animations": bones as clusters of rigid motion.
//   Le & Deng 2012, "Smooth skinning decomposition with rigid bones" (SSDR) §4.1: alternate a
//     per-bone Kabsch fit with reassigning each vertex to the bone that reproduces its trajectory.
//   Le & Deng 2014, "Robust and accurate skeletal rig extraction" (the initialisation of Dem
//     Bones): grow the number of bones by splitting the worst-fitting clusters.
//   Merry 2007 §4.1.4: what skeleton fitting needs from the user (hierarchy, core vertices,
//     joint positions u_j) — produced here instead.
//
// Precision: double throughout (positions arrive as float). Trajectory errors are evaluated
// directly, Σ_k ‖R_k v̂ + t_k − v^k‖², not through an expanded quadratic form, which would cancel
// for characters far from the origin.
#include "core/animspace/segmentation.h"

#include <algorithm>
#include <cassert>
#include <climits>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <numeric>
#include <queue>
#include <string>
#include <tuple>
#include <utility>

#include <Eigen/Eigenvalues>

#include "core/common/parallel.h"
#include "core/geometry/edges.h"
#include "core/geometry/rigid_fit.h"

namespace animspace::animation_space {
namespace {

using Eigen::Index;
using Eigen::Matrix3d;
using Eigen::Vector3d;

// Per-frame rigid motions of P parts, 12F × P: column p holds, for frame k, R (column-major) in
// rows 12k … 12k+8 and t in rows 12k+9 … 12k+11, so that one part's whole motion is contiguous.
using Motions = Eigen::MatrixXd;
constexpr Index kMotionStride = 12;


// The sequence in the layout the fitting wants.
struct Sequence {
  int vertex_count = 0;
  int frame_count = 0;
  Eigen::Matrix3Xd rest;         // 3 × V
  Eigen::MatrixXd trajectories;  // 3F × V: column i is vertex i in frames 0 … F-1 (x y z each)
  Eigen::MatrixXd positions;     // 3V × F: column k is frame k (x y z per vertex)
  Vector3d rest_centroid;
  Eigen::VectorXd frame_centroids;  // 3F: centroid of frame k at 3k … 3k+2
  geometry::Adjacency adjacency;
};

std::string shape(Index rows, Index cols) { return std::to_string(rows) + " × " + std::to_string(cols); }

Status validate_inputs(const PointMatrix& rest, const FaceMatrix& faces, const FrameMatrix& frames,
                       const SegmentationOptions& options) {
  const Index V = rest.rows();
  const auto invalid = [](const std::string& message) {
    return make_error(ErrorCode::kInvalidArgument, "segment_rigid_parts: " + message);
  };
  if (V < 1) return invalid("rest must have at least 1 vertex, got " + shape(V, 3));
  if (options.bone_count < 1 || options.bone_count > V) {
    return invalid("options.bone_count must be in [1, #V = " + std::to_string(V) + "], got " +
                   std::to_string(options.bone_count));
  }
  if (options.iterations < 0)
    return invalid("options.iterations must be ≥ 0, got " + std::to_string(options.iterations));
  if (options.init_iterations < 0) {
    return invalid("options.init_iterations must be ≥ 0, got " + std::to_string(options.init_iterations));
  }
  if (options.merge_split_attempts < 0) {
    return invalid("options.merge_split_attempts must be ≥ 0, got " + std::to_string(options.merge_split_attempts));
  }
  if (options.core_erosion_rings < 0) {
    return invalid("options.core_erosion_rings must be ≥ 0, got " + std::to_string(options.core_erosion_rings));
  }
  if (!(options.tolerance >= 0.0) || !std::isfinite(options.tolerance)) {
    return invalid("options.tolerance must be finite and ≥ 0, got " + std::to_string(options.tolerance));
  }
  if (!std::isfinite(options.core_error_factor) || !(options.core_error_factor > 0.0)) {
    return invalid("options.core_error_factor must be finite and > 0, got " +
                   std::to_string(options.core_error_factor));
  }
  if (frames.rows() < 1)
    return invalid("frames must have at least 1 frame (row), got " + shape(frames.rows(), frames.cols()));
  if (frames.cols() != 3 * V) {
    return invalid("frames must have 3·#V = " + std::to_string(3 * V) + " columns, got " +
                   shape(frames.rows(), frames.cols()));
  }
  for (Index f = 0; f < faces.rows(); ++f) {
    for (Index c = 0; c < 3; ++c) {
      const int32_t index = faces(f, c);
      if (index < 0 || index >= V) {
        return invalid("faces(" + std::to_string(f) + ", " + std::to_string(c) + ") = " + std::to_string(index) +
                       " is outside [0, #V = " + std::to_string(V) + ")");
      }
    }
  }
  for (Index i = 0; i < V; ++i) {
    if (!rest.row(i).allFinite()) return invalid("rest vertex " + std::to_string(i) + " is not finite");
  }
  for (Index k = 0; k < frames.rows(); ++k) {
    for (Index x = 0; x < frames.cols(); ++x) {
      if (!std::isfinite(frames(k, x))) {
        return invalid("frames(" + std::to_string(k) + ", " + std::to_string(x) + ") (frame " + std::to_string(k) +
                       ", vertex " + std::to_string(x / 3) + ") is not finite");
      }
    }
  }
  return Status::Ok();
}


Sequence make_sequence(const PointMatrix& rest, const FaceMatrix& faces, const FrameMatrix& frames) {
  Sequence s;
  s.vertex_count = static_cast<int>(rest.rows());
  s.frame_count = static_cast<int>(frames.rows());
  s.rest = rest.cast<double>().transpose();
  // Both layouts: the error of a vertex under a part reads its whole trajectory, the fit of a
  // part in one frame reads that frame's positions of scattered vertices.
  s.positions = frames.cast<double>().transpose();
  s.trajectories.resize(3 * s.frame_count, s.vertex_count);
  for (int i = 0; i < s.vertex_count; ++i) {
    for (int k = 0; k < s.frame_count; ++k) {
      for (int c = 0; c < 3; ++c) s.trajectories(3 * k + c, i) = frames(k, 3 * i + c);
    }
  }
  s.rest_centroid = s.rest.rowwise().mean();
  s.frame_centroids = s.trajectories.rowwise().mean();
  s.adjacency = geometry::vertex_adjacency(s.vertex_count, faces);
  return s;
}

// Σ_k ‖R_k v̂ + t_k − v^k‖² of `vertex` under the motion of `part`.
double trajectory_error(const Sequence& s, const Motions& motions, int32_t part, int32_t vertex) {
  const double* motion = motions.col(part).data();
  const double* trajectory = s.trajectories.col(vertex).data();
  const Vector3d rest = s.rest.col(vertex);
  double sum = 0.0;
  for (int k = 0; k < s.frame_count; ++k) {
    const Eigen::Map<const Matrix3d> R(motion + kMotionStride * k);
    const Eigen::Map<const Vector3d> t(motion + kMotionStride * k + 9);
    const Eigen::Map<const Vector3d> v(trajectory + 3 * k);
    sum += (R * rest + t - v).squaredNorm();
  }
  return sum;
}

// Each vertex's error under its own part's motion.
Eigen::VectorXd own_errors(const Sequence& s, const Motions& motions, const std::vector<int32_t>& labels) {
  Eigen::VectorXd errors(s.vertex_count);
  parallel_for_chunks(s.vertex_count, 512, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      errors(i) = trajectory_error(s, motions, labels[static_cast<size_t>(i)], static_cast<int32_t>(i));
    }
  });
  return errors;
}

std::vector<std::vector<int32_t>> part_members(const std::vector<int32_t>& labels, int part_count) {
  std::vector<std::vector<int32_t>> members(static_cast<size_t>(part_count));
  for (size_t i = 0; i < labels.size(); ++i) members[static_cast<size_t>(labels[i])].push_back(static_cast<int32_t>(i));
  return members;
}

// SSDR §4.1 transformation update with hard labels: per part and frame, the least-squares rigid
// motion of the part's vertices from the rest pose (Kabsch via geometry::fit_rigid, which keeps a
// proper rotation for the degenerate parts: a single vertex, collinear vertices).
Motions fit_motions(const Sequence& s, const std::vector<int32_t>& labels, int part_count) {
  const std::vector<std::vector<int32_t>> members = part_members(labels, part_count);
  std::vector<Eigen::Matrix3Xd> from(static_cast<size_t>(part_count));
  for (size_t p = 0; p < members.size(); ++p) {
    from[p].resize(3, static_cast<Index>(members[p].size()));
    for (size_t n = 0; n < members[p].size(); ++n) from[p].col(static_cast<Index>(n)) = s.rest.col(members[p][n]);
  }
  Motions motions(kMotionStride * s.frame_count, part_count);
  // Frames are independent and equally expensive: one chunk of frames per thread.
  parallel_for_chunks(s.frame_count, 2, [&](int64_t begin, int64_t end) {
    Eigen::Matrix3Xd to;
    for (int64_t k = begin; k < end; ++k) {
      for (size_t p = 0; p < members.size(); ++p) {
        to.resize(3, static_cast<Index>(members[p].size()));
        for (size_t n = 0; n < members[p].size(); ++n) {
          to.col(static_cast<Index>(n)) = s.positions.col(k).segment<3>(3 * Index{members[p][n]});
        }
        const geometry::RigidTransform fit = geometry::fit_rigid(from[p], to);
        double* motion = motions.col(static_cast<Index>(p)).data() + kMotionStride * k;
        Eigen::Map<Matrix3d> rotation(motion);
        Eigen::Map<Vector3d> translation(motion + 9);
        rotation = fit.rotation;
        translation = fit.translation;
      }
    }
  });
  return motions;
}

// For every vertex, the part whose motion reproduces its trajectory best (SSDR §4.1's labelling
// step), among its current part and the parts adjacent to it over mesh edges: a part far away
// could only claim a stray piece, which the connectivity step would drop again, and limiting
// the candidates keeps the cost at a few trajectory errors per vertex whatever B is. A part with
// no neighbour (a piece of mesh of its own, or no faces at all) considers every part.
std::vector<int32_t> best_parts(const Sequence& s, const Motions& motions, const std::vector<int32_t>& labels,
                                int part_count) {
  std::vector<std::vector<int32_t>> candidates(static_cast<size_t>(part_count));
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    for (int32_t k = s.adjacency.begin(i); k < s.adjacency.end(i); ++k) {
      const int32_t a = labels[static_cast<size_t>(i)], b = labels[static_cast<size_t>(s.adjacency.at(k))];
      if (a != b) candidates[static_cast<size_t>(a)].push_back(b);
    }
  }
  for (int32_t p = 0; p < part_count; ++p) {
    std::vector<int32_t>& list = candidates[static_cast<size_t>(p)];
    if (list.empty()) {
      list.resize(static_cast<size_t>(part_count));
      std::iota(list.begin(), list.end(), 0);
    } else {
      list.push_back(p);
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
    }
  }
  std::vector<int32_t> best(static_cast<size_t>(s.vertex_count));
  parallel_for_chunks(s.vertex_count, 256, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int32_t vertex = static_cast<int32_t>(i);
      const int32_t own = labels[static_cast<size_t>(i)];
      int32_t best_part = own;
      double best_error = trajectory_error(s, motions, own, vertex);
      for (int32_t p : candidates[static_cast<size_t>(own)]) {
        if (p == own) continue;
        const double error = trajectory_error(s, motions, p, vertex);
        if (error < best_error) {
          best_error = error;
          best_part = p;
        }
      }
      best[static_cast<size_t>(i)] = best_part;
    }
  });
  return best;
}

// One entry of the flood queue: `part` offers to take `vertex` at trajectory error `error`.
// Ordered by error, then part and vertex so that the result is deterministic.
struct Offer {
  double error;
  int32_t part;
  int32_t vertex;
  bool operator>(const Offer& other) const {
    return std::tie(error, part, vertex) > std::tie(other.error, other.part, other.vertex);
  }
};

// The labelling step with spatial coherence: each vertex takes its best part (best_parts), then
// each part keeps only its largest connected piece over mesh edges, and the vertices cut loose
// are flooded from the kept pieces — the queue serves the offer of least error, so a loose
// vertex joins the best of the parts that reach it. Parts are connected afterwards, except that
// a piece of mesh no kept piece reaches keeps its best-part labels. A part that no vertex
// prefers vanishes (the caller splits another to restore the count).
std::vector<int32_t> assign_parts(const Sequence& s, const Motions& motions, const std::vector<int32_t>& current,
                                  int part_count) {
  const size_t V = static_cast<size_t>(s.vertex_count);
  const geometry::Adjacency& adjacency = s.adjacency;
  const std::vector<int32_t> best = best_parts(s, motions, current, part_count);

  // Connected pieces of each part; the largest (first found on a tie) is kept.
  std::vector<int32_t> piece(V, -1);
  std::vector<int> piece_size;
  std::vector<int32_t> kept_piece(static_cast<size_t>(part_count), -1);
  std::vector<int32_t> stack;
  for (size_t start = 0; start < V; ++start) {
    if (piece[start] >= 0) continue;
    const int32_t id = static_cast<int32_t>(piece_size.size());
    const int32_t part = best[start];
    int size = 0;
    piece[start] = id;
    stack.assign(1, static_cast<int32_t>(start));
    while (!stack.empty()) {
      const int32_t i = stack.back();
      stack.pop_back();
      ++size;
      for (int32_t k = adjacency.begin(i); k < adjacency.end(i); ++k) {
        const int32_t j = adjacency.at(k);
        if (piece[static_cast<size_t>(j)] >= 0 || best[static_cast<size_t>(j)] != part) continue;
        piece[static_cast<size_t>(j)] = id;
        stack.push_back(j);
      }
    }
    piece_size.push_back(size);
    int32_t& kept = kept_piece[static_cast<size_t>(part)];
    if (kept < 0 || size > piece_size[static_cast<size_t>(kept)]) kept = id;
  }
  std::vector<int32_t> labels(V, -1);
  for (size_t i = 0; i < V; ++i) {
    if (piece[i] == kept_piece[static_cast<size_t>(best[i])]) labels[i] = best[i];
  }

  // Flood the loose vertices from the kept pieces.
  std::priority_queue<Offer, std::vector<Offer>, std::greater<Offer>> queue;
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    if (labels[static_cast<size_t>(i)] >= 0) continue;
    for (int32_t k = adjacency.begin(i); k < adjacency.end(i); ++k) {
      const int32_t part = labels[static_cast<size_t>(adjacency.at(k))];
      if (part >= 0) queue.push({trajectory_error(s, motions, part, i), part, i});
    }
  }
  while (!queue.empty()) {
    const Offer offer = queue.top();
    queue.pop();
    if (labels[static_cast<size_t>(offer.vertex)] >= 0) continue;
    labels[static_cast<size_t>(offer.vertex)] = offer.part;
    for (int32_t k = adjacency.begin(offer.vertex); k < adjacency.end(offer.vertex); ++k) {
      const int32_t neighbour = adjacency.at(k);
      if (labels[static_cast<size_t>(neighbour)] >= 0) continue;
      queue.push({trajectory_error(s, motions, offer.part, neighbour), offer.part, neighbour});
    }
  }
  for (size_t i = 0; i < V; ++i) {
    if (labels[i] < 0) labels[i] = best[i];
  }
  return labels;
}

// Renumbers the parts that still own vertices to 0 … n-1, keeping their order; returns n.
int compact_parts(std::vector<int32_t>& labels, int part_count) {
  std::vector<int32_t> renumber(static_cast<size_t>(part_count), -1);
  for (int32_t label : labels) renumber[static_cast<size_t>(label)] = 0;
  int count = 0;
  for (int32_t& index : renumber) {
    if (index >= 0) index = count++;
  }
  for (int32_t& label : labels) label = renumber[static_cast<size_t>(label)];
  return count;
}

// Le & Deng 2014 (Dem Bones' split): adds up to target − part_count parts, one from each of the
// worst-fitting parts (largest Σ error) that have two vertices or more. The new part's seed is
// the vertex that is both far from its part's rest centroid and badly fitted — the score
// |(e_i − min e)(d_i − min d)| with e the RMS trajectory error and d the distance — typically a
// limb the part has not yet separated; the new part starts as the seed's one-ring within the
// part (a few vertices, enough for a Kabsch fit). Returns the new part count.
int split_parts(const Sequence& s, const Motions& motions, std::vector<int32_t>& labels, int part_count, int target) {
  const size_t P = static_cast<size_t>(part_count);
  const Eigen::VectorXd own = own_errors(s, motions, labels);
  std::vector<Vector3d, Eigen::aligned_allocator<Vector3d>> centroid(P, Vector3d::Zero());
  std::vector<int> size(P, 0);
  std::vector<double> total_error(P, 0.0);
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    const size_t p = static_cast<size_t>(labels[static_cast<size_t>(i)]);
    centroid[p] += s.rest.col(i);
    ++size[p];
    total_error[p] += own(i);
  }
  for (size_t p = 0; p < P; ++p) {
    if (size[p] > 0) centroid[p] /= size[p];
  }
  Eigen::VectorXd e = own.cwiseSqrt(), d(s.vertex_count);
  std::vector<double> min_e(P, INFINITY), min_d(P, INFINITY);
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    const size_t p = static_cast<size_t>(labels[static_cast<size_t>(i)]);
    d(i) = (s.rest.col(i) - centroid[p]).norm();
    min_e[p] = std::min(min_e[p], e(i));
    min_d[p] = std::min(min_d[p], d(i));
  }
  std::vector<int32_t> seeds(P, -1);
  std::vector<double> best_score(P, -1.0);
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    const size_t p = static_cast<size_t>(labels[static_cast<size_t>(i)]);
    const double score = std::abs((e(i) - min_e[p]) * (d(i) - min_d[p]));
    if (score > best_score[p]) {
      best_score[p] = score;
      seeds[p] = i;
    }
  }
  std::vector<int32_t> candidates;
  for (size_t p = 0; p < P; ++p) {
    if (size[p] >= 2) candidates.push_back(static_cast<int32_t>(p));
  }
  std::stable_sort(candidates.begin(), candidates.end(), [&](int32_t a, int32_t b) {
    return total_error[static_cast<size_t>(a)] > total_error[static_cast<size_t>(b)];
  });
  const size_t split_count = std::min(candidates.size(), static_cast<size_t>(std::max(0, target - part_count)));
  int count = part_count;
  for (size_t n = 0; n < split_count; ++n) {
    const int32_t p = candidates[n];
    const int32_t seed = seeds[static_cast<size_t>(p)];
    const int32_t created = count++;
    std::vector<int32_t> ring{seed};
    for (int32_t k = s.adjacency.begin(seed); k < s.adjacency.end(seed); ++k) {
      const int32_t neighbour = s.adjacency.at(k);
      if (labels[static_cast<size_t>(neighbour)] == p) ring.push_back(neighbour);
    }
    // The part must keep a vertex: when the ring is all of it, split off the seed alone.
    if (static_cast<int>(ring.size()) == size[static_cast<size_t>(p)]) ring.resize(1);
    for (int32_t i : ring) labels[static_cast<size_t>(i)] = created;
  }
  return count;
}

// Last resort when assignment keeps losing parts (B close to #V): the largest part gives up one
// vertex as a new part — a leaf of a breadth-first tree of the part over mesh edges, so that
// what remains stays connected.
void split_off_leaf(const Sequence& s, std::vector<int32_t>& labels, int part_count) {
  std::vector<int> size(static_cast<size_t>(part_count), 0);
  for (int32_t label : labels) ++size[static_cast<size_t>(label)];
  const int32_t largest = static_cast<int32_t>(std::max_element(size.begin(), size.end()) - size.begin());
  assert(size[static_cast<size_t>(largest)] >= 2);
  const int32_t start = static_cast<int32_t>(std::find(labels.begin(), labels.end(), largest) - labels.begin());
  std::vector<char> seen(labels.size(), 0);
  std::queue<int32_t> queue;
  queue.push(start);
  seen[static_cast<size_t>(start)] = 1;
  int32_t last = start;
  while (!queue.empty()) {
    last = queue.front();
    queue.pop();
    for (int32_t k = s.adjacency.begin(last); k < s.adjacency.end(last); ++k) {
      const int32_t neighbour = s.adjacency.at(k);
      if (seen[static_cast<size_t>(neighbour)] || labels[static_cast<size_t>(neighbour)] != largest) continue;
      seen[static_cast<size_t>(neighbour)] = 1;
      queue.push(neighbour);
    }
  }
  if (last == start) {
    // The start vertex is alone in its piece of mesh: any other vertex of the part will do.
    for (size_t i = 0; i < labels.size(); ++i) {
      if (labels[i] == largest && static_cast<int32_t>(i) != start) last = static_cast<int32_t>(i);
    }
  }
  labels[static_cast<size_t>(last)] = part_count;
}

// A partition into B connected parts with the motions fitted to it.
struct Partition {
  std::vector<int32_t> labels;  // #V, parts 0 … B-1
  Motions motions;
  double error = INFINITY;  // Σ over vertices and frames of the squared residual
  int iterations = 0;       // refinement iterations that produced it
};

// SSDR §4.1 iterations: reassign the vertices under the current motions (assign_parts) and
// refit the motions, until no vertex changes part, or the best error has improved by less than
// options.tolerance for three iterations in a row, or options.iterations have run. Parts that
// vanish are split off again. The connectivity step can raise the error, so the result is the
// best connected B-part state seen. `connected`: whether `labels` already has connected parts.
Partition refine(const Sequence& s, std::vector<int32_t> labels, int parts, bool connected,
                 const SegmentationOptions& options) {
  const int B = options.bone_count;
  Motions motions = fit_motions(s, labels, parts);
  Partition best;
  const auto keep_if_best = [&] {
    if (parts != B || !connected) return;
    const double error = own_errors(s, motions, labels).sum();
    if (error < best.error) {
      best.error = error;
      best.labels = labels;
      best.motions = motions;
    }
  };
  keep_if_best();
  constexpr int kPatience = 3;
  int iterations = 0, stalled = 0;
  while (iterations < options.iterations) {
    ++iterations;
    std::vector<int32_t> assigned = assign_parts(s, motions, labels, parts);
    const int assigned_parts = compact_parts(assigned, parts);
    const bool changed = assigned != labels || assigned_parts != parts;
    labels = std::move(assigned);
    parts = assigned_parts;
    connected = true;
    motions = fit_motions(s, labels, parts);
    if (parts < B) {
      parts = split_parts(s, motions, labels, parts, B);
      connected = false;
      motions = fit_motions(s, labels, parts);
    }
    const double previous_best = best.error;
    keep_if_best();
    if (!changed) break;
    stalled = best.error > (1.0 - options.tolerance) * previous_best ? stalled + 1 : 0;
    if (stalled >= kPatience) break;
  }
  if (best.labels.empty()) {
    // No connected B-part state (iterations = 0 right after a split, or B close to #V): assign
    // once more, then split off single vertices until there are B parts.
    if (!connected) {
      labels = assign_parts(s, motions, labels, parts);
      parts = compact_parts(labels, parts);
    }
    while (parts < B) split_off_leaf(s, labels, parts++);
    best.motions = fit_motions(s, labels, parts);
    best.error = own_errors(s, best.motions, labels).sum();
    best.labels = std::move(labels);
  }
  best.iterations = iterations;
  return best;
}

// The labels with the two adjacent parts merged whose union one rigid motion fits with the
// least increase of the total error (ties: the first pair in index order).
std::vector<int32_t> merge_cheapest_pair(const Sequence& s, const std::vector<int32_t>& labels, int part_count) {
  std::vector<std::pair<int32_t, int32_t>> pairs;
  for (int32_t i = 0; i < s.vertex_count; ++i) {
    for (int32_t k = s.adjacency.begin(i); k < s.adjacency.end(i); ++k) {
      const int32_t a = labels[static_cast<size_t>(i)], b = labels[static_cast<size_t>(s.adjacency.at(k))];
      if (a < b) pairs.emplace_back(a, b);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  std::vector<int32_t> merged = labels;
  if (pairs.empty()) {
    // No two parts touch (a point set, or every part a piece of mesh): merge the first two.
    for (int32_t& label : merged) label = label == 1 ? 0 : label;
    return merged;
  }
  const std::vector<std::vector<int32_t>> members = part_members(labels, part_count);
  const Motions motions = fit_motions(s, labels, part_count);
  const Eigen::VectorXd own = own_errors(s, motions, labels);
  std::vector<double> increase(pairs.size());
  parallel_for_chunks(static_cast<int64_t>(pairs.size()), 1, [&](int64_t begin, int64_t end) {
    Eigen::Matrix3Xd from, to;
    Motions joint(kMotionStride * s.frame_count, 1);
    for (int64_t n = begin; n < end; ++n) {
      const auto [a, b] = pairs[static_cast<size_t>(n)];
      std::vector<int32_t> both = members[static_cast<size_t>(a)];
      both.insert(both.end(), members[static_cast<size_t>(b)].begin(), members[static_cast<size_t>(b)].end());
      from.resize(3, static_cast<Index>(both.size()));
      to.resize(3, static_cast<Index>(both.size()));
      for (size_t m = 0; m < both.size(); ++m) from.col(static_cast<Index>(m)) = s.rest.col(both[m]);
      for (int k = 0; k < s.frame_count; ++k) {
        for (size_t m = 0; m < both.size(); ++m) {
          to.col(static_cast<Index>(m)) = s.positions.col(k).segment<3>(3 * Index{both[m]});
        }
        const geometry::RigidTransform fit = geometry::fit_rigid(from, to);
        joint.block<9, 1>(kMotionStride * k, 0) = fit.rotation.reshaped();
        joint.block<3, 1>(kMotionStride * k + 9, 0) = fit.translation;
      }
      double delta = 0.0;
      for (int32_t i : both) delta += trajectory_error(s, joint, 0, i) - own(i);
      increase[static_cast<size_t>(n)] = delta;
    }
  });
  const auto [a, b] = pairs[static_cast<size_t>(std::min_element(increase.begin(), increase.end()) - increase.begin())];
  for (int32_t& label : merged) label = label == b ? a : label;
  return merged;
}

// The bone tree over the parts and the numbering that puts parents first.
struct Hierarchy {
  std::vector<int32_t> bone_of_part;  // P: bone index 1 … P
  std::vector<int32_t> parent_part;   // P: the parent part, or -1 for a child of bone 0
  std::vector<int32_t> parents;       // P + 1: φ by bone
};

// Maximum spanning tree of part adjacency (weight: mesh edges across the shared boundary), so
// that parts joined by a wide boundary — a limb and the body it hangs from — are parent and
// child rather than parts that merely touch at a corner. Each tree is rooted at its median part
// (least Σ size · hops), and bones are numbered breadth-first from the roots.
Hierarchy build_hierarchy(const geometry::Adjacency& adjacency, const std::vector<int32_t>& labels, int part_count) {
  const size_t P = static_cast<size_t>(part_count);
  std::vector<int> size(P, 0);
  for (int32_t label : labels) ++size[static_cast<size_t>(label)];
  std::map<std::pair<int32_t, int32_t>, int> boundary;
  for (int32_t i = 0; i + 1 < static_cast<int32_t>(adjacency.offsets.size()); ++i) {
    for (int32_t k = adjacency.begin(i); k < adjacency.end(i); ++k) {
      const int32_t j = adjacency.at(k);
      const int32_t a = labels[static_cast<size_t>(i)], b = labels[static_cast<size_t>(j)];
      if (i < j && a != b) ++boundary[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::vector<std::pair<std::pair<int32_t, int32_t>, int>> edges(boundary.begin(), boundary.end());
  std::stable_sort(edges.begin(), edges.end(), [](const auto& x, const auto& y) { return x.second > y.second; });

  // Kruskal with union–find.
  std::vector<int32_t> set(P);
  std::iota(set.begin(), set.end(), 0);
  const auto find = [&](int32_t x) {
    while (set[static_cast<size_t>(x)] != x) {
      set[static_cast<size_t>(x)] = set[static_cast<size_t>(set[static_cast<size_t>(x)])];  // path halving
      x = set[static_cast<size_t>(x)];
    }
    return x;
  };
  std::vector<std::vector<int32_t>> tree(P);
  for (const auto& [pair, weight] : edges) {
    const int32_t a = find(pair.first), b = find(pair.second);
    if (a == b) continue;
    set[static_cast<size_t>(a)] = b;
    tree[static_cast<size_t>(pair.first)].push_back(pair.second);
    tree[static_cast<size_t>(pair.second)].push_back(pair.first);
  }
  // Children in order of size (largest first), then index.
  for (auto& neighbours : tree) {
    std::sort(neighbours.begin(), neighbours.end(), [&](int32_t a, int32_t b) {
      return std::make_pair(-size[static_cast<size_t>(a)], a) < std::make_pair(-size[static_cast<size_t>(b)], b);
    });
  }

  // Breadth-first hop counts from `root` within its tree; visits the tree in order.
  std::vector<int32_t> hops(P, -1), order;
  const auto breadth_first = [&](int32_t root) {
    order.clear();
    order.push_back(root);
    hops[static_cast<size_t>(root)] = 0;
    for (size_t n = 0; n < order.size(); ++n) {
      const int32_t p = order[n];
      for (int32_t q : tree[static_cast<size_t>(p)]) {
        if (hops[static_cast<size_t>(q)] >= 0) continue;
        hops[static_cast<size_t>(q)] = hops[static_cast<size_t>(p)] + 1;
        order.push_back(q);
      }
    }
  };

  // The trees of the forest, largest first, each rooted at its median part.
  std::vector<char> placed(P, 0);
  std::vector<std::pair<int64_t, int32_t>> roots;  // (−total size, root)
  for (int32_t p = 0; p < part_count; ++p) {
    if (placed[static_cast<size_t>(p)]) continue;
    breadth_first(p);
    const std::vector<int32_t> members = order;
    int64_t total = 0;
    for (int32_t q : members) {
      placed[static_cast<size_t>(q)] = 1;
      total += size[static_cast<size_t>(q)];
      hops[static_cast<size_t>(q)] = -1;
    }
    int32_t root = members.front();
    int64_t best_cost = INT64_MAX;
    for (int32_t r : members) {
      breadth_first(r);
      int64_t cost = 0;
      for (int32_t q : order) cost += int64_t{size[static_cast<size_t>(q)]} * hops[static_cast<size_t>(q)];
      for (int32_t q : order) hops[static_cast<size_t>(q)] = -1;
      const bool better =
          cost < best_cost ||
          (cost == best_cost && (size[static_cast<size_t>(r)] > size[static_cast<size_t>(root)] ||
                                 (size[static_cast<size_t>(r)] == size[static_cast<size_t>(root)] && r < root)));
      if (better) {
        best_cost = cost;
        root = r;
      }
    }
    roots.emplace_back(-total, root);
  }
  std::sort(roots.begin(), roots.end());

  Hierarchy hierarchy;
  hierarchy.bone_of_part.assign(P, -1);
  hierarchy.parent_part.assign(P, -1);
  hierarchy.parents.assign(P + 1, 0);
  hierarchy.parents[0] = -1;
  int32_t next_bone = 1;
  for (const auto& [negative_total, root] : roots) {
    breadth_first(root);
    for (int32_t p : order) {
      hierarchy.bone_of_part[static_cast<size_t>(p)] = next_bone++;
      for (int32_t q : tree[static_cast<size_t>(p)]) {
        if (hops[static_cast<size_t>(q)] == hops[static_cast<size_t>(p)] + 1) {
          hierarchy.parent_part[static_cast<size_t>(q)] = p;
        }
      }
    }
  }
  for (size_t p = 0; p < P; ++p) {
    const int32_t parent = hierarchy.parent_part[p];
    hierarchy.parents[static_cast<size_t>(hierarchy.bone_of_part[p])] =
        parent < 0 ? 0 : hierarchy.bone_of_part[static_cast<size_t>(parent)];
  }
  return hierarchy;
}

// True when the points span more than a line: the middle principal extent is above 1e-3 of
// the largest (a sliver that thin would leave the twist of a core-vertex fit to rounding).
bool spans_plane(const Eigen::Matrix3Xd& rest, const std::vector<int32_t>& vertices) {
  if (vertices.size() < 3) return false;
  Vector3d mean = Vector3d::Zero();
  for (int32_t i : vertices) mean += rest.col(i);
  mean /= static_cast<double>(vertices.size());
  Matrix3d covariance = Matrix3d::Zero();
  for (int32_t i : vertices) {
    const Vector3d x = rest.col(i) - mean;
    covariance.noalias() += x * x.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Matrix3d> solver;
  solver.computeDirect(covariance, Eigen::EigenvaluesOnly);
  const Vector3d eigenvalues = solver.eigenvalues();  // ascending
  return eigenvalues(2) > 0.0 && eigenvalues(1) > 1e-6 * eigenvalues(2);
}

}  // namespace

Result<RigidSegmentation> segment_rigid_parts(const PointMatrix& rest, const FaceMatrix& faces,
                                              const FrameMatrix& frames, const SegmentationOptions& options) {
  // 1. Validate, and lay the sequence out per vertex in double.
  ANIMSPACE_RETURN_IF_ERROR(validate_inputs(rest, faces, frames, options));
  const Sequence s = make_sequence(rest, faces, frames);
  const int V = s.vertex_count, F = s.frame_count, B = options.bone_count;

  // 2. Initialise (Le & Deng 2014): one part, then rounds of splitting the worst-fitting parts
  //    (at most doubling the count) each followed by a few fit/assign iterations.
  std::vector<int32_t> labels(static_cast<size_t>(V), 0);
  int parts = 1;
  bool connected = true;  // the labels came out of assign_parts, so parts are connected
  // Doubling reaches B in ⌈log₂ B⌉ rounds; the margin covers parts that vanish on the way.
  const int max_rounds = 2 * static_cast<int>(std::ceil(std::log2(B))) + 8;
  for (int round = 0; parts < B && round < max_rounds; ++round) {
    parts = split_parts(s, fit_motions(s, labels, parts), labels, parts, B);
    connected = false;
    for (int iteration = 0; iteration < options.init_iterations; ++iteration) {
      labels = assign_parts(s, fit_motions(s, labels, parts), labels, parts);
      parts = compact_parts(labels, parts);
      connected = true;
    }
  }

  // 3. Refine (SSDR §4.1).
  Partition partition = refine(s, std::move(labels), parts, connected, options);
  int iterations = partition.iterations;

  // 4. Leave local optima by merge–split moves (bisecting k-means style): the two adjacent
  //    parts that one motion fits with the least extra error become one, the worst part is
  //    split, and the result is refined; kept only when the total error drops.
  for (int attempt = 0; attempt < options.merge_split_attempts && B >= 2; ++attempt) {
    std::vector<int32_t> candidate = merge_cheapest_pair(s, partition.labels, B);
    int candidate_parts = compact_parts(candidate, B);
    candidate_parts = split_parts(s, fit_motions(s, candidate, candidate_parts), candidate, candidate_parts, B);
    Partition refined = refine(s, std::move(candidate), candidate_parts, false, options);
    iterations += refined.iterations;
    if (!(refined.error < (1.0 - options.tolerance) * partition.error)) break;
    partition = std::move(refined);
  }
  labels = std::move(partition.labels);
  const Motions& motions = partition.motions;
  parts = B;

  // 5. Skeleton: the tree over the parts, bones numbered parents first.
  const Hierarchy hierarchy = build_hierarchy(s.adjacency, labels, parts);
  RigidSegmentation result;
  result.parents = hierarchy.parents;
  result.iterations = iterations;
  result.labels.resize(static_cast<size_t>(V));
  for (int i = 0; i < V; ++i) {
    result.labels[static_cast<size_t>(i)] = hierarchy.bone_of_part[static_cast<size_t>(labels[static_cast<size_t>(i)])];
  }

  // 6. Per-vertex fit and the per-frame transforms of each bone.
  const Eigen::VectorXd own = own_errors(s, motions, labels);
  result.fit_error = (own / F).cwiseSqrt();
  result.rms_error = std::sqrt(own.sum() / (static_cast<double>(V) * F));
  result.transforms.assign(static_cast<size_t>(F), TransformList(static_cast<size_t>(B) + 1, Transform::Identity()));
  for (int p = 0; p < parts; ++p) {
    const size_t bone = static_cast<size_t>(hierarchy.bone_of_part[static_cast<size_t>(p)]);
    for (int k = 0; k < F; ++k) {
      const double* motion = motions.col(p).data() + kMotionStride * k;
      result.transforms[static_cast<size_t>(k)][bone] =
          make_transform(Eigen::Map<const Matrix3d>(motion), Eigen::Map<const Vector3d>(motion + 9));
    }
  }

  // 7. Initial joint positions u_j (§4.1.4): the middle of the boundary with the parent part.
  result.joint_positions = Eigen::MatrixX3d::Zero(B + 1, 3);
  Eigen::VectorXd joint_weight = Eigen::VectorXd::Zero(B + 1);
  for (int32_t i = 0; i < V; ++i) {
    for (int32_t k = s.adjacency.begin(i); k < s.adjacency.end(i); ++k) {
      const int32_t j = s.adjacency.at(k);
      if (j < i) continue;
      const int32_t a = labels[static_cast<size_t>(i)], b = labels[static_cast<size_t>(j)];
      int32_t child = -1;
      if (hierarchy.parent_part[static_cast<size_t>(a)] == b) child = a;
      if (hierarchy.parent_part[static_cast<size_t>(b)] == a) child = b;
      if (child < 0) continue;
      const int32_t bone = hierarchy.bone_of_part[static_cast<size_t>(child)];
      result.joint_positions.row(bone) += 0.5 * (s.rest.col(i) + s.rest.col(j)).transpose();
      joint_weight(bone) += 1.0;
    }
  }
  for (int32_t i = 0; i < V; ++i) {
    const int32_t p = labels[static_cast<size_t>(i)];
    if (hierarchy.parent_part[static_cast<size_t>(p)] >= 0) continue;
    const int32_t bone = hierarchy.bone_of_part[static_cast<size_t>(p)];
    result.joint_positions.row(bone) += s.rest.col(i).transpose();
    joint_weight(bone) += 1.0;
  }
  for (int j = 1; j <= B; ++j) {
    assert(joint_weight(j) > 0.0);
    result.joint_positions.row(j) /= joint_weight(j);
  }

  // 8. Core vertices: away from other parts (rings counted over mesh edges from the boundary)
  //    and fitting well; relaxed step by step until 3 non-collinear vertices remain.
  std::vector<int> ring(static_cast<size_t>(V), INT_MAX);
  std::queue<int32_t> queue;
  for (int32_t i = 0; i < V; ++i) {
    for (int32_t k = s.adjacency.begin(i); k < s.adjacency.end(i); ++k) {
      if (labels[static_cast<size_t>(s.adjacency.at(k))] != labels[static_cast<size_t>(i)]) {
        ring[static_cast<size_t>(i)] = 1;
        queue.push(i);
        break;
      }
    }
  }
  while (!queue.empty()) {
    const int32_t i = queue.front();
    queue.pop();
    for (int32_t k = s.adjacency.begin(i); k < s.adjacency.end(i); ++k) {
      const int32_t j = s.adjacency.at(k);
      if (labels[static_cast<size_t>(j)] != labels[static_cast<size_t>(i)] || ring[static_cast<size_t>(j)] != INT_MAX)
        continue;
      ring[static_cast<size_t>(j)] = ring[static_cast<size_t>(i)] + 1;
      queue.push(j);
    }
  }
  const double diagonal = (s.rest.rowwise().maxCoeff() - s.rest.rowwise().minCoeff()).norm();
  const std::vector<std::vector<int32_t>> members = part_members(labels, parts);
  result.core_vertices.assign(static_cast<size_t>(B) + 1, {});
  for (int p = 0; p < parts; ++p) {
    const std::vector<int32_t>& part = members[static_cast<size_t>(p)];
    std::vector<double> errors;
    for (int32_t i : part) errors.push_back(result.fit_error(i));
    std::nth_element(errors.begin(), errors.begin() + static_cast<std::ptrdiff_t>(errors.size() / 2), errors.end());
    const double threshold = options.core_error_factor * errors[errors.size() / 2] + 1e-6 * diagonal;
    std::vector<int32_t> core;
    const auto select = [&](int rings, bool filter_error) {
      core.clear();
      for (int32_t i : part) {
        if (ring[static_cast<size_t>(i)] > rings && (!filter_error || result.fit_error(i) <= threshold))
          core.push_back(i);
      }
      return spans_plane(s.rest, core);
    };
    bool found = false;
    for (int filter = 1; filter >= 0 && !found; --filter) {
      for (int rings = options.core_erosion_rings; rings >= 0 && !found; --rings) found = select(rings, filter == 1);
    }
    if (!found) core = part;
    result.core_vertices[static_cast<size_t>(hierarchy.bone_of_part[static_cast<size_t>(p)])] = std::move(core);
  }
  return result;
}

}  // namespace animspace::animation_space
