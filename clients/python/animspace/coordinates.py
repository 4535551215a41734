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

The cache's files are shared with the C++ client (``clients/cpp``), byte for byte:
``<dir>/<model>/<version>-<checksum, 16 lowercase hex digits>.basis`` holding the 8 bytes
``ASBASIS1``, a 40-byte little-endian header (uint32 N, D, M, aligned; uint64 version, checksum)
and then the float32 little-endian values: the N·D mean, then A column by column.
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
from typing import Callable, Optional, Tuple, Union

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
            (Fortran order), as on the wire. Read-only.
        basis_sha256: SHA-256 of the values as GetBasis sends them (32 bytes; b"" from a server
            before it): names the subspace so that it cannot be forged.
        values_encoding: "float32", the basis itself; or "float16" (``get_basis(...,
            values_encoding="float16")``, issue #53): half the bytes on the wire, each value
            within ``values_max_error`` of the float32 basis the checksum and SHA-256 name, so
            :func:`reconstruct` is within ``values_max_error·(1 + Σ_j |p_j|)`` more per value
            (:func:`rounding_bound` includes it). A float16 basis is never cached.
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
    basis: np.ndarray
    basis_sha256: bytes = b""
    values_encoding: str = "float32"
    values_max_error: float = 0.0

    @property
    def nbytes(self) -> int:
        return int(self.mean.nbytes + self.basis.nbytes)


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
    mean_bytes = np.ascontiguousarray(mean, dtype=wire.WIRE_FLOAT).tobytes()
    basis_bytes = np.asarray(basis, dtype=wire.WIRE_FLOAT).tobytes(order="F")
    return (zlib.crc32(mean_bytes) << 32) | zlib.crc32(basis_bytes)


def basis_sha256(mean: np.ndarray, basis: np.ndarray) -> bytes:
    """SHA-256 of the mean's float32 little-endian bytes followed by the basis's, column by column:
    the values exactly as GetBasis streams them (poses.proto BasisChunk.basis_sha256)."""
    digest = hashlib.sha256(np.ascontiguousarray(mean, dtype=wire.WIRE_FLOAT).tobytes())
    digest.update(np.asarray(basis, dtype=wire.WIRE_FLOAT).tobytes(order="F"))
    return digest.digest()


def _basis_from_values(model: str, model_version: int, checksum: int, n: int, d: int, m: int, aligned: bool,
                       values: np.ndarray, sha256: bytes = b"", values_encoding: str = "float32",
                       values_max_error: float = 0.0) -> Basis:
    """A Basis over ``values`` (N·D·(M+1) float32: the mean, then A column by column), read-only."""
    values.setflags(write=False)
    rows = n * d
    mean = values[:rows]
    basis = values[rows:].reshape((rows, m), order="F")
    return Basis(model=model, model_version=model_version, basis_checksum=checksum, point_count=n, channel_count=d,
                 basis_size=m, aligned=aligned, mean=mean, basis=basis, basis_sha256=sha256,
                 values_encoding=values_encoding, values_max_error=values_max_error)


# Bytes a value of a BasisChunk takes, by its values_encoding (unset: a server before issue #53).
_VALUE_BYTES = {common_pb2.POINT_ENCODING_UNSPECIFIED: 4, common_pb2.POINT_ENCODING_FLOAT32: 4,
                common_pb2.POINT_ENCODING_FLOAT16: 2}


class BasisAssembler:
    """Puts GetBasis's chunks together, refusing a stream that breaks BasisChunk's contract.

    ``take`` each chunk in arrival order, then ``complete()`` and ``basis(model)``. Each returns a
    problem (a sentence naming the chunk and field) or None; the client raises ProtocolError with
    it. The checksum of the assembled values must equal the one every chunk repeats.
    """

    def __init__(self) -> None:
        self._first: Optional[poses_pb2.BasisChunk] = None
        self._values: Optional[np.ndarray] = None
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
            if n == 0 or d == 0:
                return f"{where}: point_count {n} × channel_count {d}: an empty subspace"
            if chunk.aligned and d != 3:
                return f"{where}: aligned with channel_count {d} (alignment moves 3-channel points)"
            expected = n * d * (m + 1)
            if chunk.total_values != expected:
                return (f"{where}: total_values {chunk.total_values}, but N·D·(M+1) = {n}·{d}·{m + 1} = "
                        f"{expected}")
            self._first = chunk
            self._values = np.empty(expected, dtype=np.float32)
        else:
            first = self._first
            for name in ("model_version", "basis_checksum", "basis_sha256", "point_count", "channel_count",
                         "basis_size", "aligned", "total_values", "values_encoding", "values_sha256"):
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
        if self._first is None or self._values is None:
            return "the stream ended without a chunk"
        if self._filled != self._values.size:
            return f"the stream ended after {self._filled} of {self._values.size} values"
        if self._half():
            # The names are the float32 basis's; float16 values are checked as they came.
            digest = self._sent.digest()
            if digest != self._first.values_sha256:
                return (f"the float16 values' SHA-256 {digest.hex()} is not the values_sha256 "
                        f"{self._first.values_sha256.hex()} the chunks carry")
            return None
        rows = self._first.point_count * self._first.channel_count
        checksum = basis_checksum(self._values[:rows],
                                  self._values[rows:].reshape((rows, self._first.basis_size), order="F"))
        if checksum != self._first.basis_checksum:
            return (f"the values' checksum {checksum:016x} is not the basis_checksum "
                    f"{self._first.basis_checksum:016x} the chunks carry")
        if self._first.basis_sha256:
            digest = hashlib.sha256(self._values.tobytes()).digest()
            if digest != self._first.basis_sha256:
                return (f"the values' SHA-256 {digest.hex()} is not the basis_sha256 "
                        f"{self._first.basis_sha256.hex()} the chunks carry")
        return None

    def basis(self, model: str) -> Basis:
        """The assembled subspace (call after ``complete()`` returned None)."""
        first = self._first
        assert first is not None and self._values is not None and self._filled == self._values.size
        return _basis_from_values(model, first.model_version, first.basis_checksum, first.point_count,
                                  first.channel_count, first.basis_size, first.aligned, self._values,
                                  bytes(first.basis_sha256), "float16" if self._half() else "float32",
                                  float(first.values_max_error) if self._half() else 0.0)


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
    2⁻²⁴·|f̂_c| twice for the rounding of the final sum with t (:func:`rounding_bound`).

    Raises:
        ValueError: ``coordinates`` that do not belong to ``basis`` (another checksum, M values
            other than its basis_size, an alignment missing or present against ``aligned``).
    """
    check_coordinates(basis, coordinates)
    values = basis.mean + basis.basis @ coordinates.p  # float32 × float32: one sgemv, float32 sums
    points = values.reshape(basis.point_count, basis.channel_count)
    if basis.aligned:
        assert coordinates.rotation is not None and coordinates.translation is not None
        points = points @ coordinates.rotation.T + coordinates.translation
    return np.ascontiguousarray(points, dtype=np.float32)


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
    mean = basis.mean.astype(np.float64)
    A = basis.basis.astype(np.float64)
    p = coordinates.p.astype(np.float64)
    size = np.abs(mean) + np.abs(A) @ np.abs(p)
    if basis.values_encoding == "float16":
        # Each value within 2⁻¹¹ of its own size (2⁻²⁵ below 2⁻¹⁴) of the float32 one (poses.proto).
        bound = (2 * gamma + 2.0 ** -11) * (1 + 2.0 ** -10) * size + 2.0 ** -24 * (1 + np.abs(p).sum())
    else:
        bound = 2 * gamma * size
    bound = bound.reshape(basis.point_count, basis.channel_count)
    if not basis.aligned:
        return bound
    x = (mean + A @ p).reshape(-1, 3)
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
                if basis_sha256(basis.mean, basis.basis) != expected:
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
        there is checked when it is read). A float16 basis is not the one its names name: refused."""
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
    """Writes ``basis`` to ``path`` atomically in the shared format (module docstring)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    header = _HEADER.pack(CACHE_MAGIC, basis.point_count, basis.channel_count, basis.basis_size, int(basis.aligned),
                          basis.model_version, basis.basis_checksum)
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, "wb") as out:
            out.write(header)
            out.write(np.ascontiguousarray(basis.mean, dtype=wire.WIRE_FLOAT).tobytes())
            out.write(np.asarray(basis.basis, dtype=wire.WIRE_FLOAT).tobytes(order="F"))
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
    if len(data) < _HEADER.size:
        return None
    magic, n, d, m, aligned, version, stored = _HEADER.unpack_from(data)
    if magic != CACHE_MAGIC or aligned not in (0, 1) or version != model_version or stored != checksum:
        return None
    if n == 0 or d == 0 or (aligned and d != 3) or len(data) != _HEADER.size + 4 * n * d * (m + 1):
        return None
    values = np.frombuffer(data, dtype=wire.WIRE_FLOAT, offset=_HEADER.size).astype(np.float32)
    rows = n * d
    if basis_checksum(values[:rows], values[rows:].reshape((rows, m), order="F")) != checksum:
        return None
    return _basis_from_values(model, version, checksum, n, d, m, bool(aligned), values)
