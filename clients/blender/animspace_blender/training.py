"""Train from animation: the active object's evaluated animation — whatever Blender plays, an
armature, shape keys, a Mesh Cache modifier, a Mesh Sequence Cache reading Alembic or USD — sent as
a sequence to the command line's offline trainers, `animspace fit` (an animation-space model by the
skinning decomposition, Merry 2007 §4.1) or `animspace train-pmsc` (a PMSC model, Meyer & Anderson
2007 §2), which write the next version of a model into a repository.

Why the command line and not an RPC: training is offline work on the user's machine (minutes, all
cores) and its result is a file in a repository, which a daemon serving that repository loads
(its --poll-interval-s, or LoadModel, which this operator calls when asked). The sequence goes as
the trainers' own input: a folder with reference.obj (the first frame's mesh, its polygons as
Blender has them) and frames.pc2 (every frame's evaluated positions, in the object's own space).
"""
import json
import os
import shutil
import subprocess
import tempfile
from typing import List

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty

from . import bake, connection, mesh_data, registry
from .connection import SetupError

TOOLS = [
    ("FIT", "fit", "An animation-space model: near-rigid parts, the skinning decomposition and the animation-space "
                   "refit (animspace fit)"),
    ("TRAIN_PMSC", "train-pmsc", "A PMSC model for soft-cache playback: subspace, key points, calibrated soft "
                                 "cache (animspace train-pmsc)"),
]


def write_sequence(folder: str, first: bpy.types.Mesh, frames: List[np.ndarray], start: int) -> None:
    """reference.obj (``first``'s polygons on the first frame's positions) and frames.pc2."""
    lines = ["# animspace: evaluated animation sent from Blender\n"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in frames[0]]
    for polygon in first.polygons:
        lines.append("f " + " ".join(str(v + 1) for v in polygon.vertices) + "\n")
    with open(os.path.join(folder, "reference.obj"), "w") as f:
        f.writelines(lines)
    bake.write_pc2(os.path.join(folder, "frames.pc2"), frames, start)


def run_trainer(command: List[str]) -> dict:
    """Runs the trainer with --json; its report, or a SetupError with the trainer's own message."""
    try:
        done = subprocess.run(command, capture_output=True, text=True)
    except OSError as error:
        raise SetupError(f"animspace command: cannot run '{command[0]}': {error.strerror or error} (give the path "
                         "of the animspace command line, build/bin/animspace)") from error
    if done.returncode != 0:
        message = done.stderr.strip().splitlines()
        raise SetupError(message[-1] if message else f"{command[1]} exited with {done.returncode}")
    return json.loads(done.stdout)


class ANIMSPACE_OT_train_from_animation(connection.ReportingOperator, bpy.types.Operator):
    """Send the active object's evaluated animation (armature, shape keys, Mesh Cache, Alembic or USD Mesh Sequence
    Cache) over a frame range to animspace fit or train-pmsc, which write the next version of a model into a
    repository"""
    bl_idname = "animspace.train_from_animation"
    bl_label = "Train from animation"
    bl_options = {"REGISTER"}

    tool: EnumProperty(name="Trainer", items=TOOLS, default="FIT")
    frame_start: IntProperty(name="Start", default=-1, description="First frame (-1: the scene's)")
    frame_end: IntProperty(name="End", default=-1, description="Last frame, included (-1: the scene's)")

    def run(self, context):
        scene, settings = context.scene, context.scene.animspace
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            raise SetupError("Train from animation: make the animated mesh the active object")
        model = settings.train_model.strip()
        if not model:
            raise SetupError("Model name: give the name the new model is written under")
        if not settings.train_repository.strip():
            raise SetupError("Repository: give the model repository folder (the daemon's --model-repository)")
        repository = connection.file_path(settings.train_repository, "Repository")
        start = scene.frame_start if self.frame_start < 0 else self.frame_start
        end = scene.frame_end if self.frame_end < 0 else self.frame_end
        if end - start + 1 < 3:
            raise SetupError(f"Frames {start}…{end}: a sequence needs at least 3 frames to train on")

        depsgraph = context.evaluated_depsgraph_get()
        # Live skinning stays on: a mesh the server poses from its armature is animated by it.
        frames = bake.step_frames(scene, start, end, ("soft_cache",),
                                  lambda: mesh_data.evaluated_positions(obj, depsgraph))
        for offset, points in enumerate(frames):
            if len(points) != len(frames[0]):
                raise SetupError(f"'{obj.name}' has {len(frames[0])} vertices at frame {start} and {len(points)} at "
                                 f"frame {start + offset}: a sequence keeps one topology")
        tool = "fit" if self.tool == "FIT" else "train-pmsc"
        command = [settings.train_command.strip() or "animspace", "--json", tool]
        if self.tool == "FIT":
            command += ["--bones", str(settings.train_bones)]
        elif settings.train_align:
            command.append("--align")
        kept = bool(settings.train_sequence_folder.strip())
        folder = (connection.file_path(settings.train_sequence_folder.strip(), "Sequence folder") if kept
                  else tempfile.mkdtemp(prefix="animspace-sequence-"))
        try:
            # The polygons (one topology over the range, checked above) of the mesh as evaluated now.
            evaluated = obj.evaluated_get(depsgraph)
            first = evaluated.to_mesh()
            try:
                if len(first.vertices) != len(frames[0]):
                    raise SetupError(f"'{obj.name}' has {len(first.vertices)} vertices at frame "
                                     f"{scene.frame_current} and {len(frames[0])} over frames {start}…{end}: go to "
                                     "a frame of the range")
                os.makedirs(folder, exist_ok=True)
                write_sequence(folder, first, frames, start)
            finally:
                evaluated.to_mesh_clear()
            report = run_trainer(command + [folder, "-o", repository, "--model", model])
        finally:
            if not kept:
                shutil.rmtree(folder, ignore_errors=True)
        message = f"{tool}: {len(frames)} frames of '{obj.name}' → {report['output']}"
        if settings.train_load:
            summary = connection.client(context).load_model(model)
            message += f"; the server serves version {summary.default_version}"
        return message


_CLASSES = (ANIMSPACE_OT_train_from_animation,)

register, unregister = registry.for_classes(_CLASSES)
