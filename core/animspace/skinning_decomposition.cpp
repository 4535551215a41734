#include "core/animspace/skinning_decomposition.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <string>

#include "core/animspace/bone_motions.h"
#include "core/common/parallel.h"
#include "core/common/timing.h"
#include "core/geometry/edges.h"

namespace animspace::animation_space {
namespace {

Error invalid(const std::string& message) {
  return make_error(ErrorCode::kInvalidArgument, "decompose_skinning: " + message);
}

Status check_inputs(const PointMatrix& rest, const FaceMatrix& faces, const FrameMatrix& frames,
                    const std::vector<int32_t>& labels, const std::vector<TransformList>& motions,
                    const DecompositionOptions& options) {
  const Eigen::Index V = rest.rows();
  if (V < 1) return invalid("rest must have at least 1 vertex");
  if (!rest.allFinite()) return invalid("rest has a non-finite coordinate");
  if (frames.rows() < 1 || frames.cols() != 3 * V) {
    return invalid("frames must be F × 3V = F × " + std::to_string(3 * V) + " with F ≥ 1, got " +
                   std::to_string(frames.rows()) + " × " + std::to_string(frames.cols()));
  }
  if (!frames.allFinite()) return invalid("frames hold a non-finite coordinate");
  if ((faces.array() < 0).any() || (faces.array() >= V).any()) {
    return invalid("faces index a vertex outside [0, " + std::to_string(V) + ")");
  }
  if (static_cast<Eigen::Index>(motions.size()) != frames.rows()) {
    return invalid("initial_motions must hold one list per frame (" + std::to_string(frames.rows()) + "), got " +
                   std::to_string(motions.size()));
  }
  const size_t bones = motions.front().size();
  if (bones < 2) return invalid("initial_motions need the root and at least one bone, got " + std::to_string(bones));
  for (size_t f = 0; f < motions.size(); ++f) {
    if (motions[f].size() != bones) {
      return invalid("initial_motions[" + std::to_string(f) + "] has " + std::to_string(motions[f].size()) +
                     " bones, expected " + std::to_string(bones));
    }
    for (const Transform& M : motions[f]) {
      if (!M.allFinite()) return invalid("initial_motions[" + std::to_string(f) + "] has a non-finite transform");
    }
  }
  if (static_cast<Eigen::Index>(labels.size()) != V) {
    return invalid("labels must hold one bone per vertex (" + std::to_string(V) + "), got " + std::to_string(labels.size()));
  }
  for (size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] < 1 || static_cast<size_t>(labels[i]) >= bones) {
      return invalid("labels[" + std::to_string(i) + "] must be in [1, " + std::to_string(bones) + "), got " +
                     std::to_string(labels[i]));
    }
  }
  if (options.iterations < 0) return invalid("options.iterations must be ≥ 0, got " + std::to_string(options.iterations));
  if (!(options.tolerance >= 0)) return invalid("options.tolerance must be ≥ 0");
  if (options.motion_sweeps < 1) return invalid("options.motion_sweeps must be ≥ 1, got " + std::to_string(options.motion_sweeps));
  if (options.candidate_hops < 1) {
    return invalid("options.candidate_hops must be ≥ 1, got " + std::to_string(options.candidate_hops));
  }
  if (options.weights.max_influences < 1) {
    return invalid("options.weights.max_influences must be ≥ 1, got " + std::to_string(options.weights.max_influences));
  }
  if (!(options.weights.smoothness >= 0) || !std::isfinite(options.weights.smoothness)) {
    return invalid("options.weights.smoothness must be finite and ≥ 0");
  }
  return Status::Ok();
}

// The bone with the largest weight on each vertex.
std::vector<int32_t> dominant_bones(const SkinningWeights& weights) {
  std::vector<int32_t> out(static_cast<size_t>(weights.influences.vertex_count()), 0);
  for (int i = 0; i < weights.influences.vertex_count(); ++i) {
    double best = -1;
    for (int k = weights.influences.begin(i); k < weights.influences.end(i); ++k) {
      if (weights.weights(k) > best) {
        best = weights.weights(k);
        out[static_cast<size_t>(i)] = weights.influences.bones[static_cast<size_t>(k)];
      }
    }
  }
  return out;
}

// See the file comment of the header: own bones, the dominant bone and the parts within `hops`
// steps of it in the graph of touching parts.
InfluenceSets candidate_bones(const SkinningWeights& weights, const geometry::Adjacency& adjacency, int bones,
                              int hops) {
  const std::vector<int32_t> dominant = dominant_bones(weights);
  std::vector<std::set<int32_t>> touching(static_cast<size_t>(bones));
  for (int i = 0; i < static_cast<int>(dominant.size()); ++i) {
    for (int e = adjacency.begin(i); e < adjacency.end(i); ++e) {
      const int32_t a = dominant[static_cast<size_t>(i)], b = dominant[static_cast<size_t>(adjacency.at(e))];
      if (a != b) touching[static_cast<size_t>(a)].insert(b);
    }
  }
  std::vector<std::set<int32_t>> reach(static_cast<size_t>(bones));
  for (int j = 0; j < bones; ++j) {
    std::set<int32_t>& near = reach[static_cast<size_t>(j)];
    near.insert(j);
    for (int hop = 0; hop < hops; ++hop) {
      std::set<int32_t> next = near;
      for (int32_t b : near) next.insert(touching[static_cast<size_t>(b)].begin(), touching[static_cast<size_t>(b)].end());
      near = std::move(next);
    }
  }
  InfluenceSets out;
  for (int i = 0; i < weights.influences.vertex_count(); ++i) {
    std::set<int32_t> set(reach[static_cast<size_t>(dominant[static_cast<size_t>(i)])]);
    for (int k = weights.influences.begin(i); k < weights.influences.end(i); ++k) {
      set.insert(weights.influences.bones[static_cast<size_t>(k)]);
    }
    set.erase(0);
    out.bones.insert(out.bones.end(), set.begin(), set.end());
    out.offsets.push_back(static_cast<int32_t>(out.bones.size()));
  }
  return out;
}

MotionSkinning as_motion_skinning(const SkinningWeights& weights, const Eigen::Matrix3Xd& rest) {
  MotionSkinning out;
  out.influences = weights.influences;
  out.y.resize(4, weights.influences.influence_count());
  for (int i = 0; i < weights.influences.vertex_count(); ++i) {
    for (int k = weights.influences.begin(i); k < weights.influences.end(i); ++k) {
      out.y.col(k) << weights.weights(k) * rest.col(i), weights.weights(k);
    }
  }
  return out;
}

// Updates every frame's motions (in parallel over frames) and returns the RMS error.
double update_motions(const SkinningWeights& weights, const Eigen::Matrix3Xd& rest,
                      const std::vector<Eigen::Matrix3Xd>& frames, std::vector<TransformList>& motions, int sweeps) {
  const MotionSkinning skinning = as_motion_skinning(weights, rest);
  const BoneInfluences by_bone = bone_influences(skinning.influences, static_cast<int>(motions.front().size()));
  std::vector<double> squared(frames.size(), 0.0);
  parallel_for_chunks(static_cast<int64_t>(frames.size()), 1, [&](int64_t begin, int64_t end) {
    for (int64_t f = begin; f < end; ++f) {
      squared[static_cast<size_t>(f)] =
          refine_motions(skinning, by_bone, frames[static_cast<size_t>(f)], motions[static_cast<size_t>(f)], sweeps);
    }
  });
  double total = 0;
  for (double s : squared) total += s;
  return std::sqrt(total / (static_cast<double>(frames.size()) * static_cast<double>(rest.cols())));
}

}  // namespace

Result<SkinningDecomposition> decompose_skinning(const PointMatrix& rest_points, const FaceMatrix& faces,
                                                 const FrameMatrix& frame_rows, const std::vector<int32_t>& labels,
                                                 std::vector<TransformList> initial_motions,
                                                 const DecompositionOptions& options, DecompositionReport* report,
                                                 const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  ANIMSPACE_RETURN_IF_ERROR(check_inputs(rest_points, faces, frame_rows, labels, initial_motions, options));
  DecompositionReport local;
  DecompositionReport& out = report ? *report : local;
  out = DecompositionReport{};

  const int vertices = static_cast<int>(rest_points.rows());
  const int bones = static_cast<int>(initial_motions.front().size());
  const Eigen::Matrix3Xd rest = rest_points.transpose().cast<double>();
  std::vector<Eigen::Matrix3Xd> frames;
  frames.reserve(static_cast<size_t>(frame_rows.rows()));
  for (Eigen::Index f = 0; f < frame_rows.rows(); ++f) frames.push_back(frame_points(frame_rows.row(f)));
  const double scale = (rest.rowwise().maxCoeff() - rest.rowwise().minCoeff()).maxCoeff();
  const geometry::Adjacency adjacency = geometry::vertex_adjacency(vertices, faces);

  SkinningDecomposition result;
  result.motions = std::move(initial_motions);
  for (TransformList& frame : result.motions) frame[0] = Transform::Identity();
  // Hard skinning of the segmentation: every vertex wholly on its part's bone.
  result.weights.influences.offsets.resize(static_cast<size_t>(vertices) + 1);
  for (int i = 0; i <= vertices; ++i) result.weights.influences.offsets[static_cast<size_t>(i)] = i;
  result.weights.influences.bones = labels;
  result.weights.weights = Eigen::VectorXd::Ones(vertices);
  // The motions of the hard skinning are each part's rigid fit; one update makes them so even if
  // the initial motions came from elsewhere.
  result.rms = update_motions(result.weights, rest, frames, result.motions, 1);
  out.initial_rms = result.rms;

  // Near convergence the smoothness pull and the K-largest truncation can trade a little error
  // back; the best iterate is kept, and the loop ends at the first iteration that does not
  // improve on it by `tolerance`.
  report_progress(progress, "skinning decomposition", 0, options.iterations);
  SkinningDecomposition current = result;
  for (int iteration = 0; iteration < options.iterations; ++iteration) {
    const InfluenceSets candidates = candidate_bones(current.weights, adjacency, bones, options.candidate_hops);
    current.weights = solve_skinning_weights(rest, frames, current.motions, candidates, current.weights, adjacency,
                                             scale, options.weights);
    current.rms = update_motions(current.weights, rest, frames, current.motions, options.motion_sweeps);
    out.iterations.push_back({current.rms, seconds_since(start),
                              static_cast<double>(current.weights.influences.influence_count()) / vertices});
    report_progress(progress, "skinning decomposition", iteration + 1, options.iterations);
    const bool improved = current.rms < (1 - options.tolerance) * result.rms;
    if (current.rms < result.rms) result = current;
    if (!improved) {
      out.converged = true;
      break;
    }
  }
  out.seconds = seconds_since(start);
  return result;
}

}  // namespace animspace::animation_space
