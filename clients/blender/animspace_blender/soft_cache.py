"""Soft-cache playback of a PMSC model (Meyer & Anderson 2006 §5, 2007 §2).

The source is a mesh whose vertices are the model's points in order (typically a sequence brought
in with a Mesh Cache modifier reading a PC2 file). For a frame, the source's evaluated key points
— K of its N vertices, ``describe_key_points`` order — and its check points (issue #35: C more
vertices the server checks the estimate at) go to the server (EvaluateKeyPoints; a range goes
over one StreamKeyPoints call) and the whole answered pose is written into the output object, its
vertices coloured by the verdict (HIT / BLEND / MISS, attribute ``animspace_verdict``) and e_key,
e_check and α shown in the panel. With "Answers as coordinates" (the default) an answer the client
can rebuild comes as its M subspace coordinates and the Python client rebuilds the points with the
model's basis, fetched once and kept in its cache on disk (issue #36): a 100k-point pose then costs
a few hundred bytes on the wire instead of 1.2 MB. On a BLEND or MISS the evaluated full mesh can be sent back
(CompleteMiss): the answer is then α·full + (1−α)·estimate, and the server logs the pose for the
next retrain ("train each night, better tomorrow").
"""
from typing import Dict, List, Optional, Tuple

import bpy
import numpy as np

import animspace

from . import bake, connection, mesh_data, registry
from .connection import SetupError

# describe_key_points per (client, model): a frame-change handler must not ask every frame. The
# answer pins its model_version, so the indices stay those of the version that answers.
_key_points: Dict[Tuple[int, str], animspace.KeyPoints] = {}


def _keys(client: animspace.Client, model: str) -> animspace.KeyPoints:
    key = (id(client), model)
    if key not in _key_points:
        _key_points[key] = client.describe_key_points(model)
    return _key_points[key]


def forget_key_points() -> None:
    _key_points.clear()


def _checked_setup(context) -> Tuple[bpy.types.Object, str]:
    settings = context.scene.animspace
    source = settings.source
    if source is None or source.type != "MESH":
        raise SetupError("Source: choose the mesh whose vertices are the model's points")
    return source, connection.chosen_model(context, prop="pmsc_model", label="PMSC model")


def _full_pose(source: bpy.types.Object, depsgraph, keys: animspace.KeyPoints) -> np.ndarray:
    full = mesh_data.evaluated_positions(source, depsgraph)
    if full.shape[0] != keys.control_point_count:
        raise SetupError(f"Source: '{source.name}' has {full.shape[0]} vertices at this frame, the model's "
                         f"key points index {keys.control_point_count} points")
    if keys.channel_count != 3:
        raise SetupError(f"PMSC model: its points have {keys.channel_count} channels, not positions (3)")
    return full


def _output(context, source: bpy.types.Object, model: str) -> bpy.types.Object:
    """The output object: the scene's choice, else a copy of the source's mesh (same topology,
    no modifiers) placed where the source is."""
    settings = context.scene.animspace
    output = settings.output
    if output is None:
        output = bpy.data.objects.new(f"{source.name} ({model})", source.data.copy())
        output.matrix_world = source.matrix_world
        mesh_data.link(context, output)
        settings.output = output
    if output == source:
        raise SetupError("Output: choose another object than the source (the answer would feed back into it)")
    output.animspace.role = "SOFT_CACHE_OUTPUT"
    output.animspace.model = model
    return output


def _answers(context) -> Dict[str, object]:
    """The answer encoding keywords of the client's calls, as the scene asks."""
    if context.scene.animspace.answers_as_coordinates:
        return {"points_encoding": "coordinates", "reconstruct": True}
    return {}


def _show(context, output: bpy.types.Object, result: animspace.PoseResult, logged: bool) -> None:
    if result.points is None or result.points.shape != (len(output.data.vertices), 3):
        raise SetupError(f"Output: '{output.name}' has {len(output.data.vertices)} vertices, the answer "
                         f"{0 if result.points is None else result.points.shape[0]} points")
    mesh_data.set_positions(output.data, result.points)
    mesh_data.set_verdict(output.data, result.status)
    output.animspace.model_version = result.model_version
    settings = context.scene.animspace
    settings.status = result.status
    settings.key_point_error = result.key_point_error
    settings.check_point_error = result.check_point_error
    settings.checked = result.checked
    settings.blend_weight = result.blend_weight
    settings.logged = logged


def evaluate_frame(context, depsgraph) -> animspace.PoseResult:
    """The current frame of the source through the soft cache, written into the output."""
    source, model = _checked_setup(context)
    client = connection.client(context)
    keys = _keys(client, model)
    full = _full_pose(source, depsgraph, keys)
    pose = keys.pose(full)  # the key values and the check values: a HIT the check points overturn is none
    result = client.evaluate_key_points(model, pose.key_values, check_values=pose.check_values,
                                        version=keys.model_version, **_answers(context))
    logged = False
    if result.full_evaluation_needed and context.scene.animspace.complete_misses:
        completion = client.complete_miss(model, pose.key_values, full, check_values=pose.check_values,
                                          version=result.model_version, **_answers(context))
        result, logged = completion.result, completion.logged
    _show(context, _output(context, source, model), result, logged)
    return result


class ANIMSPACE_OT_soft_cache_frame(connection.ReportingOperator, bpy.types.Operator):
    """Send the source's key points at this frame through the soft cache and write the answer into the output"""
    bl_idname = "animspace.soft_cache_frame"
    bl_label = "Evaluate frame"

    def run(self, context):
        try:
            result = evaluate_frame(context, context.evaluated_depsgraph_get())
        except (animspace.RpcError, animspace.BasisMismatch):
            forget_key_points()  # a retrain or reload may have changed them: ask again next time
            raise
        check = f", e_check {result.check_point_error:.6g}" if result.checked else ""
        return f"{result.status}: e_key {result.key_point_error:.6g}{check}, α {result.blend_weight:.4g}"


class ANIMSPACE_OT_soft_cache_bake(bake.range_bake("//soft_cache.pc2"), bpy.types.Operator):
    """Play a frame range through the soft cache (one stream) and bake the answers to a PC2 point cache"""
    bl_idname = "animspace.soft_cache_bake"

    def run(self, context):
        scene = context.scene
        settings = scene.animspace
        source, model = _checked_setup(context)
        start, end, path = self.range_and_path(scene)
        client = connection.client(context)
        forget_key_points()
        keys = _keys(client, model)

        # Blender's data is read on this thread only; the stream then sends what was collected.
        def read() -> Tuple[animspace.KeyPointPose, Optional[np.ndarray]]:
            full = _full_pose(source, context.evaluated_depsgraph_get(), keys)
            return keys.pose(full), (full if settings.complete_misses else None)

        # Live skinning keeps running: the source may be an animation-space mesh it poses.
        frames = bake.step_frames(scene, start, end, ("soft_cache",), read)
        poses: List[animspace.KeyPointPose] = [pose for pose, _ in frames]
        full_frames: List[Optional[np.ndarray]] = [full for _, full in frames]

        # The deadline bounds the whole stream: the per-call deadline, plus 50 ms a frame.
        results = list(client.stream_key_points(model, poses, version=keys.model_version,
                                                deadline_s=settings.deadline_s + 0.05 * len(poses),
                                                **_answers(context)))
        points = []
        logged = 0
        for pose, full, result in zip(poses, full_frames, results):
            if result.full_evaluation_needed and full is not None:
                completion = client.complete_miss(model, pose.key_values, full, check_values=pose.check_values,
                                                  version=result.model_version, **_answers(context))
                result = completion.result
                logged += completion.logged
            points.append(result.points)
        bake.write_pc2(path, points, start)
        counts = {status: sum(r.status == status for r in results) for status in ("HIT", "BLEND", "MISS")}
        return (f"{len(results)} frames → {path}: {counts['HIT']} hits, {counts['BLEND']} blends, "
                f"{counts['MISS']} misses" + (f", {logged} logged" if settings.complete_misses else ""))


def on_frame_change(scene) -> None:
    """Live playback (frame_change.py calls it after live skinning)."""
    settings = scene.animspace
    if not settings.live_soft_cache:
        return
    # Asked now rather than taken from the handler: live skinning may just have moved the source.
    connection.in_handler(scene, "soft cache",
                          lambda: evaluate_frame(bpy.context, bpy.context.evaluated_depsgraph_get()),
                          on_error=forget_key_points)


_CLASSES = (ANIMSPACE_OT_soft_cache_frame, ANIMSPACE_OT_soft_cache_bake)


def register() -> None:
    registry.register_classes(_CLASSES)
    connection.reset_hooks.append(forget_key_points)


def unregister() -> None:
    if forget_key_points in connection.reset_hooks:
        connection.reset_hooks.remove(forget_key_points)
    registry.unregister_classes(_CLASSES)
    forget_key_points()
