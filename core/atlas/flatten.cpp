#include "core/atlas/flatten.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

namespace animspace::atlas {

namespace {

using Uv = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
constexpr double kInf = std::numeric_limits<double>::infinity();

uint64_t edge_key(int32_t a, int32_t b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

// Whether closed segments pq and rs intersect (touching counts).
bool segments_intersect(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r,
                        const Eigen::Vector2d& s) {
  const double o1 = cross(q - p, r - p), o2 = cross(q - p, s - p);
  const double o3 = cross(s - r, p - r), o4 = cross(s - r, q - r);
  if (((o1 > 0 && o2 > 0) || (o1 < 0 && o2 < 0)) || ((o3 > 0 && o4 > 0) || (o3 < 0 && o4 < 0))) return false;
  if (o1 == 0 && o2 == 0) {  // collinear: overlap of the projections
    const Eigen::Vector2d d = q - p;
    double a = d.dot(r - p), b = d.dot(s - p);
    if (a > b) std::swap(a, b);
    return b >= 0 && a <= d.squaredNorm();
  }
  return true;
}

// The border as one loop of local vertices, or empty when it is not a single loop covering every
// border vertex.
std::vector<int32_t> border_loop(const FaceMatrix& faces) {
  std::unordered_map<uint64_t, int> directed;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) ++directed[edge_key(faces(f, k), faces(f, (k + 1) % 3))];
  }
  std::unordered_map<int32_t, int32_t> next;
  for (const auto& [key, count] : directed) {
    const auto a = static_cast<int32_t>(key >> 32), b = static_cast<int32_t>(key & 0xffffffffu);
    if (directed.count(edge_key(b, a))) continue;
    if (!next.emplace(a, b).second) return {};
  }
  if (next.empty()) return {};
  std::vector<int32_t> loop{next.begin()->first};
  while (true) {
    const auto it = next.find(loop.back());
    if (it == next.end()) return {};
    if (it->second == loop.front()) break;
    loop.push_back(it->second);
    if (loop.size() > next.size()) return {};
  }
  return loop.size() == next.size() ? loop : std::vector<int32_t>{};
}

struct Chart {
  const FaceMatrix& faces;
  const FaceMetrics& g;
  int vertex_count;
  std::vector<double> area;                 // surface area per face
  std::vector<std::vector<int32_t>> fan;    // faces around each vertex
  std::vector<int32_t> border;              // the border loop
  std::vector<int32_t> border_index;        // position in the loop, −1 inside
};

double metric_edge_length(const FaceMetrics& g, Eigen::Index f, int k) {
  // Edge k joins corners k and k+1: e1 = x1 − x0, e2 = x2 − x0, e2 − e1 = x2 − x1.
  if (k == 0) return std::sqrt(g(f, 0));
  if (k == 2) return std::sqrt(g(f, 2));
  return std::sqrt(std::max(0.0, g(f, 0) + g(f, 2) - 2 * g(f, 1)));
}

bool valid_map(const Chart& c, const Uv& uv) {
  for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
    const Eigen::Vector2d a = uv.row(c.faces(f, 0)), b = uv.row(c.faces(f, 1)), d = uv.row(c.faces(f, 2));
    if (!(cross(b - a, d - a) > 0)) return false;
  }
  const size_t n = c.border.size();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d p = uv.row(c.border[i]), q = uv.row(c.border[(i + 1) % n]);
    for (size_t j = i + 2; j < n; ++j) {
      if ((j + 1) % n == i) continue;
      if (segments_intersect(p, q, uv.row(c.border[j]), uv.row(c.border[(j + 1) % n]))) return false;
    }
  }
  return true;
}

// Lévy et al. 2002 with the triangles laid out from g; pins: border vertex 0 and the border
// vertex half-way round by length.
Uv lscm(const Chart& c) {
  const auto V = c.vertex_count;
  const size_t n = c.border.size();
  std::vector<double> along(n + 1, 0);
  std::unordered_map<uint64_t, double> length;
  for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) length[edge_key(c.faces(f, k), c.faces(f, (k + 1) % 3))] = metric_edge_length(c.g, f, k);
  }
  for (size_t i = 0; i < n; ++i) along[i + 1] = along[i] + length[edge_key(c.border[i], c.border[(i + 1) % n])];
  size_t half = 0;
  while (half + 1 < n && along[half + 1] < 0.5 * along[n]) ++half;
  if (half == 0) half = n / 2;
  const int32_t pin0 = c.border[0], pin1 = c.border[half];
  // Unknown index of each vertex (u then v), −1 for pinned.
  std::vector<int> index(static_cast<size_t>(V), -1);
  int free_count = 0;
  for (int32_t v = 0; v < V; ++v) {
    if (v != pin0 && v != pin1) index[static_cast<size_t>(v)] = free_count++;
  }
  Eigen::Vector2d pinned[2] = {{0, 0}, {along[half], 0}};
  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::VectorXd rhs_rows = Eigen::VectorXd::Zero(2 * c.faces.rows());
  double mean_area = 0;
  for (double a : c.area) mean_area += a / static_cast<double>(c.area.size());
  for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
    const double l1 = std::sqrt(c.g(f, 0));
    const double det = std::max(c.g(f, 0) * c.g(f, 2) - c.g(f, 1) * c.g(f, 1), 0.0);
    const double area = std::max(0.5 * std::sqrt(det), 1e-12 * mean_area);
    const std::complex<double> z[3] = {{0, 0}, {l1, 0}, {l1 > 0 ? c.g(f, 1) / l1 : 0, l1 > 0 ? 2 * area / l1 : 0}};
    const double s = 1 / std::sqrt(2 * area);
    for (int j = 0; j < 3; ++j) {
      const std::complex<double> w = (z[(j + 2) % 3] - z[(j + 1) % 3]) * s;
      const int32_t v = c.faces(f, j);
      const int i = index[static_cast<size_t>(v)];
      const auto re = 2 * f, im = 2 * f + 1;
      if (i >= 0) {
        triplets.emplace_back(re, i, w.real());
        triplets.emplace_back(re, free_count + i, -w.imag());
        triplets.emplace_back(im, i, w.imag());
        triplets.emplace_back(im, free_count + i, w.real());
      } else {
        const Eigen::Vector2d& p = pinned[v == pin0 ? 0 : 1];
        rhs_rows(re) -= w.real() * p.x() - w.imag() * p.y();
        rhs_rows(im) -= w.imag() * p.x() + w.real() * p.y();
      }
    }
  }
  Eigen::SparseMatrix<double> A(2 * c.faces.rows(), 2 * free_count);
  A.setFromTriplets(triplets.begin(), triplets.end());
  const Eigen::SparseMatrix<double> AtA = A.transpose() * A;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(AtA);
  Uv uv(V, 2);
  if (solver.info() != Eigen::Success) return Uv();
  const Eigen::VectorXd x = solver.solve(A.transpose() * rhs_rows);
  if (solver.info() != Eigen::Success || !x.allFinite()) return Uv();
  for (int32_t v = 0; v < V; ++v) {
    const int i = index[static_cast<size_t>(v)];
    if (i >= 0) {
      uv.row(v) << x(i), x(free_count + i);
    } else {
      uv.row(v) = pinned[v == pin0 ? 0 : 1].transpose();
    }
  }
  return uv;
}

// Tutte's embedding: the border on a circle by edge length, every inside vertex the mean of its
// neighbours.
Uv tutte(const Chart& c) {
  const auto V = c.vertex_count;
  const size_t n = c.border.size();
  std::unordered_map<uint64_t, double> length;
  std::vector<std::vector<int32_t>> neighbours(static_cast<size_t>(V));
  for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = c.faces(f, k), b = c.faces(f, (k + 1) % 3);
      length[edge_key(a, b)] = metric_edge_length(c.g, f, k);
      neighbours[static_cast<size_t>(a)].push_back(b);
      neighbours[static_cast<size_t>(b)].push_back(a);
    }
  }
  for (auto& list : neighbours) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  std::vector<double> along(n + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    // A zero-length border edge would put two vertices on one point: at least a tiny step.
    along[i + 1] = along[i] + std::max(length[edge_key(c.border[i], c.border[(i + 1) % n])], 1e-12);
  }
  Uv uv = Uv::Zero(V, 2);
  const double radius = along[n] / (2 * M_PI);
  for (size_t i = 0; i < n; ++i) {
    const double angle = 2 * M_PI * along[i] / along[n];
    uv.row(c.border[i]) << radius * std::cos(angle), radius * std::sin(angle);
  }
  std::vector<int> index(static_cast<size_t>(V), -1);
  int inside = 0;
  for (int32_t v = 0; v < V; ++v) {
    if (c.border_index[static_cast<size_t>(v)] < 0) index[static_cast<size_t>(v)] = inside++;
  }
  if (inside == 0) return uv;
  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(inside, 2);
  for (int32_t v = 0; v < V; ++v) {
    const int i = index[static_cast<size_t>(v)];
    if (i < 0) continue;
    triplets.emplace_back(i, i, static_cast<double>(neighbours[static_cast<size_t>(v)].size()));
    for (int32_t w : neighbours[static_cast<size_t>(v)]) {
      const int j = index[static_cast<size_t>(w)];
      if (j >= 0) {
        triplets.emplace_back(i, j, -1.0);
      } else {
        rhs.row(i) += uv.row(w);
      }
    }
  }
  Eigen::SparseMatrix<double> L(inside, inside);
  L.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(L);
  if (solver.info() != Eigen::Success) return Uv();
  const Eigen::MatrixXd x = solver.solve(rhs);
  for (int32_t v = 0; v < V; ++v) {
    const int i = index[static_cast<size_t>(v)];
    if (i >= 0) uv.row(v) = x.row(i);
  }
  return uv;
}

// Sander 2001's per-vertex line search on the chart's normalised L2².
class Optimiser {
 public:
  Optimiser(const Chart& c, Uv& uv) : c_(c), uv_(uv) {
    per_face_.resize(static_cast<size_t>(c.faces.rows()));
    for (Eigen::Index f = 0; f < c.faces.rows(); ++f) {
      const TriangleStretch t = face(f, -1, Eigen::Vector2d::Zero());
      per_face_[static_cast<size_t>(f)] = t.surface_area * t.l2_squared;
      weighted_ += per_face_[static_cast<size_t>(f)];
      uv_area_ += t.uv_area;
      surface_ += t.surface_area;
    }
  }

  double energy() const { return weighted_ * uv_area_ / (surface_ * surface_); }

  int run(const FlattenOptions& options) {
    std::mt19937_64 random(1);
    int sweeps = 0;
    std::vector<int32_t> order(static_cast<size_t>(c_.vertex_count));
    std::iota(order.begin(), order.end(), 0);
    for (; sweeps < options.max_sweeps; ++sweeps) {
      const double before = energy();
      // Sander 2001: vertices in decreasing order of their neighbourhood's stretch.
      std::vector<double> local(order.size(), 0);
      for (int32_t v = 0; v < c_.vertex_count; ++v) {
        for (int32_t f : c_.fan[static_cast<size_t>(v)]) local[static_cast<size_t>(v)] += per_face_[static_cast<size_t>(f)];
      }
      std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) { return local[static_cast<size_t>(a)] > local[static_cast<size_t>(b)]; });
      for (int32_t v : order) move_vertex(v, random);
      const double after = energy();
      if (!(before - after > options.tolerance * before)) {
        ++sweeps;
        break;
      }
    }
    return sweeps;
  }

 private:
  TriangleStretch face(Eigen::Index f, int32_t moved, const Eigen::Vector2d& at) const {
    Eigen::Vector2d x[3];
    for (int k = 0; k < 3; ++k) {
      const int32_t v = c_.faces(f, k);
      x[k] = v == moved ? at : Eigen::Vector2d(uv_.row(v).transpose());
    }
    return triangle_stretch(c_.g(f, 0), c_.g(f, 1), c_.g(f, 2), x[0], x[1], x[2]);
  }

  // The chart's energy with vertex v at `at`; +∞ if a triangle of its fan flips.
  double energy_at(int32_t v, const Eigen::Vector2d& at, double* fan_weighted = nullptr, double* fan_uv = nullptr) const {
    double weighted = 0, uv = 0, weighted0 = 0, uv0 = 0;
    for (int32_t f : c_.fan[static_cast<size_t>(v)]) {
      const TriangleStretch t = face(f, v, at);
      if (!(t.uv_area > 0)) return kInf;
      weighted += t.surface_area * t.l2_squared;
      uv += t.uv_area;
      weighted0 += per_face_[static_cast<size_t>(f)];
      uv0 += face_uv_area(f);
    }
    if (fan_weighted) *fan_weighted = weighted;
    if (fan_uv) *fan_uv = uv;
    return (weighted_ - weighted0 + weighted) * (uv_area_ - uv0 + uv) / (surface_ * surface_);
  }

  double face_uv_area(int32_t f) const {
    const Eigen::Vector2d a = uv_.row(c_.faces(f, 0)), b = uv_.row(c_.faces(f, 1)), d = uv_.row(c_.faces(f, 2));
    return 0.5 * cross(b - a, d - a);
  }

  bool border_ok(int32_t v, const Eigen::Vector2d& at) const {
    const int bi = c_.border_index[static_cast<size_t>(v)];
    if (bi < 0) return true;
    const auto n = static_cast<int>(c_.border.size());
    const int32_t prev = c_.border[static_cast<size_t>((bi + n - 1) % n)], next = c_.border[static_cast<size_t>((bi + 1) % n)];
    const Eigen::Vector2d p = uv_.row(prev), q = uv_.row(next);
    for (int j = 0; j < n; ++j) {
      const int32_t a = c_.border[static_cast<size_t>(j)], b = c_.border[static_cast<size_t>((j + 1) % n)];
      if (a == v || b == v) continue;
      const Eigen::Vector2d ra = uv_.row(a), rb = uv_.row(b);
      if (a != prev && b != prev && segments_intersect(p, at, ra, rb)) return false;
      if (a != next && b != next && segments_intersect(at, q, ra, rb)) return false;
    }
    return true;
  }

  void move_vertex(int32_t v, std::mt19937_64& random) {
    const auto& fan = c_.fan[static_cast<size_t>(v)];
    if (fan.empty()) return;
    const Eigen::Vector2d x0 = uv_.row(v);
    double reach = 0;
    for (int32_t f : fan) {
      for (int k = 0; k < 3; ++k) reach = std::max(reach, (Eigen::Vector2d(uv_.row(c_.faces(f, k))) - x0).norm());
    }
    if (!(reach > 0)) return;
    const double e0 = energy();
    // Descent direction by central differences; a random one if the gradient is not usable.
    const double h = 1e-4 * reach;
    Eigen::Vector2d grad;
    for (int d = 0; d < 2; ++d) {
      Eigen::Vector2d step = Eigen::Vector2d::Zero();
      step(d) = h;
      grad(d) = (energy_at(v, x0 + step) - energy_at(v, x0 - step)) / (2 * h);
    }
    Eigen::Vector2d dir;
    if (grad.allFinite() && grad.norm() > 0) {
      dir = -grad.normalized();
    } else {
      std::uniform_real_distribution<double> angle(0, 2 * M_PI);
      const double a = angle(random);
      dir << std::cos(a), std::sin(a);
    }
    // The interval of t where no fan triangle flips: a_f(t) = a_f + t·½ d×(q − r), linear in t.
    double lo = -2 * reach, hi = 2 * reach;
    for (int32_t f : fan) {
      int k = 0;
      while (c_.faces(f, k) != v) ++k;
      const Eigen::Vector2d q = uv_.row(c_.faces(f, (k + 1) % 3)), r = uv_.row(c_.faces(f, (k + 2) % 3));
      const double a0 = face_uv_area(f), rate = 0.5 * cross(dir, q - r);
      if (rate < 0) hi = std::min(hi, a0 / -rate);
      if (rate > 0) lo = std::max(lo, -a0 / rate);
    }
    lo *= 0.99;
    hi *= 0.99;
    if (!(hi > lo)) return;
    // Golden-section search on [lo, hi].
    const double phi = 0.5 * (std::sqrt(5.0) - 1);
    double a = lo, b = hi;
    double t1 = b - phi * (b - a), t2 = a + phi * (b - a);
    double f1 = energy_at(v, x0 + t1 * dir), f2 = energy_at(v, x0 + t2 * dir);
    for (int it = 0; it < 30; ++it) {
      if (f1 < f2) {
        b = t2;
        t2 = t1;
        f2 = f1;
        t1 = b - phi * (b - a);
        f1 = energy_at(v, x0 + t1 * dir);
      } else {
        a = t1;
        t1 = t2;
        f1 = f2;
        t2 = a + phi * (b - a);
        f2 = energy_at(v, x0 + t2 * dir);
      }
    }
    double t = f1 < f2 ? t1 : t2;
    for (int halving = 0; halving < 8; ++halving, t *= 0.5) {
      const Eigen::Vector2d x = x0 + t * dir;
      double fan_weighted = 0, fan_uv = 0;
      const double e = energy_at(v, x, &fan_weighted, &fan_uv);
      if (!(e < e0)) continue;
      if (!border_ok(v, x)) continue;
      // Accept: update the running sums.
      double weighted0 = 0, uv0 = 0;
      for (int32_t f : fan) {
        weighted0 += per_face_[static_cast<size_t>(f)];
        uv0 += face_uv_area(f);
      }
      uv_.row(v) = x.transpose();
      for (int32_t f : fan) {
        const TriangleStretch s = face(f, -1, Eigen::Vector2d::Zero());
        per_face_[static_cast<size_t>(f)] = s.surface_area * s.l2_squared;
      }
      weighted_ += fan_weighted - weighted0;
      uv_area_ += fan_uv - uv0;
      return;
    }
  }

  const Chart& c_;
  Uv& uv_;
  std::vector<double> per_face_;
  double weighted_ = 0, uv_area_ = 0, surface_ = 0;
};

}  // namespace

Result<ChartMap> flatten_chart(const FaceMatrix& faces, int vertex_count, const FaceMetrics& metrics,
                               const FlattenOptions& options) {
  Chart c{faces, metrics, vertex_count, {}, {}, {}, {}};
  c.border = border_loop(faces);
  if (c.border.size() < 3) {
    return make_error(ErrorCode::kInvalidArgument, "flatten_chart: the chart is not a disc (its border is not one loop)");
  }
  c.border_index.assign(static_cast<size_t>(vertex_count), -1);
  for (size_t i = 0; i < c.border.size(); ++i) c.border_index[static_cast<size_t>(c.border[i])] = static_cast<int32_t>(i);
  c.fan.resize(static_cast<size_t>(vertex_count));
  double surface = 0;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const double det = metrics(f, 0) * metrics(f, 2) - metrics(f, 1) * metrics(f, 1);
    c.area.push_back(0.5 * std::sqrt(std::max(det, 0.0)));
    surface += c.area.back();
    for (int k = 0; k < 3; ++k) c.fan[static_cast<size_t>(faces(f, k))].push_back(static_cast<int32_t>(f));
  }
  if (!(surface > 0)) return make_error(ErrorCode::kInvalidArgument, "flatten_chart: the chart has no area");

  ChartMap out;
  Uv uv = lscm(c);
  if (uv.rows() != vertex_count || !uv.allFinite() || !valid_map(c, uv)) {
    uv = tutte(c);
    out.used_tutte = true;
    if (uv.rows() != vertex_count || !uv.allFinite() || !valid_map(c, uv)) {
      return make_error(ErrorCode::kInternal, "flatten_chart: Tutte's embedding of a " + std::to_string(faces.rows()) +
                                                  "-face chart has a flipped triangle (numerically degenerate chart)");
    }
  }
  // Scale so that the UV area equals the surface area (keeps the numbers near 1).
  double uv_area = 0;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector2d a = uv.row(faces(f, 0)), b = uv.row(faces(f, 1)), d = uv.row(faces(f, 2));
    uv_area += 0.5 * cross(b - a, d - a);
  }
  uv *= std::sqrt(surface / uv_area);
  if (options.optimise_stretch) {
    Optimiser optimiser(c, uv);
    out.sweeps = optimiser.run(options);
  }
  CornerUvs corners(3 * faces.rows(), 2);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) corners.row(3 * f + k) = uv.row(faces(f, k));
  }
  const Stretch s = stretch(metrics, corners);
  out.l2 = s.l2;
  out.linf = s.linf;
  out.surface_area = surface;
  out.uv_area = 0;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector2d a = uv.row(faces(f, 0)), b = uv.row(faces(f, 1)), d = uv.row(faces(f, 2));
    out.uv_area += 0.5 * cross(b - a, d - a);
  }
  out.uv = std::move(uv);
  return out;
}

}  // namespace animspace::atlas
