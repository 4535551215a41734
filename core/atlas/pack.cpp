#include "core/atlas/pack.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>

namespace animspace::atlas {

namespace {

double cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

// Andrew's monotone chain; counter-clockwise, no repeated points.
std::vector<Eigen::Vector2d> convex_hull(const ChartUv& uv) {
  std::vector<Eigen::Vector2d> p;
  p.reserve(static_cast<size_t>(uv.rows()));
  for (Eigen::Index i = 0; i < uv.rows(); ++i) p.emplace_back(uv(i, 0), uv(i, 1));
  std::sort(p.begin(), p.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  if (p.size() < 3) return p;
  std::vector<Eigen::Vector2d> hull(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], p[i]) <= 0) --k;
    hull[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], p[i - 1]) <= 0) --k;
    hull[k++] = p[i - 1];
  }
  hull.resize(k - 1);
  return hull;
}

// Rotates the chart to its minimum-area bounding rectangle, landscape, with its corner at 0.
Eigen::Vector2d orient(ChartUv& uv) {
  const std::vector<Eigen::Vector2d> hull = convex_hull(uv);
  Eigen::Matrix2d best = Eigen::Matrix2d::Identity();
  double best_area = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < hull.size(); ++i) {
    const Eigen::Vector2d e = hull[(i + 1) % hull.size()] - hull[i];
    if (!(e.norm() > 0)) continue;
    const Eigen::Vector2d d = e.normalized();
    Eigen::Matrix2d R;
    R << d.x(), d.y(), -d.y(), d.x();  // rows: the edge direction, its normal
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const Eigen::Vector2d& q : hull) {
      const Eigen::Vector2d r = R * q;
      lo = lo.cwiseMin(r);
      hi = hi.cwiseMax(r);
    }
    const double area = (hi - lo).prod();
    if (area < best_area) {
      best_area = area;
      best = R;
    }
  }
  for (Eigen::Index i = 0; i < uv.rows(); ++i) uv.row(i) = (best * uv.row(i).transpose()).transpose();
  Eigen::Vector2d lo = uv.colwise().minCoeff().transpose(), hi = uv.colwise().maxCoeff().transpose();
  if (hi.y() - lo.y() > hi.x() - lo.x()) {  // landscape: a quarter turn, which keeps orientation
    for (Eigen::Index i = 0; i < uv.rows(); ++i) {
      const double x = uv(i, 0);
      uv(i, 0) = -uv(i, 1);
      uv(i, 1) = x;
    }
    lo = uv.colwise().minCoeff().transpose();
    hi = uv.colwise().maxCoeff().transpose();
  }
  uv.rowwise() -= lo.transpose();
  return hi - lo;
}

struct Segment {
  double x, width, y;
};

// Skyline placement of rectangles (in the given order) into a strip of width `width`: each at
// the lowest top it can reach, in either orientation (then lowest bottom, then leftmost). Returns
// the height used; each rectangle's corner in `at` and whether it was turned in `turned`.
double skyline(const std::vector<Eigen::Vector2d>& sizes, const std::vector<size_t>& order, double width,
               std::vector<Eigen::Vector2d>& at, std::vector<char>& turned) {
  std::vector<Segment> sky{{0, width, 0}};
  double top = 0;
  for (size_t r : order) {
    double best_top = std::numeric_limits<double>::infinity(), best_y = 0, best_x = 0;
    bool best_turned = false;
    for (const bool turn : {false, true}) {
      const double w = turn ? sizes[r].y() : sizes[r].x(), h = turn ? sizes[r].x() : sizes[r].y();
      for (size_t i = 0; i < sky.size(); ++i) {
        const double x = sky[i].x;
        if (x + w > width + 1e-12) break;
        double y = 0;
        for (size_t j = i; j < sky.size() && sky[j].x < x + w - 1e-15; ++j) y = std::max(y, sky[j].y);
        if (y + h < best_top || (y + h == best_top && y < best_y)) {
          best_top = y + h;
          best_y = y;
          best_x = x;
          best_turned = turn;
        }
      }
    }
    if (!std::isfinite(best_top)) return std::numeric_limits<double>::infinity();  // wider than the strip
    at[r] = {best_x, best_y};
    turned[r] = best_turned ? 1 : 0;
    top = std::max(top, best_top);
    const double w = best_turned ? sizes[r].y() : sizes[r].x();
    // Raise the skyline over [best_x, best_x + w] to best_top.
    std::vector<Segment> next;
    const double x0 = best_x, x1 = best_x + w;
    for (const Segment& s : sky) {
      const double s0 = s.x, s1 = s.x + s.width;
      if (s1 <= x0 || s0 >= x1) {
        next.push_back(s);
        continue;
      }
      if (s0 < x0) next.push_back({s0, x0 - s0, s.y});
      if (s1 > x1) next.push_back({x1, s1 - x1, s.y});
    }
    next.push_back({x0, w, best_top});
    std::sort(next.begin(), next.end(), [](const Segment& a, const Segment& b) { return a.x < b.x; });
    sky.clear();
    for (const Segment& s : next) {  // merge neighbours of equal height
      if (!sky.empty() && sky.back().y == s.y && std::abs(sky.back().x + sky.back().width - s.x) < 1e-15) {
        sky.back().width += s.width;
      } else {
        sky.push_back(s);
      }
    }
  }
  return top;
}

}  // namespace

Result<PackResult> pack_charts(std::vector<ChartUv>& charts, const std::vector<FaceMatrix>& faces,
                               const PackOptions& options) {
  if (charts.empty() || faces.size() != charts.size()) {
    return make_error(ErrorCode::kInvalidArgument, "pack_charts: expected one face list per chart, at least one chart");
  }
  if (!(options.gutter > 0 && options.gutter < 0.25)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "pack_charts: gutter should be in (0, 0.25), got " + std::to_string(options.gutter));
  }
  std::vector<Eigen::Vector2d> sizes;
  double box_area = 0, uv_area = 0;
  for (size_t i = 0; i < charts.size(); ++i) {
    if (charts[i].rows() == 0) return make_error(ErrorCode::kInvalidArgument, "pack_charts: chart " + std::to_string(i) + " has no points");
    sizes.push_back(orient(charts[i]));
    box_area += sizes.back().prod();
    for (Eigen::Index f = 0; f < faces[i].rows(); ++f) {
      const Eigen::Vector2d a = charts[i].row(faces[i](f, 0)), b = charts[i].row(faces[i](f, 1)),
                            c = charts[i].row(faces[i](f, 2));
      uv_area += 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
    }
  }
  // Three orders (tallest, largest, longest first) and shuffles of the tallest-first order in
  // which each chart moves by a few places (a fixed seed: the result is deterministic); the one
  // that fits the largest scale wins.
  std::vector<std::vector<size_t>> orders(3, std::vector<size_t>(charts.size()));
  const auto key = [&](int which, size_t i) {
    return which == 0 ? sizes[i].y() : which == 1 ? sizes[i].prod() : sizes[i].maxCoeff();
  };
  for (int which = 0; which < 3; ++which) {
    auto& order = orders[static_cast<size_t>(which)];
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key(which, a) > key(which, b); });
  }
  std::mt19937_64 random(1);
  for (int shuffle = 0; shuffle < options.shuffled_orders; ++shuffle) {
    std::normal_distribution<double> jitter(0, 2);
    std::vector<double> rank(charts.size());
    for (size_t i = 0; i < charts.size(); ++i) rank[orders[0][i]] = static_cast<double>(i) + jitter(random);
    std::vector<size_t> order = orders[0];
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return rank[a] < rank[b]; });
    orders.push_back(std::move(order));
  }
  const double g = options.gutter;
  std::vector<Eigen::Vector2d> at(charts.size()), padded(charts.size());
  std::vector<char> turned(charts.size(), 0);
  const auto fits = [&](double s, const std::vector<size_t>& order) {
    for (size_t i = 0; i < charts.size(); ++i) padded[i] = s * sizes[i] + Eigen::Vector2d::Constant(g);
    return skyline(padded, order, 1 - g, at, turned) <= 1 - g;
  };
  double s = 0;
  size_t best_order = 0;
  for (size_t o = 0; o < orders.size(); ++o) {
    double lo = 0, hi = std::sqrt(1 / std::max(box_area, 1e-300));  // no packing beats the boxes' area
    for (int it = 0; it < 50; ++it) {
      const double mid = 0.5 * (lo + hi);
      (fits(mid, orders[o]) ? lo : hi) = mid;
    }
    if (lo > s) {
      s = lo;
      best_order = o;
    }
  }
  fits(s, orders[best_order]);
  for (size_t i = 0; i < charts.size(); ++i) {
    charts[i] *= s;
    if (turned[i]) {  // a quarter turn (orientation kept), back to the corner at 0
      for (Eigen::Index v = 0; v < charts[i].rows(); ++v) {
        const double x = charts[i](v, 0);
        charts[i](v, 0) = s * sizes[i].y() - charts[i](v, 1);
        charts[i](v, 1) = x;
      }
    }
    charts[i].rowwise() += (at[i] + Eigen::Vector2d::Constant(g)).transpose();
  }
  PackResult out;
  out.scale = s;
  out.utilisation = s * s * uv_area;
  return out;
}

}  // namespace animspace::atlas
