"""The generated Python stubs talk to the real daemon (the Python client package grows on them)."""
import time

import grpc
import pytest

from animspace.v1 import common_pb2, models_pb2, models_pb2_grpc, poses_pb2, poses_pb2_grpc


def wait_until_loaded(stub):
    deadline = time.time() + 30
    while time.time() < deadline:
        models = stub.ListModels(models_pb2.ListModelsRequest(), timeout=5).models
        if len(models) == 4:
            return models
        time.sleep(0.05)
    pytest.fail("the demo repository never finished loading")


def test_demo_models_are_listed_with_their_kinds(channel):
    stub = models_pb2_grpc.ModelServiceStub(channel)
    models = {m.name: m for m in wait_until_loaded(stub)}
    assert sorted(models) == ["arm", "arm-animspace", "arm-cross-pmsc", "arm-pmsc"]
    animspace = models["arm-animspace"].versions[0]
    assert animspace.kind == models_pb2.MODEL_KIND_ANIMATION_SPACE
    assert animspace.bone_count == 3 and animspace.point_count > 0
    pmsc = models["arm-pmsc"].versions[0]
    assert pmsc.kind == models_pb2.MODEL_KIND_PMSC
    assert pmsc.key_point_count > 0 and 0 < pmsc.basis_size < pmsc.frame_count
    assert 0 < pmsc.epsilon_min <= pmsc.epsilon_max
    cross = models["arm-cross-pmsc"].versions[0]
    assert cross.fail_through == common_pb2.FAIL_THROUGH_IMPOSSIBLE


def test_unknown_model_is_not_found_with_its_name(channel):
    stub = models_pb2_grpc.ModelServiceStub(channel)
    with pytest.raises(grpc.RpcError) as error:
        stub.DescribeModel(models_pb2.DescribeModelRequest(model={"name": "no-such-model"}), timeout=5)
    assert error.value.code() == grpc.StatusCode.NOT_FOUND
    assert "no-such-model" in error.value.details()


def test_pending_rpcs_say_unimplemented(channel):
    stub = poses_pb2_grpc.PoseServiceStub(channel)
    with pytest.raises(grpc.RpcError) as error:
        stub.EvaluateKeyPoints(poses_pb2.EvaluateKeyPointsRequest(model={"name": "arm-pmsc"}), timeout=5)
    assert error.value.code() == grpc.StatusCode.UNIMPLEMENTED
    assert "not implemented" in error.value.details()
