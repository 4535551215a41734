// An illumination model served in process (Meyer & Anderson 2007 §3.2): its engine announced in
// DescribeModel, lights on the wire (KeyPointPose.light_set) decoded and checked naming each
// field, key values the server gathers itself, server fail-through that computes the full
// indirect illumination for the request's lights (whole and local), client fail-through with
// CompleteMiss, the stream, and thumbnails coloured by the served radiance — each answer checked
// against the engine and the soft cache computed here, independently of the daemon.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/illumination/illumination_io.h"
#include "core/model/servable.h"
#include "core/pmsc/pmsc_model.h"
#include "server/convert.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::InProcessServer;
using testing::TempDir;
using Code = grpc::StatusCode;

const std::string kCornell(demo::kDemoIlluminationModelName);
const std::string kArm(demo::kDemoPmscModelName);

v1::PointArray point_array(const Eigen::VectorXf& values, uint32_t channels = 3) {
  v1::PointArray a;
  a.set_point_count(static_cast<uint32_t>(values.size() / channels));
  a.set_channel_count(channels);
  a.set_data(values.data(), static_cast<size_t>(values.size()) * sizeof(float));
  return a;
}

Eigen::VectorXf values_of(const v1::PointArray& a) {
  Eigen::VectorXf v(static_cast<long>(a.data().size() / sizeof(float)));
  std::memcpy(v.data(), a.data().data(), a.data().size());
  return v;
}

void set_light(v1::LightSet* set, const Eigen::Vector3d& position) {
  auto* light = set->add_lights();
  for (int c = 0; c < 3; ++c) light->add_position(position(c));
}

class IlluminationServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repository_ = new TempDir();
    const auto dir = repository_->path() / kCornell / "1";
    std::filesystem::create_directories(dir);
    auto model = demo::make_demo_illumination_container({1500, 8, 6, 6});
    ASSERT_TRUE(model.ok()) << model.error().message;
    ASSERT_TRUE(container::write_file(dir / "model.anim", *model).ok());
    auto servable = model::load_servable(*model, "test");
    ASSERT_TRUE(servable.ok()) << servable.error().message;
    local_ = new model::Servable(std::move(*servable));
    const auto arm = repository_->path() / kArm / "1";
    std::filesystem::create_directories(arm);
    auto pmsc = demo::make_demo_pmsc_container(24);
    ASSERT_TRUE(pmsc.ok());
    ASSERT_TRUE(container::write_file(arm / "model.anim", *pmsc).ok());
  }
  static void TearDownTestSuite() {
    delete local_;
    delete repository_;
  }

  void SetUp() override {
    server::ServerOptions options;
    options.miss_log_dir = work_.path();
    server_ = std::make_unique<InProcessServer>(repository_->path(), options);
    poses_ = v1::PoseService::NewStub(server_->channel());
  }

  // The model and its engine as this process loads them: the independent computation.
  static const pmsc::PmscModel& model() { return *local_->pmsc; }
  static const illumination::ServedIllumination& engine() { return *local_->illumination; }
  static Eigen::VectorXf gather(const Eigen::Vector3d& position, const std::vector<int>& points) {
    Eigen::VectorXf out;
    engine().engine->indirect({{position, engine().default_intensity()}}, engine().gather, points, out);
    return out;
  }
  static Eigen::VectorXf gather_all(const Eigen::Vector3d& position) {
    return gather(position, engine().engine->all_points());
  }
  // The answer for a light as core gives it, with the engine as the full calculation: what the
  // server must serve, whatever the verdict. (On this small, 8-ray model a light between grid nodes
  // is over the tolerance — 1.8× at the light below — so the calibrated cache rightly fails it
  // through; a HIT is not assumed.)
  static pmsc::CachedPose answer_for(const Eigen::Vector3d& light) {
    pmsc::CachedPose out;
    pmsc::evaluate_cached(model(), gather(light, model().key_points), gather(light, model().check_points), nullptr,
                          [&](Eigen::VectorXf& full) {
                            full = gather_all(light);
                            return true;
                          },
                          out);
    return out;
  }
  // A light inside the training grid (between nodes) and one at floor level, far outside it.
  static Eigen::Vector3d inside_light() { return engine().training_lights[7].position + Eigen::Vector3d(0.01, 0, 0.01); }
  static Eigen::Vector3d floor_light() { return {0.5, 0.03, 0.5}; }

  grpc::Status evaluate(const v1::EvaluateKeyPointsRequest& request, v1::EvaluateKeyPointsResponse* response) {
    grpc::ClientContext context;
    return poses_->EvaluateKeyPoints(&context, request, response);
  }

  static inline TempDir* repository_ = nullptr;
  static inline model::Servable* local_ = nullptr;
  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
};

TEST_F(IlluminationServiceTest, DescribeModelAnnouncesTheIlluminationEngine) {
  auto models = v1::ModelService::NewStub(server_->channel());
  grpc::ClientContext context;
  v1::DescribeModelRequest request;
  request.mutable_model()->set_name(kCornell);
  v1::DescribeModelResponse response;
  ASSERT_TRUE(models->DescribeModel(&context, request, &response).ok());
  const v1::ModelVersion& v = response.model().versions(0);
  EXPECT_EQ(v.state(), v1::VERSION_STATE_AVAILABLE) << v.error();
  EXPECT_EQ(v.kind(), v1::MODEL_KIND_PMSC);
  EXPECT_EQ(v.channel_count(), 3u);
  EXPECT_EQ(v.fail_through(), v1::FAIL_THROUGH_SERVER);
  EXPECT_EQ(v.server_engine(), v1::SERVER_ENGINE_ILLUMINATION);
  EXPECT_TRUE(v.relative_tolerance()) << "the demo's tolerance is relative to each frame (issue #38)";
}

TEST_F(IlluminationServiceTest, TheServerGathersTheKeysOfALightAndAnswersAsForTheClientsKeys) {
  const Eigen::VectorXf keys = gather(inside_light(), model().key_points);
  const Eigen::VectorXf checks = gather(inside_light(), model().check_points);  // empty without check points
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(kCornell);
  set_light(request.add_poses()->mutable_light_set(), inside_light());  // no key values
  v1::KeyPointPose* client = request.add_poses();                       // the client's keys and checks
  *client->mutable_key_values() = point_array(keys);
  if (checks.size() > 0) *client->mutable_check_values() = point_array(checks);
  v1::EvaluateKeyPointsResponse response;
  const grpc::Status status = evaluate(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  // Pose 0 carries its light, so a blend or miss is completed by the server's gather; pose 1 carries
  // only values, so the server answers f̂ and asks for the full values. The verdict is the same.
  const pmsc::CachedPose expected = answer_for(inside_light());
  pmsc::CachedPose estimate_only;
  pmsc::evaluate_cached(model(), keys, checks, nullptr, pmsc::FullCalculation(), estimate_only);
  for (int p = 0; p < 2; ++p) {
    const pmsc::CachedPose& answer = p == 0 ? expected : estimate_only;
    EXPECT_EQ(response.results(p).status(), server::to_proto(answer.status)) << "pose " << p;
    EXPECT_EQ(response.results(p).checked(), checks.size() > 0) << "the server gathers the check points too";
    EXPECT_EQ(response.results(p).check_point_error(), static_cast<float>(answer.check_point_error));
    EXPECT_EQ(response.results(p).full_evaluation_needed(), answer.full_evaluation_needed) << "pose " << p;
    EXPECT_TRUE(values_of(response.results(p).points()).isApprox(answer.points, 1e-5f)) << "pose " << p;
  }
}

// f̂ for `keys`, and α f + (1 − α) f̂ as eq. 11 blends it (α = 1: the full values).
Eigen::VectorXf blended(const pmsc::PmscModel& model, const Eigen::VectorXf& keys, const Eigen::VectorXf& full,
                        float alpha) {
  pmsc::PoseEstimate estimate;
  pmsc::evaluate(model, keys, estimate);
  return alpha * full + (1 - alpha) * estimate.points;
}

TEST_F(IlluminationServiceTest, ALightTheTrainingNeverCoveredFailsThroughToTheFullGatherForIt) {
  const Eigen::VectorXf full = gather_all(floor_light());
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(kCornell);
  set_light(request.add_poses()->mutable_light_set(), floor_light());
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(evaluate(request, &response).ok());
  const v1::PoseResult& result = response.results(0);
  ASSERT_NE(result.status(), v1::CACHE_STATUS_HIT) << "a light at floor level, e_key " << result.key_point_error();
  EXPECT_FALSE(result.full_evaluation_needed());
  const Eigen::VectorXf expected =
      blended(model(), pmsc::gather_key_values(model(), full), full, result.blend_weight());
  EXPECT_TRUE(values_of(result.points()).isApprox(expected, 1e-5f)) << "the server blends with its own full gather";

  // Locally: only the failing regions' points are gathered, each as in the full frame.
  request.set_local_fail_through(true);
  ASSERT_TRUE(evaluate(request, &response).ok());
  const v1::PoseResult& local = response.results(0);
  ASSERT_GT(local.full_points_size(), 0);
  const Eigen::VectorXf served = values_of(local.points());
  for (int j = 0; j < local.full_points_size(); ++j) {
    if (local.full_point_blend_weights(j) != 1.0f) continue;
    const uint32_t i = local.full_points(j);
    EXPECT_EQ(served.segment<3>(3 * i), full.segment<3>(3 * i)) << "point " << i;
  }
}

TEST_F(IlluminationServiceTest, ClientFailThroughCompletesAMissWithTheFullValues) {
  const Eigen::VectorXf full = gather_all(floor_light());
  const Eigen::VectorXf keys = pmsc::gather_key_values(model(), full);
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name(kCornell);
  *request.mutable_key_values() = point_array(keys);
  *request.mutable_full_values() = point_array(full);
  v1::CompleteMissResponse response;
  grpc::ClientContext context;
  const grpc::Status status = poses_->CompleteMiss(&context, request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_NE(response.result().status(), v1::CACHE_STATUS_HIT);
  EXPECT_TRUE(values_of(response.result().points()).isApprox(blended(model(), keys, full, response.result().blend_weight()), 1e-5f));
  EXPECT_TRUE(response.logged());
}

TEST_F(IlluminationServiceTest, StreamedLightsAreAnsweredLikeUnaryOnes) {
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  const std::vector<Eigen::Vector3d> path = {inside_light(), floor_light()};
  for (size_t f = 0; f < path.size(); ++f) {
    v1::KeyPointFrame frame;
    if (f == 0) frame.mutable_model()->set_name(kCornell);
    frame.set_sequence(f);
    set_light(frame.mutable_pose()->mutable_light_set(), path[f]);
    ASSERT_TRUE(stream->Write(frame));
  }
  stream->WritesDone();
  v1::PoseResult result;
  ASSERT_TRUE(stream->Read(&result));
  const pmsc::CachedPose expected = answer_for(inside_light());
  EXPECT_EQ(result.status(), server::to_proto(expected.status));
  EXPECT_TRUE(values_of(result.points()).isApprox(expected.points, 1e-5f));
  ASSERT_TRUE(stream->Read(&result));
  ASSERT_NE(result.status(), v1::CACHE_STATUS_HIT);
  const Eigen::VectorXf full = gather_all(floor_light());
  EXPECT_TRUE(values_of(result.points())
                  .isApprox(blended(model(), pmsc::gather_key_values(model(), full), full, result.blend_weight()), 1e-5f));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(IlluminationServiceTest, BadLightSetsAreRefusedNamingTheField) {
  struct Case {
    std::function<void(v1::LightSet*)> make;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](v1::LightSet*) {}, "poses[0].light_set.lights: expected 1 to 64 lights, got 0"},
      {[](v1::LightSet* s) { s->add_lights()->add_position(1); }, "poses[0].light_set.lights[0].position: expected 3"},
      {[](v1::LightSet* s) {
         set_light(s, {0.2, 0.4, 0.2});
         for (double c : {1.0, 1.0}) s->mutable_lights(0)->add_intensity(c);
       },
       "poses[0].light_set.lights[0].intensity: expected 3"},
      {[](v1::LightSet* s) {
         set_light(s, {0.2, 0.4, 0.2});
         for (double c : {1.0, -1.0, 1.0}) s->mutable_lights(0)->add_intensity(c);
       },
       "poses[0].light_set.lights[0].intensity"},
      {[](v1::LightSet* s) { set_light(s, {0.2, std::nan(""), 0.2}); }, "poses[0].light_set.lights[0].position"},
  };
  for (const Case& c : cases) {
    v1::EvaluateKeyPointsRequest request;
    request.mutable_model()->set_name(kCornell);
    c.make(request.add_poses()->mutable_light_set());
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = evaluate(request, &response);
    EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(status.error_message().find(c.field), std::string::npos) << status.error_message();
  }
  // Lights for a model without an illumination engine.
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(kArm);
  auto* pose = request.add_poses();
  set_light(pose->mutable_light_set(), inside_light());
  v1::EvaluateKeyPointsResponse response;
  const grpc::Status status = evaluate(request, &response);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("poses[0].light_set"), std::string::npos) << status.error_message();
}

TEST_F(IlluminationServiceTest, ThumbnailsDrawTheSurfaceColouredByTheServedRadiance) {
  auto render = v1::RenderService::NewStub(server_->channel());
  const auto draw = [&](const v1::RenderThumbnailRequest& request, v1::RenderThumbnailResponse* response) {
    grpc::ClientContext context;
    return render->RenderThumbnail(&context, request, response);
  };
  const illumination::SurfaceMesh& surface = engine().engine->surface();
  const std::vector<int> all = engine().engine->all_points();
  const pmsc::CachedPose served = answer_for(inside_light());

  v1::RenderThumbnailRequest request;
  request.mutable_model()->set_name(kCornell);
  request.set_width_px(32);
  request.set_height_px(24);
  set_light(request.mutable_key_points()->mutable_light_set(), inside_light());
  request.mutable_illumination()->set_white_radiance(2.0f);
  v1::RenderThumbnailResponse response;
  grpc::Status status = draw(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.pose().status(), server::to_proto(served.status));

  // Total radiance: the direct part computed for the light plus the served indirect, unlit.
  Eigen::VectorXf direct;
  engine().engine->direct({{inside_light(), engine().default_intensity()}}, all, direct);
  const Eigen::VectorXf total = (served.points + direct).cwiseMax(0.0f);
  std::vector<render::Scene> scenes = server_->renders().scenes();
  ASSERT_EQ(scenes.size(), 1u);
  const render::Scene& scene = scenes.back();
  EXPECT_EQ(scene.points, surface.vertices);
  EXPECT_EQ(scene.faces, surface.faces);
  EXPECT_EQ(scene.shading, render::Shading::kUnlit);
  EXPECT_TRUE(scene.srgb);
  EXPECT_FLOAT_EQ(scene.exposure, 0.5f);
  ASSERT_EQ(scene.vertex_colours.rows(), surface.vertices.rows());
  EXPECT_TRUE(scene.vertex_colours.isApprox(Eigen::Map<const PointMatrix>(total.data(), surface.vertices.rows(), 3)));
  ASSERT_TRUE(scene.camera.has_value()) << "the model's own camera";
  EXPECT_EQ(scene.camera->eye, engine().view->eye);

  // The heat map of |full − served| with the server's own full gather.
  request.mutable_illumination()->set_heat_from_full_gather(true);
  status = draw(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  const Eigen::VectorXf full = gather_all(inside_light());
  const Eigen::VectorXf heat =
      (Eigen::Map<const PointMatrix>(full.data(), surface.vertices.rows(), 3) -
       Eigen::Map<const PointMatrix>(served.points.data(), surface.vertices.rows(), 3))
          .rowwise()
          .norm();
  scenes = server_->renders().scenes();
  ASSERT_EQ(scenes.size(), 2u);
  EXPECT_TRUE(scenes.back().heat.isApprox(heat));
  EXPECT_EQ(scenes.back().vertex_colours.rows(), 0);
  EXPECT_FLOAT_EQ(static_cast<float>(response.heat_max_error()), heat.maxCoeff());

  // Total radiance needs the lights; so does the server's full gather.
  request.mutable_key_points()->clear_light_set();
  *request.mutable_key_points()->mutable_key_values() = point_array(gather(inside_light(), model().key_points));
  status = draw(request, &response);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("key_points.light_set"), std::string::npos) << status.error_message();
  request.mutable_illumination()->set_heat_from_full_gather(false);
  request.mutable_illumination()->set_radiance(v1::IlluminationView::RADIANCE_INDIRECT);
  request.mutable_illumination()->set_white_radiance(-1);
  status = draw(request, &response);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("illumination.white_radiance"), std::string::npos);
  request.mutable_illumination()->set_white_radiance(0);
  status = draw(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message() << " (indirect alone needs no lights)";
}

}  // namespace
}  // namespace animspace
