#include "server/convert.h"

namespace animspace::server {

v1::ModelKind to_proto(container::ModelKind kind) {
  switch (kind) {
    case container::ModelKind::kMeshSequence: return v1::MODEL_KIND_MESH_SEQUENCE;
    case container::ModelKind::kPmsc: return v1::MODEL_KIND_PMSC;
    case container::ModelKind::kCrossPmsc: return v1::MODEL_KIND_CROSS_PMSC;
    case container::ModelKind::kAnimationSpace: return v1::MODEL_KIND_ANIMATION_SPACE;
  }
  return v1::MODEL_KIND_UNSPECIFIED;
}

v1::FailThrough to_proto(model::FailThrough fail_through) {
  switch (fail_through) {
    case model::FailThrough::kNone: return v1::FAIL_THROUGH_UNSPECIFIED;
    case model::FailThrough::kServer: return v1::FAIL_THROUGH_SERVER;
    case model::FailThrough::kClient: return v1::FAIL_THROUGH_CLIENT;
    case model::FailThrough::kImpossible: return v1::FAIL_THROUGH_IMPOSSIBLE;
  }
  return v1::FAIL_THROUGH_UNSPECIFIED;
}

v1::ServerEngine to_proto(model::ServerEngine engine) {
  switch (engine) {
    case model::ServerEngine::kNone: return v1::SERVER_ENGINE_UNSPECIFIED;
    case model::ServerEngine::kAnimationSpace: return v1::SERVER_ENGINE_ANIMATION_SPACE;
    case model::ServerEngine::kIllumination: return v1::SERVER_ENGINE_ILLUMINATION;
  }
  return v1::SERVER_ENGINE_UNSPECIFIED;
}

namespace {

// What a version is, from its info: the same whether it is loaded now or evicted.
void set_description(const model::ModelInfo& info, v1::ModelVersion* out) {
  out->set_kind(to_proto(info.kind));
  out->set_description(info.description);
  out->set_point_count(static_cast<uint32_t>(info.point_count));
  out->set_channel_count(static_cast<uint32_t>(info.channel_count));
  out->set_face_count(static_cast<uint32_t>(info.face_count));
  out->set_bone_count(static_cast<uint32_t>(info.bone_count));
  out->set_key_point_count(static_cast<uint32_t>(info.key_point_count));
  out->set_basis_size(static_cast<uint32_t>(info.basis_size));
  out->set_frame_count(static_cast<uint32_t>(info.frame_count));
  out->set_lod_level_count(static_cast<uint32_t>(info.lod_level_count));
  out->set_epsilon_min(info.epsilon_min);
  out->set_epsilon_max(info.epsilon_max);
  out->set_fail_through(to_proto(info.fail_through));
  out->set_server_engine(to_proto(info.server_engine));
  out->set_check_point_count(static_cast<uint32_t>(info.check_point_count));
  out->set_false_hit_rate(info.false_hit_rate);
  out->set_calibration_bad_samples(static_cast<uint64_t>(info.calibration_bad_samples));
  out->set_calibration_real_bad_samples(static_cast<uint64_t>(info.calibration_real_bad_samples));
  out->set_calibration_guarantee_holds(info.calibration_guarantee_holds);
  out->set_calibration_statement(info.calibration_statement);
  out->set_relative_tolerance(info.relative_tolerance);
  if (!info.subspace_kind.empty()) {
    out->set_subspace_kind(info.subspace_kind == "articulated" ? v1::SUBSPACE_KIND_ARTICULATED : v1::SUBSPACE_KIND_LINEAR);
  }
  out->set_subspace_bone_count(static_cast<uint32_t>(info.subspace_bone_count));
  out->set_residual_components(static_cast<uint32_t>(info.residual_components));
}

}  // namespace

void to_proto(const VersionEntry& entry, v1::ModelVersion* out) {
  out->set_version(entry.version);
  if (entry.evicted) {
    out->set_state(v1::VERSION_STATE_EVICTED);
    set_description(entry.evicted_info, out);
    out->set_file_size_bytes(entry.evicted_file_size_bytes);
    out->set_resident_bytes(entry.evicted_resident_bytes);
    return;
  }
  if (!entry.model) {
    out->set_state(v1::VERSION_STATE_FAILED);
    out->set_error(entry.error);
    return;
  }
  const LoadedModel& m = *entry.model;
  out->set_state(v1::VERSION_STATE_AVAILABLE);
  set_description(m.info, out);
  out->set_file_size_bytes(m.file_size_bytes);
  out->set_loaded_at_unix_s(m.loaded_at_unix_s);
  out->set_resident_bytes(m.resident_bytes);
  for (const auto& [key, value] : m.container.metadata()) (*out->mutable_metadata())[key] = value;
  for (const auto& name : m.container.section_names()) out->add_sections(name);
}

void to_proto(const ModelEntry& entry, v1::ModelSummary* out) {
  out->set_name(entry.name);
  out->set_default_version(entry.default_version());
  for (const auto& [version, v] : entry.versions) to_proto(v, out->add_versions());
}

v1::CacheStatus to_proto(pmsc::CacheStatus status) {
  switch (status) {
    case pmsc::CacheStatus::kHit: return v1::CACHE_STATUS_HIT;
    case pmsc::CacheStatus::kBlend: return v1::CACHE_STATUS_BLEND;
    case pmsc::CacheStatus::kMiss: return v1::CACHE_STATUS_MISS;
  }
  return v1::CACHE_STATUS_UNSPECIFIED;
}

lod::PixelTolerance from_proto(const v1::PixelTolerance& view) {
  lod::PixelTolerance out;
  out.tolerance_px = view.tolerance_px();
  out.viewport_width_px = view.viewport_width_px();
  out.horizontal_fov_rad = view.horizontal_fov_rad();
  out.distance = view.distance();
  return out;
}

}  // namespace animspace::server
