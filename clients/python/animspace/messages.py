"""Plain Python types for what the server returns (and the few structured inputs it takes).

Each result is a frozen dataclass built from its animspace.v1 message by a ``from_proto``
classmethod: arrays arrive as numpy arrays in their natural shapes (N×D float32 points, uint32
indices), enums as short upper-case names (``"HIT"``, ``"PMSC"``, ``"SERVER"``), so that code
using the client never touches protobuf. Dataclasses holding arrays are declared with
``eq=False``: numpy's element-wise ``==`` has no truth value, so they compare by identity.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from animspace import wire
from animspace.coordinates import SubspaceCoordinates
from animspace.display import compact_repr
from animspace.v1 import common_pb2, models_pb2, poses_pb2, render_pb2, stats_pb2, training_pb2

__all__ = [
    "Camera",
    "KeyPointPose",
    "ModelVersion",
    "ModelSummary",
    "ServerInfo",
    "HistogramData",
    "ModelStats",
    "Stats",
    "KeyPoints",
    "RegionError",
    "PoseResult",
    "MissCompletion",
    "SkinnedPose",
    "Thumbnail",
    "RetrainResult",
]


def enum_name(enum_type, value: int, prefix: str) -> str:
    """``CACHE_STATUS_HIT`` → ``"HIT"``; an enum value this client does not know → its number."""
    try:
        name = enum_type.Name(value)
    except ValueError:
        return str(value)
    return name[len(prefix):] if name.startswith(prefix) else name


def _status(value: int) -> str:
    return enum_name(common_pb2.CacheStatus, value, "CACHE_STATUS_")


def _fail_through(value: int) -> str:
    return enum_name(common_pb2.FailThrough, value, "FAIL_THROUGH_")


# ----------------------------------------------------------------------------------------------
# Inputs


@dataclass(frozen=True)
class Camera:
    """A perspective camera for thumbnails, in the model's object frame (common.proto Camera).

    ``up`` need not be normalised but must not be parallel to ``target − eye``;
    ``vertical_fov_rad`` lies in (0, π).
    """

    eye: Tuple[float, float, float]
    target: Tuple[float, float, float]
    up: Tuple[float, float, float] = (0.0, 1.0, 0.0)
    vertical_fov_rad: float = 0.8

    def to_proto(self) -> common_pb2.Camera:
        for name in ("eye", "target", "up"):
            value = getattr(self, name)
            if len(value) != 3:
                raise ValueError(f"camera.{name}: expected 3 floats, got {len(value)}")
        return common_pb2.Camera(eye=[float(v) for v in self.eye], target=[float(v) for v in self.target],
                                 up=[float(v) for v in self.up], vertical_fov_rad=float(self.vertical_fov_rad))


@dataclass(frozen=True)
class PointLight:
    """A point light for an illumination model (poses.proto PointLight; Meyer & Anderson 2007
    §3.2): ``position`` in the model's units (metres for the Cornell box), ``intensity`` the RGB
    radiant intensity in W/sr, None for the model's training intensity."""

    position: Tuple[float, float, float]
    intensity: Optional[Tuple[float, float, float]] = None

    def to_proto(self, name: str) -> poses_pb2.PointLight:
        position = [float(v) for v in self.position]
        if len(position) != 3:
            raise ValueError(f"{name}.position: expected 3 floats, got {len(position)}")
        light = poses_pb2.PointLight(position=position)
        if self.intensity is not None:
            intensity = [float(v) for v in self.intensity]
            if len(intensity) != 3:
                raise ValueError(f"{name}.intensity: expected 3 floats (R, G, B), got {len(intensity)}")
            light.intensity.extend(intensity)
        return light


def light_set(name: str, lights: Union["PointLight", Sequence["PointLight"], npt.ArrayLike]) -> poses_pb2.LightSet:
    """A LightSet from one PointLight, a sequence of them, or an L×3 (or 3) array of positions at
    the model's training intensity."""
    if isinstance(lights, PointLight):
        lights = [lights]
    elif not (isinstance(lights, (list, tuple)) and lights and all(isinstance(x, PointLight) for x in lights)):
        positions = np.asarray(lights, dtype=np.float64)
        if positions.shape == (3,):
            positions = positions[np.newaxis]
        if positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] == 0:
            raise ValueError(f"{name}: expected PointLight(s) or an L×3 array of positions, got shape "
                             f"{wire.shape_text(positions.shape)}")
        lights = [PointLight(tuple(float(v) for v in p)) for p in positions]
    message = poses_pb2.LightSet()
    for i, light in enumerate(lights):
        message.lights.append(light.to_proto(f"{name}[{i}]"))
    return message


@dataclass(frozen=True)
class IlluminationView:
    """How a thumbnail of an illumination model shows its radiance (render.proto IlluminationView).

    ``radiance`` is "total" (direct, computed by the server for the lights, plus the served
    indirect) or "indirect"; ``white_radiance`` the radiance drawn white (0: the 99th percentile
    of the drawn points); ``heat_from_full_gather`` draws |full − served| instead, with the full
    indirect illumination gathered by the server (as slow as a full calculation).
    """

    radiance: str = "total"
    white_radiance: float = 0.0
    heat_from_full_gather: bool = False

    def to_proto(self) -> render_pb2.IlluminationView:
        values = {"total": render_pb2.IlluminationView.RADIANCE_TOTAL,
                  "indirect": render_pb2.IlluminationView.RADIANCE_INDIRECT}
        if self.radiance not in values:
            raise ValueError(f"illumination.radiance: expected 'total' or 'indirect', got {self.radiance!r}")
        return render_pb2.IlluminationView(radiance=values[self.radiance], white_radiance=float(self.white_radiance),
                                           heat_from_full_gather=self.heat_from_full_gather)


@dataclass(frozen=True, eq=False)
class KeyPointPose:
    """One frame for the soft cache: K×D key values, optionally its C×D check values and the
    skeleton pose they came from.

    The check values (``KeyPoints.check_point_indices`` order, computed like the key values;
    ``KeyPoints.pose`` gathers both from a full frame) let the server measure the estimate's error
    where the key points are blind: a HIT the key points alone give can become BLEND or MISS.
    None (or an empty array): the verdict rests on e_key alone. The skeleton pose (B×3×4 or
    B×4×4, in ``space``) lets a model with a server posing engine (fail-through ``SERVER``)
    complete a blend or miss itself (Meyer & Anderson 2007 §2: the full calculation runs only when
    the cache cannot be trusted).
    """

    __repr__ = compact_repr

    key_values: npt.ArrayLike
    skeleton_pose: Optional[npt.ArrayLike] = None
    space: str = "global"
    check_values: Optional[npt.ArrayLike] = None

    def to_proto(self, name: str) -> poses_pb2.KeyPointPose:
        """The pose as a message; ``name`` (e.g. "frames[3]") prefixes the argument names in
        shape errors."""
        if self.skeleton_pose is None and self.check_values is None:
            return poses_pb2.KeyPointPose(key_values=wire.point_array(name, self.key_values, points_label="K"))
        pose = poses_pb2.KeyPointPose(
            key_values=wire.point_array(f"{name}.key_values", self.key_values, points_label="K"))
        checks = check_point_array(f"{name}.check_values", self.check_values)
        if checks is not None:
            pose.check_values.CopyFrom(checks)
        if self.skeleton_pose is not None:
            pose.skeleton_pose.CopyFrom(wire.skeleton_pose(f"{name}.skeleton_pose", self.skeleton_pose, self.space))
        return pose


def check_point_array(name: str, check_values: Optional[npt.ArrayLike]) -> Optional[common_pb2.PointArray]:
    """C×D check values as a ``PointArray``, or None for no check values (None, or no points: a
    model without check points, whose ``KeyPoints.select_check_values`` is C = 0 rows)."""
    if check_values is None:
        return None
    array = wire.as_points(name, check_values, points_label="C")
    return None if array.shape[0] == 0 else wire.point_array(name, array, points_label="C")


# ----------------------------------------------------------------------------------------------
# Models and the server


@dataclass(frozen=True)
class ModelVersion:
    """One version of a model as the registry holds it (models.proto ModelVersion).

    ``state`` is "AVAILABLE", "FAILED" (then ``error`` says why) or "EVICTED" (served, but unloaded
    to keep the server within its ``--memory-budget``: the next request for it loads it again;
    issue #53); ``resident_bytes`` is the heap the version holds while loaded. ``kind`` is "PMSC",
    "CROSS_PMSC", "ANIMATION_SPACE" or "MESH_SEQUENCE"; ``fail_through`` is "SERVER", "CLIENT",
    "IMPOSSIBLE" or "UNSPECIFIED" (a model without a soft cache); with "SERVER", ``server_engine``
    says which full calculation the server runs: "ANIMATION_SPACE" (send skeleton poses) or
    "ILLUMINATION" (send lights), else "UNSPECIFIED". ε_min ≤ ε_max bound the error estimate of a
    hit and of a blend (Meyer & Anderson 2006 §5; ``PoseResult.error_estimate``), model units.

    ``check_point_count`` is C, the check points a client sends beside the key points (0 for a
    model without them). ``false_hit_rate`` is the δ ε was calibrated for (0: not calibrated),
    ``calibration_bad_samples`` the over-tolerance samples it rests on (of which
    ``calibration_real_bad_samples`` held-out frames over the tolerance themselves, the rest
    residuals under it scaled up to it),
    ``calibration_guarantee_holds`` whether they back δ, and ``calibration_statement`` the
    server's sentence for operators: what a HIT means for this model, or why nothing is
    guaranteed. ``relative_tolerance`` (issue #38): ε and every error a ``PoseResult`` reports are
    fractions of each pose's own scale (``PoseResult.pose_scale``), not model units, so a HIT
    means the same at any intensity. ``subspace_kind`` (issue #51): "LINEAR" (principal components
    of the training frames) or "ARTICULATED" (``subspace_bone_count`` bones' transforms, 12
    coordinates each, then ``residual_components`` principal components of what the skinning
    leaves), "UNSPECIFIED" for a model that is not PMSC or a server from before.
    """

    version: int
    state: str
    error: str
    kind: str
    description: str
    point_count: int
    channel_count: int
    face_count: int
    bone_count: int
    key_point_count: int
    basis_size: int
    frame_count: int
    lod_level_count: int
    epsilon_min: float
    epsilon_max: float
    fail_through: str
    file_size_bytes: int
    loaded_at_unix_s: int
    metadata: Dict[str, str] = field(hash=False)
    sections: Tuple[str, ...]
    server_engine: str = "UNSPECIFIED"
    check_point_count: int = 0
    false_hit_rate: float = 0.0
    calibration_bad_samples: int = 0
    calibration_real_bad_samples: int = 0
    calibration_guarantee_holds: bool = False
    calibration_statement: str = ""
    relative_tolerance: bool = False
    subspace_kind: str = "UNSPECIFIED"
    subspace_bone_count: int = 0
    residual_components: int = 0
    resident_bytes: int = 0

    @classmethod
    def from_proto(cls, m: models_pb2.ModelVersion) -> "ModelVersion":
        return cls(version=m.version, state=enum_name(models_pb2.VersionState, m.state, "VERSION_STATE_"),
                   error=m.error, kind=enum_name(models_pb2.ModelKind, m.kind, "MODEL_KIND_"),
                   description=m.description, point_count=m.point_count, channel_count=m.channel_count,
                   face_count=m.face_count, bone_count=m.bone_count, key_point_count=m.key_point_count,
                   basis_size=m.basis_size, frame_count=m.frame_count, lod_level_count=m.lod_level_count,
                   epsilon_min=m.epsilon_min, epsilon_max=m.epsilon_max, fail_through=_fail_through(m.fail_through),
                   file_size_bytes=m.file_size_bytes, loaded_at_unix_s=m.loaded_at_unix_s,
                   metadata=dict(m.metadata), sections=tuple(m.sections),
                   server_engine=enum_name(models_pb2.ServerEngine, m.server_engine, "SERVER_ENGINE_"),
                   check_point_count=m.check_point_count, false_hit_rate=m.false_hit_rate,
                   calibration_bad_samples=m.calibration_bad_samples,
                   calibration_real_bad_samples=m.calibration_real_bad_samples,
                   calibration_guarantee_holds=m.calibration_guarantee_holds,
                   calibration_statement=m.calibration_statement,
                   relative_tolerance=m.relative_tolerance,
                   subspace_kind=enum_name(models_pb2.SubspaceKind, m.subspace_kind, "SUBSPACE_KIND_"),
                   subspace_bone_count=m.subspace_bone_count, residual_components=m.residual_components,
                   resident_bytes=m.resident_bytes)


@dataclass(frozen=True)
class ModelSummary:
    """A model with every version found in the repository, ascending (refused ones included)."""

    name: str
    default_version: int
    versions: Tuple[ModelVersion, ...]

    @property
    def default(self) -> Optional[ModelVersion]:
        """The version a request naming version 0 gets (None when no version is serving)."""
        return next((v for v in self.versions if v.version == self.default_version), None)

    @classmethod
    def from_proto(cls, m: models_pb2.ModelSummary) -> "ModelSummary":
        return cls(name=m.name, default_version=m.default_version,
                   versions=tuple(ModelVersion.from_proto(v) for v in m.versions))


@dataclass(frozen=True)
class ServerInfo:
    """Server build, limits and uptime (models.proto GetServerInfoResponse), to size requests."""

    server_version: str
    api: str
    started_at_unix_s: int
    max_message_bytes: int
    max_batch_poses: int
    max_thumbnail_px: int
    max_concurrent_calls: int
    renderer: str
    implemented_rpcs: Tuple[str, ...]
    grpc_memory_bytes: int  # memory for requests still arriving, all connections; 0 = unbounded
    kernel: str = ""  # the dense products' kernel, e.g. "openblas:haswell" or "eigen:sse2"
    max_batch_size: int = 0  # dynamic batching: most poses reconstructed as one product
    batch_delay_us: int = 0  # how long a batch may wait to fill (0: only poses already waiting)

    @classmethod
    def from_proto(cls, m: models_pb2.GetServerInfoResponse) -> "ServerInfo":
        return cls(server_version=m.server_version, api=m.api, started_at_unix_s=m.started_at_unix_s,
                   max_message_bytes=m.max_message_bytes, max_batch_poses=m.max_batch_poses,
                   max_thumbnail_px=m.max_thumbnail_px, max_concurrent_calls=m.max_concurrent_calls,
                   renderer=m.renderer, implemented_rpcs=tuple(m.implemented_rpcs),
                   grpc_memory_bytes=m.grpc_memory_bytes, kernel=m.kernel, max_batch_size=m.max_batch_size,
                   batch_delay_us=m.batch_delay_us)


@dataclass(frozen=True, eq=False)
class HistogramData:
    """A Prometheus-style histogram: ``counts[i]`` counts observations ≤ ``upper_bounds[i]``;
    the last count (one beyond the bounds) is the +Inf bucket. Counts are not cumulative."""

    __repr__ = compact_repr

    upper_bounds: np.ndarray  # (K,) float64
    counts: np.ndarray  # (K + 1,) uint64
    total_count: int
    sum: float

    @classmethod
    def from_proto(cls, m: common_pb2.Histogram) -> "HistogramData":
        return cls(upper_bounds=np.array(m.upper_bounds, dtype=np.float64), counts=np.array(m.counts, dtype=np.uint64),
                   total_count=m.total_count, sum=m.sum)


@dataclass(frozen=True)
class ModelStats:
    """Soft-cache and latency statistics of one model since start or the last reset."""

    model: str
    requests: int
    poses: int
    hits: int
    blends: int
    misses: int
    errors: int
    hit_rate: float
    key_point_error: HistogramData = field(hash=False)
    latency_seconds: HistogramData = field(hash=False)
    latency_p50_s: float
    latency_p90_s: float
    latency_p99_s: float

    @classmethod
    def from_proto(cls, m: stats_pb2.ModelStats) -> "ModelStats":
        return cls(model=m.model, requests=m.requests, poses=m.poses, hits=m.hits, blends=m.blends, misses=m.misses,
                   errors=m.errors, hit_rate=m.hit_rate, key_point_error=HistogramData.from_proto(m.key_point_error),
                   latency_seconds=HistogramData.from_proto(m.latency_seconds), latency_p50_s=m.latency_p50_s,
                   latency_p90_s=m.latency_p90_s, latency_p99_s=m.latency_p99_s)


@dataclass(frozen=True)
class Stats:
    """Every model's statistics, by name, and when counting started."""

    models: Dict[str, ModelStats] = field(hash=False)
    since_unix_s: int

    @classmethod
    def from_proto(cls, m: stats_pb2.GetStatsResponse) -> "Stats":
        return cls(models={s.model: ModelStats.from_proto(s) for s in m.models}, since_unix_s=m.since_unix_s)


# ----------------------------------------------------------------------------------------------
# Poses


@dataclass(frozen=True, eq=False)
class KeyPoints:
    """The key points a posing engine must compute for a PMSC model, in request order.

    ``indices`` (K,) uint32 index the model's full point set (for cross-PMSC, its control point
    set of ``control_point_count`` points); fiducial seeds come first (Meyer & Anderson 2007 §2.3).
    ``regions`` (K,) uint32 is empty unless the model has regions (local fail-through).
    ``check_point_indices`` (C,) uint32 index the same point set: check points, computed like key
    points and sent as ``check_values`` in this order (the projection never uses them; the server
    measures the estimate's error there, and a HIT the key points alone give can become BLEND or
    MISS); empty for a model without check points. ``check_point_regions`` (C,) as ``regions``.
    ``basis_checksum`` and ``basis_sha256`` name the version's subspace as GetBasis does (0 and
    b"" without one): a cached basis is checked against the digest before it is used.
    Pin ``model_version`` in later calls to keep using these indices across a retrain.
    """

    __repr__ = compact_repr

    model_version: int
    indices: np.ndarray
    channel_count: int
    control_point_count: int
    regions: np.ndarray
    fail_through: str
    check_point_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint32))
    check_point_regions: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint32))
    basis_checksum: int = 0
    basis_sha256: bytes = b""

    @property
    def count(self) -> int:
        """K, the number of key points."""
        return int(self.indices.shape[0])

    @property
    def check_point_count(self) -> int:
        """C, the number of check points (0 for a model without them)."""
        return int(self.check_point_indices.shape[0])

    def _gather(self, points: npt.ArrayLike, indices: np.ndarray) -> np.ndarray:
        array = np.asarray(points, dtype=np.float32)
        if array.ndim not in (2, 3) or array.shape[-2] != self.control_point_count:
            want = f"({self.control_point_count}, D) or (P, {self.control_point_count}, D)"
            raise ValueError(f"points: expected shape {want}, got {wire.shape_text(array.shape)}")
        return np.ascontiguousarray(array[..., indices.astype(np.intp), :])

    def select(self, points: npt.ArrayLike) -> np.ndarray:
        """The key values of full pose(s): ``points[..., indices, :]`` of N×D or P×N×D float32.

        Raises:
            ValueError: when ``points`` does not hold ``control_point_count`` points.
        """
        return self._gather(points, self.indices)

    def select_check_values(self, points: npt.ArrayLike) -> np.ndarray:
        """The check values of full pose(s): ``points[..., check_point_indices, :]`` (C×D or P×C×D
        float32; C = 0 rows for a model without check points). Raises as ``select``."""
        return self._gather(points, self.check_point_indices)

    def pose(self, points: npt.ArrayLike, skeleton_pose: Optional[npt.ArrayLike] = None,
             space: str = "global") -> KeyPointPose:
        """One full frame (N×D) as the pose a client sends: its key values and its check values."""
        return KeyPointPose(self.select(points), skeleton_pose, space, self.select_check_values(points))

    @classmethod
    def from_proto(cls, m: poses_pb2.DescribeKeyPointsResponse) -> "KeyPoints":
        return cls(model_version=m.model_version, indices=np.array(m.key_point_indices, dtype=np.uint32),
                   channel_count=m.channel_count, control_point_count=m.control_point_count,
                   regions=np.array(m.key_point_regions, dtype=np.uint32), fail_through=_fail_through(m.fail_through),
                   check_point_indices=np.array(m.check_point_indices, dtype=np.uint32),
                   check_point_regions=np.array(m.check_point_regions, dtype=np.uint32),
                   basis_checksum=m.basis_checksum, basis_sha256=bytes(m.basis_sha256))


@dataclass(frozen=True)
class RegionError:
    """Error estimate of one region (local fail-through: only failing regions need the full pose):
    e_key over the region's key points, joined by its check points' e_check when they were sent."""

    region: int
    key_point_error: float
    status: str

    @classmethod
    def from_proto(cls, m: poses_pb2.RegionError) -> "RegionError":
        return cls(region=m.region, key_point_error=m.key_point_error, status=_status(m.status))


@dataclass(frozen=True, eq=False)
class PoseResult:
    """The soft cache's answer for one pose (Meyer & Anderson 2006 §5, "soft caching").

    Attributes:
        points: N×D float32: the subspace estimate for a hit, α·full + (1−α)·estimate for a blend,
            the full values for a miss — or the estimate with ``full_evaluation_needed`` when no
            full values were available. None when the request asked to omit points, and when the
            answer came as ``coordinates`` (unless the call reconstructed them: ``reconstruct=True``).
        status: "HIT" (e ≤ ε_min), "BLEND" or "MISS" (e ≥ ε_max), e = ``error_estimate``.
        key_point_error: e_key, RMS over key points and channels of f_key − f̂_key, model units.
        key_point_max_error: the worst key point's residual, max over key points of ‖f_k − f̂_k‖
            (issue #52).
        check_point_error: e_check, the largest distance ‖f_c − f̂_c‖ over the check points sent
            (0 unless ``checked``), model units.
        error_estimate: what the verdict compared with ε: max(w·k, e_check) when ``checked``, else
            k (against the model's stricter key-only thresholds when it has check points), k being
            ``key_point_max_error`` for a model trained since issue #52, else ``key_point_error``.
        checked: the pose was sent with check values (and the model has check points).
        pose_scale: for a model with ``relative_tolerance``, S, the pose's RMS point norm (model
            units) that the errors above are fractions of; 0 when they are in model units.
        blend_weight: α ∈ [0, 1]: 0 for a hit, 1 for a miss.
        model_version: the version that answered.
        full_evaluation_needed: a blend or miss whose points are still the estimate: compute the
            full pose and send it with ``Client.complete_miss`` (or accept the estimate).
        region_errors: per-region errors when requested and the model has regions.
        sequence: the frame's sequence number (streams only; 0 otherwise).
        full_points: local fail-through (requested; blend or miss): uint32 indices, ascending, of
            the points that need the full calculation — send their values with
            ``Client.complete_miss(..., full_points=...)``. Empty when every region is within
            tolerance (``points`` is then the answer) or local fail-through was not requested.
        full_point_blend_weights: float32 α_i ∈ (0, 1] of each of ``full_points``: point i of the
            answer is α_i·f_i + (1 − α_i)·f̂_i.
        points_max_error: with ``points_encoding`` "float16" or "fixed16": the largest
            |decoded − float32 value| over ``points``, measured by the server; 0 for float32.
        coordinates: with ``points_encoding="coordinates"``, for an answer the client can
            reconstruct (a HIT, or a BLEND/MISS with ``full_evaluation_needed``): p and, for an
            aligned model, R and t (``Client.reconstruct`` turns them into the points). None when
            the server sent ``points`` (it computed them itself: fail-through on the server).
    """

    __repr__ = compact_repr

    points: Optional[np.ndarray]
    status: str
    key_point_error: float
    blend_weight: float
    model_version: int
    full_evaluation_needed: bool
    region_errors: Tuple[RegionError, ...] = ()
    sequence: int = 0
    full_points: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint32))
    full_point_blend_weights: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    points_max_error: float = 0.0
    check_point_error: float = 0.0
    error_estimate: float = 0.0
    checked: bool = False
    coordinates: Optional[SubspaceCoordinates] = None
    pose_scale: float = 0.0
    key_point_max_error: float = 0.0

    @property
    def hit(self) -> bool:
        return self.status == "HIT"

    @classmethod
    def from_proto(cls, m: poses_pb2.PoseResult, what: str = "points") -> "PoseResult":
        points = wire.points_from(m.points, what) if m.HasField("points") else None
        coordinates = None
        if m.HasField("coordinates"):  # "results[0].points" → "results[0].coordinates"
            coordinates = SubspaceCoordinates.from_proto(m.coordinates, what.rsplit("points", 1)[0] + "coordinates")
        return cls(points=points, status=_status(m.status), key_point_error=m.key_point_error,
                   blend_weight=m.blend_weight, model_version=m.model_version,
                   full_evaluation_needed=m.full_evaluation_needed,
                   region_errors=tuple(RegionError.from_proto(r) for r in m.region_errors), sequence=m.sequence,
                   full_points=np.array(m.full_points, dtype=np.uint32),
                   full_point_blend_weights=np.array(m.full_point_blend_weights, dtype=np.float32),
                   points_max_error=m.points.max_error, check_point_error=m.check_point_error,
                   error_estimate=m.error_estimate, checked=m.checked, coordinates=coordinates,
                   pose_scale=m.pose_scale, key_point_max_error=m.key_point_max_error)


@dataclass(frozen=True, eq=False)
class MissCompletion:
    """``Client.complete_miss``'s answer: the blended/full result, and whether the miss was logged
    for retraining ("train each night, better tomorrow"); when a blend or miss was not,
    ``not_logged_reason`` says why (the server's miss log could not be written, e.g. a full disk).
    """

    __repr__ = compact_repr

    result: PoseResult
    logged: bool
    not_logged_reason: str = ""


@dataclass(frozen=True, eq=False)
class SkinnedPose:
    """One posed animation-space mesh, v = Σ_j G_j p_j (Merry 2007 §3.1).

    ``points`` N×3 float32 in model units; ``normals`` N×3 unit normals from the tangent planes
    (§3.5) when requested, else None.
    """

    __repr__ = compact_repr

    points: np.ndarray
    normals: Optional[np.ndarray]
    model_version: int


# ----------------------------------------------------------------------------------------------
# Thumbnails and retraining


@dataclass(frozen=True, eq=False)
class Thumbnail:
    """A rendered PNG (8-bit RGBA) and what was drawn.

    ``pose`` is the soft cache's verdict when the source was key points, else None;
    ``lod_level`` the level drawn (0 = full detail). With a heat map: ``heat_max_error`` the
    largest |full − estimate| and ``heat_scale_max`` the error drawn red (model units), and
    ``heat_legend_drawn`` whether the asked-for legend fitted on the image.
    """

    __repr__ = compact_repr

    png: bytes
    width_px: int
    height_px: int
    model_version: int
    lod_level: int
    pose: Optional[PoseResult]
    render_ms: float
    heat_max_error: float = 0.0
    heat_scale_max: float = 0.0
    heat_legend_drawn: bool = False

    def save(self, path: str) -> None:
        """Writes the PNG bytes to ``path``."""
        with open(path, "wb") as out:
            out.write(self.png)

    @classmethod
    def from_proto(cls, m: render_pb2.RenderThumbnailResponse) -> "Thumbnail":
        return cls(png=m.png, width_px=m.width_px, height_px=m.height_px, model_version=m.model_version,
                   lod_level=m.lod_level, pose=PoseResult.from_proto(m.pose, "pose.points") if m.HasField("pose") else None,
                   render_ms=m.render_ms, heat_max_error=m.heat_max_error, heat_scale_max=m.heat_scale_max,
                   heat_legend_drawn=m.heat_legend_drawn)


@dataclass(frozen=True)
class RetrainResult:
    """What a retrain built: ``new_version`` is 0 for a dry run.

    ε is recalibrated on every retrain, so the ``previous_*`` thresholds and hit rate (the version
    retrained from, on the same new training frames) show why the hit rate moved. ``unchanged``:
    no miss was folded in and no option changed, so the retrain reproduces the version it started
    from — reported by a dry run; a retrain that would publish it is refused (FailedPrecondition).
    """

    new_version: int
    training_frames: int
    misses_used: int
    basis_size: int
    key_point_count: int
    max_training_error: float
    condition_number: float
    training_seconds: float
    previous_epsilon_min: float = 0.0
    previous_epsilon_max: float = 0.0
    epsilon_min: float = 0.0
    epsilon_max: float = 0.0
    previous_hit_rate: float = 0.0
    hit_rate: float = 0.0
    misses_inconsistent: int = 0
    unchanged: bool = False

    @classmethod
    def from_proto(cls, m: training_pb2.RetrainResponse) -> "RetrainResult":
        return cls(new_version=m.new_version, training_frames=m.training_frames, misses_used=m.misses_used,
                   basis_size=m.basis_size, key_point_count=m.key_point_count,
                   max_training_error=m.max_training_error, condition_number=m.condition_number,
                   training_seconds=m.training_seconds, previous_epsilon_min=m.previous_epsilon_min,
                   previous_epsilon_max=m.previous_epsilon_max, epsilon_min=m.epsilon_min,
                   epsilon_max=m.epsilon_max, previous_hit_rate=m.previous_hit_rate, hit_rate=m.hit_rate,
                   misses_inconsistent=m.misses_inconsistent, unchanged=m.unchanged)

