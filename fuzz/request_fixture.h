// The model the request fuzzer validates against, shared with the seed generator so that the
// seeds are requests this model accepts. An input is one selector byte (which request message
// follows), then the message's wire bytes.
#pragma once

#include <cstdint>

#include "core/animspace/skeleton.h"

namespace animspace::fuzz::request_fixture {

enum Selector : uint8_t {
  kKeyPointsRequest = 0,     // v1::EvaluateKeyPointsRequest (PoseService)
  kSkeletonPoseRequest = 1,  // v1::EvaluateSkeletonPoseRequest (SkinningService)
};

inline constexpr uint32_t kKeyPoints = 4;     // K
inline constexpr uint32_t kCheckPoints = 2;   // C (issue #35)
inline constexpr uint32_t kChannels = 3;      // D
inline constexpr uint32_t kVertices = 11;     // N, for the response size
inline constexpr uint32_t kMaxBatch = 8;      // --max-batch-poses
inline constexpr int64_t kMaxMessageBytes = 1024;  // --max-message-bytes, small so the check bites

// A three-bone chain (root, child, grandchild), rest transforms translated along +x: the
// hand-built skeleton of tests/server/validation_test.cpp, one bone deeper.
inline animation_space::Skeleton skeleton() {
  animation_space::Skeleton s;
  s.parents = {-1, 0, 1};
  s.rest.assign(3, animation_space::Transform::Identity());
  s.rest[1](0, 3) = 1;
  s.rest[2](0, 3) = 2;
  return s;
}

}  // namespace animspace::fuzz::request_fixture
