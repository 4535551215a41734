"""Point multiplication on the client (issue #36): answers as subspace coordinates.

A PMSC answer is f̂ = mean + A p (Meyer & Anderson 2007 eq. 1): N·D values that are a linear
function of M ≪ N·D coordinates p. A client that holds the subspace — the N·D mean and the
N·D × M basis A, fetched once with ``PoseService.GetBasis`` — can take its answers as p
(``points_encoding="coordinates"``: M float32 values, plus R and t for an aligned model) and
compute the points itself:

    f̂_i = R (mean_i + Σ_j A_ij p_j) + t        (i a point; R = I, t = 0 unless aligned)

This module holds what that needs, without gRPC: the :class:`Basis` and how its chunks assemble
(:class:`BasisAssembler`), its checksum (:func:`basis_checksum`), the :class:`BasisCache` on disk
and in memory, and :func:`reconstruct`. ``Client.get_basis`` and ``Client.reconstruct`` drive it.

An articulated model's A is [L | R] (issue #51 item 4): 12 columns per bone, zero wherever a point
does not depend on the bone, then r residual columns. Its SKINNED layout (``layout="skinned"``,
poses.proto BasisChunk) keeps each point's K bones and skinning terms instead of L — a fraction of
the values, a tenth with tens of bones — and :func:`reconstruct` applies the bone maps to the
terms, skipping the zeros. It is the same basis: its checksum and SHA-256 are those of the dense
values it expands to, computed a column at a time, so the dense matrix is never needed
(:meth:`Basis.dense_basis` makes it).

The cache's files are shared with the C++ client (``clients/cpp``), byte for byte:
``<dir>/<model>/<version>-<checksum, 16 lowercase hex digits>.basis`` holding the 8 bytes
``ASBASIS1``, a 40-byte little-endian header (uint32 N, D, M, aligned; uint64 version, checksum)
and then the float32 little-endian values: the N·D mean, then A column by column. A skinned basis
is ``ASBASIS2``: the same header, then uint32 layout (2), B, K and 0 (56 bytes), then the values
in the SKINNED order (docs/FORMATS.md, "Basis cache").
"""
from __future__ import annotations

import collections
import dataclasses
import hashlib
import stat
import os
import pathlib
import struct
import tempfile
import threading
import zlib
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator, Optional, Tuple, Union

import numpy as np

from animspace import wire
from animspace.display import compact_repr
from animspace.v1 import common_pb2, poses_pb2

__all__ = [
    "Basis",
    "BasisAssembler",
    "BasisCache",
    "SubspaceCoordinates",
    "basis_checksum",
    "basis_sha256",
    "default_cache_directory",
    "reconstruct",
    "rounding_bound",
]

# The cache file: magic, then uint32 point_count, channel_count, basis_size, aligned and uint64
# model_version, basis_checksum, all little-endian (40 bytes with the magic).
CACHE_MAGIC = b"ASBASIS1"
_HEADER = struct.Struct("<8sIIIIQQ")
assert _HEADER.size == 40
# A skinned basis's file: the same fields, then uint32 layout (2), B, K and a reserved 0.
SKINNED_CACHE_MAGIC = b"ASBASIS2"
_SKINNED_HEADER = struct.Struct("<8sIIIIQQIIII")
assert _SKINNED_HEADER.size == 56

# float32's unit roundoff.
_U = 2.0 ** -24


# ----------------------------------------------------------------------------------------------
# The subspace and an answer's coordinates


@dataclass(frozen=True, eq=False)
class Basis:
    """The subspace of one model version, as GetBasis sends it (poses.proto BasisChunk).

    Attributes:
        model: the model's name.
        model_version: the version it belongs to.
        basis_checksum: crc32 of the mean's float32 bytes in the high 32 bits, of the basis's
            (column by column) in the low 32: names the subspace exactly.
        point_count, channel_count, basis_size: N, D and M.
        aligned: the model moves its estimate to the world with a per-pose R and t.
        mean: (N·D,) float32, point-major (as ``PointArray``). Read-only.
        basis: (N·D, M) float32, column j the j-th basis vector, stored column by column
            (Fortran order), as on the wire; None for a skinned basis (:meth:`dense_basis` makes
            it). Read-only.
        basis_sha256: SHA-256 of the values as GetBasis sends them (32 bytes; b"" from a server
            before it): names the subspace so that it cannot be forged.
        values_encoding: "float32", the basis itself; or "float16" (``get_basis(...,
            values_encoding="float16")``, issue #53): half the bytes on the wire, each value
            within ``values_max_error`` of the float32 basis the checksum and SHA-256 name, so
            :func:`reconstruct` is within ``values_max_error·(1 + Σ_j |p_j|)`` more per value
            (:func:`rounding_bound` includes it). A float16 basis is never cached.
        layout: "dense" (``basis`` holds A) or "skinned" (an articulated model, D = 3: A's first
            12·B columns as each point's bones and terms, then its r residual columns).
        bone_count, influences: (skinned) B, the subspace's bones, and K, slots per point; 0 for
            dense.
        bones: (skinned) (N, K) int32, the bone of each slot, in [0, B).
        terms: (skinned) (N, K, 4) float32, each slot's skinning term h = w (p̂ − c, 1); a slot
            whose 4 values are 0 is padding and stands for nothing. Column 12·j + 4·a + c of A
            holds h[c] at row 3·i + a for each slot (j, h) of point i, and 0 elsewhere.
        residuals: (skinned) (N·3, r) float32, A's last r = M − 12·B columns, Fortran order.
    """

    __repr__ = compact_repr

    model: str
    model_version: int
    basis_checksum: int
    point_count: int
    channel_count: int
    basis_size: int
    aligned: bool
    mean: np.ndarray
    basis: Optional[np.ndarray]
    basis_sha256: bytes = b""
    values_encoding: str = "float32"
    values_max_error: float = 0.0
    layout: str = "dense"
    bone_count: int = 0
    influences: int = 0
    bones: Optional[np.ndarray] = None
    terms: Optional[np.ndarray] = None
    residuals: Optional[np.ndarray] = None

    @property
    def nbytes(self) -> int:
        """The bytes of the arrays it holds."""
        arrays = (self.mean, self.basis, self.bones, self.terms, self.residuals)
        return int(sum(a.nbytes for a in arrays if a is not None))

    def dense_basis(self) -> np.ndarray:
        """A as an (N·D, M) float32 matrix, Fortran order, whatever the layout: ``basis`` itself
        for a dense basis, otherwise a new one: N·D·M values, the zeros the skinned form leaves out."""
        if self.basis is not None:
            return self.basis
        A = np.empty((self.point_count * self.channel_count, self.basis_size), dtype=np.float32, order="F")
        for j, column in enumerate(_skinned_columns(self)):
            A[:, j] = column
        return A


@dataclass(frozen=True, eq=False)
class SubspaceCoordinates:
    """An answer as subspace coordinates (poses.proto SubspaceCoordinates).

    Attributes:
        p: (M,) float32 coordinates.
        basis_checksum: the :attr:`Basis.basis_checksum` of the basis they belong to.
        rotation: 3×3 float32 R (aligned models), else None.
        translation: (3,) float32 t (aligned models), else None.
    """

    __repr__ = compact_repr

    p: np.ndarray
    basis_checksum: int
    rotation: Optional[np.ndarray] = None
    translation: Optional[np.ndarray] = None

    @classmethod
    def from_proto(cls, m: poses_pb2.SubspaceCoordinates, what: str = "coordinates") -> "SubspaceCoordinates":
        """Raises ValueError for a rotation other than 0 or 9 values, a translation other than 0 or
        3, or one without the other (the server never sends those)."""
        if (len(m.rotation), len(m.translation)) not in ((0, 0), (9, 3)):
            raise ValueError(f"{what}: expected a rotation of 9 values and a translation of 3 (aligned) or "
                             f"neither, got {len(m.rotation)} and {len(m.translation)}")
        aligned = len(m.rotation) == 9
        return cls(p=np.array(m.p, dtype=np.float32), basis_checksum=m.basis_checksum,
                   rotation=np.array(m.rotation, dtype=np.float32).reshape(3, 3) if aligned else None,
                   translation=np.array(m.translation, dtype=np.float32) if aligned else None)


def basis_checksum(mean: np.ndarray, basis: np.ndarray) -> int:
    """(crc32 of the mean's float32 little-endian bytes) << 32 | crc32 of the basis's, column by
    column. ``mean`` is N·D values, ``basis`` N·D × M (any memory order)."""
    return _digests(mean, [np.asarray(basis, dtype=wire.WIRE_FLOAT).ravel(order="F")], sha256=False)[0]


def basis_sha256(mean: np.ndarray, basis: np.ndarray) -> bytes:
    """SHA-256 of the mean's float32 little-endian bytes followed by the basis's, column by column:
    the values exactly as GetBasis streams them (poses.proto BasisChunk.basis_sha256)."""
    return _digests(mean, [np.asarray(basis, dtype=wire.WIRE_FLOAT).ravel(order="F")])[1]


def _digests(mean: np.ndarray, parts: Iterable[np.ndarray], sha256: bool = True) -> Tuple[int, bytes]:
    """basis_checksum and (unless ``sha256`` is False: b"") basis_sha256 of the mean and A's
    float32 bytes, A given as contiguous parts in column order (zlib's CRC and hashlib's digest
    both chain, so a part may be a column or the whole matrix)."""
    mean = np.ascontiguousarray(mean, dtype=wire.WIRE_FLOAT)
    digest = hashlib.sha256(mean) if sha256 else None
    crc = 0
    for part in parts:
        part = np.ascontiguousarray(part, dtype=wire.WIRE_FLOAT)
        crc = zlib.crc32(part, crc)
        if digest is not None:
            digest.update(part)
    return (zlib.crc32(mean) << 32) | crc, digest.digest() if digest is not None else b""


def _basis_digests(basis: Basis, sha256: bool = True) -> Tuple[int, bytes]:
    """:func:`_digests` of the dense values ``basis`` stands for: a skinned one expanded a column
    at a time (skinned_basis.h's for_each_dense_column), never as a whole matrix."""
    parts = [basis.basis.ravel(order="F")] if basis.basis is not None else _skinned_columns(basis)
    return _digests(basis.mean, parts, sha256)


def _skinned_columns(basis: Basis) -> Iterator[np.ndarray]:
    """A skinned basis's dense columns in order, N·3 float32 each. The 12·B columns of the bones
    share one buffer, valid until the next column: each costs its own entries and one clearing."""
    assert basis.bones is not None and basis.terms is not None and basis.residuals is not None
    K = basis.influences
    bones = basis.bones.ravel()
    # The slots of each bone (slot s is slot s % K of point s // K), padding left out.
    live = np.flatnonzero(basis.terms.any(axis=2).ravel())
    by_bone = live[np.argsort(bones[live], kind="stable")]
    starts = np.searchsorted(bones[by_bone], np.arange(basis.bone_count + 1))
    terms = basis.terms.reshape(-1, 4)
    column = np.zeros(3 * basis.point_count, dtype=np.float32)
    for j in range(basis.bone_count):
        slots = by_bone[starts[j]:starts[j + 1]]
        rows, h = 3 * (slots // K), terms[slots]
        for a in range(3):
            for c in range(4):
                column[rows + a] = h[:, c]
                yield column
                column[rows + a] = 0
    yield from basis.residuals.T  # rows of the C-order transpose: contiguous columns


def _value_count(n: int, d: int, m: int, bone_count: int = 0, influences: int = 0) -> int:
    """Values GetBasis sends: N·D·(M+1) dense; N·3·(r+1) + 5·N·K skinned (bone_count B > 0)."""
    if bone_count == 0:
        return n * d * (m + 1)
    return n * 3 * (m - 12 * bone_count + 1) + 5 * n * influences


def _shape_problem(n: int, d: int, m: int, aligned: bool, bone_count: int = 0, influences: int = 0) -> Optional[str]:
    """What makes N, D, M (and B, K for a skinned basis) no subspace, or None."""
    if n == 0 or d == 0:
        return f"point_count {n} × channel_count {d}: an empty subspace"
    if aligned and d != 3:
        return f"aligned with channel_count {d} (alignment moves 3-channel points)"
    if bone_count and (d != 3 or influences == 0 or m < 12 * bone_count):
        return (f"skinned with channel_count {d}, subspace_bone_count {bone_count}, influences_per_point "
                f"{influences} and basis_size {m}: expected D = 3, K ≥ 1 and M ≥ 12·B")
    return None


def _basis_from_values(model: str, model_version: int, checksum: int, n: int, d: int, m: int, aligned: bool,
                       values: np.ndarray, sha256: bytes = b"", values_encoding: str = "float32",
                       values_max_error: float = 0.0, bone_count: int = 0, influences: int = 0) -> Basis:
    """A Basis over ``values`` (:func:`_value_count` float32 in GetBasis's order), read-only: dense
    when ``bone_count`` is 0, else skinned with B = ``bone_count`` and K = ``influences``.

    Raises:
        ValueError: (skinned) naming the slot and point of a bone number that is not an integer
            in [0, B), or of a point that names one bone in two slots (its entries of A would
            hold two values, and the reconstruction would not be A's).
    """
    values.setflags(write=False)
    rows = n * d
    mean = values[:rows]
    common = dict(model=model, model_version=model_version, basis_checksum=checksum, point_count=n, channel_count=d,
                  basis_size=m, aligned=aligned, mean=mean, basis_sha256=sha256, values_encoding=values_encoding,
                  values_max_error=values_max_error)
    if bone_count == 0:
        return Basis(basis=values[rows:].reshape((rows, m), order="F"), **common)
    B, K = bone_count, influences
    slots = values[rows:rows + 5 * n * K].reshape(n, K, 5)
    j = slots[..., 0]
    bad = ~((j >= 0) & (j < B) & (j == np.floor(j)))  # NaN fails every comparison
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise ValueError(f"slot {k} of point {i} names bone {j[i, k]:.9g}, expected an integer in [0, {B})")
    bones = j.astype(np.int32)
    terms = slots[..., 1:]
    # Padding (h = 0) never collides: each of its slots gets its own negative number.
    named = np.sort(np.where(terms.any(axis=2), bones, -1 - np.arange(K)), axis=1)
    twice = named[:, 1:] == named[:, :-1]
    if twice.any():
        i, k = np.argwhere(twice)[0]
        raise ValueError(f"point {i} names bone {named[i, k]} in two slots")
    bones.setflags(write=False)
    residuals = values[rows + 5 * n * K:].reshape((rows, m - 12 * B), order="F")
    return Basis(basis=None, layout="skinned", bone_count=B, influences=K, bones=bones, terms=terms,
                 residuals=residuals, **common)


# Bytes a value of a BasisChunk takes, by its values_encoding (unset: a server before issue #53).
_VALUE_BYTES = {common_pb2.POINT_ENCODING_UNSPECIFIED: 4, common_pb2.POINT_ENCODING_FLOAT32: 4,
                common_pb2.POINT_ENCODING_FLOAT16: 2}
# The layouts a BasisChunk comes in (unset: a server before issue #51's layouts, dense).
_LAYOUTS = {poses_pb2.BASIS_LAYOUT_UNSPECIFIED: "dense", poses_pb2.BASIS_LAYOUT_DENSE: "dense",
            poses_pb2.BASIS_LAYOUT_SKINNED: "skinned"}


class BasisAssembler:
    """Puts GetBasis's chunks together, refusing a stream that breaks BasisChunk's contract.

    ``take`` each chunk in arrival order, then ``complete()`` and ``basis(model)``. Each returns a
    problem (a sentence naming the chunk and field) or None; the client raises ProtocolError with
    it. The checksum of the assembled values — of the dense values a skinned basis expands to —
    must equal the one every chunk repeats.
    """

    def __init__(self) -> None:
        self._first: Optional[poses_pb2.BasisChunk] = None
        self._values: Optional[np.ndarray] = None
        self._basis: Optional[Basis] = None
        self._filled = 0
        self._chunks = 0
        self._sent = hashlib.sha256()  # over float16 values as they came

    def take(self, chunk: poses_pb2.BasisChunk) -> Optional[str]:
        where = f"chunk {self._chunks}"
        self._chunks += 1
        value_bytes = _VALUE_BYTES.get(chunk.values_encoding)
        if value_bytes is None:
            return f"{where}: values_encoding {chunk.values_encoding}, not FLOAT32 or FLOAT16"
        if self._first is None:
            n, d, m = chunk.point_count, chunk.channel_count, chunk.basis_size
            layout = _LAYOUTS.get(chunk.layout)
            if layout is None:
                return f"{where}: layout {chunk.layout}, not DENSE or SKINNED"
            B, K = (chunk.subspace_bone_count, chunk.influences_per_point) if layout == "skinned" else (0, 0)
            if layout == "skinned" and B == 0:
                return f"{where}: layout SKINNED with subspace_bone_count 0"
            problem = _shape_problem(n, d, m, chunk.aligned, B, K)
            if problem:
                return f"{where}: {problem}"
            expected = _value_count(n, d, m, B, K)
            if chunk.total_values != expected:
                formula = (f"N·3·(r+1) + 5·N·K = {n}·3·{m - 12 * B + 1} + 5·{n}·{K}" if B else
                           f"N·D·(M+1) = {n}·{d}·{m + 1}")
                return f"{where}: total_values {chunk.total_values}, but {formula} = {expected}"
            self._first = chunk
            self._values = np.empty(expected, dtype=np.float32)
        else:
            first = self._first
            for name in ("model_version", "basis_checksum", "basis_sha256", "point_count", "channel_count",
                         "basis_size", "aligned", "total_values", "values_encoding", "values_sha256", "layout",
                         "subspace_bone_count", "influences_per_point"):
                if getattr(chunk, name) != getattr(first, name):
                    return f"{where}: {name} {getattr(chunk, name)} differs from chunk 0's {getattr(first, name)}"
        assert self._values is not None
        if chunk.offset != self._filled:
            return (f"{where}: offset {chunk.offset}, expected {self._filled} (chunks arrive in order and cover "
                    "the values once)")
        kind = "float16" if value_bytes == 2 else "float32"
        if len(chunk.data) % value_bytes != 0:
            return f"{where}: {len(chunk.data)} bytes of data, not whole {kind} values"
        count = len(chunk.data) // value_bytes
        if count == 0:
            return f"{where}: no values"
        if self._filled + count > self._values.size:
            return (f"{where}: values {self._filled}..{self._filled + count} run past total_values "
                    f"{self._values.size}")
        if value_bytes == 2:
            self._sent.update(chunk.data)
            values = np.frombuffer(chunk.data, dtype=np.dtype("<f2")).astype(np.float32)  # exact
        else:
            values = np.frombuffer(chunk.data, dtype=wire.WIRE_FLOAT)
        self._values[self._filled:self._filled + count] = values
        self._filled += count
        return None

    def _half(self) -> bool:
        return self._first is not None and self._first.values_encoding == common_pb2.POINT_ENCODING_FLOAT16

    def complete(self) -> Optional[str]:
        first = self._first
        if first is None or self._values is None:
            return "the stream ended without a chunk"
        if self._filled != self._values.size:
            return f"the stream ended after {self._filled} of {self._values.size} values"
        skinned = _LAYOUTS[first.layout] == "skinned"
        try:
            self._basis = _basis_from_values(
                "", first.model_version, first.basis_checksum, first.point_count, first.channel_count,
                first.basis_size, first.aligned, self._values, bytes(first.basis_sha256),
                "float16" if self._half() else "float32", float(first.values_max_error) if self._half() else 0.0,
                first.subspace_bone_count if skinned else 0, first.influences_per_point if skinned else 0)
        except ValueError as error:
            return f"the skinned values: {error}"
        if self._half():
            # The names are the float32 basis's; float16 values are checked as they came.
            digest = self._sent.digest()
            if digest != first.values_sha256:
                return (f"the float16 values' SHA-256 {digest.hex()} is not the values_sha256 "
                        f"{first.values_sha256.hex()} the chunks carry")
            return None
        checksum, digest = _basis_digests(self._basis, sha256=bool(first.basis_sha256))
        if checksum != first.basis_checksum:
            return (f"the values' checksum {checksum:016x} is not the basis_checksum "
                    f"{first.basis_checksum:016x} the chunks carry")
        if first.basis_sha256 and digest != first.basis_sha256:
            return (f"the values' SHA-256 {digest.hex()} is not the basis_sha256 "
                    f"{first.basis_sha256.hex()} the chunks carry")
        return None

    def basis(self, model: str) -> Basis:
        """The assembled subspace (call after ``complete()`` returned None)."""
        assert self._basis is not None
        return dataclasses.replace(self._basis, model=model)


# ----------------------------------------------------------------------------------------------
# Reconstruction


def reconstruct(basis: Basis, coordinates: SubspaceCoordinates) -> np.ndarray:
    """f̂ = R (mean + A p) + t in float32, as an N×D float32 array (poses.proto SubspaceCoordinates).

    float32 throughout, as the server computes its own float32 answer: mean + A p, then for an
    aligned model every point x moved to R x + t. The result differs from the server's float32
    points by rounding alone — per value i at most

        2·(M + 2)·2⁻²⁴ · (|mean_i| + Σ_j |A_ij p_j|)

    (both sums are within γ_{M+2} of the exact one, whatever the order of the additions), and for
    an aligned model, whose rotation moves each point's error without growing its length, at most
    2·3·2⁻²⁴·‖x‖ more per coordinate of the point x = mean + A p for the two rotations, and
    2⁻²⁴·|f̂_c| twice for the rounding of the final sum with t (:func:`rounding_bound`). A skinned
    basis sums 1 + 4·K + r terms per value, A's nonzero ones, so the same bound holds.

    Raises:
        ValueError: ``coordinates`` that do not belong to ``basis`` (another checksum, M values
            other than its basis_size, an alignment missing or present against ``aligned``).
    """
    check_coordinates(basis, coordinates)
    values = _mean_plus_Ap(basis, coordinates.p)  # float32 throughout
    points = values.reshape(basis.point_count, basis.channel_count)
    if basis.aligned:
        assert coordinates.rotation is not None and coordinates.translation is not None
        points = points @ coordinates.rotation.T + coordinates.translation
    return np.ascontiguousarray(points, dtype=np.float32)


def _mean_plus_Ap(basis: Basis, p: np.ndarray, dtype: type = np.float32, absolute: bool = False) -> np.ndarray:
    """mean + A p over N·D values in ``dtype`` (``absolute``: |mean| + |A| |p|, each product's size),
    for either layout. Skinned: f̂_i = mean_i + Σ_slots M_j h + Σ_k R_ik p_{12B+k} with M_j bone j's
    3 × 4 block of p (skinned_basis.h), so only A's nonzero entries are multiplied."""
    size = np.abs if absolute else (lambda x: x)
    mean, p = size(basis.mean.astype(dtype, copy=False)), size(p.astype(dtype, copy=False))
    if basis.basis is not None:
        return mean + size(basis.basis.astype(dtype, copy=False)) @ p  # float32: one sgemv
    assert basis.bones is not None and basis.terms is not None and basis.residuals is not None
    skinning = 12 * basis.bone_count
    values = mean + size(basis.residuals.astype(dtype, copy=False)) @ p[skinning:]
    points = values.reshape(-1, 3)
    maps = p[:skinning].reshape(basis.bone_count, 3, 4)
    for k in range(basis.influences):  # one slot of every point at a time: N 3×4 maps, not N·K
        points += np.einsum("nac,nc->na", maps[basis.bones[:, k]], size(basis.terms[:, k].astype(dtype, copy=False)))
    return values


def check_coordinates(basis: Basis, coordinates: SubspaceCoordinates) -> None:
    """Raises ValueError unless ``coordinates`` can be reconstructed with ``basis``."""
    if coordinates.basis_checksum != basis.basis_checksum:
        raise ValueError(f"coordinates: basis_checksum {coordinates.basis_checksum:016x}, the basis of "
                         f"'{basis.model}' version {basis.model_version} is {basis.basis_checksum:016x}")
    if coordinates.p.shape != (basis.basis_size,):
        raise ValueError(f"coordinates.p: expected {basis.basis_size} values (M), got shape "
                         f"{wire.shape_text(coordinates.p.shape)}")
    if (coordinates.rotation is not None) != basis.aligned or (coordinates.translation is not None) != basis.aligned:
        raise ValueError(f"coordinates: {'no' if basis.aligned else 'an'} alignment for "
                         f"{'an aligned' if basis.aligned else 'a'} model")


def rounding_bound(basis: Basis, coordinates: SubspaceCoordinates) -> np.ndarray:
    """The N×D bound :func:`reconstruct` states on |f̂_client − f̂_server|, both float32, computed in
    float64 (a diagnostic; the tests compute it independently)."""
    check_coordinates(basis, coordinates)
    m = basis.basis_size
    gamma = (m + 2) * _U / (1 - (m + 2) * _U)
    p = coordinates.p.astype(np.float64)
    size = _mean_plus_Ap(basis, p, np.float64, absolute=True)
    if basis.values_encoding == "float16":
        # Each value within 2⁻¹¹ of its own size (2⁻²⁵ below 2⁻¹⁴) of the float32 one (poses.proto).
        bound = (2 * gamma + 2.0 ** -11) * (1 + 2.0 ** -10) * size + 2.0 ** -24 * (1 + np.abs(p).sum())
    else:
        bound = 2 * gamma * size
    bound = bound.reshape(basis.point_count, basis.channel_count)
    if not basis.aligned:
        return bound
    x = _mean_plus_Ap(basis, p, np.float64).reshape(-1, 3)
    R = coordinates.rotation.astype(np.float64)
    t = coordinates.translation.astype(np.float64)
    gamma3 = 3 * _U / (1 - 3 * _U)
    moved = np.linalg.norm(bound, axis=1, keepdims=True)  # R keeps each point's error's length
    world = np.abs(x @ R.T + t)
    return moved + 2 * gamma3 * np.linalg.norm(x, axis=1, keepdims=True) + 2 * _U * world


# ----------------------------------------------------------------------------------------------
# The cache


def default_cache_directory() -> pathlib.Path:
    """$ANIMSPACE_BASIS_CACHE if set, else $XDG_CACHE_HOME/animspace/bases, else
    ~/.cache/animspace/bases (the C++ client's too). An empty variable counts as unset."""
    explicit = os.environ.get("ANIMSPACE_BASIS_CACHE")
    if explicit:
        return pathlib.Path(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg:
        return pathlib.Path(xdg) / "animspace" / "bases"
    return pathlib.Path.home() / ".cache" / "animspace" / "bases"


_Key = Tuple[str, int, int]


class BasisCache:
    """Bases by (model, version, checksum): in memory, and on disk in the format the C++ client
    shares (module docstring).

    Args:
        directory: where the files live; None: :func:`default_cache_directory` (read when the
            cache is made).
        disk: False keeps the bases in memory only (nothing read or written on disk).
        memory_limit_bytes: most bytes of bases kept in memory; the least recently used go first
            (the one just used always stays).

    A file is written atomically (a temporary file in the same folder, then ``os.replace``), so a
    reader — another process, the C++ client — sees a whole file or none. A file whose size,
    header or checksum does not match its name is deleted and counts as a miss; a folder that
    cannot be written leaves the cache in memory only. Thread-safe.
    """

    def __init__(self, directory: Union[str, os.PathLike, None] = None, *, disk: bool = True,
                 memory_limit_bytes: int = 1 << 30) -> None:
        self._directory: Optional[pathlib.Path] = (
            (pathlib.Path(directory) if directory is not None else default_cache_directory()) if disk else None)
        self._memory_limit_bytes = memory_limit_bytes
        self._memory: "collections.OrderedDict[_Key, Basis]" = collections.OrderedDict()
        self._lock = threading.Lock()
        #: Files refused because their values were not the basis the server names.
        self.refused_copies = 0

    def __repr__(self) -> str:
        where = str(self._directory) if self._directory is not None else "memory only"
        return f"animspace.BasisCache({where!r}, {len(self._memory)} in memory)"

    @property
    def directory(self) -> Optional[pathlib.Path]:
        """The folder of the files (None: memory only)."""
        return self._directory

    def path(self, model: str, model_version: int, checksum: int) -> Optional[pathlib.Path]:
        """The file of a basis: ``<directory>/<model>/<version>-<checksum:016x>.basis`` (None: memory
        only, or a model name that is not one path component)."""
        if self._directory is None or not _safe_component(model):
            return None
        return self._directory / model / f"{model_version}-{checksum:016x}.basis"

    def get(self, model: str, model_version: int, checksum: int, *,
            server_sha256: Optional[Callable[[], Optional[bytes]]] = None) -> Optional[Basis]:
        """The basis from memory, else from its file (kept in memory then), else None.

        What the file promises (issue #54): its CRC catches accidents only — a CRC-32 is forged in
        four bytes — so a file is used only when its values' SHA-256 is the one ``server_sha256()``
        returns, the server's digest of that version's basis (the client asks DescribeKeyPoints);
        a file that differs is deleted and gives None (fetched again). ``server_sha256`` returning
        b"" (a server before the digest) or left out trusts the CRC alone; returning None (the
        version is gone or has another basis) gives None.
        """
        key = (model, model_version, checksum)
        with self._lock:
            basis = self._memory.get(key)
            if basis is not None:
                self._memory.move_to_end(key)
                return basis
        path = self.path(model, model_version, checksum)
        basis = read_basis_file(path, model, model_version, checksum) if path is not None else None
        if basis is not None and server_sha256 is not None:
            expected = server_sha256()
            if expected is None:
                return None
            if expected:
                if _basis_digests(basis)[1] != expected:
                    self.refused_copies += 1
                    try:
                        path.unlink()
                    except OSError:
                        pass
                    return None
                basis = dataclasses.replace(basis, basis_sha256=expected)
        if basis is not None:
            self._remember(basis)
        return basis

    def put(self, basis: Basis) -> None:
        """Keeps ``basis`` in memory and writes its file unless one is there already (a file that is
        there is checked when it is read; dense or skinned, it holds the same basis). A float16
        basis is not the one its names name: refused."""
        if basis.values_encoding != "float32":
            raise ValueError(f"basis of '{basis.model}' version {basis.model_version}: a {basis.values_encoding} "
                             "copy is not cached (the cache holds the float32 basis its checksum names)")
        self._remember(basis)
        path = self.path(basis.model, basis.model_version, basis.basis_checksum)
        if path is not None and not path.is_file():
            try:
                write_basis_file(path, basis)
            except OSError:
                pass  # a read-only or full disk: the cache stays in memory

    def forget(self) -> None:
        """Empties the memory (the files stay)."""
        with self._lock:
            self._memory.clear()

    def _remember(self, basis: Basis) -> None:
        key = (basis.model, basis.model_version, basis.basis_checksum)
        with self._lock:
            self._memory[key] = basis
            self._memory.move_to_end(key)
            total = sum(b.nbytes for b in self._memory.values())
            while len(self._memory) > 1 and total > self._memory_limit_bytes:
                _, dropped = self._memory.popitem(last=False)
                total -= dropped.nbytes


def _safe_component(name: str) -> bool:
    return bool(name) and name not in (".", "..") and not any(c in name for c in "/\\\0")


def write_basis_file(path: pathlib.Path, basis: Basis) -> None:
    """Writes ``basis`` to ``path`` atomically in the shared format (module docstring): ``ASBASIS1``
    dense, ``ASBASIS2`` skinned, its values as GetBasis sent them."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fields = (basis.point_count, basis.channel_count, basis.basis_size, int(basis.aligned), basis.model_version,
              basis.basis_checksum)
    if basis.basis is not None:
        header = _HEADER.pack(CACHE_MAGIC, *fields)
        parts = [basis.basis.ravel(order="F")]
    else:
        assert basis.bones is not None and basis.terms is not None and basis.residuals is not None
        header = _SKINNED_HEADER.pack(SKINNED_CACHE_MAGIC, *fields, poses_pb2.BASIS_LAYOUT_SKINNED, basis.bone_count,
                                      basis.influences, 0)
        slots = np.concatenate([basis.bones[..., np.newaxis].astype(np.float32), basis.terms], axis=2)
        parts = [slots, basis.residuals.ravel(order="F")]
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, "wb") as out:
            out.write(header)
            for part in (basis.mean, *parts):
                out.write(np.ascontiguousarray(part, dtype=wire.WIRE_FLOAT).tobytes())
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, path)
    except BaseException:
        try:
            os.unlink(temporary)
        except OSError:
            pass
        raise


def read_basis_file(path: pathlib.Path, model: str, model_version: int, checksum: int) -> Optional[Basis]:
    """The basis in ``path`` when it is whole and is the one its name says (version and checksum in
    the header, the values' checksum); None when there is no file. A file that is not right is
    deleted (it is fetched again) and gives None."""
    try:
        # Only a regular file: reading a FIFO in its place would wait for a writer forever (issue #54).
        if not stat.S_ISREG(path.stat().st_mode):
            return None
        data = path.read_bytes()
    except OSError:
        return None
    basis = _parse_basis_file(data, model, model_version, checksum)
    if basis is None:
        try:
            path.unlink()
        except OSError:
            pass
    return basis


def _parse_basis_file(data: bytes, model: str, model_version: int, checksum: int) -> Optional[Basis]:
    header, bone_count, influences = _HEADER, 0, 0
    if data[:8] == SKINNED_CACHE_MAGIC and len(data) >= _SKINNED_HEADER.size:
        header = _SKINNED_HEADER
        *_, layout, bone_count, influences, reserved = header.unpack_from(data)
        if layout != poses_pb2.BASIS_LAYOUT_SKINNED or bone_count == 0 or reserved != 0:
            return None
    elif data[:8] != CACHE_MAGIC or len(data) < _HEADER.size:
        return None
    _, n, d, m, aligned, version, stored = _HEADER.unpack_from(data)
    if aligned not in (0, 1) or version != model_version or stored != checksum:
        return None
    if (_shape_problem(n, d, m, bool(aligned), bone_count, influences)
            or len(data) != header.size + 4 * _value_count(n, d, m, bone_count, influences)):
        return None
    values = np.frombuffer(data, dtype=wire.WIRE_FLOAT, offset=header.size).astype(np.float32)
    try:
        basis = _basis_from_values(model, version, checksum, n, d, m, bool(aligned), values,
                                   bone_count=bone_count, influences=influences)
    except ValueError:  # a bone number that is no bone's
        return None
    return basis if _basis_digests(basis, sha256=False)[0] == checksum else None
