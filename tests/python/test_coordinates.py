"""Answers as subspace coordinates (issue #36 item 2) through the Python client and a real daemon:
GetBasis and its checksum, reconstruction within the bound poses.proto states, the basis cache
on disk (the format the C++ client shares), and every way a basis can be the wrong one.

Expected values come from independent computations here — zlib over the raw chunks, the bound in
float64 from the basis and p, the file parsed with struct — never from the client under test."""
import collections
import dataclasses
import hashlib
import math
import re
import socket
import struct
import subprocess
import zlib
from concurrent import futures

import grpc
import numpy as np
import pytest

import animspace
from animspace import coordinates, wire
from animspace.v1 import common_pb2, poses_pb2, poses_pb2_grpc

from conftest import BUILD
from test_client import posed_arm

U = 2.0 ** -24  # float32's unit roundoff
GET_BASIS = "/animspace.v1.PoseService/GetBasis"
DESCRIBE_KEY_POINTS = "/animspace.v1.PoseService/DescribeKeyPoints"


# ----------------------------------------------------------------------------------------------
# Independent computations


def raw_basis(channel, model, version=0):
    """GetBasis on a raw stub: the chunks, and the mean (N·D) and basis (N·D × M) they hold,
    assembled here by offset, float64."""
    request = poses_pb2.GetBasisRequest()
    request.model.name, request.model.version = model, version
    chunks = list(poses_pb2_grpc.PoseServiceStub(channel).GetBasis(request, timeout=30))
    first = chunks[0]
    n, d, m = first.point_count, first.channel_count, first.basis_size
    values = np.full(first.total_values, np.nan)
    for chunk in chunks:
        part = np.frombuffer(chunk.data, "<f4")
        values[chunk.offset:chunk.offset + part.size] = part
    return chunks, values[:n * d], values[n * d:].reshape(m, n * d).T


def stated_bound(mean, A, p, rotation=None, translation=None):
    """poses.proto's bound on |f_client − f_server| per value, float64, shape (N, D): both float32
    sums mean_i + Σ_j A_ij p_j are within γ_{M+2} of the exact one; an aligned model's R keeps
    each point's error's length, its two products R x differ by 2·γ_3·‖x‖ at most, and the sum
    with t rounds once on each side."""
    M = A.shape[1]
    gamma = (M + 2) * U / (1 - (M + 2) * U)
    p = np.asarray(p, np.float64)
    bound = 2 * gamma * (np.abs(mean) + np.abs(A) @ np.abs(p))
    if rotation is None:
        return bound.reshape(-1, 3)
    x = (mean + A @ p).reshape(-1, 3)
    gamma3 = 3 * U / (1 - 3 * U)
    R, t = np.asarray(rotation, np.float64), np.asarray(translation, np.float64)
    return (np.linalg.norm(bound.reshape(-1, 3), axis=1, keepdims=True)
            + 2 * gamma3 * np.linalg.norm(x, axis=1, keepdims=True) + 2 * U * np.abs(x @ R.T + t))


def expect_within_bound(reconstructed, exact, mean, A, result):
    """``reconstructed`` (from coordinates) is the float32 answer ``exact`` within the bound, and
    the bound is tight enough to mean something (far below the points' own size)."""
    c = result.coordinates
    bound = stated_bound(mean, A, c.p, c.rotation, c.translation)
    assert reconstructed.dtype == np.float32 and reconstructed.shape == exact.shape
    error = np.abs(reconstructed.astype(np.float64) - exact.astype(np.float64))
    assert np.all(error <= bound), float((error - bound).max())
    assert bound.max() < 1e-4 * np.abs(exact).max()


class CountingInterceptor(grpc.UnaryStreamClientInterceptor, grpc.UnaryUnaryClientInterceptor):
    """Counts the unary and server-streaming calls a client makes, by method."""

    def __init__(self):
        self.calls = collections.Counter()

    def intercept_unary_stream(self, continuation, details, request):
        self.calls[details.method] += 1
        return continuation(details, request)

    def intercept_unary_unary(self, continuation, details, request):
        self.calls[details.method] += 1
        return continuation(details, request)


@pytest.fixture()
def counted(daemon, tmp_path):
    """A client whose GetBasis calls are counted, with its own basis cache in tmp_path/bases."""
    counter = CountingInterceptor()
    with grpc.insecure_channel(daemon) as channel:
        with animspace.Client(channel=grpc.intercept_channel(channel, counter),
                              basis_cache=tmp_path / "bases") as client:
            client.wait_until_serving(deadline_s=30)
            yield client, counter


def closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def arm_poses(client, arm_transforms, demo_arm_transforms):
    """Key values and check values of arm-pmsc: two demo frames its subspace reproduces (HIT), one
    far outside it (MISS)."""
    keys = client.describe_key_points("arm-pmsc")
    frames = [posed_arm(client, G) for G in (demo_arm_transforms(14 / 120), demo_arm_transforms(31 / 120),
                                             arm_transforms(2.9))]
    return keys, np.stack([keys.select(f) for f in frames]), np.stack([keys.select_check_values(f) for f in frames])


# ----------------------------------------------------------------------------------------------
# GetBasis


def test_get_basis_assembles_the_chunks_and_its_checksum_is_zlibs(counted, channel):
    client, _ = counted
    chunks, mean, A = raw_basis(channel, "arm-pmsc")
    version = client.describe_model("arm-pmsc").default
    basis = client.get_basis("arm-pmsc")
    assert (basis.model, basis.model_version) == ("arm-pmsc", version.version)
    assert (basis.point_count, basis.channel_count, basis.basis_size) == (version.point_count,
                                                                          version.channel_count, version.basis_size)
    assert not basis.aligned
    assert basis.mean.dtype == basis.basis.dtype == np.float32
    assert basis.mean.shape == (version.point_count * 3,) and basis.basis.shape == (version.point_count * 3,
                                                                                     version.basis_size)
    np.testing.assert_array_equal(basis.mean, mean)
    np.testing.assert_array_equal(basis.basis, A)
    # crc32 of the mean's bytes, high; of the basis column by column, low — over the raw bytes.
    raw = b"".join(c.data for c in chunks)
    split = 4 * mean.size
    assert basis.basis_checksum == (zlib.crc32(raw[:split]) << 32) | zlib.crc32(raw[split:])
    assert all(c.basis_checksum == basis.basis_checksum for c in chunks)
    assert basis.mean.flags.writeable is False and basis.basis.flags.writeable is False
    # Pinned to that version, the same basis.
    assert client.get_basis("arm-pmsc", version.version).basis_checksum == basis.basis_checksum


def test_a_float16_basis_is_half_the_bytes_and_reconstructs_within_its_stated_bound(counted, channel, arm_poses):
    """Issue #53: GetBasis in float16. The values are float32's rounded to nearest binary16 (numpy's
    own rounding, here), named by the SHA-256 of the bytes sent, with the largest error sent; an
    answer reconstructed with them is within values_max_error·(1 + Σ|p_j|) of the float32 one."""
    client, counter = counted
    chunks, mean, A = raw_basis(channel, "arm-pmsc")
    request = poses_pb2.GetBasisRequest(values_encoding=common_pb2.POINT_ENCODING_FLOAT16)
    request.model.name = "arm-pmsc"
    half_chunks = list(poses_pb2_grpc.PoseServiceStub(channel).GetBasis(request, timeout=30))
    raw32 = b"".join(c.data for c in chunks)
    raw16 = b"".join(c.data for c in half_chunks)
    assert len(raw16) * 2 == len(raw32)
    values32 = np.frombuffer(raw32, "<f4")
    expected16 = values32.astype("<f2")
    assert raw16 == expected16.tobytes()
    first = half_chunks[0]
    assert first.values_encoding == common_pb2.POINT_ENCODING_FLOAT16
    assert first.values_sha256 == hashlib.sha256(raw16).digest()
    assert first.basis_sha256 == chunks[0].basis_sha256 and first.basis_checksum == chunks[0].basis_checksum
    error = np.abs(expected16.astype(np.float64) - values32.astype(np.float64)).max()
    assert first.values_max_error == np.float32(error)
    assert 0 < error <= 2.0 ** -11 * np.abs(values32).max()

    gets = counter.calls[GET_BASIS]
    basis = client.get_basis("arm-pmsc", values_encoding="float16")
    assert counter.calls[GET_BASIS] == gets + 1
    assert basis.values_encoding == "float16" and basis.values_max_error == first.values_max_error
    np.testing.assert_array_equal(basis.mean, expected16[:mean.size].astype(np.float32))
    keys, values, checks = arm_poses
    exact = client.evaluate_key_points("arm-pmsc", values[0], check_values=checks[0], version=keys.model_version)
    answer = client.evaluate_key_points("arm-pmsc", values[0], check_values=checks[0], version=keys.model_version,
                                        points_encoding="coordinates")
    assert answer.status == "HIT"
    c = answer.coordinates
    # poses.proto's FLOAT16 bound over the float32 values: each value within 2⁻¹¹ of its size.
    p = np.abs(c.p.astype(np.float64))
    M = A.shape[1]
    gamma = (M + 2) * U / (1 - (M + 2) * U)
    size = (np.abs(mean) + np.abs(A) @ p).reshape(exact.points.shape)
    stated = (2 * gamma + 2.0 ** -11) * (1 + 2.0 ** -10) * size + 2.0 ** -24 * (1 + p.sum())
    error = np.abs(coordinates.reconstruct(basis, c).astype(np.float64) - exact.points.astype(np.float64))
    assert np.all(error <= stated), float((error - stated).max())
    assert np.all(error <= coordinates.rounding_bound(basis, c))
    print("float16 bound", stated.max(), "error", error.max(), "points", np.abs(exact.points).max())
    assert stated.max() < 2e-3 * np.abs(exact.points).max()
    # Not cached: the next reconstruction fetches the float32 basis its checksum names.
    client.reconstruct("arm-pmsc", answer)
    assert counter.calls[GET_BASIS] == gets + 2
    with pytest.raises(ValueError, match="values_encoding"):
        client.get_basis("arm-pmsc", values_encoding="fixed16")
    request.values_encoding = common_pb2.POINT_ENCODING_FIXED16
    with pytest.raises(grpc.RpcError) as invalid:
        list(poses_pb2_grpc.PoseServiceStub(channel).GetBasis(request, timeout=30))
    assert invalid.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "values_encoding: expected FLOAT32 or FLOAT16, got POINT_ENCODING_FIXED16" in invalid.value.details()


def test_bad_basis_requests_name_their_status(client, channel, arm_poses):
    with pytest.raises(animspace.NotFound):
        client.get_basis("no-such-model")
    with pytest.raises(animspace.NotFound):
        client.get_basis("arm-pmsc", 99)
    with pytest.raises(animspace.FailedPrecondition) as refused:
        client.get_basis("arm-animspace")
    assert refused.value.rpc == "GetBasis"
    # Coordinates are for answers only: key values sent "as coordinates" are refused.
    keys, values, _ = arm_poses
    request = poses_pb2.EvaluateKeyPointsRequest(points_encoding=common_pb2.POINT_ENCODING_COORDINATES)
    request.model.name = "arm-pmsc"
    pose = request.poses.add()
    pose.key_values.CopyFrom(wire.point_array("key_values", values[0]))
    pose.key_values.encoding = common_pb2.POINT_ENCODING_COORDINATES
    with pytest.raises(grpc.RpcError) as invalid:
        poses_pb2_grpc.PoseServiceStub(channel).EvaluateKeyPoints(request, timeout=10)
    assert invalid.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "poses[0].key_values.encoding" in invalid.value.details()


# ----------------------------------------------------------------------------------------------
# Reconstruction against the server's float32 answer


def test_a_batch_as_coordinates_reconstructs_the_float32_answer_within_the_bound(counted, channel, arm_poses):
    client, counter = counted
    keys, values, checks = arm_poses
    _, mean, A = raw_basis(channel, "arm-pmsc")
    exact = client.evaluate_key_points("arm-pmsc", values, check_values=checks, version=keys.model_version)
    answers = client.evaluate_key_points("arm-pmsc", values, check_values=checks, version=keys.model_version,
                                         points_encoding="coordinates")
    assert [r.status for r in answers] == [r.status for r in exact]
    assert {r.status for r in answers} == {"HIT", "MISS"}
    for a, b in zip(exact, answers):
        assert (b.key_point_error, b.blend_weight, b.full_evaluation_needed) == (a.key_point_error, a.blend_weight,
                                                                                 a.full_evaluation_needed)
        assert b.points is None and b.coordinates.p.dtype == np.float32 and b.coordinates.p.shape == (A.shape[1],)
        assert b.coordinates.rotation is None and b.coordinates.translation is None
        expect_within_bound(client.reconstruct("arm-pmsc", b), a.points, mean, A, b)
    assert counter.calls[GET_BASIS] == 1  # fetched once for the three
    # reconstruct=True fills the points and keeps the coordinates.
    filled = client.evaluate_key_points("arm-pmsc", values[0], check_values=checks[0], points_encoding="coordinates",
                                        reconstruct=True)
    assert filled.coordinates is not None
    expect_within_bound(filled.points, exact[0].points, mean, A, filled)
    assert counter.calls[GET_BASIS] == 1


def test_a_stream_as_coordinates_reconstructs_the_float32_answer_within_the_bound(counted, channel, arm_poses):
    client, counter = counted
    keys, values, checks = arm_poses
    _, mean, A = raw_basis(channel, "arm-pmsc")
    frames = [animspace.KeyPointPose(v + np.float32(shift), check_values=c + np.float32(shift))
              for shift in (0, 0.003) for v, c in zip(values, checks)]
    exact = list(client.stream_key_points("arm-pmsc", frames))
    answers = list(client.stream_key_points("arm-pmsc", frames, points_encoding="coordinates", reconstruct=True,
                                            first_sequence=5))
    assert [r.sequence for r in answers] == list(range(5, 5 + len(frames)))
    assert {r.status for r in answers} == {"HIT", "MISS"}
    for a, b in zip(exact, answers, strict=True):
        assert b.status == a.status and b.coordinates is not None
        expect_within_bound(b.points, a.points, mean, A, b)
    assert counter.calls[GET_BASIS] == 1


def test_relight_answers_as_coordinates_within_the_bound(client, channel, tmp_path):
    # The Cornell box: M ≈ 100, 2990 RGB points; the server gathers the key values itself. The
    # tour's first light, a HIT (what a client reconstructs from coordinates).
    _, mean, A = raw_basis(channel, "cornell")
    light = [0.1, 0.44, 0.45]
    exact = client.relight("cornell", light)
    with animspace.Client(channel=client.channel, basis_cache=tmp_path) as own:
        answer = own.relight("cornell", light, points_encoding="coordinates", reconstruct=True)
    assert answer.status == exact.status == "HIT"
    expect_within_bound(answer.points, exact.points, mean, A, answer)


def exact_and_coordinate_answers(client, model, keys, frames):
    """`frames` (full poses) answered from their key and check values twice: as float32 points, and
    as coordinates."""
    values = np.stack([keys.select(f) for f in frames])
    checks = np.stack([keys.select_check_values(f) for f in frames])
    exact = client.evaluate_key_points(model, values, check_values=checks)
    return exact, client.evaluate_key_points(model, values, check_values=checks, points_encoding="coordinates")


def test_an_articulated_model_answers_bone_transforms_and_residuals_as_coordinates(counted, channel, arm_transforms,
                                                                                    demo_arm_transforms):
    # Issue #51: arm-articulated's p is 12 numbers per bone, then its residual coefficients; the
    # client reconstructs it with the mean and basis GetBasis sends, within the same bound.
    client, counter = counted
    described = client.describe_model("arm-articulated").default
    assert described.subspace_kind == "ARTICULATED" and described.subspace_bone_count >= 1
    _, mean, A = raw_basis(channel, "arm-articulated")
    assert A.shape[1] == described.basis_size == 12 * described.subspace_bone_count + described.residual_components
    keys = client.describe_key_points("arm-articulated")
    # A demo frame, and an elbow bent 150° with the shoulder swung 40°: past every training pose
    # (the demo flexes to 130° and swings 15°).
    frames = [posed_arm(client, G) for G in (demo_arm_transforms(14 / 120),
                                             arm_transforms(math.radians(150), math.radians(40)))]
    exact, answers = exact_and_coordinate_answers(client, "arm-articulated", keys, frames)
    for a, b in zip(exact, answers, strict=True):
        assert b.status == a.status and b.coordinates.p.shape == (A.shape[1],)
        expect_within_bound(client.reconstruct("arm-articulated", b), a.points, mean, A, b)
    assert counter.calls[GET_BASIS] == 1
    # Past the training poses the skinning carries the arm where principal components of the
    # same frames cannot: arm-pmsc's estimate of that pose (its points before any blend) is
    # several times farther from it.
    linear_keys = client.describe_key_points("arm-pmsc")
    linear = client.evaluate_key_points("arm-pmsc", linear_keys.select(frames[1]),
                                        check_values=linear_keys.select_check_values(frames[1]),
                                        points_encoding="coordinates", reconstruct=True)
    articulated = client.reconstruct("arm-articulated", answers[1])

    def worst(points):
        return float(np.linalg.norm(points.astype(np.float64) - frames[1].astype(np.float64), axis=1).max())

    assert worst(articulated) < 0.25 * worst(linear.points), (worst(articulated), worst(linear.points))


def raw_chunks(channel, model, layout):
    request = poses_pb2.GetBasisRequest(layout=layout)
    request.model.name = model
    return list(poses_pb2_grpc.PoseServiceStub(channel).GetBasis(request, timeout=30))


def expand_by_hand(chunks):
    """The mean and dense A of SKINNED chunks, expanded here entry by entry (poses.proto
    BasisChunk), float32."""
    first = chunks[0]
    n, m, B, K = first.point_count, first.basis_size, first.subspace_bone_count, first.influences_per_point
    values = np.frombuffer(b"".join(c.data for c in chunks), "<f4")
    assert values.size == first.total_values == n * 3 * (m - 12 * B + 1) + 5 * n * K
    A = np.zeros((3 * n, m), np.float32)
    slots = values[3 * n:3 * n + 5 * n * K].reshape(n, K, 5)
    for i in range(n):
        for j, *h in slots[i]:
            if any(h):
                assert j == int(j) and 0 <= j < B
                for a in range(3):
                    A[3 * i + a, 12 * int(j) + 4 * a:12 * int(j) + 4 * a + 4] = h
    A[:, 12 * B:] = values[3 * n + 5 * n * K:].reshape(m - 12 * B, 3 * n).T
    return values[:3 * n], A


def test_a_compact_basis_of_an_articulated_model_is_skinned_and_the_same_basis(counted, channel, tmp_path,
                                                                                 demo_arm_transforms):
    """Issue #51 item 4: arm-articulated's basis in the SKINNED layout is a fraction of the dense
    values and expands, entry by entry, to the very float32 values the dense layout sends; answers
    reconstructed with it are the server's within the stated bound; the cache keeps it as it came."""
    client, counter = counted
    described = client.describe_model("arm-articulated").default
    dense_chunks, mean, A = raw_basis(channel, "arm-articulated")
    skinned_chunks = raw_chunks(channel, "arm-articulated", poses_pb2.BASIS_LAYOUT_COMPACT)
    first = skinned_chunks[0]
    assert first.layout == poses_pb2.BASIS_LAYOUT_SKINNED and dense_chunks[0].layout == poses_pb2.BASIS_LAYOUT_DENSE
    assert first.subspace_bone_count == described.subspace_bone_count and first.influences_per_point >= 1
    assert (first.basis_checksum, first.basis_sha256) == (dense_chunks[0].basis_checksum, dense_chunks[0].basis_sha256)
    print("skinned values", first.total_values, "dense", dense_chunks[0].total_values)
    assert first.total_values < dense_chunks[0].total_values / 2
    hand_mean, hand_A = expand_by_hand(skinned_chunks)
    assert hand_mean.tobytes() == mean.astype("<f4").tobytes()
    assert hand_A.tobytes(order="F") == A.astype("<f4").tobytes(order="F")

    compact = client.get_basis("arm-articulated", layout="compact")
    dense = client.get_basis("arm-articulated", layout="dense")
    assert (compact.layout, dense.layout) == ("skinned", "dense")
    assert compact.basis_checksum == dense.basis_checksum and compact.nbytes < dense.nbytes / 2
    assert compact.dense_basis().tobytes(order="F") == dense.basis.tobytes(order="F")
    assert client.get_basis("arm-articulated", layout="skinned").layout == "skinned"

    keys = client.describe_key_points("arm-articulated")
    frames = [posed_arm(client, demo_arm_transforms(f / 120)) for f in (14, 57)]
    exact, answers = exact_and_coordinate_answers(client, "arm-articulated", keys, frames)
    for a, b in zip(exact, answers, strict=True):
        expect_within_bound(coordinates.reconstruct(compact, b.coordinates), a.points, mean, A, b)

    # reconstruct() fetches the compact layout and caches it as it came (ASBASIS2); a new client
    # reads it back once the server vouches for its SHA-256, and answers the same.
    gets = counter.calls[GET_BASIS]
    with animspace.Client(channel=client.channel, basis_cache=tmp_path / "own") as own:  # counted too
        first_points = own.reconstruct("arm-articulated", answers[0])
        assert own.basis_cache.get("arm-articulated", answers[0].model_version,
                                   answers[0].coordinates.basis_checksum).layout == "skinned"
    assert counter.calls[GET_BASIS] == gets + 1
    path = tmp_path / "own" / "arm-articulated" / f"{answers[0].model_version}-{first.basis_checksum:016x}.basis"
    data = path.read_bytes()
    assert data[:8] == b"ASBASIS2" and data[56:] == b"".join(c.data for c in skinned_chunks)
    new_counter = CountingInterceptor()
    with animspace.Client(channel=grpc.intercept_channel(channel, new_counter), basis_cache=tmp_path / "own") as new:
        np.testing.assert_array_equal(new.reconstruct("arm-articulated", answers[0]), first_points)
    assert new_counter.calls[GET_BASIS] == 0 and new_counter.calls[DESCRIBE_KEY_POINTS] == 1


def test_a_linear_model_comes_dense_when_compact_and_refuses_skinned(client, channel):
    assert client.get_basis("arm-pmsc", layout="compact").layout == "dense"
    assert raw_chunks(channel, "arm-pmsc", poses_pb2.BASIS_LAYOUT_COMPACT)[0].layout == poses_pb2.BASIS_LAYOUT_DENSE
    with pytest.raises(animspace.FailedPrecondition, match="layout") as refused:
        client.get_basis("arm-pmsc", layout="skinned")
    assert refused.value.rpc == "GetBasis"


def test_points_the_server_computes_still_come_as_float32(client, arm_transforms):
    # arm-pmsc-engine completes a miss itself from the skeleton pose: those are points, not p.
    keys = client.describe_key_points("arm-pmsc-engine")
    G = arm_transforms(math.radians(-60))
    full = posed_arm(client, G)
    exact = client.evaluate_key_points("arm-pmsc-engine", keys.select(full), skeleton_pose=G)
    answer = client.evaluate_key_points("arm-pmsc-engine", keys.select(full), skeleton_pose=G,
                                        points_encoding="coordinates")
    assert answer.status == exact.status == "MISS" and not answer.full_evaluation_needed
    assert answer.coordinates is None
    np.testing.assert_array_equal(answer.points, exact.points)
    # reconstruct hands such points back as they are.
    assert client.reconstruct("arm-pmsc-engine", answer) is answer.points
    # CompleteMiss: the server blends, so points again.
    keys = client.describe_key_points("arm-pmsc")
    full = posed_arm(client, arm_transforms(2.9))
    done = client.complete_miss("arm-pmsc", keys.select(full), full, points_encoding="coordinates",
                                reconstruct=True).result
    assert done.coordinates is None
    np.testing.assert_array_equal(done.points, client.complete_miss("arm-pmsc", keys.select(full), full).result.points)
    # Verdicts only: neither points nor coordinates.
    probe = client.evaluate_key_points("arm-pmsc", keys.select(full), points_encoding="coordinates", omit_points=True)
    assert probe.points is None and probe.coordinates is None
    with pytest.raises(ValueError, match="neither coordinates nor points"):
        client.reconstruct("arm-pmsc", probe)


def test_reconstruct_is_asked_for_with_coordinates_only(client, arm_poses):
    _, values, _ = arm_poses
    with pytest.raises(ValueError, match="reconstruct: .* points_encoding='coordinates'"):
        client.evaluate_key_points("arm-pmsc", values[0], reconstruct=True)
    with pytest.raises(ValueError, match="reconstruct"):
        client.stream_key_points("arm-pmsc", values, points_encoding="float16", reconstruct=True)


def train(client, demo_arm_transforms, folder, *flags, move=lambda points: points):
    """``animspace train-pmsc`` on the demo arm's even frames (each through ``move``), writing a
    model version under ``-o``/``--model`` in ``flags``."""
    sequence = folder.parent / (folder.name + "-sequence")
    if not sequence.exists():
        sequence.mkdir()
        frames = np.stack([move(posed_arm(client, demo_arm_transforms(f / 120))) for f in range(0, 120, 2)])
        animspace.write_pc2(sequence / "frames.pc2", frames)
        with open(sequence / "reference.obj", "w") as obj:
            obj.writelines("v %r %r %r\n" % tuple(float(c) for c in v) for v in frames[0])
            obj.writelines("f %d %d %d\n" % tuple(int(i) + 1 for i in f)
                           for f in client.get_lod("arm-animspace", level=0).indices)
    trained = subprocess.run([str(BUILD / "bin" / "animspace"), "train-pmsc", str(sequence), *flags],
                             capture_output=True, text=True, timeout=120)
    assert trained.returncode == 0, trained.stderr


def test_an_aligned_model_reconstructs_with_its_rotation_and_translation(client, spawn_daemon, tmp_path,
                                                                         demo_arm_transforms):
    # The demo arm carried around by a rigid motion per frame, trained with --align (rigid
    # motion removed before PCA): answers carry R and t, f̂ = R (mean + A p) + t.
    rng = np.random.default_rng(7)

    def rigid(points):
        axis = rng.normal(size=3)
        K = np.cross(np.eye(3), axis / np.linalg.norm(axis))
        angle = rng.uniform(0.2, 1.0)
        R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
        return (points.astype(np.float64) @ R.T + rng.normal(size=3) * 3).astype(np.float32)

    repository = tmp_path / "repository"
    train(client, demo_arm_transforms, repository, "-o", str(repository), "--model", "arm-aligned", "--align",
          move=rigid)
    address = spawn_daemon("--model-repository", str(repository))
    with grpc.insecure_channel(address) as channel, \
            animspace.Client(address, basis_cache=tmp_path / "bases") as aligned:
        aligned.wait_until_serving(deadline_s=60)
        keys = aligned.describe_key_points("arm-aligned")
        _, mean, A = raw_basis(channel, "arm-aligned")
        frames = [keys.pose(rigid(posed_arm(client, demo_arm_transforms(f / 120)))) for f in (3, 41, 77)]
        exact = [aligned.evaluate_key_points("arm-aligned", f.key_values, check_values=f.check_values)
                 for f in frames]
        answers = list(aligned.stream_key_points("arm-aligned", frames, points_encoding="coordinates",
                                                 reconstruct=True))
        assert aligned.get_basis("arm-aligned").aligned
        assert "HIT" in {r.status for r in answers}
        for a, b in zip(exact, answers):
            assert b.status == a.status and b.coordinates is not None
            R = b.coordinates.rotation.astype(np.float64)
            assert R.shape == (3, 3) and b.coordinates.translation.shape == (3,)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-5)
            assert np.abs(b.coordinates.translation).max() > 0.1  # a real move, not the identity
            expect_within_bound(b.points, a.points, mean, A, b)


# ----------------------------------------------------------------------------------------------
# The cache


def parse_cache_file(path):
    data = path.read_bytes()
    magic, n, d, m, aligned, version, checksum = struct.unpack_from("<8sIIIIQQ", data)
    values = np.frombuffer(data, "<f4", offset=40)
    return magic, (n, d, m, aligned, version, checksum), values


def test_the_cache_file_is_the_shared_format_and_spares_the_next_fetch(counted, channel, arm_poses, tmp_path):
    client, counter = counted
    keys, values, _ = arm_poses
    answer = client.evaluate_key_points("arm-pmsc", values[0], points_encoding="coordinates")
    first = client.reconstruct("arm-pmsc", answer)
    assert counter.calls[GET_BASIS] == 1
    checksum = answer.coordinates.basis_checksum
    path = tmp_path / "bases" / "arm-pmsc" / f"{answer.model_version}-{checksum:016x}.basis"
    assert sorted(p.name for p in (tmp_path / "bases" / "arm-pmsc").iterdir()) == [path.name]  # no temporaries
    magic, header, stored = parse_cache_file(path)
    stored_bytes = path.read_bytes()
    chunks, mean, A = raw_basis(channel, "arm-pmsc")
    N, M = chunks[0].point_count, chunks[0].basis_size
    assert magic == b"ASBASIS1" and header == (N, 3, M, 0, answer.model_version, checksum)
    assert stored.tobytes() == b"".join(c.data for c in chunks)  # the mean, then A column by column
    # The same client: from memory. A new one: from the file, once the server vouches for it
    # (its digest, one DescribeKeyPoints); with no server to ask, the copy is not used.
    np.testing.assert_array_equal(client.reconstruct("arm-pmsc", answer), first)
    assert counter.calls[GET_BASIS] == 1
    new_counter = CountingInterceptor()
    with animspace.Client(channel=grpc.intercept_channel(channel, new_counter), basis_cache=tmp_path / "bases") as new:
        np.testing.assert_array_equal(new.reconstruct("arm-pmsc", answer), first)
    assert new_counter.calls[GET_BASIS] == 0 and new_counter.calls[DESCRIBE_KEY_POINTS] == 1
    with animspace.Client(f"127.0.0.1:{closed_port()}", basis_cache=tmp_path / "bases", deadline_s=2) as offline:
        with pytest.raises(animspace.Unavailable):
            offline.reconstruct("arm-pmsc", answer)
    assert path.read_bytes() == stored_bytes  # the copy stays for when the server answers


def test_a_basis_the_cpp_client_cached_is_read_by_the_python_client(daemon, arm_poses, tmp_path):
    """One cache for both clients: `animspace play --coordinates` (the C++ client) writes the file,
    and a Python client reconstructs from it without fetching the basis."""
    keys, values, _ = arm_poses
    demo = tmp_path / "demo"
    subprocess.run([str(BUILD / "bin" / "animspace"), "demo-repository", str(demo)], check=True,
                   capture_output=True, timeout=300)
    played = subprocess.run([str(BUILD / "bin" / "animspace"), "-s", daemon, "--json", "play", "arm-pmsc",
                             str(demo / "arm" / "1" / "model.anim"), "--select", "0:4", "--coordinates",
                             "--basis-cache", str(tmp_path / "bases")], capture_output=True, text=True, timeout=120)
    assert played.returncode == 0, played.stderr
    with animspace.Client(daemon) as online:
        answer = online.evaluate_key_points("arm-pmsc", values[0], points_encoding="coordinates")
        expected = online.evaluate_key_points("arm-pmsc", values[0]).points
    files = list((tmp_path / "bases" / "arm-pmsc").glob(f"{answer.model_version}-*.basis"))
    assert [f.name for f in files] == [f"{answer.model_version}-{answer.coordinates.basis_checksum:016x}.basis"]
    counter = CountingInterceptor()
    with grpc.insecure_channel(daemon) as channel, \
            animspace.Client(channel=grpc.intercept_channel(channel, counter), basis_cache=tmp_path / "bases") as fresh:
        reconstructed = fresh.reconstruct("arm-pmsc", answer)
    assert counter.calls[GET_BASIS] == 0
    # The stated bound, from the C++-written file's own values: the float32 answer within it.
    _, (n, d, m, _, _, _), stored = parse_cache_file(files[0])
    stored = stored.astype(np.float64)
    mean, A = stored[:n * d], stored[n * d:].reshape(m, n * d).T
    expect_within_bound(reconstructed, expected, mean, A, answer)


def _flip_a_value(data):
    data[40 + 4 * 17 + 1] ^= 0x40
    return data


@pytest.mark.parametrize("damage", [
    _flip_a_value,
    lambda data: data[:-4],  # truncated
    lambda data: data[:8] + struct.pack("<I", 1153) + data[12:],  # another N in the header
    lambda data: b"ASBASIS0" + data[8:],  # another magic
    lambda data: data[:32] + struct.pack("<Q", 12345) + data[40:],  # another checksum in the header
], ids=["value", "truncated", "point_count", "magic", "header_checksum"])
def test_a_corrupt_cache_file_is_deleted_and_fetched_again(daemon, arm_poses, tmp_path, damage):
    keys, values, _ = arm_poses
    with animspace.Client(daemon, basis_cache=tmp_path / "bases") as client:
        answer = client.evaluate_key_points("arm-pmsc", values[0], points_encoding="coordinates")
        good = client.reconstruct("arm-pmsc", answer)
    path = next((tmp_path / "bases" / "arm-pmsc").iterdir())
    original = path.read_bytes()
    path.write_bytes(bytes(damage(bytearray(original))))
    counter = CountingInterceptor()
    with grpc.insecure_channel(daemon) as channel, \
            animspace.Client(channel=grpc.intercept_channel(channel, counter), basis_cache=tmp_path / "bases") as fresh:
        np.testing.assert_array_equal(fresh.reconstruct("arm-pmsc", answer), good)
        assert counter.calls[GET_BASIS] == 1
    assert path.read_bytes() == original  # written again, whole


def forge_crc32(data: bytearray, begin: int, end: int, patch_at: int, target: int) -> None:
    """Makes crc32(data[begin:end]) == target by choosing the 4 bytes at ``patch_at``: the CRC is
    affine in those 32 bits over GF(2) and the map is invertible — what anyone can do to a file
    checked by a CRC."""
    data[patch_at:patch_at + 4] = bytes(4)
    base = zlib.crc32(data[begin:end])
    rows = []  # (reduced column, the patch bits that made it), distinct leading bits
    for bit in range(32):
        data[patch_at + bit // 8] = 1 << (bit % 8)
        value, made_of = zlib.crc32(data[begin:end]) ^ base, 1 << bit
        data[patch_at + bit // 8] = 0
        for v, m in rows:
            if value ^ v < value:
                value, made_of = value ^ v, made_of ^ m
        if value:
            rows.append((value, made_of))
            rows.sort(reverse=True)
    assert len(rows) == 32
    wanted, patch = target ^ base, 0
    for v, m in rows:
        if wanted ^ v < wanted:
            wanted, patch = wanted ^ v, patch ^ m
    assert wanted == 0
    data[patch_at:patch_at + 4] = patch.to_bytes(4, "little")
    assert zlib.crc32(data[begin:end]) == target


def test_a_cached_basis_with_a_forged_crc_is_refused_by_the_servers_digest(daemon, arm_poses, tmp_path):
    """Issue #54 item 8: point 0 moved by 0.5 and the CRC forged to match — accepted by the CRC
    alone — is refused because its SHA-256 is not the server's, fetched again and overwritten."""
    keys, values, _ = arm_poses
    with animspace.Client(daemon, basis_cache=tmp_path / "bases") as client:
        described = client.describe_key_points("arm-pmsc")
        answer = client.evaluate_key_points("arm-pmsc", values[0], points_encoding="coordinates")
        good = client.reconstruct("arm-pmsc", answer)
    path = next((tmp_path / "bases" / "arm-pmsc").iterdir())
    original = path.read_bytes()
    assert hashlib.sha256(original[40:]).digest() == described.basis_sha256  # the values as sent
    assert described.basis_checksum == answer.coordinates.basis_checksum
    forged = bytearray(original)
    _, n, d = struct.unpack_from("<8sII", forged)
    mean_end = 40 + 4 * n * d
    struct.pack_into("<f", forged, 40, struct.unpack_from("<f", forged, 40)[0] + 0.5)
    forge_crc32(forged, 40, mean_end, mean_end - 4, answer.coordinates.basis_checksum >> 32)
    path.write_bytes(bytes(forged))
    counter = CountingInterceptor()
    with grpc.insecure_channel(daemon) as channel, \
            animspace.Client(channel=grpc.intercept_channel(channel, counter), basis_cache=tmp_path / "bases") as fresh:
        np.testing.assert_array_equal(fresh.reconstruct("arm-pmsc", answer), good)
        assert counter.calls[GET_BASIS] == 1
        assert fresh.basis_cache.refused_copies == 1
    assert path.read_bytes() == original


def test_the_cache_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("ANIMSPACE_BASIS_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert animspace.BasisCache().directory == tmp_path / "home" / ".cache" / "animspace" / "bases"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert animspace.BasisCache().directory == tmp_path / "xdg" / "animspace" / "bases"
    monkeypatch.setenv("ANIMSPACE_BASIS_CACHE", str(tmp_path / "mine"))
    assert animspace.BasisCache().directory == tmp_path / "mine"
    assert animspace.BasisCache(disk=False).directory is None
    assert animspace.BasisCache(disk=False).path("m", 1, 2) is None
    cache = animspace.BasisCache(tmp_path / "given")
    assert cache.path("arm-pmsc", 3, 0xAB) == tmp_path / "given" / "arm-pmsc" / "3-00000000000000ab.basis"
    assert cache.path("../escape", 3, 0xAB) is None  # not one path component: memory only


# ----------------------------------------------------------------------------------------------
# The wrong basis is never used


def test_coordinates_of_no_basis_of_their_version_raise(counted, arm_poses, tmp_path):
    client, counter = counted
    _, values, _ = arm_poses
    answer = client.evaluate_key_points("arm-pmsc", values[0], points_encoding="coordinates")
    served = answer.coordinates.basis_checksum
    stranger = dataclasses.replace(answer, coordinates=dataclasses.replace(answer.coordinates,
                                                                           basis_checksum=served ^ 1))
    with pytest.raises(animspace.BasisMismatch) as refused:
        client.reconstruct("arm-pmsc", stranger)
    assert (refused.value.expected_checksum, refused.value.served_checksum) == (served ^ 1, served)
    assert refused.value.model_version == answer.model_version and isinstance(refused.value, animspace.Error)
    # The basis fetched is cached under its own checksum only; asking again asks the server again.
    assert [p.name for p in (tmp_path / "bases" / "arm-pmsc").iterdir()] == [
        f"{answer.model_version}-{served:016x}.basis"]
    with pytest.raises(animspace.BasisMismatch):
        client.reconstruct("arm-pmsc", stranger)
    assert counter.calls[GET_BASIS] == 2
    # An answer of a version the server never had.
    unknown = dataclasses.replace(answer, model_version=77)
    with pytest.raises(animspace.NotFound):
        client.reconstruct("arm-pmsc", unknown)


def test_a_version_swap_fetches_each_versions_basis_and_a_replaced_version_raises(client, spawn_daemon, tmp_path,
                                                                                  demo_arm_transforms):
    # Versions of one model with different subspaces: the demo arm trained with M = 5 and M = 8.
    repository = tmp_path / "repository"
    train(client, demo_arm_transforms, repository, "-o", str(repository), "--model", "swap", "--version", "1",
          "--basis", "5")
    address = spawn_daemon("--model-repository", str(repository))
    with animspace.Client(address, basis_cache=tmp_path / "bases") as c, grpc.insecure_channel(address) as channel:
        c.wait_until_serving(deadline_s=60)
        keys = c.describe_key_points("swap")
        pose = keys.pose(posed_arm(client, demo_arm_transforms(31 / 120)))
        old = c.evaluate_key_points("swap", pose.key_values, check_values=pose.check_values, version=1,
                                    points_encoding="coordinates")
        assert old.model_version == 1 and old.coordinates.p.shape == (5,)
        old_float32 = c.evaluate_key_points("swap", pose.key_values, check_values=pose.check_values, version=1).points
        _, mean, A = raw_basis(channel, "swap", 1)

        # Version 2 is published and becomes the default; the answer of version 1 still
        # reconstructs, with version 1's basis, fetched by its version.
        train(client, demo_arm_transforms, repository, "-o", str(repository), "--model", "swap", "--version", "2",
              "--basis", "8")
        assert c.load_model("swap", 2).default_version == 2
        assert c.get_basis("swap").basis_size == 8  # cached beside version 1's
        expect_within_bound(c.reconstruct("swap", old), old_float32, mean, A, old)
        names = sorted(p.name for p in (tmp_path / "bases" / "swap").iterdir())
        assert [n.split("-")[0] for n in names] == ["1", "2"]

        # Version 1 replaced by another subspace: a cache that holds its old basis still answers
        # rightly; one that does not refuses rather than use the new basis.
        c.unload_model("swap", 1)
        train(client, demo_arm_transforms, repository, "-o", str(repository), "--model", "swap", "--version", "1",
              "--basis", "8")
        c.load_model("swap", 1)
        assert c.get_basis("swap", 1).basis_size == 8
        expect_within_bound(c.reconstruct("swap", old), old_float32, mean, A, old)
        with animspace.Client(address, basis_cache=tmp_path / "empty") as fresh:
            with pytest.raises(animspace.BasisMismatch):
                fresh.reconstruct("swap", old)


# ----------------------------------------------------------------------------------------------
# Streams that break BasisChunk's contract (an in-process server)


def _split(values, split, changes, **fields):
    """BasisChunks of model version 3 carrying ``values`` (float32) from each offset in ``split``,
    with ``fields`` on every chunk, then ``changes`` ({"c<index>": {field: value}}) applied."""
    raw = np.asarray(values, "<f4").tobytes()
    bounds = list(split) + [len(raw) // 4]
    chunks = [poses_pb2.BasisChunk(model_version=3, total_values=bounds[-1], offset=a, data=raw[4 * a:4 * b], **fields)
              for a, b in zip(bounds, bounds[1:])]
    for index, chunk_changes in changes.items():
        for name, value in chunk_changes.items():
            setattr(chunks[int(index[1:])], name, value)
    return chunks


def _chunks(n=4, d=3, m=2, split=(0, 7, 20), **changes):
    rng = np.random.default_rng(1)
    mean = rng.normal(size=n * d).astype("<f4")
    A = rng.normal(size=(n * d, m)).astype("<f4")
    checksum = (zlib.crc32(mean.tobytes()) << 32) | zlib.crc32(A.tobytes(order="F"))
    chunks = _split(np.concatenate([mean, A.ravel(order="F")]), split, changes, basis_checksum=checksum,
                    point_count=n, channel_count=d, basis_size=m)
    return chunks, mean, A


class ScriptedPoses(poses_pb2_grpc.PoseServiceServicer):
    script = []

    def GetBasis(self, request, context):
        yield from self.script


@pytest.fixture()
def scripted_server():
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=2))
    poses_pb2_grpc.add_PoseServiceServicer_to_server(ScriptedPoses(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    yield f"127.0.0.1:{port}"
    server.stop(grace=None)


def test_a_well_formed_stream_assembles(scripted_server, tmp_path):
    ScriptedPoses.script, mean, A = _chunks()
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        basis = client.get_basis("m", 3)
        # A server from before layouts ignores the request's and leaves the chunks' unset: dense.
        assert client.get_basis("m", 3, layout="compact").layout == "dense"
    assert basis.layout == "dense" and basis.bones is None
    np.testing.assert_array_equal(basis.mean, mean)
    np.testing.assert_array_equal(basis.basis, A)
    assert basis.dense_basis() is basis.basis
    p = np.float32([0.5, -2.0])
    got = coordinates.reconstruct(basis, animspace.SubspaceCoordinates(p=p, basis_checksum=basis.basis_checksum))
    np.testing.assert_allclose(got, (mean.astype(np.float64) + A.astype(np.float64) @ p).reshape(4, 3), rtol=1e-6)


@pytest.mark.parametrize("changes, problem", [
    ({"c1": {"offset": 8}}, "chunk 1: offset 8, expected 7"),  # a gap
    ({"c1": {"offset": 6}}, "chunk 1: offset 6, expected 7"),  # an overlap
    ({"c2": {"basis_size": 3}}, "chunk 2: basis_size 3 differs from chunk 0's 2"),
    ({"c1": {"model_version": 4}}, "chunk 1: model_version 4 differs from chunk 0's 3"),
    ({"c2": {"basis_checksum": 5}}, "chunk 2: basis_checksum 5 differs"),
    ({"c0": {"total_values": 35}}, "total_values 35, but N·D·(M+1)"),
    ({"c2": {"data": b"\0" * 68}}, "run past total_values 36"),
    ({"c0": {"basis_checksum": 5}, "c1": {"basis_checksum": 5}, "c2": {"basis_checksum": 5}},
     "is not the basis_checksum 0000000000000005"),
], ids=["gap", "overlap", "shape", "version", "checksum_changes", "total", "overrun", "checksum_wrong"])
def test_broken_basis_streams_are_protocol_errors(scripted_server, tmp_path, changes, problem):
    ScriptedPoses.script, _, _ = _chunks(**changes)
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        with pytest.raises(animspace.ProtocolError, match="GetBasis: .*" + problem.replace("(", r"\(")
                           .replace(")", r"\)").replace("+", r"\+")):
            client.get_basis("m", 3)
    assert not any(tmp_path.rglob("*.basis"))  # nothing cached


def test_a_short_stream_and_another_version_are_protocol_errors(scripted_server, tmp_path):
    chunks, _, _ = _chunks()
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        ScriptedPoses.script = chunks[:-1]
        with pytest.raises(animspace.ProtocolError, match="the stream ended after 20 of 36 values"):
            client.get_basis("m", 3)
        ScriptedPoses.script = []
        with pytest.raises(animspace.ProtocolError, match="without a chunk"):
            client.get_basis("m", 3)
        ScriptedPoses.script = chunks
        with pytest.raises(animspace.ProtocolError, match="asked for version 2, the chunks are of version 3"):
            client.get_basis("m", 2)


def test_a_fifo_in_the_basis_cache_is_not_read(tmp_path):
    # Issue #54: reading a FIFO at a cached basis's path waited for a writer forever; it is no
    # cached basis (the client fetches the basis and its write replaces the FIFO).
    import os
    import threading
    path = tmp_path / "1-0000000000000001.basis"
    os.mkfifo(path)
    result = []
    reader = threading.Thread(target=lambda: result.append(coordinates.read_basis_file(path, "arm", 1, 1)),
                              daemon=True)
    reader.start()
    reader.join(timeout=30)
    if reader.is_alive():
        with open(path, "wb"):  # a writer that closes at once lets the blocked reader finish
            pass
        reader.join(timeout=30)
        pytest.fail("reading the basis cache blocked on a FIFO")
    assert result == [None]


# ----------------------------------------------------------------------------------------------
# The skinned layout (issue #51 item 4), without a daemon


def hand_skinned(rng, n=6, bones=3, influences=2, residuals=2):
    """A small skinned basis built here from poses.proto's definition, entry by entry: its values
    in GetBasis's SKINNED order (the mean; per point K slots (j, h0..h3), a point with fewer bones
    padded with (0, 0, 0, 0, 0); the residual columns) and the mean and dense A they stand for."""
    mean = rng.normal(size=3 * n).astype(np.float32)
    R = rng.normal(size=(3 * n, residuals)).astype(np.float32)
    A = np.zeros((3 * n, 12 * bones + residuals), np.float32)
    slots = []
    for i in range(n):
        # Point 0 has bone 0 and then a padding slot naming bone 0 too; odd points have K bones.
        chosen = [0] if i == 0 else rng.choice(bones, size=1 + i % influences, replace=False)
        for k in range(influences):
            if k >= len(chosen):
                slots += [0, 0, 0, 0, 0]
                continue
            j, h = int(chosen[k]), rng.normal(size=4).astype(np.float32)
            if i == 1:
                h[0] = 0  # one zero in h is a term like any other: only four zeros are padding
            slots += [j, *h]
            for a in range(3):
                for c in range(4):
                    A[3 * i + a, 12 * j + 4 * a + c] = h[c]
    A[:, 12 * bones:] = R
    values = np.concatenate([mean, np.float32(slots), R.T.ravel()])  # R column by column
    return values, mean, A


SKINNED = dict(point_count=6, channel_count=3, basis_size=12 * 3 + 2, layout=poses_pb2.BASIS_LAYOUT_SKINNED,
               subspace_bone_count=3, influences_per_point=2)
BONE_OF_POINT_1_SLOT_0 = 18 + 5 * 2  # after the mean and point 0's two slots


def _skinned_chunks(split=(0, 11, 40), aligned=False, tamper=lambda values: None, **changes):
    values, mean, A = hand_skinned(np.random.default_rng(2))
    dense = mean.tobytes() + A.tobytes(order="F")
    checksum = (zlib.crc32(mean.tobytes()) << 32) | zlib.crc32(A.tobytes(order="F"))
    tamper(values)
    chunks = _split(values, split, changes, basis_checksum=checksum, basis_sha256=hashlib.sha256(dense).digest(),
                    aligned=aligned, **SKINNED)
    return chunks, values, mean, A


@pytest.mark.parametrize("aligned", [False, True], ids=["plain", "aligned"])
def test_a_skinned_stream_is_the_dense_basis_it_expands_to(scripted_server, tmp_path, aligned):
    ScriptedPoses.script, values, mean, A = _skinned_chunks(aligned=aligned)
    first = ScriptedPoses.script[0]
    assert first.total_values == 6 * 3 * (2 + 1) + 5 * 6 * 2 < A.size + mean.size
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        basis = client.get_basis("m", 3, layout="compact")
        with pytest.raises(animspace.ProtocolError, match="asked for the dense layout, the chunks are skinned"):
            client.get_basis("m", 3)
        with pytest.raises(ValueError, match="layout: expected 'dense', 'skinned' or 'compact', got 'sparse'"):
            client.get_basis("m", 3, layout="sparse")
    assert (basis.layout, basis.bone_count, basis.influences, basis.basis) == ("skinned", 3, 2, None)
    assert basis.basis_checksum == first.basis_checksum and basis.basis_sha256 == first.basis_sha256
    assert basis.nbytes == 4 * values.size  # the int32 bones in place of their float32 numbers
    np.testing.assert_array_equal(basis.mean, mean)
    np.testing.assert_array_equal(basis.residuals, A[:, 36:])
    dense = basis.dense_basis()
    assert dense.dtype == np.float32 and dense.flags.f_contiguous
    np.testing.assert_array_equal(dense, A)
    # The expansion's digests are zlib's and hashlib's of the dense values built here.
    assert coordinates.basis_checksum(mean, A) == first.basis_checksum
    assert coordinates.basis_sha256(mean, A) == first.basis_sha256

    rng = np.random.default_rng(3)
    for scale in (1e-4, 1.0, 1e4):
        p = (rng.normal(size=A.shape[1]) * scale).astype(np.float32)
        rotation = translation = None
        if aligned:
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            rotation, translation = q.astype(np.float32), rng.normal(size=3).astype(np.float32)
        c = animspace.SubspaceCoordinates(p=p, basis_checksum=basis.basis_checksum, rotation=rotation,
                                          translation=translation)
        exact = (mean.astype(np.float64) + A.astype(np.float64) @ p).reshape(-1, 3)
        if aligned:
            exact = exact @ rotation.astype(np.float64).T + translation
        got = coordinates.reconstruct(basis, c)
        bound = stated_bound(mean.astype(np.float64), A.astype(np.float64), p, rotation, translation)
        assert got.dtype == np.float32 and got.shape == (6, 3)
        # The bound is the client's rounding plus the server's: the client alone is within half of
        # it (unaligned: γ_{M+2}·(|mean_i| + Σ_j |A_ij p_j|); aligned, with room for R's rounding).
        allowed = bound if aligned else bound / 2
        assert np.all(np.abs(got - exact) <= allowed), float((np.abs(got - exact) - allowed).max())
        np.testing.assert_allclose(coordinates.rounding_bound(basis, c), bound, rtol=1e-12)


def test_a_skinned_float16_stream_assembles_and_is_not_cached(scripted_server, tmp_path):
    values, mean, A = hand_skinned(np.random.default_rng(2))
    half = values.astype("<f2")
    raw = half.tobytes()
    checksum = (zlib.crc32(mean.tobytes()) << 32) | zlib.crc32(A.tobytes(order="F"))
    ScriptedPoses.script = [poses_pb2.BasisChunk(
        model_version=3, basis_checksum=checksum, total_values=values.size, offset=0, data=raw,
        values_encoding=common_pb2.POINT_ENCODING_FLOAT16, values_sha256=hashlib.sha256(raw).digest(), **SKINNED)]
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        basis = client.get_basis("m", 3, values_encoding="float16", layout="skinned")
    assert basis.layout == "skinned" and basis.values_encoding == "float16"
    np.testing.assert_array_equal(basis.bones.ravel(), values[18:78:5])  # bone numbers are exact in binary16
    np.testing.assert_array_equal(basis.residuals.ravel(order="F"), half[78:].astype(np.float32))
    assert not any(tmp_path.rglob("*.basis"))


def _set(index, value):
    return lambda values: values.__setitem__(index, value)


@pytest.mark.parametrize("script, problem", [
    (dict(tamper=_set(BONE_OF_POINT_1_SLOT_0, 2.5)), "slot 0 of point 1 names bone 2.5, expected an integer in [0, 3)"),
    (dict(tamper=_set(BONE_OF_POINT_1_SLOT_0, 3)), "slot 0 of point 1 names bone 3, expected an integer in [0, 3)"),
    (dict(tamper=_set(BONE_OF_POINT_1_SLOT_0, -1)), "slot 0 of point 1 names bone -1"),
    (dict(tamper=_set(BONE_OF_POINT_1_SLOT_0, np.nan)), "slot 0 of point 1 names bone nan"),
    (dict(tamper=lambda v: v.__setitem__(BONE_OF_POINT_1_SLOT_0 + 5, v[BONE_OF_POINT_1_SLOT_0])),
     "point 1 names bone .* in two slots"),
    (dict(tamper=_set(BONE_OF_POINT_1_SLOT_0 + 2, 0.25)), "the values' checksum .* is not the basis_checksum"),
    (dict(c0={"total_values": 113}), "chunk 0: total_values 113, but N·3·(r+1) + 5·N·K = 6·3·3 + 5·6·2 = 114"),
    (dict(c1={"layout": poses_pb2.BASIS_LAYOUT_DENSE}), "chunk 1: layout 1 differs from chunk 0's 2"),
    (dict(c2={"subspace_bone_count": 4}), "chunk 2: subspace_bone_count 4 differs from chunk 0's 3"),
    (dict(c1={"influences_per_point": 3}), "chunk 1: influences_per_point 3 differs from chunk 0's 2"),
    (dict(c0={"layout": poses_pb2.BASIS_LAYOUT_COMPACT}), "chunk 0: layout 3, not DENSE or SKINNED"),
    (dict(c0={"subspace_bone_count": 0}), "chunk 0: layout SKINNED with subspace_bone_count 0"),
    (dict(c0={"channel_count": 1}), "chunk 0: skinned with channel_count 1"),
    (dict(c0={"basis_sha256": bytes(32)}, c1={"basis_sha256": bytes(32)}, c2={"basis_sha256": bytes(32)}),
     "the values' SHA-256 .* is not the basis_sha256 0000"),
], ids=["bone_2.5", "bone_out_of_range", "bone_negative", "bone_nan", "bone_twice", "term", "total",
        "layout_changes", "bone_count_changes", "influences_change", "layout_compact", "no_bones", "channels",
        "sha256_wrong"])
def test_broken_skinned_streams_are_protocol_errors(scripted_server, tmp_path, script, problem):
    ScriptedPoses.script, *_ = _skinned_chunks(**script)
    with animspace.Client(scripted_server, basis_cache=tmp_path) as client:
        with pytest.raises(animspace.ProtocolError, match="GetBasis: .*" + re.escape(problem).replace(r"\.\*", ".*")):
            client.get_basis("m", 3, layout="skinned")
    assert not any(tmp_path.rglob("*.basis"))


def skinned_basis(scripted_server, tmp_path):
    """The hand-built skinned basis assembled by a client (whose cache is tmp_path/"fetched")."""
    ScriptedPoses.script, values, mean, A = _skinned_chunks()
    with animspace.Client(scripted_server, basis_cache=tmp_path / "fetched") as client:
        return client.get_basis("m", 3, layout="skinned"), values, mean, A


def test_a_skinned_basis_is_cached_as_asbasis2_and_read_back(scripted_server, tmp_path):
    basis, values, mean, A = skinned_basis(scripted_server, tmp_path)
    cache = animspace.BasisCache(tmp_path / "bases")
    cache.put(basis)
    path = tmp_path / "bases" / "m" / f"3-{basis.basis_checksum:016x}.basis"
    data = path.read_bytes()
    # docs/FORMATS.md "Basis cache", parsed here: a 56-byte header, then the values as sent.
    assert struct.unpack_from("<8sIIIIQQIIII", data) == (b"ASBASIS2", 6, 3, 38, 0, 3, basis.basis_checksum, 2, 3,
                                                            2, 0)
    assert data[56:] == values.astype("<f4").tobytes()
    assert path.read_bytes() == (tmp_path / "fetched" / "m" / path.name).read_bytes()  # get_basis cached it too
    dense_sha256 = hashlib.sha256(mean.tobytes() + A.tobytes(order="F")).digest()
    read = animspace.BasisCache(tmp_path / "bases").get("m", 3, basis.basis_checksum,
                                                        server_sha256=lambda: dense_sha256)
    assert read.layout == "skinned" and read.basis_sha256 == dense_sha256
    np.testing.assert_array_equal(read.dense_basis(), A)
    np.testing.assert_array_equal(read.mean, mean)
    # A digest the copy does not have: refused, deleted.
    other = animspace.BasisCache(tmp_path / "bases")
    assert other.get("m", 3, basis.basis_checksum, server_sha256=lambda: bytes(32)) is None
    assert other.refused_copies == 1 and not path.exists()


@pytest.mark.parametrize("damage", [
    lambda data: data.__setitem__(slice(56 + 4 * 100, 56 + 4 * 101), struct.pack("<f", 0.5)),  # a residual
    lambda data: data.__setitem__(slice(56 + 4 * BONE_OF_POINT_1_SLOT_0, 56 + 4 * BONE_OF_POINT_1_SLOT_0 + 4),
                                  struct.pack("<f", 2.5)),
    lambda data: data.__delitem__(slice(-4, None)),  # truncated
    lambda data: data.__setitem__(slice(44, 48), struct.pack("<I", 2)),  # another B
    lambda data: data.__setitem__(slice(40, 44), struct.pack("<I", 1)),  # another layout
    lambda data: data.__setitem__(slice(52, 56), struct.pack("<I", 1)),  # reserved
    lambda data: data.__setitem__(slice(0, 8), b"ASBASIS1"),  # dense's magic
], ids=["value", "bone", "truncated", "bone_count", "layout", "reserved", "magic"])
def test_a_corrupt_skinned_cache_file_is_deleted(scripted_server, tmp_path, damage):
    basis, *_ = skinned_basis(scripted_server, tmp_path)
    path = next((tmp_path / "fetched" / "m").iterdir())
    data = bytearray(path.read_bytes())
    damage(data)
    path.write_bytes(bytes(data))
    assert coordinates.read_basis_file(path, "m", 3, basis.basis_checksum) is None
    assert not path.exists()
