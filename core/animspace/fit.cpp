// Merry 2007 §4.1 (fitting to examples), §4.1.1 (influence sets), §4.1.2 (vertex and edge
// regularisation, scale normalisation), §4.1.3 (homogeneous weight by elimination).
//
// Notation: n examples k, V vertices i, b bones j, I influences; Ḡ^k_j is the top 3×4 of G^k_j.
// Each vertex's unknowns are its animation-space position p_i restricted to its influence set
// (a 4m-vector for m influences), parametrised affinely as p_i = B_i y_i + c_i so that the
// constraint holds for every y_i:
//   animation space  y_i = p_i without the eliminated weight (4m − 1 unknowns), c_i = that
//                    weight's unit vector; the eliminated weight is 1 − Σ of the others;
//   linear blend     y_i = the weights w_j but one (m − 1 unknowns), p_j = w_j q_j with
//                    q_j = Ĝ_j⁻¹ v̂_i, the last weight 1 − Σ of the others.
// The objective is quadratic in p, ½pᵀHp − gᵀp + const, so the reduced normal equations are
//   (Bᵀ H B) y = Bᵀ (g − H c).
// H's per-vertex block is built from Gram blocks C_ab = Σ_k Ḡ^kᵀ_a Ḡ^k_b computed once per
// bone pair, so the cost per vertex does not grow with n except for the right-hand side.
#include "core/animspace/fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include "core/common/parallel.h"
#include "core/common/timing.h"
#include "core/geometry/edges.h"

namespace animspace::animation_space {
namespace {

using Matrix34 = Eigen::Matrix<double, 3, 4>;
using Matrix34List = std::vector<Matrix34, Eigen::aligned_allocator<Matrix34>>;
using Matrix4List = std::vector<Eigen::Matrix4d, Eigen::aligned_allocator<Eigen::Matrix4d>>;

// Vertices per thread below which a thread does not pay for its start-up (each vertex costs a
// few tens of microseconds of small dense algebra).
constexpr int64_t kVerticesPerThread = 128;

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

enum class Parametrisation { kAnimationSpace, kLinearBlend };

// The similarity x' = s (x − c) into the unit-box frame (§4.1.2), as a 4×4 matrix T acting on
// points and on animation-space 4-vectors alike.
struct Normalisation {
  double scale = 1;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();

  Transform forward() const {
    Transform t = Transform::Identity();
    t.topLeftCorner<3, 3>() *= scale;
    t.topRightCorner<3, 1>() = -scale * centre;
    return t;
  }
  Transform inverse() const {
    Transform t = Transform::Identity();
    t.topLeftCorner<3, 3>() /= scale;
    t.topRightCorner<3, 1>() = centre;
    return t;
  }
};

// Everything the least squares needs, in the normalised frame.
struct Problem {
  Parametrisation parametrisation = Parametrisation::kAnimationSpace;
  const InfluenceSets* influences = nullptr;
  int n = 0, V = 0, b = 0;
  Matrix34List poses;        // n·b, index k·b + j: Ḡ'^k_j = top rows of T G^k_j T⁻¹
  Matrix4List gram;          // b·b, index a·b + c: C_ac = Σ_k Ḡ'^kᵀ_a Ḡ'^k_c
  Eigen::MatrixXd points;    // 3V × n: example k's vertex i in rows 3i … 3i+2 of column k
  InfluenceVectors data;     // 4 × I: g_j = Σ_k Ḡ'^kᵀ_j v'^k_i per influence
  InfluenceVectors rest_directions;  // linear blend only, 4 × I: q'_j = T Ĝ_j⁻¹ v̂_i
  double lambda = 0;
  std::vector<double> edge_weight_sum;  // V: Σ δ/ℓ_e over the edges at the vertex (0 if none)
  std::vector<int64_t> unknown_offsets;  // V + 1

  int influence_begin(int i) const { return influences->begin(i); }
  int influence_count(int i) const { return influences->end(i) - influences->begin(i); }
  int bone(int k) const { return influences->bones[static_cast<size_t>(k)]; }
  int unknowns(int i) const {
    const int m = influence_count(i);
    return parametrisation == Parametrisation::kAnimationSpace ? 4 * m - 1 : m - 1;
  }
};

struct Edge {
  int a = 0, b = 0;
  double weight = 0;  // δ / ℓ
};

// B_i (4m × unknowns) and c_i (4m) of the parametrisation p_i = B_i y_i + c_i. The last
// influence's weight is the eliminated one (§4.1.3; any choice gives the same minimiser).
void vertex_basis(const Problem& P, int i, Eigen::MatrixXd& B, Eigen::VectorXd& c) {
  const int m = P.influence_count(i);
  const int e = m - 1;
  B.setZero(4 * m, P.unknowns(i));
  c.setZero(4 * m);
  if (P.parametrisation == Parametrisation::kAnimationSpace) {
    for (int r = 0; r < 4 * m - 1; ++r) B(r, r) = 1;
    for (int a = 0; a < e; ++a) B(4 * e + 3, 4 * a + 3) = -1;
    c(4 * e + 3) = 1;
  } else {
    const int first = P.influence_begin(i);
    const Eigen::Vector4d q_e = P.rest_directions.col(first + e);
    for (int a = 0; a < e; ++a) {
      B.block<4, 1>(4 * a, a) = P.rest_directions.col(first + a);
      B.block<4, 1>(4 * e, a) = -q_e;
    }
    c.segment<4>(4 * e) = q_e;
  }
}

// H_i (4m × 4m, data term + λ + the diagonal of the edge term) and g_i (4m).
void vertex_hessian(const Problem& P, int i, Eigen::MatrixXd& H, Eigen::VectorXd& g) {
  const int m = P.influence_count(i);
  const int first = P.influence_begin(i);
  H.resize(4 * m, 4 * m);
  g.resize(4 * m);
  for (int a = 0; a < m; ++a) {
    g.segment<4>(4 * a) = P.data.col(first + a);
    for (int c = 0; c < m; ++c) {
      H.block<4, 4>(4 * a, 4 * c) = P.gram[static_cast<size_t>(P.bone(first + a) * P.b + P.bone(first + c))];
    }
  }
  H.diagonal().array() += P.lambda + P.edge_weight_sum[static_cast<size_t>(i)];
}

// The vertex's diagonal block K_ii = Bᵀ H B and its right-hand side Bᵀ (g − H c), without the
// constant terms of the edges.
void vertex_system(const Problem& P, int i, Eigen::MatrixXd& K, Eigen::VectorXd& r) {
  Eigen::MatrixXd B, H;
  Eigen::VectorXd c, g;
  vertex_basis(P, i, B, c);
  vertex_hessian(P, i, H, g);
  const Eigen::MatrixXd HB = H * B;
  K.noalias() = B.transpose() * HB;
  r.noalias() = B.transpose() * (g - H * c);
}

Status check_inputs(const Skeleton& skeleton, const FitExamples& examples, const FaceMatrix& faces,
                    const InfluenceSets& influences, const FitOptions& options) {
  ANIMSPACE_RETURN_IF_ERROR(validate(skeleton));
  ANIMSPACE_RETURN_IF_ERROR(validate(influences, skeleton.bone_count()));
  const int n = examples.example_count();
  const int V = influences.vertex_count();
  if (n < 1) return invalid("fit: no example poses; expected at least one");
  if (V < 1) return invalid("fit: the influence sets have no vertices; expected at least one");
  for (int k = 0; k < n; ++k) {
    ANIMSPACE_RETURN_IF_ERROR(validate_pose(skeleton, examples.poses[static_cast<size_t>(k)],
                                            "fit: example pose " + std::to_string(k)));
  }
  if (examples.meshes.rows() != n || examples.meshes.cols() != 3L * V) {
    return invalid("fit: example meshes are " + std::to_string(examples.meshes.rows()) + " × " +
                   std::to_string(examples.meshes.cols()) + ", expected " + std::to_string(n) + " × " +
                   std::to_string(3L * V) + " (examples × 3·vertices of the influence sets)");
  }
  if (!examples.meshes.allFinite()) return invalid("fit: example meshes contain a NaN or infinite coordinate");
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      if (faces(f, c) < 0 || faces(f, c) >= V) {
        return invalid("fit: face " + std::to_string(f) + " indexes vertex " + std::to_string(faces(f, c)) +
                       ", expected 0 … " + std::to_string(V - 1));
      }
    }
  }
  if (!(options.vertex_regularisation >= 0) || !std::isfinite(options.vertex_regularisation)) {
    return invalid("fit: vertex_regularisation must be finite and ≥ 0");
  }
  if (!(options.edge_regularisation >= 0) || !std::isfinite(options.edge_regularisation)) {
    return invalid("fit: edge_regularisation must be finite and ≥ 0");
  }
  if (!(options.tolerance > 0)) return invalid("fit: tolerance must be > 0");
  if (options.max_iterations < 1) return invalid("fit: max_iterations must be ≥ 1");
  return Status::Ok();
}

// §4.1.2: the examples' bounding box becomes a box of largest side 1 centred at the origin.
Result<Normalisation> make_normalisation(const FrameMatrix& meshes, bool enabled) {
  Normalisation normalisation;
  if (!enabled) return normalisation;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  const Eigen::Index V = meshes.cols() / 3;
  for (Eigen::Index k = 0; k < meshes.rows(); ++k) {
    for (Eigen::Index i = 0; i < V; ++i) {
      const Eigen::Vector3d x = meshes.block<1, 3>(k, 3 * i).transpose().cast<double>();
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
  }
  const double side = (hi - lo).maxCoeff();
  if (!(side > 0)) return invalid("fit: all example points coincide; the scale normalisation (§4.1.2) is undefined");
  normalisation.scale = 1 / side;
  normalisation.centre = 0.5 * (lo + hi);
  return normalisation;
}

// Fills everything but the edge terms.
void build_problem(const FitExamples& examples, const InfluenceSets& influences, const Normalisation& T,
                   double lambda, Problem& P) {
  P.influences = &influences;
  P.n = examples.example_count();
  P.V = influences.vertex_count();
  P.b = static_cast<int>(examples.poses.front().size());
  P.lambda = lambda;
  const Transform forward = T.forward(), inverse = T.inverse();

  P.poses.resize(static_cast<size_t>(P.n) * static_cast<size_t>(P.b));
  for (int k = 0; k < P.n; ++k) {
    for (int j = 0; j < P.b; ++j) {
      const Transform& G = examples.poses[static_cast<size_t>(k)][static_cast<size_t>(j)];
      P.poses[static_cast<size_t>(k * P.b + j)] = (forward * G * inverse).topRows<3>();
    }
  }
  P.gram.assign(static_cast<size_t>(P.b) * static_cast<size_t>(P.b), Eigen::Matrix4d::Zero());
  for (int a = 0; a < P.b; ++a) {
    for (int c = 0; c < P.b; ++c) {
      Eigen::Matrix4d C = Eigen::Matrix4d::Zero();
      for (int k = 0; k < P.n; ++k) {
        C.noalias() += P.poses[static_cast<size_t>(k * P.b + a)].transpose() * P.poses[static_cast<size_t>(k * P.b + c)];
      }
      P.gram[static_cast<size_t>(a * P.b + c)] = C;
    }
  }

  P.points.resize(3L * P.V, P.n);
  for (int k = 0; k < P.n; ++k) {
    for (int i = 0; i < P.V; ++i) {
      const Eigen::Vector3d x = examples.meshes.block<1, 3>(k, 3L * i).transpose().cast<double>();
      P.points.block<3, 1>(3L * i, k) = T.scale * (x - T.centre);
    }
  }
  P.data.resize(4, influences.influence_count());
  parallel_for_chunks(P.V, kVerticesPerThread, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) {
      for (int k = influences.begin(static_cast<int>(i)); k < influences.end(static_cast<int>(i)); ++k) {
        Eigen::Vector4d g = Eigen::Vector4d::Zero();
        for (int e = 0; e < P.n; ++e) {
          g.noalias() += P.poses[static_cast<size_t>(e * P.b + P.bone(k))].transpose() * P.points.block<3, 1>(3 * i, e);
        }
        P.data.col(k) = g;
      }
    }
  });
  P.edge_weight_sum.assign(static_cast<size_t>(P.V), 0.0);
  P.unknown_offsets.resize(static_cast<size_t>(P.V) + 1);
  P.unknown_offsets[0] = 0;
  for (int i = 0; i < P.V; ++i) {
    P.unknown_offsets[static_cast<size_t>(i) + 1] = P.unknown_offsets[static_cast<size_t>(i)] + P.unknowns(i);
  }
}

// Eq. 4.4's edges with weight δ / ℓ_e, ℓ_e the edge's average length over the examples in the
// normalised frame.
Result<std::vector<Edge>> make_edges(const FaceMatrix& faces, double delta, Problem& P) {
  std::vector<Edge> edges;
  if (delta == 0) return edges;
  for (const auto& [a, b] : geometry::unique_edges(faces)) {
    double length = 0;
    for (int k = 0; k < P.n; ++k) length += (P.points.block<3, 1>(3L * a, k) - P.points.block<3, 1>(3L * b, k)).norm();
    length /= P.n;
    if (!(length > 0)) {
      return invalid("fit: edge (" + std::to_string(a) + ", " + std::to_string(b) +
                     ") has length 0 in every example; eq. 4.4 weights edges by 1/length");
    }
    edges.push_back({a, b, delta / length});
    P.edge_weight_sum[static_cast<size_t>(a)] += delta / length;
    P.edge_weight_sum[static_cast<size_t>(b)] += delta / length;
  }
  return edges;
}

Error singular(int vertex) {
  return make_error(ErrorCode::kFailedPrecondition,
                    "fit: the normal matrix of vertex " + std::to_string(vertex) +
                        " is singular (the examples do not determine its position); set vertex_regularisation > 0");
}

// Without edges every vertex is independent: solve K_ii y_i = r_i densely, in parallel.
Status solve_per_vertex(const Problem& P, Eigen::VectorXd& y) {
  y.resize(P.unknown_offsets.back());
  std::vector<int> failed(static_cast<size_t>(P.V), 0);
  parallel_for_chunks(P.V, kVerticesPerThread, [&](int64_t first, int64_t last) {
    Eigen::MatrixXd K;
    Eigen::VectorXd r;
    for (int64_t i = first; i < last; ++i) {
      const int d = P.unknowns(static_cast<int>(i));
      if (d == 0) continue;
      vertex_system(P, static_cast<int>(i), K, r);
      const Eigen::LLT<Eigen::MatrixXd> llt(K);
      if (llt.info() != Eigen::Success) {
        failed[static_cast<size_t>(i)] = 1;
        continue;
      }
      y.segment(P.unknown_offsets[static_cast<size_t>(i)], d) = llt.solve(r);
    }
  });
  for (int i = 0; i < P.V; ++i) {
    if (failed[static_cast<size_t>(i)]) return singular(i);
  }
  return Status::Ok();
}

// The coupled system of eq. 4.4, K (symmetric, both triangles stored) and r.
struct CoupledSystem {
  Eigen::SparseMatrix<double> K;
  Eigen::VectorXd r;
  // Inverses of the diagonal blocks K_ii (the block-Jacobi preconditioner), column-major, vertex
  // i's d_i² entries from block_offsets[i]. Explicit inverses: a small dense product is several
  // times faster than two triangular solves, and the blocks are well conditioned (λ > 0 or
  // determined by the data).
  std::vector<double> block_inverses;
  std::vector<int64_t> block_offsets;  // V + 1
};

Status assemble(const Problem& P, const std::vector<Edge>& edges, CoupledSystem& system) {
  const int64_t D = P.unknown_offsets.back();
  system.r.setZero(D);
  system.block_offsets.resize(static_cast<size_t>(P.V) + 1);
  system.block_offsets[0] = 0;
  for (int i = 0; i < P.V; ++i) {
    system.block_offsets[static_cast<size_t>(i) + 1] = system.block_offsets[static_cast<size_t>(i)] + P.unknowns(i) * P.unknowns(i);
  }
  system.block_inverses.resize(static_cast<size_t>(system.block_offsets.back()));
  // Diagonal blocks: dense, computed in parallel; their inverses kept for the preconditioner.
  std::vector<Eigen::MatrixXd> diagonal(static_cast<size_t>(P.V));
  std::vector<int> failed(static_cast<size_t>(P.V), 0);
  parallel_for_chunks(P.V, kVerticesPerThread, [&](int64_t first, int64_t last) {
    Eigen::VectorXd r;
    for (int64_t i = first; i < last; ++i) {
      const int d = P.unknowns(static_cast<int>(i));
      Eigen::MatrixXd& K = diagonal[static_cast<size_t>(i)];
      vertex_system(P, static_cast<int>(i), K, r);
      system.r.segment(P.unknown_offsets[static_cast<size_t>(i)], d) = r;
      const Eigen::LLT<Eigen::MatrixXd> llt(K);
      if (llt.info() != Eigen::Success) {
        failed[static_cast<size_t>(i)] = 1;
        continue;
      }
      Eigen::Map<Eigen::MatrixXd>(system.block_inverses.data() + system.block_offsets[static_cast<size_t>(i)], d, d) =
          llt.solve(Eigen::MatrixXd::Identity(d, d));
    }
  });
  for (int i = 0; i < P.V; ++i) {
    if (failed[static_cast<size_t>(i)]) return singular(i);
  }

  std::vector<Eigen::Triplet<double>> triplets;
  size_t reserve = 0;
  for (int i = 0; i < P.V; ++i) reserve += static_cast<size_t>(P.unknowns(i) * P.unknowns(i));
  triplets.reserve(reserve + 40 * edges.size());
  for (int i = 0; i < P.V; ++i) {
    const Eigen::MatrixXd& K = diagonal[static_cast<size_t>(i)];
    const int64_t o = P.unknown_offsets[static_cast<size_t>(i)];
    for (Eigen::Index c = 0; c < K.cols(); ++c) {
      for (Eigen::Index r = 0; r < K.rows(); ++r) {
        triplets.emplace_back(static_cast<int>(o + r), static_cast<int>(o + c), K(r, c));
      }
    }
  }
  // Off-diagonal blocks K_ab = −ω B_aᵀ Π B_b, Π matching the influences the two vertices share;
  // the constant parts c enter the right-hand sides. Exact zeros (most of an animation-space
  // block, whose basis is a selection) are not stored.
  Eigen::MatrixXd Ba, Bb, Kab;
  Eigen::VectorXd ca, cb;
  for (const Edge& edge : edges) {
    vertex_basis(P, edge.a, Ba, ca);
    vertex_basis(P, edge.b, Bb, cb);
    Kab.setZero(Ba.cols(), Bb.cols());
    Eigen::VectorXd ra = Eigen::VectorXd::Zero(Ba.cols()), rb = Eigen::VectorXd::Zero(Bb.cols());
    const int first_a = P.influence_begin(edge.a), first_b = P.influence_begin(edge.b);
    int ka = 0, kb = 0;
    while (ka < P.influence_count(edge.a) && kb < P.influence_count(edge.b)) {
      const int bone_a = P.bone(first_a + ka), bone_b = P.bone(first_b + kb);
      if (bone_a < bone_b) {
        ++ka;
      } else if (bone_b < bone_a) {
        ++kb;
      } else {
        Kab.noalias() -= edge.weight * Ba.middleRows<4>(4 * ka).transpose() * Bb.middleRows<4>(4 * kb);
        ra.noalias() += edge.weight * Ba.middleRows<4>(4 * ka).transpose() * cb.segment<4>(4 * kb);
        rb.noalias() += edge.weight * Bb.middleRows<4>(4 * kb).transpose() * ca.segment<4>(4 * ka);
        ++ka;
        ++kb;
      }
    }
    const int64_t oa = P.unknown_offsets[static_cast<size_t>(edge.a)], ob = P.unknown_offsets[static_cast<size_t>(edge.b)];
    system.r.segment(oa, ra.size()) += ra;
    system.r.segment(ob, rb.size()) += rb;
    for (Eigen::Index c = 0; c < Kab.cols(); ++c) {
      for (Eigen::Index r = 0; r < Kab.rows(); ++r) {
        if (Kab(r, c) == 0) continue;
        triplets.emplace_back(static_cast<int>(oa + r), static_cast<int>(ob + c), Kab(r, c));
        triplets.emplace_back(static_cast<int>(ob + c), static_cast<int>(oa + r), Kab(r, c));
      }
    }
  }
  system.K.resize(D, D);
  system.K.setFromTriplets(triplets.begin(), triplets.end());
  return Status::Ok();
}

// y ← block-Jacobi preconditioner applied to x.
void apply_block_jacobi(const Problem& P, const CoupledSystem& system, const Eigen::VectorXd& x, Eigen::VectorXd& y) {
  y.resize(x.size());
  parallel_for_chunks(P.V, kVerticesPerThread * 8, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) {
      const int d = P.unknowns(static_cast<int>(i));
      if (d == 0) continue;
      const int64_t o = P.unknown_offsets[static_cast<size_t>(i)];
      const Eigen::Map<const Eigen::MatrixXd> inverse(system.block_inverses.data() + system.block_offsets[static_cast<size_t>(i)], d, d);
      y.segment(o, d).noalias() = inverse * x.segment(o, d);
    }
  });
}

// y ← K x, K symmetric so column c of K is row c: each thread owns a range of output entries.
void multiply(const Eigen::SparseMatrix<double>& K, const Eigen::VectorXd& x, Eigen::VectorXd& y) {
  y.resize(x.size());
  parallel_for_chunks(K.cols(), 4096, [&](int64_t first, int64_t last) {
    for (int64_t c = first; c < last; ++c) {
      double sum = 0;
      for (Eigen::SparseMatrix<double>::InnerIterator it(K, c); it; ++it) sum += it.value() * x(it.index());
      y(c) = sum;
    }
  });
}

// Preconditioned conjugate gradients, warm-started from the block-Jacobi solution (every vertex
// solved against its own data, λ and the diagonal of the edge term).
void solve_conjugate_gradient(const Problem& P, const CoupledSystem& system, const FitOptions& options,
                              Eigen::VectorXd& y, FitReport& report) {
  apply_block_jacobi(P, system, system.r, y);
  Eigen::VectorXd Ky, residual, z, direction, Kd;
  multiply(system.K, y, Ky);
  residual = system.r - Ky;
  const double target = options.tolerance * system.r.norm();
  apply_block_jacobi(P, system, residual, z);
  direction = z;
  double rz = residual.dot(z);
  report.converged = residual.norm() <= target;
  int iteration = 0;
  while (!report.converged && iteration < options.max_iterations) {
    multiply(system.K, direction, Kd);
    const double alpha = rz / direction.dot(Kd);
    y += alpha * direction;
    residual -= alpha * Kd;
    ++iteration;
    if (residual.norm() <= target) {
      report.converged = true;
      break;
    }
    apply_block_jacobi(P, system, residual, z);
    const double rz_next = residual.dot(z);
    direction = z + (rz_next / rz) * direction;
    rz = rz_next;
  }
  report.iterations = iteration;
}

Status solve_coupled(const Problem& P, const std::vector<Edge>& edges, const FitOptions& options, Eigen::VectorXd& y,
                     FitReport& report) {
  CoupledSystem system;
  ANIMSPACE_RETURN_IF_ERROR(assemble(P, edges, system));
  report.nonzeros = system.K.nonZeros();
  if (options.solver == FitSolver::kConjugateGradient) {
    solve_conjugate_gradient(P, system, options, y, report);
    return Status::Ok();
  }
  Eigen::SimplicialLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholesky(system.K);
  if (cholesky.info() != Eigen::Success) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "fit: the coupled normal matrix is not positive definite (some vertex is not determined by the "
                      "examples); set vertex_regularisation > 0");
  }
  y = cholesky.solve(system.r);
  return Status::Ok();
}

// p'_i = B_i y_i + c_i for every vertex (normalised frame), 4 × I.
InfluenceVectors positions_from_unknowns(const Problem& P, const Eigen::VectorXd& y) {
  InfluenceVectors positions(4, P.influences->influence_count());
  parallel_for_chunks(P.V, kVerticesPerThread * 8, [&](int64_t first, int64_t last) {
    Eigen::MatrixXd B;
    Eigen::VectorXd c;
    for (int64_t i = first; i < last; ++i) {
      vertex_basis(P, static_cast<int>(i), B, c);
      const int d = P.unknowns(static_cast<int>(i));
      const Eigen::VectorXd p = B * y.segment(P.unknown_offsets[static_cast<size_t>(i)], d) + c;
      const int m = P.influence_count(static_cast<int>(i));
      for (int a = 0; a < m; ++a) positions.col(P.influence_begin(static_cast<int>(i)) + a) = p.segment<4>(4 * a);
    }
  });
  return positions;
}

// Training error over all examples, in model units.
void measure_residual(const Problem& P, const InfluenceVectors& positions, double scale, FitReport& report) {
  std::vector<double> squared(static_cast<size_t>(P.V)), largest(static_cast<size_t>(P.V));
  parallel_for_chunks(P.V, kVerticesPerThread * 4, [&](int64_t first, int64_t last) {
    for (int64_t i = first; i < last; ++i) {
      double sum = 0, worst = 0;
      for (int k = 0; k < P.n; ++k) {
        Eigen::Vector3d v = -P.points.block<3, 1>(3 * i, k);
        for (int e = P.influences->begin(static_cast<int>(i)); e < P.influences->end(static_cast<int>(i)); ++e) {
          v.noalias() += P.poses[static_cast<size_t>(k * P.b + P.bone(e))] * positions.col(e);
        }
        sum += v.squaredNorm();
        worst = std::max(worst, v.norm());
      }
      squared[static_cast<size_t>(i)] = sum;
      largest[static_cast<size_t>(i)] = worst;
    }
  });
  const double total = std::accumulate(squared.begin(), squared.end(), 0.0);
  report.residual_rms = std::sqrt(total / (static_cast<double>(P.n) * std::max(1, P.V))) / scale;
  report.residual_max = (P.V > 0 ? *std::max_element(largest.begin(), largest.end()) : 0.0) / scale;
}

// The shared pipeline: returns p' (normalised frame) and fills the report.
Result<InfluenceVectors> fit_positions(const FitExamples& examples, const FaceMatrix& faces,
                                       const InfluenceSets& influences, const FitOptions& options,
                                       const Normalisation& normalisation, Problem& P, FitReport& report) {
  // 1. Examples, poses and Gram blocks in the normalised frame.
  build_problem(examples, influences, normalisation, options.vertex_regularisation, P);
  // 2. Edges of eq. 4.4 (none when δ = 0).
  auto edges = make_edges(faces, options.edge_regularisation, P);
  if (!edges.ok()) return edges.error();
  report.vertices = P.V;
  report.examples = P.n;
  report.edges = static_cast<int>(edges->size());
  report.unknowns = P.unknown_offsets.back();
  report.scale = normalisation.scale;
  // 3. Solve: per vertex when uncoupled, else one sparse system.
  Eigen::VectorXd y;
  report.coupled = !edges->empty();
  if (report.coupled) {
    ANIMSPACE_RETURN_IF_ERROR(solve_coupled(P, *edges, options, y, report));
  } else {
    ANIMSPACE_RETURN_IF_ERROR(solve_per_vertex(P, y));
  }
  if (!y.allFinite()) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "fit: the solution is not finite (singular system); set vertex_regularisation > 0");
  }
  // 4. Back to p = B y + c, and the training error.
  InfluenceVectors positions = positions_from_unknowns(P, y);
  measure_residual(P, positions, normalisation.scale, report);
  return positions;
}

}  // namespace

Result<AnimationSpaceModel> fit_animation_space(const Skeleton& skeleton, const FitExamples& examples,
                                                const FaceMatrix& faces, const InfluenceSets& influences,
                                                const FitOptions& options, FitReport* report) {
  const auto start = std::chrono::steady_clock::now();
  ANIMSPACE_RETURN_IF_ERROR(check_inputs(skeleton, examples, faces, influences, options));
  auto normalisation = make_normalisation(examples.meshes, options.normalise_scale);
  if (!normalisation.ok()) return normalisation.error();
  FitReport local;
  FitReport& out = report ? *report : local;
  out = FitReport{};
  Problem P;
  P.parametrisation = Parametrisation::kAnimationSpace;
  auto positions = fit_positions(examples, faces, influences, options, *normalisation, P, out);
  if (!positions.ok()) return positions.error();

  AnimationSpaceModel model;
  model.skeleton = skeleton;
  model.faces = faces;
  model.influences = influences;
  // p = T⁻¹ p': T⁻¹ keeps the weight row, so p̲ = 1 survives the mapping.
  model.positions = normalisation->inverse() * *positions;
  out.seconds = seconds_since(start);
  return model;
}

Result<LinearBlendModel> fit_linear_blend(const Skeleton& skeleton, const PointMatrix& rest_points,
                                          const FitExamples& examples, const FaceMatrix& faces,
                                          const InfluenceSets& influences, const FitOptions& options,
                                          FitReport* report) {
  const auto start = std::chrono::steady_clock::now();
  ANIMSPACE_RETURN_IF_ERROR(check_inputs(skeleton, examples, faces, influences, options));
  if (rest_points.rows() != influences.vertex_count()) {
    return invalid("fit: rest points have " + std::to_string(rest_points.rows()) + " rows, expected " +
                   std::to_string(influences.vertex_count()) + " (one per vertex)");
  }
  if (!rest_points.allFinite()) return invalid("fit: rest points contain a NaN or infinite coordinate");
  auto normalisation = make_normalisation(examples.meshes, options.normalise_scale);
  if (!normalisation.ok()) return normalisation.error();
  FitReport local;
  FitReport& out = report ? *report : local;
  out = FitReport{};

  Problem P;
  P.parametrisation = Parametrisation::kLinearBlend;
  // q'_j = T Ĝ_j⁻¹ v̂ (§3.1's SSD position, in the normalised frame).
  const Transform forward = normalisation->forward();
  TransformList rest_inverse(skeleton.rest.size());
  for (size_t j = 0; j < skeleton.rest.size(); ++j) rest_inverse[j] = forward * affine_inverse(skeleton.rest[j]);
  P.rest_directions.resize(4, influences.influence_count());
  for (int i = 0; i < influences.vertex_count(); ++i) {
    const Eigen::Vector4d rest = rest_points.row(i).transpose().cast<double>().homogeneous();
    for (int k = influences.begin(i); k < influences.end(i); ++k) {
      P.rest_directions.col(k) = rest_inverse[static_cast<size_t>(influences.bones[static_cast<size_t>(k)])] * rest;
    }
  }
  auto positions = fit_positions(examples, faces, influences, options, *normalisation, P, out);
  if (!positions.ok()) return positions.error();

  LinearBlendModel model;
  model.skeleton = skeleton;
  model.faces = faces;
  model.rest_points = rest_points.transpose().cast<double>();
  model.influences = influences;
  // p_j = w_j q_j and q_j has weight 1, so w_j is the weight component of p_j; the eliminated
  // one is recomputed from the others so that the sum is 1 to rounding.
  model.weights.resize(influences.influence_count());
  for (int i = 0; i < influences.vertex_count(); ++i) {
    double sum = 0;
    for (int k = influences.begin(i); k + 1 < influences.end(i); ++k) {
      model.weights(k) = (*positions)(3, k);
      sum += model.weights(k);
    }
    model.weights(influences.end(i) - 1) = 1 - sum;
  }
  out.seconds = seconds_since(start);
  return model;
}

Result<InfluenceSets> grow_influence_sets(const Skeleton& skeleton, const std::vector<int32_t>& owning_bone,
                                          const FaceMatrix& faces, const InfluenceGrowthOptions& options) {
  const int b = skeleton.bone_count();
  const int V = static_cast<int>(owning_bone.size());
  if (options.rings < 0) return invalid("grow_influence_sets: rings must be ≥ 0");
  if (options.max_influences < 1) return invalid("grow_influence_sets: max_influences must be ≥ 1");
  for (int i = 0; i < V; ++i) {
    const int bone = owning_bone[static_cast<size_t>(i)];
    if (bone < 0 || bone >= b) {
      return invalid("grow_influence_sets: vertex " + std::to_string(i) + " is labelled with bone " +
                     std::to_string(bone) + ", expected 0 … " + std::to_string(b - 1));
    }
  }
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      if (faces(f, c) < 0 || faces(f, c) >= V) {
        return invalid("grow_influence_sets: face " + std::to_string(f) + " indexes vertex " +
                       std::to_string(faces(f, c)) + ", expected 0 … " + std::to_string(V - 1));
      }
    }
  }
  // Vertex adjacency as compressed rows.
  const auto edges = geometry::unique_edges(faces);
  std::vector<int32_t> adjacency_offsets(static_cast<size_t>(V) + 1, 0), adjacency(2 * edges.size());
  for (const auto& [u, w] : edges) {
    ++adjacency_offsets[static_cast<size_t>(u) + 1];
    ++adjacency_offsets[static_cast<size_t>(w) + 1];
  }
  std::partial_sum(adjacency_offsets.begin(), adjacency_offsets.end(), adjacency_offsets.begin());
  {
    std::vector<int32_t> fill(adjacency_offsets.begin(), adjacency_offsets.end() - 1);
    for (const auto& [u, w] : edges) {
      adjacency[static_cast<size_t>(fill[static_cast<size_t>(u)]++)] = w;
      adjacency[static_cast<size_t>(fill[static_cast<size_t>(w)]++)] = u;
    }
  }

  struct Candidate {
    int bone = 0;
    int rank = 0;      // 0 own bone, 1 its parent, 2 others
    int distance = 0;  // rings to the nearest vertex the bone owns
    int count = 0;     // vertices within `rings` it owns
  };
  InfluenceSets sets;
  sets.offsets.reserve(static_cast<size_t>(V) + 1);
  std::vector<int> visited(static_cast<size_t>(V), -1);
  std::vector<int32_t> frontier, next, chosen;
  std::vector<Candidate> candidates;
  for (int i = 0; i < V; ++i) {
    candidates.clear();
    const auto add = [&](int bone, int rank, int distance) {
      for (Candidate& c : candidates) {
        if (c.bone == bone) {
          c.rank = std::min(c.rank, rank);
          c.distance = std::min(c.distance, distance);
          ++c.count;
          return;
        }
      }
      candidates.push_back({bone, rank, distance, 1});
    };
    const int own = owning_bone[static_cast<size_t>(i)];
    add(own, 0, 0);
    if (options.include_parent && skeleton.parents[static_cast<size_t>(own)] >= 0) {
      add(skeleton.parents[static_cast<size_t>(own)], 1, 0);
      candidates.back().count = 0;  // the parent is added by rule, not by owning vertices
    }
    // Breadth-first over `rings` edges.
    visited[static_cast<size_t>(i)] = i;
    frontier.assign(1, i);
    for (int ring = 1; ring <= options.rings && !frontier.empty(); ++ring) {
      next.clear();
      for (int u : frontier) {
        for (int32_t a = adjacency_offsets[static_cast<size_t>(u)]; a < adjacency_offsets[static_cast<size_t>(u) + 1]; ++a) {
          const int w = adjacency[static_cast<size_t>(a)];
          if (visited[static_cast<size_t>(w)] == i) continue;
          visited[static_cast<size_t>(w)] = i;
          next.push_back(w);
          add(owning_bone[static_cast<size_t>(w)], 2, ring);
        }
      }
      frontier.swap(next);
    }
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) {
      if (x.rank != y.rank) return x.rank < y.rank;
      if (x.distance != y.distance) return x.distance < y.distance;
      if (x.count != y.count) return x.count > y.count;
      return x.bone < y.bone;
    });
    chosen.clear();
    for (size_t c = 0; c < candidates.size() && static_cast<int>(chosen.size()) < options.max_influences; ++c) {
      chosen.push_back(candidates[c].bone);
    }
    std::sort(chosen.begin(), chosen.end());
    sets.bones.insert(sets.bones.end(), chosen.begin(), chosen.end());
    sets.offsets.push_back(static_cast<int32_t>(sets.bones.size()));
  }
  return sets;
}

}  // namespace animspace::animation_space
