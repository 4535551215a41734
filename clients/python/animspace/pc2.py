"""PC2 point caches (Blender, Maya, 3ds Max "POINTCACHE2"), read and written with numpy.

A PC2 file is a 32-byte little-endian header — ``char[12] "POINTCACHE2\\0"``, int32 version (1),
int32 numPoints, float32 startFrame, float32 sampleRate, int32 numSamples — followed by
numSamples × numPoints × 3 float32. It is the usual way to hand a posed sequence from a DCC tool
to PMSC: the key points of each frame drive the soft cache (``examples/replay_pc2.py``).
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from typing import Union

import numpy as np
import numpy.typing as npt

from animspace.display import compact_repr

__all__ = ["PointCache", "read_pc2", "write_pc2"]

MAGIC = b"POINTCACHE2\0"
VERSION = 1
_HEADER = struct.Struct("<12siiffi")

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True, eq=False)
class PointCache:
    """A point cache: ``frames`` F×N×3 float32 in the cache's units.

    PC2's sampleRate is the step between samples, in frames: sample f lies at frame
    ``start_frame + f · sample_rate``.
    """

    __repr__ = compact_repr

    frames: np.ndarray
    start_frame: float = 0.0
    sample_rate: float = 1.0

    @property
    def frame_count(self) -> int:
        return int(self.frames.shape[0])

    @property
    def point_count(self) -> int:
        return int(self.frames.shape[1])


def read_pc2(path: PathLike) -> PointCache:
    """Reads a PC2 file.

    Raises:
        ValueError: for a wrong magic or version, negative counts, or a file whose size is not
            exactly the header plus numSamples·numPoints·12 bytes (a truncated cache is an error,
            never a shorter sequence).
    """
    with open(path, "rb") as file:
        header = file.read(_HEADER.size)
        if len(header) != _HEADER.size:
            raise ValueError(f"{path}: {len(header)} bytes, shorter than the {_HEADER.size}-byte PC2 header")
        magic, version, points, start, rate, samples = _HEADER.unpack(header)
        if magic != MAGIC:
            raise ValueError(f"{path}: not a PC2 file (magic {magic!r}, expected {MAGIC!r})")
        if version != VERSION:
            raise ValueError(f"{path}: PC2 version {version}, expected {VERSION}")
        if points < 0 or samples < 0:
            raise ValueError(f"{path}: negative counts: numPoints {points}, numSamples {samples}")
        expected = _HEADER.size + 12 * points * samples
        actual = os.fstat(file.fileno()).st_size
        if actual != expected:
            raise ValueError(f"{path}: {samples} samples of {points} points need {expected} bytes, "
                             f"the file has {actual}")
        data = np.fromfile(file, dtype="<f4", count=samples * points * 3)
    return PointCache(frames=data.astype(np.float32).reshape(samples, points, 3), start_frame=start, sample_rate=rate)


def write_pc2(path: PathLike, frames: npt.ArrayLike, start_frame: float = 0.0, sample_rate: float = 1.0) -> None:
    """Writes F×N×3 ``frames`` (any array-like convertible to float32) as a PC2 file.

    Raises:
        ValueError: when ``frames`` is not F×N×3.
    """
    array = np.asarray(frames, dtype=np.float32)
    if array.ndim != 3 or array.shape[2] != 3:
        raise ValueError(f"frames: expected shape (F, N, 3), got {tuple(array.shape)}")
    samples, points, _ = array.shape
    with open(path, "wb") as file:
        file.write(_HEADER.pack(MAGIC, VERSION, points, float(start_frame), float(sample_rate), samples))
        file.write(np.ascontiguousarray(array, dtype="<f4").tobytes())
