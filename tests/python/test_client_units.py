"""Client pieces without animspaced: the wire format, the error mapping, the LOD stream checks, and
an in-process server that breaks the API's contract.

The LOD assembler is fed hand-made chunk streams, including the broken ones a real server never
sends (out of order, truncated, indices out of range), mirroring clients/cpp/lod_mesh.cpp.
"""
import pickle
import struct
from concurrent import futures

import grpc
import numpy as np
import pytest

import animspace
from animspace import wire
from animspace.lod import LodAssembler
from animspace.v1 import lod_pb2, lod_pb2_grpc, poses_pb2, poses_pb2_grpc

POSED = lod_pb2.GetLodRequest.FORM_POSED
ANIMATION_SPACE = lod_pb2.GetLodRequest.FORM_ANIMATION_SPACE


def test_point_arrays_are_packed_little_endian_point_major():
    message = wire.point_array("points", [[1, 2, 3], [4, 5, 6]])
    assert (message.point_count, message.channel_count) == (2, 3)
    assert message.data == struct.pack("<6f", 1, 2, 3, 4, 5, 6)
    big_endian = np.array([[1.5, -2, 3]], dtype=">f8")
    assert wire.point_array("points", big_endian).data == struct.pack("<3f", 1.5, -2, 3)
    back = wire.points_from(message)
    assert back.dtype == np.float32 and back.shape == (2, 3) and back.flags.writeable
    np.testing.assert_array_equal(back, [[1, 2, 3], [4, 5, 6]])
    message.point_count = 3
    with pytest.raises(ValueError, match=r"3 × 3 float32 need 36 bytes, got 24"):
        wire.points_from(message)


def test_skeleton_poses_carry_the_top_three_rows_row_major():
    G = np.tile(np.eye(4), (2, 1, 1))
    G[1, :3, 3] = (7, 8, 9)
    pose = wire.skeleton_pose("pose", G, "local")
    assert pose.bone_count == 2 and pose.space == animspace.v1.common_pb2.SkeletonPose.SPACE_LOCAL
    expected = struct.pack("<12f", 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0) + struct.pack(
        "<12f", 1, 0, 0, 7, 0, 1, 0, 8, 0, 0, 1, 9)
    assert pose.transforms == expected
    np.testing.assert_array_equal(wire.transforms_from(pose.transforms, 2), G[:, :3, :])
    G[0, 3, 0] = 1e-3
    with pytest.raises(ValueError, match=r"pose\[0\] has \[0.0010"):
        wire.skeleton_pose("pose", G)
    with pytest.raises(ValueError, match="space"):
        wire.skeleton_pose("pose", G[:, :3], "world")


def test_shape_messages_name_the_argument_and_both_shapes():
    with pytest.raises(ValueError, match=r"^key_values: expected shape \(K, 3\), got \(24, 2\)$"):
        wire.as_points("key_values", np.zeros((24, 2)), channels=3, points_label="K")
    with pytest.raises(ValueError, match=r"^full_values: expected shape \(1154, 3\), got \(1153, 3\)$"):
        wire.as_points("full_values", np.zeros((1153, 3)), count=1154)
    with pytest.raises(ValueError, match=r"^frames: expected shape \(P, N, D\), got \(3,\)$"):
        wire.as_points("frames", [1, 2, 3], ndim=3)
    keys = animspace.KeyPoints(model_version=1, indices=np.array([2, 0], np.uint32), channel_count=3,
                               control_point_count=3, regions=np.zeros(0, np.uint32), fail_through="CLIENT")
    full = np.arange(9, dtype=np.float32).reshape(3, 3)
    np.testing.assert_array_equal(keys.select(full), [[6, 7, 8], [0, 1, 2]])
    np.testing.assert_array_equal(keys.select(np.stack([full, full + 1]))[1], [[7, 8, 9], [1, 2, 3]])
    with pytest.raises(ValueError, match=r"points: expected shape \(3, D\) or \(P, 3, D\), got \(4, 3\)"):
        keys.select(np.zeros((4, 3)))


class FakeCallError(grpc.RpcError, grpc.Call):
    """What grpcio raises for a failed call: an RpcError that is also the Call."""

    def __init__(self, code, details):
        self._code, self._details = code, details

    def code(self):
        return self._code

    def details(self):
        return self._details

    def initial_metadata(self): return None  # noqa: E704
    def trailing_metadata(self): return None  # noqa: E704
    def is_active(self): return False  # noqa: E704
    def time_remaining(self): return None  # noqa: E704
    def cancel(self): return False  # noqa: E704
    def add_callback(self, callback): return False  # noqa: E704


def test_every_status_code_maps_to_its_subclass():
    expected = {
        grpc.StatusCode.CANCELLED: animspace.Cancelled,
        grpc.StatusCode.INVALID_ARGUMENT: animspace.InvalidArgument,
        grpc.StatusCode.DEADLINE_EXCEEDED: animspace.DeadlineExceeded,
        grpc.StatusCode.NOT_FOUND: animspace.NotFound,
        grpc.StatusCode.ALREADY_EXISTS: animspace.AlreadyExists,
        grpc.StatusCode.PERMISSION_DENIED: animspace.PermissionDenied,
        grpc.StatusCode.RESOURCE_EXHAUSTED: animspace.ResourceExhausted,
        grpc.StatusCode.FAILED_PRECONDITION: animspace.FailedPrecondition,
        grpc.StatusCode.ABORTED: animspace.Aborted,
        grpc.StatusCode.OUT_OF_RANGE: animspace.OutOfRange,
        grpc.StatusCode.UNIMPLEMENTED: animspace.Unimplemented,
        grpc.StatusCode.INTERNAL: animspace.Internal,
        grpc.StatusCode.UNAVAILABLE: animspace.Unavailable,
        grpc.StatusCode.DATA_LOSS: animspace.DataLoss,
        grpc.StatusCode.UNAUTHENTICATED: animspace.Unauthenticated,
        grpc.StatusCode.UNKNOWN: animspace.RpcError,
    }
    for code, cls in expected.items():
        error = animspace.error_from_grpc("EvaluateKeyPoints", FakeCallError(code, "poses[3].key_values: bad"))
        assert type(error) is cls and isinstance(error, animspace.RpcError) and isinstance(error, animspace.Error)
        assert (error.code, error.message, error.rpc) == (code, "poses[3].key_values: bad", "EvaluateKeyPoints")
        assert str(error) == f"EvaluateKeyPoints failed: {code.name}: poses[3].key_values: bad"
        copy = pickle.loads(pickle.dumps(error))
        assert type(copy) is cls and (copy.code, copy.message, copy.rpc) == (error.code, error.message, error.rpc)
    # An RpcError that is not a finished call still maps, never escaping as grpc.RpcError.
    bare = animspace.error_from_grpc("GetLod", grpc.RpcError("channel closed"))
    assert type(bare) is animspace.RpcError and bare.code == grpc.StatusCode.UNKNOWN


def posed_stream(vertices=4, faces=2, vertex_block=3, face_block=1):
    positions = np.arange(3 * vertices, dtype="<f4").reshape(vertices, 3)
    indices = np.array([[0, 1, 2], [1, 2, 3], [0, 2, 3]][:faces], dtype="<u4")
    chunks = [lod_pb2.LodChunk(header=lod_pb2.LodHeader(level=1, level_count=3, vertex_count=vertices,
                                                        face_count=faces, form=POSED))]
    for first in range(0, vertices, vertex_block):
        block = positions[first:first + vertex_block]
        chunks.append(lod_pb2.LodChunk(vertices=lod_pb2.VertexBlock(
            first_vertex=first, vertex_count=len(block),
            positions={"point_count": len(block), "channel_count": 3, "data": block.tobytes()})))
    for first in range(0, faces, face_block):
        block = indices[first:first + face_block]
        chunks.append(lod_pb2.LodChunk(faces=lod_pb2.FaceBlock(first_face=first, face_count=len(block),
                                                               indices=block.tobytes())))
    return chunks, positions, indices


def assemble(chunks):
    assembler = LodAssembler()
    for chunk in chunks:
        problem = assembler.take(chunk)
        if problem:
            return problem
    return assembler.complete() or assembler.mesh()


def test_a_posed_stream_reassembles_from_any_blocking():
    chunks, positions, indices = posed_stream()
    mesh = assemble(chunks)
    assert mesh.header.form == "posed" and mesh.chunk_count == len(chunks)
    np.testing.assert_array_equal(mesh.positions, positions)
    np.testing.assert_array_equal(mesh.indices, indices)
    np.testing.assert_array_equal(mesh.pose(), positions)
    with pytest.raises(ValueError, match="already posed"):
        mesh.pose(np.tile(np.eye(4), (1, 1, 1)))


def test_broken_posed_streams_are_named():
    chunks, _, _ = posed_stream()
    header, v0, v1, f0, f1 = chunks
    cases = {
        "the first chunk must be the header": [v0, header],
        "a second header": [header, header],
        "expected first_vertex 0 (blocks in order, contiguous)": [header, v1, v0],
        "faces must follow every vertex block": [header, v0, f0],
        "expected first_face 1": [header, v0, v1, f0, f0],
        "the stream ended after 3 of 4 vertices": [header, v0],
        "the stream ended after 1 of 2 faces": [header, v0, v1, f0],
        "the stream ended without a header": [],
        "a skeleton in a FORM_POSED stream": [header, v0, v1, f0, f1, lod_pb2.LodChunk(skeleton={})],
        "a chunk without a payload": [header, lod_pb2.LodChunk()],
    }
    for problem, stream in cases.items():
        assert problem in assemble(stream)
    bad_index = lod_pb2.LodChunk(faces={"first_face": 0, "face_count": 1, "indices": struct.pack("<3I", 0, 1, 4)})
    assert "vertex index 4 is not below vertex_count 4" in assemble([header, v0, v1, bad_index])
    short = lod_pb2.LodChunk(vertices={"first_vertex": 0, "vertex_count": 3,
                                       "positions": {"point_count": 3, "channel_count": 3, "data": b"\0" * 24}})
    assert "positions must be 3 × 3 float32 (36 bytes), got 3 × 3 in 24 bytes" in assemble([header, short])
    bad_form = lod_pb2.LodChunk(header={"vertex_count": 1})
    assert "header.form: expected FORM_ANIMATION_SPACE or FORM_POSED" in assemble([bad_form])


def animation_space_chunks(morph=False):
    # Two vertices, bones 0 and 1: vertex 0 has one influence, vertex 1 two (CSR 0, 1, 3).
    offsets = np.array([0, 1, 3], "<u4")
    bones = np.array([0, 0, 1], "<u4")
    p = np.array([[1, 2, 3, 1], [4, 5, 6, 0.25], [7, 8, 9, 0.75]], "<f4")
    delta = np.array([[0, 0, 0, 0], [1, 1, 1, 0.5], [0, 0, 0, -0.5]], "<f4")
    rest = np.tile(np.eye(4)[:3], (2, 1, 1)).astype("<f4")
    rest[1, :, 3] = (10, 0, 0)
    block = {"first_vertex": 0, "vertex_count": 2, "influence_offsets": offsets.tobytes(),
             "bone_indices": bones.tobytes(), "animation_positions": p.tobytes()}
    if morph:
        block["geomorph_delta"] = delta.tobytes()
    return [
        lod_pb2.LodChunk(header={"vertex_count": 2, "face_count": 1, "bone_count": 2, "influence_count": 3,
                                 "form": ANIMATION_SPACE}),
        lod_pb2.LodChunk(vertices=block),
        lod_pb2.LodChunk(faces={"first_face": 0, "face_count": 1, "indices": struct.pack("<3I", 0, 1, 1)}),
        lod_pb2.LodChunk(skeleton={"parents": [-1, 0], "rest_transforms": rest.tobytes(),
                                   "bone_names": ["root", "child"]}),
    ], p, delta


def test_an_animation_space_stream_reassembles_and_skins_by_eq_3_1():
    chunks, p, delta = animation_space_chunks(morph=True)
    mesh = assemble(chunks)
    assert mesh.skeleton.bone_names == ("root", "child") and mesh.skeleton.parents.tolist() == [-1, 0]
    np.testing.assert_array_equal(mesh.influence_offsets, [0, 1, 3])
    np.testing.assert_array_equal(mesh.animation_positions, p)
    np.testing.assert_array_equal(mesh.geomorph_delta, delta)
    # v = Σ_j G_j p_j by hand, at the rest pose: G_0 = I, G_1 = T(10, 0, 0).
    expected = np.array([[1, 2, 3], [4 + 7 + 10 * 0.75, 5 + 8, 6 + 9]])
    np.testing.assert_allclose(mesh.pose(), expected, rtol=1e-6)
    # A local pose: L_1 = identity puts the child at its parent's frame, so G_1 = I.
    np.testing.assert_allclose(mesh.pose(np.tile(np.eye(4), (2, 1, 1)), space="local"),
                               [[1, 2, 3], [11, 13, 15]], rtol=1e-6)
    np.testing.assert_allclose(mesh.skeleton.rest_local_transforms()[1, :, 3], [10, 0, 0])
    # p + t·Δp: bone 0's p moves by t·(1, 1, 1, 0.5) under G_0 = I; bone 1's w drops by 0.5·t, so
    # its translation T(10, 0, 0) contributes 10·(−0.5)·t to x.
    morphed = mesh.pose(geomorph=0.5)
    np.testing.assert_allclose(morphed[1], expected[1] + 0.5 * np.array([1 + 10 * -0.5, 1, 1]), rtol=1e-6)


def test_broken_animation_space_streams_are_named():
    chunks, _, _ = animation_space_chunks()
    header, vertices, faces, skeleton = chunks
    assert "the stream ended without the skeleton" in assemble([header, vertices, faces])
    bad_bone = lod_pb2.LodChunk()
    bad_bone.CopyFrom(vertices)
    bad_bone.vertices.bone_indices = struct.pack("<3I", 0, 2, 1)
    assert "bone index 2 is not below bone_count 2" in assemble([header, bad_bone])
    decreasing = lod_pb2.LodChunk()
    decreasing.CopyFrom(vertices)
    decreasing.vertices.influence_offsets = struct.pack("<3I", 0, 2, 1)
    assert "influence_offsets decrease at entry 2" in assemble([header, decreasing])
    lonely = lod_pb2.LodChunk()
    lonely.CopyFrom(skeleton)
    del lonely.skeleton.parents[:]
    assert "skeleton: expected 2 parents" in assemble([header, vertices, faces, lonely])
    assert "a second skeleton" in assemble([header, vertices, faces, skeleton, skeleton])
    greedy = lod_pb2.LodChunk()
    greedy.CopyFrom(header)
    greedy.header.influence_count = 2
    assert "more influences than the header's 2" in assemble([greedy, vertices])


# ----------------------------------------------------------------------------------------------
# A misbehaving server (in-process, from the generated servicers): replies that break the API's
# contract are ProtocolErrors, not silently wrong results.


class MisbehavingPoses(poses_pb2_grpc.PoseServiceServicer):
    def StreamKeyPoints(self, request_iterator, context):
        for frame in request_iterator:
            # Answers every frame, numbering the second one wrong.
            yield poses_pb2.PoseResult(status=1, sequence=frame.sequence + (frame.sequence == 1))

    def EvaluateKeyPoints(self, request, context):
        # Counts that do not match the bytes.
        return poses_pb2.EvaluateKeyPointsResponse(results=[
            poses_pb2.PoseResult(points={"point_count": 5, "channel_count": 3, "data": b"\0" * 12})])


class TruncatingLod(lod_pb2_grpc.LodServiceServicer):
    def GetLod(self, request, context):
        chunks, _, _ = posed_stream()
        yield from chunks[:2]  # the header announces more than arrives


@pytest.fixture()
def misbehaving_server():
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=4))
    poses_pb2_grpc.add_PoseServiceServicer_to_server(MisbehavingPoses(), server)
    lod_pb2_grpc.add_LodServiceServicer_to_server(TruncatingLod(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    yield f"127.0.0.1:{port}"
    server.stop(grace=None)


def test_replies_that_break_the_contract_are_protocol_errors(misbehaving_server):
    with animspace.Client(misbehaving_server, deadline_s=10) as client:
        stream = client.stream_key_points("m", [np.zeros((2, 3))] * 3)
        assert next(stream).sequence == 0
        with pytest.raises(animspace.ProtocolError, match="expected the result of frame 1, got sequence 2") as error:
            next(stream)
        assert error.value.rpc == "StreamKeyPoints" and isinstance(error.value, animspace.Error)
        with pytest.raises(animspace.ProtocolError, match=r"5 × 3 float32 need 60 bytes, got 12"):
            client.evaluate_key_points("m", np.zeros((2, 3)))
        with pytest.raises(animspace.ProtocolError, match="GetLod: the stream ended after 3 of 4 vertices"):
            client.get_lod("m", level=0)
