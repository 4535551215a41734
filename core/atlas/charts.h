// Segmentation of a mesh into charts for texture mapping (Merry 2007 §5.2), by region growing
// with Lloyd re-seeding (Sander, Wood, Gortler, Snyder & Hoppe 2003, "Multi-chart geometry
// images" §3) under the animation-space metric.
//
// The thesis's planarity metric (eq. 5.3, E_area = Σ‖n_i‖ / ‖Σ n_i‖, equivalent to L2,1 of
// Cohen-Steiner et al. 2004) is taken to animation space (its Appendix A.1) with the triangle's
// area bivector B_f = C e1 ∧ C e2 in normalised animation space (C = P^½, §3.3.2): |B_f| is the
// triangle's L2,2 area (×2) and ⟨B_f, B_g⟩ = (a_f·a_g)(b_f·b_g) − (a_f·b_g)(b_f·a_g). A chart's
// proxy is its summed bivector S_c (as an antisymmetric matrix Σ a bᵀ − b aᵀ), so
// cos(f, c) = a_fᵀ S_c b_f / (|B_f| |S_c|). Growing (Sander 2003): from one seed face per chart,
// a face joins the chart that reaches it at the least cost
//   (1 − cos(f, c) + ρ) · ‖centroid_f − centroid_seed‖₂,₂,
// planarity (the thesis's metric) times distance (compactness), ρ a floor so that flat regions
// still grow compactly. Re-seeding: each chart's new seed is its face farthest from the chart's
// boundary; the proxies are re-fitted; until the seeds stop moving.
//
// Then the charts are made topological discs (§5.2: charts must be homeomorphic to discs): a
// chart that is disconnected is cut into its components, one that is not a disc (a cylinder, a
// closed part, two boundary loops meeting at a vertex) is split in two by growing from its two
// mutually farthest faces, until every chart is a disc.
//
// Borders: first smoothed — a face whose two or three neighbours lie in one other chart moves to
// that chart (a few passes before the disc repair), removing one-triangle notches. Then §5.2.3's
// edge straightening: each border between two charts, from corner to corner (where three charts
// meet, or on the mesh's border), is replaced by the shortest path (L2,2 edge lengths) between
// its corners through the two charts' union, kept only if both charts stay discs and neither
// one's E_combined (eq. 5.4, ρ = 0.2, in normalised animation space) grows by more than 1.2×
// (§8.4). Where it would, the thesis retries with a path over the original border's vertices
// (Figure 5.3c); that constrained form is not implemented — the ragged border is kept.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::atlas {

// Per face, in normalised animation space (n = rank used of C, ≤ 4b), column f of each:
// edge1 = C(p1 − p0), edge2 = C(p2 − p0), centroid = C(p0 + p1 + p2)/3.
struct NormalisedFaces {
  Eigen::MatrixXd edge1;     // n × #F
  Eigen::MatrixXd edge2;     // n × #F
  Eigen::MatrixXd centroid;  // n × #F
};

struct ChartOptions {
  int chart_count = 0;         // seeds to start from (≥ 1); the disc repair may add charts
  int lloyd_iterations = 8;    // re-seedings at most
  double compactness = 0.05;   // ρ above (dimensionless: a fraction of the largest 1 − cos, which is 2)
  int smoothing_passes = 3;    // border smoothing passes (0: none)
  int straightening_passes = 2;  // §5.2.3 edge straightening passes (0: none)
};

// Face adjacency across edges: #F × 3, entry k the face sharing edge (v_k, v_{k+1}) with the
// opposite orientation, −1 on a border or a non-manifold edge.
Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> face_adjacency(const FaceMatrix& faces);

// Whether the faces with chart_of_face[f] == chart form one connected topological disc: connected
// across edges, Euler characteristic V − E + F = 1 and no vertex with two outgoing border edges.
bool is_disc(const FaceMatrix& faces, const std::vector<int32_t>& chart_of_face, int32_t chart);

// Splits `chart` in two (Voronoi cells of its two mutually farthest faces under the L2,2 distance
// across faces), then each part further until it is a disc. New charts take ids `next_id`,
// `next_id` + 1, … (next_id is advanced). Returns the ids now covering the chart's faces (only
// `chart` itself for a one-face chart).
std::vector<int32_t> split_chart(const FaceMatrix& faces, const NormalisedFaces& normalised,
                                 std::vector<int32_t>& chart_of_face, int32_t chart, int32_t& next_id);

// Chart of every face (#F entries in [0, charts)), charts numbered densely; every chart a disc.
// Errors: kInvalidArgument for no faces, chart_count < 1, or sizes that differ.
Result<std::vector<int32_t>> segment_charts(const FaceMatrix& faces, const NormalisedFaces& normalised,
                                            const ChartOptions& options);

}  // namespace animspace::atlas
