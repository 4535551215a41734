#include "core/illumination/surface_filter.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <utility>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "core/common/format.h"
#include "core/common/parallel.h"

namespace animspace::illumination {

namespace {

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

// A cell's key: 21 bits per axis (cells are counted from the surface's bounding box, so a key is
// only ambiguous past 2 million cells along one axis, which a radius from the point density
// cannot reach for fewer than ~10¹² points).
uint64_t cell_key(int64_t x, int64_t y, int64_t z) {
  return (static_cast<uint64_t>(x) << 42) | (static_cast<uint64_t>(y) << 21) | static_cast<uint64_t>(z);
}

}  // namespace

Status check_surface_filter_options(const SurfaceFilterOptions& options, const std::string& name) {
  if (options.neighbours < 0) {
    return invalid(name + ".neighbours must be ≥ 0 (0: no filter), got " + std::to_string(options.neighbours));
  }
  if (!(options.min_normal_cosine > -1 && options.min_normal_cosine <= 1)) {
    return invalid(name + ".min_normal_cosine must be in (−1, 1], got " + format_number(options.min_normal_cosine));
  }
  return Status::Ok();
}

Result<SurfaceFilter> surface_filter_precompute(const SurfaceMesh& surface, const SurfaceFilterOptions& options,
                                                const std::string& name) {
  ANIMSPACE_RETURN_IF_ERROR(check_surface_filter_options(options, name));
  SurfaceFilter filter;
  filter.options = options;
  if (!options.enabled()) return filter;
  const PointMatrix& V = surface.vertices;
  const long n = V.rows();
  if (n == 0) return filter;

  // The radius holding k points at the mean density N / A (double: the area is a sum of many
  // small triangles).
  double area = 0;
  for (long t = 0; t < surface.faces.rows(); ++t) {
    const Eigen::Vector3d a = V.row(surface.faces(t, 0)).transpose().cast<double>();
    const Eigen::Vector3d b = V.row(surface.faces(t, 1)).transpose().cast<double>();
    const Eigen::Vector3d c = V.row(surface.faces(t, 2)).transpose().cast<double>();
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  if (!(area > 0) || !std::isfinite(area)) {
    return invalid(name + ": the surface has no area (" + format_number(area) + " m²): no point density to size the "
                          "filter's radius from");
  }
  const double r = std::sqrt(options.neighbours * area / (M_PI * static_cast<double>(n)));
  filter.radius = r;
  filter.albedo = surface.albedo;

  // Points sorted by cell: each query looks up the 27 cells around its own.
  const Eigen::Vector3d lo = V.colwise().minCoeff().transpose().cast<double>();
  const auto cell_of = [&](long i) {
    const Eigen::Vector3d p = (V.row(i).transpose().cast<double>() - lo) / r;
    return Eigen::Matrix<int64_t, 3, 1>(static_cast<int64_t>(std::floor(p.x())), static_cast<int64_t>(std::floor(p.y())),
                                        static_cast<int64_t>(std::floor(p.z())));
  };
  std::vector<std::pair<uint64_t, int>> sorted(static_cast<size_t>(n));
  for (long i = 0; i < n; ++i) {
    const auto c = cell_of(i);
    sorted[static_cast<size_t>(i)] = {cell_key(c.x(), c.y(), c.z()), static_cast<int>(i)};
  }
  std::sort(sorted.begin(), sorted.end());

  const double two_sigma2 = 2 * (r / 2) * (r / 2);
  const double edge = std::exp(-r * r / two_sigma2);
  struct Entry {
    int j;
    float w;
    Eigen::Vector2f tangent;
  };
  std::vector<std::vector<Entry>> lists(static_cast<size_t>(n));
  parallel_for_chunks(n, 256, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const Eigen::Vector3d p = V.row(i).transpose().cast<double>();
      const Eigen::Vector3d normal = surface.normals.row(i).transpose().cast<double>();
      const auto c = cell_of(static_cast<long>(i));
      // Tangent axes of the point: any orthonormal pair ⟂ n (a fitted plane does not depend on
      // which).
      const Eigen::Vector3d t1 =
          (std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY()).cross(normal).normalized();
      const Eigen::Vector3d t2 = normal.cross(t1);
      auto& list = lists[static_cast<size_t>(i)];
      for (int64_t dx = -1; dx <= 1; ++dx) {
        for (int64_t dy = -1; dy <= 1; ++dy) {
          for (int64_t dz = -1; dz <= 1; ++dz) {
            if (c.x() + dx < 0 || c.y() + dy < 0 || c.z() + dz < 0) continue;
            const uint64_t key = cell_key(c.x() + dx, c.y() + dy, c.z() + dz);
            auto it = std::lower_bound(sorted.begin(), sorted.end(), std::make_pair(key, 0));
            for (; it != sorted.end() && it->first == key; ++it) {
              const int j = it->second;
              const double d2 = (V.row(j).transpose().cast<double>() - p).squaredNorm();
              if (d2 > r * r) continue;
              if (normal.dot(surface.normals.row(j).transpose().cast<double>()) < options.min_normal_cosine) continue;
              const double w = std::exp(-d2 / two_sigma2) - edge;
              const Eigen::Vector3d d = V.row(j).transpose().cast<double>() - p;
              if (w > 0) list.push_back({j, static_cast<float>(w), Eigen::Vector2d(d.dot(t1), d.dot(t2)).cast<float>() / static_cast<float>(r)});
            }
          }
        }
      }
      // The point itself always counts (weight 1 − e^{−2} at d = 0, also when its normal test
      // would fail by rounding), so every list is non-empty.
      if (std::none_of(list.begin(), list.end(), [&](const Entry& e) { return e.j == i; })) {
        list.push_back({static_cast<int>(i), static_cast<float>(1 - edge), Eigen::Vector2f::Zero()});
      }
    }
  });
  filter.offsets.resize(static_cast<size_t>(n) + 1);
  filter.offsets[0] = 0;
  for (long i = 0; i < n; ++i) {
    filter.offsets[static_cast<size_t>(i) + 1] = filter.offsets[static_cast<size_t>(i)] + static_cast<int64_t>(lists[static_cast<size_t>(i)].size());
  }
  filter.indices.reserve(static_cast<size_t>(filter.offsets.back()));
  filter.weights.reserve(static_cast<size_t>(filter.offsets.back()));
  if (options.linear) filter.tangent.reserve(static_cast<size_t>(filter.offsets.back()));
  for (auto& list : lists) {
    for (const Entry& e : list) {
      filter.indices.push_back(e.j);
      filter.weights.push_back(e.w);
      if (options.linear) filter.tangent.push_back(e.tangent);
    }
    std::vector<Entry>().swap(list);
  }
  return filter;
}

namespace {

// Ẽ_i ⊙ ρ_i for one point, reading the neighbours' radiance through value(j) (3 floats).
template <typename Value>
Eigen::Vector3f filtered_point(const SurfaceFilter& filter, int64_t i, const Value& value) {
  const bool linear = filter.options.linear;
  // Per channel: the weighted moments of (1, u, v) and of E against them; the mean uses only the
  // first.
  Eigen::Matrix3d moments[3] = {Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero()};
  Eigen::Vector3d sums[3] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  for (int64_t e = filter.offsets[static_cast<size_t>(i)]; e < filter.offsets[static_cast<size_t>(i) + 1]; ++e) {
    const int j = filter.indices[static_cast<size_t>(e)];
    const double w = filter.weights[static_cast<size_t>(e)];
    const float* L = value(j);
    const Eigen::Vector3d x = linear ? Eigen::Vector3d(1, filter.tangent[static_cast<size_t>(e)].x(),
                                                       filter.tangent[static_cast<size_t>(e)].y())
                                     : Eigen::Vector3d(1, 0, 0);
    for (int c = 0; c < 3; ++c) {
      const double rho = filter.albedo(j, c);
      if (rho > 0) {
        sums[c] += w * (L[c] / rho) * x;  // the neighbour's irradiance E_j
        if (linear) {
          moments[c].noalias() += w * x * x.transpose();
        } else {
          moments[c](0, 0) += w;
        }
      }
    }
  }
  Eigen::Vector3f out;
  for (int c = 0; c < 3; ++c) {
    const double rho = filter.albedo(i, c);
    double E = 0;
    if (rho > 0 && moments[c](0, 0) > 0) {
      E = sums[c][0] / moments[c](0, 0);
      if (linear) {
        // The plane's value at u = v = 0; the mean when the neighbours do not span the plane
        // (tangent coordinates are in units of r, so the moments are O(1) and the threshold is
        // scale-free).
        Eigen::FullPivLU<Eigen::Matrix3d> lu(moments[c] / moments[c](0, 0));
        lu.setThreshold(1e-6);
        if (lu.rank() == 3) E = lu.solve(sums[c] / moments[c](0, 0))[0];
      }
    }
    out[c] = static_cast<float>(rho * E);
  }
  return out;
}

}  // namespace

void surface_filter_apply(const SurfaceFilter& filter, const Eigen::VectorXf& frame, Eigen::VectorXf& out) {
  if (!filter.enabled()) {
    out = frame;
    return;
  }
  const long n = static_cast<long>(filter.offsets.size()) - 1;
  assert(frame.size() == 3 * n && filter.albedo.rows() == n);
  assert(&out != &frame);
  assert(!filter.options.linear || filter.tangent.size() == filter.indices.size());
  out.resize(3 * n);
  parallel_for_chunks(n, 1024, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      out.segment<3>(3 * i) = filtered_point(filter, i, [&](int j) { return frame.data() + 3 * static_cast<long>(j); });
    }
  });
}

std::vector<int> surface_filter_support(const SurfaceFilter& filter, const std::vector<int>& points) {
  std::vector<int> support;
  for (const int i : points) {
    if (!filter.enabled()) {
      support.push_back(i);
      continue;
    }
    for (int64_t e = filter.offsets[static_cast<size_t>(i)]; e < filter.offsets[static_cast<size_t>(i) + 1]; ++e) {
      support.push_back(filter.indices[static_cast<size_t>(e)]);
    }
  }
  std::sort(support.begin(), support.end());
  support.erase(std::unique(support.begin(), support.end()), support.end());
  return support;
}

void surface_filter_apply_at(const SurfaceFilter& filter, const std::vector<int>& points,
                             const std::vector<int>& support, const Eigen::VectorXf& values, Eigen::VectorXf& out) {
  assert(values.size() == 3 * static_cast<long>(support.size()));
  const auto value = [&](int j) {
    const auto it = std::lower_bound(support.begin(), support.end(), j);
    assert(it != support.end() && *it == j);
    return values.data() + 3 * (it - support.begin());
  };
  out.resize(3 * static_cast<long>(points.size()));
  for (size_t p = 0; p < points.size(); ++p) {
    out.segment<3>(3 * static_cast<long>(p)) =
        filter.enabled() ? filtered_point(filter, points[p], value) : Eigen::Map<const Eigen::Vector3f>(value(points[p]));
  }
}

}  // namespace animspace::illumination
