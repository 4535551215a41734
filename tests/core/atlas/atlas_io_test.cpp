// The atlas section: a round trip, a model written before it (no section) loading unchanged, and
// refusals that name the section.
#include "core/atlas/atlas_io.h"

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"

namespace animspace::atlas {
namespace {

namespace as = animation_space;

as::AnimationSpaceModel two_triangles() {
  as::AnimationSpaceModel m;
  m.skeleton.parents = {-1};
  m.skeleton.rest = {Eigen::Matrix4d::Identity()};
  m.faces.resize(2, 3);
  m.faces << 0, 1, 2, 0, 2, 3;
  m.influences.offsets = {0, 1, 2, 3, 4};
  m.influences.bones = {0, 0, 0, 0};
  m.positions.resize(4, 4);
  m.positions << 0, 1, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 1, 1, 1;
  return m;
}

Atlas an_atlas() {
  Atlas a;
  a.chart_of_face = {0, 1};
  a.chart_count = 2;
  a.uvs.resize(6, 2);
  a.uvs << 0.1, 0.1, 0.4, 0.1, 0.4, 0.4, 0.6, 0.6, 0.9, 0.9, 0.6, 0.9;
  return a;
}

Result<container::ModelContainer> reparse(const container::ModelContainer& c) {
  return container::parse(container::serialize(c), "test.anim");
}

TEST(AtlasIo, RoundTripsExactly) {
  container::ModelContainer c;
  as::store(two_triangles(), c);
  store_atlas(an_atlas(), "poses", c);
  auto back = reparse(c);
  ASSERT_TRUE(back.ok()) << back.error().message;
  auto loaded = load_atlas(*back, 2, "test.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_TRUE(loaded->has_value());
  const Atlas& a = **loaded;
  EXPECT_EQ(a.chart_of_face, an_atlas().chart_of_face);
  EXPECT_EQ(a.chart_count, 2);
  EXPECT_EQ(a.uvs, an_atlas().uvs);  // float64: bit for bit
  EXPECT_EQ(back->metadata_value("atlas.format_version"), "1");
  EXPECT_EQ(back->metadata_value("atlas.metric"), "poses");
  EXPECT_TRUE(as::load(*back, "test.anim").ok());
}

TEST(AtlasIo, AModelWrittenBeforeTheSectionLoadsUnchanged) {
  container::ModelContainer c;
  as::store(two_triangles(), c);
  auto back = reparse(c);
  ASSERT_TRUE(back.ok());
  auto model = as::load(*back, "old.anim");
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_EQ(model->faces, two_triangles().faces);
  auto loaded = load_atlas(*back, 2, "old.anim");
  ASSERT_TRUE(loaded.ok());
  EXPECT_FALSE(loaded->has_value());
}

TEST(AtlasIo, RefusesBadSections) {
  const auto refused = [](container::ModelContainer c, const std::string& expected) {
    auto loaded = load_atlas(c, 2, "bad.anim");
    ASSERT_FALSE(loaded.ok());
    EXPECT_NE(loaded.error().message.find(expected), std::string::npos) << loaded.error().message;
  };
  container::ModelContainer base;
  store_atlas(an_atlas(), "poses", base);
  {
    container::ModelContainer c = base;
    const container::Float64Matrix short_uvs = container::Float64Matrix::Zero(3, 6);
    c.set_matrix(container::sections::kAtlasUvs, short_uvs);
    refused(c, "atlas.uvs");
  }
  {
    container::ModelContainer c = base;
    container::Float64Matrix uvs = container::Float64Matrix::Constant(2, 6, 0.5);
    uvs(1, 3) = 1.5;
    c.set_matrix(container::sections::kAtlasUvs, uvs);
    refused(c, "outside [0, 1]");
  }
  {
    container::ModelContainer c = base;
    container::Int32Matrix ids(2, 1);
    ids << 0, 2;  // chart 1 missing
    c.set_matrix(container::sections::kAtlasChartIds, ids);
    refused(c, "dense");
  }
  {
    container::ModelContainer c = base;
    c.metadata()["atlas.format_version"] = "2";
    auto loaded = load_atlas(c, 2, "new.anim");
    ASSERT_FALSE(loaded.ok());
    EXPECT_EQ(loaded.error().code, ErrorCode::kFailedPrecondition);
  }
}

}  // namespace
}  // namespace animspace::atlas
