// Fuzz target: the model container parser, and everything the daemon runs on a container it
// loads (server/model_registry.cpp, load_version): container::parse → model::load_servable,
// then the first things serving does with the result (one evaluation, the geomorphs).
//
// Header, section and file CRCs stop almost every mutated input at the first checksum, so each
// input is tried twice: as it is (the checksum paths), and "resealed" — every CRC recomputed and
// the header's file size set to the input's length — so that mutations reach the structural
// checks and the section decoders behind them. (Defining FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
// would switch the checks off instead; this build does not, so the code fuzzed is the code that
// ships.)
#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/common/bytes.h"
#include "core/container/crc32.h"
#include "core/container/model_container.h"
#include "core/lod/levels.h"
#include "core/model/servable.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/skinned_basis.h"
#include "fuzz/fuzz_support.h"

namespace animspace::fuzz {
namespace {

constexpr std::string_view kSource = "fuzz.anim";

// --- Resealing (layout restated from docs/FORMATS.md, "Model container (.anim)") ----------------

constexpr size_t kHeaderSize = 64;
constexpr size_t kEntrySize = 80;
constexpr size_t kFooterSize = 8;
constexpr size_t kFileSizeAt = 16;
constexpr size_t kSectionCountAt = 24;
constexpr size_t kHeaderCrcAt = 60;
constexpr size_t kEntryCrcAt = 60;
constexpr size_t kEntryOffsetAt = 64;
constexpr size_t kEntrySizeAt = 72;

// The input with its redundancy made consistent: the file size field, the CRC of every payload
// that lies inside the input, the header CRC and the footer CRC (in that order: each covers the
// fields written before it). `bytes` must hold a header and a footer.
std::string reseal(std::string_view bytes) {
  std::string out(bytes);
  store_le<uint64_t>(out, kFileSizeAt, out.size());
  const size_t table_capacity = (out.size() - kHeaderSize - kFooterSize) / kEntrySize;
  const size_t count = std::min<size_t>(load_le<uint32_t>(out, kSectionCountAt), table_capacity);
  for (size_t i = 0; i < count; ++i) {
    const size_t entry = kHeaderSize + kEntrySize * i;
    const uint64_t offset = load_le<uint64_t>(out, entry + kEntryOffsetAt);
    const uint64_t size = load_le<uint64_t>(out, entry + kEntrySizeAt);
    if (offset > out.size() || size > out.size() - offset) continue;
    store_le<uint32_t>(out, entry + kEntryCrcAt, container::crc32(std::string_view(out).substr(offset, size)));
  }
  store_le<uint32_t>(out, kHeaderCrcAt, container::crc32(std::string_view(out).substr(0, kHeaderCrcAt)));
  const size_t footer = out.size() - kFooterSize;
  store_le<uint32_t>(out, footer, container::crc32(std::string_view(out).substr(0, footer)));
  return out;
}

// --- What a parsed container must satisfy -----------------------------------------------------

size_t element_size(container::SectionType type) {
  switch (type) {
    case container::SectionType::kFloat32Matrix:
    case container::SectionType::kInt32Matrix: return 4;
    case container::SectionType::kFloat64Matrix: return 8;
    case container::SectionType::kBytes:
    case container::SectionType::kText: return 0;
  }
  FUZZ_CHECK(false);  // parse() refuses types it does not know
  return 0;
}

bool same_sections(const container::ModelContainer& a, const container::ModelContainer& b) {
  if (a.metadata() != b.metadata() || a.sections().size() != b.sections().size()) return false;
  for (const auto& [name, section] : a.sections()) {
    const auto other = b.sections().find(name);
    if (other == b.sections().end()) return false;
    const container::Section& s = other->second;
    if (s.type != section.type || s.rows != section.rows || s.cols != section.cols || s.bytes != section.bytes) {
      return false;
    }
  }
  return true;
}

// Every section as the header documents it, and serialize() gives back the same container.
void check_container(const container::ModelContainer& c) {
  for (const auto& [name, section] : c.sections()) {
    FUZZ_CHECK(!name.empty() && name.size() <= container::kMaxSectionNameLength);
    FUZZ_CHECK(name != container::kMetadataSectionName);
    const size_t element = element_size(section.type);
    if (element == 0) {
      FUZZ_CHECK(section.rows == 0 && section.cols == 0);
    } else {
      FUZZ_CHECK(uint64_t{section.rows} * section.cols * element == section.bytes.size());
    }
  }
  const auto again = container::parse(container::serialize(c), kSource);
  FUZZ_CHECK(again.ok());
  FUZZ_CHECK(same_sections(c, *again));
}

// --- The registry's load, then the first use of what it loaded --------------------------------

void use_pmsc(const pmsc::PmscModel& m, const model::ModelInfo& info) {
  FUZZ_CHECK(m.point_count == info.point_count && m.channel_count == info.channel_count);
  FUZZ_CHECK(m.key_point_count() == info.key_point_count && m.basis_size() == info.basis_size);
  FUZZ_CHECK(m.mean.size() == int64_t{m.point_count} * m.channel_count);
  // A pose of all-zero key values (finite, which is all the request validation guarantees).
  const Eigen::VectorXf key_values = Eigen::VectorXf::Zero(int64_t{m.key_point_count()} * m.channel_count);
  pmsc::CachedPose pose;
  pmsc::evaluate_cached(m, key_values, nullptr, pose);
  FUZZ_CHECK(pose.points.size() == m.mean.size());
}

void use_animation_space(const animation_space::AnimationSpaceModel& m, const lod::LodLevels& levels,
                         const model::ModelInfo& info) {
  // load() promises a validated model, describe() the same counts.
  FUZZ_CHECK(animation_space::validate(m).ok());
  FUZZ_CHECK(m.vertex_count() == info.point_count && m.bone_count() == info.bone_count);
  FUZZ_CHECK(levels.count() >= 1 && levels.levels[0].model.vertex_count() == m.vertex_count());
  const animation_space::TransformList rest = animation_space::rest_pose(m.skeleton);
  PointMatrix points;
  for (int l = 0; l < levels.count(); ++l) {
    const lod::LodLevel& level = levels.levels[static_cast<size_t>(l)];
    FUZZ_CHECK(animation_space::validate(level.model).ok());
    animation_space::evaluate(level.model, rest, points);
    FUZZ_CHECK(points.rows() == level.model.vertex_count());
    if (level.model.has_tangents()) animation_space::evaluate_normals(level.model, rest, points);
    if (l + 1 < levels.count()) {
      const lod::Geomorph morph = lod::geomorph(levels, l);
      FUZZ_CHECK(morph.aligned.vertex_count() == level.model.vertex_count());
    }
  }
}

void load_like_the_registry(std::string_view bytes) {
  const auto parsed = container::parse(bytes, kSource);
  if (!parsed) {
    check_refusal(parsed.error(), kSource);
    return;
  }
  check_container(*parsed);

  const auto servable = model::load_servable(*parsed, std::string(kSource));
  if (!servable) return;
  if (servable->pmsc) use_pmsc(*servable->pmsc, servable->info);
  if (servable->skinned) {
    // GetBasis's SKINNED values read back as a client reads them, and name the dense basis.
    const auto& layout = *servable->skinned;
    std::vector<float> values;
    for (const auto part : layout.parts(*servable->pmsc)) values.insert(values.end(), part.begin(), part.end());
    auto skinned = pmsc::skinned_basis_from_values(values, servable->pmsc->point_count, layout.bone_count,
                                                   layout.influences, servable->pmsc->basis_size());
    FUZZ_CHECK(skinned.ok());
    FUZZ_CHECK(pmsc::basis_checksum(*skinned) == servable->basis_checksum);
  }
  if (servable->animation_space) use_animation_space(*servable->animation_space, *servable->lod_levels, servable->info);
}

}  // namespace
}  // namespace animspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace::fuzz;
  const std::string_view bytes = as_bytes(data, size);
  load_like_the_registry(bytes);
  if (size >= kHeaderSize + kFooterSize) load_like_the_registry(reseal(bytes));
  return 0;
}
