"""animspace: the Python client for animspaced, numpy in and out.

animspaced serves character-animation models over gRPC: Point Multiplication / Soft Caching
(Meyer & Anderson 2006, 2007: key points in, the whole pose out, with HIT / BLEND / MISS) and
animation-space skinning with levels of detail (Merry 2007), plus PNG thumbnails::

    import numpy as np
    import animspace

    with animspace.Client("127.0.0.1:50051") as client:
        keys = client.describe_key_points("arm-pmsc")
        result = client.evaluate_key_points("arm-pmsc", np.zeros((keys.count, 3)),
                                            version=keys.model_version)
        print(result.status, result.key_point_error, result.points.shape)

The generated messages and stubs are importable as ``animspace.v1`` (``from animspace.v1 import
poses_pb2``) for anything the client does not wrap.
"""
import sys as _sys

try:
    import google.protobuf  # noqa: F401
    import grpc  # noqa: F401
    import numpy  # noqa: F401
except ImportError as _error:
    # One line that says what to do: the bare "No module named 'grpc'" names neither the
    # interpreter that lacks it nor the package that provides it.
    raise ImportError(
        f"animspace needs grpcio and protobuf (and numpy), and {_sys.executable} cannot import "
        f"{_error.name or _error}: on Debian use /usr/bin/python3 with python3-grpcio python3-protobuf "
        "python3-numpy (apt install python3-grpcio python3-protobuf python3-numpy), or a virtual environment "
        "made with `/usr/bin/python3 -m venv --system-site-packages` (clients/python/README.md)") from _error
try:
    import animspace.v1.common_pb2  # noqa: F401
except ImportError as _error:
    raise ImportError(
        f"animspace.v1, the messages generated from proto/, is missing ({_error}): from a build tree use "
        "PYTHONPATH=build/python (after `make build`), or install the package, which generates them "
        "(clients/python/README.md)") from _error

from animspace.client import DEFAULT_DEADLINE_S, DEFAULT_MAX_RECEIVE_MESSAGE_BYTES, Client
from animspace.coordinates import Basis, BasisCache, SubspaceCoordinates
from animspace.errors import (Aborted, AlreadyExists, BasisMismatch, Cancelled, DataLoss, DeadlineExceeded, Error,
                              FailedPrecondition, Internal, InvalidArgument, NotFound, OutOfRange, PermissionDenied,
                              ProtocolError, ResourceExhausted, RpcError, Unauthenticated, Unavailable, Unimplemented,
                              error_from_grpc)
from animspace.lod import LodHeader, LodMesh, Skeleton
from animspace.messages import (Camera, HistogramData, IlluminationView, KeyPointPose, KeyPoints, MissCompletion,
                                ModelStats, ModelSummary, ModelVersion, PointLight, PoseResult, RegionError,
                                RetrainResult, ServerInfo, SkinnedPose, Stats, Thumbnail)
from animspace.pc2 import PointCache, read_pc2, write_pc2

__version__ = "0.1.0"

__all__ = [
    "Client",
    "DEFAULT_DEADLINE_S",
    "DEFAULT_MAX_RECEIVE_MESSAGE_BYTES",
    # errors
    "Error",
    "RpcError",
    "ProtocolError",
    "BasisMismatch",
    "Aborted",
    "AlreadyExists",
    "Cancelled",
    "DataLoss",
    "DeadlineExceeded",
    "FailedPrecondition",
    "Internal",
    "InvalidArgument",
    "NotFound",
    "OutOfRange",
    "PermissionDenied",
    "ResourceExhausted",
    "Unauthenticated",
    "Unavailable",
    "Unimplemented",
    "error_from_grpc",
    # results and inputs
    "Basis",
    "BasisCache",
    "Camera",
    "HistogramData",
    "IlluminationView",
    "KeyPointPose",
    "KeyPoints",
    "LodHeader",
    "LodMesh",
    "MissCompletion",
    "ModelStats",
    "ModelSummary",
    "ModelVersion",
    "PointLight",
    "PoseResult",
    "RegionError",
    "RetrainResult",
    "ServerInfo",
    "Skeleton",
    "SkinnedPose",
    "Stats",
    "SubspaceCoordinates",
    "Thumbnail",
    # point caches
    "PointCache",
    "read_pc2",
    "write_pc2",
]
