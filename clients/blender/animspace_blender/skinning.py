"""Animation-space models in Blender (Merry 2007): the model as a mesh plus an armature built
from its skeleton, posed by the server (EvaluateSkeletonPose, v = Σ_j G_j p_j, §3.1) from the
armature's pose — on frame change, for the current frame, or baked over a range to PC2 — with
normals from the model's tangent planes (§3.5) when it stores them.

Bone j's skinning transform is G_j = D_j · Ĝ_j, where D_j = M_j · M̂_j⁻¹ is how far the Blender
bone moved from its rest (M̂_j = ``bone.matrix_local``, M_j = the evaluated ``pose_bone.matrix``,
both armature space) and Ĝ_j is the model's rest transform, kept on the bone. So the rest pose
gives G_j = Ĝ_j exactly — the rest mesh — whatever head, tail and roll Blender gave the bone, and
the mesh, parented to the armature without an offset, shares the armature's space, the model's.
"""
from typing import List, Optional

import bpy
import numpy as np

import animspace

from . import bake, connection, mesh_data, registry
from .connection import SetupError

POSES_PER_CALL = 64  # a bake's batch per EvaluateSkeletonPose, well under any server's max_batch_poses


def _tail(j: int, heads: np.ndarray, axes: np.ndarray, children: List[List[int]], length: float) -> np.ndarray:
    """Where bone j's tail goes: towards its children's joints, else along its own x axis (Blender
    drops a bone whose head and tail coincide)."""
    if children[j]:
        towards = heads[children[j]].mean(axis=0)
        if np.linalg.norm(towards - heads[j]) > 1e-3 * length:
            return towards
    axis = axes[j] / max(np.linalg.norm(axes[j]), 1e-30)
    return heads[j] + length * axis


def build(context, model: str) -> bpy.types.Object:
    """The model's level 0 (the model itself, its points in order) as a mesh object parented to a
    new armature object; returns the mesh object."""
    client = connection.client(context)
    described = client.describe_model(model)
    version = described.default
    if version is None:
        raise SetupError(f"Model: no version of '{model}' is loaded")
    level = client.get_lod(model, level=0, form="animation_space")
    skeleton = level.skeleton
    has_tangents = "animspace.tangents" in version.sections
    rest = client.evaluate_skeleton_pose(model, skeleton.rest_transforms, include_normals=has_tangents)

    mesh = mesh_data.new_mesh(model, rest.points, level.indices)
    mesh_data.set_normals(mesh, rest.normals)
    armature = bpy.data.armatures.new(f"{model} skeleton")
    rig = bpy.data.objects.new(f"{model} skeleton", armature)
    mesh_data.link(context, rig)
    skinned = bpy.data.objects.new(model, mesh)
    mesh_data.link(context, skinned)
    skinned.parent = rig

    # Bones are made in edit mode, which needs the armature active in the view layer.
    rest_transforms = skeleton.rest_transforms.astype(np.float64)  # B×3×4
    heads = rest_transforms[:, :, 3]
    axes = rest_transforms[:, :, 0]
    extent = np.ptp(rest.points, axis=0).max() if rest.points.size else 1.0
    length = 0.1 * float(extent) if extent > 0 else 1.0
    parents = skeleton.parents.tolist()
    children: List[List[int]] = [[] for _ in parents]
    for j, parent in enumerate(parents):
        if parent >= 0:
            children[parent].append(j)
    names = list(skeleton.bone_names) or [f"bone_{j}" for j in range(skeleton.bone_count)]
    previous_active = context.view_layer.objects.active
    context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        edit_bones = []
        for j in range(skeleton.bone_count):
            bone = armature.edit_bones.new(names[j])
            bone.head = heads[j]
            bone.tail = _tail(j, heads, axes, children, length)
            edit_bones.append(bone)
        for j, parent in enumerate(parents):
            if parent >= 0:
                edit_bones[j].parent = edit_bones[parent]
        made_names = [bone.name for bone in edit_bones]  # Blender may have renamed duplicates
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
        context.view_layer.objects.active = previous_active
    for j, name in enumerate(made_names):
        bone = armature.bones[name]
        bone.animspace.index = j
        bone.animspace.rest_transform = rest_transforms[j].ravel().tolist()

    skinned.animspace.role = "SKINNED"
    skinned.animspace.model = model
    skinned.animspace.model_version = rest.model_version
    skinned.animspace.armature = rig
    skinned.animspace.include_normals = has_tangents
    return skinned


def skeleton_pose(rig: bpy.types.Object, depsgraph) -> np.ndarray:
    """G_j of every model bone from the armature's evaluated pose, B×4×4 float64 (module doc)."""
    bones = [bone for bone in rig.data.bones if bone.animspace.index >= 0]
    count = len(bones)
    if sorted(bone.animspace.index for bone in bones) != list(range(count)):
        raise SetupError(f"Armature: '{rig.name}' does not hold the model's bones 0…{count - 1} (was it edited?)")
    evaluated = rig.evaluated_get(depsgraph)
    G = np.empty((count, 4, 4))
    for bone in bones:
        pose_bone = evaluated.pose.bones[bone.name]
        motion = np.array(pose_bone.matrix, dtype=np.float64) @ np.linalg.inv(np.array(bone.matrix_local,
                                                                                      dtype=np.float64))
        rest = np.vstack([np.asarray(bone.animspace.rest_transform, dtype=np.float64).reshape(3, 4),
                          [0.0, 0.0, 0.0, 1.0]])
        G[bone.animspace.index] = motion @ rest
    return G


def active_skinned(context, model: Optional[str] = None) -> Optional[bpy.types.Object]:
    """The active object when it is an animation-space mesh (of ``model``, when given), else None."""
    active = context.active_object
    if active is None or active.animspace.role != "SKINNED":
        return None
    if model is not None and active.animspace.model != model:
        return None
    return active


def armature_pose(context, obj: Optional[bpy.types.Object]) -> Optional[np.ndarray]:
    """``skeleton_pose`` of ``obj``'s armature as evaluated now; None without ``obj`` or armature."""
    if obj is None or obj.animspace.armature is None:
        return None
    return skeleton_pose(obj.animspace.armature, context.evaluated_depsgraph_get())


def _skinned(obj: Optional[bpy.types.Object]) -> bpy.types.Object:
    if obj is None or obj.type != "MESH" or obj.animspace.role != "SKINNED":
        raise SetupError("Select an animation-space mesh made by 'Build model'")
    if obj.animspace.armature is None:
        raise SetupError(f"'{obj.name}' has no armature to take its pose from")
    return obj


def pose(context, obj: bpy.types.Object, depsgraph) -> animspace.SkinnedPose:
    """Poses ``obj`` from its armature at the depsgraph's frame."""
    settings = obj.animspace
    G = skeleton_pose(settings.armature, depsgraph)
    result = connection.client(context).evaluate_skeleton_pose(settings.model, G,
                                                               include_normals=settings.include_normals)
    if result.points.shape[0] != len(obj.data.vertices):
        raise SetupError(f"'{obj.name}' has {len(obj.data.vertices)} vertices, model '{settings.model}' "
                         f"{result.points.shape[0]} points")
    mesh_data.set_positions(obj.data, result.points)
    mesh_data.set_normals(obj.data, result.normals)
    settings.model_version = result.model_version
    return result


class ANIMSPACE_OT_build_skinned(connection.ReportingOperator, bpy.types.Operator):
    """Build the model as a mesh plus an armature from its skeleton"""
    bl_idname = "animspace.build_skinned"
    bl_label = "Build model"

    def run(self, context):
        skinned = build(context, connection.chosen_model(context, "a model with a skeleton"))
        return (f"'{skinned.name}': {len(skinned.data.vertices)} vertices, "
                f"{len(skinned.animspace.armature.data.bones)} bones")


class ANIMSPACE_OT_pose_skinned(connection.ReportingOperator, bpy.types.Operator):
    """Pose the active animation-space mesh from its armature at this frame"""
    bl_idname = "animspace.pose_skinned"
    bl_label = "Pose from armature"

    def run(self, context):
        pose(context, _skinned(context.active_object), context.evaluated_depsgraph_get())
        return None


class ANIMSPACE_OT_bake_skinned(bake.range_bake("//skinned.pc2"), bpy.types.Operator):
    """Pose the active animation-space mesh at every frame of a range and bake the positions to PC2"""
    bl_idname = "animspace.bake_skinned"

    def run(self, context):
        scene = context.scene
        obj = _skinned(context.active_object)
        start, end, path = self.range_and_path(scene)
        poses = bake.step_frames(scene, start, end, ("skinning", "soft_cache"),
                                 lambda: armature_pose(context, obj))
        client = connection.client(context)
        points = []
        for first in range(0, len(poses), POSES_PER_CALL):
            batch = np.stack(poses[first:first + POSES_PER_CALL])
            points.extend(p.points for p in client.evaluate_skeleton_pose(obj.animspace.model, batch))
        bake.write_pc2(path, points, start)
        return f"{len(points)} frames → {path}"


def on_frame_change(scene) -> None:
    """Live skinning of every animation-space mesh in the scene (frame_change.py calls it)."""
    settings = scene.animspace
    if not settings.live_skinning:
        return
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in scene.objects:
        if obj.type != "MESH" or obj.animspace.role != "SKINNED" or obj.animspace.armature is None:
            continue
        connection.in_handler(scene, "skinning", lambda: pose(bpy.context, obj, depsgraph), prefix=f"{obj.name}: ")


_CLASSES = (ANIMSPACE_OT_build_skinned, ANIMSPACE_OT_pose_skinned, ANIMSPACE_OT_bake_skinned)

register, unregister = registry.for_classes(_CLASSES)
