"""One name and one unit per quantity across the Python client (issue #21 item 10): the proto's
field names (width_px, tolerance_px, horizontal_fov_rad), seconds as `deadline_s` on every call,
the old keyword names working with a DeprecationWarning, arguments the wire cannot carry refused
naming the argument, results that print short and save themselves, and an import that says what
is missing."""
import inspect
import os
import pathlib
import subprocess
import sys
import warnings

import numpy as np
import pytest

import animspace
from animspace.lod import LodAssembler
from animspace.v1 import common_pb2, lod_pb2

PACKAGE = pathlib.Path(animspace.__file__).resolve().parent


def public_calls():
    return [(name, member) for name, member in inspect.getmembers(animspace.Client, inspect.isfunction)
            if not name.startswith("_") and name != "close"]


def test_every_call_takes_its_deadline_as_deadline_s_and_no_other_name():
    for name, member in public_calls():
        parameters = inspect.signature(member).parameters
        assert "deadline_s" in parameters, name
        assert parameters["deadline_s"].kind is inspect.Parameter.KEYWORD_ONLY or name == "wait_until_serving", name
        assert not {"timeout", "timeout_s"} & set(parameters), name
    assert "deadline_s" in inspect.signature(animspace.Client).parameters


def test_the_old_deadline_names_still_work_with_a_deprecation_warning(daemon):
    with animspace.Client(daemon) as client:
        with pytest.warns(DeprecationWarning, match="wait_until_serving: timeout_s is deprecated; use deadline_s"):
            client.wait_until_serving(timeout_s=30)
        with pytest.warns(DeprecationWarning, match="list_models: timeout is deprecated; use deadline_s"):
            assert [m.name for m in client.list_models(timeout=10)] == [m.name for m in client.list_models()]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert client.server_info(deadline_s=10).max_thumbnail_px > 0
            client.wait_until_serving(deadline_s=30)
        with pytest.raises(TypeError, match="give deadline_s, not both deadline_s and timeout"):
            client.list_models(timeout=10, deadline_s=10)
        with pytest.raises(ValueError, match="deadline_s: expected seconds > 0"):
            client.list_models(deadline_s=0)


def test_the_thumbnail_tolerance_is_tolerance_px_like_get_lods(client):
    assert "tolerance_px" in inspect.signature(animspace.Client.render_thumbnail).parameters
    assert "pixel_tolerance" not in inspect.signature(animspace.Client.render_thumbnail).parameters
    full = client.render_thumbnail("arm-animspace", 32, 32)
    coarse = client.render_thumbnail("arm-animspace", 32, 32, tolerance_px=4)
    assert full.lod_level == 0 and coarse.lod_level > 0
    with pytest.warns(DeprecationWarning, match="render_thumbnail: pixel_tolerance is deprecated; use tolerance_px"):
        old = client.render_thumbnail("arm-animspace", 32, 32, pixel_tolerance=4)
    assert old.lod_level == coarse.lod_level


@pytest.mark.parametrize("call, argument", [
    (lambda c: c.render_thumbnail("arm", -5, 10), "width_px"),
    (lambda c: c.render_thumbnail("arm", 10, 2 ** 32), "height_px"),
    (lambda c: c.render_thumbnail("arm", 10, 10, samples=-1), "samples"),
    (lambda c: c.render_thumbnail("arm", 10, 10, sequence_frame=-1), "sequence_frame"),
    (lambda c: c.render_thumbnail("arm", 10.5, 10), "width_px"),
    (lambda c: c.render_thumbnail("arm", 10, 10, tolerance_px="one"), "tolerance_px"),
    (lambda c: c.get_lod("arm-animspace", level=-1), "level"),
    (lambda c: c.get_lod("arm-animspace", max_vertices=-300), "max_vertices"),
    (lambda c: c.get_lod("arm-animspace", tolerance_px=1, distance=40, viewport_width_px=-1920), "viewport_width_px"),
    (lambda c: c.get_lod("arm-animspace", level=0, vertices_per_chunk=-1), "vertices_per_chunk"),
    (lambda c: c.get_lod("arm-animspace", tolerance_px=1, distance="far"), "distance"),
    (lambda c: c.evaluate_skeleton_pose("arm-animspace", np.zeros((3, 3, 4)), lod_level=-1), "lod_level"),
    (lambda c: c.describe_model("arm", version=1.5), "version"),
    (lambda c: c.retrain("arm-pmsc", max_key_points=-1, dry_run=True), "max_key_points"),
])
def test_numbers_the_wire_cannot_carry_are_refused_naming_the_argument(client, call, argument):
    before = client.stats().models
    with pytest.raises(ValueError) as error:
        call(client)
    assert str(error.value).startswith(f"{argument}: expected ")
    # Refused before anything was sent: no model's request count moved.
    assert {n: s.requests for n, s in client.stats().models.items()} == {n: s.requests for n, s in before.items()}


def test_thumbnail_and_lod_results_print_short_and_save_themselves(client, tmp_path):
    thumbnail = client.render_thumbnail("arm-animspace", 64, 48)
    text = repr(thumbnail)
    assert text.startswith("Thumbnail(") and "width_px=64" in text and "height_px=48" in text
    assert f"png=<{len(thumbnail.png)} bytes>" in text and "\\x" not in text and len(text) < 300

    mesh = client.get_lod("arm-animspace", max_vertices=300)
    text = repr(mesh)
    assert text.startswith("LodMesh(") and f"positions=float32({mesh.vertex_count}, 3)" in text
    assert f"indices=uint32({mesh.face_count}, 3)" in text and len(text) < 600
    path = tmp_path / "arm.obj"
    mesh.save(path)
    assert path.read_text() == mesh.to_obj()
    vertices = np.array([[float(x) for x in line.split()[1:]] for line in path.read_text().splitlines()
                         if line.startswith("v ")])
    faces = np.array([[int(x) for x in line.split()[1:]] for line in path.read_text().splitlines()
                      if line.startswith("f ")])
    np.testing.assert_array_equal(vertices.astype(np.float32), mesh.positions)  # float32 round-trips
    np.testing.assert_array_equal(faces - 1, mesh.indices)  # OBJ counts from 1
    with pytest.raises(ValueError, match=r"path: expected a \.obj file, got 'arm\.ply'"):
        mesh.save(tmp_path / "arm.ply")

    # An animation-space level saves posed: at the rest pose, or at the pose given.
    skinned = client.get_lod("arm-animspace", max_vertices=300, form="animation_space")
    G = skinned.skeleton.rest_transforms.copy()
    G[:, :, 3] += (0.0, 2.0, 0.0)  # every bone moved up by 2
    skinned.save(tmp_path / "up.obj", G)
    up = np.array([[float(x) for x in line.split()[1:]] for line in (tmp_path / "up.obj").read_text().splitlines()
                   if line.startswith("v ")])
    np.testing.assert_allclose(up, skinned.pose() + np.array([0, 2, 0], dtype=np.float32), atol=1e-5)


def test_results_holding_arrays_print_their_shapes_not_their_values():
    header = lod_pb2.LodHeader(level=1, level_count=3, vertex_count=2000, face_count=3996,
                               form=lod_pb2.GetLodRequest.FORM_POSED)
    assembler = LodAssembler()
    assert assembler.take(lod_pb2.LodChunk(header=header)) == ""
    assert assembler.take(lod_pb2.LodChunk(vertices=lod_pb2.VertexBlock(
        first_vertex=0, vertex_count=2000,
        positions=common_pb2.PointArray(point_count=2000, channel_count=3, data=bytes(2000 * 12))))) == ""
    assert assembler.take(lod_pb2.LodChunk(faces=lod_pb2.FaceBlock(first_face=0, face_count=3996,
                                                                    indices=bytes(3996 * 12)))) == ""
    for result in (assembler.mesh(), animspace.PoseResult(points=np.zeros((5000, 3), np.float32), status="HIT",
                                                          key_point_error=0.0, blend_weight=0.0, model_version=1,
                                                          full_evaluation_needed=False),
                   animspace.SkinnedPose(points=np.zeros((5000, 3), np.float32), normals=None, model_version=1),
                   animspace.PointCache(np.zeros((10, 5000, 3), np.float32))):
        text = repr(result)
        assert "\n" not in text and "..." not in text and len(text) < 600, text
        assert "float32(" in text, text


def test_importing_without_grpcio_says_which_interpreter_and_packages(tmp_path):
    # An interpreter where grpc cannot be imported (a finder refusing it stands in for a Python
    # without python3-grpcio, such as a pyenv or a venv without --system-site-packages).
    script = ("import sys\n"
              "class NoGrpc:\n"
              "    def find_spec(self, name, path=None, target=None):\n"
              "        if name == 'grpc' or name.startswith('grpc.'):\n"
              "            raise ModuleNotFoundError(f\"No module named '{name}'\", name=name)\n"
              "sys.meta_path.insert(0, NoGrpc())\n"
              "import animspace\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(PACKAGE.parent)))
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: animspace needs grpcio and protobuf")
    assert f"{sys.executable} cannot import grpc" in last
    assert "/usr/bin/python3" in last and "python3-grpcio" in last and "--system-site-packages" in last
