"""What the two bakes to PC2 share: the operator's range and file settings, stepping the scene
through the range with the live updates the bake does itself suspended, and writing the file."""
from typing import Callable, List, Sequence, Tuple, TypeVar

import numpy as np
from bpy.props import IntProperty, StringProperty

import animspace

from . import connection, frame_change
from .connection import SetupError

T = TypeVar("T")


class _RangeBake(connection.ReportingOperator):
    bl_label = "Bake range to PC2"
    bl_options = {"REGISTER"}

    def range_and_path(self, scene) -> Tuple[int, int, str]:
        """(first frame, last frame, absolute PC2 path), checked."""
        start = scene.frame_start if self.frame_start < 0 else self.frame_start
        end = scene.frame_end if self.frame_end < 0 else self.frame_end
        if end < start:
            raise SetupError(f"End: {end} is before Start {start}")
        if not self.filepath.lower().endswith(".pc2"):
            raise SetupError(f"PC2 file: expected a .pc2 path, got '{self.filepath}'")
        return start, end, connection.file_path(self.filepath, "PC2 file")


def range_bake(default_file: str) -> type:
    """The mixin of a bake operator whose PC2 file defaults to ``default_file``: its settings (file,
    then range) and their checks."""

    class RangeBake(_RangeBake):
        filepath: StringProperty(name="PC2 file", subtype="FILE_PATH", default=default_file)
        frame_start: IntProperty(name="Start", default=-1, description="First frame (-1: the scene's)")
        frame_end: IntProperty(name="End", default=-1, description="Last frame, included (-1: the scene's)")

    return RangeBake


def step_frames(scene, start: int, end: int, suspend: Sequence[str], read: Callable[[], T]) -> List[T]:
    """``read()`` at each frame from ``start`` to ``end``, with ``suspend``'s live updates off; the
    scene returns to its current frame after."""
    read_frames = []
    was = scene.frame_current
    with frame_change.suspended(*suspend):
        try:
            for frame in range(start, end + 1):
                scene.frame_set(frame)
                read_frames.append(read())
        finally:
            scene.frame_set(was)
    return read_frames


def write_pc2(path: str, points: Sequence[np.ndarray], start: int) -> None:
    """One PC2 sample a frame from ``start``."""
    animspace.write_pc2(path, np.stack(points), start_frame=float(start), sample_rate=1.0)
