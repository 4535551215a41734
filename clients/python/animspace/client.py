"""animspace.Client: a thin Python client for animspaced, numpy in and out.

The Python sibling of ``clients/cpp/client.h``: one method per RPC, a deadline on every call, the
bearer token on every call, and every failure raised as an :class:`~animspace.errors.RpcError`
subclass carrying the gRPC code and the server's message (which names the offending field).
Arrays go in as anything numpy can turn into float32 of the right shape and come out as numpy
arrays in plain frozen dataclasses (``animspace.messages``, ``animspace.lod``).

What the calls are for (Meyer & Anderson 2006, 2007; Merry 2007):
- PMSC soft cache: a posing engine computes only the K key points of a pose; the server
  reconstructs every point from the trained subspace and says whether the estimate can be
  trusted — HIT (e_key ≤ ε_min), BLEND, or MISS (e_key ≥ ε_max) — with the blend weight α.
- Animation space: v = Σ_j G_j p_j for any skeleton pose, and discrete levels of detail chosen
  by screen-space error (eq. 7.2).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import os
import time
import warnings
from typing import Any, Callable, Iterable, Iterator, List, Optional, Sequence, Tuple, TypeVar, Union

import grpc
import numpy as np
import numpy.typing as npt

from animspace import health as health_messages
from animspace import messages, wire
from animspace.coordinates import Basis, BasisAssembler, BasisCache
from animspace.coordinates import reconstruct as reconstruct_coordinates
from animspace.errors import BasisMismatch, DeadlineExceeded, ProtocolError, RpcError, Unavailable, error_from_grpc
from animspace.lod import FORMS, LodAssembler, LodMesh
from animspace.messages import (Camera, IlluminationView, KeyPointPose, KeyPoints, MissCompletion, ModelSummary,
                                PointLight, PoseResult, RetrainResult, ServerInfo, SkinnedPose, Stats, Thumbnail)
from animspace.v1 import (common_pb2, lod_pb2, lod_pb2_grpc, models_pb2, models_pb2_grpc, poses_pb2, poses_pb2_grpc,
                          render_pb2, render_pb2_grpc, skinning_pb2, skinning_pb2_grpc, stats_pb2, stats_pb2_grpc,
                          training_pb2, training_pb2_grpc)

__all__ = ["Client", "DEFAULT_DEADLINE_S", "DEFAULT_MAX_RECEIVE_MESSAGE_BYTES"]

# Same defaults as the C++ ClientOptions: 10 s per call, 64 MiB replies (a dense pose batch or a
# LOD block can be large; gRPC's own 4 MiB default is too small for a 100k-point batch).
DEFAULT_DEADLINE_S = 10.0
DEFAULT_MAX_RECEIVE_MESSAGE_BYTES = 64 << 20

_Response = TypeVar("_Response")
_Function = TypeVar("_Function", bound=Callable[..., Any])
Pem = Union[bytes, str]

_SHADING = {
    "blinn_phong": render_pb2.RenderThumbnailRequest.SHADING_BLINN_PHONG,
    "lambert": render_pb2.RenderThumbnailRequest.SHADING_LAMBERT,
}


def _renamed_keywords(**renamed: str) -> Callable[[_Function], _Function]:
    """Keeps the keyword names of an earlier release working for one more, with a
    DeprecationWarning: ``old="new"`` passes ``old=`` on as ``new=`` (same meaning, same units)."""

    def decorate(function: _Function) -> _Function:
        @functools.wraps(function)
        def call(*args: Any, **kwargs: Any) -> Any:
            for old, new in renamed.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{function.__name__}: give {new}, not both {new} and {old}")
                    warnings.warn(f"{function.__name__}: {old} is deprecated; use {new} (same meaning and units)",
                                  DeprecationWarning, stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return function(*args, **kwargs)

        return call  # type: ignore[return-value]

    return decorate


def _pem(value: Optional[Pem]) -> Optional[bytes]:
    return value.encode("ascii") if isinstance(value, str) else value


def _model_ref(name: str, version: int) -> common_pb2.ModelRef:
    if not isinstance(name, str) or not name:
        raise ValueError(f"model: expected a model name, got {name!r}")
    return common_pb2.ModelRef(name=name, version=wire.as_uint("version", version, 64))


@contextlib.contextmanager
def _decoding(rpc: str) -> Iterator[None]:
    """Turns a reply that cannot be decoded (a PointArray whose bytes do not match its counts)
    into a ProtocolError: the server never sends one, a proxy or a truncation could."""
    try:
        yield
    except ValueError as error:
        raise ProtocolError(rpc, str(error)) from error


def _assemble(rpc: str, call: Any, assembler: Any) -> Any:
    """Feeds a server stream's chunks to ``assembler`` (``take`` and ``complete`` name a problem or
    return None): a problem cancels the rest of the stream and raises ProtocolError."""
    try:
        for chunk in call:
            problem = assembler.take(chunk)
            if problem:
                call.cancel()  # the rest of the stream is of no use
                raise ProtocolError(rpc, problem)
    except grpc.RpcError as error:
        raise error_from_grpc(rpc, error) from error
    problem = assembler.complete()
    if problem:
        raise ProtocolError(rpc, problem)
    return assembler


def _point_array(array: np.ndarray) -> common_pb2.PointArray:
    """An N×D float32 array already checked by wire.as_points, packed as a PointArray."""
    return common_pb2.PointArray(point_count=array.shape[0], channel_count=array.shape[1],
                                 data=array.astype(wire.WIRE_FLOAT, copy=False).tobytes())


class Client:
    """A connection to animspaced. Use it as a context manager so the channel is closed::

        with animspace.Client("127.0.0.1:50051") as client:
            keys = client.describe_key_points("arm-pmsc")

    Args:
        target: a gRPC target ("host:port", "dns:///name:port", "unix:/path", …). Exactly one of
            ``target`` and ``channel`` must be given.
        channel: an existing ``grpc.Channel`` (interceptors, load balancing, credentials set up by
            the caller). The client does not close a channel it did not create.
        token: bearer token, sent as ``authorization: Bearer <token>`` metadata on every call
            (the daemon's ``--auth-token-file``; admin RPCs may need an admin token).
        deadline_s: deadline of every call, seconds; each method's ``deadline_s`` overrides it for
            that call. None: no deadline. For a stream it bounds the whole stream.
        max_receive_message_bytes: largest reply accepted, bytes.
        tls: use TLS. Implied by any of the TLS arguments below.
        root_certificates: PEM of the CA that signed the server's certificate (None: the
            system's roots).
        client_certificate, client_key: PEM of this client's certificate chain and key, for a
            server started with ``--tls-client-ca``. Both or neither.
        server_name: the name the server's certificate must carry, when it differs from the
            target's host (``grpc.ssl_target_name_override``).
        channel_options: further ``grpc`` channel arguments, e.g. ``[("grpc.enable_retries", 0)]``.
        basis_cache: where :meth:`reconstruct` keeps the bases it fetches: a :class:`BasisCache`
            (share one between clients), a folder, or None for the default folder
            ($ANIMSPACE_BASIS_CACHE, else $XDG_CACHE_HOME/animspace/bases, else
            ~/.cache/animspace/bases — the C++ client's too).

    A client may be shared by threads: gRPC channels and stubs are thread-safe, the basis cache
    takes a lock, and the client keeps no per-call state.
    """

    def __init__(self, target: Optional[str] = None, *, channel: Optional[grpc.Channel] = None,
                 token: Optional[str] = None, deadline_s: Optional[float] = DEFAULT_DEADLINE_S,
                 max_receive_message_bytes: int = DEFAULT_MAX_RECEIVE_MESSAGE_BYTES, tls: bool = False,
                 root_certificates: Optional[Pem] = None, client_certificate: Optional[Pem] = None,
                 client_key: Optional[Pem] = None, server_name: Optional[str] = None,
                 channel_options: Sequence[Tuple[str, Any]] = (),
                 basis_cache: Union[BasisCache, str, "os.PathLike[str]", None] = None) -> None:
        if (target is None) == (channel is None):
            raise ValueError("Client: give exactly one of target and channel")
        if deadline_s is not None and not deadline_s > 0:
            raise ValueError(f"deadline_s: expected seconds > 0 or None, got {deadline_s}")
        if (client_certificate is None) != (client_key is None):
            raise ValueError("client_certificate, client_key: give both or neither")
        if token is not None and (not token or any(not "!" <= c <= "~" for c in token)):
            # What a gRPC text metadata value can carry, and what animspaced's token files hold.
            raise ValueError("token: expected printable ASCII without spaces")
        self._target = target
        self._deadline_s = deadline_s
        self._basis_cache = basis_cache if isinstance(basis_cache, BasisCache) else BasisCache(basis_cache)
        self._metadata: Optional[Tuple[Tuple[str, str], ...]] = (
            (("authorization", f"Bearer {token}"),) if token is not None else None)
        self._owns_channel = channel is None
        self._closed = False
        if channel is None:
            assert target is not None
            options: List[Tuple[str, Any]] = [("grpc.max_receive_message_length", int(max_receive_message_bytes))]
            secure = tls or any(x is not None for x in (root_certificates, client_certificate, server_name))
            if server_name is not None:
                options.append(("grpc.ssl_target_name_override", server_name))
            options.extend(channel_options)
            if secure:
                credentials = grpc.ssl_channel_credentials(root_certificates=_pem(root_certificates),
                                                           private_key=_pem(client_key),
                                                           certificate_chain=_pem(client_certificate))
                channel = grpc.secure_channel(target, credentials, options=options)
            else:
                channel = grpc.insecure_channel(target, options=options)
        self._channel: grpc.Channel = channel
        self._models = models_pb2_grpc.ModelServiceStub(channel)
        self._stats = stats_pb2_grpc.StatsServiceStub(channel)
        self._poses = poses_pb2_grpc.PoseServiceStub(channel)
        self._skinning = skinning_pb2_grpc.SkinningServiceStub(channel)
        self._training = training_pb2_grpc.TrainingServiceStub(channel)
        self._lod = lod_pb2_grpc.LodServiceStub(channel)
        self._render = render_pb2_grpc.RenderServiceStub(channel)
        self._health_check = channel.unary_unary(
            health_messages.CHECK_METHOD,
            request_serializer=health_messages.HealthCheckRequest.SerializeToString,
            response_deserializer=health_messages.HealthCheckResponse.FromString)

    # ------------------------------------------------------------------------------------------
    # Life cycle

    def __repr__(self) -> str:
        where = repr(self._target) if self._target is not None else "channel=<given>"
        return f"animspace.Client({where}, deadline_s={self._deadline_s}{', closed' if self._closed else ''})"

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Closes the channel if this client created it (idempotent). Later calls raise ValueError."""
        if not self._closed:
            self._closed = True
            if self._owns_channel:
                self._channel.close()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def channel(self) -> grpc.Channel:
        """The underlying channel, for calls made on raw stubs (add :attr:`metadata` to them)."""
        return self._channel

    @property
    def metadata(self) -> Optional[Tuple[Tuple[str, str], ...]]:
        """The metadata sent with every call (the bearer token), or None."""
        return self._metadata

    @property
    def basis_cache(self) -> BasisCache:
        """The bases :meth:`reconstruct` uses, by model, version and checksum."""
        return self._basis_cache

    # ------------------------------------------------------------------------------------------
    # Plumbing: every call goes through _unary or _stream_call, and every failure through
    # errors.error_from_grpc.

    def _deadline(self, deadline_s: Optional[float]) -> Optional[float]:
        """The deadline of one call, seconds: ``deadline_s``, or the client's when it is None
        (grpcio calls it ``timeout``)."""
        if self._closed:
            raise ValueError("the animspace.Client is closed")
        if deadline_s is None:
            return self._deadline_s
        if not deadline_s > 0:
            raise ValueError(f"deadline_s: expected seconds > 0, got {deadline_s}")
        return deadline_s

    def _unary(self, rpc: str, method: Callable[..., _Response], request: Any,
               deadline_s: Optional[float]) -> _Response:
        deadline = self._deadline(deadline_s)
        try:
            return method(request, timeout=deadline, metadata=self._metadata)
        except grpc.RpcError as error:
            raise error_from_grpc(rpc, error) from error

    # ------------------------------------------------------------------------------------------
    # Health and the registry (models.proto)

    @_renamed_keywords(timeout="deadline_s")
    def health(self, service: str = "", *, deadline_s: Optional[float] = None) -> str:
        """grpc.health.v1 status of ``service`` ("" = the whole server): "SERVING", or
        "NOT_SERVING" while the repository loads and while the daemon shuts down.

        Raises:
            NotFound: for a service name the server does not know.
        """
        response = self._unary("Health/Check", self._health_check,
                               health_messages.HealthCheckRequest(service=service), deadline_s)
        return health_messages.serving_status_name(response.status)

    @_renamed_keywords(timeout_s="deadline_s")
    def wait_until_serving(self, deadline_s: float = 30.0, *, poll_s: float = 0.05) -> None:
        """Waits until health is SERVING (the daemon reports NOT_SERVING while it loads its
        repository, and the channel may not be connected yet).

        Raises:
            DeadlineExceeded: when the server is not serving within ``deadline_s``; the last
                status or error is in the message.
        """
        if not deadline_s > 0:
            raise ValueError(f"deadline_s: expected seconds > 0, got {deadline_s}")
        give_up = time.monotonic() + deadline_s
        last = "no answer"
        while True:
            left = give_up - time.monotonic()
            if left <= 0:
                raise DeadlineExceeded("Health/Check", grpc.StatusCode.DEADLINE_EXCEEDED,
                                       f"not SERVING after {deadline_s} s; last: {last}")
            try:
                last = self.health(deadline_s=min(left, max(poll_s, 1.0)))
                if last == "SERVING":
                    return
            except (Unavailable, DeadlineExceeded) as error:  # not up yet, or busy starting
                last = str(error)
            time.sleep(min(poll_s, max(0.0, give_up - time.monotonic())))

    @_renamed_keywords(timeout="deadline_s")
    def list_models(self, *, deadline_s: Optional[float] = None) -> List[ModelSummary]:
        """Every model the server knows, sorted by name, with its versions (failed ones included)."""
        response = self._unary("ListModels", self._models.ListModels, models_pb2.ListModelsRequest(), deadline_s)
        return [ModelSummary.from_proto(m) for m in response.models]

    @_renamed_keywords(timeout="deadline_s")
    def describe_model(self, name: str, version: int = 0, *, deadline_s: Optional[float] = None) -> ModelSummary:
        """One model in detail (version 0: every version). Raises NotFound for an unknown one."""
        request = models_pb2.DescribeModelRequest(model=_model_ref(name, version))
        return ModelSummary.from_proto(self._unary("DescribeModel", self._models.DescribeModel, request, deadline_s).model)

    @_renamed_keywords(timeout="deadline_s")
    def load_model(self, name: str, version: int = 0, *, deadline_s: Optional[float] = None) -> ModelSummary:
        """Admin: (re)loads a model from the repository (version 0: every version found).

        Raises:
            NotFound: no such directory. DataLoss / FailedPrecondition: a corrupt or too-new file
            (the previously loaded version keeps serving). PermissionDenied: admin RPCs locked.
        """
        request = models_pb2.LoadModelRequest(model=_model_ref(name, version))
        return ModelSummary.from_proto(self._unary("LoadModel", self._models.LoadModel, request, deadline_s).model)

    @_renamed_keywords(timeout="deadline_s")
    def unload_model(self, name: str, version: int = 0, *, deadline_s: Optional[float] = None) -> None:
        """Admin: stops serving a model (version 0: every version); calls in flight finish."""
        request = models_pb2.UnloadModelRequest(model=_model_ref(name, version))
        self._unary("UnloadModel", self._models.UnloadModel, request, deadline_s)

    @_renamed_keywords(timeout="deadline_s")
    def server_info(self, *, deadline_s: Optional[float] = None) -> ServerInfo:
        """Server version, limits (max batch, message size, thumbnail size), renderer, RPCs."""
        response = self._unary("GetServerInfo", self._models.GetServerInfo, models_pb2.GetServerInfoRequest(),
                               deadline_s)
        return ServerInfo.from_proto(response)

    @_renamed_keywords(timeout="deadline_s")
    def stats(self, model: str = "", *, reset: bool = False, deadline_s: Optional[float] = None) -> Stats:
        """Per-model hits/blends/misses, hit rate, e_key and latency histograms ("" = every model).
        ``reset`` zeroes the counters after reading (admin)."""
        request = stats_pb2.GetStatsRequest(model=model, reset=reset)
        return Stats.from_proto(self._unary("GetStats", self._stats.GetStats, request, deadline_s))

    # ------------------------------------------------------------------------------------------
    # The soft cache (poses.proto; Meyer & Anderson 2006 §4–5, 2007 §2)

    @_renamed_keywords(timeout="deadline_s")
    def describe_key_points(self, model: str, version: int = 0, *, deadline_s: Optional[float] = None) -> KeyPoints:
        """The key points (and check points) a posing engine must compute for a PMSC model, in
        request order.

        Raises:
            FailedPrecondition: for a model without key points (not PMSC).
        """
        request = poses_pb2.DescribeKeyPointsRequest(model=_model_ref(model, version))
        return KeyPoints.from_proto(self._unary("DescribeKeyPoints", self._poses.DescribeKeyPoints, request, deadline_s))

    @_renamed_keywords(timeout="deadline_s")
    def evaluate_key_points(self, model: str, key_values: npt.ArrayLike, *, version: int = 0,
                            check_values: Optional[npt.ArrayLike] = None,
                            skeleton_pose: Optional[npt.ArrayLike] = None, space: str = "global",
                            include_region_errors: bool = False, omit_points: bool = False,
                            local_fail_through: bool = False, points_encoding: str = "float32",
                            reconstruct: bool = False, skip_miss_log: bool = False,
                            deadline_s: Optional[float] = None) -> Union[PoseResult, List[PoseResult]]:
        """Key points in, the whole pose out, through the soft cache.

        Args:
            key_values: K×D key values in ``describe_key_points`` order for one pose (returns one
                PoseResult), or P×K×D for a batch of P poses (returns a list, request order).
            version: pin the version the key points belong to (``KeyPoints.model_version``).
            check_values: C×D check values in ``KeyPoints.check_point_indices`` order, computed like
                the key values (P×C×D with a batch; ``KeyPoints.select_check_values`` gathers them
                from full frames): the server measures the estimate's error there too, and a HIT the
                key points alone give becomes BLEND or MISS when the check points disagree. None
                (or C = 0): the verdict rests on e_key alone.
            skeleton_pose: the skeleton pose(s) the key values come from — B×3×4 / B×4×4 for one
                pose, P×B×3×4 / P×B×4×4 for a batch — so that a model with a server posing engine
                (fail-through "SERVER") completes blends and misses itself.
            space: "global" (G_j) or "local" (L_j) for ``skeleton_pose``.
            include_region_errors: return per-region e_key (models with regions).
            omit_points: return only the verdicts (``points`` is None): cheap probing.
            local_fail_through: on a blend or miss, name in ``PoseResult.full_points`` only the
                points that need the full calculation (those of the regions whose key points
                fail); complete them with ``complete_miss(..., full_points=...)``.
            skip_miss_log: test traffic (load tests, benchmarks): blends and misses are served but
                kept out of the model's miss log, and so out of retraining.
            points_encoding: how the answer's points travel: "float32" (exact), "float16"
                (IEEE binary16: half the bytes, relative error ≤ 2^-11; refused with OutOfRange for
                a pose with a value beyond ±65504) or "fixed16" (per-channel 16-bit fixed point:
                half the bytes, error ≤ half the channel's range / 65535). Points always decode
                to float32; ``PoseResult.points_max_error`` says what the encoding lost.
                "coordinates": an answer the client can reconstruct (a HIT, or a BLEND/MISS with
                ``full_evaluation_needed``) comes as ``PoseResult.coordinates`` — M values instead
                of N·D — and no points; points the server computed itself come as float32.
            reconstruct: with "coordinates", fill ``points`` of such answers from their
                coordinates (:meth:`reconstruct`, through the basis cache), keeping
                ``coordinates``.

        Raises:
            ValueError: for a wrong shape or an unknown ``points_encoding``, naming the argument
                (nothing is sent); ``reconstruct`` without "coordinates".
            BasisMismatch: (``reconstruct``) the answer's version was replaced under it.
            InvalidArgument: a key point count or channel count the model does not expect, or
                non-finite values (the message names ``poses[i].key_values``); the same for
                ``poses[i].check_values``, or check values for a model without check points.
            ResourceExhausted: a batch over the server's ``max_batch_poses``.
        """
        encoding = wire.points_encoding("points_encoding", points_encoding)
        _check_reconstruct(reconstruct, encoding)
        values = wire.as_float32("key_values", key_values)
        if values.ndim not in (2, 3):
            raise ValueError(f"key_values: expected shape (K, D) or (P, K, D), got {wire.shape_text(values.shape)}")
        batch = values.ndim == 3
        if batch and values.shape[0] == 0:
            raise ValueError("key_values: expected at least one pose, got shape " + wire.shape_text(values.shape))
        values = wire.as_points("key_values", values, ndim=values.ndim, points_label="K")
        poses = values if batch else values[np.newaxis]
        transforms: Optional[np.ndarray] = None
        if skeleton_pose is not None:
            transforms = wire.as_transforms("skeleton_pose", skeleton_pose, batch=batch)
            if batch and transforms.shape[0] != poses.shape[0]:
                raise ValueError(f"skeleton_pose: expected {poses.shape[0]} poses like key_values, got shape "
                                 f"{wire.shape_text(transforms.shape)}")
            transforms = transforms if batch else transforms[np.newaxis]
        if space not in wire.SPACES:
            raise ValueError(f"space: expected 'global' or 'local', got {space!r}")
        checks: Optional[np.ndarray] = None
        if check_values is not None:
            checks = wire.as_points("check_values", check_values, ndim=3 if batch else 2, points_label="C")
            if batch and checks.shape[0] != poses.shape[0]:
                raise ValueError(f"check_values: expected {poses.shape[0]} poses like key_values, got shape "
                                 f"{wire.shape_text(checks.shape)}")
            checks = checks if batch else checks[np.newaxis]
        request = poses_pb2.EvaluateKeyPointsRequest(model=_model_ref(model, version),
                                                     include_region_errors=include_region_errors,
                                                     omit_points=omit_points,
                                                     local_fail_through=local_fail_through,
                                                     points_encoding=encoding, skip_miss_log=skip_miss_log)
        for i in range(poses.shape[0]):
            pose = request.poses.add()
            pose.key_values.CopyFrom(_point_array(poses[i]))
            if checks is not None and checks.shape[1] > 0:
                pose.check_values.CopyFrom(_point_array(checks[i]))
            if transforms is not None:
                pose.skeleton_pose.CopyFrom(wire.skeleton_pose(f"skeleton_pose[{i}]", transforms[i], space))
        response = self._unary("EvaluateKeyPoints", self._poses.EvaluateKeyPoints, request, deadline_s)
        if len(response.results) != poses.shape[0]:
            raise ProtocolError("EvaluateKeyPoints", f"{len(response.results)} results for {poses.shape[0]} poses")
        with _decoding("EvaluateKeyPoints"):
            results = [PoseResult.from_proto(r, f"results[{i}].points") for i, r in enumerate(response.results)]
        if reconstruct:
            results = [self._with_points(model, r, deadline_s) for r in results]
        return results if batch else results[0]

    def relight(self, model: str, lights: Union[PointLight, Sequence[PointLight], npt.ArrayLike], *,
                key_values: Optional[npt.ArrayLike] = None, check_values: Optional[npt.ArrayLike] = None,
                version: int = 0, include_region_errors: bool = False,
                omit_points: bool = False, local_fail_through: bool = False, points_encoding: str = "float32",
                reconstruct: bool = False, deadline_s: Optional[float] = None) -> PoseResult:
        """One frame of an illumination model (``ModelVersion.server_engine`` "ILLUMINATION";
        Meyer & Anderson 2007 §3.2): the RGB radiance of every point for ``lights``.

        Args:
            lights: a PointLight, a sequence of them, or an L×3 array of positions (the model's
                training intensity).
            key_values: K×3 indirect radiance at the key points, if the caller gathered them; None
                lets the server gather them and the check points' (the cheap part of the full
                calculation).
            check_values: C×3 radiance at the check points, gathered with ``key_values`` (only
                with them).
            Others as ``evaluate_key_points``. On a blend or miss the server gathers the full
                values for ``lights`` itself (fail-through "SERVER").

        Raises:
            ValueError: a malformed light (nothing is sent).
            InvalidArgument: a model without an illumination engine (naming ``poses[0].light_set``),
                or a light the server refuses (position or intensity not finite, intensity < 0).
        """
        encoding = wire.points_encoding("points_encoding", points_encoding)
        _check_reconstruct(reconstruct, encoding)
        request = poses_pb2.EvaluateKeyPointsRequest(model=_model_ref(model, version),
                                                     include_region_errors=include_region_errors,
                                                     omit_points=omit_points,
                                                     local_fail_through=local_fail_through,
                                                     points_encoding=encoding)
        pose = request.poses.add()
        pose.light_set.CopyFrom(messages.light_set("lights", lights))
        if key_values is not None:
            pose.key_values.CopyFrom(wire.point_array("key_values", key_values, points_label="K"))
        elif check_values is not None:
            raise ValueError("check_values: give them with key_values (without, the server gathers both)")
        checks = messages.check_point_array("check_values", check_values)
        if checks is not None:
            pose.check_values.CopyFrom(checks)
        response = self._unary("EvaluateKeyPoints", self._poses.EvaluateKeyPoints, request, deadline_s)
        if len(response.results) != 1:
            raise ProtocolError("EvaluateKeyPoints", f"{len(response.results)} results for 1 pose")
        with _decoding("EvaluateKeyPoints"):
            result = PoseResult.from_proto(response.results[0], "results[0].points")
        return self._with_points(model, result, deadline_s) if reconstruct else result

    @_renamed_keywords(timeout="deadline_s")
    def stream_key_points(self, model: str, frames: Iterable[Union[npt.ArrayLike, KeyPointPose]], *,
                          version: int = 0, omit_points: bool = False, first_sequence: int = 0,
                          local_fail_through: bool = False, points_encoding: str = "float32",
                          reconstruct: bool = False, skip_miss_log: bool = False,
                          deadline_s: Optional[float] = None) -> Iterator[PoseResult]:
        """Plays a sequence through the soft cache over one StreamKeyPoints call: one result per
        frame, yielded in frame order as they arrive.

        Frames are sent as the server takes them (gRPC flow control), so ``frames`` may be a lazy
        generator reading a file or a live posing engine. Each frame is a K×D array of key
        values, or a :class:`KeyPointPose` that also carries its check values and its skeleton pose
        (``KeyPoints.pose`` builds one from a full frame). The stream is
        pinned to the version its first frame resolves (a retrain never changes the key points
        under it); frame i is numbered ``first_sequence + i`` and every result's ``sequence`` is
        checked against it.

        The call starts when iteration starts; ``deadline_s`` (or the client's deadline) bounds the
        whole stream — pass a generous one for a long sequence. Stopping the iteration early
        cancels the call. ``local_fail_through``, ``points_encoding``, ``reconstruct`` and ``skip_miss_log`` are
        ``evaluate_key_points``' for every frame (the basis is fetched, once, when the first
        answer as coordinates arrives).

        Raises:
            ValueError: a frame of the wrong shape — after the results of every frame before it.
                An exception raised by ``frames`` itself is re-raised the same way.
            ProtocolError: a result out of order, or fewer results than frames.
            InvalidArgument etc.: a frame the server refused (the message names its sequence).
        """
        # Arguments are checked now; the call starts with the iteration.
        encoding = wire.points_encoding("points_encoding", points_encoding)
        _check_reconstruct(reconstruct, encoding)
        requests = _FrameRequests(_model_ref(model, version), frames, omit_points, first_sequence, local_fail_through,
                                  encoding, skip_miss_log)
        self._deadline(deadline_s)
        return self._stream_key_points(requests, first_sequence, deadline_s, model if reconstruct else None)

    def _stream_key_points(self, requests: "_FrameRequests", first_sequence: int, deadline_s: Optional[float],
                           reconstruct_model: Optional[str]) -> Iterator[PoseResult]:
        call = self._poses.StreamKeyPoints(iter(requests), timeout=self._deadline(deadline_s), metadata=self._metadata)
        expected = first_sequence
        try:
            try:
                for response in call:
                    if response.sequence != expected:
                        raise ProtocolError("StreamKeyPoints", f"expected the result of frame {expected}, got "
                                                               f"sequence {response.sequence}")
                    with _decoding("StreamKeyPoints"):
                        result = PoseResult.from_proto(response, f"frame {expected}: points")
                    if reconstruct_model is not None:
                        result = self._with_points(reconstruct_model, result, deadline_s)
                    yield result
                    expected += 1
            except grpc.RpcError as error:
                if requests.failure is not None:
                    raise requests.failure from None
                raise error_from_grpc("StreamKeyPoints", error) from error
        finally:
            call.cancel()  # no-op once the call finished; ends it when the caller stopped early
        if requests.failure is not None:
            raise requests.failure
        if expected != first_sequence + requests.sent:
            raise ProtocolError("StreamKeyPoints",
                                f"the stream ended after {expected - first_sequence} results for {requests.sent} frames")

    @_renamed_keywords(timeout="deadline_s")
    def complete_miss(self, model: str, key_values: npt.ArrayLike, full_values: npt.ArrayLike, *, version: int = 0,
                      check_values: Optional[npt.ArrayLike] = None, full_points: Optional[npt.ArrayLike] = None,
                      points_encoding: str = "float32", reconstruct: bool = False, skip_miss_log: bool = False,
                      deadline_s: Optional[float] = None) -> MissCompletion:
        """Completes a blend or miss with the full pose from the client's posing engine
        (fail-through "CLIENT"), and logs it for retraining.

        Stateless: pass the same K×D ``key_values`` (and C×D ``check_values``, if any) that were
        evaluated, the N×D ``full_values``, and the ``version`` that produced the estimate
        (``PoseResult.model_version``). The answer is α·full + (1−α)·estimate with the α of this
        pose.

        Local fail-through: with ``full_points`` (ascending point indices, at least the
        ``PoseResult.full_points`` of this pose), ``full_values`` holds only those points' values
        (len(full_points)×D, same order); the answer is blended point by point and the miss log
        keeps a partial frame.

        ``points_encoding`` and ``reconstruct`` are ``evaluate_key_points``' for the answer's points
        (with "coordinates" only a HIT comes as coordinates: the server blends a blend or miss).
        ``skip_miss_log``: test traffic; the blend is answered but not logged (``logged`` False,
        ``not_logged_reason`` says so).

        Raises:
            ValueError: ``full_values`` rows differ from ``full_points``, or an unknown
                ``points_encoding`` (nothing is sent).
            InvalidArgument: ``full_points`` not ascending, out of range, or missing a point that
                needs the full calculation (the message names ``full_points``).
            FailedPrecondition: for a cross-PMSC model (no full calculation exists).
        """
        encoding = wire.points_encoding("points_encoding", points_encoding)
        _check_reconstruct(reconstruct, encoding)
        keys = wire.as_points("key_values", key_values, points_label="K")
        full = wire.as_points("full_values", full_values)
        points = np.zeros(0, np.uint32)
        if full_points is not None:
            points = np.asarray(full_points)
            if points.ndim != 1 or (points.size > 0 and not np.issubdtype(points.dtype, np.integer)):
                raise ValueError(f"full_points: expected a 1-D array of point indices, got shape "
                                 f"{wire.shape_text(points.shape)} of {points.dtype}")
            if points.size > 0 and full.shape[0] != points.size:
                raise ValueError(f"full_values: expected {points.size} rows, one per full_points entry, got "
                                 f"{full.shape[0]}")
        checks = messages.check_point_array("check_values", check_values)
        request = poses_pb2.CompleteMissRequest(model=_model_ref(model, version), key_values=_point_array(keys),
                                                full_values=_point_array(full),
                                                full_points=[int(p) for p in points], points_encoding=encoding,
                                                skip_miss_log=skip_miss_log)
        if checks is not None:
            request.check_values.CopyFrom(checks)
        response = self._unary("CompleteMiss", self._poses.CompleteMiss, request, deadline_s)
        with _decoding("CompleteMiss"):
            result = PoseResult.from_proto(response.result, "result.points")
        if reconstruct:
            result = self._with_points(model, result, deadline_s)
        return MissCompletion(result=result, logged=response.logged, not_logged_reason=response.not_logged_reason)

    # ------------------------------------------------------------------------------------------
    # Answers as coordinates (issue #36): the basis, its cache, the reconstruction

    def get_basis(self, model: str, version: int = 0, *, values_encoding: str = "float32", layout: str = "dense",
                  deadline_s: Optional[float] = None) -> Basis:
        """The subspace of a PMSC model version — N·D mean and N·D × M basis, float32 — streamed in
        chunks by GetBasis, assembled and checked (order, shape, checksum), and kept in
        :attr:`basis_cache` for :meth:`reconstruct`. Always asks the server (version 0: the
        version served now; ``Basis.model_version`` says which).

        ``layout`` (issue #51 item 4): "dense", A as N·D × M values; "skinned", an articulated
        model's A as each point's bones and skinning terms plus its residual columns — a fraction
        of the values (a tenth with tens of bones), the same basis (checked by expanding it
        through the checksum and SHA-256), a reconstruction that skips A's zeros; "compact",
        skinned where the model is articulated, else dense (what :meth:`reconstruct` asks for).
        ``Basis.layout`` says which came: a server from before layouts sends dense whatever is
        asked.

        ``values_encoding="float16"`` (issue #53) halves the bytes sent: the values are checked
        against the SHA-256 of what was sent, widened to float32, and the Basis says how far each
        may be from the float32 basis (``values_max_error``); it is returned, not cached.
        ``animspace.coordinates.reconstruct`` with it is within about
        ``2⁻¹¹·(|mean_i| + Σ_j |A_ij p_j|)`` more per value (``rounding_bound`` computes it). A
        basis with a value beyond ±65504 raises FailedPrecondition.

        Raises:
            NotFound: an unknown model or version. FailedPrecondition: a model without key points
                (not PMSC); ``layout="skinned"`` for a model that is not articulated.
            ProtocolError: chunks out of order, overlapping, short, changing shape, layout, version
                or checksum mid-stream, values whose checksum is not the one they carry, bone
                numbers that are no bone's, or another version (or a skinned layout when dense was
                asked for) than the one asked for.
        """
        encodings = {"float32": common_pb2.POINT_ENCODING_FLOAT32, "float16": common_pb2.POINT_ENCODING_FLOAT16}
        if values_encoding not in encodings:
            raise ValueError(f"values_encoding: expected 'float32' or 'float16', got {values_encoding!r}")
        layouts = {"dense": poses_pb2.BASIS_LAYOUT_DENSE, "skinned": poses_pb2.BASIS_LAYOUT_SKINNED,
                   "compact": poses_pb2.BASIS_LAYOUT_COMPACT}
        if layout not in layouts:
            raise ValueError(f"layout: expected 'dense', 'skinned' or 'compact', got {layout!r}")
        request = poses_pb2.GetBasisRequest(model=_model_ref(model, version),
                                            values_encoding=encodings[values_encoding], layout=layouts[layout])
        call = self._poses.GetBasis(request, timeout=self._deadline(deadline_s), metadata=self._metadata)
        assembler = _assemble("GetBasis", call, BasisAssembler())
        basis = assembler.basis(model)
        if version != 0 and basis.model_version != version:
            raise ProtocolError("GetBasis", f"asked for version {version}, the chunks are of version "
                                            f"{basis.model_version}")
        if layout == "dense" and basis.layout != "dense":
            raise ProtocolError("GetBasis", f"asked for the dense layout, the chunks are {basis.layout}")
        if basis.values_encoding == "float32":
            self._basis_cache.put(basis)
        return basis

    def reconstruct(self, model: str, result: PoseResult, *, deadline_s: Optional[float] = None) -> np.ndarray:
        """The N×D float32 points of an answer that came as coordinates:
        f̂_i = R (mean_i + Σ_j A_ij p_j) + t, in float32 (R = I, t = 0 unless the model is aligned).

        The basis is (model, ``result.model_version``, ``result.coordinates.basis_checksum``) from
        :attr:`basis_cache` — memory, then disk — else fetched with GetBasis for that exact version
        in its compact layout (skinned for an articulated model) and cached. An answer whose points
        the server sent gives those points.

        The points differ from the server's float32 answer by rounding only: per value i at most
            2·(M + 2)·2⁻²⁴·(|mean_i| + Σ_j |A_ij p_j|)
        (+ 2·3·2⁻²⁴·‖x‖ per coordinate of a point x = mean_i + A_i p of an aligned model, whose
        rotation moves that error without lengthening it, and 2⁻²⁴·|f̂| twice for the sum with t;
        ``animspace.coordinates.rounding_bound`` computes it).

        Raises:
            ValueError: a result with neither coordinates nor points (``omit_points``).
            BasisMismatch: the server's basis of that version is another one (the version was
                replaced since the answer): never reconstructed with a wrong basis.
            NotFound: the version is no longer served (and its basis is not cached).
            ProtocolError: coordinates that do not fit their basis (M, alignment).
        """
        coordinates = result.coordinates
        if coordinates is None:
            if result.points is None:
                raise ValueError("result: it carries neither coordinates nor points (asked with omit_points?)")
            return result.points
        version, checksum = result.model_version, coordinates.basis_checksum
        basis = self._basis_cache.get(model, version, checksum,
                                      server_sha256=lambda: self._server_basis_sha256(model, version, checksum,
                                                                                      deadline_s))
        if basis is None:
            basis = self.get_basis(model, version, layout="compact", deadline_s=deadline_s)
            if basis.basis_checksum != checksum:
                raise BasisMismatch(model, version, checksum, basis.basis_checksum)
        try:
            return reconstruct_coordinates(basis, coordinates)
        except ValueError as error:
            raise ProtocolError("reconstruct", str(error)) from error

    def _server_basis_sha256(self, model: str, version: int, checksum: int,
                             deadline_s: Optional[float]) -> Optional[bytes]:
        """The SHA-256 the server names for that version's basis (DescribeKeyPoints, one small call):
        b"" from a server before the digest (the CRC check alone then), None when the version is gone
        or has another basis (GetBasis then says which)."""
        try:
            described = self.describe_key_points(model, version, deadline_s=deadline_s)
        except RpcError:
            return None
        if not described.basis_sha256:
            return b""
        return described.basis_sha256 if described.basis_checksum == checksum else None

    def _with_points(self, model: str, result: PoseResult, deadline_s: Optional[float]) -> PoseResult:
        """``result`` with its coordinates reconstructed into ``points`` (unchanged without any)."""
        if result.coordinates is None:
            return result
        return dataclasses.replace(result, points=self.reconstruct(model, result, deadline_s=deadline_s))

    # ------------------------------------------------------------------------------------------
    # Animation space (skinning.proto, lod.proto; Merry 2007)

    @_renamed_keywords(timeout="deadline_s")
    def evaluate_skeleton_pose(self, model: str, transforms: npt.ArrayLike, *, version: int = 0,
                               space: str = "global", include_normals: bool = False, lod_level: int = 0,
                               deadline_s: Optional[float] = None) -> Union[SkinnedPose, List[SkinnedPose]]:
        """Poses an animation-space model: v = Σ_j G_j p_j (Merry 2007 §3.1), normals from
        tangent planes (§3.5).

        Args:
            transforms: one pose, B×3×4 or B×4×4 (returns a SkinnedPose), or a batch, P×B×3×4 or
                P×B×4×4 (returns a list). B must equal the model's bone count. 4×4 matrices must
                be affine: the wire carries the top three rows.
            space: "global": G_j (world from bone); "local": joint transforms L_j, composed by
                the server as G_j = G_parent(j) · L_j (§2.2).
            lod_level: evaluate this level of detail instead of the full mesh (0).

        Raises:
            FailedPrecondition: a model without a skeleton.
            InvalidArgument: wrong bone count or non-finite values (naming ``poses[i]``).
        """
        array = wire.as_float32("transforms", transforms)
        batch = array.ndim == 4
        array = wire.as_transforms("transforms", array, batch=batch)
        if batch and array.shape[0] == 0:
            raise ValueError("transforms: expected at least one pose, got shape " + wire.shape_text(array.shape))
        if space not in wire.SPACES:
            raise ValueError(f"space: expected 'global' or 'local', got {space!r}")
        poses = array if batch else array[np.newaxis]
        request = skinning_pb2.EvaluateSkeletonPoseRequest(model=_model_ref(model, version),
                                                           include_normals=include_normals,
                                                           lod_level=wire.as_uint("lod_level", lod_level))
        for pose in poses:
            request.poses.add(space=wire.SPACES[space], bone_count=pose.shape[0],
                              transforms=pose.astype(wire.WIRE_FLOAT, copy=False).tobytes())
        response = self._unary("EvaluateSkeletonPose", self._skinning.EvaluateSkeletonPose, request, deadline_s)
        if len(response.poses) != poses.shape[0]:
            raise ProtocolError("EvaluateSkeletonPose", f"{len(response.poses)} results for {poses.shape[0]} poses")
        with _decoding("EvaluateSkeletonPose"):
            results = [SkinnedPose(points=wire.points_from(p.points, f"poses[{i}].points"),
                                   normals=(wire.points_from(p.normals, f"poses[{i}].normals")
                                            if p.HasField("normals") else None),
                                   model_version=response.model_version)
                       for i, p in enumerate(response.poses)]
        return results if batch else results[0]

    @_renamed_keywords(timeout="deadline_s")
    def get_lod(self, model: str, *, version: int = 0, level: Optional[int] = None,
                max_vertices: Optional[int] = None, tolerance_px: Optional[float] = None,
                distance: Optional[float] = None, viewport_width_px: int = 1920,
                horizontal_fov_rad: float = math.radians(45), form: str = "posed",
                pose: Optional[npt.ArrayLike] = None, space: str = "global", include_geomorph: bool = False,
                vertices_per_chunk: int = 0, texture_coordinates: bool = False,
                deadline_s: Optional[float] = None) -> LodMesh:
        """One level of detail, streamed in chunks and reassembled (Merry 2007 ch. 6, §7.3).

        Choose the level with exactly one of:
            level: an index (0 = full detail);
            max_vertices: the finest level with at most this many vertices;
            tolerance_px + distance: the coarsest level whose error ε^l projects to at most
                ``tolerance_px`` pixels at ``distance`` (camera to bounding-sphere centre, model
                units) in a ``viewport_width_px``-wide view of horizontal field of view
                ``horizontal_fov_rad`` (eq. 7.2).

        Args:
            form: "posed": V×3 positions at ``pose`` (the rest pose when None); "animation_space":
                per-influence p_j, bone indices and the skeleton, for skinning it with any G_j
                (``LodMesh.pose``).
            pose: FORM_POSED's skeleton pose, B×3×4 or B×4×4 in ``space``.
            include_geomorph: animation-space form: Δp towards the next coarser level (eq. 7.1).
            vertices_per_chunk: most vertices per block (0 = server default).
            texture_coordinates: "posed" form only: also the model's texture atlas (``animspace
                atlas``) at the level, ``LodMesh.texture_coordinates``, F×3×2 float32 per face
                corner; a coarser level's are the UVs build-lod stored with it (its faces keep
                their charts).

        Raises:
            ValueError: not exactly one selection, or a distance without a tolerance.
            InvalidArgument: ``texture_coordinates`` with the animation-space form (the message
                names include_texture_coordinates).
            OutOfRange: ``max_vertices`` below the coarsest level's vertex count.
            FailedPrecondition: a model without levels, or ``texture_coordinates`` for a model
                without an atlas or at a level stored without UVs (built before the atlas).
            ProtocolError: blocks out of order or not adding up to the header.
        """
        chosen = [name for name, value in (("level", level), ("max_vertices", max_vertices),
                                           ("tolerance_px", tolerance_px)) if value is not None]
        if len(chosen) != 1:
            raise ValueError("level, max_vertices, tolerance_px: give exactly one, got "
                             + (", ".join(chosen) if chosen else "none"))
        if (distance is not None) != (tolerance_px is not None):
            raise ValueError("distance: give it with tolerance_px (and only then)")
        if form not in FORMS:
            raise ValueError(f"form: expected 'posed' or 'animation_space', got {form!r}")
        request = lod_pb2.GetLodRequest(model=_model_ref(model, version), form=FORMS[form],
                                        include_geomorph=include_geomorph,
                                        include_texture_coordinates=bool(texture_coordinates),
                                        vertices_per_chunk=wire.as_uint("vertices_per_chunk", vertices_per_chunk))
        if level is not None:
            request.level = wire.as_uint("level", level)
        elif max_vertices is not None:
            request.budget.max_vertices = wire.as_uint("max_vertices", max_vertices)
        else:
            view = request.pixel_tolerance  # lod.proto PixelTolerance, field for field
            view.tolerance_px = wire.as_float("tolerance_px", tolerance_px)
            view.distance = wire.as_float("distance", distance)
            view.viewport_width_px = wire.as_uint("viewport_width_px", viewport_width_px)
            view.horizontal_fov_rad = wire.as_float("horizontal_fov_rad", horizontal_fov_rad)
        if pose is not None:
            request.pose.CopyFrom(wire.skeleton_pose("pose", pose, space))
        call = self._lod.GetLod(request, timeout=self._deadline(deadline_s), metadata=self._metadata)
        assembler = _assemble("GetLod", call, LodAssembler())
        with _decoding("GetLod"):
            return assembler.mesh()

    # ------------------------------------------------------------------------------------------
    # Thumbnails and retraining

    @_renamed_keywords(timeout="deadline_s", pixel_tolerance="tolerance_px")
    def render_thumbnail(self, model: str, width_px: int, height_px: int, *, version: int = 0,
                         key_values: Optional[npt.ArrayLike] = None, skeleton_pose: Optional[npt.ArrayLike] = None,
                         check_values: Optional[npt.ArrayLike] = None, space: str = "global",
                         sequence_frame: Optional[int] = None, camera: Optional[Camera] = None,
                         background_rgba: Optional[Sequence[float]] = None, shading: Optional[str] = None,
                         samples: int = 0, show_key_points: bool = False, show_wireframe: bool = False,
                         full_values: Optional[npt.ArrayLike] = None, tolerance_px: float = 0.0,
                         heat_max: float = 0.0, show_heat_legend: bool = False,
                         lights: Optional[Union[PointLight, Sequence[PointLight], npt.ArrayLike]] = None,
                         illumination: Optional[IlluminationView] = None,
                         texture_checker: bool = False, checker_squares: int = 0, show_chart_borders: bool = False,
                         deadline_s: Optional[float] = None) -> Thumbnail:
        """A PNG of the model drawn headless by the daemon's render thread.

        What is drawn: the rest pose; or ``key_values`` (K×D) through the soft cache (PMSC; with
        ``skeleton_pose`` too for a server posing engine; the verdict comes back in
        ``Thumbnail.pose``, judged with ``check_values`` (C×D) when given); or ``skeleton_pose``
        alone through the animation-space model; or
        stored frame ``sequence_frame``.

        Args:
            camera: None frames the posed bounding box automatically.
            background_rgba: 4 floats in [0, 1] (None: opaque dark grey).
            shading: "blinn_phong" or "lambert" (None: the server's default, Blinn-Phong).
            samples: multisampling 1, 2, 4 or 8 (0: the server's default, 4).
            show_key_points, show_wireframe: overlays.
            full_values: N×D full pose, for a heat map of |full − estimate| (blue 0 → red at the
                scale; ``Thumbnail.heat_max_error`` and ``heat_scale_max`` say the largest error
                and the scale).
            heat_max: the error drawn red, model units (needs full_values); 0: the model's error
                tolerance when it stores one, else the pose's largest error.
            show_heat_legend: draw the scale as a colour bar with its numbers (needs full_values).
            tolerance_px: draw the coarsest level whose error stays under this many pixels
                (eq. 7.2, in this ``width_px``-wide view); 0 draws full detail.
            lights: an illumination model's lights (PointLight(s) or L×3 positions): draws its
                surface coloured by the served radiance (key_values optional: the server gathers
                them); ``illumination`` says which radiance and how bright (IlluminationView).
            texture_checker: draw the model's texture atlas (``animspace atlas``) as a checker of
                light and dark squares, one texture coordinate per face corner, at full detail.
            checker_squares: with texture_checker, squares along one unit of texture coordinate
                (0: the server's default, 16).
            show_chart_borders: with texture_checker, lines along the atlas's chart borders.

        Raises:
            InvalidArgument: a size outside 1..max_thumbnail_px (naming ``width_px``) or a bad camera;
                checker_squares < 0 (naming ``checker_squares``).
            FailedPrecondition: texture_checker for a model that stores no texture atlas.
            Unavailable: the server has no renderer. ResourceExhausted: the render queue is full.
        """
        if sequence_frame is not None and (key_values is not None or skeleton_pose is not None):
            raise ValueError("sequence_frame: give it alone, not with key_values or skeleton_pose")
        if check_values is not None and key_values is None:
            raise ValueError("check_values: give them with the key_values they were posed with")
        request = render_pb2.RenderThumbnailRequest(model=_model_ref(model, version),
                                                    width_px=wire.as_uint("width_px", width_px),
                                                    height_px=wire.as_uint("height_px", height_px),
                                                    samples=wire.as_uint("samples", samples),
                                                    show_key_points=show_key_points, show_wireframe=show_wireframe,
                                                    tolerance_px=wire.as_float("tolerance_px", tolerance_px),
                                                    heat_max=wire.as_float("heat_max", heat_max),
                                                    show_heat_legend=show_heat_legend,
                                                    texture_checker=texture_checker,
                                                    checker_squares=wire.as_int("checker_squares", checker_squares),
                                                    show_chart_borders=show_chart_borders)
        if lights is not None:
            request.key_points.light_set.CopyFrom(messages.light_set("lights", lights))
        if illumination is not None:
            request.illumination.CopyFrom(illumination.to_proto())
        if key_values is not None:
            request.key_points.key_values.CopyFrom(wire.point_array("key_values", key_values, points_label="K"))
            checks = messages.check_point_array("check_values", check_values)
            if checks is not None:
                request.key_points.check_values.CopyFrom(checks)
            if skeleton_pose is not None:
                request.key_points.skeleton_pose.CopyFrom(wire.skeleton_pose("skeleton_pose", skeleton_pose, space))
        elif skeleton_pose is not None:
            request.skeleton_pose.CopyFrom(wire.skeleton_pose("skeleton_pose", skeleton_pose, space))
        elif sequence_frame is not None:
            request.sequence_frame = wire.as_uint("sequence_frame", sequence_frame)
        if camera is not None:
            request.camera.CopyFrom(camera.to_proto())
        if background_rgba is not None:
            rgba = [float(v) for v in background_rgba]
            if len(rgba) != 4:
                raise ValueError(f"background_rgba: expected 4 floats, got {len(rgba)}")
            request.background_rgba.extend(rgba)
        if shading is not None:
            if shading not in _SHADING:
                raise ValueError(f"shading: expected 'blinn_phong' or 'lambert', got {shading!r}")
            request.shading = _SHADING[shading]
        if full_values is not None:
            request.full_values.CopyFrom(wire.point_array("full_values", full_values))
        response = self._unary("RenderThumbnail", self._render.RenderThumbnail, request, deadline_s)
        with _decoding("RenderThumbnail"):
            return Thumbnail.from_proto(response)

    @_renamed_keywords(timeout="deadline_s")
    def retrain(self, model: str, *, version: int = 0, exclude_misses: bool = False, error_bound: float = 0.0,
                max_key_points: int = 0, dry_run: bool = False, deadline_s: Optional[float] = None) -> RetrainResult:
        """Admin: "train each night, better tomorrow" — rebuilds the subspace from the model's
        training frames plus the logged misses that carry full values, writes it as the next
        version and hot-swaps it in (calls in flight finish on the old one).

        Retraining can take minutes on real data: pass a ``deadline_s`` to match.

        Args:
            exclude_misses: train on the original frames only.
            error_bound: override the bound on the max per-point residual (model units; 0 keeps it).
            max_key_points: override the key point budget (0 keeps it).
            dry_run: train and report without writing or serving (``new_version`` is 0).

        Raises:
            FailedPrecondition: a model that cannot be retrained, or nothing new to train on (no
            completed miss since its training and no option changed: the retrain would publish a
            copy; a dry run reports it as ``unchanged``). Aborted: a retrain of the same
            model is running. PermissionDenied: admin RPCs are locked.
        """
        request = training_pb2.RetrainRequest(model=_model_ref(model, version), exclude_misses=exclude_misses,
                                              error_bound=wire.as_float("error_bound", error_bound),
                                              max_key_points=wire.as_uint("max_key_points", max_key_points),
                                              dry_run=dry_run)
        return RetrainResult.from_proto(self._unary("Retrain", self._training.Retrain, request, deadline_s))


def _check_reconstruct(reconstruct: bool, encoding: int) -> None:
    if reconstruct and encoding != common_pb2.POINT_ENCODING_COORDINATES:
        raise ValueError("reconstruct: only answers as coordinates are reconstructed; pass "
                         "points_encoding='coordinates' with it")


class _FrameRequests:
    """StreamKeyPoints' request iterator.

    gRPC consumes it on its own thread, where an exception would only cancel the call with an
    opaque CANCELLED. So a frame that fails to convert (or a ``frames`` iterable that raises)
    is remembered instead and ends the request side cleanly: the server answers every frame sent
    before it, and the caller's iterator re-raises the exception after yielding those results.
    """

    def __init__(self, model: common_pb2.ModelRef, frames: Iterable[Union[npt.ArrayLike, KeyPointPose]],
                 omit_points: bool, first_sequence: int, local_fail_through: bool = False,
                 points_encoding: int = common_pb2.POINT_ENCODING_UNSPECIFIED, skip_miss_log: bool = False) -> None:
        first_sequence = wire.as_uint("first_sequence", first_sequence, 64)
        self._model = model
        self._frames = frames
        self._omit_points = omit_points
        self._points_encoding = points_encoding
        self._local_fail_through = local_fail_through
        self._skip_miss_log = skip_miss_log
        self._first_sequence = first_sequence
        self.sent = 0
        self.failure: Optional[BaseException] = None

    def __iter__(self) -> Iterator[poses_pb2.KeyPointFrame]:
        shape: Optional[Tuple[int, ...]] = None
        try:
            for i, frame in enumerate(self._frames):
                pose = frame if isinstance(frame, KeyPointPose) else KeyPointPose(frame)
                values = wire.as_points(f"frames[{i}]", pose.key_values, points_label="K")
                if shape is None:
                    shape = values.shape
                elif values.shape != shape:
                    raise ValueError(f"frames[{i}]: expected shape {wire.shape_text(shape)} like frames[0], "
                                     f"got {wire.shape_text(values.shape)}")
                message = poses_pb2.KeyPointFrame(sequence=self._first_sequence + i, omit_points=self._omit_points,
                                                  local_fail_through=self._local_fail_through,
                                                  points_encoding=self._points_encoding,
                                                  skip_miss_log=self._skip_miss_log)
                if i == 0:
                    message.model.CopyFrom(self._model)  # later frames keep the stream's model
                message.pose.CopyFrom(
                    KeyPointPose(values, pose.skeleton_pose, pose.space, pose.check_values).to_proto(f"frames[{i}]"))
                self.sent += 1
                yield message
        except Exception as error:  # noqa: BLE001 — re-raised on the caller's thread
            self.failure = error
