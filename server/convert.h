// Conversions between registry/core values and animspace.v1 messages. Nothing here decides
// anything: validation lives in the handlers, algorithms in core/.
#pragma once

#include "animspace/v1/lod.pb.h"
#include "animspace/v1/models.pb.h"
#include "animspace/v1/poses.pb.h"
#include "core/lod/levels.h"
#include "core/pmsc/soft_cache.h"
#include "server/model_registry.h"

namespace animspace::server {

v1::ModelKind to_proto(container::ModelKind kind);
v1::FailThrough to_proto(model::FailThrough fail_through);
v1::ServerEngine to_proto(model::ServerEngine engine);
void to_proto(const VersionEntry& entry, v1::ModelVersion* out);
void to_proto(const ModelEntry& entry, v1::ModelSummary* out);
v1::CacheStatus to_proto(pmsc::CacheStatus status);
// Field for field (the core names them as the proto does); lod::validate checks them.
lod::PixelTolerance from_proto(const v1::PixelTolerance& view);

}  // namespace animspace::server
