"""The Blender add-on (clients/blender), installed from the built zip into Debian's Blender and
driven headless (`blender -b`) against a daemon serving the demo repository.

Blender runs once (tests/python/blender_workflows.py) and writes what it ended up holding; each
test here compares one workflow with the daemon's own answers for the same input, fetched with the
Python client outside Blender, and with poses built independently (conftest's arm transforms,
restated from core/demo/bending_arm.h).
"""
import ast
import json
import math
import os
import pathlib
import shutil
import socket
import subprocess
import zipfile

import numpy as np
import pytest

import animspace

from conftest import BUILD
from test_coordinates import raw_basis, stated_bound

HERE = pathlib.Path(__file__).resolve().parent
ZIP = BUILD / "clients" / "blender" / "animspace_blender.zip"
BLENDER = shutil.which("blender")
# Set to a path to refresh the README's picture from this run (docs/blender/workflows.png).
SCREENSHOT = os.environ.get("ANIMSPACE_BLENDER_SCREENSHOT")

NO_BLENDER = "Blender is not installed (scripts/install-deps.sh installs Debian's blender package)"

PMSC_MODEL = "arm-pmsc"  # client fail-through: blends and misses wait for CompleteMiss
SKINNED_MODEL = "arm-animspace"
# Poses as (shoulder_rad, elbow_rad) of the bending arm.
POSES = {"operator": (0.3, 1.1), "handler": (-0.2, 0.6), "bake_first": (0.1, 0.4), "bake_last": (0.25, 1.5)}
LOD_LEVEL = 3
# The demo's model whose levels were built under its texture atlas, and the coarser level of it
# imported with its UV map.
LEVELS_MODEL = "arm-smooth"
LEVELS_MODEL_LEVEL = 2
MAX_VERTICES = 600
VIEW = {"location": (0.5, -20.0, 3.0), "rotation_euler": (math.radians(85), 0.0, 0.0), "lens_mm": 50.0,
        "sensor_width_mm": 36.0, "resolution": (1920, 1080), "resolution_percentage": 50, "tolerance_px": 1.5}
THUMBNAIL = (200, 150)
VERDICT_COLOURS = {"HIT": (0.05, 0.60, 0.10, 1.0), "BLEND": (0.90, 0.55, 0.00, 1.0), "MISS": (0.80, 0.02, 0.02, 1.0)}


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def blender_run(tmp_path_factory, request):
    """One Blender session over every workflow: (daemon address, out dir, results, frames)."""
    if BLENDER is None:
        pytest.skip(NO_BLENDER)
    if not ZIP.is_file():
        pytest.fail(f"{ZIP} is missing: the build makes it (target animspace_blender_addon)")
    from conftest import _arm_transforms, _demo_arm_transforms, run_animspaced

    work = tmp_path_factory.mktemp("blender")
    out = work / "out"
    out.mkdir()
    misses = work / "misses"
    misses.mkdir()
    # A second daemon that wants a bearer token and, where openssl can make certificates, mutual
    # TLS under a name other than its address.
    secure = work / "secure"
    secure.mkdir()
    (secure / "users").write_text("user-secret\n")
    (secure / "token").write_text("user-secret\n")
    secure_flags = ["--auth-token-file", str(secure / "users")]
    tls = None
    if shutil.which("openssl") is not None:
        from test_client_admin import _certificate, _openssl

        _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout",
                 "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=animspace test CA", cwd=secure)
        _certificate(secure, "server", "/CN=animspace.test", "subjectAltName=DNS:animspace.test")
        _certificate(secure, "client", "/CN=animspace test client", "extendedKeyUsage=clientAuth")
        secure_flags += ["--tls-cert", str(secure / "server.pem"), "--tls-key", str(secure / "server.key"),
                         "--tls-client-ca", str(secure / "ca.pem")]
        tls = {"root_certificates_file": str(secure / "ca.pem"), "client_certificate_file": str(secure / "client.pem"),
               "client_key_file": str(secure / "client.key"), "server_name": "animspace.test"}
    # A third daemon serving the demo arm with a texture atlas (`animspace atlas`), under its own name.
    atlas_work = work / "atlas"
    atlas_repository = atlas_work / "repository"
    (atlas_repository / SKINNED_MODEL / "1").mkdir(parents=True)
    for arguments in (["demo-repository", atlas_work / "demo"],
                      ["atlas", atlas_work / "demo" / SKINNED_MODEL / "1" / "model.anim", "-o",
                       atlas_repository / SKINNED_MODEL / "1" / "model.anim"]):
        made = subprocess.run([str(BUILD / "bin" / "animspace"), *map(str, arguments)], capture_output=True,
                              text=True, timeout=600)
        assert made.returncode == 0, made.stdout + made.stderr
    with run_animspaced(work, "--miss-log-dir", str(misses)) as address, animspace.Client(address) as client, \
            run_animspaced(secure, *secure_flags) as token_address, \
            run_animspaced(atlas_work, "--model-repository", str(atlas_repository)) as atlas_address:
        client.wait_until_serving(deadline_s=60)
        # The sequence the Mesh Cache modifier plays: three of the demo's unseen frames (hits),
        # an elbow bent past the training range (a blend, judged with its check points: the
        # middle of arm-pmsc's blend zone) and one bent backwards (a miss).
        transforms = [_demo_arm_transforms(f / 120) for f in (1, 31, 61)] + [_arm_transforms(2.37),
                                                                             _arm_transforms(math.radians(-60))]
        frames = np.stack([client.evaluate_skeleton_pose(SKINNED_MODEL, G).points for G in transforms])
        animspace.write_pc2(work / "sequence.pc2", frames)
        # The animation Blender writes to Alembic and sends to the trainers: the demo arm's motion
        # over 16 frames.
        train_frames = np.stack([client.evaluate_skeleton_pose(SKINNED_MODEL, _demo_arm_transforms(f / 16)).points
                                 for f in range(16)])
        animspace.write_pc2(work / "train.pc2", train_frames)
        level0 = client.get_lod(SKINNED_MODEL, level=0)
        np.save(work / "rest.npy", level0.positions)
        np.save(work / "faces.npy", level0.indices.astype(np.int64))
        config = {
            "zip": str(ZIP), "out_dir": str(out), "address": address, "unreachable": f"127.0.0.1:{_closed_port()}",
            "token_address": token_address, "token_file": str(secure / "token"), "tls": tls,
            "rest_points": str(work / "rest.npy"), "faces": str(work / "faces.npy"),
            "sequence_pc2": str(work / "sequence.pc2"), "frame_count": len(frames), "complete_frames": [4, 5],
            "pmsc_model": PMSC_MODEL, "bad_model": "no-such-model", "skinned_model": SKINNED_MODEL,
            "poses": POSES, "lod_level": LOD_LEVEL, "max_vertices": MAX_VERTICES, "view": VIEW,
            "train": {"pc2": str(work / "train.pc2"), "frames": len(train_frames), "abc": str(work / "arm.abc"),
                      "mdd": str(work / "arm.mdd"),
                      "command": str(BUILD / "bin" / "animspace"), "missing_command": str(work / "no-such-animspace"),
                      "repository": str(work / "trained"), "sequence_folder": str(work / "sent")},
            "atlas": {"address": atlas_address, "levels_model": LEVELS_MODEL, "coarser_level": LEVELS_MODEL_LEVEL},
            "thumbnail": THUMBNAIL, "screenshot": {"path": str(out / "workflows.png"), "resolution": [1200, 520]},
        }
        (work / "config.json").write_text(json.dumps(config))
        # Blender's user folders in the test's tree: installing the add-on must not touch $HOME.
        environment = dict(os.environ, BLENDER_USER_SCRIPTS=str(work / "user-scripts"),
                           BLENDER_USER_CONFIG=str(work / "user-config"), ANIMSPACE_BASIS_CACHE=str(work / "bases"))
        done = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                               str(HERE / "blender_workflows.py"), "--", str(work / "config.json")],
                              capture_output=True, text=True, timeout=300, env=environment)
        (work / "blender.log").write_text(done.stdout + done.stderr)
        results_file = out / "results.json"
        assert done.returncode == 0 and results_file.is_file(), done.stdout[-4000:] + done.stderr[-4000:]
        results = json.loads(results_file.read_text())
        assert "script_error" not in results, results["script_error"] + "\n" + done.stdout[-3000:]
        if SCREENSHOT:
            shutil.copyfile(out / "workflows.png", SCREENSHOT)
        yield {"client": client, "out": out, "results": results, "frames": frames, "work": work, "misses": misses,
               "train_frames": train_frames, "atlas_address": atlas_address}


def test_the_zip_holds_the_add_on_and_the_client_it_carries_and_builds_reproducibly(tmp_path):
    # No Blender needed: what Blender's "Install from file" would unpack.
    assert ZIP.is_file(), f"{ZIP} is missing: the build makes it (target animspace_blender_addon)"
    addon = HERE.parents[1] / "clients" / "blender"
    with zipfile.ZipFile(ZIP) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    expected = {f"animspace_blender/{p.relative_to(addon / 'animspace_blender').as_posix()}": p.read_bytes()
                for p in (addon / "animspace_blender").rglob("*.py")}
    client = BUILD / "python" / "animspace"
    expected.update({f"animspace_blender/vendor/animspace/{p.relative_to(client).as_posix()}": p.read_bytes()
                     for p in client.rglob("*") if p.is_file() and p.suffix in (".py", ".typed")
                     and "__pycache__" not in p.parts})
    assert entries == expected
    assert "animspace_blender/vendor/animspace/v1/poses_pb2_grpc.py" in entries
    # bl_info, read without importing bpy: the add-on declares the Blender it was tested on.
    tree = ast.parse(entries["animspace_blender/__init__.py"])
    bl_info = next(ast.literal_eval(node.value) for node in tree.body
                   if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "bl_info")
    assert bl_info["blender"] == (3, 4, 0) and bl_info["name"] == "animspace"
    # The same sources give the same bytes.
    again = tmp_path / "again.zip"
    subprocess.run(["/usr/bin/python3", str(addon / "build_addon.py"), "--addon", str(addon / "animspace_blender"),
                    "--python", str(BUILD / "python"), "--output", str(again)], check=True, timeout=60)
    assert again.read_bytes() == ZIP.read_bytes()


def load(run, name):
    return np.load(run["out"] / f"{name}.npy")


def test_the_add_on_installs_from_the_zip_and_uses_the_client_it_carries(blender_run):
    results = blender_run["results"]
    user_scripts = blender_run["work"] / "user-scripts"
    addon = pathlib.Path(results["addon_file"])
    assert addon.is_relative_to(user_scripts / "addons" / "animspace_blender")
    assert pathlib.Path(results["client_file"]) == addon.parent / "vendor" / "animspace" / "__init__.py"


def test_connect_lists_the_models_and_reports_an_unreachable_server(blender_run):
    results, client = blender_run["results"], blender_run["client"]
    assert results["health"] == "SERVING"
    expected = {m.name: m.default for m in client.list_models()}
    assert set(results["models"]) == set(expected)
    for name, listed in results["models"].items():
        assert listed["kind"] == expected[name].kind
        assert listed["point_count"] == expected[name].point_count
        assert listed["has_tangents"] == ("animspace.tangents" in expected[name].sections)
    report = results["unreachable_report"]
    assert report is not None and "UNAVAILABLE" in report and "Traceback" not in report


def test_a_token_file_is_sent_as_the_bearer_token(blender_run):
    results = blender_run["results"]
    report = results["no_token_report"]
    assert report is not None and "UNAUTHENTICATED" in report and "Traceback" not in report
    assert results["token_models"] == sorted(m.name for m in blender_run["client"].list_models())


def test_tls_options_reach_the_client(blender_run):
    results = blender_run["results"]
    if "tls" not in results:
        pytest.skip("needs the openssl command to make test certificates")
    # Plaintext to a TLS-only daemon, and TLS without the client certificate it requires: refused.
    # With the CA, the client certificate and key and the server name the models are listed (the
    # token test above ran over that connection).
    assert results["token_models"]
    for report in (results["plaintext_report"], results["no_client_certificate_report"]):
        assert report is not None and "UNAVAILABLE" in report and "Traceback" not in report


def test_the_sidebar_draws_every_workflow_and_disabling_leaves_nothing_behind(blender_run):
    results = blender_run["results"]
    drawn = results["panels"]
    assert len(drawn["panels"]) == 6
    assert set(drawn["operators"]) == set(results["operators"])  # every operator has its button
    assert {"address", "token_file", "root_certificates_file", "pmsc_model", "source", "model", "lod_selection"} \
        <= set(drawn["props"])
    assert not any("animspace" in name for name in results["after_disable"]["handlers"])
    assert results["after_disable"]["scene_settings"] is False
    assert results["after_disable"]["panels"] == []


def test_caches_blender_wrote_are_sent_to_train_pmsc_and_fit(blender_run, tmp_path):
    from conftest import run_animspaced

    results, work = blender_run["results"]["train"], blender_run["work"]
    sent = blender_run["train_frames"]
    # MDD always; Alembic where this Blender can write and read it (Debian's 3.4 cannot).
    caches = {"mdd": "MESH_CACHE"}
    if results["alembic_supported"]:
        caches["alembic"] = "MESH_SEQUENCE_CACHE"
    repository = work / "trained"
    for name, modifier in caches.items():
        assert results[name]["modifiers"] == [modifier]
        # What reached the trainer is the animation that went into the cache, frame by frame and
        # vertex by vertex (both formats keep float32 positions; Alembic's Y-up is converted back).
        cache = animspace.read_pc2(work / "sent" / name / "frames.pc2").frames
        assert cache.shape == sent.shape
        np.testing.assert_allclose(cache, sent, rtol=0, atol=1e-5 * np.abs(sent).max())
        reference = (work / "sent" / name / "reference.obj").read_text().splitlines()
        assert sum(line.startswith("f ") for line in reference) == np.load(work / "faces.npy").shape[0]
        assert (repository / f"arm-pmsc-from-{name}" / "1" / "model.anim").is_file()
    assert (repository / "arm-fit-from-mdd" / "1" / "model.anim").is_file()
    # A daemon serving the repository loads each model as what it is, trained on every frame.
    with run_animspaced(tmp_path, "--model-repository", str(repository), "--renderer", "none") as address, \
            animspace.Client(address) as client:
        client.wait_until_serving(deadline_s=60)
        fitted = client.describe_model("arm-fit-from-mdd").default
        assert (fitted.kind, fitted.point_count, fitted.bone_count) == ("ANIMATION_SPACE", sent.shape[1], 3)
        diagonal = np.linalg.norm(sent[0].max(axis=0) - sent[0].min(axis=0))
        for name in caches:
            model = f"arm-pmsc-from-{name}"
            pmsc = client.describe_model(model).default
            assert (pmsc.kind, pmsc.point_count, pmsc.frame_count) == ("PMSC", sent.shape[1], len(sent))
            # A training frame's key points give back that frame: the model learned these positions.
            keys = client.describe_key_points(model)
            answer = client.evaluate_key_points(model, sent[5][keys.indices])
            assert answer.status == "HIT"
            assert np.linalg.norm(answer.points - sent[5], axis=1).max() < 0.01 * diagonal
    assert "at least 3 frames" in results["short_range_report"]
    assert "cannot run" in results["missing_command_report"] and "no-such-animspace" in results["missing_command_report"]
    assert "Model name" in results["no_model_report"]
    for report in (results["short_range_report"], results["missing_command_report"], results["no_model_report"]):
        assert "Traceback" not in report


def test_bad_input_is_a_report_with_the_servers_message_not_a_traceback(blender_run):
    client, results = blender_run["client"], blender_run["results"]
    with pytest.raises(animspace.NotFound) as unknown_model:
        client.describe_key_points("no-such-model")
    with pytest.raises(animspace.InvalidArgument) as bad_level:
        client.get_lod(SKINNED_MODEL, level=10_000)
    for report, refused in ((results["bad_model_report"], unknown_model.value),
                            (results["bad_level_report"], bad_level.value)):
        assert report is not None and refused.message in report and refused.code.name in report
        assert "Traceback" not in report


def expect_answer(client, shown, key_values, check_values):
    """``shown`` is the soft cache's float32 answer for these values, within the rounding bound of
    a reconstruction from coordinates (test_coordinates.stated_bound) where the answer is one."""
    expected = client.evaluate_key_points(PMSC_MODEL, key_values, check_values=check_values)
    as_coordinates = client.evaluate_key_points(PMSC_MODEL, key_values, check_values=check_values,
                                                points_encoding="coordinates")
    bound = 0.0
    if as_coordinates.coordinates is not None:
        _, mean, A = raw_basis(client.channel, PMSC_MODEL, as_coordinates.model_version)
        bound = stated_bound(mean, A, as_coordinates.coordinates.p)
    # (+ the 1e-6 this test always allowed the float32 answer on its way through Blender)
    assert np.all(np.abs(shown.astype(np.float64) - expected.points) <= bound + 1e-6)
    return expected


def test_playback_writes_the_daemons_answer_for_each_frames_key_points(blender_run):
    client, frames = blender_run["client"], blender_run["frames"]
    keys = client.describe_key_points(PMSC_MODEL)
    played = load(blender_run, "played")
    statuses = set()
    # Answers came as coordinates (the default), rebuilt with the basis the add-on cached.
    assert blender_run["results"]["answers_as_coordinates"] is True
    assert [p.parent.name for p in (blender_run["work"] / "bases").rglob("*.basis")] == [PMSC_MODEL]
    for i, shown in enumerate(blender_run["results"]["played"]):
        # The add-on sends the frame's check values with its key values (issue #35).
        expected = client.evaluate_key_points(PMSC_MODEL, keys.select(frames[i]),
                                              check_values=keys.select_check_values(frames[i]))
        assert shown["last_error"] == ""
        assert shown["status"] == expected.status, f"frame {i + 1}"
        assert shown["key_point_error"] == pytest.approx(expected.key_point_error, rel=1e-5)
        assert shown["checked"] == expected.checked == (keys.check_point_count > 0)
        assert shown["check_point_error"] == pytest.approx(expected.check_point_error, rel=1e-5)
        assert shown["blend_weight"] == pytest.approx(expected.blend_weight, abs=1e-6)
        expect_answer(client, played[i], keys.select(frames[i]), keys.select_check_values(frames[i]))
        # The verdict as a colour attribute on every point.
        attribute = shown["attribute"]
        assert attribute["domain"] == "POINT"
        np.testing.assert_allclose(attribute["colours"], np.tile(VERDICT_COLOURS[expected.status], (len(played[i]), 1)),
                                   atol=1e-6)
        statuses.add(expected.status)
    assert statuses == {"HIT", "BLEND", "MISS"}  # the sequence was chosen to show all three


def test_blends_and_misses_are_completed_with_the_evaluated_mesh_and_logged(blender_run):
    client, frames = blender_run["client"], blender_run["frames"]
    keys = client.describe_key_points(PMSC_MODEL)
    for completed in blender_run["results"]["completed"]:
        full = frames[completed["frame"] - 1]
        pose = keys.pose(full)
        estimate = client.evaluate_key_points(PMSC_MODEL, pose.key_values, check_values=pose.check_values)
        assert completed["status"] == estimate.status and estimate.status in ("BLEND", "MISS")
        assert completed["logged"] is True
        expected = client.complete_miss(PMSC_MODEL, pose.key_values, full, check_values=pose.check_values,
                                        version=estimate.model_version).result
        np.testing.assert_allclose(load(blender_run, f"completed_{completed['frame']}"), expected.points,
                                   rtol=0, atol=1e-6)
    log = blender_run["misses"] / f"{PMSC_MODEL}.misses"
    assert log.is_file() and log.stat().st_size > 0


def test_a_baked_range_holds_the_streams_answers(blender_run):
    client, frames = blender_run["client"], blender_run["frames"]
    keys = client.describe_key_points(PMSC_MODEL)
    baked = animspace.read_pc2(blender_run["out"] / "soft_cache.pc2")
    assert (baked.frame_count, baked.point_count, baked.start_frame) == (len(frames), frames.shape[1], 1.0)
    streamed = list(client.stream_key_points(PMSC_MODEL, [keys.pose(frame) for frame in frames]))
    for i, result in enumerate(streamed):
        np.testing.assert_allclose(baked.frames[i], result.points, rtol=0, atol=1e-5, err_msg=f"frame {i + 1}")


def _G(shoulder_rad, elbow_rad):
    from conftest import _arm_transforms
    return _arm_transforms(elbow_rad=elbow_rad, shoulder_rad=shoulder_rad)


def test_the_built_model_is_the_servers_rest_mesh_with_its_skeleton(blender_run):
    client = blender_run["client"]
    built = blender_run["results"]["skinned"]
    level = client.get_lod(SKINNED_MODEL, level=0, form="animation_space")
    assert built["vertices"] == level.header.vertex_count and built["bones"] == level.header.bone_count
    assert built["parent"] == built["rig"] and built["include_normals"] is True
    rest = client.evaluate_skeleton_pose(SKINNED_MODEL, level.skeleton.rest_transforms).points
    np.testing.assert_allclose(load(blender_run, "skinned_rest"), rest, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(load(blender_run, "skinned_faces"), level.indices)


def test_posing_from_the_armature_equals_evaluate_skeleton_pose(blender_run):
    client = blender_run["client"]
    for name in ("operator", "handler"):
        expected = client.evaluate_skeleton_pose(SKINNED_MODEL, _G(*POSES[name]), include_normals=True)
        np.testing.assert_allclose(load(blender_run, f"skinned_{name}"), expected.points, rtol=0, atol=2e-5,
                                   err_msg=name)
        if name == "operator":
            # Custom split normals as Blender draws them: the server's, to Blender's storage precision.
            unit = expected.normals / np.linalg.norm(expected.normals, axis=1, keepdims=True)
            cosine = np.sum(load(blender_run, "skinned_operator_normals") * unit, axis=1)
            assert cosine.min() > 0.9999
    # The soft cache, live on the posed arm, answered for the new pose (not the one before it).
    keys = client.describe_key_points(PMSC_MODEL)
    posed = client.evaluate_skeleton_pose(SKINNED_MODEL, _G(*POSES["handler"])).points
    handler = keys.pose(load(blender_run, "skinned_handler"))
    played = client.evaluate_key_points(PMSC_MODEL, handler.key_values, check_values=handler.check_values)
    assert blender_run["results"]["chained"]["status"] == played.status
    expect_answer(client, load(blender_run, "chained"), handler.key_values, handler.check_values)
    assert client.evaluate_key_points(PMSC_MODEL, keys.select(posed),
                                      check_values=keys.select_check_values(posed)).status == played.status
    assert blender_run["results"]["skinned_handler_error"] == ""
    baked = animspace.read_pc2(blender_run["out"] / "skinned.pc2")
    assert baked.frame_count == 3 and baked.start_frame == 1.0
    for index, name in ((0, "bake_first"), (2, "bake_last")):
        expected = client.evaluate_skeleton_pose(SKINNED_MODEL, _G(*POSES[name])).points
        np.testing.assert_allclose(baked.frames[index], expected, rtol=0, atol=2e-5, err_msg=name)


def _check_lod(run, name, expected):
    shown = run["results"]["lods"][name]
    assert shown["level"] == expected.header.level
    assert shown["epsilon"] == pytest.approx(expected.header.epsilon, rel=1e-6)
    positions = load(run, f"lod_{name}_positions")
    assert positions.shape == (expected.header.vertex_count, 3)
    np.testing.assert_allclose(positions, expected.positions, rtol=0, atol=2e-5)
    np.testing.assert_array_equal(load(run, f"lod_{name}_faces"), expected.indices)
    return shown


def test_imported_levels_have_the_levels_counts_and_positions(blender_run):
    client = blender_run["client"]
    # By index, with the armature at the "bake_first" keyframe (frame 1): posed there.
    _check_lod(blender_run, "level", client.get_lod(SKINNED_MODEL, level=LOD_LEVEL, pose=_G(*POSES["bake_first"])))
    budget = _check_lod(blender_run, "budget", client.get_lod(SKINNED_MODEL, max_vertices=MAX_VERTICES))
    assert np.allclose(budget["matrix_world"], np.eye(4))

    # By camera: eq. 7.2's view restated from the scene's camera, 50 mm lens on a 36 mm sensor
    # across a 960-px-wide (1920 at 50 %) landscape render, at the distance from the camera to the
    # centre of the model's rest bounding box (of its coarsest level).
    info = client.describe_model(SKINNED_MODEL).default
    coarsest = client.get_lod(SKINNED_MODEL, level=info.lod_level_count - 1).positions
    centre = 0.5 * (coarsest.min(axis=0) + coarsest.max(axis=0))
    distance = float(np.linalg.norm(np.array(VIEW["location"]) - centre))
    expected = client.get_lod(SKINNED_MODEL, tolerance_px=VIEW["tolerance_px"], distance=distance,
                              viewport_width_px=960, horizontal_fov_rad=2 * math.atan(36.0 / (2 * 50.0)))
    assert 0 < expected.header.level < info.lod_level_count - 1  # the view picks a level between the ends
    shown = _check_lod(blender_run, "view", expected)
    assert shown["tolerated_error"] == pytest.approx(expected.header.tolerated_error, rel=1e-4)


def _check_uv_map(run, name, expected):
    """The imported level ``name`` holds one UV map, "animspace atlas", whose loop at corner k of
    triangle f has the UV ``expected`` (the Python client's own GetLod with texture coordinates)
    sends for that corner: the same faces, corner for corner, float32 as sent."""
    shown = run["results"]["lods"][name]
    assert shown["level"] == expected.header.level and shown["uv_layers"] == ["animspace atlas"]
    assert "UV map 'animspace atlas'" in shown["report"]
    np.testing.assert_array_equal(load(run, f"lod_{name}_faces"), expected.indices.astype(np.int64))
    uvs = load(run, f"lod_{name}_uvs")
    assert uvs.shape == (expected.face_count, 3, 2)
    np.testing.assert_array_equal(uvs, expected.texture_coordinates)


def test_level_0_of_a_model_with_an_atlas_gets_its_uv_map(blender_run):
    results = blender_run["results"]
    # The demo's own arm has no atlas: no UV map, and the report says why.
    plain = results["lods"]["plain_level0"]
    assert plain["level"] == 0 and plain["uv_layers"] == []
    assert "no UV map: " in plain["report"] and "stores no texture atlas" in plain["report"]
    # The atlas'd copy: one UV map, one UV per loop, each triangle's loops its corners.
    with animspace.Client(blender_run["atlas_address"]) as client:
        _check_uv_map(blender_run, "atlas_level0", client.get_lod(SKINNED_MODEL, level=0, texture_coordinates=True))


def test_a_coarser_level_built_under_the_atlas_gets_its_uv_map(blender_run):
    client = blender_run["client"]
    levels = client.describe_model(LEVELS_MODEL).default.lod_level_count
    assert 0 < LEVELS_MODEL_LEVEL < levels - 1
    expected = client.get_lod(LEVELS_MODEL, level=LEVELS_MODEL_LEVEL, texture_coordinates=True)
    # A coarser level indeed: fewer faces than the full mesh.
    assert expected.face_count < client.get_lod(LEVELS_MODEL, level=0).face_count
    _check_uv_map(blender_run, "smooth_level", expected)
    np.testing.assert_allclose(load(blender_run, "lod_smooth_level_positions"), expected.positions, rtol=0, atol=2e-5)


def test_a_level_built_before_the_atlas_is_imported_without_uvs_and_the_report_says_so(blender_run):
    with animspace.Client(blender_run["atlas_address"]) as client:
        with pytest.raises(animspace.FailedPrecondition) as refused:
            client.get_lod(SKINNED_MODEL, level=LOD_LEVEL, texture_coordinates=True)
        expected = client.get_lod(SKINNED_MODEL, level=LOD_LEVEL)
    assert "include_texture_coordinates" in refused.value.message
    shown = _check_lod(blender_run, "atlas_stale_level", expected)
    assert shown["uv_layers"] == []
    reason = refused.value.message.split("include_texture_coordinates: ", 1)[1]
    assert f"no UV map: {reason}" in shown["report"] and "Traceback" not in shown["report"]


def test_the_thumbnail_is_the_servers_png_in_an_image_datablock(blender_run):
    results = blender_run["results"]
    assert results["thumbnail"] == {"size": list(THUMBNAIL), "packed": True}
    expected = blender_run["client"].render_thumbnail(SKINNED_MODEL, *THUMBNAIL)
    assert (blender_run["out"] / "thumbnail.png").read_bytes() == expected.png


def test_workbench_draws_the_workflows_headless(blender_run):
    import matplotlib.image

    picture = matplotlib.image.imread(blender_run["out"] / "workflows.png")
    assert picture.shape[:2] == (520, 1200)
    # Something was drawn: the verdict colours and the grey meshes are not one flat background.
    assert np.unique(picture.reshape(-1, picture.shape[2]), axis=0).shape[0] > 100


@pytest.mark.skipif(BLENDER is None, reason=NO_BLENDER)
def test_the_readmes_blender_snippet_runs(daemon, tmp_path):
    readme = (HERE.parents[1] / "README.md").read_text()
    section = readme[readme.index("### Use it from Blender"):]
    start = section.index("```python\n") + len("```python\n")
    snippet = section[start:section.index("\n```", start)]
    assert "127.0.0.1:50051" in snippet
    # The add-on as a user has it: installed from the zip and enabled; files the snippet writes
    # ("/tmp/…") go to the test's folder.
    prelude = (f"import bpy\nbpy.ops.preferences.addon_install(filepath={str(ZIP)!r})\n"
               "bpy.ops.preferences.addon_enable(module='animspace_blender')\n")
    script = tmp_path / "snippet.py"
    script.write_text(prelude + snippet.replace("127.0.0.1:50051", daemon).replace('"/tmp/', f'"{tmp_path}/')
                      .replace('"build/bin/animspace"', repr(str(BUILD / "bin" / "animspace"))))
    environment = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "user-scripts"),
                       BLENDER_USER_CONFIG=str(tmp_path / "user-config"), ANIMSPACE_BASIS_CACHE=str(tmp_path / "bases"))
    done = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script)],
                          capture_output=True, text=True, timeout=300, env=environment)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    with animspace.Client(daemon) as client:
        names = [m.name for m in client.list_models()]
    lines = done.stdout.splitlines()
    assert f"SERVING {names}" in lines
    assert any(line.split(" ")[0] in ("HIT", "BLEND", "MISS") for line in lines), lines
    assert "(256, 256)" in lines
    baked = animspace.read_pc2(tmp_path / "arm-pmsc.pc2")
    assert (baked.frame_count, baked.point_count) == (24, 1154)
    assert (tmp_path / "blender-repo" / "arm-from-blender" / "1" / "model.anim").is_file()
