// The cow rig of ../shared/data/cow-rig (CraGL, libigl formats): a real linear-blend-skinned
// model with ground-truth posed meshes. Skips when the folder is absent.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "core/animspace/import.h"
#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"
#include "core/mesh_io/libigl_rig.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "tests/support/test_support.h"

namespace animspace::animation_space {
namespace {

constexpr int kPoses = 7;

class AnimationSpaceSharedData : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto data = testing::shared_data_dir();
    if (!data) GTEST_SKIP() << "shared data folder (../shared/data) is absent; skipping the cow-rig tests";
    dir_ = *data / "cow-rig";
    if (!std::filesystem::is_directory(dir_)) GTEST_SKIP() << dir_.string() << " is absent; skipping";
    auto rest = mesh_io::read_triangle_mesh(dir_ / "cow.obj");
    ASSERT_TRUE(rest.ok()) << rest.error().message;
    rest_ = *rest;
    const Eigen::RowVector3f extent = rest_.V.colwise().maxCoeff() - rest_.V.colwise().minCoeff();
    diagonal_ = extent.cast<double>().norm();
  }

  Result<ImportedRig> read_rig(const WeightOptions& options = {}) const {
    return read_libigl_rig(dir_ / "cow.obj", dir_ / "cow.tgf", dir_ / "cow.DMAT", options);
  }
  std::filesystem::path pose_file(int k, const char* extension) const {
    return dir_ / "poses" / ("cow-" + std::to_string(k) + extension);
  }

  // Largest vertex distance between `posed` and the mesh `expected`, relative to the rest
  // bounding-box diagonal.
  double relative_deviation(const PointMatrix& posed, const PointMatrix& expected) const {
    EXPECT_EQ(posed.rows(), expected.rows());
    return (posed.cast<double>() - expected.cast<double>()).rowwise().norm().maxCoeff() / diagonal_;
  }

  // The rig read with `options` and converted: printed as `label` with what the weights lost, then
  // each posed file's relative_deviation from the model posed by its .Tmat, in pose order.
  std::vector<double> deviations_with_dropped_weights(const WeightOptions& options, const char* label) const {
    auto rig = read_rig(options);
    EXPECT_TRUE(rig.ok()) << rig.error().message;
    if (!rig.ok()) return {};
    const AnimationSpaceModel model = from_linear_blend(rig->model);
    std::printf("cow, %s: dropped %lld weights (at most %.3g per vertex), %.2f influences per vertex\n", label,
                static_cast<long long>(rig->dropped_weights), rig->max_dropped_weight_sum,
                static_cast<double>(model.influences.influence_count()) / model.vertex_count());
    EXPECT_GT(rig->dropped_weights, 0);
    if (options.drop_budget > 0) {
      EXPECT_LE(rig->max_dropped_weight_sum, options.drop_budget);
    }
    std::vector<double> deviations;
    PointMatrix posed;
    for (int k = 1; k <= kPoses; ++k) {
      auto pose = read_tmat_pose(*rig, pose_file(k, ".Tmat"));
      auto expected = mesh_io::read_triangle_mesh(pose_file(k, ".obj"));
      EXPECT_TRUE(pose.ok() && expected.ok()) << "pose " << k;
      if (!pose.ok() || !expected.ok()) return deviations;
      evaluate(model, *pose, posed);
      deviations.push_back(relative_deviation(posed, expected->V));
      std::printf("cow-%d (%s): max deviation %.3g of the diagonal\n", k, label, deviations.back());
    }
    return deviations;
  }

  std::filesystem::path dir_;
  TriangleMesh rest_;
  double diagonal_ = 0;
};

// The rig converted to animation space (p_j = w_j Ĝ_j⁻¹ v̂, §3.1) reproduces the rest mesh in
// the identity pose (G = Ĝ) and all seven ground-truth posed meshes.
TEST_F(AnimationSpaceSharedData, CowRigReproducesEveryPosedMesh) {
  auto rig = read_rig();
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_EQ(rig->model.skeleton.bone_count(), 16);  // super-root + 15 TGF bones
  EXPECT_EQ(rig->dropped_weights, 0);
  const AnimationSpaceModel model = from_linear_blend(rig->model);
  ASSERT_TRUE(validate(model, 1e-12).ok()) << validate(model).error().message;
  std::printf("cow: %d vertices, %d influences (%.2f per vertex), bounding-box diagonal %.3f\n", model.vertex_count(),
              model.influences.influence_count(),
              static_cast<double>(model.influences.influence_count()) / model.vertex_count(), diagonal_);

  // Hierarchy, checked against the TGF directly: the parent of bone b is the bone ending at b's
  // first joint.
  auto tgf = mesh_io::read_tgf(dir_ / "cow.tgf");
  ASSERT_TRUE(tgf.ok());
  for (Eigen::Index b = 0; b < tgf->bones.rows(); ++b) {
    int expected_parent = 0;
    for (Eigen::Index c = 0; c < tgf->bones.rows(); ++c) {
      if (tgf->bones(c, 1) == tgf->bones(b, 0)) expected_parent = rig->bone_of_source[static_cast<size_t>(c)];
    }
    EXPECT_EQ(rig->model.skeleton.parents[static_cast<size_t>(rig->bone_of_source[static_cast<size_t>(b)])], expected_parent)
        << "TGF bone " << b;
  }

  PointMatrix posed;
  evaluate(model, model.skeleton.rest, posed);
  const double rest_deviation = relative_deviation(posed, rest_.V);
  std::printf("cow identity pose vs cow.obj: max deviation %.3g of the diagonal\n", rest_deviation);
  EXPECT_LT(rest_deviation, 1e-6);

  auto weights = mesh_io::read_dmat(dir_ / "cow.DMAT");
  ASSERT_TRUE(weights.ok());
  double worst = 0;
  for (int k = 1; k <= kPoses; ++k) {
    auto pose = read_tmat_pose(*rig, pose_file(k, ".Tmat"));
    ASSERT_TRUE(pose.ok()) << pose.error().message;
    auto expected = mesh_io::read_triangle_mesh(pose_file(k, ".obj"));
    ASSERT_TRUE(expected.ok()) << expected.error().message;
    evaluate(model, *pose, posed);
    const double deviation = relative_deviation(posed, expected->V);

    // The README's formula straight from the files, in double: Σ_b W(v, b) [v̂ 1] T_b. Against
    // it the conversion must be exact to float32 output rounding; against the posed OBJ files
    // the deviation is the files' own (their Tmat entries have 6 significant digits).
    auto tmat = mesh_io::read_tmat(pose_file(k, ".Tmat"));
    ASSERT_TRUE(tmat.ok());
    PointMatrix direct(rest_.V.rows(), 3);
    for (Eigen::Index v = 0; v < rest_.V.rows(); ++v) {
      const Eigen::RowVector4d row(rest_.V(v, 0), rest_.V(v, 1), rest_.V(v, 2), 1.0);
      Eigen::RowVector3d sum = Eigen::RowVector3d::Zero();
      for (Eigen::Index b = 0; b < weights->cols(); ++b) sum += (*weights)(v, b) * (row * (*tmat)[static_cast<size_t>(b)]);
      direct.row(v) = sum.cast<float>();
    }
    const double conversion = relative_deviation(posed, direct);
    std::printf("cow-%d: max deviation %.3g of the diagonal from cow-%d.obj, %.3g from the formula\n", k, deviation, k,
                conversion);
    EXPECT_LT(deviation, 1e-4) << "pose " << k;
    EXPECT_LT(conversion, 1e-6) << "pose " << k;
    worst = std::max(worst, deviation);
  }
  std::printf("cow: worst pose deviation %.3g of the diagonal from the posed OBJ files\n", worst);
}

// The file's 6.87 non-zeros per vertex include many tiny weights; dropping those below 1e-6
// keeps the poses within float precision of the files too.
TEST_F(AnimationSpaceSharedData, CowRigWithTinyWeightsDropped) {
  WeightOptions options;
  options.drop_below = 1e-6;
  const std::vector<double> deviations = deviations_with_dropped_weights(options, "drop_below 1e-6");
  ASSERT_EQ(deviations.size(), static_cast<size_t>(kPoses));
  for (int k = 1; k <= kPoses; ++k) EXPECT_LT(deviations[static_cast<size_t>(k - 1)], 1e-4) << "pose " << k;
}

// `import-rig`'s rule (issue #55 item 11): each vertex's smallest weights up to 1e-4 of its total
// dropped and the rest renormalised. A vertex then moves by at most the dropped sum times the
// distance between where its dropped and kept bones carry it — a few times the diagonal at most —
// so the posed files are matched within a few 1e-4 of the diagonal.
TEST_F(AnimationSpaceSharedData, CowRigWithImportRigsWeightBudget) {
  WeightOptions options;
  options.drop_budget = 1e-4;
  const std::vector<double> deviations = deviations_with_dropped_weights(options, "drop_budget 1e-4");
  ASSERT_EQ(deviations.size(), static_cast<size_t>(kPoses));
  for (int k = 1; k <= kPoses; ++k) EXPECT_LT(deviations[static_cast<size_t>(k - 1)], 3e-4) << "pose " << k;
}

// Normals on real data: eq. 4.8 tangent planes reproduce SSD's M⁻ᵀ n̂ exactly, and planes
// fitted to the geometry (§4.3.1) stay close to the area-weighted normals of the posed meshes.
TEST_F(AnimationSpaceSharedData, CowNormals) {
  auto rig = read_rig();
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  AnimationSpaceModel model = from_linear_blend(rig->model);
  const Eigen::MatrixX3d rest_normals = geometry::area_weighted_normals(rest_positions(model), model.faces);
  auto ssd_planes = tangent_planes_from_normals(model, rest_normals);
  ASSERT_TRUE(ssd_planes.ok()) << ssd_planes.error().message;
  auto fitted_planes = fit_tangent_planes(model);
  ASSERT_TRUE(fitted_planes.ok()) << fitted_planes.error().message;
  std::printf("cow tangent planes: %lld degenerate (eq. 4.8), %lld degenerate (fitted)\n",
              static_cast<long long>(ssd_planes->degenerate_vertices),
              static_cast<long long>(fitted_planes->degenerate_vertices));

  const auto angle = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
  };
  for (int k = 1; k <= kPoses; ++k) {
    auto pose = read_tmat_pose(*rig, pose_file(k, ".Tmat"));
    ASSERT_TRUE(pose.ok());
    auto posed_mesh = mesh_io::read_triangle_mesh(pose_file(k, ".obj"));
    ASSERT_TRUE(posed_mesh.ok());

    model.tangent_s = ssd_planes->s;
    model.tangent_t = ssd_planes->t;
    PointMatrix ssd_normals;
    evaluate_normals(model, *pose, ssd_normals);
    model.tangent_s = fitted_planes->s;
    model.tangent_t = fitted_planes->t;
    PointMatrix fitted_normals;
    evaluate_normals(model, *pose, fitted_normals);

    const Eigen::MatrixX3d geometric = geometry::area_weighted_normals(posed_mesh->V.cast<double>(), posed_mesh->F);
    double ssd_worst = 0;
    std::vector<double> fitted_angles;
    for (int i = 0; i < model.vertex_count(); ++i) {
      if (rest_normals.row(i).norm() == 0 || geometric.row(i).norm() == 0) continue;
      // Eq. 3.35 computed from the rig's weights and the pose's skinning matrices.
      Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
      for (int k2 = rig->model.influences.begin(i); k2 < rig->model.influences.end(i); ++k2) {
        const size_t j = static_cast<size_t>(rig->model.influences.bones[static_cast<size_t>(k2)]);
        M += rig->model.weights(k2) * ((*pose)[j] * affine_inverse(rig->model.skeleton.rest[j])).topLeftCorner<3, 3>();
      }
      const Eigen::Vector3d expected =
          (M.determinant() > 0 ? 1.0 : -1.0) * M.inverse().transpose() * rest_normals.row(i).transpose();
      ssd_worst = std::max(ssd_worst, angle(ssd_normals.row(i).cast<double>().transpose(), expected));
      fitted_angles.push_back(angle(fitted_normals.row(i).cast<double>().transpose(), geometric.row(i).transpose()));
    }
    std::sort(fitted_angles.begin(), fitted_angles.end());
    const double median = fitted_angles[fitted_angles.size() / 2];
    const double p99 = fitted_angles[fitted_angles.size() * 99 / 100];
    std::printf("cow-%d normals: eq. 4.8 vs M^-T n worst %.2g deg; fitted vs posed area-weighted: median %.3f, "
                "99%% %.3f, max %.3f deg\n",
                k, ssd_worst, median, p99, fitted_angles.back());
    EXPECT_LT(ssd_worst, 1e-3) << "pose " << k;
    EXPECT_LT(median, 0.5) << "pose " << k;
    EXPECT_LT(p99, 4.0) << "pose " << k;
  }
}

}  // namespace
}  // namespace animspace::animation_space
