#include "bench/lod_comparison.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>

#include <meshoptimizer.h>

#include "core/common/parallel.h"

namespace animspace::bench {

namespace as = animation_space;

lod::Points3d posed(const as::AnimationSpaceModel& model, const as::TransformList& G) {
  PointMatrix points;
  as::evaluate(model, G, points);
  return points.cast<double>();
}

double rest_diagonal(const as::AnimationSpaceModel& model) {
  const lod::Points3d rest = posed(model, model.skeleton.rest);
  return (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).norm();
}

as::AnimationSpaceModel subset(const as::AnimationSpaceModel& model, const std::vector<int32_t>& keep,
                               const std::vector<std::array<int32_t, 3>>& faces) {
  as::AnimationSpaceModel out;
  out.skeleton = model.skeleton;
  std::vector<int32_t> compact(static_cast<size_t>(model.vertex_count()), -1);
  std::vector<Eigen::Vector4d> columns;
  for (size_t k = 0; k < keep.size(); ++k) {
    const int v = keep[k];
    compact[static_cast<size_t>(v)] = static_cast<int32_t>(k);
    for (int i = model.influences.begin(v); i < model.influences.end(v); ++i) {
      out.influences.bones.push_back(model.influences.bones[static_cast<size_t>(i)]);
      columns.push_back(model.positions.col(i));
    }
    out.influences.offsets.push_back(static_cast<int32_t>(out.influences.bones.size()));
  }
  out.positions.resize(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) out.positions.col(static_cast<Eigen::Index>(k)) = columns[k];
  out.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) {
    for (int c = 0; c < 3; ++c)
      out.faces(static_cast<Eigen::Index>(f), c) = compact[static_cast<size_t>(faces[f][static_cast<size_t>(c)])];
  }
  return out;
}

Simplified meshoptimizer_rest(const as::AnimationSpaceModel& model, int target_vertices) {
  const auto start = std::chrono::steady_clock::now();
  const PointMatrix rest = posed(model, model.skeleton.rest).cast<float>();
  const std::vector<unsigned int> indices(model.faces.data(), model.faces.data() + model.faces.size());
  const double face_ratio = static_cast<double>(model.faces.rows()) / model.vertex_count();
  const size_t target_indices = 3 * static_cast<size_t>(std::lround(face_ratio * target_vertices));
  std::vector<unsigned int> out(indices.size());
  const size_t count = meshopt_simplify(out.data(), indices.data(), indices.size(), rest.data(),
                                        static_cast<size_t>(rest.rows()), sizeof(float) * 3, target_indices, 1e9f);
  std::vector<std::array<int32_t, 3>> faces;
  std::vector<uint8_t> used(static_cast<size_t>(model.vertex_count()), 0);
  for (size_t i = 0; i + 2 < count; i += 3) {
    faces.push_back({static_cast<int32_t>(out[i]), static_cast<int32_t>(out[i + 1]), static_cast<int32_t>(out[i + 2])});
    for (int c = 0; c < 3; ++c) used[out[i + static_cast<size_t>(c)]] = 1;
  }
  std::vector<int32_t> keep;
  for (int v = 0; v < model.vertex_count(); ++v) {
    if (used[static_cast<size_t>(v)]) keep.push_back(v);
  }
  Simplified simplified{subset(model, keep, faces), 0};
  simplified.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return simplified;
}

SurfaceError measure_across_poses(const as::AnimationSpaceModel& input, const as::AnimationSpaceModel& simplified,
                                  const std::vector<as::TransformList>& poses, double diagonal) {
  std::mutex mutex;
  double sum = 0, worst = 0;
  long count = 0;
  parallel_for_chunks(static_cast<int64_t>(poses.size()), 1, [&](int64_t begin, int64_t end) {
    double local_sum = 0, local_max = 0;
    long local_count = 0;
    for (int64_t p = begin; p < end; ++p) {
      const as::TransformList& G = poses[static_cast<size_t>(p)];
      const lod::SurfaceDistance surface(posed(simplified, G), simplified.faces);
      const lod::DistanceSummary s = lod::distances_to_surface(posed(input, G), surface);
      local_sum += s.sum_of_squares;
      local_max = std::max(local_max, s.max);
      local_count += s.count;
    }
    const std::lock_guard lock(mutex);
    sum += local_sum;
    worst = std::max(worst, local_max);
    count += local_count;
  });
  return {std::sqrt(sum / static_cast<double>(count)) / diagonal, worst / diagonal};
}

}  // namespace animspace::bench
