"""Python client of the fastrack safety service (``fastrack.v1`` over gRPC): learned tracking error bounds
and optimal tracking controls of Parametric FaSTrack.

>>> import numpy as np, fastrack
>>> with fastrack.Client("127.0.0.1:50051") as client:  # doctest: +SKIP
...     speed = client.query_planner_control("dubins4d", d_obs=2.5)
...     with client.track("dubins4d") as robot:
...         reply = robot.tick([0.1, 0.0, 0.0, 1.0], [0.0, 0.0], d_obs=2.5)

Units are those of the model (``get_model``): for ``dubins4d`` metres, radians, m/s, rad/s and m/s^2.
"""

from .aio import AsyncClient
from .channel import Retry, Tls
from .client import Client
from .convert import Dims, OutOfDomain
from .errors import (
    Cancelled,
    ConfigError,
    DeadlineExceeded,
    FailedPrecondition,
    FastrackError,
    Internal,
    InvalidArgument,
    NotFound,
    OutOfRange,
    PermissionDenied,
    ResourceExhausted,
    Unauthenticated,
    Unavailable,
)
from .results import Evaluation, PlannerControl, TrackingControl, TrackingErrorBound, TrackReply
from .track import AsyncTrackStream, TrackStream

__all__ = [
    "AsyncClient",
    "AsyncTrackStream",
    "Cancelled",
    "Client",
    "ConfigError",
    "DeadlineExceeded",
    "Dims",
    "Evaluation",
    "FailedPrecondition",
    "FastrackError",
    "Internal",
    "InvalidArgument",
    "NotFound",
    "OutOfDomain",
    "OutOfRange",
    "PermissionDenied",
    "PlannerControl",
    "ResourceExhausted",
    "Retry",
    "Tls",
    "TrackReply",
    "TrackStream",
    "TrackingControl",
    "TrackingErrorBound",
    "Unauthenticated",
    "Unavailable",
]
