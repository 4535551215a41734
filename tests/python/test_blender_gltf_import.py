"""Issue #39: every kind of glTF file animspace writes — a fitted rig with its armature and action,
a level of detail, a posed mesh — imports in Debian's Blender 3.4 once the add-on is enabled (its
importer calls ``np.bool``, which Debian's numpy no longer has). Headless Blender, files written
by the CLI; skipped when Blender is not installed."""
import json
import math
import os
import pathlib
import subprocess

import numpy as np
import pytest

import animspace
from conftest import BUILD, _arm_transforms
from test_blender_addon import BLENDER, NO_BLENDER, ZIP

CLI = BUILD / "bin" / "animspace"

# Inside Blender: enable the add-on from its zip, import each file into the scene, and record the
# objects each import made.
SCRIPT = r'''
import bpy, json, sys, traceback
config = json.loads(open(sys.argv[sys.argv.index("--") + 1]).read())
bpy.ops.preferences.addon_install(filepath=config["zip"])
bpy.ops.preferences.addon_enable(module="animspace_blender")
results = {}
for name, path in config["files"].items():
    before = set(bpy.data.objects.keys())
    actions_before = set(bpy.data.actions.keys())
    try:
        bpy.ops.import_scene.gltf(filepath=path)
    except Exception:
        results[name] = {"error": traceback.format_exc()[-2000:]}
        continue
    made = [bpy.data.objects[n] for n in sorted(set(bpy.data.objects.keys()) - before)]
    actions = [bpy.data.actions[n] for n in sorted(set(bpy.data.actions.keys()) - actions_before)]
    results[name] = {
        "meshes": [{"vertices": len(o.data.vertices), "faces": len(o.data.polygons),
                    "skinned": any(m.type == "ARMATURE" for m in o.modifiers),
                    "shape_keys": sorted(k.name for k in o.data.shape_keys.key_blocks) if o.data.shape_keys else []}
                   for o in made if o.type == "MESH"],
        "armatures": [len(o.data.bones) for o in made if o.type == "ARMATURE"],
        "names": sorted(o.name for o in made),
        "action_frames": [list(a.frame_range) for a in actions],
    }
open(config["out"], "w").write(json.dumps(results))
'''


def _tube(rings=12, segments=8):
    """A tube along x, bent at its middle by a rotation about z: two near-rigid parts."""
    x = np.linspace(0.0, 1.0, rings)
    angle = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    rest = np.array([[xi, 0.1 * math.cos(a), 0.1 * math.sin(a)] for xi in x for a in angle])
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            faces += [(a, b, b + segments), (a, b + segments, a + segments)]
    return rest, np.array(faces)


def _write_sequence(folder, frames=12):
    rest, faces = _tube()
    poses = []
    for f in range(frames):
        theta = 0.8 * f / (frames - 1)
        c, s = math.cos(theta), math.sin(theta)
        posed = rest.copy()
        far = rest[:, 0] > 0.5
        local = rest[far] - [0.5, 0.0, 0.0]
        posed[far] = local @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + [0.5, 0.0, 0.0]
        poses.append(posed)
    folder.mkdir()
    with open(folder / "reference.obj", "w") as obj:
        obj.writelines(f"v {p[0]} {p[1]} {p[2]}\n" for p in rest)
        obj.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    animspace.write_pc2(folder / "frames.pc2", np.stack(poses))
    return len(rest), len(faces), frames


def _run(*arguments):
    done = subprocess.run([str(CLI), *arguments], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.skipif(BLENDER is None, reason=NO_BLENDER)
def test_every_gltf_file_we_write_imports_in_blender(daemon, tmp_path):
    if not ZIP.is_file():
        pytest.fail(f"{ZIP} is missing: the build makes it (target animspace_blender_addon)")
    # A rig: fitted to a bending tube, with its frames as the animation.
    vertices, faces, frames = _write_sequence(tmp_path / "tube")
    _run("fit", str(tmp_path / "tube"), "--bones", "2", "--iterations", "5", "-o", str(tmp_path / "tube.anim"),
         "--export", str(tmp_path / "rig.glb"))
    # A level of detail and a posed mesh of the demo's animation-space arm.
    _run("demo-repository", str(tmp_path / "demo"))
    _run("export-lod", str(tmp_path / "demo" / "arm-animspace" / "1" / "model.anim"), "--level", "2",
         "-o", str(tmp_path / "lod.glb"))
    # An articulated model (issue #51): affine joints as shape and joint nodes, residual morph targets.
    _run("export-rig", str(tmp_path / "demo" / "arm-articulated" / "1" / "model.anim"), "-o",
         str(tmp_path / "articulated.glb"))
    with animspace.Client(daemon) as client:
        client.wait_until_serving(deadline_s=60)
        residual_components = client.describe_model("arm-articulated").default.residual_components
        level2 = client.get_lod("arm-animspace", level=2)
        arm = client.get_lod("arm-animspace", level=0)
    G = _arm_transforms(1.0)
    (tmp_path / "pose.txt").write_text("\n".join(" ".join(f"{v:.9g}" for v in bone[:3].ravel()) for bone in G) + "\n")
    _run("--server", daemon, "pose", "arm-animspace", "--pose-file", str(tmp_path / "pose.txt"), "--normals",
         "-o", str(tmp_path / "pose.glb"))

    config = {"zip": str(ZIP), "out": str(tmp_path / "imported.json"),
              "files": {name: str(tmp_path / f"{name}.glb") for name in ("rig", "lod", "pose", "articulated")}}
    (tmp_path / "config.json").write_text(json.dumps(config))
    (tmp_path / "import.py").write_text(SCRIPT)
    environment = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "user-scripts"),
                       BLENDER_USER_CONFIG=str(tmp_path / "user-config"))
    done = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                           str(tmp_path / "import.py"), "--", str(tmp_path / "config.json")],
                          capture_output=True, text=True, timeout=300, env=environment)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    results = json.loads((tmp_path / "imported.json").read_text())
    for name, result in results.items():
        assert "error" not in result, f"{name}.glb: {result['error']}"

    rig = results["rig"]
    assert rig["armatures"] == [3], "the fitted root and two bones"
    # Issue #55 item 13: the objects are named after the model (tube.anim), not "mesh" and "Armature".
    assert rig["names"] == ["tube", "tube rig"]
    assert len(rig["meshes"]) == 1 and rig["meshes"][0]["skinned"]
    assert rig["meshes"][0]["faces"] == faces
    assert rig["action_frames"] and max(end for _, end in rig["action_frames"]) >= frames - 1
    for name, expected in (("lod", level2), ("pose", arm)):
        meshes = results[name]["meshes"]
        assert len(meshes) == 1 and meshes[0]["faces"] == len(expected.indices), name
        assert meshes[0]["vertices"] == len(expected.positions), name
    articulated = results["articulated"]
    assert len(articulated["meshes"]) == 1 and articulated["meshes"][0]["skinned"], articulated
    assert articulated["meshes"][0]["vertices"] == 1154, articulated
    # Blender's importer names the shape keys after the targets, with its own "Basis" first.
    keys = articulated["meshes"][0]["shape_keys"]
    assert sorted(k for k in keys if k.startswith("residual_")) == sorted(
        f"residual_{k}" for k in range(residual_components)), keys
