"""numpy <-> protobuf: request building with shape checks against the model's description, and replies
turned into :mod:`fastrack.results`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Union

import numpy as np
import numpy.typing as npt

from . import results
from .errors import InvalidArgument, from_status
from .v1 import models_pb2, safety_pb2

#: A real number as a caller may hold it: a Python float or int, or a numpy scalar of any precision.
Real = Union[float, np.floating[Any], np.integer[Any]]

OutOfDomain = Literal["default", "reject", "flag"]
"""How a batch treats states outside the trained domain: ``"default"`` rejects a single item
(``OutOfRange``) and flags items of larger batches; ``"reject"`` rejects the request; ``"flag"`` evaluates
and flags every item (``in_domain = False``)."""

_POLICIES: dict[str, safety_pb2.OutOfDomainPolicy.ValueType] = {
    "default": safety_pb2.OUT_OF_DOMAIN_POLICY_UNSPECIFIED,
    "reject": safety_pb2.OUT_OF_DOMAIN_POLICY_REJECT,
    "flag": safety_pb2.OUT_OF_DOMAIN_POLICY_FLAG,
}


@dataclass(frozen=True)
class Dims:
    """The vector sizes of one model version, from its ``ModelInfo``."""

    model: str
    state: tuple[str, ...]
    params: tuple[str, ...]
    controls: tuple[str, ...]
    planner_dim: int

    @classmethod
    def of(cls, info: models_pb2.ModelInfo) -> Dims:
        return cls(
            model=f"{info.name}/{info.version}",
            state=tuple(d.name for d in info.state),
            params=tuple(d.name for d in info.params),
            controls=tuple(d.name for d in info.controls),
            planner_dim=info.planner_dim,
        )


def model_ref(name: str, version: int = 0) -> models_pb2.ModelRef:
    """``ModelRef`` for ``name`` at ``version`` (0: the server's default version)."""
    return models_pb2.ModelRef(name=name, version=version)


def policy(out_of_domain: OutOfDomain) -> safety_pb2.OutOfDomainPolicy.ValueType:
    try:
        return _POLICIES[out_of_domain]
    except KeyError:
        raise InvalidArgument(f"out_of_domain = {out_of_domain!r}; must be one of {', '.join(_POLICIES)}") from None


def _numbers(field: str, value: npt.ArrayLike) -> npt.NDArray[np.float64]:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidArgument(f"{field} must be an array of numbers: {e}") from None


def batch(dims: Dims, states: npt.ArrayLike, params: npt.ArrayLike) -> tuple[list[float], list[float], int]:
    """Checks ``states`` [N, n_state] and ``params`` [N, n_params] (or one [n_params] row, or one number,
    used for every item); returns both flattened row-major, and N."""
    s = _numbers("states", states)
    ns, npar = len(dims.state), len(dims.params)
    if s.ndim != 2 or s.shape[1] != ns or s.shape[0] == 0:
        raise InvalidArgument(
            f"states has shape {list(s.shape)}; model {dims.model} needs [N, n_state] = [N, {ns}] with N >= 1 "
            f"({', '.join(dims.state)} per row; one state: reshape(1, -1))"
        )
    n = s.shape[0]
    p = _numbers("params", params)
    if p.ndim < 2 and p.size in (1, npar):
        p = np.broadcast_to(p.reshape(1, -1) if p.size == npar else p.reshape(1, 1), (n, npar))
    if p.shape != (n, npar):
        raise InvalidArgument(
            f"params has shape {list(p.shape)}; model {dims.model} needs [N, n_params] = [{n}, {npar}] "
            f"({', '.join(dims.params)} per row) for the {n} states given, or one row of {npar} for all"
        )
    return s.ravel().tolist(), np.ascontiguousarray(p).ravel().tolist(), n


def _floats(values: Sequence[float], shape: tuple[int, ...]) -> results.Floats:
    return np.array(values[:], dtype=np.float64).reshape(shape)  # a list first: much faster than the container


def _bools(values: Sequence[bool]) -> results.Bools:
    return np.array(values[:], dtype=np.bool_)


def evaluation(reply: safety_pb2.EvaluateValueResponse, dims: Dims, n: int) -> results.Evaluation:
    return results.Evaluation(
        values=_floats(reply.values, (n,)),
        gradients=_floats(reply.gradients, (n, len(dims.state))),
        controls=_floats(reply.controls, (n, len(dims.controls))),
        in_teb=_bools(reply.in_teb),
        in_domain=_bools(reply.in_domain),
        model_version=reply.model_version,
    )


def tracking_control(reply: safety_pb2.TrackingControlResponse, dims: Dims, n: int) -> results.TrackingControl:
    return results.TrackingControl(
        controls=_floats(reply.controls, (n, len(dims.controls))),
        values=_floats(reply.values, (n,)),
        in_teb=_bools(reply.in_teb),
        in_domain=_bools(reply.in_domain),
        model_version=reply.model_version,
    )


def planner_control(reply: safety_pb2.QueryPlannerControlResponse) -> results.PlannerControl:
    return results.PlannerControl(
        beta_query=reply.beta_query,
        dteb_radius=reply.dteb_radius,
        steb_radius=reply.steb_radius,
        steb_exceeds_half_distance=reply.steb_exceeds_half_distance,
        model_version=reply.model_version,
    )


def tracking_error_bound(reply: safety_pb2.GetTrackingErrorBoundResponse) -> results.TrackingErrorBound:
    n_error = max(len(reply.extent), 1)
    return results.TrackingErrorBound(
        level=reply.level,
        radius=reply.radius,
        extent=_floats(reply.extent, (len(reply.extent),)),
        table_beta=reply.table_beta,
        boundary=_floats(reply.boundary, (len(reply.boundary) // n_error, n_error)),
        model_version=reply.model_version,
    )


def _vector(field: str, value: npt.ArrayLike, size: int, what: str, dims: Dims) -> list[float]:
    v = _numbers(field, value)
    if v.ndim != 1 or v.shape[0] != size:
        raise InvalidArgument(f"{field} has shape {list(v.shape)}; model {dims.model} needs [{size}] ({what})")
    values: list[float] = v.tolist()
    return values


def tick(
    dims: Dims,
    seq: int,
    tracker_state: npt.ArrayLike,
    planner_state: npt.ArrayLike,
    d_obs: Real | None,
    planner_clearance: Real | None = None,
) -> safety_pb2.TrackRequest:
    """A ``Track`` tick, its vectors checked against the model (tracker [n_state], planner [planner_dim])."""
    tracker = _vector("tracker_state", tracker_state, len(dims.state), ", ".join(dims.state), dims)
    planner = _vector("planner_state", planner_state, dims.planner_dim, "planner coordinates", dims)
    message = safety_pb2.TrackTick(seq=seq, tracker_state=tracker, planner_state=planner)
    if d_obs is not None:
        message.d_obs = float(d_obs)
    if planner_clearance is not None:
        message.planner_clearance = float(planner_clearance)
    return safety_pb2.TrackRequest(tick=message)


def planner_speed_request(
    model: str, version: int, d_obs: Real | None, planner_clearance: Real | None
) -> safety_pb2.QueryPlannerControlRequest:
    """A ``QueryPlannerControl`` request: the paper's rule on ``d_obs``, or the planner rule on
    ``planner_clearance`` when it is given."""
    request = safety_pb2.QueryPlannerControlRequest(model=model_ref(model, version))
    if d_obs is not None:
        request.d_obs = float(d_obs)
    if planner_clearance is not None:
        request.planner_clearance = float(planner_clearance)
    return request


def open_stream(name: str, version: int, idle_timeout: float) -> safety_pb2.TrackRequest:
    return safety_pb2.TrackRequest(
        open=safety_pb2.TrackOpen(model=model_ref(name, version), idle_timeout_s=idle_timeout)
    )


def track_reply(reply: safety_pb2.TrackReply) -> results.TrackReply:
    """The reply as a dataclass, or the tick's error (``TrackReply.error``) raised as its exception."""
    if reply.HasField("error"):
        raise from_status(reply.error.code, reply.error.message)
    return results.TrackReply(
        seq=reply.seq,
        beta_query=reply.beta_query,
        dteb_radius=reply.dteb_radius,
        steb_radius=reply.steb_radius,
        relative_state=_floats(reply.relative_state, (len(reply.relative_state),)),
        value=reply.value,
        in_teb=reply.in_teb,
        in_domain=reply.in_domain,
        control=_floats(reply.control, (len(reply.control),)),
    )
