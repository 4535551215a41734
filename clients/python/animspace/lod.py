"""Levels of detail from ``LodService.GetLod``, reassembled into numpy arrays.

Merry 2007 ch. 6 and §7.3: an animation-space model simplified (appearance-preserving
simplification under the L2,2 metric, plus influence simplification) into discrete levels, each
with an error bound ε^l; a render-farm node asks for the coarsest level whose error projects under
a pixel tolerance (eq. 7.2), or the finest under a vertex budget, or a level by index.

The server streams a header, then vertex blocks, face blocks and (animation-space form) the
skeleton. :class:`LodAssembler` checks every chunk against the header as it arrives — order,
contiguity, sizes, index ranges — exactly as the C++ client's ``clients/cpp/lod_mesh.cpp`` does,
so that a truncated or reordered stream is a :class:`~animspace.errors.ProtocolError` rather
than a mesh with holes.
"""
from __future__ import annotations

import io
import os
import pathlib
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

from animspace import wire
from animspace.display import compact_repr
from animspace.messages import enum_name
from animspace.v1 import lod_pb2

__all__ = ["LodHeader", "Skeleton", "LodMesh", "LodAssembler", "FORMS"]

# GetLodRequest.Form by name. FORM_UNSPECIFIED is refused by the server on purpose (the two forms
# are different payloads); the client always sends one of these.
FORMS = {
    "posed": lod_pb2.GetLodRequest.FORM_POSED,
    "animation_space": lod_pb2.GetLodRequest.FORM_ANIMATION_SPACE,
}


def _form_name(value: int) -> str:
    return enum_name(lod_pb2.GetLodRequest.Form, value, "FORM_").lower()


@dataclass(frozen=True)
class LodHeader:
    """What the stream announces: the level chosen and the exact counts that follow.

    ``epsilon`` is ε^l, the L2,2 deviation bound of the level in model units; with a pixel
    tolerance ``tolerated_error`` is eq. 7.2's ε for the request's view (``epsilon ≤
    tolerated_error``), else 0. ``form`` is "posed" or "animation_space".
    ``texture_coordinates``: the face blocks carry the model's atlas UVs at the level (asked for).
    """

    model_version: int
    level: int
    level_count: int
    epsilon: float
    vertex_count: int
    face_count: int
    bone_count: int
    influence_count: int
    form: str
    tolerated_error: float
    texture_coordinates: bool = False

    @classmethod
    def from_proto(cls, m: lod_pb2.LodHeader) -> "LodHeader":
        return cls(model_version=m.model_version, level=m.level, level_count=m.level_count, epsilon=m.epsilon,
                   vertex_count=m.vertex_count, face_count=m.face_count, bone_count=m.bone_count,
                   influence_count=m.influence_count, form=_form_name(m.form), tolerated_error=m.tolerated_error,
                   texture_coordinates=m.texture_coordinates)


@dataclass(frozen=True, eq=False)
class Skeleton:
    """The skeleton of an animation-space level: B bones.

    ``parents`` (B,) int32, -1 for a root; ``rest_transforms`` B×3×4 float32, Ĝ_j (bone to model,
    the top three rows of each 4×4); ``bone_names`` empty or one per bone.
    """

    __repr__ = compact_repr

    parents: np.ndarray
    rest_transforms: np.ndarray
    bone_names: Tuple[str, ...]

    @property
    def bone_count(self) -> int:
        return int(self.parents.shape[0])

    def global_transforms(self, local: npt.ArrayLike) -> np.ndarray:
        """Composes joint transforms L_j (B×3×4 or B×4×4) into G_j = G_parent(j) · L_j (Merry 2007
        §2.2), B×3×4 float32 — what the server does for a ``space="local"`` pose. Computed in
        float64 so that a deep chain does not accumulate float32 round-off."""
        L = wire.to_4x4(wire.as_transforms("local", local).astype(np.float64))
        if L.shape[0] != self.bone_count:
            raise ValueError(f"local: expected {self.bone_count} bones, got {L.shape[0]}")
        G: List[Optional[np.ndarray]] = [None] * self.bone_count

        def resolve(j: int, depth: int) -> np.ndarray:
            if depth > self.bone_count:
                raise ValueError("skeleton.parents: the hierarchy has a cycle")
            if G[j] is None:
                parent = int(self.parents[j])
                G[j] = L[j] if parent < 0 else resolve(parent, depth + 1) @ L[j]
            return G[j]  # type: ignore[return-value]

        return np.stack([resolve(j, 0)[:3] for j in range(self.bone_count)]).astype(np.float32)

    def rest_local_transforms(self) -> np.ndarray:
        """The rest pose as joint transforms, L̂_j = Ĝ_parent(j)⁻¹ · Ĝ_j, B×3×4 float32: a starting
        point for posing in local space (rotate a joint by right-multiplying its L̂_j)."""
        G = wire.to_4x4(self.rest_transforms.astype(np.float64))
        L = [G[j] if p < 0 else np.linalg.solve(G[p], G[j]) for j, p in enumerate(self.parents.tolist())]
        return np.stack(L)[:, :3].astype(np.float32)


@dataclass(frozen=True, eq=False)
class LodMesh:
    """One level of detail (``Client.get_lod``).

    Attributes:
        header: the level and its counts.
        positions: FORM_POSED: V×3 float32 vertex positions; None for the animation-space form.
        influence_offsets: animation-space form: (V+1,) uint32 CSR offsets into the influences.
        bone_indices: animation-space form: (I,) uint32, increasing within a vertex.
        animation_positions: animation-space form: I×4 float32 p_j (homogeneous, Σ_j p_j.w = 1).
        geomorph_delta: I×4 float32 Δp = p^{l+1} − p^l towards the next coarser level (§7.3,
            eq. 7.1) when requested, else None.
        indices: F×3 uint32 vertex indices, counter-clockwise seen from outside.
        skeleton: animation-space form: the skeleton; None for the posed form.
        chunk_count, bytes_received: what the stream took (for transfer reports).
        texture_coordinates: with ``get_lod(..., texture_coordinates=True)`` (posed, any level of
            a model with an atlas): F×3×2 float32, ``[f, k]`` the (u, v) of corner k of face f
            (vertex ``indices[f, k]``), in [0, 1]², v up; per corner because a seam gives one
            vertex several UVs. None otherwise.
    """

    __repr__ = compact_repr

    header: LodHeader
    positions: Optional[np.ndarray]
    influence_offsets: Optional[np.ndarray]
    bone_indices: Optional[np.ndarray]
    animation_positions: Optional[np.ndarray]
    geomorph_delta: Optional[np.ndarray]
    indices: np.ndarray
    skeleton: Optional[Skeleton]
    chunk_count: int = 0
    bytes_received: int = 0
    texture_coordinates: Optional[np.ndarray] = None

    @property
    def vertex_count(self) -> int:
        return self.header.vertex_count

    @property
    def face_count(self) -> int:
        return self.header.face_count

    def pose(self, transforms: Optional[npt.ArrayLike] = None, *, space: str = "global",
             geomorph: float = 0.0) -> np.ndarray:
        """Skins an animation-space level on the client: v_i = Σ_{j ∈ infl(i)} G_j p_ij (Merry 2007
        eq. 3.1), V×3 float32.

        Args:
            transforms: B×3×4 or B×4×4 bone transforms (G_j for "global", L_j for "local");
                None poses the rest pose G_j = Ĝ_j. For a posed-form mesh only None is allowed
                (its positions are returned).
            space: "global" or "local".
            geomorph: t ∈ [0, 1]: draw p + t·Δp, morphing towards the next coarser level (§7.3);
                needs a mesh fetched with ``include_geomorph``.

        Precision: float64 accumulation, float32 result (the wire's precision).
        """
        if self.header.form == "posed":
            if transforms is not None:
                raise ValueError("transforms: a FORM_POSED mesh is already posed; fetch form='animation_space' "
                                 "to pose it on the client")
            assert self.positions is not None
            return self.positions
        assert self.skeleton is not None and self.animation_positions is not None
        assert self.bone_indices is not None and self.influence_offsets is not None
        if space not in wire.SPACES:
            raise ValueError(f"space: expected 'global' or 'local', got {space!r}")
        if transforms is None:
            G = self.skeleton.rest_transforms.astype(np.float64)
        elif space == "local":
            G = self.skeleton.global_transforms(transforms).astype(np.float64)
        else:
            G = wire.as_transforms("transforms", transforms).astype(np.float64)
        if G.shape[0] != self.header.bone_count:
            raise ValueError(f"transforms: expected shape ({self.header.bone_count}, 3, 4), got {G.shape}")
        if not 0.0 <= geomorph <= 1.0:
            raise ValueError(f"geomorph: expected t in [0, 1], got {geomorph}")
        p = self.animation_positions.astype(np.float64)
        if geomorph:
            if self.geomorph_delta is None:
                raise ValueError("geomorph: this mesh was fetched without include_geomorph")
            p = p + geomorph * self.geomorph_delta
        per_influence = np.einsum("irc,ic->ir", G[self.bone_indices.astype(np.intp)], p)
        counts = np.diff(self.influence_offsets.astype(np.int64))
        vertex_of = np.repeat(np.arange(self.header.vertex_count), counts)
        out = np.empty((self.header.vertex_count, 3), dtype=np.float32)
        for c in range(3):
            out[:, c] = np.bincount(vertex_of, weights=per_influence[:, c], minlength=self.header.vertex_count)
        return out

    def to_obj(self, transforms: Optional[npt.ArrayLike] = None, *, space: str = "global",
               geomorph: float = 0.0) -> str:
        """The level as Wavefront OBJ text, posed by :meth:`pose` (same arguments; the rest pose
        by default): a comment naming the level, ``v x y z`` per vertex (``%.9g``, which
        round-trips float32) and ``f a b c`` per face, counting from 1 as OBJ does."""
        h = self.header
        out = io.StringIO()
        out.write(f"# animspace LOD level {h.level} of {h.level_count}, model version {h.model_version}, "
                  f"epsilon {h.epsilon:.9g}: {h.vertex_count} vertices, {h.face_count} faces\n")
        np.savetxt(out, self.pose(transforms, space=space, geomorph=geomorph).astype(np.float64),
                   fmt="v %.9g %.9g %.9g")
        np.savetxt(out, self.indices.astype(np.int64) + 1, fmt="f %d %d %d")
        return out.getvalue()

    def save(self, path: Union[str, "os.PathLike[str]"], transforms: Optional[npt.ArrayLike] = None, *,
             space: str = "global", geomorph: float = 0.0) -> None:
        """Writes :meth:`to_obj` to ``path``, which must name a ``.obj`` file (like
        ``Thumbnail.save`` writes its PNG).

        Raises:
            ValueError: for another extension (only OBJ is written; the C++ CLI's ``animspace
                lod`` also writes PLY and glTF).
        """
        name = pathlib.Path(path).name
        if not name.lower().endswith(".obj"):
            raise ValueError(f"path: expected a .obj file, got {name!r}")
        text = self.to_obj(transforms, space=space, geomorph=geomorph)
        with open(path, "w") as out:
            out.write(text)


class LodAssembler:
    """Takes GetLod's chunks one at a time and builds a :class:`LodMesh` (see the module doc)."""

    def __init__(self) -> None:
        self._header: Optional[lod_pb2.LodHeader] = None
        self._skeleton: Optional[lod_pb2.Skeleton] = None
        self._has_geomorph = False
        self._vertices = 0
        self._faces = 0
        self._influences = 0
        self._positions: List[bytes] = []
        self._offsets: List[np.ndarray] = [np.zeros(1, dtype=np.uint32)]
        self._bones: List[np.ndarray] = []
        self._animation_positions: List[bytes] = []
        self._geomorph: List[bytes] = []
        self._indices: List[np.ndarray] = []
        self._uvs: List[bytes] = []
        self.chunk_count = 0
        self.bytes_received = 0

    def take(self, chunk: lod_pb2.LodChunk) -> str:
        """Takes one chunk; returns what is wrong with it, or "" when it fits."""
        self.chunk_count += 1
        self.bytes_received += chunk.ByteSize()
        payload = chunk.WhichOneof("payload")
        if self._header is None and payload != "header":
            return f"the first chunk must be the header, got payload {payload}"
        if payload == "header":
            return self._take_header(chunk.header)
        if payload == "vertices":
            return self._take_vertices(chunk.vertices)
        if payload == "faces":
            return self._take_faces(chunk.faces)
        if payload == "skeleton":
            return self._take_skeleton(chunk.skeleton)
        return "a chunk without a payload"

    def _animation_space(self) -> bool:
        return self._header is not None and self._header.form == lod_pb2.GetLodRequest.FORM_ANIMATION_SPACE

    def _take_header(self, h: lod_pb2.LodHeader) -> str:
        if self._header is not None:
            return "a second header"
        if h.form not in (lod_pb2.GetLodRequest.FORM_ANIMATION_SPACE, lod_pb2.GetLodRequest.FORM_POSED):
            return f"header.form: expected FORM_ANIMATION_SPACE or FORM_POSED, got {h.form}"
        self._header = h
        return ""

    def _take_vertices(self, b: lod_pb2.VertexBlock) -> str:
        h = self._header
        assert h is not None
        at = f"vertex block at {b.first_vertex}"
        if self._faces > 0 or self._skeleton is not None:
            return f"{at}: vertex blocks must come before faces and the skeleton"
        if b.first_vertex != self._vertices:
            return f"{at}: expected first_vertex {self._vertices} (blocks in order, contiguous)"
        n = b.vertex_count
        if n == 0 or b.first_vertex + n > h.vertex_count:
            return f"{at}: vertex_count {n} does not fit in the header's {h.vertex_count} vertices"
        if not self._animation_space():
            p = b.positions
            if p.point_count != n or p.channel_count != 3 or len(p.data) != n * 12:
                return (f"{at}: positions must be {n} × 3 float32 ({n * 12} bytes), got {p.point_count} × "
                        f"{p.channel_count} in {len(p.data)} bytes")
            self._positions.append(p.data)
            self._vertices += n
            return ""
        if len(b.influence_offsets) != (n + 1) * 4:
            return f"{at}: influence_offsets must be {n + 1} uint32, got {len(b.influence_offsets)} bytes"
        offsets = np.frombuffer(b.influence_offsets, dtype=wire.WIRE_UINT32).astype(np.uint32)
        if offsets[0] != 0:
            return f"{at}: influence_offsets must start at 0"
        decreasing = np.flatnonzero(np.diff(offsets.astype(np.int64)) < 0)
        if decreasing.size:
            return f"{at}: influence_offsets decrease at entry {int(decreasing[0]) + 1}"
        count = int(offsets[-1])
        if len(b.bone_indices) != count * 4 or len(b.animation_positions) != count * 16:
            return (f"{at}: {count} influences need {count * 4} bytes of bone_indices and {count * 16} of "
                    f"animation_positions, got {len(b.bone_indices)} and {len(b.animation_positions)}")
        # Geomorph data is all or nothing: the first block decides.
        morph = len(b.geomorph_delta) > 0
        if self._vertices == 0:
            self._has_geomorph = morph
        if morph != self._has_geomorph or (morph and len(b.geomorph_delta) != count * 16):
            return (f"{at}: geomorph_delta must be {count * 16 if self._has_geomorph else 0} bytes, "
                    f"got {len(b.geomorph_delta)}")
        if self._influences + count > h.influence_count:
            return f"{at}: more influences than the header's {h.influence_count}"
        bones = np.frombuffer(b.bone_indices, dtype=wire.WIRE_UINT32).astype(np.uint32)
        bad = np.flatnonzero(bones >= h.bone_count)
        if bad.size:
            return f"{at}: bone index {int(bones[bad[0]])} is not below bone_count {h.bone_count}"
        self._bones.append(bones)
        self._offsets.append(offsets[1:] + np.uint32(self._influences))
        self._animation_positions.append(b.animation_positions)
        if morph:
            self._geomorph.append(b.geomorph_delta)
        self._influences += count
        self._vertices += n
        return ""

    def _take_faces(self, b: lod_pb2.FaceBlock) -> str:
        h = self._header
        assert h is not None
        at = f"face block at {b.first_face}"
        if self._vertices != h.vertex_count:
            return f"{at}: faces must follow every vertex block"
        if self._skeleton is not None:
            return f"{at}: faces must come before the skeleton"
        if b.first_face != self._faces:
            return f"{at}: expected first_face {self._faces} (blocks in order, contiguous)"
        if b.face_count == 0 or b.first_face + b.face_count > h.face_count:
            return f"{at}: face_count {b.face_count} does not fit in the header's {h.face_count} faces"
        if len(b.indices) != b.face_count * 12:
            return f"{at}: indices must be {b.face_count * 12} bytes, got {len(b.indices)}"
        uv_bytes = b.face_count * 24 if h.texture_coordinates else 0
        if len(b.texture_coordinates) != uv_bytes:
            state = "set" if h.texture_coordinates else "unset"
            return (f"{at}: texture_coordinates must be {uv_bytes} bytes (header.texture_coordinates {state}), "
                    f"got {len(b.texture_coordinates)}")
        indices = np.frombuffer(b.indices, dtype=wire.WIRE_UINT32).astype(np.uint32)
        bad = np.flatnonzero(indices >= h.vertex_count)
        if bad.size:
            return f"{at}: vertex index {int(indices[bad[0]])} is not below vertex_count {h.vertex_count}"
        self._indices.append(indices)
        if h.texture_coordinates:
            self._uvs.append(b.texture_coordinates)
        self._faces += b.face_count
        return ""

    def _take_skeleton(self, s: lod_pb2.Skeleton) -> str:
        h = self._header
        assert h is not None
        if not self._animation_space():
            return "a skeleton in a FORM_POSED stream"
        if self._skeleton is not None:
            return "a second skeleton"
        if self._vertices != h.vertex_count or self._faces != h.face_count:
            return "the skeleton must follow every vertex and face block"
        if (len(s.parents) != h.bone_count or len(s.rest_transforms) != h.bone_count * 48
                or (len(s.bone_names) != 0 and len(s.bone_names) != h.bone_count)):
            return (f"skeleton: expected {h.bone_count} parents, {h.bone_count * 48} bytes of rest_transforms and "
                    f"no or as many names, got {len(s.parents)}, {len(s.rest_transforms)} and {len(s.bone_names)}")
        self._skeleton = s
        return ""

    def complete(self) -> str:
        """After the stream ended cleanly: what is missing, or "" when everything announced arrived."""
        h = self._header
        if h is None:
            return "the stream ended without a header"
        if self._vertices != h.vertex_count:
            return f"the stream ended after {self._vertices} of {h.vertex_count} vertices"
        if self._faces != h.face_count:
            return f"the stream ended after {self._faces} of {h.face_count} faces"
        if self._animation_space() and self._influences != h.influence_count:
            return f"the vertex blocks carry {self._influences} influences, the header says {h.influence_count}"
        if self._animation_space() and self._skeleton is None:
            return "the stream ended without the skeleton"
        return ""

    def mesh(self) -> LodMesh:
        """The reassembled mesh; call only after :meth:`complete` returned ""."""
        h = self._header
        assert h is not None and self.complete() == ""
        indices = (np.concatenate(self._indices) if self._indices else np.zeros(0, dtype=np.uint32)).reshape(-1, 3)
        if not self._animation_space():
            positions = np.frombuffer(b"".join(self._positions), dtype=wire.WIRE_FLOAT).astype(np.float32)
            uvs = None
            if h.texture_coordinates:
                uvs = np.frombuffer(b"".join(self._uvs), dtype=wire.WIRE_FLOAT).astype(np.float32).reshape(-1, 3, 2)
            return LodMesh(header=LodHeader.from_proto(h), positions=positions.reshape(-1, 3), influence_offsets=None,
                           bone_indices=None, animation_positions=None, geomorph_delta=None, indices=indices,
                           skeleton=None, chunk_count=self.chunk_count, bytes_received=self.bytes_received,
                           texture_coordinates=uvs)
        assert self._skeleton is not None
        s = self._skeleton
        skeleton = Skeleton(parents=np.array(s.parents, dtype=np.int32),
                            rest_transforms=wire.transforms_from(s.rest_transforms, h.bone_count,
                                                                 "skeleton.rest_transforms"),
                            bone_names=tuple(s.bone_names))

        def floats4(blocks: List[bytes]) -> np.ndarray:
            return np.frombuffer(b"".join(blocks), dtype=wire.WIRE_FLOAT).astype(np.float32).reshape(-1, 4)

        return LodMesh(header=LodHeader.from_proto(h), positions=None,
                       influence_offsets=np.concatenate(self._offsets).astype(np.uint32),
                       bone_indices=(np.concatenate(self._bones) if self._bones else np.zeros(0, dtype=np.uint32)),
                       animation_positions=floats4(self._animation_positions),
                       geomorph_delta=floats4(self._geomorph) if self._has_geomorph else None,
                       indices=indices, skeleton=skeleton, chunk_count=self.chunk_count,
                       bytes_received=self.bytes_received)
