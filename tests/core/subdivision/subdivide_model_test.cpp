// Subdivision in animation space (Merry 2007 §4.2): posing P' = P S against refining the posed
// control mesh with OpenSubdiv's PrimvarRefiner here, independently of core/subdivision; the
// linear-blend alternative against the same reference; the limit normals against the geometry.
#include "core/subdivision/subdivide_model.h"

#include <cmath>
#include <filesystem>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>

#include "core/animspace/animspace_io.h"
#include "core/animspace/import.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "core/geometry/normals.h"
#include "tests/support/animspace_fixtures.h"
#include "tests/support/articulated_tube.h"
#include "tests/support/test_support.h"

namespace animspace::subdivision {
namespace {

namespace as = animation_space;
namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

// A point as OpenSubdiv's PrimvarRefiner wants it.
struct Point {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  void Clear() { x.setZero(); }
  void AddWithWeight(const Point& source, double weight) { x += weight * source.x; }
};

// The reference: `points` (a posed control mesh) refined `levels` times by a refiner built here
// (Loop unless told), with the boundary rule core/subdivision documents (smooth boundary, corners
// kept).
class Reference {
 public:
  Reference(const FaceMatrix& faces, int vertex_count, int levels, Sdc::SchemeType scheme = Sdc::SCHEME_LOOP)
      : levels_(levels), faces_(faces) {
    sizes_.assign(static_cast<size_t>(faces.rows()), 3);
    Far::TopologyDescriptor descriptor;
    descriptor.numVertices = vertex_count;
    descriptor.numFaces = static_cast<int>(faces.rows());
    descriptor.numVertsPerFace = sizes_.data();
    descriptor.vertIndicesPerFace = faces_.data();
    Sdc::Options sdc;
    sdc.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
    using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
    refiner_.reset(Factory::Create(descriptor, Factory::Options(scheme, sdc)));
    Far::TopologyRefiner::UniformOptions uniform(levels);
    uniform.fullTopologyInLastLevel = true;
    refiner_->RefineUniform(uniform);
  }

  std::vector<Point> refine(const PointMatrix& points) const {
    std::vector<Point> level(static_cast<size_t>(points.rows()));
    for (Eigen::Index i = 0; i < points.rows(); ++i) level[static_cast<size_t>(i)].x = points.row(i).cast<double>();
    const Far::PrimvarRefinerReal<double> primvar(*refiner_);
    for (int l = 1; l <= levels_; ++l) {
      std::vector<Point> next(static_cast<size_t>(refiner_->GetLevel(l).GetNumVertices()));
      primvar.Interpolate(l, level, next);
      level = std::move(next);
    }
    return level;
  }

  // The limit normal ∂u × ∂v, normalised, at every finest-level vertex.
  std::vector<Eigen::Vector3d> limit_normals(const PointMatrix& points) const {
    const std::vector<Point> finest = refine(points);
    std::vector<Point> position(finest.size()), du(finest.size()), dv(finest.size());
    Far::PrimvarRefinerReal<double>(*refiner_).Limit(finest, position, du, dv);
    std::vector<Eigen::Vector3d> normals;
    for (size_t i = 0; i < finest.size(); ++i) normals.push_back(du[i].x.cross(dv[i].x).normalized());
    return normals;
  }

  // The finest level's triangles (Loop).
  FaceMatrix faces() const {
    const Far::TopologyLevel& level = refiner_->GetLevel(levels_);
    FaceMatrix out(level.GetNumFaces(), 3);
    for (int f = 0; f < level.GetNumFaces(); ++f) {
      const auto corners = level.GetFaceVertices(f);
      out.row(f) << corners[0], corners[1], corners[2];
    }
    return out;
  }

 private:
  int levels_;
  FaceMatrix faces_;
  std::vector<int> sizes_;
  std::unique_ptr<Far::TopologyRefiner> refiner_;
};

double max_distance(const PointMatrix& posed, const std::vector<Point>& reference) {
  EXPECT_EQ(posed.rows(), static_cast<Eigen::Index>(reference.size()));
  double worst = 0;
  for (Eigen::Index i = 0; i < posed.rows(); ++i) {
    worst = std::max(worst, (posed.row(i).cast<double>().transpose() - reference[static_cast<size_t>(i)].x).norm());
  }
  return worst;
}

double angle_between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// A two-bone limb: bone 1 holds x < 0, bone 2 (joint at the origin) x > 0, blended linearly over
// |x| < blend. Bone 0 is the fixed root.
as::LinearBlendModel two_bone_limb(const PointMatrix& rest, const FaceMatrix& faces, double blend) {
  as::LinearBlendModel lbs;
  lbs.skeleton.parents = {-1, 0, 1};
  lbs.skeleton.rest = {as::Transform::Identity(), as::Transform::Identity(), as::Transform::Identity()};
  lbs.faces = faces;
  lbs.rest_points = rest.cast<double>().transpose();
  std::vector<double> weights;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    const double child = std::clamp(0.5 + 0.5 * rest(i, 0) / blend, 0.0, 1.0);
    if (child < 1) {
      lbs.influences.bones.push_back(1);
      weights.push_back(1 - child);
    }
    if (child > 0) {
      lbs.influences.bones.push_back(2);
      weights.push_back(child);
    }
    lbs.influences.offsets.push_back(static_cast<int32_t>(lbs.influences.bones.size()));
  }
  lbs.weights = Eigen::Map<Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  return lbs;
}

// Bone 2 turned by `angle` about z at the joint (the origin); bone 1 still.
as::TransformList bend(double angle) {
  as::TransformList pose(3, as::Transform::Identity());
  pose[2] = as::make_transform(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                               Eigen::Vector3d::Zero());
  return pose;
}

// The articulated tube's rest mesh with its joint moved to x = 0.
PointMatrix centred(PointMatrix rest, double joint_x) {
  rest.col(0).array() -= static_cast<float>(joint_x);
  return rest;
}

PointMatrix icosahedron(double stretch_x) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  Eigen::MatrixX3d v(12, 3);
  v << -1, t, 0, 1, t, 0, -1, -t, 0, 1, -t, 0, 0, -1, t, 0, 1, t, 0, -1, -t, 0, 1, -t, t, 0, -1, t, 0, 1, -t, 0, -1,
      -t, 0, 1;
  v.col(0) *= stretch_x;
  return v.cast<float>();
}

FaceMatrix icosahedron_faces() {
  FaceMatrix faces(20, 3);
  faces << 0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9, 4, 3,
      4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1;
  return faces;
}

// Both sides end in float32 (evaluate writes float; the reference starts from the float posed
// control points and S's rows are convex), so they differ by at most two roundings of the
// largest coordinate, 2·2⁻²⁴·max|v|; allowed: twice that.
double rounding_tolerance(const PointMatrix& posed) { return 4.0 * std::ldexp(1.0, -24) * posed.cwiseAbs().maxCoeff(); }

TEST(SubdivideModel, PosingTheSubdividedModelEqualsRefiningThePosedMesh) {
  // A general animation-space model (random p, not from a rig) on the tube's connectivity,
  // posed by random rotations of every joint of a random skeleton.
  const testing::ArticulatedTube tube = testing::make_tube(3, 4, 1, 7);
  const as::Skeleton skeleton = testing::random_skeleton(5, 11);
  as::AnimationSpaceModel model = testing::random_model(skeleton, static_cast<int>(tube.rest.rows()), 13);
  model.faces = tube.faces;
  ASSERT_TRUE(as::validate(model).ok());
  std::mt19937_64 engine(17);
  for (int levels = 1; levels <= 2; ++levels) {
    SubdivisionOptions options;
    options.levels = levels;
    auto refined = subdivide(model, options);
    ASSERT_TRUE(refined.ok()) << refined.error().message;
    ASSERT_TRUE(as::validate(*refined).ok());
    const Reference reference(model.faces, model.vertex_count(), levels);
    for (int k = 0; k < 10; ++k) {
      const as::TransformList pose = testing::random_pose(skeleton, engine, std::numbers::pi);
      PointMatrix control, posed;
      as::evaluate(model, pose, control);
      as::evaluate(*refined, pose, posed);
      EXPECT_LE(max_distance(posed, reference.refine(control)), rounding_tolerance(control))
          << "levels " << levels << ", pose " << k;
      // The tangent planes give the limit surface's normal of the posed mesh: the same sums
      // (P U, P W) posed, so equal to rounding too (measured ≤ 2.4e-6 rad: float normals).
      PointMatrix normals;
      as::evaluate_normals(*refined, pose, normals);
      const std::vector<Eigen::Vector3d> limit = reference.limit_normals(control);
      double worst = 0;
      for (Eigen::Index i = 0; i < normals.rows(); ++i) {
        worst = std::max(worst, angle_between(normals.row(i).cast<double>().transpose(), limit[static_cast<size_t>(i)]));
      }
      EXPECT_LT(worst, 1e-5) << "levels " << levels << ", pose " << k;
    }
  }
}

TEST(SubdivideModel, CatmullClarkOnTrianglesIsExactToo) {
  // Catmull–Clark on the model's triangles (the first step makes quads; stored as two triangles
  // each, which moves no vertex): posed against OpenSubdiv's Catmull–Clark of the posed mesh.
  const testing::ArticulatedTube tube = testing::make_tube(2, 4, 1, 5);
  const as::Skeleton skeleton = testing::random_skeleton(4, 23);
  as::AnimationSpaceModel model = testing::random_model(skeleton, static_cast<int>(tube.rest.rows()), 29);
  model.faces = tube.faces;
  SubdivisionOptions options;
  options.levels = 2;
  options.scheme = Scheme::kCatmullClark;
  auto refined = subdivide(model, options);
  ASSERT_TRUE(refined.ok()) << refined.error().message;
  ASSERT_TRUE(as::validate(*refined).ok());
  const Reference reference(model.faces, model.vertex_count(), 2, Sdc::SCHEME_CATMARK);
  std::mt19937_64 engine(31);
  for (int k = 0; k < 5; ++k) {
    const as::TransformList pose = testing::random_pose(skeleton, engine, std::numbers::pi);
    PointMatrix control, posed;
    as::evaluate(model, pose, control);
    as::evaluate(*refined, pose, posed);
    EXPECT_LE(max_distance(posed, reference.refine(control)), rounding_tolerance(control)) << "pose " << k;
  }
}

TEST(SubdivideModel, TheCowRigPosesExactlyWhenSubdivided) {
  // The real rig of ../shared/data (11 666 vertices, up to 15 weights per vertex), one Loop step,
  // posed by random joint rotations (it poses exactly for any).
  const auto data = testing::shared_data_dir();
  if (!data) GTEST_SKIP() << "shared data folder (../shared/data) is absent; skipping the cow-rig test";
  const std::filesystem::path dir = *data / "cow-rig";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << dir.string() << " is absent; skipping";
  auto rig = as::read_libigl_rig(dir / "cow.obj", dir / "cow.tgf", dir / "cow.DMAT");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const as::AnimationSpaceModel model = as::from_linear_blend(rig->model);
  auto refined = subdivide(model, SubdivisionOptions{});
  ASSERT_TRUE(refined.ok()) << refined.error().message;
  const Reference reference(model.faces, model.vertex_count(), 1);
  for (const as::TransformList& pose : as::random_joint_rotation_poses(model.skeleton, 3, 35.0 * std::numbers::pi / 180, 7)) {
    PointMatrix control, posed;
    as::evaluate(model, pose, control);
    as::evaluate(*refined, pose, posed);
    EXPECT_LE(max_distance(posed, reference.refine(control)), rounding_tolerance(control));
  }
}

TEST(SubdivideModel, LinearBlendSubdivisionIsNotExactOnABentLimbWhileAnimationSpaceIs) {
  // Merry 2007 §4.2: subdividing the rest pose and the weights apart poses Σ_j (S w)_j M_j (S v̂),
  // not S (Σ_j w_j M_j v̂). A tube of two segments, the skin blended over two rings either side
  // of the elbow, bent 90°.
  const testing::ArticulatedTube tube = testing::make_tube(2, 6, 1, 3);
  const double joint_x = tube.joint[1].x();
  const PointMatrix rest = centred(tube.rest, joint_x);
  const as::LinearBlendModel lbs = two_bone_limb(rest, tube.faces, 2 * testing::ArticulatedTube::kRingSpacing);
  ASSERT_TRUE(as::validate(lbs).ok());
  const double diagonal = (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).cast<double>().norm();
  const as::TransformList pose = bend(std::numbers::pi / 2);
  PointMatrix control;
  as::evaluate(lbs, pose, control);

  auto matrices = subdivision_matrices(triangle_topology(lbs.faces, lbs.vertex_count()), SubdivisionOptions{});
  ASSERT_TRUE(matrices.ok());
  const as::AnimationSpaceModel refined = apply(as::from_linear_blend(lbs), *matrices);
  const as::LinearBlendModel refined_lbs = subdivide_linear_blend(lbs, *matrices);
  ASSERT_TRUE(as::validate(refined_lbs).ok());
  const std::vector<Point> reference = Reference(lbs.faces, lbs.vertex_count(), 1).refine(control);
  PointMatrix exact, alternative;
  as::evaluate(refined, pose, exact);
  as::evaluate(refined_lbs, pose, alternative);
  EXPECT_LE(max_distance(exact, reference), rounding_tolerance(control));
  // Independent of the code: in the rest pose both are the refined rest mesh.
  PointMatrix rest_lbs;
  as::evaluate(refined_lbs, bend(0), rest_lbs);
  EXPECT_LE(max_distance(rest_lbs, Reference(lbs.faces, lbs.vertex_count(), 1).refine(rest)), rounding_tolerance(rest));
  // Bent, the linear blend alternative misses by a visible fraction of the limb (measured 0.94%
  // of the diagonal, where the exact one is 1.4e-8; 0.1% required).
  const double alternative_error = max_distance(alternative, reference) / diagonal;
  EXPECT_GT(alternative_error, 1e-3) << "linear blend alternative: " << alternative_error << " of the diagonal";
}

TEST(SubdivideModel, LimitNormalsOfAClosedMeshPointOutwardAndMatchFiniteDifferences) {
  // A stretched icosahedron (every vertex extraordinary, valence 5) as a two-bone limb.
  const PointMatrix rest = icosahedron(2.0);
  const FaceMatrix faces = icosahedron_faces();
  const as::LinearBlendModel lbs = two_bone_limb(rest, faces, 1.0);
  const as::AnimationSpaceModel model = as::from_linear_blend(lbs);
  const int levels = 2;
  SubdivisionOptions options;
  options.levels = levels;
  auto refined = subdivide(model, options);
  ASSERT_TRUE(refined.ok()) << refined.error().message;
  ASSERT_TRUE(refined->has_tangents());

  // Rest pose: the limit surface of a convex control mesh is convex, so every normal points
  // away from the centre.
  PointMatrix points, normals;
  as::evaluate(*refined, bend(0), points);
  as::evaluate_normals(*refined, bend(0), normals);
  const Eigen::RowVector3f centre = points.colwise().mean();
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    EXPECT_GT(normals.row(i).dot((points.row(i) - centre).normalized()), 0.2f) << "vertex " << i;
  }

  // Bent 60°: against the surface itself, by finite differences: the posed control mesh refined
  // three levels further (OpenSubdiv keeps a vertex's index as it refines: vertex-children come
  // first), whose facets around vertex i shrink towards the limit surface's tangent plane there.
  const as::TransformList pose = bend(std::numbers::pi / 3);
  PointMatrix control;
  as::evaluate(lbs, pose, control);
  as::evaluate_normals(*refined, pose, normals);
  const Reference fine(faces, static_cast<int>(rest.rows()), levels + 3);
  const std::vector<Point> fine_points = fine.refine(control);
  Eigen::MatrixX3d fine_matrix(static_cast<Eigen::Index>(fine_points.size()), 3);
  for (size_t i = 0; i < fine_points.size(); ++i) fine_matrix.row(static_cast<Eigen::Index>(i)) = fine_points[i].x;
  const Eigen::MatrixX3d facet_normals = geometry::area_weighted_normals(fine_matrix, fine.faces());
  double worst = 0;
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    worst = std::max(worst, angle_between(normals.row(i).cast<double>().transpose(), facet_normals.row(i).transpose()));
  }
  // Measured 0.009° at worst (the facets' remaining discretisation error); 0.1° allowed.
  EXPECT_LT(worst, 0.1 * std::numbers::pi / 180) << "worst angle " << worst * 180 / std::numbers::pi << "°";
}

TEST(SubdivideModel, ContainerKeepsMetricsAndPosesAndDropsTheLevels) {
  auto demo = demo::make_demo_animation_space_container();
  ASSERT_TRUE(demo.ok()) << demo.error().message;
  auto control = as::load(*demo, "demo");
  ASSERT_TRUE(control.ok());
  SubdivisionReport report;
  auto out = subdivide_container(*demo, "demo", SubdivisionOptions{}, &report);
  ASSERT_TRUE(out.ok()) << out.error().message;
  auto model = as::load(*out, "subdivided");
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_EQ(model->vertex_count(), report.vertices);
  EXPECT_GT(report.vertices, control->vertex_count());
  EXPECT_EQ(report.scheme, Scheme::kLoop);
  EXPECT_EQ(out->metadata_value("kind"), "animation_space");
  EXPECT_EQ(out->metadata_value("subdivision.levels"), "1");
  EXPECT_TRUE(report.metrics_kept);
  EXPECT_TRUE(as::load_metrics(*out, model->bone_count(), "subdivided").ok());
  for (const std::string& name : out->section_names()) EXPECT_NE(name.rfind("lod.", 0), 0u) << name;
  EXPECT_FALSE(out->metadata().contains("lod_levels"));
  // The stored frames, if any, are the control frames refined (S applied), row by row.
  if (demo->has_section(container::sections::kSequenceFrames)) {
    auto frames = demo->float_matrix(container::sections::kSequenceFrames);
    auto refined_frames = out->float_matrix(container::sections::kSequenceFrames);
    ASSERT_TRUE(frames.ok() && refined_frames.ok());
    ASSERT_EQ(refined_frames->cols(), 3 * model->vertex_count());
    PointMatrix first = Eigen::Map<const PointMatrix>(frames->row(0).data(), control->vertex_count(), 3);
    const Reference reference(control->faces, control->vertex_count(), 1);
    const PointMatrix stored = Eigen::Map<const PointMatrix>(refined_frames->row(0).data(), model->vertex_count(), 3);
    EXPECT_LE(max_distance(stored, reference.refine(first)), rounding_tolerance(first));
  }
  // Another kind is refused, naming the source and the kind.
  auto pmsc = demo::make_demo_pmsc_container();
  ASSERT_TRUE(pmsc.ok());
  auto refused = subdivide_container(*pmsc, "pmsc.anim", SubdivisionOptions{});
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(refused.error().message.find("pmsc.anim: metadata kind"), std::string::npos) << refused.error().message;
}

}  // namespace
}  // namespace animspace::subdivision
