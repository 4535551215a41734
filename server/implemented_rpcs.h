// The RPCs this build implements (GetServerInfo reports them, so that clients and load testers
// can tell an UNIMPLEMENTED method from a failure before they call it). Each issue that lands an
// RPC adds it here.
#pragma once

namespace animspace::server {

inline constexpr const char* kRenderThumbnailRpc = "animspace.v1.RenderService/RenderThumbnail";

inline constexpr const char* kImplementedRpcs[] = {
    "animspace.v1.ModelService/ListModels",
    "animspace.v1.ModelService/DescribeModel",
    "animspace.v1.ModelService/LoadModel",
    "animspace.v1.ModelService/UnloadModel",
    "animspace.v1.ModelService/GetServerInfo",
    "animspace.v1.StatsService/GetStats",
    "animspace.v1.PoseService/DescribeKeyPoints",
    "animspace.v1.PoseService/EvaluateKeyPoints",
    "animspace.v1.PoseService/StreamKeyPoints",
    "animspace.v1.PoseService/CompleteMiss",
    "animspace.v1.PoseService/GetBasis",
    "animspace.v1.SkinningService/EvaluateSkeletonPose",
    "animspace.v1.LodService/GetLod",
    "animspace.v1.TrainingService/Retrain",
    kRenderThumbnailRpc,
    "grpc.health.v1.Health/Check",
    "grpc.health.v1.Health/Watch",
};

}  // namespace animspace::server
