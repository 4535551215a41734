"""Levels of detail (Merry 2007 ch. 6, §7.3) imported as new mesh objects (GetLod, posed form).

A level is chosen by index, by vertex budget, or by the active camera: the coarsest level whose
error ε^l projects under ``tolerance_px`` pixels (eq. 7.2, ε = 2·p·d·sin θ / w, evaluated by the
server). The view's quantities come from the scene: ``viewport_width_px`` is the render width
(resolution × percentage), ``horizontal_fov_rad`` the camera's horizontal angle for that
resolution and sensor fit, and ``distance`` runs from the camera to the model's centre. The
server measures distance to its bounding sphere's centre, which the API does not expose; the
add-on uses the centre of the model's rest bounding box (of its coarsest level, one cheap call),
which coincides with it for a symmetric model and is close otherwise.

When the active object is an animation-space mesh built by the add-on, the level is placed where
that mesh is and posed at its armature's pose; otherwise it is placed at the origin, at rest.

Every level of a model that stores a texture atlas (``animspace atlas``) arrives with it: the mesh
gets a UV map, "animspace atlas", one UV per loop (the server sends them per face corner, and
each triangle's three loops are its corners); a coarser level's are the UVs ``build-lod`` stored
with it (its faces keep their charts, Merry 2007 §5.1). A model without an atlas, or a level built
before it, is imported without one and the report says why (the server's FAILED_PRECONDITION
naming include_texture_coordinates).
"""
import math
from typing import Optional, Tuple

import bpy
import numpy as np

import animspace

from . import connection, mesh_data, registry, skinning
from .connection import SetupError

# The UV map a level of a model with a texture atlas gets.
ATLAS_UV_MAP = "animspace atlas"


def view_of(scene: bpy.types.Scene, camera: Optional[bpy.types.Object]) -> Tuple[int, float]:
    """(viewport_width_px, horizontal_fov_rad) of ``camera`` rendering ``scene``."""
    if camera is None or camera.type != "CAMERA":
        raise SetupError("Camera: the scene has no active camera")
    data = camera.data
    if data.type != "PERSP":
        raise SetupError(f"Camera: '{camera.name}' is {data.type.lower()}; eq. 7.2 needs a perspective camera")
    render = scene.render
    width_px = max(1, round(render.resolution_x * render.resolution_percentage / 100))
    height_px = max(1, round(render.resolution_y * render.resolution_percentage / 100))
    aspect = (width_px * render.pixel_aspect_x) / (height_px * render.pixel_aspect_y)
    fit = data.sensor_fit
    if fit == "AUTO":  # the sensor width spans the image's larger side
        fit, sensor_mm = ("HORIZONTAL", data.sensor_width) if aspect >= 1 else ("VERTICAL", data.sensor_width)
    else:
        sensor_mm = data.sensor_width if fit == "HORIZONTAL" else data.sensor_height
    half_angle = math.atan(sensor_mm / (2.0 * data.lens))
    if fit == "VERTICAL":
        half_angle = math.atan(math.tan(half_angle) * aspect)
    return width_px, 2.0 * half_angle


def camera_distance(client: animspace.Client, model: str, camera: bpy.types.Object,
                    placement: Optional[bpy.types.Object]) -> float:
    """Camera to the model's rest bounding-box centre, model units (the module doc says why)."""
    version = client.describe_model(model).default
    if version is None:
        raise SetupError(f"Model: no version of '{model}' is loaded")
    # A PMSC model serving its engine's levels lists none of its own: its level 0 is then used.
    mesh = client.get_lod(model, level=max(version.lod_level_count - 1, 0))
    centre = 0.5 * (mesh.positions.min(axis=0) + mesh.positions.max(axis=0)).astype(np.float64)
    eye = np.array(camera.matrix_world.translation, dtype=np.float64)
    if placement is not None:  # into the model's space: the placement may move or scale it
        to_model = np.linalg.inv(np.array(placement.matrix_world, dtype=np.float64))
        eye = (to_model @ np.append(eye, 1.0))[:3]
    return float(np.linalg.norm(eye - centre))


def fetch_level(client: animspace.Client, model: str, pose, selection: dict) -> Tuple[animspace.LodMesh, Optional[str]]:
    """The level ``selection`` chooses, posed at ``pose``, with its atlas UVs (``texture_coordinates``,
    F×3×2) where the server has them; and, when it has none, the server's reason (else None).
    UVs are asked for first, so a level with them costs one call; a refusal comes before any
    block is sent, and the second call chooses the same level (the selection is deterministic)."""
    try:
        return client.get_lod(model, pose=pose, texture_coordinates=True, **selection), None
    except animspace.FailedPrecondition as error:
        # A model without an atlas, or a level built before it; other refusals stay errors.
        if "include_texture_coordinates" not in error.message:
            raise
        reason = error.message.split("include_texture_coordinates: ", 1)[-1]
    return client.get_lod(model, pose=pose, **selection), reason


class ANIMSPACE_OT_import_lod(connection.ReportingOperator, bpy.types.Operator):
    """Import one level of detail of the model as a new mesh object"""
    bl_idname = "animspace.import_lod"
    bl_label = "Import level"

    def run(self, context):
        scene = context.scene
        settings = scene.animspace
        model = connection.chosen_model(context, "a model with levels")
        client = connection.client(context)
        placement = skinning.active_skinned(context)
        pose = skinning.armature_pose(context, placement)
        selection = {}
        if settings.lod_selection == "LEVEL":
            selection["level"] = settings.lod_level
        elif settings.lod_selection == "BUDGET":
            selection["max_vertices"] = settings.max_vertices
        else:
            width_px, fov_rad = view_of(scene, scene.camera)
            selection.update(tolerance_px=settings.tolerance_px, viewport_width_px=width_px,
                             horizontal_fov_rad=fov_rad,
                             distance=camera_distance(client, model, scene.camera, placement))
        level, no_uvs = fetch_level(client, model, pose, selection)
        header = level.header
        uvs = level.texture_coordinates
        mesh = mesh_data.new_mesh(f"{model} LOD {header.level}", level.positions, level.indices)
        if uvs is not None:
            layer = mesh.uv_layers.new(name=ATLAS_UV_MAP)
            layer.data.foreach_set("uv", np.ascontiguousarray(uvs, dtype=np.float32).ravel())
        obj = bpy.data.objects.new(f"{model} LOD {header.level}", mesh)
        if placement is not None:
            obj.matrix_world = placement.matrix_world
        mesh_data.link(context, obj)
        obj.animspace.role = "LOD"
        obj.animspace.model = model
        obj.animspace.model_version = header.model_version
        obj.animspace.lod_level = header.level
        obj.animspace.epsilon = header.epsilon
        obj.animspace.tolerated_error = header.tolerated_error
        view = (f", tolerated error {header.tolerated_error:.6g} at distance {selection['distance']:.6g}"
                if "distance" in selection else "")
        atlas = f", UV map '{ATLAS_UV_MAP}'" if uvs is not None else f", no UV map: {no_uvs}"
        return (f"level {header.level} of {header.level_count}: {header.vertex_count} vertices, "
                f"{header.face_count} faces, ε^l {header.epsilon:.6g}{view}{atlas}")


_CLASSES = (ANIMSPACE_OT_import_lod,)

register, unregister = registry.for_classes(_CLASSES)
