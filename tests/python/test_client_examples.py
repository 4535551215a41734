"""The examples in clients/python/examples, run as a user would (subprocesses), and the PC2 module."""
import json
import os
import pathlib
import struct
import subprocess
import sys

import numpy as np
import pytest

import animspace

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "clients" / "python" / "examples"
SHARED_DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"


def run_example(name, *arguments):
    # The same interpreter and import path as the tests: the package under test, not another.
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    done = subprocess.run([sys.executable, str(EXAMPLES / name), *arguments], capture_output=True, text=True,
                          timeout=120, env=environment)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_pc2_round_trip_and_refusals(tmp_path):
    frames = np.random.default_rng(7).normal(size=(5, 11, 3))
    path = tmp_path / "frames.pc2"
    animspace.write_pc2(path, frames, start_frame=12.0, sample_rate=0.5)
    raw = path.read_bytes()
    # The header, decoded here by hand from the format's definition.
    assert raw[:12] == b"POINTCACHE2\0"
    assert struct.unpack("<iiffi", raw[12:32]) == (1, 11, 12.0, 0.5, 5)
    assert len(raw) == 32 + 5 * 11 * 12
    cache = animspace.read_pc2(path)
    assert (cache.frame_count, cache.point_count, cache.start_frame, cache.sample_rate) == (5, 11, 12.0, 0.5)
    assert cache.frames.dtype == np.float32
    np.testing.assert_array_equal(cache.frames, frames.astype(np.float32))

    (tmp_path / "short.pc2").write_bytes(raw[:-4])
    with pytest.raises(ValueError, match="5 samples of 11 points need 692 bytes, the file has 688"):
        animspace.read_pc2(tmp_path / "short.pc2")
    (tmp_path / "magic.pc2").write_bytes(b"POINTCACHE3\0" + raw[12:])
    with pytest.raises(ValueError, match="not a PC2 file"):
        animspace.read_pc2(tmp_path / "magic.pc2")
    with pytest.raises(ValueError, match=r"frames: expected shape \(F, N, 3\), got \(5, 11\)"):
        animspace.write_pc2(tmp_path / "bad.pc2", np.zeros((5, 11)))


def test_replay_pc2_reports_every_frame_of_a_bending_arm(client, daemon, demo_arm_transforms, arm_transforms,
                                                         tmp_path):
    # The arm at the demo's unseen (odd) frames and at elbow bends beyond the demo's, posed by
    # arm-animspace (the posing engine arm-pmsc-engine's soft cache was trained on), as a PC2.
    transforms = [demo_arm_transforms(f / 120) for f in range(1, 120, 6)] + [arm_transforms(e) for e in (0.6, 1.2, 3.0)]
    frames = np.stack([client.evaluate_skeleton_pose("arm-animspace", G).points for G in transforms])
    path = tmp_path / "arm.pc2"
    animspace.write_pc2(path, frames)

    report = json.loads(run_example("replay_pc2.py", str(path), "--model", "arm-pmsc-engine", "--server", daemon,
                                    "--json"))
    assert report["frames"] == len(frames) and report["hit"] + report["blend"] + report["miss"] == len(frames)
    # The same key points (and check points) through unary calls give the same verdicts.
    keys = client.describe_key_points("arm-pmsc-engine")
    unary = client.evaluate_key_points("arm-pmsc-engine", frames[:, keys.indices],
                                       check_values=frames[:, keys.check_point_indices])
    assert all(r.checked for r in unary)
    for status in ("HIT", "BLEND", "MISS"):
        assert report[status.lower()] == sum(r.status == status for r in unary)
    assert report["hit"] > 0 and report["miss"] > 0
    assert report["hit_rate"] == pytest.approx(report["hit"] / len(frames))
    assert report["max_key_point_error"] == pytest.approx(max(r.key_point_error for r in unary), rel=1e-6)

    selected = json.loads(run_example("replay_pc2.py", str(path), "--model", "arm-pmsc-engine", "--server", daemon,
                                      "--json", "--select", "1::2"))
    assert selected["frames"] == len(frames[1::2])
    text = run_example("replay_pc2.py", str(path), "--model", "arm-pmsc-engine", "--server", daemon)
    assert f"{len(frames)} frames, {keys.count} key points" in text and "hit" in text and "miss" in text


def test_replay_pc2_refuses_a_cache_of_another_mesh(daemon, tmp_path):
    animspace.write_pc2(tmp_path / "other.pc2", np.zeros((2, 10, 3)))
    done = subprocess.run([sys.executable, str(EXAMPLES / "replay_pc2.py"), str(tmp_path / "other.pc2"), "--model",
                           "arm-pmsc", "--server", daemon], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p)))
    assert done.returncode == 2 and "has 10 points per frame" in done.stderr and "expects 1154" in done.stderr


@pytest.mark.skipif(not (SHARED_DATA / "crane" / "frames.pc2").exists(),
                    reason="needs ../shared/data/crane (reference data), absent here")
def test_the_crane_cache_reads(tmp_path):
    # Reference data from a DCC tool: the reader takes it whole. (No demo model was trained on
    # crane, so replaying it needs `animspace train-pmsc` first; the C++ tests cover that.)
    cache = animspace.read_pc2(SHARED_DATA / "crane" / "frames.pc2")
    assert cache.frame_count > 0 and cache.point_count > 0 and np.isfinite(cache.frames).all()


def read_obj(path):
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:]])
        elif line.startswith("f "):
            faces.append([int(x) for x in line.split()[1:]])
    return np.array(vertices), np.array(faces)


def test_lod_to_obj_writes_the_level_the_budget_allows(client, daemon, tmp_path):
    out = tmp_path / "arm-300.obj"
    report = json.loads(run_example("lod_to_obj.py", "arm-animspace", "-o", str(out), "--max-vertices", "300",
                                    "--server", daemon, "--json"))
    levels = [client.get_lod("arm-animspace", level=level) for level in range(report["level_count"])]
    finest_fitting = next(level for level, mesh in enumerate(levels) if mesh.vertex_count <= 300)
    assert report["level"] == finest_fitting
    mesh = levels[finest_fitting]
    vertices, faces = read_obj(out)
    assert vertices.shape == (mesh.vertex_count, 3) and faces.shape == (mesh.face_count, 3)
    assert (report["vertices"], report["faces"]) == (mesh.vertex_count, mesh.face_count)
    assert faces.min() >= 1 and faces.max() <= mesh.vertex_count  # OBJ counts from 1
    np.testing.assert_array_equal(faces - 1, mesh.indices)
    np.testing.assert_array_equal(vertices.astype(np.float32), mesh.positions)  # %.9g round-trips float32

    by_view = json.loads(run_example("lod_to_obj.py", "arm-animspace", "-o", str(tmp_path / "view.obj"),
                                     "--tolerance-px", "1.5", "--distance", "40", "--server", daemon, "--json"))
    assert by_view["epsilon"] <= by_view["tolerated_error"]
    text = run_example("lod_to_obj.py", "arm-animspace", "-o", str(tmp_path / "l2.obj"), "--level", "2",
                       "--server", daemon)
    assert f"level 2 of {report['level_count']}" in text and f"{levels[2].vertex_count} vertices" in text


def test_save_thumbnail_writes_a_png_of_the_requested_size(daemon, tmp_path):
    out = tmp_path / "arm.png"
    report = json.loads(run_example("save_thumbnail.py", "arm-animspace", "-o", str(out), "--width", "96",
                                    "--height", "64", "--wireframe", "--server", daemon, "--json"))
    png = out.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[12:16] == b"IHDR"
    assert struct.unpack(">II", png[16:24]) == (96, 64)
    assert (report["width_px"], report["height_px"], report["bytes"]) == (96, 64, len(png))
    text = run_example("save_thumbnail.py", "arm", "-o", str(tmp_path / "frame.png"), "--frame", "30",
                       "--server", daemon)
    assert "arm v1: 256×256" in text


@pytest.mark.parametrize("readme", ["clients/python/README.md", "README.md"])
def test_the_readmes_query_it_from_python_snippet_runs(readme, daemon, tmp_path):
    tour = readme == "README.md"
    readme = (EXAMPLES.parents[2] / readme).read_text()
    section = readme[readme.index("## Query it from Python"):]
    start = section.index("```python\n") + len("```python\n")
    snippet = section[start:section.index("\n```", start)]
    assert "127.0.0.1:50051" in snippet
    script = tmp_path / "snippet.py"
    # Every file the snippet writes ("/tmp/…", f"/tmp/…") goes to the test's folder.
    script.write_text(snippet.replace("127.0.0.1:50051", daemon).replace('"/tmp/', f'"{tmp_path}/'))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p),
                                   ANIMSPACE_BASIS_CACHE=str(tmp_path / "bases")))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "arm MESH_SEQUENCE 1154 points"
    cornell = next(i for i, line in enumerate(lines) if line.startswith("cornell PMSC "))  # the last model listed
    assert lines[cornell + 1].startswith("HIT ")
    # Check points overturn the dent's HIT (issue #35).
    assert any(line.startswith("dent: HIT from the key points alone, ") and
               (" MISS with e_check " in line or " BLEND with e_check " in line) for line in lines), lines
    assert any(line.split(" ")[:2] in (["cornell", "HIT"], ["cornell", "BLEND"], ["cornell", "MISS"])
               for line in lines), lines
    assert lines[-1].startswith("NOT_FOUND model 'no-such-model' is not loaded; models: arm, arm-animspace, ")
    if tour:
        # Answers as coordinates (issue #36): p reconstructed into every point, the basis cached.
        assert any(line.endswith("coordinates -> (1154, 3)") for line in lines), lines
        assert list((tmp_path / "bases" / "arm-pmsc-engine").glob("1-*.basis")), "no basis cached"
        # Issue #51: the articulated arm names its kind, and its p is 12 per bone + the residuals.
        line = next(line for line in lines if line.startswith("arm-articulated ARTICULATED "))
        words = line.split()
        bones, residuals, sent = int(words[2]), int(words[5]), int(words[-2])
        assert sent == 12 * bones + residuals and bones >= 1, line
    assert (tmp_path / "arm.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "cornell-3.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
