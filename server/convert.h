// Conversions between registry/core values and animspace.v1 messages. Nothing here decides
// anything: validation lives in the handlers, algorithms in core/.
#pragma once

#include "animspace/v1/models.pb.h"
#include "server/model_registry.h"

namespace animspace::server {

v1::ModelKind to_proto(model::ModelKind kind);
v1::FailThrough to_proto(model::FailThrough fail_through);
void to_proto(const VersionEntry& entry, v1::ModelVersion* out);
void to_proto(const ModelEntry& entry, v1::ModelSummary* out);

}  // namespace animspace::server
