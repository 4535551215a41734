#include "core/atlas/charts.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <queue>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>

namespace animspace::atlas {

namespace {

using Adjacency = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
constexpr double kInf = std::numeric_limits<double>::infinity();

uint64_t edge_key(int32_t a, int32_t b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

// Dual-graph Dijkstra from `sources` over faces for which `allowed(f)` holds; `dist` is updated in
// place (it may already hold distances from earlier sources). Edge weights are the L2,2 distances
// between face centroids.
template <typename Allowed>
void dual_dijkstra(const Adjacency& adjacency, const Eigen::MatrixXd& weight, const std::vector<int32_t>& sources,
                   Allowed allowed, std::vector<double>& dist) {
  using Entry = std::pair<double, int32_t>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
  for (int32_t s : sources) {
    dist[static_cast<size_t>(s)] = 0;
    queue.emplace(0.0, s);
  }
  while (!queue.empty()) {
    const auto [d, f] = queue.top();
    queue.pop();
    if (d > dist[static_cast<size_t>(f)]) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t g = adjacency(f, k);
      if (g < 0 || !allowed(g)) continue;
      const double nd = d + weight(f, k);
      if (nd < dist[static_cast<size_t>(g)]) {
        dist[static_cast<size_t>(g)] = nd;
        queue.emplace(nd, g);
      }
    }
  }
}

int32_t argmax(const std::vector<double>& values, const std::vector<int32_t>& among) {
  int32_t best = among.front();
  for (int32_t f : among) {
    if (values[static_cast<size_t>(f)] > values[static_cast<size_t>(best)]) best = f;
  }
  return best;
}

// Renumbers charts densely in order of first appearance; returns the count.
int32_t renumber(std::vector<int32_t>& chart_of_face) {
  std::unordered_map<int32_t, int32_t> ids;
  for (int32_t& c : chart_of_face) c = ids.try_emplace(c, static_cast<int32_t>(ids.size())).first->second;
  return static_cast<int32_t>(ids.size());
}

std::vector<std::vector<int32_t>> faces_by_chart(const std::vector<int32_t>& chart_of_face, int32_t charts) {
  std::vector<std::vector<int32_t>> out(static_cast<size_t>(charts));
  for (size_t f = 0; f < chart_of_face.size(); ++f) {
    out[static_cast<size_t>(chart_of_face[f])].push_back(static_cast<int32_t>(f));
  }
  return out;
}

class Segmenter {
 public:
  Segmenter(const FaceMatrix& faces, const NormalisedFaces& normalised, const ChartOptions& options)
      : faces_(faces), nf_(normalised), options_(options), adjacency_(face_adjacency(faces)) {
    const Eigen::Index F = faces.rows();
    weight_.resize(F, 3);
    bivector_norm_.resize(F);
    for (Eigen::Index f = 0; f < F; ++f) {
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency_(f, k);
        weight_(f, k) = g < 0 ? kInf : (nf_.centroid.col(f) - nf_.centroid.col(g)).norm();
      }
      const double aa = nf_.edge1.col(f).squaredNorm(), bb = nf_.edge2.col(f).squaredNorm();
      const double ab = nf_.edge1.col(f).dot(nf_.edge2.col(f));
      bivector_norm_[static_cast<size_t>(f)] = std::sqrt(std::max(0.0, aa * bb - ab * ab));
      for (int k = 0; k < 3; ++k) edge_faces_[edge_key(faces(f, k), faces(f, (k + 1) % 3))] = static_cast<int32_t>(f);
    }
  }

  std::vector<int32_t> run() {
    const auto F = static_cast<int32_t>(faces_.rows());
    std::vector<int32_t> seeds = farthest_seeds();
    std::vector<int32_t> chart(static_cast<size_t>(F), -1);
    std::vector<Eigen::MatrixXd> proxies;
    for (int32_t s : seeds) {
      // A unit proxy, as fit_proxies makes them: the cosine must not depend on the model's units.
      Eigen::MatrixXd B = bivector(s);
      const double norm = B.norm() / std::sqrt(2.0);
      if (norm > 0) B /= norm;
      proxies.push_back(std::move(B));
    }
    for (int it = 0; it <= options_.lloyd_iterations; ++it) {
      grow(seeds, proxies, chart);
      fit_proxies(chart, static_cast<int32_t>(seeds.size()), proxies);
      std::vector<int32_t> next = reseed(chart, seeds);
      if (next == seeds) break;
      seeds = std::move(next);
    }
    smooth(chart, seeds);
    make_discs(chart);
    renumber(chart);
    for (int pass = 0; pass < options_.straightening_passes; ++pass) {
      if (straighten(chart) == 0) break;
    }
    renumber(chart);
    return chart;
  }

 private:
  // B_f as an antisymmetric matrix a bᵀ − b aᵀ.
  Eigen::MatrixXd bivector(int32_t f) const {
    const auto a = nf_.edge1.col(f), b = nf_.edge2.col(f);
    return a * b.transpose() - b * a.transpose();
  }

  double cost(int32_t f, int32_t chart, const std::vector<int32_t>& seeds, const std::vector<Eigen::MatrixXd>& proxies) const {
    const Eigen::MatrixXd& S = proxies[static_cast<size_t>(chart)];
    const double norm_f = bivector_norm_[static_cast<size_t>(f)];
    double cosine = 1;
    if (norm_f > 0) cosine = nf_.edge1.col(f).dot(S * nf_.edge2.col(f)) / norm_f;
    const double distance = (nf_.centroid.col(f) - nf_.centroid.col(seeds[static_cast<size_t>(chart)])).norm();
    return (1 - cosine + options_.compactness) * distance;
  }

  // Farthest-point seeds on the dual graph; every connected component gets at least one.
  std::vector<int32_t> farthest_seeds() const {
    const auto F = static_cast<int32_t>(faces_.rows());
    std::vector<int32_t> all(static_cast<size_t>(F));
    std::iota(all.begin(), all.end(), 0);
    std::vector<double> dist(static_cast<size_t>(F), kInf);
    const auto any = [](int32_t) { return true; };
    dual_dijkstra(adjacency_, weight_, {0}, any, dist);
    std::vector<int32_t> seeds;
    // The first seed is the face farthest from face 0 (a tip rather than wherever face 0 lies).
    int32_t next = 0;
    for (int32_t f = 0; f < F; ++f) {
      if (std::isfinite(dist[static_cast<size_t>(f)]) && dist[static_cast<size_t>(f)] > dist[static_cast<size_t>(next)]) next = f;
    }
    std::fill(dist.begin(), dist.end(), kInf);
    while (true) {
      seeds.push_back(next);
      dual_dijkstra(adjacency_, weight_, {next}, any, dist);
      next = argmax(dist, all);
      const bool unreached = std::isinf(dist[static_cast<size_t>(next)]);
      if (!unreached && static_cast<int>(seeds.size()) >= options_.chart_count) break;
      if (dist[static_cast<size_t>(next)] == 0) break;  // fewer faces than charts
    }
    return seeds;
  }

  void grow(const std::vector<int32_t>& seeds, const std::vector<Eigen::MatrixXd>& proxies,
            std::vector<int32_t>& chart) const {
    std::fill(chart.begin(), chart.end(), -1);
    struct Entry {
      double cost;
      int32_t face, chart;
      bool operator>(const Entry& o) const { return cost > o.cost; }
    };
    std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
    for (size_t c = 0; c < seeds.size(); ++c) queue.push({0.0, seeds[c], static_cast<int32_t>(c)});
    while (!queue.empty()) {
      const Entry e = queue.top();
      queue.pop();
      if (chart[static_cast<size_t>(e.face)] >= 0) continue;
      chart[static_cast<size_t>(e.face)] = e.chart;
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency_(e.face, k);
        if (g >= 0 && chart[static_cast<size_t>(g)] < 0) queue.push({cost(g, e.chart, seeds, proxies), g, e.chart});
      }
    }
    // Faces no seed reaches (a component without a seed cannot occur: farthest_seeds covers
    // every component) would stay −1; give them their own chart defensively.
    int32_t extra = static_cast<int32_t>(seeds.size());
    for (int32_t& c : chart) {
      if (c < 0) c = extra++;
    }
  }

  void fit_proxies(const std::vector<int32_t>& chart, int32_t charts, std::vector<Eigen::MatrixXd>& proxies) const {
    const Eigen::Index n = nf_.edge1.rows();
    proxies.assign(static_cast<size_t>(charts), Eigen::MatrixXd::Zero(n, n));
    for (size_t f = 0; f < chart.size(); ++f) {
      if (chart[f] >= charts) continue;
      const auto a = nf_.edge1.col(static_cast<Eigen::Index>(f)), b = nf_.edge2.col(static_cast<Eigen::Index>(f));
      Eigen::MatrixXd& S = proxies[static_cast<size_t>(chart[f])];
      S.noalias() += a * b.transpose();
      S.noalias() -= b * a.transpose();
    }
    for (Eigen::MatrixXd& S : proxies) {
      const double norm = S.norm() / std::sqrt(2.0);  // the bivector norm of Σ B_f
      if (norm > 0) S /= norm;
    }
  }

  // Each chart's face farthest from its border (Sander 2003 §3.1's re-seeding).
  std::vector<int32_t> reseed(const std::vector<int32_t>& chart, const std::vector<int32_t>& seeds) const {
    const auto F = static_cast<int32_t>(faces_.rows());
    std::vector<std::vector<int32_t>> border(seeds.size());
    for (int32_t f = 0; f < F; ++f) {
      const int32_t c = chart[static_cast<size_t>(f)];
      if (c >= static_cast<int32_t>(seeds.size())) continue;
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency_(f, k);
        if (g < 0 || chart[static_cast<size_t>(g)] != c) {
          border[static_cast<size_t>(c)].push_back(f);
          break;
        }
      }
    }
    std::vector<double> dist(static_cast<size_t>(F), kInf);
    std::vector<int32_t> next = seeds;
    const auto members = faces_by_chart(chart, 1 + *std::max_element(chart.begin(), chart.end()));
    for (size_t c = 0; c < seeds.size(); ++c) {
      if (border[c].empty()) continue;  // a closed chart keeps its seed; the disc repair splits it
      const auto cc = static_cast<int32_t>(c);
      dual_dijkstra(adjacency_, weight_, border[c], [&](int32_t g) { return chart[static_cast<size_t>(g)] == cc; },
                    dist);
      next[c] = argmax(dist, members[c]);
    }
    return next;
  }

  // ---- Edge straightening (§5.2.3) ------------------------------------------------------------

  // The thesis's E_combined of a chart (eq. 5.4) in normalised animation space:
  // (Σ|B_f| + ρ perimeter²/4π) / |Σ B_f|, with ρ = 0.2 (its §8.4 value); +∞ for |Σ B_f| = 0.
  double combined_metric(const std::vector<int32_t>& chart, int32_t c) const {
    const Eigen::Index n = nf_.edge1.rows();
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, n);
    double area = 0, perimeter = 0;
    for (Eigen::Index f = 0; f < faces_.rows(); ++f) {
      if (chart[static_cast<size_t>(f)] != c) continue;
      const auto a = nf_.edge1.col(f), b = nf_.edge2.col(f);
      S.noalias() += a * b.transpose();
      S.noalias() -= b * a.transpose();
      area += bivector_norm_[static_cast<size_t>(f)];
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency_(f, k);
        if (g < 0 || chart[static_cast<size_t>(g)] != c) perimeter += edge_length(f, k);
      }
    }
    const double projected = S.norm() / std::sqrt(2.0);
    if (!(projected > 0)) return kInf;
    // |B_f| is twice the triangle's area; so is |Σ B_f| of the projected area: the ratio holds.
    return (area + 0.2 * 2 * perimeter * perimeter / (4 * M_PI)) / projected;
  }

  // L2,2 length of edge k (corners k, k+1) of face f.
  double edge_length(Eigen::Index f, int k) const {
    if (k == 0) return nf_.edge1.col(f).norm();
    if (k == 2) return nf_.edge2.col(f).norm();
    return (nf_.edge2.col(f) - nf_.edge1.col(f)).norm();
  }

  // One pass over the borders between two charts: each chain of border edges between two corners
  // (vertices where three or more charts meet, or on the mesh's own border) is replaced by the
  // shortest path between the corners through the two charts' union — accepted only if both
  // charts stay discs and neither one's E_combined grows by more than 1.2× (the thesis's ratio;
  // where it would, the thesis retries a path over the original vertices, which is not done
  // here: the border is kept). Returns the borders straightened.
  int straighten(std::vector<int32_t>& chart) const {
    const auto F = static_cast<int32_t>(faces_.rows());
    const auto V = faces_.maxCoeff() + 1;
    // Charts around each vertex, and which vertices lie on the mesh's border.
    std::vector<std::vector<int32_t>> around(static_cast<size_t>(V));
    std::vector<char> mesh_border(static_cast<size_t>(V), 0);
    for (int32_t f = 0; f < F; ++f) {
      for (int k = 0; k < 3; ++k) {
        auto& list = around[static_cast<size_t>(faces_(f, k))];
        if (std::find(list.begin(), list.end(), chart[static_cast<size_t>(f)]) == list.end()) list.push_back(chart[static_cast<size_t>(f)]);
        if (adjacency_(f, k) < 0) {
          mesh_border[static_cast<size_t>(faces_(f, k))] = 1;
          mesh_border[static_cast<size_t>(faces_(f, (k + 1) % 3))] = 1;
        }
      }
    }
    const auto is_corner = [&](int32_t v) { return around[static_cast<size_t>(v)].size() >= 3 || mesh_border[static_cast<size_t>(v)]; };
    // Border edges between two charts, by vertex.
    struct BorderEdge {
      int32_t other;   // the other vertex
      int32_t a, b;    // the two charts (a < b)
    };
    std::vector<std::vector<BorderEdge>> border(static_cast<size_t>(V));
    for (int32_t f = 0; f < F; ++f) {
      for (int k = 0; k < 3; ++k) {
        const int32_t g = adjacency_(f, k);
        if (g < f) continue;  // each edge once; mesh-border edges are not chart borders
        const int32_t cf = chart[static_cast<size_t>(f)], cg = chart[static_cast<size_t>(g)];
        if (cf == cg) continue;
        const int32_t u = faces_(f, k), w = faces_(f, (k + 1) % 3);
        border[static_cast<size_t>(u)].push_back({w, std::min(cf, cg), std::max(cf, cg)});
        border[static_cast<size_t>(w)].push_back({u, std::min(cf, cg), std::max(cf, cg)});
      }
    }
    // Chains: walk from each corner along each border edge until the next corner.
    struct Chain {
      int32_t from, to, a, b;
      std::vector<int32_t> vertices;  // from … to
    };
    std::vector<Chain> chains;
    for (int32_t v = 0; v < V; ++v) {
      if (!is_corner(v)) continue;
      for (const BorderEdge& start : border[static_cast<size_t>(v)]) {
        Chain ch{v, -1, start.a, start.b, {v}};
        int32_t prev = v, cur = start.other;
        while (true) {
          ch.vertices.push_back(cur);
          if (is_corner(cur) || ch.vertices.size() > static_cast<size_t>(V)) break;
          int32_t next = -1;
          for (const BorderEdge& e : border[static_cast<size_t>(cur)]) {
            if (e.a == ch.a && e.b == ch.b && e.other != prev) next = e.other;
          }
          if (next < 0) break;
          prev = cur;
          cur = next;
        }
        ch.to = ch.vertices.back();
        if (is_corner(ch.to) && ch.to != v && v < ch.to && ch.vertices.size() > 2) chains.push_back(std::move(ch));
      }
    }
    // Edge lengths by vertex pair.
    std::unordered_map<uint64_t, double> length;
    for (int32_t f = 0; f < F; ++f) {
      for (int k = 0; k < 3; ++k) length[edge_key(faces_(f, k), faces_(f, (k + 1) % 3))] = edge_length(f, k);
    }
    int straightened = 0;
    std::vector<double> dist(static_cast<size_t>(V), kInf);
    std::vector<int32_t> parent(static_cast<size_t>(V), -1);
    for (const Chain& ch : chains) {
      // Still a border of the same two charts (an earlier straightening may have moved it)?
      bool valid = true;
      for (size_t i = 0; i + 1 < ch.vertices.size() && valid; ++i) {
        bool found = false;
        for (int32_t f : faces_around_edge(ch.vertices[i], ch.vertices[i + 1])) found = found || chart[static_cast<size_t>(f)] == ch.a;
        bool found_b = false;
        for (int32_t f : faces_around_edge(ch.vertices[i], ch.vertices[i + 1])) found_b = found_b || chart[static_cast<size_t>(f)] == ch.b;
        valid = found && found_b;
      }
      if (!valid) continue;
      // Faces of the union, and vertices a path may use: the corners, and vertices whose faces
      // all lie in the union and that are no corner.
      std::vector<int32_t> union_faces;
      for (int32_t f = 0; f < F; ++f) {
        const int32_t c = chart[static_cast<size_t>(f)];
        if (c == ch.a || c == ch.b) union_faces.push_back(f);
      }
      std::unordered_map<int32_t, char> usable;
      for (int32_t f : union_faces) {
        for (int k = 0; k < 3; ++k) usable[faces_(f, k)] = 1;
      }
      for (int32_t f = 0; f < F; ++f) {
        const int32_t c = chart[static_cast<size_t>(f)];
        if (c == ch.a || c == ch.b) continue;
        for (int k = 0; k < 3; ++k) {
          const auto it = usable.find(faces_(f, k));
          if (it != usable.end()) it->second = 0;
        }
      }
      for (auto& [v, ok] : usable) {
        if (mesh_border[static_cast<size_t>(v)]) ok = 0;
      }
      usable[ch.from] = usable[ch.to] = 1;
      // Dijkstra over the union's interior edges.
      std::unordered_map<int32_t, std::vector<std::pair<int32_t, double>>> graph;
      for (int32_t f : union_faces) {
        for (int k = 0; k < 3; ++k) {
          const int32_t u = faces_(f, k), w = faces_(f, (k + 1) % 3);
          if (usable[u] && usable[w]) graph[u].emplace_back(w, length[edge_key(u, w)]);
        }
      }
      for (const auto& [v, unused] : usable) {
        dist[static_cast<size_t>(v)] = kInf;
        parent[static_cast<size_t>(v)] = -1;
      }
      using Entry = std::pair<double, int32_t>;
      std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
      dist[static_cast<size_t>(ch.from)] = 0;
      queue.emplace(0.0, ch.from);
      while (!queue.empty()) {
        const auto [d, u] = queue.top();
        queue.pop();
        if (d > dist[static_cast<size_t>(u)] || u == ch.to) continue;
        for (const auto& [w, l] : graph[u]) {
          if (w != ch.to && w != ch.from && !usable[w]) continue;
          if (d + l < dist[static_cast<size_t>(w)]) {
            dist[static_cast<size_t>(w)] = d + l;
            parent[static_cast<size_t>(w)] = u;
            queue.emplace(d + l, w);
          }
        }
      }
      if (!std::isfinite(dist[static_cast<size_t>(ch.to)])) continue;
      std::vector<int32_t> path{ch.to};
      while (path.back() != ch.from) path.push_back(parent[static_cast<size_t>(path.back())]);
      std::unordered_set<uint64_t> cut;
      for (size_t i = 0; i + 1 < path.size(); ++i) {
        cut.insert(edge_key(path[i], path[i + 1]));
        cut.insert(edge_key(path[i + 1], path[i]));
      }
      // The union cut along the new path: two components, labelled by their overlap with a.
      std::unordered_map<int32_t, int> component;
      for (int32_t f : union_faces) component[f] = -1;
      int components = 0;
      for (int32_t f : union_faces) {
        if (component[f] >= 0) continue;
        std::vector<int32_t> stack{f};
        component[f] = components;
        while (!stack.empty()) {
          const int32_t g = stack.back();
          stack.pop_back();
          for (int k = 0; k < 3; ++k) {
            const int32_t h = adjacency_(g, k);
            if (h < 0 || cut.count(edge_key(faces_(g, k), faces_(g, (k + 1) % 3)))) continue;
            const auto it = component.find(h);
            if (it == component.end() || it->second >= 0) continue;
            it->second = components;
            stack.push_back(h);
          }
        }
        ++components;
      }
      if (components != 2) continue;
      double overlap[2] = {0, 0};
      for (int32_t f : union_faces) {
        if (chart[static_cast<size_t>(f)] == ch.a) overlap[component[f]] += bivector_norm_[static_cast<size_t>(f)];
      }
      const int side_a = overlap[0] >= overlap[1] ? 0 : 1;
      const double before_a = combined_metric(chart, ch.a), before_b = combined_metric(chart, ch.b);
      std::vector<int32_t> trial = chart;
      for (int32_t f : union_faces) trial[static_cast<size_t>(f)] = component[f] == side_a ? ch.a : ch.b;
      if (trial == chart) continue;
      if (!is_disc(faces_, trial, ch.a) || !is_disc(faces_, trial, ch.b)) continue;
      if (combined_metric(trial, ch.a) > 1.2 * before_a || combined_metric(trial, ch.b) > 1.2 * before_b) continue;
      chart = std::move(trial);
      ++straightened;
    }
    return straightened;
  }

  std::vector<int32_t> faces_around_edge(int32_t u, int32_t w) const {
    std::vector<int32_t> out;
    const auto it = edge_faces_.find(edge_key(u, w));
    if (it != edge_faces_.end()) out.push_back(it->second);
    const auto jt = edge_faces_.find(edge_key(w, u));
    if (jt != edge_faces_.end()) out.push_back(jt->second);
    return out;
  }

  void smooth(std::vector<int32_t>& chart, const std::vector<int32_t>& seeds) const {
    std::vector<char> is_seed(chart.size(), 0);
    for (int32_t s : seeds) is_seed[static_cast<size_t>(s)] = 1;
    for (int pass = 0; pass < options_.smoothing_passes; ++pass) {
      bool changed = false;
      for (size_t f = 0; f < chart.size(); ++f) {
        if (is_seed[f]) continue;
        int32_t n[3];
        for (int k = 0; k < 3; ++k) {
          const int32_t g = adjacency_(static_cast<Eigen::Index>(f), k);
          n[k] = g < 0 ? -1 : chart[static_cast<size_t>(g)];
        }
        for (int k = 0; k < 3; ++k) {
          const int32_t other = n[k];
          if (other < 0 || other == chart[f]) continue;
          if ((n[0] == other) + (n[1] == other) + (n[2] == other) >= 2) {
            chart[f] = other;
            changed = true;
            break;
          }
        }
      }
      if (!changed) break;
    }
  }

  // Splits every chart into connected components, then every non-disc in two, until all are discs.
  void make_discs(std::vector<int32_t>& chart) const {
    const auto F = static_cast<int32_t>(faces_.rows());
    // Connected components of each chart.
    {
      std::vector<int32_t> component(static_cast<size_t>(F), -1);
      int32_t next = 0;
      for (int32_t f = 0; f < F; ++f) {
        if (component[static_cast<size_t>(f)] >= 0) continue;
        std::vector<int32_t> stack{f};
        component[static_cast<size_t>(f)] = next;
        while (!stack.empty()) {
          const int32_t g = stack.back();
          stack.pop_back();
          for (int k = 0; k < 3; ++k) {
            const int32_t h = adjacency_(g, k);
            if (h >= 0 && component[static_cast<size_t>(h)] < 0 && chart[static_cast<size_t>(h)] == chart[static_cast<size_t>(f)]) {
              component[static_cast<size_t>(h)] = next;
              stack.push_back(h);
            }
          }
        }
        ++next;
      }
      chart = std::move(component);
    }
    int32_t charts = renumber(chart);
    for (int32_t c = 0, n = charts; c < n; ++c) split_until_discs(chart, c, charts);
  }

 public:
  // Splits chart c in two: Voronoi cells of its two mutually farthest faces under the L2,2
  // distance across faces (each cell connected: a face's shortest path to its seed stays in its
  // cell). The second cell gets id `fresh`. Returns false for a one-face chart.
  bool split_in_two(std::vector<int32_t>& chart, int32_t c, int32_t fresh) const {
    const auto F = static_cast<int32_t>(faces_.rows());
    std::vector<int32_t> members;
    for (int32_t f = 0; f < F; ++f) {
      if (chart[static_cast<size_t>(f)] == c) members.push_back(f);
    }
    if (members.size() < 2) return false;
    std::vector<double> dist(static_cast<size_t>(F), kInf);
    const auto inside = [&](int32_t g) { return chart[static_cast<size_t>(g)] == c; };
    dual_dijkstra(adjacency_, weight_, {members.front()}, inside, dist);
    const int32_t a = argmax(dist, members);
    for (int32_t f : members) dist[static_cast<size_t>(f)] = kInf;
    dual_dijkstra(adjacency_, weight_, {a}, inside, dist);
    const int32_t b = argmax(dist, members);
    const std::vector<double> from_a(dist);
    for (int32_t f : members) dist[static_cast<size_t>(f)] = kInf;
    dual_dijkstra(adjacency_, weight_, {b}, inside, dist);
    for (int32_t f : members) {
      if (dist[static_cast<size_t>(f)] < from_a[static_cast<size_t>(f)]) chart[static_cast<size_t>(f)] = fresh;
    }
    return true;
  }

  // Splits chart c (and the parts it is split into) until each is a disc; new charts take ids
  // from `next` up. Returns the ids now covering c's faces.
  std::vector<int32_t> split_until_discs(std::vector<int32_t>& chart, int32_t c, int32_t& next) const {
    std::vector<int32_t> pending{c}, done;
    while (!pending.empty()) {
      const int32_t d = pending.back();
      pending.pop_back();
      if (is_disc(faces_, chart, d) || !split_in_two(chart, d, next)) {
        done.push_back(d);
        continue;
      }
      pending.push_back(d);
      pending.push_back(next++);
    }
    return done;
  }

 private:
  const FaceMatrix& faces_;
  const NormalisedFaces& nf_;
  ChartOptions options_;
  Adjacency adjacency_;
  Eigen::MatrixXd weight_;
  std::vector<double> bivector_norm_;
  std::unordered_map<uint64_t, int32_t> edge_faces_;  // directed edge → its face
};

}  // namespace

Adjacency face_adjacency(const FaceMatrix& faces) {
  std::unordered_map<uint64_t, int32_t> owner;
  owner.reserve(static_cast<size_t>(3 * faces.rows()));
  std::unordered_set<uint64_t> repeated;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const uint64_t key = edge_key(faces(f, k), faces(f, (k + 1) % 3));
      if (!owner.emplace(key, static_cast<int32_t>(f)).second) repeated.insert(key);
    }
  }
  Adjacency adjacency(faces.rows(), 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = faces(f, k), b = faces(f, (k + 1) % 3);
      const uint64_t twin = edge_key(b, a);
      const auto it = owner.find(twin);
      adjacency(f, k) = (it == owner.end() || repeated.count(twin) || repeated.count(edge_key(a, b))) ? -1 : it->second;
    }
  }
  return adjacency;
}

bool is_disc(const FaceMatrix& faces, const std::vector<int32_t>& chart_of_face, int32_t chart) {
  std::vector<int32_t> members;
  for (size_t f = 0; f < chart_of_face.size(); ++f) {
    if (chart_of_face[f] == chart) members.push_back(static_cast<int32_t>(f));
  }
  if (members.empty()) return false;
  std::unordered_map<uint64_t, int> directed;  // directed edge → count
  std::unordered_set<int32_t> vertices;
  for (int32_t f : members) {
    for (int k = 0; k < 3; ++k) {
      vertices.insert(faces(f, k));
      ++directed[edge_key(faces(f, k), faces(f, (k + 1) % 3))];
    }
  }
  long edges = 0;
  std::unordered_map<int32_t, int> border_out;
  for (const auto& [key, count] : directed) {
    if (count > 1) return false;  // a repeated directed edge: not an oriented manifold
    const auto a = static_cast<int32_t>(key >> 32), b = static_cast<int32_t>(key & 0xffffffffu);
    const bool has_twin = directed.count(edge_key(b, a)) > 0;
    if (!has_twin) {
      ++edges;
      if (++border_out[a] > 1) return false;
    } else if (a < b) {
      ++edges;
    }
  }
  if (border_out.empty()) return false;  // closed
  const long euler = static_cast<long>(vertices.size()) - edges + static_cast<long>(members.size());
  if (euler != 1) return false;
  // Connected across edges.
  std::unordered_map<uint64_t, int32_t> owner;
  for (int32_t f : members) {
    for (int k = 0; k < 3; ++k) owner[edge_key(faces(f, k), faces(f, (k + 1) % 3))] = f;
  }
  std::unordered_set<int32_t> seen{members.front()};
  std::vector<int32_t> stack{members.front()};
  while (!stack.empty()) {
    const int32_t f = stack.back();
    stack.pop_back();
    for (int k = 0; k < 3; ++k) {
      const auto it = owner.find(edge_key(faces(f, (k + 1) % 3), faces(f, k)));
      if (it != owner.end() && seen.insert(it->second).second) stack.push_back(it->second);
    }
  }
  return seen.size() == members.size();
}

std::vector<int32_t> split_chart(const FaceMatrix& faces, const NormalisedFaces& normalised,
                                 std::vector<int32_t>& chart_of_face, int32_t chart, int32_t& next_id) {
  const Segmenter segmenter(faces, normalised, ChartOptions{});
  std::vector<int32_t> ids;
  if (!segmenter.split_in_two(chart_of_face, chart, next_id)) return {chart};
  const int32_t second = next_id++;
  for (int32_t c : {chart, second}) {
    for (int32_t id : segmenter.split_until_discs(chart_of_face, c, next_id)) ids.push_back(id);
  }
  return ids;
}

Result<std::vector<int32_t>> segment_charts(const FaceMatrix& faces, const NormalisedFaces& normalised,
                                            const ChartOptions& options) {
  if (faces.rows() == 0) return make_error(ErrorCode::kInvalidArgument, "segment_charts: the mesh has no faces");
  if (options.chart_count < 1) {
    return make_error(ErrorCode::kInvalidArgument,
                      "segment_charts: chart_count should be ≥ 1, got " + std::to_string(options.chart_count));
  }
  if (normalised.edge1.cols() != faces.rows() || normalised.edge2.cols() != faces.rows() ||
      normalised.centroid.cols() != faces.rows() || normalised.edge2.rows() != normalised.edge1.rows() ||
      normalised.centroid.rows() != normalised.edge1.rows()) {
    return make_error(ErrorCode::kInvalidArgument, "segment_charts: normalised face vectors should be n × " +
                                                       std::to_string(faces.rows()));
  }
  Segmenter segmenter(faces, normalised, options);
  return segmenter.run();
}

}  // namespace animspace::atlas
