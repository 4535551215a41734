"""A thumbnail drawn by the daemon's render thread (RenderThumbnail) into an image datablock,
packed into the .blend. With an animation-space mesh active, it is drawn at its armature's pose."""
import os
import tempfile

import bpy

from . import connection, registry, skinning


def image_from_png(name: str, png: bytes) -> bpy.types.Image:
    """An image datablock holding ``png``, packed (Blender 3.4 loads images from files only, so
    the bytes pass through a temporary file that is removed once packed). An image of the same
    name is replaced."""
    old = bpy.data.images.get(name)
    if old is not None:
        bpy.data.images.remove(old)
    handle, path = tempfile.mkstemp(suffix=".png", prefix="animspace-")
    try:
        with os.fdopen(handle, "wb") as out:
            out.write(png)
        image = bpy.data.images.load(path)
        image.pack()
    finally:
        os.remove(path)
    image.name = name
    return image


class ANIMSPACE_OT_thumbnail(connection.ReportingOperator, bpy.types.Operator):
    """Render a thumbnail of the model on the server into an image datablock"""
    bl_idname = "animspace.thumbnail"
    bl_label = "Thumbnail"

    def run(self, context):
        settings = context.scene.animspace
        model = connection.chosen_model(context)
        pose = skinning.armature_pose(context, skinning.active_skinned(context, model))
        drawn = connection.client(context).render_thumbnail(model, settings.width_px, settings.height_px,
                                                            skeleton_pose=pose,
                                                            show_wireframe=settings.show_wireframe)
        image = image_from_png(f"{model} thumbnail", drawn.png)
        return (f"'{image.name}': {drawn.width_px}×{drawn.height_px}, model version "
                f"{drawn.model_version}, {drawn.render_ms:.1f} ms")


_CLASSES = (ANIMSPACE_OT_thumbnail,)

register, unregister = registry.for_classes(_CLASSES)
