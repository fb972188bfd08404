"""Python client of the fastrack safety service (``fastrack.v1`` over gRPC): learned tracking error bounds
and optimal tracking controls of Parametric FaSTrack.

>>> import numpy as np, fastrack
>>> with fastrack.Client("127.0.0.1:50051") as client:  # doctest: +SKIP
...     speed = client.query_planner_control("dubins4d", d_obs=2.5)
...     with client.track("dubins4d") as robot:
...         reply = robot.tick([0.1, 0.0, 0.0, 1.0], [0.0, 0.0], d_obs=2.5)

Units are those of the model (``get_model``): for ``dubins4d`` metres, radians, m/s, rad/s and m/s^2.

An address may name several replicas (``"10.0.0.5:50051,10.0.0.6:50051"``, or a host name resolving to
several addresses): calls go round-robin over them, idempotent ones skip a replica that is gone, and
``Track`` streams move to another replica when theirs goes away (:mod:`fastrack.replicas`,
:mod:`fastrack.track`).

:class:`OnlineLoop` is the robot's half of Parametric FaSTrack (the paper's Alg. 3) over one ``Track`` stream:
each step takes the tracker state and the sensed obstacles (:mod:`fastrack.geometry`) and answers the
planner speed bound, the planner state to follow and the tracking control (:mod:`fastrack.online`).
"""

from . import geometry, online
from .aio import AsyncClient
from .channel import Retry, Tls
from .client import Client
from .convert import Dims, OutOfDomain
from .geometry import Circle, Rectangle, Wall
from .online import GridAStar, OnlineLoop, OnlineLoopError, RawPathPlanner, StepReport, StraightLine
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
    "Circle",
    "GridAStar",
    "OnlineLoop",
    "OnlineLoopError",
    "RawPathPlanner",
    "Rectangle",
    "StepReport",
    "StraightLine",
    "Wall",
    "geometry",
    "online",
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
