"""animspace for Blender: an animspaced client in the 3D viewport's sidebar (N-panel, "animspace").

Workflows (Meyer & Anderson 2006, 2007; Merry 2007), each one operator plus an optional
frame-change handler:
- soft-cache playback of a PMSC model (``soft_cache.py``): the key points of an evaluated mesh in,
  the whole pose out, coloured by verdict, misses completed and logged for retraining, a range
  baked to PC2;
- animation-space models (``skinning.py``): the model as a mesh plus an armature, posed by the
  server from the armature's pose;
- levels of detail (``lod_import.py``) by index, vertex budget or eq. 7.2 from the active camera;
- thumbnails (``thumbnail.py``) into an image datablock;
- training from animation (``training.py``): the active object's evaluated animation (Alembic and
  USD caches included) sent to the command line's ``fit`` or ``train-pmsc``.

Every RPC goes through the project's Python client, ``animspace``, which this add-on carries in
``vendor/`` (see ``_use_vendored_client``).
"""

bl_info = {
    "name": "animspace",
    "author": "animspace",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > animspace",
    "description": "Soft-cache playback, animation-space skinning, levels of detail and thumbnails from animspaced",
    "category": "Animation",
}

import os
import sys

_VENDOR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "vendor")


def _use_vendored_client() -> None:
    """Puts the bundled client first on sys.path.

    Why bundled: Blender runs its own interpreter (Debian's: /usr/bin/python3's 3.11 with the
    system python3-grpcio, python3-protobuf and python3-numpy), which sees no virtual environment
    and ignores PYTHONPATH; a client built from the same tree as the add-on also speaks exactly its
    protocol. Why on sys.path rather than as a subpackage: the client and its generated stubs
    import ``animspace`` and ``animspace.v1`` by absolute name, so they must be importable as the
    top-level ``animspace``. First on the path, so that an older ``animspace`` installed elsewhere
    does not shadow the copy the add-on was built with.
    """
    if _VENDOR not in sys.path:
        sys.path.insert(0, _VENDOR)


_use_vendored_client()

from . import (connection, frame_change, lod_import, panel, properties, skinning, soft_cache, thumbnail,  # noqa: E402
               training)

_MODULES = (properties, connection, soft_cache, skinning, frame_change, lod_import, thumbnail, training, panel)


def _let_gltf_import_run_on_this_numpy() -> None:
    """Blender 3.4's own glTF importer (io_scene_gltf2) calls ``np.bool``, an alias numpy 1.24
    removed; with Debian 12's numpy every .glb import — ours (rigs, levels of detail, poses) and
    anyone's — fails in ``set_poly_smoothing``. Restores the alias to what it always meant, the
    builtin ``bool``, and only where it is missing, so a Blender or numpy that has it (or a fixed
    importer) is left as it is. Kept for the session: the importer may run after the add-on is
    disabled, and the alias changes no numpy behaviour."""
    import numpy

    if "bool" not in vars(numpy):
        numpy.bool = bool


def register() -> None:
    _let_gltf_import_run_on_this_numpy()
    for module in _MODULES:
        module.register()


def unregister() -> None:
    for module in reversed(_MODULES):
        module.unregister()
    connection.close_clients()
