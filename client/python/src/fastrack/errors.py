"""Exceptions: one class per gRPC status the server answers with, all subclasses of :class:`FastrackError`.

Every exception carries the status ``code`` (a :class:`grpc.StatusCode`) and the server's ``message``
(what was wrong and what is allowed). Errors the client finds before sending anything (a batch of the
wrong shape, an unusable TLS file) use the same classes, so one ``except`` covers both.
"""

from __future__ import annotations

import grpc


class FastrackError(Exception):
    """A call failed: ``code`` is its gRPC status code, ``message`` the server's (or client's) reason."""

    default_code: grpc.StatusCode = grpc.StatusCode.UNKNOWN

    def __init__(self, message: str, code: grpc.StatusCode | None = None) -> None:
        self.code: grpc.StatusCode = code if code is not None else self.default_code
        self.message: str = message
        super().__init__(f"{self.code.name}: {message}")


class InvalidArgument(FastrackError):
    """A request field is malformed: wrong length or shape, NaN, a parameter outside its trained range."""

    default_code = grpc.StatusCode.INVALID_ARGUMENT


class ConfigError(InvalidArgument):
    """A client setting is unusable (an address, a TLS file, a token); found before any call."""


class NotFound(FastrackError):
    """The model, or the model version, is not loaded."""

    default_code = grpc.StatusCode.NOT_FOUND


class OutOfRange(FastrackError):
    """A state lies outside the model's trained domain (or a message exceeds the size limit)."""

    default_code = grpc.StatusCode.OUT_OF_RANGE


class Unavailable(FastrackError):
    """The server cannot answer now: unreachable, still loading, nothing loaded or shutting down."""

    default_code = grpc.StatusCode.UNAVAILABLE


class ResourceExhausted(FastrackError):
    """The server's compute queue is full: retry with backoff."""

    default_code = grpc.StatusCode.RESOURCE_EXHAUSTED


class DeadlineExceeded(FastrackError):
    """The call's deadline passed, or a ``Track`` stream was idle past its timeout."""

    default_code = grpc.StatusCode.DEADLINE_EXCEEDED


class Unauthenticated(FastrackError):
    """No bearer token, or one the server does not recognise."""

    default_code = grpc.StatusCode.UNAUTHENTICATED


class PermissionDenied(FastrackError):
    """A user token on a call that needs an admin token (``ModelAdminService``)."""

    default_code = grpc.StatusCode.PERMISSION_DENIED


class FailedPrecondition(FastrackError):
    """The request cannot be served in the current state (e.g. no loadable version of a model)."""

    default_code = grpc.StatusCode.FAILED_PRECONDITION


class Internal(FastrackError):
    """The server failed to evaluate a loaded model (ONNX Runtime error)."""

    default_code = grpc.StatusCode.INTERNAL


class Cancelled(FastrackError):
    """The call was cancelled (e.g. a ``Track`` stream closed before its ``open``)."""

    default_code = grpc.StatusCode.CANCELLED


_BY_CODE: dict[grpc.StatusCode, type[FastrackError]] = {
    cls.default_code: cls
    for cls in (
        InvalidArgument,
        NotFound,
        OutOfRange,
        Unavailable,
        ResourceExhausted,
        DeadlineExceeded,
        Unauthenticated,
        PermissionDenied,
        FailedPrecondition,
        Internal,
        Cancelled,
    )
}
_BY_NUMBER: dict[int, grpc.StatusCode] = {code.value[0]: code for code in grpc.StatusCode}


def from_status(code: grpc.StatusCode | int, message: str) -> FastrackError:
    """The exception for a status code (enum or number, as in ``TickError.code``) and message."""
    status = code if isinstance(code, grpc.StatusCode) else _BY_NUMBER.get(code, grpc.StatusCode.UNKNOWN)
    return _BY_CODE.get(status, FastrackError)(message, status)


# What the server's gRPC stack (tonic) answers when a call's deadline passes on the server first.
SERVER_TIMEOUT = "Timeout expired"


def from_rpc_error(error: grpc.RpcError) -> FastrackError:
    """The exception for a failed call (sync ``grpc.RpcError`` or ``grpc.aio.AioRpcError``)."""
    code = error.code() if isinstance(error, (grpc.Call, grpc.aio.AioRpcError)) else None
    details = error.details() if isinstance(error, (grpc.Call, grpc.aio.AioRpcError)) else None
    if code == grpc.StatusCode.CANCELLED and details == SERVER_TIMEOUT:
        # The server's gRPC stack ends a call whose deadline passed with CANCELLED "Timeout expired" when its
        # own timer fires before the client's: the deadline expired either way.
        code = grpc.StatusCode.DEADLINE_EXCEEDED
    return from_status(code or grpc.StatusCode.UNKNOWN, details or str(error))
