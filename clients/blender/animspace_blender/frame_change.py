"""The add-on's one frame-change handler. It poses the animation-space meshes first and runs the
soft cache after, so that a soft-cache source that is itself an animation-space mesh (or deforms
with one) is read at the new frame's pose, not the last one's. Handlers cannot report: each
workflow keeps its failure in ``scene.animspace.last_error`` for the panel."""
import contextlib

import bpy
from bpy.app.handlers import persistent

from . import skinning, soft_cache

WORKFLOWS = ("skinning", "soft_cache")
_suspended = set()


@contextlib.contextmanager
def suspended(*workflows):
    """Frames a bake steps through do not run these workflows' live updates (the bake does it)."""
    assert set(workflows) <= set(WORKFLOWS), workflows
    added = set(workflows) - _suspended
    _suspended.update(added)
    try:
        yield
    finally:
        _suspended.difference_update(added)


@persistent
def on_frame_change(scene, _depsgraph=None):
    if "skinning" not in _suspended:
        skinning.on_frame_change(scene)
    if "soft_cache" not in _suspended:
        soft_cache.on_frame_change(scene)


def register() -> None:
    bpy.app.handlers.frame_change_post.append(on_frame_change)


def unregister() -> None:
    if on_frame_change in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.remove(on_frame_change)
