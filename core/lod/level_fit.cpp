#include "core/lod/level_fit.h"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstring>
#include <cmath>
#include <limits>
#include <optional>
#include <queue>
#include <string>
#include <utility>

#include <Eigen/Cholesky>

#include "core/animspace/metrics.h"
#include "core/common/parallel.h"
#include "core/lod/influence_simplification.h"
#include "core/lod/vertex_state.h"

namespace animspace::lod {

namespace as = animation_space;

namespace {

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

// y = C p of every vertex of `model` (n × V).
Eigen::MatrixXd normalised_positions(const as::AnimationSpaceModel& model, const Eigen::MatrixXd& C) {
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(C.rows(), model.vertex_count());
  parallel_for_chunks(model.vertex_count(), 1024, [&](int64_t first, int64_t last) {
    for (auto v = static_cast<int>(first); v < static_cast<int>(last); ++v) {
      const int begin = model.influences.begin(v);
      add_normalised(C, model.influences.bones.data() + begin,
                     model.positions.middleCols(begin, model.influences.end(v) - begin), Y.col(v));
    }
  });
  return Y;
}

// The closest point to d (= y − A) of the triangle A + s e0 + t e1 (s, t ≥ 0, s + t ≤ 1), from
// the Gram entries a = e0·e0, b = e0·e1, c = e1·e1, d0 = e0·d, d1 = e1·d and dd = d·d: the
// unconstrained minimiser if it is inside, otherwise the best of the three edges.
struct Closest {
  double s = 0, t = 0, distance2 = 0;
};

// d = y − A's products with e0, e1 and itself, in one pass over the four columns (n values each)
// instead of forming d and then taking three dot products: the closest-point queries are most of
// a level fit's time at 10⁵ vertices (issue #53).
struct Products {
  double d0 = 0, d1 = 0, dd = 0;
};

// Four lanes (one ymm, or two xmm on the baseline), two sets of accumulators for the adds'
// latency. Inlined into each target's entry point below, so that the compiler generates it for
// that target; neither target has FMA, so both round every product and sum alike and a level is
// the same on every machine.
using Quad = double __attribute__((vector_size(32)));

// Loads and sums by reference: a vector passed or returned by value would change the ABI between
// the targets.
__attribute__((always_inline)) inline void load(Quad& value, const double* values) {
  std::memcpy(&value, values, sizeof value);
}

__attribute__((always_inline)) inline double lanes_sum(const Quad& q) { return (q[0] + q[1]) + (q[2] + q[3]); }

__attribute__((always_inline)) inline Products products_body(const double* y, const double* corner, const double* e0,
                                                             const double* e1, Eigen::Index n) {
  Quad d0a{}, d1a{}, dda{}, d0b{}, d1b{}, ddb{};
  Quad ya, yb, ca, cb, ea, eb, fa, fb;
  Eigen::Index i = 0;
  for (; i + 8 <= n; i += 8) {
    load(ya, y + i), load(yb, y + i + 4), load(ca, corner + i), load(cb, corner + i + 4);
    load(ea, e0 + i), load(eb, e0 + i + 4), load(fa, e1 + i), load(fb, e1 + i + 4);
    const Quad da = ya - ca;
    const Quad db = yb - cb;
    d0a += ea * da;
    d0b += eb * db;
    d1a += fa * da;
    d1b += fb * db;
    dda += da * da;
    ddb += db * db;
  }
  for (; i + 4 <= n; i += 4) {
    load(ya, y + i), load(ca, corner + i), load(ea, e0 + i), load(fa, e1 + i);
    const Quad d = ya - ca;
    d0a += ea * d;
    d1a += fa * d;
    dda += d * d;
  }
  d0a += d0b;
  d1a += d1b;
  dda += ddb;
  Products out{lanes_sum(d0a), lanes_sum(d1a), lanes_sum(dda)};
  for (; i < n; ++i) {
    const double d = y[i] - corner[i];
    out.d0 += e0[i] * d;
    out.d1 += e1[i] * d;
    out.dd += d * d;
  }
  return out;
}

using ProductsFunction = Products (*)(const double*, const double*, const double*, const double*, Eigen::Index);

#if defined(__x86_64__)
__attribute__((target("avx2"))) Products products_avx2(const double* y, const double* corner, const double* e0,
                                                       const double* e1, Eigen::Index n) {
  return products_body(y, corner, e0, e1, n);
}
#endif
Products products_baseline(const double* y, const double* corner, const double* e0, const double* e1,
                           Eigen::Index n) {
  return products_body(y, corner, e0, e1, n);
}

// The widest the machine has, chosen once.
Products products(const double* y, const double* corner, const double* e0, const double* e1, Eigen::Index n) {
#if defined(__x86_64__)
  static const ProductsFunction chosen = __builtin_cpu_supports("avx2") ? products_avx2 : products_baseline;
#else
  static const ProductsFunction chosen = products_baseline;
#endif
  return chosen(y, corner, e0, e1, n);
}

Closest closest_on_triangle(double a, double b, double c, double d0, double d1, double dd) {
  const auto f = [&](double s, double t) {
    return std::max(0.0, dd - 2 * (s * d0 + t * d1) + a * s * s + 2 * b * s * t + c * t * t);
  };
  const double det = a * c - b * b;
  if (det > 1e-14 * (a * c)) {
    const double s = (c * d0 - b * d1) / det;
    const double t = (a * d1 - b * d0) / det;
    if (s >= 0 && t >= 0 && s + t <= 1) return {s, t, f(s, t)};
  }
  const auto clamp01 = [](double x) { return std::clamp(std::isfinite(x) ? x : 0.0, 0.0, 1.0); };
  Closest best;
  best.distance2 = f(0, 0);
  const auto consider = [&](double s, double t) {
    const double value = f(s, t);
    if (value < best.distance2) best = {s, t, value};
  };
  if (a > 0) consider(clamp01(d0 / a), 0);
  if (c > 0) consider(0, clamp01(d1 / c));
  const double e = a - 2 * b + c;  // |e1 − e0|²
  if (e > 0) {
    const double t = clamp01((a - b - d0 + d1) / e);
    consider(1 - t, t);
  }
  return best;
}

// One input vertex's closest point: a face of the level and the barycentric weights of its corners.
struct Foot {
  int32_t face = -1;
  std::array<double, 3> weight{};
  double distance2 = 0;
};

// For each level vertex, the input vertices whose closest points it carries, with their weights λ.
using Carried = std::vector<std::vector<std::pair<int32_t, double>>>;

// Influence simplification after placement (level_fit.h): removes influences from `level`
// cheapest harm first under the two rules there, given the residuals R (n × V) and what each
// vertex carries; updates R. Returns the number removed.
Result<int> remove_influences(const Eigen::MatrixXd& C, InfluenceSimplifier& simplifier, double exchange,
                              const Carried& carried, Eigen::MatrixXd& R, as::AnimationSpaceModel& level) {
  const int L = level.vertex_count();
  const int before = level.influences.influence_count();
  double error = 0, bound2 = 0;  // Σ ‖r_o‖² and max ‖r_o‖² before any removal
  for (Eigen::Index o = 0; o < R.cols(); ++o) {
    const double d2 = R.col(o).squaredNorm();
    error += d2;
    bound2 = std::max(bound2, d2);
  }
  const double error_before = error;
  std::vector<VertexState> states(static_cast<size_t>(L));
  for (int v = 0; v < L; ++v) states[static_cast<size_t>(v)] = vertex_state(level, v);

  // Removals whose harm is below this are negligible: a millionth of one influence's share of the
  // level's error. Only speed depends on it (below); every harm taken is counted exactly.
  const double negligible = 1e-6 * error_before / std::max(before, 1);

  // The cheapest removal of vertex v now, its harm h(s) and C s.
  //  - First, a bone that can simply hand its vector to the vertex's heaviest bone (s_i = −p_i,
  //    s_j = +p_i: the move LBS weight pruning makes) at negligible harm goes that way. A rig's
  //    near-zero weights (the cow's 47 000 below 10⁻⁶) then cost two 4-column products each,
  //    instead of §6.3's operators for every influence set they pass through.
  //  - Otherwise the bone is §6.3's choice, the least ‖s‖₂,₂: with v at its placed optimum the
  //    pull term of h vanishes to first order and h = (Σλ²)‖s‖²₂,₂, so that is also the least
  //    harm (costing every slot's h exactly would form every slot's correction: k times the work).
  struct Candidate {
    double harm = 0;
    InfluenceRemoval removal;
    int heir = -1;  // slot that takes the removed vector (a handed-over bone); -1: §6.3's correction
    Eigen::VectorXd moved;
  };
  Eigen::VectorXd pull(C.rows());
  const auto cheapest = [&](int v) -> Result<Candidate> {
    const VertexState& state = states[static_cast<size_t>(v)];
    double mass = 0;
    pull.setZero();
    for (const auto& [o, lambda] : carried[static_cast<size_t>(v)]) {
      mass += lambda * lambda;
      pull.noalias() += lambda * R.col(o);
    }
    const auto harm_of = [&](const Eigen::VectorXd& moved) { return mass * moved.squaredNorm() - 2 * moved.dot(pull); };
    Candidate best;
    best.moved.resize(C.rows());
    int heir = 0;
    for (int j = 1; j < state.influence_count(); ++j) {
      if (state.position(3, j) > state.position(3, heir)) heir = j;
    }
    for (int i = 0; i < state.influence_count(); ++i) {
      if (i == heir) continue;
      const Eigen::Vector4d p = state.position.col(i);
      best.moved.noalias() = (C.middleCols(4 * state.bones[static_cast<size_t>(heir)], 4) -
                              C.middleCols(4 * state.bones[static_cast<size_t>(i)], 4)) *
                             p;
      best.harm = harm_of(best.moved);
      if (best.harm <= negligible) {
        best.heir = heir;
        best.removal.slot = i;
        best.removal.bone = state.bones[static_cast<size_t>(i)];
        return best;
      }
    }
    Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
    if (!removal) return removal.error();
    best.moved.setZero();
    add_normalised(C, state.bones.data(), removal->correction, best.moved);
    best.harm = harm_of(best.moved);
    best.removal = std::move(*removal);
    return best;
  };
  // Hands slot i's vectors to slot j and drops slot i (tangents too: the same vectors move, so
  // the plane moves with the point, by a negligible amount).
  const auto hand_over = [](VertexState& state, int i, int j) {
    const auto drop = [i](as::InfluenceVectors& vectors) {
      as::InfluenceVectors out(4, vectors.cols() - 1);
      out.leftCols(i) = vectors.leftCols(i);
      out.rightCols(vectors.cols() - 1 - i) = vectors.rightCols(vectors.cols() - 1 - i);
      vectors = std::move(out);
    };
    for (as::InfluenceVectors* vectors : {&state.position, &state.tangent_s, &state.tangent_t}) {
      if (vectors->cols() == 0) continue;
      vectors->col(j) += vectors->col(i);
      drop(*vectors);
    }
    state.bones.erase(state.bones.begin() + i);
  };

  using Entry = std::pair<double, int>;  // (harm when queued, vertex)
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
  for (int v = 0; v < L; ++v) {
    if (states[static_cast<size_t>(v)].influence_count() < 2) continue;
    Result<Candidate> c = cheapest(v);
    if (!c) return c.error();
    queue.emplace(c->harm, v);
  }
  int removed = 0;
  while (!queue.empty()) {
    const int v = queue.top().second;
    queue.pop();
    // Neighbours' removals change the residuals v's harm depends on: re-cost it, and put it back
    // if something else is now cheaper.
    Result<Candidate> c = cheapest(v);
    if (!c) return c.error();
    if (!queue.empty() && c->harm > queue.top().first) {
      queue.emplace(c->harm, v);
      continue;
    }
    // Rule 1: stop at the first removal the exchange does not pay for.
    const double allowed = 1 + exchange * (removed + 1) / static_cast<double>(before);
    if (error + c->harm > error_before * allowed * allowed) break;
    // Rule 2: skip a vertex whose removal takes some input vertex past the level's bound.
    const auto& points = carried[static_cast<size_t>(v)];
    const bool within = std::all_of(points.begin(), points.end(), [&](const auto& point) {
      return (R.col(point.first) - point.second * c->moved).squaredNorm() <= bound2;
    });
    if (!within) continue;
    for (const auto& [o, lambda] : points) R.col(o) -= lambda * c->moved;
    error += c->harm;
    if (c->heir >= 0) {
      hand_over(states[static_cast<size_t>(v)], c->removal.slot, c->heir);
    } else {
      simplifier.apply(c->removal, states[static_cast<size_t>(v)]);
    }
    ++removed;
    if (states[static_cast<size_t>(v)].influence_count() >= 2) {
      Result<Candidate> next = cheapest(v);
      if (!next) return next.error();
      queue.emplace(next->harm, v);
    }
  }
  if (removed > 0) set_vertex_states(level, states);
  return removed;
}

}  // namespace

Result<NormalisedInput> normalise_input(const as::AnimationSpaceModel& input, const Eigen::MatrixXd& P) {
  if (P.rows() != 4 * input.bone_count() || P.cols() != P.rows()) {
    return invalid("P: expected " + std::to_string(4 * input.bone_count()) + " × " +
                   std::to_string(4 * input.bone_count()) + " (the input's bones), got " + std::to_string(P.rows()) +
                   " × " + std::to_string(P.cols()));
  }
  auto C = as::normalised_animation_space_matrix(P);
  if (!C) return invalid("P: " + C.error().message);
  NormalisedInput normalised;
  normalised.positions = normalised_positions(input, *C);
  normalised.C = std::move(*C);
  normalised.P = P;
  return normalised;
}

Result<LevelFit> fit_level(const as::AnimationSpaceModel& input, const Eigen::MatrixXd& P,
                           const std::vector<int32_t>& representative, as::AnimationSpaceModel& level,
                           const LevelFitOptions& options, InfluenceSimplifier* simplifier) {
  auto normalised = normalise_input(input, P);
  if (!normalised) return normalised.error();
  return fit_level(*normalised, representative, level, options, simplifier);
}

Result<LevelFit> fit_level(const NormalisedInput& input, const std::vector<int32_t>& representative,
                           as::AnimationSpaceModel& level, const LevelFitOptions& options,
                           InfluenceSimplifier* simplifier) {
  const auto V = static_cast<int>(input.positions.cols());
  const int L = level.vertex_count();
  if (static_cast<int>(representative.size()) != V) {
    return invalid("representative: expected " + std::to_string(V) + " entries (the input's vertices), got " +
                   std::to_string(representative.size()));
  }
  for (const int32_t r : representative) {
    if (r < 0 || r >= L) {
      return invalid("representative: expected level vertices in [0, " + std::to_string(L) + "), got " +
                     std::to_string(r));
    }
  }
  if (input.C.rows() != 4 * level.bone_count()) {
    return invalid("level: expected " + std::to_string(input.C.rows() / 4) + " bones (the input's), got " +
                   std::to_string(level.bone_count()));
  }
  if (options.rounds < 0 || options.sweeps < 1) {
    return invalid("options: expected rounds ≥ 0 and sweeps ≥ 1, got " + std::to_string(options.rounds) + " and " +
                   std::to_string(options.sweeps));
  }
  const Eigen::MatrixXd* C = &input.C;
  const Eigen::MatrixXd& P = input.P;
  const Eigen::MatrixXd& Yin = input.positions;
  Eigen::MatrixXd Y = normalised_positions(level, *C);

  // Faces around each level vertex, and the candidate faces of each representative: its own and
  // its neighbours' (the closest point of a collapsed vertex lies near where it went).
  std::vector<std::vector<int32_t>> faces_of(static_cast<size_t>(L));
  for (Eigen::Index f = 0; f < level.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) faces_of[static_cast<size_t>(level.faces(f, k))].push_back(static_cast<int32_t>(f));
  }
  std::vector<std::vector<int32_t>> candidates(static_cast<size_t>(L));
  for (int v = 0; v < L; ++v) {
    std::vector<int32_t>& list = candidates[static_cast<size_t>(v)];
    for (const int32_t f : faces_of[static_cast<size_t>(v)]) {
      for (int k = 0; k < 3; ++k) {
        const auto& around = faces_of[static_cast<size_t>(level.faces(f, k))];
        list.insert(list.end(), around.begin(), around.end());
      }
    }
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }

  std::vector<Foot> feet(static_cast<size_t>(V));
  // Per face, its first corner's position and edge vectors with their Gram entries, made once a
  // round: a closest-point query is then three dot products of length n.
  const Eigen::Index F = level.faces.rows();
  Eigen::MatrixXd E0(Y.rows(), F), E1(Y.rows(), F);
  Eigen::MatrixXd gram(3, F);
  const auto find_feet = [&] {
    parallel_for_chunks(F, 1024, [&](int64_t first, int64_t last) {
      for (auto f = static_cast<Eigen::Index>(first); f < static_cast<Eigen::Index>(last); ++f) {
        E0.col(f) = Y.col(level.faces(f, 1)) - Y.col(level.faces(f, 0));
        E1.col(f) = Y.col(level.faces(f, 2)) - Y.col(level.faces(f, 0));
        gram(0, f) = E0.col(f).squaredNorm();
        gram(1, f) = E0.col(f).dot(E1.col(f));
        gram(2, f) = E1.col(f).squaredNorm();
      }
    });
    // Input vertices are independent here: split them over the cores.
    parallel_for_chunks(V, 256, [&](int64_t first, int64_t last) {
      const Eigen::Index n = Y.rows();
      for (int o = static_cast<int>(first); o < static_cast<int>(last); ++o) {
        Foot best;
        best.distance2 = std::numeric_limits<double>::infinity();
        const int32_t r = representative[static_cast<size_t>(o)];
        const auto consider = [&](int32_t f) {
          const Products d = products(Yin.col(o).data(), Y.col(level.faces(f, 0)).data(), E0.col(f).data(),
                                      E1.col(f).data(), n);
          const Closest c = closest_on_triangle(gram(0, f), gram(1, f), gram(2, f), d.d0, d.d1, d.dd);
          if (c.distance2 < best.distance2) best = {f, {1 - c.s - c.t, c.s, c.t}, c.distance2};
        };
        // Later rounds: the vertices move little, so the faces around the previous closest face's
        // corners are searched (any face gives a valid bound; these hold the closest one in practice).
        // A face around two or three of the corners is measured once (the corners' fans overlap).
        const int32_t previous = feet[static_cast<size_t>(o)].face;
        if (previous >= 0) {
          std::array<int32_t, 48> seen;
          size_t seen_count = 0;
          for (int k = 0; k < 3; ++k) {
            for (const int32_t f : faces_of[static_cast<size_t>(level.faces(previous, k))]) {
              const auto end = seen.begin() + static_cast<std::ptrdiff_t>(seen_count);
              if (std::find(seen.begin(), end, f) != end) continue;
              if (seen_count < seen.size()) seen[seen_count++] = f;
              consider(f);
            }
          }
        } else {
          for (const int32_t f : candidates[static_cast<size_t>(r)]) consider(f);
        }
        if (best.face < 0) {  // a vertex with no faces: its own position
          best.distance2 = (Yin.col(o) - Y.col(r)).squaredNorm();
        }
        feet[static_cast<size_t>(o)] = best;
      }
    });
  };
  const auto summary = [&] {
    LevelFit fit;
    double sum = 0;
    for (const Foot& foot : feet) {
      fit.bound = std::max(fit.bound, foot.distance2);
      sum += foot.distance2;
    }
    fit.bound = std::sqrt(fit.bound);
    fit.rms = V > 0 ? std::sqrt(sum / V) : 0;
    return fit;
  };

  // B_k: the moves of a k-bone vertex that keep its weight (x, y, z of every bone free; the
  // weights of all but the last bone free, the last one taking minus their sum).
  // Sized once for the largest influence set, so references into it stay valid.
  int most_bones = 0;
  for (int v = 0; v < L; ++v) most_bones = std::max(most_bones, level.influences.end(v) - level.influences.begin(v));
  std::vector<Eigen::MatrixXd> free_moves(static_cast<size_t>(most_bones) + 1);
  const auto weight_free = [&](int k) -> const Eigen::MatrixXd& {
    Eigen::MatrixXd& B = free_moves[static_cast<size_t>(k)];
    if (B.size() == 0) {
      B = Eigen::MatrixXd::Zero(4 * k, 4 * k - 1);
      for (int j = 0; j < k; ++j) {
        for (int axis = 0; axis < 3; ++axis) B(4 * j + axis, 3 * j + axis) = 1;
        if (j + 1 < k) {
          B(4 * j + 3, 3 * k + j) = 1;
          B(4 * (k - 1) + 3, 3 * k + j) = -1;
        }
      }
    }
    return B;
  };
  // Per level vertex, the factorised Bᵀ P_II B (CᵀC = P): its bones never change, so it is made
  // once. A damping far below anything P sees keeps directions P does not measure where they are.
  std::vector<std::optional<Eigen::LDLT<Eigen::MatrixXd>>> systems(static_cast<size_t>(L));
  const auto system_of = [&](int v) -> const Eigen::LDLT<Eigen::MatrixXd>& {
    std::optional<Eigen::LDLT<Eigen::MatrixXd>>& system = systems[static_cast<size_t>(v)];
    if (!system) {
      const int begin = level.influences.begin(v);
      const int k = level.influences.end(v) - begin;
      Eigen::MatrixXd PI(4 * k, 4 * k);
      for (int a = 0; a < k; ++a) {
        for (int b = 0; b < k; ++b) {
          PI.block<4, 4>(4 * a, 4 * b) = P.block<4, 4>(4 * level.influences.bones[static_cast<size_t>(begin + a)],
                                                       4 * level.influences.bones[static_cast<size_t>(begin + b)]);
        }
      }
      const Eigen::MatrixXd& B = weight_free(k);
      Eigen::MatrixXd H = B.transpose() * PI * B;
      H.diagonal().array() +=
          1e-9 * std::max(H.trace() / static_cast<double>(H.rows()), std::numeric_limits<double>::min());
      system.emplace(H);
    }
    return *system;
  };

  // Which input vertices each level vertex carries (their closest points' weights on it), from
  // the feet found last.
  Carried carried;
  const auto carry = [&] {
    carried.assign(static_cast<size_t>(L), {});
    for (int o = 0; o < V; ++o) {
      const Foot& foot = feet[static_cast<size_t>(o)];
      if (foot.face < 0) continue;
      for (int k = 0; k < 3; ++k) {
        if (foot.weight[static_cast<size_t>(k)] != 0) {
          carried[static_cast<size_t>(level.faces(foot.face, k))].emplace_back(o, foot.weight[static_cast<size_t>(k)]);
        }
      }
    }
  };
  // Residuals r_o = y_o − Σ λ_c y_c of every input vertex (influence simplification's input).
  Eigen::MatrixXd R;
  const auto residuals = [&] {
    R.resize(Yin.rows(), V);
    parallel_for_chunks(V, 1024, [&](int64_t first, int64_t last) {
      for (auto o = static_cast<Eigen::Index>(first); o < static_cast<Eigen::Index>(last); ++o) {
        const Foot& foot = feet[static_cast<size_t>(o)];
        R.col(o) = Yin.col(o);
        if (foot.face < 0) continue;
        for (int k = 0; k < 3; ++k) R.col(o) -= foot.weight[static_cast<size_t>(k)] * Y.col(level.faces(foot.face, k));
      }
    });
  };
  // A vertex's pull Σ_o λ_o r_o, with the feet held, is b_v − Σ_c M_vc y_c: b_v = Σ_o λ_ov y_o and
  // M_vc = Σ_o λ_ov λ_oc over the points v carries (c its neighbours on their faces, v among them).
  // A sweep then reads a level vertex's few neighbours instead of every residual it carries, and
  // writes only its own y: the residuals of 10⁵ input vertices were streamed twice per vertex move
  // (issue #53: most of build-lod's placement at 186k points, and all of it on the coarse levels).
  Eigen::MatrixXd pulled;  // b_v, n × L
  std::vector<std::vector<std::pair<int32_t, double>>> coupling;  // M_v·, the diagonal first
  const auto normal_equations = [&] {
    pulled.resize(Yin.rows(), L);
    coupling.assign(static_cast<size_t>(L), {});
    parallel_for_chunks(L, 256, [&](int64_t first, int64_t last) {
      for (auto v = static_cast<int32_t>(first); v < static_cast<int32_t>(last); ++v) {
        auto& row = coupling[static_cast<size_t>(v)];
        row.emplace_back(v, 0.0);
        pulled.col(v).setZero();
        for (const auto& [o, lambda] : carried[static_cast<size_t>(v)]) {
          pulled.col(v) += lambda * Yin.col(o);
          const Foot& foot = feet[static_cast<size_t>(o)];
          for (int k = 0; k < 3; ++k) {
            const int32_t c = level.faces(foot.face, k);
            const double product = lambda * foot.weight[static_cast<size_t>(k)];
            if (product == 0) continue;
            auto at = std::find_if(row.begin(), row.end(), [c](const auto& entry) { return entry.first == c; });
            if (at == row.end()) {
              row.emplace_back(c, product);
            } else {
              at->second += product;
            }
          }
        }
      }
    });
  };
  // Level vertices that carry no input vertex in common move independently: each reads and
  // writes only its own points' residuals, its own Y column and its own positions. Coloured so
  // that no two of a colour share a point, a sweep takes the colours in turn and each colour's
  // vertices in parallel — Gauss–Seidel in colour order, the same on any number of cores (issue
  // #53: at 10⁵ vertices the serial sweeps were a fifth of build-lod).
  const auto colour_classes = [&] {
    std::vector<std::array<int32_t, 3>> carriers(static_cast<size_t>(V), {-1, -1, -1});
    for (int v = 0; v < L; ++v) {
      for (const auto& [o, lambda] : carried[static_cast<size_t>(v)]) {
        auto& slots = carriers[static_cast<size_t>(o)];
        *std::find(slots.begin(), slots.end(), -1) = v;  // a point lies on one face: 3 corners at most
      }
    }
    std::vector<int32_t> colour(static_cast<size_t>(L), -1);
    std::vector<std::vector<int32_t>> classes;
    std::vector<char> taken;
    for (int v = 0; v < L; ++v) {
      if (carried[static_cast<size_t>(v)].empty()) continue;
      taken.assign(classes.size() + 1, 0);
      for (const auto& [o, lambda] : carried[static_cast<size_t>(v)]) {
        for (const int32_t w : carriers[static_cast<size_t>(o)]) {
          if (w >= 0 && colour[static_cast<size_t>(w)] >= 0) taken[static_cast<size_t>(colour[static_cast<size_t>(w)])] = 1;
        }
      }
      const auto c = static_cast<size_t>(std::find(taken.begin(), taken.end(), 0) - taken.begin());
      if (c == classes.size()) classes.emplace_back();
      classes[c].push_back(v);
      colour[static_cast<size_t>(v)] = static_cast<int32_t>(c);
    }
    return classes;
  };
  for (int k = 1; k <= most_bones; ++k) weight_free(k);  // made before the parallel sweeps read them
  const auto move_vertex = [&](int v, Eigen::VectorXd& pull, Eigen::VectorXd& moved, Eigen::VectorXd& g,
                               Eigen::VectorXd& rhs, Eigen::VectorXd& z, Eigen::VectorXd& delta) {
    const int begin = level.influences.begin(v);
    const int k = level.influences.end(v) - begin;
    // Minimise Σ_o ‖r_o − λ_o C_I Δ‖² over the move Δ (4k) with Σ Δ̲ = 0: with Δ = B z,
    // (Σλ²) Bᵀ P_II B z = Bᵀ C_Iᵀ Σ λ r_o.
    const auto& row = coupling[static_cast<size_t>(v)];
    const double lambda2 = row.front().second;
    if (!(lambda2 > 0)) return;
    pull = pulled.col(v);
    for (const auto& [c, m] : row) pull.noalias() -= m * Y.col(c);
    const Eigen::LDLT<Eigen::MatrixXd>& solver = system_of(v);
    if (solver.info() != Eigen::Success) return;
    g.resize(4 * k);
    for (int j = 0; j < k; ++j) {
      g.segment<4>(4 * j).noalias() =
          C->middleCols(4 * level.influences.bones[static_cast<size_t>(begin + j)], 4).transpose() * pull;
    }
    const Eigen::MatrixXd& B = free_moves[static_cast<size_t>(k)];
    rhs.noalias() = B.transpose() * g;
    rhs /= lambda2;
    z = solver.solve(rhs);
    if (!z.allFinite()) return;
    delta.noalias() = B * z;
    for (int j = 0; j < k; ++j) level.positions.col(begin + j) += delta.segment<4>(4 * j);
    // Weight exactly 1 again (the move's weights sum to zero only to rounding).
    double weight = 0;
    for (int j = 0; j < k; ++j) weight += level.positions(3, begin + j);
    level.positions(3, begin + k - 1) += 1 - weight;
    moved.setZero();
    add_normalised(*C, level.influences.bones.data() + begin,
                   Eigen::Map<const Eigen::Matrix<double, 4, Eigen::Dynamic>>(delta.data(), 4, k), moved);
    Y.col(v) += moved;
  };
  const auto settle = [&](int rounds) {
    for (int round = 0; round < rounds; ++round) {
      carry();
      normal_equations();
      const std::vector<std::vector<int32_t>> classes = colour_classes();
      for (int sweep = 0; sweep < options.sweeps; ++sweep) {
        for (const std::vector<int32_t>& members : classes) {
          parallel_for_chunks(static_cast<int64_t>(members.size()), 512, [&](int64_t first, int64_t last) {
            // Scratch, sized once per chunk (this runs sweeps × L times).
            Eigen::VectorXd pull(Yin.rows()), moved(Yin.rows()), g, rhs, z, delta;
            for (int64_t i = first; i < last; ++i) {
              move_vertex(members[static_cast<size_t>(i)], pull, moved, g, rhs, z, delta);
            }
          });
        }
      }
      find_feet();
    }
  };

  find_feet();
  settle(options.rounds);
  LevelFit fit = summary();
  fit.influences_before = fit.influences = level.influences.influence_count();
  fit.rms_before = fit.rms;
  if (options.influence_exchange >= 0) {
    carry();
    residuals();
    std::optional<InfluenceSimplifier> own;
    if (!simplifier) simplifier = &own.emplace(P);
    Result<int> removed = remove_influences(*C, *simplifier, options.influence_exchange, carried, R, level);
    if (!removed) return removed.error();
    if (*removed > 0) {
      // New influence sets: new normalised positions and systems, then one round on the bones left.
      Y = normalised_positions(level, *C);
      systems.assign(static_cast<size_t>(L), std::nullopt);
      // The feet found last are still points of the level: settle starts from them.
      if (options.rounds > 0) {
        settle(1);
      } else {
        find_feet();
      }
      const LevelFit after = summary();
      fit.bound = after.bound;
      fit.rms = after.rms;
      fit.influences = level.influences.influence_count();
    }
  }
  return fit;
}

}  // namespace animspace::lod
