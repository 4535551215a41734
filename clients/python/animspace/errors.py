"""Errors raised by the animspace client.

Every failed RPC, unary or streaming, crosses into Python through one function,
:func:`error_from_grpc`, which keeps the gRPC code, the server's message (it names the offending
field with the expected and the actual value, e.g. ``poses[0].key_values.point_count: expected 24
key points, got 23``) and the method name, and picks the subclass for the code so that callers can
write ``except animspace.NotFound``.

Bad arguments found before anything is sent are plain :class:`ValueError` (or :class:`TypeError`),
naming the argument with the expected and the actual shape. A reply that breaks the API's own
contract (a stream out of order, LOD blocks that do not add up to their header) is a
:class:`ProtocolError`: the call itself succeeded, but its result cannot be trusted.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple, Type

import grpc

__all__ = [
    "Error",
    "RpcError",
    "ProtocolError",
    "BasisMismatch",
    "Cancelled",
    "InvalidArgument",
    "DeadlineExceeded",
    "NotFound",
    "AlreadyExists",
    "PermissionDenied",
    "ResourceExhausted",
    "FailedPrecondition",
    "Aborted",
    "OutOfRange",
    "Unimplemented",
    "Internal",
    "Unavailable",
    "DataLoss",
    "Unauthenticated",
    "error_from_grpc",
]


class Error(Exception):
    """Base of every error this package raises on purpose (besides ValueError/TypeError)."""


class RpcError(Error):
    """An RPC that the server (or the gRPC runtime) ended with a non-OK status.

    Attributes:
        code: the gRPC status code.
        message: the server's details alone, e.g. ``model "arm-x" not found``.
        rpc: the method, e.g. ``"EvaluateKeyPoints"`` or ``"Health/Check"``.
    """

    def __init__(self, rpc: str, code: grpc.StatusCode, message: str) -> None:
        # The C++ client's what() reads the same way: "<rpc> failed: <CODE>: <message>".
        super().__init__(f"{rpc} failed: {code.name}: {message}")
        self.rpc = rpc
        self.code = code
        self.message = message

    def __reduce__(self) -> Tuple[Any, ...]:  # keeps pickling (multiprocessing, pytest-xdist) working
        return (error_for_code(self.code), (self.rpc, self.code, self.message))


class ProtocolError(Error):
    """A reply that breaks the API's contract: the call succeeded but its result is unusable.

    Attributes:
        rpc: the method whose reply was malformed.
    """

    def __init__(self, rpc: str, problem: str) -> None:
        super().__init__(f"{rpc}: {problem}")
        self.rpc = rpc


class BasisMismatch(Error):
    """An answer's coordinates name a basis the server no longer serves under their version (the
    version was replaced: unloaded and published again with another subspace). Reconstructing them
    with the basis served now would give wrong points, so nothing is reconstructed.

    Attributes:
        model, model_version: the answer's model and version.
        expected_checksum: the answer's ``coordinates.basis_checksum``.
        served_checksum: the ``basis_checksum`` GetBasis sent for that version.
    """

    def __init__(self, model: str, model_version: int, expected_checksum: int, served_checksum: int) -> None:
        super().__init__(f"coordinates of '{model}' version {model_version} belong to basis {expected_checksum:016x}, "
                         f"but the server's basis of that version is {served_checksum:016x} (the version was "
                         "replaced); evaluate the pose again")
        self.model = model
        self.model_version = model_version
        self.expected_checksum = expected_checksum
        self.served_checksum = served_checksum

    def __reduce__(self) -> Tuple[Any, ...]:
        return (BasisMismatch, (self.model, self.model_version, self.expected_checksum, self.served_checksum))


class Cancelled(RpcError):
    """CANCELLED: the call was cancelled (by this client, or the server shutting down)."""


class InvalidArgument(RpcError):
    """INVALID_ARGUMENT: a field is wrong; ``message`` names it with expected vs actual."""


class DeadlineExceeded(RpcError):
    """DEADLINE_EXCEEDED: the call's deadline passed (see ``Client(deadline_s=…)`` and each call's ``deadline_s=``)."""


class NotFound(RpcError):
    """NOT_FOUND: an unknown model or version (or health service name)."""


class AlreadyExists(RpcError):
    """ALREADY_EXISTS."""


class PermissionDenied(RpcError):
    """PERMISSION_DENIED: the token is valid but not allowed (admin RPCs are locked)."""


class ResourceExhausted(RpcError):
    """RESOURCE_EXHAUSTED: a server limit (batch size, message size, concurrency, render queue)."""


class FailedPrecondition(RpcError):
    """FAILED_PRECONDITION: the model is the wrong kind for this call (no key points, no skeleton…)."""


class Aborted(RpcError):
    """ABORTED: e.g. another retrain of the same model is running."""


class OutOfRange(RpcError):
    """OUT_OF_RANGE: a well-formed request the model cannot satisfy (a vertex budget too small)."""


class Unimplemented(RpcError):
    """UNIMPLEMENTED: the server build does not provide this RPC (see ``server_info()``)."""


class Internal(RpcError):
    """INTERNAL: a server bug; report it with the message."""


class Unavailable(RpcError):
    """UNAVAILABLE: the server cannot be reached, or has no renderer for thumbnails."""


class DataLoss(RpcError):
    """DATA_LOSS: a model file in the repository is corrupt."""


class Unauthenticated(RpcError):
    """UNAUTHENTICATED: no token or a wrong one (``Client(token=…)``)."""


_BY_CODE: Dict[grpc.StatusCode, Type[RpcError]] = {
    grpc.StatusCode.CANCELLED: Cancelled,
    grpc.StatusCode.INVALID_ARGUMENT: InvalidArgument,
    grpc.StatusCode.DEADLINE_EXCEEDED: DeadlineExceeded,
    grpc.StatusCode.NOT_FOUND: NotFound,
    grpc.StatusCode.ALREADY_EXISTS: AlreadyExists,
    grpc.StatusCode.PERMISSION_DENIED: PermissionDenied,
    grpc.StatusCode.RESOURCE_EXHAUSTED: ResourceExhausted,
    grpc.StatusCode.FAILED_PRECONDITION: FailedPrecondition,
    grpc.StatusCode.ABORTED: Aborted,
    grpc.StatusCode.OUT_OF_RANGE: OutOfRange,
    grpc.StatusCode.UNIMPLEMENTED: Unimplemented,
    grpc.StatusCode.INTERNAL: Internal,
    grpc.StatusCode.UNAVAILABLE: Unavailable,
    grpc.StatusCode.DATA_LOSS: DataLoss,
    grpc.StatusCode.UNAUTHENTICATED: Unauthenticated,
}


def error_for_code(code: grpc.StatusCode) -> Type[RpcError]:
    """The RpcError subclass for a status code (RpcError itself for UNKNOWN and the rest)."""
    return _BY_CODE.get(code, RpcError)


def error_from_grpc(rpc: str, error: grpc.RpcError) -> RpcError:
    """The one mapping from a gRPC failure to this package's exceptions.

    ``error`` is what grpcio raised: for a finished call it is also a ``grpc.Call`` with
    ``code()`` and ``details()``; anything else (an error raised before a call existed) maps to
    UNKNOWN with its text, so that no grpc.RpcError ever escapes the client.
    """
    code: Optional[grpc.StatusCode] = None
    details: Optional[str] = None
    code_of = getattr(error, "code", None)
    details_of = getattr(error, "details", None)
    if callable(code_of):
        code = code_of()
    if callable(details_of):
        details = details_of()
    if not isinstance(code, grpc.StatusCode):
        code = grpc.StatusCode.UNKNOWN
    if details is None:
        details = str(error)
    return error_for_code(code)(rpc, code, details)
