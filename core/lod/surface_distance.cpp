#include "core/lod/surface_distance.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Geometry>

#include "core/common/parallel.h"

namespace animspace::lod {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// At most this many grid cells (16 MiB of offsets): beyond it cells hold several triangles each.
constexpr int64_t kMaxCells = int64_t{1} << 22;

// Squared distance from q to the segment p + [0, 1]·e; `inv` is 1/|e|² (0 for a point).
inline double segment_squared_distance(const Eigen::Vector3d& q, const Eigen::Vector3d& p, const Eigen::Vector3d& e,
                                       double inv) {
  const Eigen::Vector3d d = q - p;
  const double t = std::clamp(d.dot(e) * inv, 0.0, 1.0);
  return (d - t * e).squaredNorm();
}

// Squared distance from q to the box [lo, hi] (0 inside); branch-free.
inline double box_squared_distance(const Eigen::Vector3d& q, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (lo - q).cwiseMax(q - hi).cwiseMax(0.0).squaredNorm();
}

// Number of cells of a grid with cell size h over a box of extents e.
double cell_count(const Eigen::Vector3d& extent, double h) {
  double count = 1;
  for (int axis = 0; axis < 3; ++axis) count *= std::min(1e9, std::floor(extent[axis] / h) + 1);
  return count;
}

// The cell index of coordinate x along an axis, clamped to [0, dim).
inline int cell_index(double x, double origin, double h, int dim) {
  const double cell = std::floor((x - origin) / h);
  if (!(cell >= 0)) return 0;  // also NaN
  if (cell >= dim - 1) return dim - 1;
  return static_cast<int>(cell);
}

}  // namespace

SurfaceDistance::Triangle SurfaceDistance::make_triangle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                                         const Eigen::Vector3d& c) {
  Triangle t;
  t.a = a;
  t.e0 = b - a;
  t.e1 = c - a;
  t.e2 = c - b;
  const double l0 = t.e0.squaredNorm();
  const double l1 = t.e1.squaredNorm();
  const double l2 = t.e2.squaredNorm();
  t.inv0 = l0 > 0 ? 1 / l0 : 0;
  t.inv1 = l1 > 0 ? 1 / l1 : 0;
  t.inv2 = l2 > 0 ? 1 / l2 : 0;
  t.lo = a.cwiseMin(b).cwiseMin(c);
  t.hi = a.cwiseMax(b).cwiseMax(c);
  // The normal is taken at the corner opposite the longest edge (its widest angle), where the
  // cross product loses the least to cancellation; |n|² = l · l' · sin²θ. Below sin²θ ≈ 1e-16
  // the plane is noise and the triangle is treated as its three edges (a segment or a point).
  Eigen::Vector3d n;
  double scale;
  if (l2 >= l0 && l2 >= l1) {
    n = t.e0.cross(t.e1);
    scale = l0 * l1;
  } else if (l1 >= l0) {
    n = t.e2.cross(-t.e0);  // at b: (c − b) × (a − b) = e0 × e1 as well
    scale = l0 * l2;
  } else {
    n = t.e1.cross(t.e2);  // at c: (a − c) × (b − c) = e0 × e1 as well
    scale = l1 * l2;
  }
  const double n2 = n.squaredNorm();
  if (!(n2 > std::numeric_limits<double>::epsilon() * scale) || !std::isfinite(n2)) {
    t.degenerate = true;
    t.normal.setZero();
    t.u.setZero();
    t.w.setZero();
    return t;
  }
  t.normal = n / std::sqrt(n2);
  // The normal's direction is off by about ε/sinθ (θ the widest angle); a few ε more for forming
  // q − a and the dot product.
  t.slack = 8 * std::numeric_limits<double>::epsilon() * (1 + std::sqrt(scale / n2));
  // p − a = s·e0 + t·e1 for p in the plane: s = n·((p − a) × e1)/|n|², t = n·(e0 × (p − a))/|n|²,
  // and the normal component of q − a drops out of both.
  t.u = t.e1.cross(n) / n2;
  t.w = n.cross(t.e0) / n2;
  return t;
}

double SurfaceDistance::squared_distance(const Triangle& t, const Eigen::Vector3d& q) {
  if (!t.degenerate) {
    const Eigen::Vector3d d = q - t.a;
    const double s = d.dot(t.u);
    const double r = d.dot(t.w);
    const bool below_s = s < 0;     // beyond edge ca (opposite b)
    const bool below_r = r < 0;     // beyond edge ab (opposite c)
    const bool beyond = s + r > 1;  // beyond edge bc (opposite a)
    if (!below_s && !below_r && !beyond) {
      // The distance to the foot point a + s·e0 + r·e1, a point of the triangle: unlike the
      // plane distance d·normal, its error is second order in the error of (s, r), which keeps
      // slivers accurate.
      return (d - s * t.e0 - r * t.e1).squaredNorm();
    }
    // Outside the triangle in its plane: the nearest point lies on an edge whose opposite
    // barycentric coordinate is negative (one or two of them).
    double best = kInfinity;
    if (below_r) best = std::min(best, segment_squared_distance(q, t.a, t.e0, t.inv0));
    if (below_s) best = std::min(best, segment_squared_distance(q, t.a, t.e1, t.inv1));
    if (beyond) best = std::min(best, segment_squared_distance(q, t.a + t.e0, t.e2, t.inv2));
    return best;
  }
  return std::min({segment_squared_distance(q, t.a, t.e0, t.inv0), segment_squared_distance(q, t.a, t.e1, t.inv1),
                   segment_squared_distance(q, t.a + t.e0, t.e2, t.inv2)});
}

double point_triangle_distance(const Eigen::Vector3d& q, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const Eigen::Vector3d& c) {
  return std::sqrt(SurfaceDistance::squared_distance(SurfaceDistance::make_triangle(a, b, c), q));
}

SurfaceDistance::SurfaceDistance(const Points3d& points, const FaceMatrix& faces) {
  assert(faces.rows() >= 1);
  assert(faces.size() == 0 || (faces.minCoeff() >= 0 && faces.maxCoeff() < points.rows()));
  const Eigen::Index face_count = faces.rows();

  triangles_.reserve(static_cast<size_t>(face_count));
  origin_.setConstant(kInfinity);
  upper_.setConstant(-kInfinity);
  for (Eigen::Index f = 0; f < face_count; ++f) {
    const Eigen::Vector3d a = points.row(faces(f, 0)).transpose();
    const Eigen::Vector3d b = points.row(faces(f, 1)).transpose();
    const Eigen::Vector3d c = points.row(faces(f, 2)).transpose();
    triangles_.push_back(make_triangle(a, b, c));
    origin_ = origin_.cwiseMin(a).cwiseMin(b).cwiseMin(c);
    upper_ = upper_.cwiseMax(a).cwiseMax(b).cwiseMax(c);
  }
  if (!origin_.allFinite() || !upper_.allFinite()) {
    // Non-finite corners: one cell holding everything (distances come out as the arithmetic says).
    origin_.setZero();
    upper_.setZero();
  }

  // Cell size: the smallest with no more cells than triangles (capped), found by bisection on the
  // monotone cell count; a box flat along an axis gets one layer of cells there.
  const Eigen::Vector3d extent = upper_ - origin_;
  const double largest = extent.maxCoeff();
  const double target = static_cast<double>(std::min<int64_t>(face_count, kMaxCells));
  if (largest > 0) {
    double small = largest / (target + 1);  // too many cells along the largest axis alone
    double large = 2 * largest;             // one cell
    for (int iteration = 0; iteration < 100 && large - small > 1e-12 * large; ++iteration) {
      const double middle = 0.5 * (small + large);
      if (cell_count(extent, middle) > target) {
        small = middle;
      } else {
        large = middle;
      }
    }
    cell_size_ = large;
  } else {
    cell_size_ = 1;
  }
  for (int axis = 0; axis < 3; ++axis) {
    dims_[axis] = static_cast<int>(std::min(1e9, std::floor(extent[axis] / cell_size_) + 1));
  }
  const int64_t cell_total = int64_t{dims_.x()} * dims_.y() * dims_.z();
  for (int axis = 0; axis < 3; ++axis) {
    grid_end_[axis] = std::max<double>(dims_[axis], (upper_[axis] - origin_[axis]) / cell_size_);
  }

  // Bin each triangle into the cells its bounding box overlaps and whose box meets its plane,
  // padded for the rounding of the test (the normal's direction error is what `slack` bounds);
  // run twice, to count and then to fill.
  const double h = cell_size_;
  const double pad = 1e-9 * h;
  auto visit_cells = [&](const Triangle& t, auto&& emit) {
    Eigen::Vector3i first, last;
    for (int axis = 0; axis < 3; ++axis) {
      first[axis] = cell_index(t.lo[axis], origin_[axis], h, dims_[axis]);
      last[axis] = cell_index(t.hi[axis], origin_[axis], h, dims_[axis]);
    }
    const bool single = first == last;
    const double radius = 0.5 * h * t.normal.cwiseAbs().sum() + pad;
    for (int k = first.z(); k <= last.z(); ++k) {
      for (int j = first.y(); j <= last.y(); ++j) {
        for (int i = first.x(); i <= last.x(); ++i) {
          if (!single && !t.degenerate) {
            const Eigen::Vector3d center = origin_ + h * Eigen::Vector3d(i + 0.5, j + 0.5, k + 0.5);
            const Eigen::Vector3d offset = center - t.a;
            if (std::abs(t.normal.dot(offset)) > radius + 2 * t.slack * (offset.norm() + h)) continue;
          }
          emit((int64_t{k} * dims_.y() + j) * dims_.x() + i);
        }
      }
    }
  };
  std::vector<int64_t> counts(static_cast<size_t>(cell_total) + 1, 0);
  for (const Triangle& t : triangles_) visit_cells(t, [&](int64_t cell) { ++counts[static_cast<size_t>(cell) + 1]; });
  for (size_t cell = 1; cell < counts.size(); ++cell) counts[cell] += counts[cell - 1];
  assert(counts.back() <= std::numeric_limits<int32_t>::max());
  cell_offsets_.assign(counts.begin(), counts.end());
  cell_faces_.resize(static_cast<size_t>(counts.back()));
  std::vector<int32_t> cursor(cell_offsets_.begin(), cell_offsets_.end() - 1);
  for (size_t f = 0; f < triangles_.size(); ++f) {
    visit_cells(triangles_[f], [&](int64_t cell) {
      cell_faces_[static_cast<size_t>(cursor[static_cast<size_t>(cell)]++)] = static_cast<int32_t>(f);
    });
  }
}

double SurfaceDistance::distance(const Eigen::Vector3d& q) const {
  if (!q.allFinite()) {
    return q.hasNaN() ? std::numeric_limits<double>::quiet_NaN() : kInfinity;
  }
  // Work in cell units: qc = (q − origin)/h, cell i spanning [i, i + 1] along an axis, except
  // that the last cell reaches grid_end_ (which covers the bounding box whatever the rounding).
  const double h2 = cell_size_ * cell_size_;
  Eigen::Vector3d qc;
  Eigen::Vector3i center;
  Eigen::Vector3d outside;  // squared distance from qc to the whole grid along each axis
  int max_shell = 0;
  for (int axis = 0; axis < 3; ++axis) {
    qc[axis] = (q[axis] - origin_[axis]) / cell_size_;
    center[axis] = cell_index(q[axis], origin_[axis], cell_size_, dims_[axis]);
    const double below = -qc[axis];
    const double above = qc[axis] - grid_end_[axis];
    const double d = std::max({below, above, 0.0});
    outside[axis] = d * d;
    max_shell = std::max({max_shell, center[axis], dims_[axis] - 1 - center[axis]});
  }
  const double outside_sum = outside.sum();
  // Squared distance along `axis` from qc to cell `i`, in cell units.
  auto axis_distance = [&](int axis, int i) {
    const double lo = i;
    const double hi = i == dims_[axis] - 1 ? grid_end_[axis] : i + 1.0;
    const double d = qc[axis] < lo ? lo - qc[axis] : (qc[axis] > hi ? qc[axis] - hi : 0.0);
    return d * d;
  };

  double best = kInfinity;
  auto search_cell = [&](int i, int j, int k, double dyz) {
    const size_t cell = static_cast<size_t>((int64_t{k} * dims_.y() + j) * dims_.x() + i);
    const int32_t begin = cell_offsets_[cell];
    const int32_t end = cell_offsets_[cell + 1];
    if (begin == end) return;
    if (h2 * (dyz + axis_distance(0, i)) >= best) return;
    for (int32_t entry = begin; entry < end; ++entry) {
      const Triangle& t = triangles_[static_cast<size_t>(cell_faces_[static_cast<size_t>(entry)])];
      if (box_squared_distance(q, t.lo, t.hi) >= best) continue;
      if (!t.degenerate) {
        // The distance to the plane is a lower bound; with rounding error e ≤ slack·|d|,
        // (|plane| − e)² ≥ plane² − 2·slack·|d|² since |plane| ≤ |d|.
        const Eigen::Vector3d d = q - t.a;
        const double plane = d.dot(t.normal);
        if (plane * plane - 2 * t.slack * d.squaredNorm() >= best) continue;
      }
      best = std::min(best, squared_distance(t, q));
    }
  };

  for (int shell = 0; shell <= max_shell; ++shell) {
    const Eigen::Vector3i first = (center.array() - shell).max(0).matrix();
    const Eigen::Vector3i last = (center.array() + shell).min(dims_.array() - 1).matrix();
    for (int k = first.z(); k <= last.z(); ++k) {
      const bool k_face = k == center.z() - shell || k == center.z() + shell;
      const double dz = axis_distance(2, k);
      for (int j = first.y(); j <= last.y(); ++j) {
        const double dyz = dz + axis_distance(1, j);
        if (k_face || j == center.y() - shell || j == center.y() + shell) {
          for (int i = first.x(); i <= last.x(); ++i) search_cell(i, j, k, dyz);
        } else {
          if (center.x() - shell >= 0) search_cell(center.x() - shell, j, k, dyz);
          if (shell > 0 && center.x() + shell < dims_.x()) search_cell(center.x() + shell, j, k, dyz);
        }
      }
    }
    // Every unsearched cell lies in a slab of the grid beyond [first, last] along some axis (full
    // extent along the others); stop when none of them can hold anything closer.
    double bound = kInfinity;
    for (int axis = 0; axis < 3; ++axis) {
      const double others = outside_sum - outside[axis];
      if (first[axis] > 0) {  // cells [0, first) span [0, first]
        const double d = std::max(0.0, qc[axis] - first[axis]);
        bound = std::min(bound, d * d + others);
      }
      if (last[axis] < dims_[axis] - 1) {  // cells (last, dims) span [last + 1, grid_end]
        const double d = std::max(0.0, last[axis] + 1.0 - qc[axis]);
        bound = std::min(bound, d * d + others);
      }
    }
    if (best <= h2 * bound) break;
  }
  return std::sqrt(best);
}

DistanceSummary distances_to_surface(const Points3d& queries, const SurfaceDistance& surface) {
  // Fixed blocks summed in order, so the result does not depend on the number of threads.
  constexpr int64_t kBlock = 1024;
  const int64_t count = queries.rows();
  const int64_t blocks = (count + kBlock - 1) / kBlock;
  std::vector<double> block_sums(static_cast<size_t>(blocks), 0.0);
  std::vector<double> block_max(static_cast<size_t>(blocks), 0.0);
  parallel_for_chunks(blocks, 4, [&](int64_t first_block, int64_t end_block) {
    for (int64_t block = first_block; block < end_block; ++block) {
      double sum = 0;
      double max = 0;
      const int64_t end = std::min(count, (block + 1) * kBlock);
      for (int64_t row = block * kBlock; row < end; ++row) {
        const double d = surface.distance(queries.row(row).transpose());
        sum += d * d;
        if (!(d <= max)) max = d;  // NaN propagates
      }
      block_sums[static_cast<size_t>(block)] = sum;
      block_max[static_cast<size_t>(block)] = max;
    }
  });
  DistanceSummary summary;
  summary.count = static_cast<long>(count);
  for (int64_t block = 0; block < blocks; ++block) {
    summary.sum_of_squares += block_sums[static_cast<size_t>(block)];
    const double max = block_max[static_cast<size_t>(block)];
    if (!(max <= summary.max)) summary.max = max;
  }
  summary.rms = count > 0 ? std::sqrt(summary.sum_of_squares / static_cast<double>(count)) : 0.0;
  return summary;
}

}  // namespace animspace::lod
