"""numpy arrays ⇄ the animspace.v1 wire format.

The API moves point sets as ``PointArray``: N×D little-endian float32, point-major, packed into
one ``bytes`` field (common.proto), so a 100k-point pose costs one copy each way instead of a
repeated-float walk. Answers may come in a 16-bit ``PointEncoding`` (binary16, or per-channel
fixed point): :func:`points_from` decodes each with numpy alone. Skeleton poses are B×12 float32: the top three rows of each bone's 4×4
affine matrix, row-major (``SkeletonPose.transforms``).

Every function here checks shapes before packing and raises ``ValueError`` naming the argument,
the expected shape and the actual one: a wrong shape is a programming mistake best caught before
a round trip. Scalars bound for unsigned fields are checked the same way (:func:`as_uint`,
:func:`as_float`): protobuf's own refusal ("Value out of range: -5") names no field. Values are not checked here (NaN, ±Inf): the server refuses them naming the field,
and checking twice would cost a pass over every array.
"""
from __future__ import annotations

import operator
from typing import Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

from animspace.v1 import common_pb2

__all__ = [
    "as_float",
    "as_float32",
    "as_uint",
    "as_points",
    "as_transforms",
    "point_array",
    "points_encoding",
    "points_from",
    "skeleton_pose",
    "transforms_from",
    "SPACES",
    "POINT_ENCODINGS",
]

# The wire's float: little-endian IEEE-754 binary32 whatever the host's byte order.
WIRE_FLOAT = np.dtype("<f4")
WIRE_UINT32 = np.dtype("<u4")
# The 16-bit PointEncodings: IEEE-754 binary16 (FLOAT16) and the q of FIXED16.
WIRE_HALF = np.dtype("<f2")
WIRE_UINT16 = np.dtype("<u2")

# The ``points_encoding=`` keyword's values → PointEncoding (common.proto).
POINT_ENCODINGS = {
    "float32": common_pb2.POINT_ENCODING_UNSPECIFIED,
    "float16": common_pb2.POINT_ENCODING_FLOAT16,
    "fixed16": common_pb2.POINT_ENCODING_FIXED16,
    # Answers only: a HIT (or a BLEND/MISS the client completes) as subspace coordinates p, which
    # the client reconstructs with the model's basis (animspace.coordinates).
    "coordinates": common_pb2.POINT_ENCODING_COORDINATES,
}
WIRE_INT32 = np.dtype("<i4")

# SkeletonPose.space by name. Unspecified is refused by the server, so there is no default here:
# callers choose, and Client methods default to "global" (G_j, world from bone).
SPACES = {
    "local": common_pb2.SkeletonPose.SPACE_LOCAL,
    "global": common_pb2.SkeletonPose.SPACE_GLOBAL,
}

# Largest deviation of a 4×4 matrix's last row from (0, 0, 0, 1) that is still taken as affine:
# float32 round-off of a product of a few rigid transforms stays far below it, while a genuinely
# projective matrix (which the wire cannot carry) is far above it.
AFFINE_ROW_TOLERANCE = 1e-6


def _shape_text(shape: Sequence[object]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def as_uint(name: str, value: object, bits: int = 32) -> int:
    """``value`` as an integer for a ``uint32`` (or, with ``bits`` 64, ``uint64``) field.

    Raises:
        ValueError: naming ``name``, for a negative or too large integer, or a value that is not
            an integer (1.5, "3"; numpy integers are accepted).
    """
    largest = (1 << bits) - 1
    try:
        number = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{name}: expected an integer in [0, {largest}], got {value!r}") from None
    if not 0 <= number <= largest:
        raise ValueError(f"{name}: expected an integer in [0, {largest}], got {number}")
    return number


def as_int(name: str, value: object) -> int:
    """``value`` as an integer for an ``int32`` field (range checks within int32 are the server's,
    which names the field too).

    Raises:
        ValueError: naming ``name``, for a value that is not an integer or is outside int32.
    """
    try:
        number = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{name}: expected an integer, got {value!r}") from None
    if not -(1 << 31) <= number < (1 << 31):
        raise ValueError(f"{name}: expected an int32, got {number}")
    return number


def as_float(name: str, value: object) -> float:
    """``value`` as a Python float for a ``float``/``double`` field (range checks are the server's,
    which names the field too).

    Raises:
        ValueError: naming ``name``, for a value that is not a number.
    """
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None


def as_float32(name: str, values: npt.ArrayLike) -> np.ndarray:
    """``values`` as a C-contiguous float32 array of any shape.

    Raises:
        ValueError: naming ``name``, when numpy cannot make a float32 array of it (ragged nested
            lists, strings, objects).
    """
    try:
        return np.ascontiguousarray(values, dtype=np.float32)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected an array of numbers convertible to float32 ({error})") from None


def as_points(name: str, values: npt.ArrayLike, *, ndim: int = 2, channels: Optional[int] = None,
              count: Optional[int] = None, points_label: str = "N") -> np.ndarray:
    """``values`` as a C-contiguous float32 array of ``ndim`` dimensions, the last one channels.

    Args:
        name: the argument's name, for the error message.
        values: anything ``numpy.asarray`` turns into numbers: N×D for ``ndim`` 2, P×N×D for 3.
        ndim: 2 for one point set, 3 for a batch of them.
        channels: D when it is known (3 for positions); None accepts any D ≥ 1.
        count: N when it is known; None accepts any N.
        points_label: what the message calls the point axis ("K" for key points).

    Raises:
        ValueError: for another number of dimensions, channels or points, naming ``name``.
    """
    array = as_float32(name, values)
    expected = ["P", points_label, "D"][3 - ndim:]
    if array.ndim != ndim or (array.ndim >= 1 and array.shape[-1] == 0 and channels is None):
        raise ValueError(f"{name}: expected shape {_shape_text(expected)}, got {_shape_text(array.shape)}")
    if channels is not None and array.shape[-1] != channels:
        want = expected[:-1] + [channels]
        raise ValueError(f"{name}: expected shape {_shape_text(want)}, got {_shape_text(array.shape)}")
    if count is not None and array.shape[-2] != count:
        want = expected[:-2] + [count, array.shape[-1]]
        raise ValueError(f"{name}: expected shape {_shape_text(want)}, got {_shape_text(array.shape)}")
    return array


def point_array(name: str, values: npt.ArrayLike, *, channels: Optional[int] = None,
                count: Optional[int] = None, points_label: str = "N") -> common_pb2.PointArray:
    """One N×D point set as a ``PointArray`` (see :func:`as_points` for the checks)."""
    array = as_points(name, values, channels=channels, count=count, points_label=points_label)
    return common_pb2.PointArray(point_count=array.shape[0], channel_count=array.shape[1],
                                 data=array.astype(WIRE_FLOAT, copy=False).tobytes())


def points_encoding(name: str, encoding: str) -> int:
    """A ``points_encoding=`` keyword ("float32", "float16", "fixed16" or "coordinates") as the
    PointEncoding value a request carries ("float32" is sent as the unset default, which every
    server reads as float32).

    Raises:
        ValueError: for another value, naming the argument.
    """
    try:
        return POINT_ENCODINGS[encoding]
    except (KeyError, TypeError):
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, POINT_ENCODINGS))}, got {encoding!r}") from None


def points_from(message: common_pb2.PointArray, what: str = "points") -> np.ndarray:
    """A ``PointArray`` in any encoding as a writable N×D float32 array (native byte order).

    FLOAT16 values widen exactly; FIXED16 values are ``offset[c] + scale[c]·q`` evaluated in
    float32 (two roundings, as the server computes its ``max_error``).

    Raises:
        ValueError: when ``data`` is not exactly 4·N·D bytes (float32) or 2·N·D bytes (16-bit
            encodings), FIXED16 lacks one scale and offset per channel, or the encoding is one
            this client does not know (the server never sends those; a proxy, a truncated message
            or a newer server could).
    """
    n, d = message.point_count, message.channel_count
    encoding = message.encoding
    if encoding in (common_pb2.POINT_ENCODING_UNSPECIFIED, common_pb2.POINT_ENCODING_FLOAT32):
        if len(message.data) != 4 * n * d:
            raise ValueError(f"{what}: {n} × {d} float32 need {4 * n * d} bytes, got {len(message.data)}")
        return np.frombuffer(message.data, dtype=WIRE_FLOAT).astype(np.float32).reshape(n, d)
    if encoding not in (common_pb2.POINT_ENCODING_FLOAT16, common_pb2.POINT_ENCODING_FIXED16):
        raise ValueError(f"{what}: unknown PointEncoding {encoding} (a newer server?)")
    name = common_pb2.PointEncoding.Name(encoding)[len("POINT_ENCODING_"):]
    if len(message.data) != 2 * n * d:
        raise ValueError(f"{what}: {n} × {d} {name} values need {2 * n * d} bytes, got {len(message.data)}")
    if encoding == common_pb2.POINT_ENCODING_FLOAT16:
        return np.frombuffer(message.data, dtype=WIRE_HALF).astype(np.float32).reshape(n, d)
    if len(message.scale) != d or len(message.offset) != d:
        raise ValueError(f"{what}: FIXED16 needs {d} scales and offsets (one per channel), got "
                         f"{len(message.scale)} and {len(message.offset)}")
    q = np.frombuffer(message.data, dtype=WIRE_UINT16).astype(np.float32).reshape(n, d)
    scale = np.asarray(message.scale, dtype=np.float32)
    offset = np.asarray(message.offset, dtype=np.float32)
    return q * scale + offset


def as_transforms(name: str, transforms: npt.ArrayLike, *, batch: bool = False) -> np.ndarray:
    """Affine bone transforms as a C-contiguous float32 array of shape (…, B, 3, 4).

    Accepts B×3×4 (the top rows, as on the wire) or B×4×4 whose last rows are (0, 0, 0, 1)
    within :data:`AFFINE_ROW_TOLERANCE`; with ``batch`` a leading pose axis P.

    Raises:
        ValueError: for another shape, or a 4×4 matrix that is not affine (the wire cannot carry
            a projective row, and dropping it silently would pose a different skeleton).
    """
    array = as_float32(name, transforms)
    expected = "(P, B, 3, 4) or (P, B, 4, 4)" if batch else "(B, 3, 4) or (B, 4, 4)"
    ndim = 4 if batch else 3
    if array.ndim != ndim or array.shape[-1] != 4 or array.shape[-2] not in (3, 4):
        raise ValueError(f"{name}: expected shape {expected}, got {_shape_text(array.shape)}")
    if array.shape[-2] == 4:
        last = array[..., 3, :]
        deviation = np.abs(last - np.array([0, 0, 0, 1], dtype=np.float32))
        if deviation.size and not np.all(deviation <= AFFINE_ROW_TOLERANCE):
            where = np.unravel_index(int(np.argmax(deviation.max(axis=-1))), last.shape[:-1])
            raise ValueError(f"{name}: the last row of every 4×4 transform must be (0, 0, 0, 1); "
                             f"{name}[{', '.join(str(int(i)) for i in where)}] has {last[where].tolist()}")
        array = np.ascontiguousarray(array[..., :3, :])
    return array


def skeleton_pose(name: str, transforms: npt.ArrayLike, space: str = "global") -> common_pb2.SkeletonPose:
    """One skeleton pose (B×3×4 or B×4×4) as a ``SkeletonPose`` in ``space`` ("global" or "local").

    "global": G_j, world from bone, as in v = Σ_j G_j p_j; "local": joint transforms L_j relative
    to the parent bone, which the server composes as G_j = G_parent(j) · L_j (Merry 2007 §2.2).
    """
    if space not in SPACES:
        raise ValueError(f"space: expected 'global' or 'local', got {space!r}")
    array = as_transforms(name, transforms)
    return common_pb2.SkeletonPose(space=SPACES[space], bone_count=array.shape[0],
                                   transforms=array.astype(WIRE_FLOAT, copy=False).tobytes())


def transforms_from(data: bytes, bone_count: int, what: str = "transforms") -> np.ndarray:
    """B·12 packed float32 (the SkeletonPose layout) as a writable B×3×4 float32 array."""
    if len(data) != 48 * bone_count:
        raise ValueError(f"{what}: {bone_count} bones need {48 * bone_count} bytes, got {len(data)}")
    return np.frombuffer(data, dtype=WIRE_FLOAT).astype(np.float32).reshape(bone_count, 3, 4)


def to_4x4(transforms: npt.ArrayLike) -> np.ndarray:
    """(…, 3, 4) affine transforms completed with the row (0, 0, 0, 1), for composing them."""
    top = np.asarray(transforms)
    bottom = np.zeros(top.shape[:-2] + (1, 4), dtype=top.dtype)
    bottom[..., 0, 3] = 1
    return np.concatenate([top, bottom], axis=-2)


def shape_text(shape: Tuple[int, ...]) -> str:
    """A shape as Python prints it, "(24, 3)" or "(5,)", for error messages."""
    return _shape_text(shape)
