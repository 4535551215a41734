"""Compact points on the wire (PointEncoding) through a real daemon: every encoding gives the
float32 verdicts, and points that decode within the reported ``points_max_error`` of the float32
answer — and within the bound core/common/point_codec.h states — from exactly 2·N·D bytes.

The bounds are computed here from the float32 answer, not taken from the code under test."""
import grpc
import numpy as np
import pytest

from animspace import wire
from animspace.v1 import common_pb2, poses_pb2, poses_pb2_grpc

from test_client import posed_arm


def stated_bound(exact, encoding):
    """The largest error the encoding allows for each value of ``exact`` (N×D float32)."""
    x = exact.astype(np.float64)
    if encoding == "float16":
        # Round to nearest with 11 significant bits: 2^-11 relative, 2^-25 absolute in the subnormals.
        return np.maximum(np.abs(x) * 2.0 ** -11, 2.0 ** -25)
    lo, hi = x.min(axis=0), x.max(axis=0)
    step = (hi - lo) / 65535 * (1 + 2.0 ** -23)  # (max − min)/65535, rounded up to float32
    return np.broadcast_to(step / 2 + 2.0 ** -23 * (hi - lo + np.maximum(np.abs(lo), np.abs(hi))), x.shape)


def expect_faithful(exact, compact, encoding):
    assert compact.status == exact.status
    assert compact.key_point_error == exact.key_point_error
    assert compact.blend_weight == exact.blend_weight
    assert compact.points.dtype == np.float32 and compact.points.shape == exact.points.shape
    error = np.abs(compact.points.astype(np.float64) - exact.points.astype(np.float64))
    assert 0 < error.max() <= compact.points_max_error
    # The reported maximum is the measured one (rounded up to float32 at most).
    assert compact.points_max_error == pytest.approx(error.max(), rel=2.0 ** -23)
    assert np.all(error <= stated_bound(exact.points, encoding))


@pytest.fixture()
def poses(client, arm_transforms):
    """Key values of two poses of arm-pmsc: one its subspace reproduces, one far outside it."""
    keys = client.describe_key_points("arm-pmsc")
    near = posed_arm(client, arm_transforms(0.4))[keys.indices]
    far = posed_arm(client, arm_transforms(2.9))[keys.indices]
    return keys, np.stack([near, far])


@pytest.mark.parametrize("encoding", ["float16", "fixed16"])
def test_evaluate_answers_within_max_error(client, poses, encoding):
    keys, values = poses
    exact = client.evaluate_key_points("arm-pmsc", values, version=keys.model_version)
    compact = client.evaluate_key_points("arm-pmsc", values, version=keys.model_version, points_encoding=encoding)
    assert [r.points_max_error for r in exact] == [0.0, 0.0]
    for a, b in zip(exact, compact):
        expect_faithful(a, b, encoding)


@pytest.mark.parametrize("encoding", ["float16", "fixed16"])
def test_stream_and_complete_miss_answer_in_the_encoding(client, poses, arm_transforms, encoding):
    keys, values = poses
    exact = list(client.stream_key_points("arm-pmsc", values, version=keys.model_version))
    compact = list(client.stream_key_points("arm-pmsc", values, version=keys.model_version, points_encoding=encoding))
    for a, b in zip(exact, compact, strict=True):
        expect_faithful(a, b, encoding)
    full = posed_arm(client, arm_transforms(2.9))
    a = client.complete_miss("arm-pmsc", full[keys.indices], full, version=keys.model_version).result
    b = client.complete_miss("arm-pmsc", full[keys.indices], full, version=keys.model_version,
                             points_encoding=encoding).result
    expect_faithful(a, b, encoding)


@pytest.mark.parametrize("encoding, value", [("float16", common_pb2.POINT_ENCODING_FLOAT16),
                                             ("fixed16", common_pb2.POINT_ENCODING_FIXED16)])
def test_16_bit_answers_are_two_bytes_a_value(channel, client, poses, encoding, value):
    keys, values = poses
    stub = poses_pb2_grpc.PoseServiceStub(channel)
    request = poses_pb2.EvaluateKeyPointsRequest(points_encoding=value)
    request.model.name = "arm-pmsc"
    request.poses.add().key_values.CopyFrom(wire.point_array("key_values", values[1]))
    points = stub.EvaluateKeyPoints(request, timeout=10).results[0].points
    assert points.encoding == value
    assert len(points.data) == 2 * points.point_count * points.channel_count
    assert len(points.scale) == len(points.offset) == (3 if encoding == "fixed16" else 0)
    # numpy alone decodes it, the way the client does: binary16 widened, or offset + scale·q.
    if encoding == "float16":
        decoded = np.frombuffer(points.data, "<f2").astype(np.float32)
    else:
        q = np.frombuffer(points.data, "<u2").astype(np.float32).reshape(-1, 3)
        decoded = q * np.asarray(points.scale, np.float32) + np.asarray(points.offset, np.float32)
    exact = client.evaluate_key_points("arm-pmsc", values[1]).points
    assert np.abs(decoded.reshape(-1, 3).astype(np.float64) - exact).max() <= points.max_error


def test_unknown_encodings_are_refused(client, channel, poses):
    keys, values = poses
    with pytest.raises(ValueError, match="points_encoding: expected one of 'float32', 'float16', 'fixed16', "
                                         "'coordinates', got 'half'"):
        client.evaluate_key_points("arm-pmsc", values[0], points_encoding="half")
    with pytest.raises(ValueError, match="points_encoding"):
        client.stream_key_points("arm-pmsc", values, points_encoding="f16")
    stub = poses_pb2_grpc.PoseServiceStub(channel)
    request = poses_pb2.EvaluateKeyPointsRequest(points_encoding=7)
    request.model.name = "arm-pmsc"
    request.poses.add().key_values.CopyFrom(wire.point_array("key_values", values[0]))
    with pytest.raises(grpc.RpcError) as refused:
        stub.EvaluateKeyPoints(request, timeout=10)
    assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert refused.value.details().startswith("points_encoding: unknown PointEncoding 7")
