#include "core/model/servable.h"

#include <algorithm>
#include <span>
#include <utility>

#include "core/animspace/animspace_io.h"
#include "core/common/sha256.h"
#include "core/lod/lod_io.h"
#include "core/lod/selection.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/skinned_basis.h"
#include "core/pmsc/subspace.h"

namespace animspace::model {
namespace {

std::shared_ptr<const Servable::SkinnedLayout> skinned_layout(const pmsc::PmscModel& model,
                                                              const pmsc::SkinnedBasis& basis) {
  auto layout = std::make_shared<Servable::SkinnedLayout>();
  layout->bone_count = basis.bone_count;
  layout->influences = basis.influences;
  layout->slots = pmsc::skinned_slot_values(basis);
  const auto parts = layout->parts(model);
  Sha256 digest;
  for (const auto part : parts) digest.update(std::as_bytes(part));
  layout->sha256 = digest.digest();
  // Bone numbers travel as values: binary16 holds every integer up to 2048 exactly.
  constexpr int kFloat16Integers = 2048;
  if (basis.bone_count > kFloat16Integers) {
    layout->float16_refusal = "its " + std::to_string(basis.bone_count) +
                              " bones cannot be numbered in float16 (integers up to " +
                              std::to_string(kFloat16Integers) + ")";
  } else if (auto half = pmsc::float16_values({parts[0], parts[1], parts[2]})) {
    layout->float16 = std::move(*half);
  } else {
    layout->float16_refusal = half.error().message;
  }
  return layout;
}

}  // namespace

std::array<std::span<const float>, 3> Servable::SkinnedLayout::parts(const pmsc::PmscModel& model) const {
  const auto rows = static_cast<size_t>(model.mean.size());
  const size_t skinning_columns = 12 * static_cast<size_t>(bone_count);
  return {std::span<const float>(model.mean.data(), rows), std::span<const float>(slots),
          std::span<const float>(model.basis.data() + skinning_columns * rows,
                                 rows * (static_cast<size_t>(model.basis.cols()) - skinning_columns))};
}

Result<Servable> load_servable(const container::ModelContainer& container, const std::string& source) {
  auto info = describe(container, source);
  if (!info) return info.error();
  Servable servable;
  if (info->kind == ModelKind::kPmsc || info->kind == ModelKind::kCrossPmsc) {
    auto runtime = pmsc::load(container, source);
    if (!runtime) return runtime.error();
    servable.pmsc = std::make_shared<const pmsc::PmscModel>(std::move(*runtime));
    servable.basis_checksum = pmsc::basis_checksum(servable.pmsc->mean, servable.pmsc->basis);
    servable.basis_sha256 = pmsc::basis_sha256(servable.pmsc->mean, servable.pmsc->basis);
    if (auto half = pmsc::float16_basis(servable.pmsc->mean, servable.pmsc->basis)) {
      servable.float16_basis = std::move(*half);
    } else {
      servable.float16_refusal = half.error().message;
    }
    auto subspace = pmsc::make_subspace(servable.pmsc);
    if (!subspace) return make_error(subspace.error().code, source + ": " + subspace.error().message);
    servable.subspace = std::move(*subspace);
    // After make_subspace, which refuses an articulated basis of the wrong shape.
    if (auto skinned = pmsc::skinned_basis(*servable.pmsc)) {
      servable.skinned = skinned_layout(*servable.pmsc, *skinned);
    } else {
      servable.skinned_refusal = skinned.error().message;
    }
    const pmsc::PmscModel& m = *servable.pmsc;
    info->check_point_count = m.check_point_count();
    info->false_hit_rate = m.calibration.false_hit_rate;
    info->calibration_bad_samples = m.calibration.bad_samples;
    info->calibration_real_bad_samples = std::min(m.calibration.over_tolerance, m.calibration.bad_samples);
    info->calibration_guarantee_holds = pmsc::calibration_guarantee_holds(m);
    info->calibration_statement = pmsc::calibration_statement(m);
    info->relative_tolerance = m.relative_tolerance;
    info->subspace_kind = pmsc::subspace_kind_name(m.subspace_kind);
    info->subspace_bone_count = m.bone_count;
    info->residual_components = m.residual_components;
  }
  if (info->kind == ModelKind::kAnimationSpace || info->server_engine == ServerEngine::kAnimationSpace) {
    auto runtime = animation_space::load(container, source);
    if (!runtime) return runtime.error();
    auto levels = lod::load_levels(container, *runtime, source);
    if (!levels) return levels.error();
    auto sphere = lod::model_bounding_sphere(container, *runtime, source);
    if (!sphere) return sphere.error();
    servable.animation_space = std::make_shared<const animation_space::AnimationSpaceModel>(std::move(*runtime));
    servable.lod_levels = std::make_shared<const lod::LodLevels>(std::move(*levels));
    if (servable.pmsc) servable.engine = make_animation_space_engine(servable.animation_space);
    servable.bounding_sphere = *sphere;
  }
  if (info->server_engine == ServerEngine::kIllumination) {
    auto served = illumination::load_served_illumination(container, source);
    if (!served) return served.error();
    if (served->engine->point_count() != info->point_count) {
      return container::section_shape_error(source, container::sections::kRestPoints,
                                            std::to_string(info->point_count) + "×3 (pmsc.mean's points)",
                                            served->engine->point_count(), 3);
    }
    servable.illumination = std::make_shared<const illumination::ServedIllumination>(std::move(*served));
    servable.engine = make_illumination_engine(servable.illumination);
  }
  servable.info = std::move(*info);
  return servable;
}

}  // namespace animspace::model
