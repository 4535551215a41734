"""animspace.Client against the real daemon serving the bundled demo repository.

Expected values come from independent computations — the soft-cache rules of poses.proto (e_key
as an RMS, α from ε_min/ε_max), the animation-space formula, eq. 7.2's slope, the PNG format —
or from a second, different path through the server (unary vs stream, posed vs client-skinned),
never from numbers the client produced.
"""
import math
import socket
import struct
import time

import grpc
import numpy as np
import pytest

import animspace
from animspace.v1 import models_pb2, models_pb2_grpc

DEMO_MODELS = ["arm", "arm-animspace", "arm-articulated", "arm-cross-pmsc", "arm-pmsc", "arm-pmsc-engine", "arm-smooth",
               "cornell"]


def rms(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def posed_arm(client, transforms):
    """arm-animspace's full pose: arm-pmsc-engine's soft cache was trained on it, same points."""
    return client.evaluate_skeleton_pose("arm-animspace", transforms).points


# ----------------------------------------------------------------------------------------------
# Registry, health, server info


def test_health_models_and_server_info(client):
    assert client.health() == "SERVING"
    models = client.list_models()
    assert [m.name for m in models] == DEMO_MODELS
    by_name = {m.name: m for m in models}
    assert by_name["arm-animspace"].default.kind == "ANIMATION_SPACE"
    assert by_name["arm-pmsc"].default.kind == "PMSC"
    assert by_name["arm-cross-pmsc"].default.fail_through == "IMPOSSIBLE"
    assert by_name["arm-pmsc-engine"].default.fail_through == "SERVER"
    described = client.describe_model("arm-animspace")
    assert described.name == "arm-animspace" and described.default == by_name["arm-animspace"].default
    assert described.default.bone_count == 3 and described.default.lod_level_count >= 4
    assert described.default.state == "AVAILABLE" and described.default.metadata["up_axis"] == "y"

    info = client.server_info()
    assert info.api == "animspace.v1" and info.server_version
    assert info.max_batch_poses > 0 and info.max_message_bytes > 0 and info.max_thumbnail_px > 0
    assert info.grpc_memory_bytes == 256 << 20  # animspaced --help's default
    # Every RPC the client wraps is one the server says it implements.
    wrapped = {"ModelService/ListModels", "ModelService/DescribeModel", "ModelService/LoadModel",
               "ModelService/UnloadModel", "ModelService/GetServerInfo", "StatsService/GetStats",
               "PoseService/DescribeKeyPoints", "PoseService/EvaluateKeyPoints", "PoseService/StreamKeyPoints",
               "PoseService/CompleteMiss", "SkinningService/EvaluateSkeletonPose", "LodService/GetLod",
               "TrainingService/Retrain", "RenderService/RenderThumbnail"}
    assert {"animspace.v1." + rpc for rpc in wrapped} | {"grpc.health.v1.Health/Check"} <= set(info.implemented_rpcs)


def test_the_stubs_are_importable_as_animspace_v1_and_mix_with_the_client(client):
    # A raw stub on the client's channel, for anything the client does not wrap.
    stub = models_pb2_grpc.ModelServiceStub(client.channel)
    response = stub.ListModels(models_pb2.ListModelsRequest(), timeout=5, metadata=client.metadata)
    assert [m.name for m in response.models] == DEMO_MODELS


# ----------------------------------------------------------------------------------------------
# Errors: one mapping, code + the server's field message + the subclass


def test_unknown_models_are_not_found_on_every_kind_of_call(client):
    calls = {
        "DescribeModel": lambda: client.describe_model("no-such-model"),
        "DescribeKeyPoints": lambda: client.describe_key_points("no-such-model"),
        "EvaluateKeyPoints": lambda: client.evaluate_key_points("no-such-model", np.zeros((4, 3))),
        "StreamKeyPoints": lambda: list(client.stream_key_points("no-such-model", [np.zeros((4, 3))])),
        "GetLod": lambda: client.get_lod("no-such-model", level=0),
        "GetStats": lambda: client.stats("no-such-model"),
    }
    for rpc, call in calls.items():
        with pytest.raises(animspace.NotFound) as error:
            call()
        assert isinstance(error.value, animspace.RpcError)
        assert error.value.code == grpc.StatusCode.NOT_FOUND and error.value.rpc == rpc
        assert "no-such-model" in error.value.message
        assert str(error.value).startswith(f"{rpc} failed: NOT_FOUND: ")
    with pytest.raises(animspace.NotFound) as error:
        client.describe_model("arm", 7)
    assert "version" in error.value.message
    with pytest.raises(animspace.NotFound):
        client.health("no.such.Service")


def test_a_wrong_key_point_count_is_invalid_argument_naming_the_field(client):
    keys = client.describe_key_points("arm-pmsc")
    k = keys.count
    with pytest.raises(animspace.InvalidArgument) as error:
        client.evaluate_key_points("arm-pmsc", np.zeros((k - 1, 3)))
    assert error.value.code == grpc.StatusCode.INVALID_ARGUMENT and error.value.rpc == "EvaluateKeyPoints"
    assert f"poses[0].key_values.point_count: expected {k} key points, got {k - 1}" in error.value.message
    with pytest.raises(animspace.InvalidArgument) as error:
        client.evaluate_key_points("arm-pmsc", np.full((k, 3), np.nan))
    assert "poses[0].key_values" in error.value.message and "NaN" in error.value.message
    with pytest.raises(animspace.InvalidArgument) as error:
        client.evaluate_skeleton_pose("arm-animspace", np.zeros((2, 3, 4)))
    assert "poses[0].bone_count: expected 3, got 2" in error.value.message


def test_the_wrong_kind_of_model_is_failed_precondition_and_small_budgets_out_of_range(client):
    with pytest.raises(animspace.FailedPrecondition):
        client.describe_key_points("arm-animspace")
    with pytest.raises(animspace.FailedPrecondition):
        client.evaluate_skeleton_pose("arm-pmsc", np.zeros((3, 3, 4)))
    with pytest.raises(animspace.FailedPrecondition) as error:
        client.get_lod("arm-pmsc", level=0)
    assert error.value.rpc == "GetLod"
    with pytest.raises(animspace.FailedPrecondition) as error:
        client.complete_miss("arm-cross-pmsc", np.zeros((24, 3)), np.zeros((1154, 3)))
    assert "cross-PMSC" in error.value.message
    coarsest = client.get_lod("arm-animspace", level=client.describe_model("arm-animspace").default.lod_level_count - 1)
    with pytest.raises(animspace.OutOfRange) as error:
        client.get_lod("arm-animspace", max_vertices=coarsest.vertex_count - 1)
    assert f"expected at least {coarsest.vertex_count}" in error.value.message
    with pytest.raises(animspace.InvalidArgument) as error:
        client.render_thumbnail("arm", 0, 10)
    assert "width_px" in error.value.message


def test_wrong_shapes_are_refused_before_anything_is_sent(client):
    def refused(call, *expected):
        with pytest.raises(ValueError) as error:
            call()
        for text in expected:
            assert text in str(error.value)

    refused(lambda: client.evaluate_key_points("arm-pmsc", np.zeros(72)),
            "key_values: expected shape (K, D) or (P, K, D), got (72,)")
    refused(lambda: client.evaluate_key_points("arm-pmsc", np.zeros((2, 2, 24, 3))), "key_values", "(2, 2, 24, 3)")
    refused(lambda: client.evaluate_key_points("arm-pmsc", np.zeros((0, 24, 3))), "at least one pose")
    refused(lambda: client.evaluate_key_points("arm-pmsc", [[1, 2, 3], [4, 5]]), "key_values", "float32")
    refused(lambda: client.evaluate_key_points("arm-pmsc", np.zeros((2, 24, 3)), skeleton_pose=np.zeros((3, 3, 4))),
            "skeleton_pose: expected shape (P, B, 3, 4) or (P, B, 4, 4), got (3, 3, 4)")
    refused(lambda: client.evaluate_skeleton_pose("arm-animspace", np.zeros((3, 3, 3))),
            "transforms: expected shape (B, 3, 4) or (B, 4, 4), got (3, 3, 3)")
    refused(lambda: client.evaluate_skeleton_pose("arm-animspace", np.ones((3, 4, 4))),
            "transforms: the last row of every 4×4 transform must be (0, 0, 0, 1)")
    refused(lambda: client.evaluate_skeleton_pose("arm-animspace", np.zeros((3, 3, 4)), space="world"), "space")
    refused(lambda: client.complete_miss("arm-pmsc", np.zeros((24, 3)), np.zeros(3462)),
            "full_values: expected shape (N, D), got (3462,)")
    refused(lambda: client.get_lod("arm-animspace", level=1, max_vertices=300), "give exactly one", "level, max_vertices")
    refused(lambda: client.get_lod("arm-animspace"), "give exactly one, got none")
    refused(lambda: client.get_lod("arm-animspace", tolerance_px=1.0), "distance")
    refused(lambda: client.get_lod("arm-animspace", level=0, form="skinned"), "form")
    refused(lambda: client.render_thumbnail("arm", 8, 8, sequence_frame=1, skeleton_pose=np.zeros((3, 3, 4))),
            "sequence_frame")
    refused(lambda: client.describe_model(""), "model")
    refused(lambda: animspace.Client("127.0.0.1:1", channel=client.channel), "exactly one of target and channel")


# ----------------------------------------------------------------------------------------------
# The soft cache


def test_a_hit_returns_the_estimate_whose_key_points_give_e_key(client, demo_arm_transforms):
    keys = client.describe_key_points("arm-pmsc-engine")
    assert keys.indices.dtype == np.uint32 and keys.indices.shape == (keys.count,)
    assert keys.channel_count == 3 and keys.fail_through == "SERVER"
    full = posed_arm(client, demo_arm_transforms(14 / 120))  # a training frame of the soft cache
    sent = full[keys.indices]
    result = client.evaluate_key_points("arm-pmsc-engine", sent.astype(np.float64), version=keys.model_version)
    assert result.status == "HIT" and result.hit and result.blend_weight == 0
    assert not result.full_evaluation_needed and result.model_version == keys.model_version
    assert result.points.dtype == np.float32 and result.points.shape == (keys.control_point_count, 3)
    assert result.points.flags.writeable
    # poses.proto: e_key is the RMS over key points and channels of f_key − f̂_key, and for a hit
    # the points returned are the estimate f̂.
    assert rms(result.points[keys.indices], sent) == pytest.approx(result.key_point_error, rel=1e-3, abs=1e-7)
    epsilon_min = client.describe_model("arm-pmsc-engine").default.epsilon_min
    assert result.key_point_error <= epsilon_min
    # A hit reconstructs the whole arm, not just the key points.
    assert np.abs(result.points - full).max() < 10 * epsilon_min


def test_blends_and_misses_follow_the_soft_cache_rule(client, arm_transforms):
    model = client.describe_model("arm-pmsc-engine").default
    keys = client.describe_key_points("arm-pmsc-engine")
    found = {}
    # Elbow bends without the demo's shoulder swing and twist leave the training set: scan for a
    # blend and a miss. Each pose is sent as a client sends it, with its check values, so that the
    # verdict is its error estimate against the model's ε (ModelVersion.epsilon_min/max).
    for elbow in np.linspace(0.1, 3.0, 30):
        G = arm_transforms(elbow)
        full = posed_arm(client, G)
        estimate = client.evaluate_key_points("arm-pmsc-engine", full[keys.indices],
                                              check_values=full[keys.check_point_indices])
        found.setdefault(estimate.status, (G, full, estimate))
    assert {"BLEND", "MISS"} <= set(found)
    for status in ("BLEND", "MISS"):
        G, full, estimate = found[status]
        # Without a skeleton pose the server cannot run its engine: the estimate, flagged.
        assert estimate.full_evaluation_needed
        e = estimate.error_estimate
        assert e >= estimate.check_point_error * (1 - 1e-6)  # e = max(w·e_key, e_check)
        expected_alpha = 1.0 if status == "MISS" else (e - model.epsilon_min) / (model.epsilon_max - model.epsilon_min)
        assert estimate.blend_weight == pytest.approx(expected_alpha, rel=1e-4)
        assert (model.epsilon_min < e < model.epsilon_max) if status == "BLEND" else e >= model.epsilon_max
        # With the skeleton pose the server poses its engine and blends: α·full + (1−α)·estimate.
        completed = client.evaluate_key_points("arm-pmsc-engine", full[keys.indices],
                                               check_values=full[keys.check_point_indices], skeleton_pose=G)
        assert completed.status == status and not completed.full_evaluation_needed
        alpha = completed.blend_weight
        np.testing.assert_allclose(completed.points, alpha * full + (1 - alpha) * estimate.points, atol=2e-5)


def assert_same_pose_points(batched, single):
    """Poses evaluated together (a batch, a stream's read-ahead) are reconstructed as one matrix
    product (the daemon's dynamic batching): their points differ from a single call's only in the
    order of the float additions, 2(M + 2)·2⁻²⁴ of each sum's size (pmsc::reconstruction_rounding_bound),
    far below 1e-5 of the arm's extent for its few basis vectors and unit-sized coordinates."""
    assert batched.shape == single.shape and batched.dtype == single.dtype
    np.testing.assert_allclose(batched, single, rtol=0, atol=1e-5 * max(1.0, float(np.abs(single).max())))


def test_a_batch_answers_in_request_order_like_single_calls(client, demo_arm_transforms):
    keys = client.describe_key_points("arm-pmsc")
    frames = np.stack([posed_arm(client, demo_arm_transforms(f / 120))[keys.indices] for f in (3, 30, 61, 95)])
    frames[2] += 0.2  # far off the subspace: a different verdict in the middle of the batch
    batch = client.evaluate_key_points("arm-pmsc", frames)
    assert isinstance(batch, list) and len(batch) == 4
    for values, result in zip(frames, batch):
        single = client.evaluate_key_points("arm-pmsc", values.tolist())  # lists work too
        assert (result.status, result.key_point_error) == (single.status, single.key_point_error)
        assert_same_pose_points(result.points, single.points)
    assert batch[2].status == "MISS" and batch[0].status != "MISS"


def test_region_errors_are_the_rms_over_each_regions_key_points(client, demo_arm_transforms):
    keys = client.describe_key_points("arm-pmsc")
    assert keys.regions.shape == (keys.count,)
    sent = posed_arm(client, demo_arm_transforms(40 / 120))[keys.indices] + 0.001
    result = client.evaluate_key_points("arm-pmsc", sent, include_region_errors=True)
    # Client fail-through without full values: the points are the subspace estimate f̂ whatever
    # the verdict, so each region's e_key can be recomputed from them.
    assert result.status == "HIT" or result.full_evaluation_needed
    estimate_keys = result.points[keys.indices]
    assert rms(estimate_keys, sent) == pytest.approx(result.key_point_error, rel=1e-3, abs=1e-7)
    assert sorted(r.region for r in result.region_errors) == sorted(set(keys.regions.tolist()))
    for region in result.region_errors:
        mask = keys.regions == region.region
        assert rms(estimate_keys[mask], sent[mask]) == pytest.approx(region.key_point_error, rel=1e-3, abs=1e-7)
        assert region.status in ("HIT", "BLEND", "MISS")


def test_omit_points_keeps_the_verdict(client):
    keys = client.describe_key_points("arm-pmsc")
    values = np.zeros((keys.count, 3))
    full = client.evaluate_key_points("arm-pmsc", values)
    probe = client.evaluate_key_points("arm-pmsc", values, omit_points=True)
    assert probe.points is None
    assert (probe.status, probe.key_point_error) == (full.status, full.key_point_error)


def test_complete_miss_blends_the_clients_full_values(client, arm_transforms):
    keys = client.describe_key_points("arm-pmsc")
    assert keys.fail_through == "CLIENT"
    # arm-pmsc was trained on the expensive rig; the animation-space arm at a bend the demo never
    # reaches stands in for "the client's posing engine".
    full = posed_arm(client, arm_transforms(2.9))
    result = client.evaluate_key_points("arm-pmsc", full[keys.indices], version=keys.model_version)
    assert result.status in ("BLEND", "MISS") and result.full_evaluation_needed
    completion = client.complete_miss("arm-pmsc", full[keys.indices], full, version=result.model_version)
    done = completion.result
    assert isinstance(completion.logged, bool) and completion.logged
    assert done.status == result.status and done.blend_weight == pytest.approx(result.blend_weight)
    assert not done.full_evaluation_needed
    alpha = done.blend_weight
    np.testing.assert_allclose(done.points, alpha * full + (1 - alpha) * result.points, atol=2e-5)


def _per_point_blend(estimate, full, points, weights):
    """Local fail-through's answer, computed here: α_i·f_i + (1 − α_i)·f̂_i at the named points."""
    expected = np.array(estimate, np.float64)
    alpha = np.asarray(weights, np.float64)[:, np.newaxis]
    expected[points] = alpha * full[points] + (1 - alpha) * expected[points]
    return expected


def test_local_fail_through_names_the_points_to_compute_and_completes_only_those(client, arm_transforms):
    keys = client.describe_key_points("arm-pmsc")
    full = posed_arm(client, arm_transforms(2.9))
    whole = client.evaluate_key_points("arm-pmsc", full[keys.indices])
    local = client.evaluate_key_points("arm-pmsc", full[keys.indices], local_fail_through=True)
    # The whole-pose verdict is unchanged; the answer without full values is still the estimate.
    assert (local.status, local.key_point_error, local.blend_weight) == (whole.status, whole.key_point_error,
                                                                          whole.blend_weight)
    assert local.status in ("BLEND", "MISS") and local.full_evaluation_needed
    np.testing.assert_array_equal(local.points, whole.points)
    points, weights = local.full_points, local.full_point_blend_weights
    assert points.dtype == np.uint32 and weights.dtype == np.float32
    assert len(points) == len(weights) > 1 and np.all(np.diff(points.astype(np.int64)) > 0)
    assert points[-1] < len(full) and np.all((weights > 0) & (weights <= 1))
    assert len(whole.full_points) == 0  # not asked for

    completion = client.complete_miss("arm-pmsc", full[keys.indices], full[points], full_points=points,
                                      version=local.model_version)
    assert completion.logged and not completion.result.full_evaluation_needed
    np.testing.assert_array_equal(completion.result.full_points, points)
    np.testing.assert_allclose(completion.result.points, _per_point_blend(local.points, full, points, weights),
                               atol=2e-5)

    # The server recomputes which points are needed: leaving one out is refused, naming the field.
    with pytest.raises(animspace.InvalidArgument) as refused:
        client.complete_miss("arm-pmsc", full[keys.indices], full[points[1:]], full_points=points[1:],
                             version=local.model_version)
    assert f"full_points: point {points[0]} needs the full calculation" in refused.value.message
    with pytest.raises(ValueError, match="full_values: expected 2 rows, one per full_points entry"):
        client.complete_miss("arm-pmsc", full[keys.indices], full, full_points=points[:2])

    # A stream names the same points.
    streamed = list(client.stream_key_points("arm-pmsc", [full[keys.indices]], local_fail_through=True))
    np.testing.assert_array_equal(streamed[0].full_points, points)


def test_local_fail_through_with_a_server_engine_poses_only_the_named_points(client, arm_transforms):
    keys = client.describe_key_points("arm-pmsc-engine")
    G = arm_transforms(2.9)
    full = posed_arm(client, G)
    estimate = client.evaluate_key_points("arm-pmsc-engine", full[keys.indices], local_fail_through=True)
    assert estimate.status in ("BLEND", "MISS") and len(estimate.full_points) > 0
    served = client.evaluate_key_points("arm-pmsc-engine", full[keys.indices], skeleton_pose=G,
                                        local_fail_through=True)
    assert not served.full_evaluation_needed
    np.testing.assert_array_equal(served.full_points, estimate.full_points)
    np.testing.assert_allclose(served.points, _per_point_blend(estimate.points, full, estimate.full_points,
                                                               estimate.full_point_blend_weights), atol=2e-5)


# ----------------------------------------------------------------------------------------------
# Streaming


def test_a_stream_answers_every_frame_in_order_like_unary_calls(client, demo_arm_transforms):
    keys = client.describe_key_points("arm-pmsc-engine")
    transforms = [demo_arm_transforms(f / 120) for f in range(1, 120, 9)]
    frames = [posed_arm(client, G)[keys.indices] for G in transforms]
    frames[4] = frames[4] + 0.05  # a miss in the middle: frames differ in verdict too
    unary = client.evaluate_key_points("arm-pmsc-engine", np.stack(frames))

    produced = []

    def lazily():
        for frame in frames:
            produced.append(len(produced))
            yield frame

    streamed = list(client.stream_key_points("arm-pmsc-engine", lazily(), version=keys.model_version,
                                             first_sequence=1000))
    assert len(produced) == len(frames)
    assert [r.sequence for r in streamed] == list(range(1000, 1000 + len(frames)))
    assert streamed[4].status == "MISS" and any(r.status == "HIT" for r in streamed)
    for s, u in zip(streamed, unary):
        assert (s.status, s.key_point_error, s.blend_weight) == (u.status, u.key_point_error, u.blend_weight)
        assert s.points.dtype == np.float32
        assert_same_pose_points(s.points, u.points)

    # Frames carrying their skeleton pose: the server completes the miss with its engine.
    poses = [animspace.KeyPointPose(f, G) for f, G in zip(frames, transforms)]
    completed = list(client.stream_key_points("arm-pmsc-engine", poses))
    with_engine = client.evaluate_key_points("arm-pmsc-engine", np.stack(frames), skeleton_pose=np.stack(transforms))
    assert not any(r.full_evaluation_needed for r in completed)
    for s, u in zip(completed, with_engine):
        assert_same_pose_points(s.points, u.points)


def test_a_bad_frame_ends_the_stream_after_the_frames_before_it(client):
    k = client.describe_key_points("arm-pmsc").count
    good = [np.full((k, 3), 0.01 * i) for i in range(3)]
    # Refused by the client: every earlier frame is answered first.
    results = []
    with pytest.raises(ValueError) as error:
        for result in client.stream_key_points("arm-pmsc", good + [np.zeros((k - 1, 3))]):
            results.append(result)
    assert [r.sequence for r in results] == [0, 1, 2]
    assert f"frames[3]: expected shape ({k}, 3) like frames[0], got ({k - 1}, 3)" in str(error.value)

    # An exception from the caller's own iterable comes back as itself.
    def failing():
        yield good[0]
        raise RuntimeError("the posing engine crashed")

    with pytest.raises(RuntimeError, match="posing engine crashed"):
        list(client.stream_key_points("arm-pmsc", failing()))

    # Refused by the server: the status names the frame's sequence number.
    with pytest.raises(animspace.InvalidArgument) as error:
        list(client.stream_key_points("arm-pmsc", [np.zeros((k - 1, 3))], first_sequence=5))
    assert error.value.rpc == "StreamKeyPoints"
    assert f"sequence=5].pose.key_values.point_count: expected {k} key points, got {k - 1}" in error.value.message


def test_leaving_a_stream_early_cancels_it(client):
    k = client.describe_key_points("arm-pmsc").count

    def endless():
        while True:
            yield np.zeros((k, 3))

    stream = client.stream_key_points("arm-pmsc", endless(), omit_points=True)
    first = [next(stream) for _ in range(3)]
    stream.close()
    assert [r.sequence for r in first] == [0, 1, 2] and all(r.points is None for r in first)
    assert client.health() == "SERVING"


# ----------------------------------------------------------------------------------------------
# Animation space: skinning and LOD


def test_skeleton_poses_in_every_layout_and_space_agree(client, demo_arm_transforms):
    G = demo_arm_transforms(0.3)
    global_4x4 = client.evaluate_skeleton_pose("arm-animspace", G)
    global_3x4 = client.evaluate_skeleton_pose("arm-animspace", G[:, :3, :].tolist())
    np.testing.assert_array_equal(global_4x4.points, global_3x4.points)
    assert global_4x4.points.dtype == np.float32 and global_4x4.points.shape == (1154, 3)
    assert global_4x4.normals is None
    # Local joint transforms L_j = G_parent⁻¹ G_j, composed back by the server (Merry 2007 §2.2).
    parents = [-1, 0, 1]
    L = np.stack([G[j] if p < 0 else np.linalg.inv(G[p]) @ G[j] for j, p in enumerate(parents)])
    local = client.evaluate_skeleton_pose("arm-animspace", L, space="local")
    np.testing.assert_allclose(local.points, global_4x4.points, atol=1e-5)

    batch = client.evaluate_skeleton_pose("arm-animspace", np.stack([G, demo_arm_transforms(0.6)]),
                                          include_normals=True)
    assert isinstance(batch, list) and len(batch) == 2
    np.testing.assert_allclose(batch[0].points, global_4x4.points, atol=0)
    assert batch[0].normals.shape == (1154, 3) and batch[0].normals.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(batch[0].normals, axis=1), 1.0, atol=1e-4)
    assert not np.allclose(batch[1].points, batch[0].points)


def test_lod_levels_match_the_model_and_their_own_headers(client):
    model = client.describe_model("arm-animspace").default
    levels = [client.get_lod("arm-animspace", level=level) for level in range(model.lod_level_count)]
    full = levels[0]
    assert (full.vertex_count, full.face_count) == (model.point_count, model.face_count)
    epsilons = []
    for level, mesh in enumerate(levels):
        h = mesh.header
        assert (h.level, h.level_count, h.form) == (level, model.lod_level_count, "posed")
        assert mesh.positions.shape == (h.vertex_count, 3) and mesh.positions.dtype == np.float32
        assert mesh.indices.shape == (h.face_count, 3) and mesh.indices.dtype == np.uint32
        assert mesh.indices.max() < h.vertex_count
        assert mesh.skeleton is None and mesh.bone_indices is None
        epsilons.append(h.epsilon)
    assert epsilons[0] == 0 and all(a <= b for a, b in zip(epsilons, epsilons[1:]))
    assert all(a.vertex_count > b.vertex_count for a, b in zip(levels, levels[1:]))

    # A vertex budget picks the finest level that fits it.
    budget = (levels[3].vertex_count + levels[4].vertex_count) // 2
    assert client.get_lod("arm-animspace", max_vertices=budget).header.level == 4
    assert client.get_lod("arm-animspace", max_vertices=levels[3].vertex_count).header.level == 3


def test_pixel_tolerance_follows_eq_7_2(client):
    p, w, fov = 1.5, 1920, math.radians(45)
    near = client.get_lod("arm-animspace", tolerance_px=p, distance=40, viewport_width_px=w, horizontal_fov_rad=fov)
    far = client.get_lod("arm-animspace", tolerance_px=p, distance=80, viewport_width_px=w, horizontal_fov_rad=fov)
    # ε = 2·p·(d − r)·sin θ / w: the radius r cancels in the difference of two distances.
    slope = (far.header.tolerated_error - near.header.tolerated_error) / 40
    assert slope == pytest.approx(2 * p * math.sin(fov / 2) / w, rel=1e-3)
    for mesh in (near, far):
        h = mesh.header
        assert h.epsilon <= h.tolerated_error
        # The coarsest level whose error is tolerated: the next one would not be.
        if h.level + 1 < h.level_count:
            assert client.get_lod("arm-animspace", level=h.level + 1).header.epsilon > h.tolerated_error
    assert far.header.level >= near.header.level


def test_the_posed_rest_level_equals_skinning_at_the_rest_transforms(client):
    skinned = client.get_lod("arm-animspace", level=0, form="animation_space")
    rest = skinned.skeleton.rest_transforms
    assert skinned.skeleton.parents.tolist() == [-1, 0, 1] and rest.shape == (3, 3, 4)
    posed = client.get_lod("arm-animspace", level=0)
    evaluated = client.evaluate_skeleton_pose("arm-animspace", rest)
    np.testing.assert_allclose(posed.positions, evaluated.points, atol=1e-6)
    np.testing.assert_array_equal(posed.indices, skinned.indices)
    # Σ_j p_j.w = 1 for every vertex (homogeneous animation-space positions, Merry 2007 §3.1).
    offsets = skinned.influence_offsets.astype(np.int64)
    assert offsets.shape == (skinned.vertex_count + 1,) and offsets[-1] == skinned.header.influence_count
    w_sums = np.add.reduceat(skinned.animation_positions[:, 3].astype(np.float64), offsets[:-1])
    np.testing.assert_allclose(w_sums, 1.0, atol=1e-5)


def test_a_level_skinned_on_the_client_equals_the_servers(client, demo_arm_transforms):
    G = demo_arm_transforms(0.37)
    level = 3
    skinned = client.get_lod("arm-animspace", level=level, form="animation_space", vertices_per_chunk=50)
    assert skinned.bone_indices.dtype == np.uint32 and skinned.animation_positions.shape == (
        skinned.header.influence_count, 4)
    # Small chunks: many blocks, reassembled to the same mesh as the default chunking.
    whole = client.get_lod("arm-animspace", level=level, form="animation_space")
    assert skinned.chunk_count > whole.chunk_count
    np.testing.assert_array_equal(skinned.animation_positions, whole.animation_positions)
    np.testing.assert_array_equal(skinned.influence_offsets, whole.influence_offsets)
    np.testing.assert_array_equal(skinned.indices, whole.indices)

    on_server = client.get_lod("arm-animspace", level=level, pose=G).positions
    evaluated = client.evaluate_skeleton_pose("arm-animspace", G, lod_level=level).points
    np.testing.assert_allclose(skinned.pose(G), on_server, atol=1e-5)
    np.testing.assert_allclose(evaluated, on_server, atol=1e-5)
    L = np.stack([G[0], np.linalg.inv(G[0]) @ G[1], np.linalg.inv(G[1]) @ G[2]])
    np.testing.assert_allclose(skinned.pose(L, space="local"), on_server, atol=1e-5)

    morph = client.get_lod("arm-animspace", level=level, form="animation_space", include_geomorph=True)
    assert morph.geomorph_delta.shape == (morph.header.influence_count, 4)
    # Σ_j Δp_j.w = 0 per vertex, so Σ_j p_j.w stays 1 all along the morph.
    offsets = morph.influence_offsets.astype(np.int64)[:-1]
    np.testing.assert_allclose(np.add.reduceat(morph.geomorph_delta[:, 3].astype(np.float64), offsets), 0, atol=1e-6)
    # t = 0 draws this level; the aligned influences do not change Σ_j G_j p_j (§7.3) …
    np.testing.assert_allclose(morph.pose(G, geomorph=0.0), on_server, atol=1e-5)
    # … and t = 1 moves every vertex onto the vertex of the next coarser level it collapses into.
    coarser = client.get_lod("arm-animspace", level=level + 1, pose=G).positions
    morphed = morph.pose(G, geomorph=1.0)
    nearest = np.linalg.norm(morphed[:, None, :] - coarser[None, :, :], axis=2).min(axis=1)
    assert nearest.max() < 1e-5


# ----------------------------------------------------------------------------------------------
# Thumbnails, statistics


def png_size(png):
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[12:16] == b"IHDR"
    return struct.unpack(">II", png[16:24])


def test_thumbnails_are_pngs_of_the_requested_size(client, tmp_path):
    rest = client.render_thumbnail("arm-animspace", 96, 64)
    assert png_size(rest.png) == (96, 64) and (rest.width_px, rest.height_px) == (96, 64)
    assert rest.pose is None and rest.model_version >= 1
    path = tmp_path / "arm.png"
    rest.save(str(path))
    assert path.read_bytes() == rest.png

    keys = client.describe_key_points("arm-pmsc")
    through_cache = client.render_thumbnail("arm-pmsc", 40, 30, key_values=np.zeros((keys.count, 3)),
                                            show_key_points=True, shading="lambert", samples=1,
                                            background_rgba=(1, 1, 1, 1))
    assert png_size(through_cache.png) == (40, 30)
    assert through_cache.pose is not None and through_cache.pose.status == "MISS"
    camera = animspace.Camera(eye=(1, 1, 6), target=(1, 0, 0), up=(0, 1, 0), vertical_fov_rad=0.7)
    framed = client.render_thumbnail("arm", 33, 17, sequence_frame=30, camera=camera, show_wireframe=True)
    assert png_size(framed.png) == (33, 17)
    coarse = client.render_thumbnail("arm-animspace", 32, 32, tolerance_px=4)
    assert coarse.lod_level > 0


def test_the_heat_map_reports_its_largest_error_and_its_scale(client, demo_arm_transforms):
    # arm-pmsc-engine's soft cache was trained on arm-animspace's poses: one of them is a full frame.
    full = posed_arm(client, demo_arm_transforms(0.37))
    keys = client.describe_key_points("arm-pmsc-engine")
    estimate = client.evaluate_key_points("arm-pmsc-engine", keys.select(full)).points
    largest = float(np.max(np.linalg.norm(full.astype(np.float64) - estimate, axis=1)))
    tolerance = float(client.describe_model("arm-pmsc-engine").default.metadata["pmsc.options.error_tolerance"])
    heat = client.render_thumbnail("arm-pmsc-engine", 128, 128, key_values=keys.select(full), full_values=full,
                                   show_heat_legend=True)
    assert heat.heat_max_error == pytest.approx(largest, rel=1e-5, abs=1e-9)
    assert heat.heat_scale_max == pytest.approx(tolerance, rel=1e-12), "red is the model's error tolerance"
    assert heat.heat_legend_drawn
    named = client.render_thumbnail("arm-pmsc-engine", 128, 128, key_values=keys.select(full), full_values=full,
                                    heat_max=0.25)
    assert named.heat_scale_max == pytest.approx(0.25) and not named.heat_legend_drawn
    with pytest.raises(animspace.InvalidArgument, match="show_heat_legend"):
        client.render_thumbnail("arm-pmsc-engine", 32, 32, key_values=keys.select(full), show_heat_legend=True)


def test_stats_count_the_poses_and_verdicts_seen(client, demo_arm_transforms):
    keys = client.describe_key_points("arm-cross-pmsc")
    before = client.stats("arm-cross-pmsc").models["arm-cross-pmsc"]
    frames = np.zeros((5, keys.count, 3))
    results = client.evaluate_key_points("arm-cross-pmsc", frames)
    after = client.stats("arm-cross-pmsc").models["arm-cross-pmsc"]
    assert after.poses - before.poses == 5 and after.requests - before.requests >= 1
    seen = {s: sum(r.status == s for r in results) for s in ("HIT", "BLEND", "MISS")}
    assert (after.hits - before.hits, after.blends - before.blends, after.misses - before.misses) == (
        seen["HIT"], seen["BLEND"], seen["MISS"])
    histogram = after.key_point_error
    assert histogram.counts.shape == (histogram.upper_bounds.shape[0] + 1,)
    assert int(histogram.counts.sum()) == histogram.total_count
    everything = client.stats()
    assert set(DEMO_MODELS) <= set(everything.models)


# ----------------------------------------------------------------------------------------------
# The client itself: deadlines, context manager


def test_the_default_deadline_applies_and_deadline_s_overrides_it(daemon):
    # A TCP listener that never speaks HTTP/2: every call waits for its deadline, so how long
    # it waited shows which deadline applied (lower bounds only: a deadline never fires early).
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        with animspace.Client("127.0.0.1:%d" % silent.getsockname()[1], deadline_s=0.2) as stuck:
            for deadline_s, rpc, call in ((None, "ListModels", lambda t: stuck.list_models(deadline_s=t)),
                                          (0.8, "GetServerInfo", lambda t: stuck.server_info(deadline_s=t))):
                started = time.monotonic()
                with pytest.raises(animspace.DeadlineExceeded) as error:
                    call(deadline_s)
                assert time.monotonic() - started >= (deadline_s or 0.2)
                assert error.value.code == grpc.StatusCode.DEADLINE_EXCEEDED and error.value.rpc == rpc

    # On the real daemon a stream's deadline bounds the whole stream.
    def slow(frames):
        for frame in frames:
            time.sleep(0.3)
            yield frame

    with animspace.Client(daemon, deadline_s=0.5) as client:
        frames = [np.zeros((24, 3))] * 3
        with pytest.raises(animspace.DeadlineExceeded) as error:
            list(client.stream_key_points("arm-pmsc", slow(frames)))
        assert error.value.rpc == "StreamKeyPoints"
        assert len(list(client.stream_key_points("arm-pmsc", slow(frames), deadline_s=30))) == 3


def test_the_context_manager_closes_the_channel_it_made(daemon):
    with animspace.Client(daemon) as client:
        channel = client.channel
        assert client.health() == "SERVING"
    assert client.closed
    with pytest.raises(ValueError, match="closed"):
        client.list_models()
    with pytest.raises(ValueError):  # grpc refuses calls on a closed channel
        models_pb2_grpc.ModelServiceStub(channel).ListModels(models_pb2.ListModelsRequest(), timeout=5)

    # A channel passed in belongs to the caller and stays open.
    with grpc.insecure_channel(daemon) as own:
        with animspace.Client(channel=own) as borrowed:
            assert borrowed.health() == "SERVING"
        assert models_pb2_grpc.ModelServiceStub(own).ListModels(models_pb2.ListModelsRequest(), timeout=5).models


def test_an_unreachable_server_is_unavailable():
    with animspace.Client("127.0.0.1:1", deadline_s=5) as client:
        with pytest.raises(animspace.Unavailable) as error:
            client.list_models()
        assert error.value.code == grpc.StatusCode.UNAVAILABLE
        with pytest.raises(animspace.DeadlineExceeded, match="not SERVING"):
            client.wait_until_serving(deadline_s=0.3)


def test_skip_miss_log_serves_test_traffic_and_keeps_it_out_of_retraining(spawn_daemon, tmp_path, arm_transforms):
    """Issue #55 item 6: a load test's blends and misses must not become training data."""
    misses = tmp_path / "misses"
    misses.mkdir()
    with animspace.Client(spawn_daemon("--miss-log-dir", str(misses))) as client:
        client.wait_until_serving(deadline_s=60)
        keys = client.describe_key_points("arm-pmsc")
        poses = [posed_arm(client, arm_transforms(elbow)) for elbow in np.linspace(0.1, 3.0, 30)]
        frames = [animspace.KeyPointPose(p[keys.indices], check_values=p[keys.check_point_indices]) for p in poses]
        log = misses / "arm-pmsc.misses"
        skipped = [client.evaluate_key_points("arm-pmsc", f.key_values, check_values=f.check_values,
                                              skip_miss_log=True) for f in frames]
        skipped += list(client.stream_key_points("arm-pmsc", frames, skip_miss_log=True))
        not_hits = sum(r.status != "HIT" for r in skipped)
        assert not_hits > 0, "the bent elbows must give blends or misses for the test to mean anything"
        assert not log.exists() or log.stat().st_size == 16, "skipped traffic reached the miss log"
        # A completion sent as test traffic is answered but not logged either.
        blend = next(i for i, r in enumerate(skipped[:len(frames)]) if r.status != "HIT")
        completion = client.complete_miss("arm-pmsc", frames[blend].key_values, poses[blend],
                                          check_values=frames[blend].check_values, skip_miss_log=True)
        assert not completion.logged and "skip_miss_log" in completion.not_logged_reason
        assert not log.exists() or log.stat().st_size == 16
        # The same stream without the flag is logged, one record per blend or miss.
        logged = list(client.stream_key_points("arm-pmsc", frames))
        assert log.stat().st_size > 16
        assert sum(r.status != "HIT" for r in logged) == not_hits // 2
