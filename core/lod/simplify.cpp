#include "core/lod/simplify.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <numbers>
#include <optional>
#include <queue>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include "core/lod/influence_simplification.h"
#include "core/lod/surface_quadrics.h"

namespace animspace::lod {

namespace as = animation_space;

namespace {

using Mesh = OpenMesh::TriMesh_ArrayKernelT<>;
using Vector2 = Eigen::Vector2d;

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

// The simplifier's working set: OpenMesh's connectivity (numbered like the input), the mesh state
// that the records are cut from, rest positions for the normal guard, every vertex in normalised
// animation space (y = C p with C = P^½, §3.3.2, so that L2,2 inner products are dot products),
// and the two queues. The normalised coordinates are dense (4b per vertex): they trade memory for
// not merging sparse bone lists in the innermost loop (§6.2.2 notes the same trade).
class Simplifier {
 public:
  Simplifier(const as::AnimationSpaceModel& model, const as::AnimationSpaceMetrics& metrics, Eigen::MatrixXd C,
             const SimplifyOptions& options, const ChartUvs* charts)
      : model_(model),
        charts_(charts),
        C_(std::move(C)),
        options_(options),
        cos_max_deviation_(std::cos(options.max_normal_deviation_degrees * std::numbers::pi / 180.0)),
        state_(MeshState::from_model(model)) {
    if (options.influence_simplification) influences_.emplace(metrics.P);
  }

  Status build_connectivity() {
    mesh_.request_vertex_status();
    mesh_.request_edge_status();
    mesh_.request_halfedge_status();
    mesh_.request_face_status();
    const int V = model_.vertex_count();
    std::vector<int> used(static_cast<size_t>(V), 0);
    for (int v = 0; v < V; ++v) mesh_.add_vertex(Mesh::Point(0, 0, 0));
    for (Eigen::Index f = 0; f < model_.faces.rows(); ++f) {
      const auto a = Mesh::VertexHandle(model_.faces(f, 0));
      const auto b = Mesh::VertexHandle(model_.faces(f, 1));
      const auto c = Mesh::VertexHandle(model_.faces(f, 2));
      const Mesh::FaceHandle handle = mesh_.add_face(a, b, c);
      if (!handle.is_valid() || handle.idx() != f) {
        return invalid("face " + std::to_string(f) + " (" + std::to_string(a.idx()) + ", " + std::to_string(b.idx()) +
                       ", " + std::to_string(c.idx()) +
                       ") makes the mesh non-manifold or repeats a vertex; level of detail needs a manifold "
                       "triangle mesh");
      }
      for (int k = 0; k < 3; ++k) used[static_cast<size_t>(model_.faces(f, k))] = 1;
    }
    for (int v = 0; v < V; ++v) {
      if (!used[static_cast<size_t>(v)]) {
        return invalid("vertex " + std::to_string(v) + " is used by no face; level of detail needs every vertex on "
                       "the surface");
      }
    }
    rest_.resize(static_cast<size_t>(V));
    normalised_.resize(C_.rows(), V);
    for (int v = 0; v < V; ++v) update_vertex_geometry(v);
    if (options_.cost == CollapseCost::kQuadric) {
      quadrics_.emplace(normalised_, model_.faces);
      vertex_error_.assign(static_cast<size_t>(V), 0.0);  // every vertex on its own planes
    }
    return Status::Ok();
  }

  ProgressiveMesh run() {
    const int V = model_.vertex_count();
    collapse_version_.assign(static_cast<size_t>(V), 0);
    influence_version_.assign(static_cast<size_t>(V), 0);
    pending_removal_.resize(static_cast<size_t>(V));
    // Negligible removals first, in order of their L2,2 motion, with no neighbour updates
    // (SimplifyOptions::negligible_cost): what they move is below any error either cost sees.
    Eigen::AlignedBox3d box;
    for (const Eigen::Vector3d& r : rest_) box.extend(r);
    negligible_ = options_.negligible_cost * box.diagonal().norm();
    prepass_ = true;
    for (int v = 0; v < V; ++v) schedule_influence(v);
    while (const Candidate* removal = top(removals_, influence_version_)) {
      if (!(removal->deviation < negligible_)) break;
      const Candidate c = *removal;
      removals_.pop();
      apply_influence_removal(c, /*update_neighbours=*/false);
    }
    prepass_ = false;
    removals_ = Queue();
    for (int v = 0; v < V; ++v) schedule_influence(v);
    for (int v = 0; v < V; ++v) schedule_collapse(v);
    const int64_t collapsible = std::max(0, V - options_.min_vertices);
    for (size_t step = 0;; ++step) {
      if (step % 1024 == 0) {
        report_progress(options_.progress, "simplification", V - state_.live_vertex_count(), collapsible);
      }
      const bool collapses_allowed = state_.live_vertex_count() > options_.min_vertices;
      const Candidate* collapse = collapses_allowed ? top(collapses_, collapse_version_) : nullptr;
      const Candidate* removal = top(removals_, influence_version_);
      if (!collapse && !removal) break;
      if (collapse && (!removal || collapse->cost <= removal->cost)) {
        const Candidate c = *collapse;
        collapses_.pop();
        // A collapse elsewhere may have changed v's ring so that u → v now breaks the link
        // condition without touching u's ring; look again before applying.
        const Mesh::HalfedgeHandle h =
            mesh_.find_halfedge(Mesh::VertexHandle(c.vertex), Mesh::VertexHandle(c.target));
        if (!h.is_valid() || !collapse_legal(h) || (charts_ && !atlas_still_allows(c.vertex, c.target))) {
          schedule_collapse(c.vertex);
          continue;
        }
        apply_collapse(c);
      } else {
        const Candidate c = *removal;
        removals_.pop();
        apply_influence_removal(c);
      }
    }
    report_progress(options_.progress, "simplification", collapsible, collapsible);
    ProgressiveMesh pm;
    pm.skeleton = model_.skeleton;
    pm.input_vertex_count = V;
    pm.input_face_count = static_cast<int>(model_.faces.rows());
    pm.base = state_.to_model(model_.skeleton, &pm.base_vertex_ids, &pm.base_face_ids);
    pm.steps = std::move(steps_);
    return pm;
  }

 private:
  struct Candidate {
    double cost = 0;       // the queue's order: SimplifyOptions::cost's units
    double deviation = 0;  // the step's memoryless deviation (Simplification::cost)
    int32_t vertex = -1;
    int32_t target = -1;
    uint32_t version = 0;
    // Min-heap on cost; ties by vertex so the sequence does not depend on queue internals.
    bool operator<(const Candidate& other) const {
      if (cost != other.cost) return cost > other.cost;
      return vertex > other.vertex;
    }
  };
  using Queue = std::priority_queue<Candidate>;

  const Candidate* top(Queue& queue, const std::vector<uint32_t>& versions) {
    while (!queue.empty()) {
      const Candidate& c = queue.top();
      if (state_.vertex_alive(c.vertex) && versions[static_cast<size_t>(c.vertex)] == c.version) return &c;
      queue.pop();
    }
    return nullptr;
  }

  Eigen::Vector3d rest_position(const VertexState& s) const {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (size_t k = 0; k < s.bones.size(); ++k) {
      v += model_.skeleton.rest[static_cast<size_t>(s.bones[k])] * s.position.col(static_cast<Eigen::Index>(k));
    }
    return v.head<3>();
  }

  // The rest position (normal guard) and y = C p (costs) of vertex v's current state.
  void update_vertex_geometry(int v) {
    const VertexState& s = state_.vertex(v);
    rest_[static_cast<size_t>(v)] = rest_position(s);
    normalised_.col(v).setZero();
    add_normalised(C_, s.bones.data(), s.position, normalised_.col(v));
  }

  // u's one-ring in rotation order: ring[k] = a_k; face k lies between a_k and a_{k+1} (wrapping
  // for an interior vertex; a boundary vertex has one face fewer than neighbours).
  struct Ring {
    std::vector<int32_t> vertices;
    std::vector<Mesh::HalfedgeHandle> outgoing;  // u → a_k
    bool boundary = false;
    int face_count() const { return static_cast<int>(vertices.size()) - (boundary ? 1 : 0); }
  };

  void ring_of(int u, Ring& ring) const {
    ring.vertices.clear();
    ring.outgoing.clear();
    ring.boundary = false;
    const auto vh = Mesh::VertexHandle(u);
    const Mesh::HalfedgeHandle start = mesh_.halfedge_handle(vh);
    if (!start.is_valid()) return;
    ring.boundary = mesh_.is_boundary(start);  // OpenMesh keeps a boundary halfedge as outgoing
    Mesh::HalfedgeHandle h = start;
    do {
      ring.vertices.push_back(mesh_.to_vertex_handle(h).idx());
      ring.outgoing.push_back(h);
      const Mesh::HalfedgeHandle back = mesh_.opposite_halfedge_handle(h);
      if (mesh_.is_boundary(back)) break;  // reached the other boundary edge
      h = mesh_.next_halfedge_handle(back);  // the next outgoing halfedge, across face(back)
    } while (h != start);
  }

  // OpenMesh's decimater legality tests (BaseDecimaterT::is_collapse_legal) for u → v.
  bool collapse_legal(Mesh::HalfedgeHandle h) {
    if (!mesh_.is_collapse_ok(h)) return false;
    const auto u = mesh_.from_vertex_handle(h);
    const auto v = mesh_.to_vertex_handle(h);
    const Mesh::HalfedgeHandle back = mesh_.opposite_halfedge_handle(h);
    const Mesh::VertexHandle vl =
        mesh_.is_boundary(h) ? Mesh::VertexHandle() : mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h));
    const Mesh::VertexHandle vr =
        mesh_.is_boundary(back) ? Mesh::VertexHandle() : mesh_.to_vertex_handle(mesh_.next_halfedge_handle(back));
    if (vl.is_valid() && vr.is_valid() && mesh_.find_halfedge(vl, vr).is_valid() && mesh_.valence(vl) == 3 &&
        mesh_.valence(vr) == 3) {
      return false;  // would leave a doubled triangle
    }
    if (mesh_.is_boundary(u)) {
      if (!mesh_.is_boundary(v)) return false;
      if (vl.is_valid() && vr.is_valid()) return false;  // the edge must be a boundary edge
    }
    if (mesh_.cw_rotated_halfedge_handle(mesh_.cw_rotated_halfedge_handle(h)) == h) return false;
    return true;
  }

  // Which collapses out of u the atlas allows (chart_atlas.h; Merry 2007 §5.1, and §5.3 Fig. 5.5:
  // a border vertex may only be removed along its border): any (u inside one chart, no border
  // edge), none (u where three or more charts meet, or where a border reaches the mesh boundary),
  // or only along its two border edges, ring positions `along` — onto the next vertex of the same
  // border, the two faces on that edge being one of each chart.
  enum class ChartMoves { kAny, kNone, kAlongBorder };
  ChartMoves chart_moves(const Ring& ring, std::array<int, 2>& along) const {
    int count = 0;
    for (size_t k = 0; k < ring.outgoing.size(); ++k) {
      const Mesh::HalfedgeHandle h = ring.outgoing[k];
      const Mesh::FaceHandle left = mesh_.face_handle(h);
      const Mesh::FaceHandle right = mesh_.face_handle(mesh_.opposite_halfedge_handle(h));
      if (!left.is_valid() || !right.is_valid()) continue;  // the mesh boundary: the boundary rule's
      if (charts_->chart_of(left.idx()) == charts_->chart_of(right.idx())) continue;
      if (count < 2) along[static_cast<size_t>(count)] = static_cast<int>(k);
      ++count;
    }
    if (count == 0) return ChartMoves::kAny;
    if (count == 2 && !ring.boundary) return ChartMoves::kAlongBorder;
    return ChartMoves::kNone;
  }

  // A collapse along a border removes one face of each chart on edge u–v; it may not take the
  // last face of a chart at the two faces' other corners or at v, or a chart would lose that
  // vertex — a chart thinned away corner by corner until it vanishes, taking a vertex where three
  // charts met with it. Every vertex keeps the charts it touches. (Inside a chart this cannot
  // happen: the faces' other corners keep the chart across their edges with u.)
  bool border_collapse_keeps_charts(const Ring& ring, int m) const {
    const int n = static_cast<int>(ring.vertices.size());
    const int v = ring.vertices[static_cast<size_t>(m)];
    std::vector<int32_t>& removed = scratch_.removed_faces;
    removed.clear();
    for (const int k : {(m + n - 1) % n, m}) {  // faces a_{m−1}–a_m and a_m–a_{m+1}
      if (k >= ring.face_count()) continue;
      const Mesh::FaceHandle f = mesh_.face_handle(mesh_.opposite_halfedge_handle(ring.outgoing[static_cast<size_t>(k)]));
      const int32_t chart = charts_->chart_of(f.idx());
      removed.push_back(f.idx());
      const int x = ring.vertices[static_cast<size_t>(k == m ? (m + 1) % n : k)];
      int others = 0;
      for (const Mesh::FaceHandle g : mesh_.vf_range(Mesh::VertexHandle(x))) {
        if (g != f && charts_->chart_of(g.idx()) == chart) ++others;
      }
      if (others == 0) return false;
    }
    // v's charts afterwards: its faces but the removed ones, and u's other faces.
    std::vector<int32_t>& before = scratch_.charts_before;
    std::vector<int32_t>& after = scratch_.charts_after;
    before.clear();
    after.clear();
    for (const Mesh::FaceHandle g : mesh_.vf_range(Mesh::VertexHandle(v))) {
      before.push_back(charts_->chart_of(g.idx()));
      if (std::find(removed.begin(), removed.end(), g.idx()) == removed.end()) after.push_back(charts_->chart_of(g.idx()));
    }
    for (int k = 0; k < ring.face_count(); ++k) {
      if (k == m || (k + 1) % n == m) continue;
      after.push_back(charts_->chart_of(
          mesh_.face_handle(mesh_.opposite_halfedge_handle(ring.outgoing[static_cast<size_t>(k)])).idx()));
    }
    for (std::vector<int32_t>* set : {&before, &after}) {
      std::sort(set->begin(), set->end());
      set->erase(std::unique(set->begin(), set->end()), set->end());
    }
    return before == after;
  }

  // Every rule of the atlas for u → ring.vertices[m] (chart_atlas.h).
  bool atlas_allows(const Ring& ring, int m) const {
    std::array<int, 2> along = {-1, -1};
    switch (chart_moves(ring, along)) {
      case ChartMoves::kNone:
        return false;
      case ChartMoves::kAlongBorder:
        if ((m != along[0] && m != along[1]) || !border_collapse_keeps_charts(ring, m)) return false;
        break;
      case ChartMoves::kAny:
        break;
    }
    return uv_fan_keeps_orientation(ring, m);
  }

  // The same, again when the collapse is taken: a collapse elsewhere may have taken a face the
  // border rule counted on without touching u's ring (it then re-queues u).
  bool atlas_still_allows(int u, int v) const {
    Ring& ring = scratch_.ring;
    ring_of(u, ring);
    const auto at = std::find(ring.vertices.begin(), ring.vertices.end(), v);
    return at != ring.vertices.end() && atlas_allows(ring, static_cast<int>(at - ring.vertices.begin()));
  }

  // The UV fold guard (chart_atlas.h): every face of u's fan that survives u → v = ring.vertices[m]
  // keeps its chart's orientation in UV with a non-degenerate area once u's corner is v. Face k of
  // the ring runs a_k → u → a_{k+1} (ring_of), which is its corner order up to rotation.
  bool uv_fan_keeps_orientation(const Ring& ring, int m) const {
    const int n = static_cast<int>(ring.vertices.size());
    const int v = ring.vertices[static_cast<size_t>(m)];
    for (int k = 0; k < ring.face_count(); ++k) {
      const int k1 = (k + 1) % n;
      if (k == m || k1 == m) continue;  // vanishes with edge u–v
      const Mesh::FaceHandle f = mesh_.face_handle(mesh_.opposite_halfedge_handle(ring.outgoing[static_cast<size_t>(k)]));
      const int32_t c = charts_->chart_of(f.idx());
      const Eigen::Vector2d* tv = charts_->find(v, c);
      const Eigen::Vector2d* ta = charts_->find(ring.vertices[static_cast<size_t>(k)], c);
      const Eigen::Vector2d* tb = charts_->find(ring.vertices[static_cast<size_t>(k1)], c);
      // A corner's vertex always has a UV in its face's chart (chart_atlas.h's induction); v lacks
      // one only when u → v would join charts, which chart_moves has refused.
      if (tv == nullptr || ta == nullptr || tb == nullptr) return false;
      const double area = charts_->orientation(c) * signed_uv_area(*ta, *tv, *tb);
      const double scale = (*ta - *tv).squaredNorm() + (*tb - *tv).squaredNorm();
      if (!(area > 1e-12 * scale)) return false;
    }
    return true;
  }

  // Memoryless cost of u → ring.vertices[m] (§6.2.1), or nullopt when a guard refuses it.
  // `q` is the flattened ring, `gram` the L2,2 Gram matrix of d_k = p_{a_k} − p_u.
  std::optional<double> collapse_cost(int u, const Ring& ring, int m, const std::vector<Vector2>& q,
                                      const Eigen::MatrixXd& gram) const {
    const int n = static_cast<int>(ring.vertices.size());
    const int faces = ring.face_count();
    const auto next = [n](int k) { return (k + 1) % n; };
    // Faces of the old fan that survive, as (a_k, a_{k+1}); the two (or one) on edge u–v vanish.
    std::vector<int>& kept = scratch_.kept;
    kept.clear();
    for (int k = 0; k < faces; ++k) {
      if (k != m && next(k) != m) kept.push_back(k);
    }
    if (kept.empty()) return std::nullopt;
    // Fold-over in the flattening, and the rest-pose normal guard.
    const Vector2& qv = q[static_cast<size_t>(m)];
    const Eigen::Vector3d& ru = rest_[static_cast<size_t>(u)];
    const Eigen::Vector3d& rv = rest_[static_cast<size_t>(ring.vertices[static_cast<size_t>(m)])];
    for (const int k : kept) {
      const Vector2 e1 = q[static_cast<size_t>(k)] - qv;
      const Vector2 e2 = q[static_cast<size_t>(next(k))] - qv;
      const double area = e1.x() * e2.y() - e1.y() * e2.x();
      const double scale = e1.squaredNorm() + e2.squaredNorm();
      if (!(area > 1e-12 * scale)) return std::nullopt;
      const Eigen::Vector3d& ra = rest_[static_cast<size_t>(ring.vertices[static_cast<size_t>(k)])];
      const Eigen::Vector3d& rb = rest_[static_cast<size_t>(ring.vertices[static_cast<size_t>(next(k))])];
      const Eigen::Vector3d before = (ra - ru).cross(rb - ru);
      const Eigen::Vector3d after = (ra - rv).cross(rb - rv);
      const double after_norm = after.norm();
      if (!(after_norm > 0)) return std::nullopt;
      const double before_norm = before.norm();
      if (before_norm > 0 && before.dot(after) < cos_max_deviation_ * before_norm * after_norm) return std::nullopt;
    }
    // Deviations at the cell corners: combinations Σ c_k d_k, so their squared L2,2 norms are
    // cᵀ·gram·c. Corner 1: u (the origin) inside a new triangle (v, a_k, a_{k+1}).
    const auto norm2 = [&gram](const std::array<int, 3>& idx, const std::array<double, 3>& c) {
      double s = 0;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) s += c[static_cast<size_t>(i)] * c[static_cast<size_t>(j)] * gram(idx[static_cast<size_t>(i)], idx[static_cast<size_t>(j)]);
      }
      return s;
    };
    double worst = -1;
    for (const int k : kept) {
      const Vector2 a = q[static_cast<size_t>(k)] - qv;
      const Vector2 b = q[static_cast<size_t>(next(k))] - qv;
      const Vector2 o = -qv;
      const double det = a.x() * b.y() - a.y() * b.x();
      const double la = (o.x() * b.y() - o.y() * b.x()) / det;
      const double lb = (a.x() * o.y() - a.y() * o.x()) / det;
      const double lv = 1 - la - lb;
      const double tolerance = -1e-9;
      if (la >= tolerance && lb >= tolerance && lv >= tolerance) {
        // p_u − (lv p_v + la p_a + lb p_b) = −(lv d_m + la d_k + lb d_{k+1})
        worst = std::max(worst, norm2({m, k, next(k)}, {lv, la, lb}));
        break;
      }
    }
    if (worst < 0) return std::nullopt;  // the new fan does not cover u: the flattening folded
    // Corner 2: where an old edge u–a_k crosses a new edge v–a_j.
    for (int k = 0; k < n; ++k) {
      if (k == m) continue;
      const Vector2& qk = q[static_cast<size_t>(k)];
      for (int j = 0; j < n; ++j) {
        if (j == m || j == k || j == next(m) || next(j) == m) continue;
        const Vector2 e = q[static_cast<size_t>(j)] - qv;
        // t qk = qv + s e
        const double det = qk.x() * (-e.y()) - qk.y() * (-e.x());
        if (std::abs(det) < 1e-14 * (qk.squaredNorm() + e.squaredNorm())) continue;
        const double t = (qv.x() * (-e.y()) - qv.y() * (-e.x())) / det;
        const double s = (qk.x() * qv.y() - qk.y() * qv.x()) / det;
        if (t <= 0 || t >= 1 || s <= 0 || s >= 1) continue;
        // (1−t)p_u + t p_{a_k} − (1−s)p_v − s p_{a_j} = t d_k − (1−s) d_m − s d_j
        worst = std::max(worst, norm2({k, m, j}, {t, -(1 - s), -s}));
      }
    }
    return std::sqrt(std::max(0.0, worst));
  }

  // The cheapest legal collapse out of u, pushed onto the queue.
  void schedule_collapse(int u) {
    ++collapse_version_[static_cast<size_t>(u)];
    // Scratch buffers live in the simplifier: this runs hundreds of thousands of times.
    Ring& ring = scratch_.ring;
    ring_of(u, ring);
    const int n = static_cast<int>(ring.vertices.size());
    if (n < 2) return;
    if (charts_) {
      std::array<int, 2> along;
      if (chart_moves(ring, along) == ChartMoves::kNone) return;  // pinned by the atlas's borders
    }
    // d_k = p_{a_k} − p_u in normalised animation space, and their L2,2 Gram matrix.
    Eigen::MatrixXd& d = scratch_.d;
    d.resize(normalised_.rows(), n);
    for (int k = 0; k < n; ++k) d.col(k) = normalised_.col(ring.vertices[static_cast<size_t>(k)]) - normalised_.col(u);
    Eigen::MatrixXd& gram = scratch_.gram;
    gram.resize(n, n);
    gram.noalias() = d.transpose() * d;
    // Polar map (the flattening): |q_k| = ‖d_k‖₂,₂, and the angles between consecutive d_k
    // measured by ⟨·,·⟩₂,₂, scaled to 2π (interior) or π (boundary) as in Floater's map.
    const int faces = ring.face_count();
    std::vector<double>& length = scratch_.length;
    length.resize(static_cast<size_t>(n));
    for (int k = 0; k < n; ++k) length[static_cast<size_t>(k)] = std::sqrt(std::max(0.0, gram(k, k)));
    for (const double l : length) {
      if (!(l > 0)) return;  // a zero-length edge under P: no flattening
    }
    std::vector<double>& angle = scratch_.angle;
    angle.resize(static_cast<size_t>(faces));
    double total = 0;
    for (int k = 0; k < faces; ++k) {
      const int k1 = (k + 1) % n;
      const double c = gram(k, k1) / (length[static_cast<size_t>(k)] * length[static_cast<size_t>(k1)]);
      angle[static_cast<size_t>(k)] = std::acos(std::clamp(c, -1.0, 1.0));
      total += angle[static_cast<size_t>(k)];
    }
    if (!(total > 0)) return;
    const double scale = (ring.boundary ? std::numbers::pi : 2 * std::numbers::pi) / total;
    std::vector<Vector2>& q = scratch_.q;
    q.resize(static_cast<size_t>(n));
    double phi = 0;
    for (int k = 0; k < n; ++k) {
      q[static_cast<size_t>(k)] = length[static_cast<size_t>(k)] * Vector2(std::cos(phi), std::sin(phi));
      if (k < faces) {
        const double step = scale * angle[static_cast<size_t>(k)];
        if (!(step < std::numbers::pi - 1e-9)) return;  // an old triangle would fold in the map
        phi += step;
      }
    }
    // Cheapest first, so OpenMesh's topology test runs only until one candidate passes. The
    // memoryless deviation is computed for every candidate either way: its guards (folds in the
    // flattening, the normal guard) decide what is allowed, and it is the step's recorded cost.
    std::vector<CollapseOption>& costs = scratch_.costs;
    costs.clear();
    for (int m = 0; m < n; ++m) {
      if (ring.boundary && m != 0 && m != n - 1) continue;  // boundary vertices move along the boundary
      if (charts_ && !atlas_allows(ring, m)) continue;
      const std::optional<double> deviation = collapse_cost(u, ring, m, q, gram);
      if (!deviation) continue;
      const int v = ring.vertices[static_cast<size_t>(m)];
      // Quadric cost: the merged vertex, kept at y_v, against every original plane u and v
      // stand for (Q_u + Q_v)(y_v); v's part is its error so far.
      const double cost = quadrics_ ? quadrics_->error(u, normalised_.col(v)) + vertex_error_[static_cast<size_t>(v)]
                                    : *deviation;
      costs.push_back({cost, *deviation, m});
    }
    std::sort(costs.begin(), costs.end(), [](const CollapseOption& a, const CollapseOption& b) {
      return a.cost != b.cost ? a.cost < b.cost : a.m < b.m;
    });
    Candidate best;
    for (const CollapseOption& option : costs) {
      if (!collapse_legal(ring.outgoing[static_cast<size_t>(option.m)])) continue;
      best.cost = option.cost;
      best.deviation = option.deviation;
      best.target = ring.vertices[static_cast<size_t>(option.m)];
      break;
    }
    if (best.target < 0) return;
    best.vertex = u;
    best.version = collapse_version_[static_cast<size_t>(u)];
    collapses_.push(best);
  }

  // The removal to queue for v. Memoryless (and in the negligible pre-pass): the bone whose
  // removal moves v least in L2,2, costed by that motion (§6.3.1). Quadric: the bone whose
  // removal raises Q_v least, costed by that rise — the units of a collapse's cost, so that one
  // queue orders both by the harm they do to the original surface (issue #26). A motion within
  // the planes v stands for costs nothing there, as it changes no surface point's distance.
  void schedule_influence(int v) {
    ++influence_version_[static_cast<size_t>(v)];
    pending_removal_[static_cast<size_t>(v)].reset();
    const VertexState& state = state_.vertex(v);
    if (!influences_ || state.influence_count() < 2) return;
    std::optional<InfluenceRemoval> chosen;
    double cost = 0;
    if (!quadrics_ || prepass_) {
      Result<InfluenceRemoval> removal = influences_->cheapest_removal(state);
      if (!removal.ok()) return;  // a solver failure leaves the vertex as it is
      cost = removal->cost;
      chosen = std::move(*removal);
    } else {
      Eigen::VectorXd& moved = scratch_.moved;
      for (int slot = 0; slot < state.influence_count(); ++slot) {
        Result<InfluenceRemoval> removal = influences_->removal(state, slot);
        if (!removal.ok()) continue;
        moved = normalised_.col(v);
        add_normalised(C_, state.bones.data(), removal->correction, moved);
        const double rise = std::max(0.0, quadrics_->error(v, moved) - vertex_error_[static_cast<size_t>(v)]);
        if (!chosen || rise < cost) {
          cost = rise;
          chosen = std::move(*removal);
        }
      }
      if (!chosen) return;
    }
    const double deviation = chosen->cost;
    const int32_t bone = chosen->bone;
    pending_removal_[static_cast<size_t>(v)] = std::move(chosen);
    Candidate c;
    c.cost = cost;
    c.deviation = deviation;
    c.vertex = v;
    c.target = bone;
    c.version = influence_version_[static_cast<size_t>(v)];
    removals_.push(c);
  }

  void apply_collapse(const Candidate& c) {
    const int u = c.vertex;
    const auto uh = Mesh::VertexHandle(u);
    const Mesh::HalfedgeHandle h = mesh_.find_halfedge(uh, Mesh::VertexHandle(c.target));
    assert(h.is_valid());
    Simplification step;
    step.kind = SimplificationKind::kEdgeCollapse;
    step.cost = c.deviation;
    step.vertex = u;
    step.target = c.target;
    step.before = state_.vertex(u);
    for (const Mesh::HalfedgeHandle side : {h, mesh_.opposite_halfedge_handle(h)}) {
      if (!mesh_.is_boundary(side)) step.removed_faces.push_back(mesh_.face_handle(side).idx());
    }
    step.removed_face_corners.resize(static_cast<Eigen::Index>(step.removed_faces.size()), 3);
    for (size_t k = 0; k < step.removed_faces.size(); ++k) {
      step.removed_face_corners.row(static_cast<Eigen::Index>(k)) = state_.faces().row(step.removed_faces[k]);
    }
    std::vector<int32_t> neighbours;
    for (const Mesh::VertexHandle a : mesh_.vv_range(uh)) neighbours.push_back(a.idx());
    for (const Mesh::FaceHandle f : mesh_.vf_range(uh)) {
      if (std::find(step.removed_faces.begin(), step.removed_faces.end(), f.idx()) == step.removed_faces.end()) {
        step.moved_faces.push_back(f.idx());
      }
    }
    std::sort(step.moved_faces.begin(), step.moved_faces.end());
    mesh_.collapse(h);
    state_.apply(step);
    ++influence_version_[static_cast<size_t>(u)];
    ++collapse_version_[static_cast<size_t>(u)];
    pending_removal_[static_cast<size_t>(u)].reset();
    steps_.push_back(std::move(step));
    if (quadrics_) {
      const int v = c.target;
      quadrics_->merge(u, v);
      vertex_error_[static_cast<size_t>(v)] = quadrics_->error(v, normalised_.col(v));
      // v's error changed, so every collapse into v costs more now, and so may its removal.
      for (const Mesh::VertexHandle a : mesh_.vv_range(Mesh::VertexHandle(v))) {
        if (std::find(neighbours.begin(), neighbours.end(), a.idx()) == neighbours.end()) neighbours.push_back(a.idx());
      }
      schedule_influence(v);
    }
    // Every vertex whose one-ring changed: v and u's old neighbours (v among them); with
    // quadrics also v's other neighbours.
    for (const int32_t a : neighbours) schedule_collapse(a);
  }

  void apply_influence_removal(const Candidate& c, bool update_neighbours = true) {
    const int v = c.vertex;
    const std::optional<InfluenceRemoval>& removal = pending_removal_[static_cast<size_t>(v)];
    assert(removal);
    Simplification step;
    step.kind = SimplificationKind::kInfluenceRemoval;
    step.cost = removal->cost;
    step.vertex = v;
    step.target = removal->bone;
    step.before = state_.vertex(v);
    step.after = step.before;
    influences_->apply(*removal, step.after);
    state_.apply(step);
    update_vertex_geometry(v);
    if (quadrics_) vertex_error_[static_cast<size_t>(v)] = quadrics_->error(v, normalised_.col(v));
    steps_.push_back(std::move(step));
    // v moved: its own collapses and every collapse whose one-ring holds v change (Fig. 6.6).
    schedule_influence(v);
    if (!update_neighbours) return;
    schedule_collapse(v);
    for (const Mesh::VertexHandle a : mesh_.vv_range(Mesh::VertexHandle(v))) schedule_collapse(a.idx());
  }

  const as::AnimationSpaceModel& model_;
  const ChartUvs* charts_;  // the atlas's, or null
  Eigen::MatrixXd C_;  // P^½
  Eigen::MatrixXd normalised_;  // 4b × V, y = C p of every vertex
  SimplifyOptions options_;
  double cos_max_deviation_;
  Mesh mesh_;
  MeshState state_;
  std::vector<Eigen::Vector3d> rest_;
  std::optional<InfluenceSimplifier> influences_;
  std::optional<SurfaceQuadrics> quadrics_;  // CollapseCost::kQuadric only
  std::vector<double> vertex_error_;         // Q_v(y_v) of every live vertex
  double negligible_ = 0;                    // SimplifyOptions::negligible_cost in model units
  bool prepass_ = false;                     // taking the negligible removals
  std::vector<uint32_t> collapse_version_;
  std::vector<uint32_t> influence_version_;
  std::vector<std::optional<InfluenceRemoval>> pending_removal_;  // the removal each queued entry stands for
  Queue collapses_;
  Queue removals_;
  std::vector<Simplification> steps_;
  struct CollapseOption {
    double cost = 0;
    double deviation = 0;
    int m = -1;
  };
  struct Scratch {
    Ring ring;
    Eigen::MatrixXd d, gram;
    std::vector<double> length, angle;
    std::vector<Vector2> q;
    std::vector<CollapseOption> costs;
    std::vector<int> kept;
    std::vector<int32_t> removed_faces, charts_before, charts_after;
    Eigen::VectorXd moved;
  };
  mutable Scratch scratch_;
};

}  // namespace

Result<ProgressiveMesh> build_progressive_mesh(const as::AnimationSpaceModel& model,
                                               const as::AnimationSpaceMetrics& metrics,
                                               const SimplifyOptions& options) {
  ANIMSPACE_RETURN_IF_ERROR(as::validate(model));
  if (metrics.bone_count() != model.bone_count()) {
    return invalid("metrics: expected " + std::to_string(model.bone_count()) + " bones (the model's), got " +
                   std::to_string(metrics.bone_count()));
  }
  ANIMSPACE_RETURN_IF_ERROR(as::validate(metrics, model.bone_count()));
  if (model.faces.rows() == 0) return invalid("model: level of detail needs faces, the model has none");
  if (!std::isfinite(options.max_normal_deviation_degrees) || options.max_normal_deviation_degrees <= 0 ||
      options.max_normal_deviation_degrees > 180) {
    return invalid("max_normal_deviation_degrees: expected a value in (0, 180], got " +
                   std::to_string(options.max_normal_deviation_degrees));
  }
  if (!std::isfinite(options.negligible_cost) || options.negligible_cost < 0) {
    return invalid("negligible_cost: expected a finite value ≥ 0, got " + std::to_string(options.negligible_cost));
  }
  if (options.min_vertices < 3) {
    return invalid("min_vertices: expected at least 3, got " + std::to_string(options.min_vertices));
  }
  auto C = as::normalised_animation_space_matrix(metrics.P);
  if (!C) return invalid("metrics: " + C.error().message);
  std::optional<ChartUvs> charts;
  if (options.atlas) {
    auto built = ChartUvs::build(*options.atlas, model.faces);
    if (!built) return built.error();
    charts = std::move(*built);
  }
  Simplifier simplifier(model, metrics, std::move(*C), options, charts ? &*charts : nullptr);
  ANIMSPACE_RETURN_IF_ERROR(simplifier.build_connectivity());
  return simplifier.run();
}

}  // namespace animspace::lod
