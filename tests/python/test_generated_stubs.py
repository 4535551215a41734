"""The generated Python stubs talk to the real daemon (the Python client package grows on them)."""
import time

import grpc
import pytest

import struct

from animspace.v1 import common_pb2, models_pb2, models_pb2_grpc, poses_pb2, poses_pb2_grpc, render_pb2, render_pb2_grpc


def wait_until_loaded(stub):
    deadline = time.time() + 30
    while time.time() < deadline:
        models = stub.ListModels(models_pb2.ListModelsRequest(), timeout=5).models
        if len(models) == 8:
            return models
        time.sleep(0.05)
    pytest.fail("the demo repository never finished loading")


def test_demo_models_are_listed_with_their_kinds(channel):
    stub = models_pb2_grpc.ModelServiceStub(channel)
    models = {m.name: m for m in wait_until_loaded(stub)}
    assert sorted(models) == ["arm", "arm-animspace", "arm-articulated", "arm-cross-pmsc", "arm-pmsc", "arm-pmsc-engine",
                              "arm-smooth", "cornell"]
    animspace = models["arm-animspace"].versions[0]
    assert animspace.kind == models_pb2.MODEL_KIND_ANIMATION_SPACE
    assert animspace.bone_count == 3 and animspace.point_count > 0
    pmsc = models["arm-pmsc"].versions[0]
    assert pmsc.kind == models_pb2.MODEL_KIND_PMSC
    assert pmsc.key_point_count > 0 and 0 < pmsc.basis_size < pmsc.frame_count
    assert 0 < pmsc.epsilon_min <= pmsc.epsilon_max
    cross = models["arm-cross-pmsc"].versions[0]
    assert cross.fail_through == common_pb2.FAIL_THROUGH_IMPOSSIBLE
    engine = models["arm-pmsc-engine"].versions[0]
    assert engine.fail_through == common_pb2.FAIL_THROUGH_SERVER and engine.bone_count == 3
    smooth = models["arm-smooth"].versions[0]  # arm-animspace subdivided once: V + E vertices, 4F faces
    assert smooth.kind == models_pb2.MODEL_KIND_ANIMATION_SPACE and smooth.bone_count == 3
    assert smooth.point_count > animspace.point_count and smooth.face_count == 4 * animspace.face_count
    articulated = models["arm-articulated"].versions[0]  # issue #51: 12 coordinates per bone + residuals
    assert articulated.kind == models_pb2.MODEL_KIND_PMSC
    assert articulated.subspace_kind == models_pb2.SUBSPACE_KIND_ARTICULATED
    assert articulated.subspace_bone_count >= 1
    assert articulated.basis_size == 12 * articulated.subspace_bone_count + articulated.residual_components
    assert pmsc.subspace_kind == models_pb2.SUBSPACE_KIND_LINEAR and pmsc.subspace_bone_count == 0


def test_unknown_model_is_not_found_with_its_name(channel):
    stub = models_pb2_grpc.ModelServiceStub(channel)
    with pytest.raises(grpc.RpcError) as error:
        stub.DescribeModel(models_pb2.DescribeModelRequest(model={"name": "no-such-model"}), timeout=5)
    assert error.value.code() == grpc.StatusCode.NOT_FOUND
    assert "no-such-model" in error.value.details()


def test_thumbnails_are_pngs_of_the_requested_size_and_bad_sizes_name_the_field(channel):
    wait_until_loaded(models_pb2_grpc.ModelServiceStub(channel))
    stub = render_pb2_grpc.RenderServiceStub(channel)
    with pytest.raises(grpc.RpcError) as error:
        stub.RenderThumbnail(render_pb2.RenderThumbnailRequest(model={"name": "arm-pmsc"}), timeout=30)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "width_px" in error.value.details()
    thumb = stub.RenderThumbnail(
        render_pb2.RenderThumbnailRequest(model={"name": "arm-animspace"}, width_px=96, height_px=64), timeout=30)
    assert thumb.png[:8] == b"\x89PNG\r\n\x1a\n"
    # The PNG IHDR chunk: width and height, big-endian, right after the signature and chunk header.
    assert struct.unpack(">II", thumb.png[16:24]) == (96, 64)
    assert (thumb.width_px, thumb.height_px) == (96, 64)


def test_key_points_evaluate_through_the_soft_cache(channel):
    models = models_pb2_grpc.ModelServiceStub(channel)
    wait_until_loaded(models)
    poses = poses_pb2_grpc.PoseServiceStub(channel)
    keys = poses.DescribeKeyPoints(poses_pb2.DescribeKeyPointsRequest(model={"name": "arm-pmsc"}), timeout=5)
    count = len(keys.key_point_indices)
    assert count > 0 and keys.channel_count == 3
    # A pose with every key point at the origin: nothing like the arm, so not a hit.
    values = struct.pack("<%df" % (3 * count), *([0.0] * (3 * count)))
    request = poses_pb2.EvaluateKeyPointsRequest(
        model={"name": "arm-pmsc"},
        poses=[{"key_values": {"point_count": count, "channel_count": 3, "data": values}}])
    result = poses.EvaluateKeyPoints(request, timeout=5).results[0]
    assert result.status in (common_pb2.CACHE_STATUS_BLEND, common_pb2.CACHE_STATUS_MISS)
    assert result.full_evaluation_needed and result.model_version == keys.model_version
    assert result.points.point_count == keys.control_point_count
    assert len(result.points.data) == 12 * keys.control_point_count
    # One key point too few is refused, naming the field.
    request.poses[0].key_values.point_count = count - 1
    with pytest.raises(grpc.RpcError) as error:
        poses.EvaluateKeyPoints(request, timeout=5)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "poses[0].key_values.point_count: expected %d key points, got %d" % (count, count - 1) in error.value.details()
