"""The synchronous client, :class:`Client`."""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType
from typing import TypeVar

import grpc
import numpy.typing as npt
from google.protobuf.message import Message
from grpc_health.v1 import health_pb2

from . import convert, results
from .channel import DEFAULT_TIMEOUT_S, NO_RETRY, Retry, Settings, Tls
from .errors import FastrackError, Unavailable, from_rpc_error
from .replicas import Rotation, StreamCounts, all_unavailable, not_ready, replicas_wanted
from .track import SyncTrackStub, TrackStream
from .v1 import models_pb2, models_pb2_grpc, safety_pb2, safety_pb2_grpc

Request = TypeVar("Request", bound=Message)
Response = TypeVar("Response", bound=Message)

HEALTH_CHECK = "/grpc.health.v1.Health/Check"


class Replica:
    """One server of a :class:`Client`: its endpoint, its channel and the stubs on it."""

    def __init__(self, endpoint: str, channel: grpc.Channel) -> None:
        self.endpoint = endpoint
        self.channel = channel
        self.models = models_pb2_grpc.ModelServiceStub(channel)
        self.admin = models_pb2_grpc.ModelAdminServiceStub(channel)
        self.safety = safety_pb2_grpc.SafetyServiceStub(channel)
        self.health: grpc.UnaryUnaryMultiCallable[health_pb2.HealthCheckRequest, health_pb2.HealthCheckResponse]
        self.health = channel.unary_unary(
            HEALTH_CHECK,
            request_serializer=health_pb2.HealthCheckRequest.SerializeToString,
            response_deserializer=health_pb2.HealthCheckResponse.FromString,
        )


class Client:
    """A connection to a fastrack server, or to its replicas (``fastrack.v1`` over gRPC); thread-safe, cheap
    to share.

    ``address`` is ``host:port`` (or ``http://host:port``; ``https://host:port`` with ``tls``), several of
    them separated by commas, or a host name resolving to several addresses (e.g. a Kubernetes headless
    Service): each address is a replica, and calls go round-robin over them (see :mod:`fastrack.replicas`).
    ``timeout`` is the default deadline of unary calls in seconds (each method takes its own ``timeout``
    too); ``token`` is sent as ``authorization: Bearer <token>``; ``retry`` says how idempotent unary calls
    are retried on ``UNAVAILABLE`` (never ``Track`` nor the admin calls). Use as a context manager, or call
    :meth:`close`. Models are named by ``model`` (e.g. ``"dubins4d"``) and ``version`` (0: the server's
    default version).
    """

    def __init__(
        self,
        address: str = "127.0.0.1:50051",
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        token: str | None = None,
        tls: Tls | None = None,
        retry: Retry = Retry(),
        max_reconnect_backoff: float = 1.0,
    ) -> None:
        self.settings = Settings(address, timeout, token, tls, retry, max_reconnect_backoff)
        endpoints = self.settings.endpoints()
        credentials = self.settings.credentials()
        self._replicas = Rotation([Replica(e.target, self.settings.sync_channel(e, credentials)) for e in endpoints])
        self._streams = StreamCounts(self.endpoints)
        self._dims: dict[tuple[str, int], convert.Dims] = {}

    @property
    def stream_counts(self) -> list[int]:
        """This client's open ``Track`` streams on each replica, in the order of :attr:`endpoints`."""
        return self._streams.counts()

    @property
    def endpoints(self) -> list[str]:
        """The replicas' endpoints (``host:port``), in round-robin order."""
        return [replica.endpoint for replica in self._replicas.replicas]

    @property
    def channel(self) -> grpc.Channel:
        """The gRPC channel to the first replica (for stubs of one's own)."""
        return self._replicas.replicas[0].channel

    def _unary(
        self,
        rpc: Callable[[Replica], grpc.UnaryUnaryMultiCallable[Request, Response]],
        request: Request,
        timeout: float | None,
        idempotent: bool = True,
    ) -> Response:
        """One unary call with the token and deadline. ``idempotent``: on the next replica, then on the
        following ones while they answer UNAVAILABLE, the whole pass repeated with backoff as the retry
        policy says; otherwise on the next replica only, once."""
        policy = self.settings.retry if idempotent else NO_RETRY
        deadline = self.settings.timeout if timeout is None else timeout
        for attempt in range(policy.attempts):
            failures: list[tuple[str, FastrackError]] = []
            for replica in self._replicas.rotation() if idempotent else [self._replicas.next()]:
                try:
                    return rpc(replica)(request, timeout=deadline, metadata=self.settings.metadata)
                except grpc.RpcError as e:
                    error = from_rpc_error(e)
                if not isinstance(error, Unavailable):
                    raise error
                failures.append((replica.endpoint, error))
            if attempt + 1 == policy.attempts:
                raise all_unavailable(failures)
            time.sleep(policy.delay(attempt))
        raise AssertionError("unreachable: Retry.attempts >= 1")

    def health(self, service: str = "", *, timeout: float | None = None) -> str:
        """The health (``grpc.health.v1``) of the next replica: ``"SERVING"``, ``"NOT_SERVING"``, ..."""
        request = health_pb2.HealthCheckRequest(service=service)
        reply = self._unary(lambda r: r.health, request, timeout, idempotent=False)
        return health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)

    def serving_replicas(self, *, timeout: float | None = None) -> list[str]:
        """The endpoints of the replicas whose health is ``SERVING`` now (each asked once)."""
        deadline = self.settings.timeout if timeout is None else timeout
        serving = []
        for replica in self._replicas.replicas:
            try:
                reply = replica.health(health_pb2.HealthCheckRequest(), timeout=deadline, metadata=self.settings.metadata)
            except grpc.RpcError:
                continue
            if reply.status == health_pb2.HealthCheckResponse.SERVING:
                serving.append(replica.endpoint)
        return serving

    def wait_until_serving(self, timeout: float = 30.0, *, quorum: int | None = None) -> None:
        """Polls every replica's health until all of them (or ``quorum`` of them, clamped to 1 .. the number of
        replicas) are ``SERVING``; raises :class:`Unavailable` after ``timeout`` seconds, saying how many were."""
        wanted = replicas_wanted(quorum, len(self._replicas.replicas))
        end = time.monotonic() + timeout
        while True:
            serving = self.serving_replicas(timeout=max(0.05, min(1.0, end - time.monotonic())))
            if len(serving) >= wanted:
                return
            if time.monotonic() >= end:
                raise not_ready(self.settings.address, serving, len(self._replicas.replicas), wanted, timeout)
            time.sleep(0.05)

    def list_models(self, *, timeout: float | None = None) -> list[models_pb2.ModelInfo]:
        """Every loaded model version, by name then version."""
        return list(self._unary(lambda r: r.models.ListModels, models_pb2.ListModelsRequest(), timeout).models)

    def get_model(self, model: str, version: int = 0, *, timeout: float | None = None) -> models_pb2.ModelInfo:
        """One model version's description: state, parameters, controls (with units and bounds), TEB table."""
        request = models_pb2.GetModelRequest(model=convert.model_ref(model, version))
        info = self._unary(lambda r: r.models.GetModel, request, timeout).model
        self._dims[(model, version)] = convert.Dims.of(info)
        return info

    def dims(self, model: str, version: int = 0) -> convert.Dims:
        """The model's vector sizes, fetched once (``GetModel``) and cached."""
        found = self._dims.get((model, version))
        if found is None:
            self.get_model(model, version)
            found = self._dims[(model, version)]
        return found

    def query_planner_control(
        self,
        model: str,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
        version: int = 0,
        timeout: float | None = None,
    ) -> results.PlannerControl:
        """queryPlannerControl: the fastest planner speed bound whose TEB fits ``d_obs / 2``.

        ``d_obs`` is the distance from the tracker to the nearest sensed obstacle, metres (None: none sensed,
        the fastest beta is returned). With ``planner_clearance`` (the planner's distance to the nearest sensed
        obstacle less the farthest one control period can move it, metres) the planner rule answers instead:
        the fastest planner speed bound whose TEB is less than it.
        """
        request = convert.planner_speed_request(model, version, d_obs, planner_clearance)
        return convert.planner_control(self._unary(lambda r: r.safety.QueryPlannerControl, request, timeout))

    def tracking_error_bound(
        self,
        model: str,
        beta: convert.Real,
        boundary_points: int = 0,
        *,
        version: int = 0,
        timeout: float | None = None,
    ) -> results.TrackingErrorBound:
        """The tracking error bound for planner speed bound ``beta`` (m/s, within the model's range), with
        ``boundary_points`` points on its boundary (0: none, at most 4096)."""
        request = safety_pb2.GetTrackingErrorBoundRequest(
            model=convert.model_ref(model, version), beta=float(beta), boundary_points=boundary_points
        )
        return convert.tracking_error_bound(self._unary(lambda r: r.safety.GetTrackingErrorBound, request, timeout))

    def evaluate(
        self,
        model: str,
        states: npt.ArrayLike,
        params: npt.ArrayLike,
        *,
        out_of_domain: convert.OutOfDomain = "default",
        version: int = 0,
        timeout: float | None = None,
    ) -> results.Evaluation:
        """V, dV/dr, the optimal control u* and TEB membership for a batch.

        ``states`` are relative states r [N, n_state] (dubins4d: x_r m, y_r m, theta rad, v m/s); ``params``
        [N, n_params] (the shipped dubins4d has one, beta in m/s; :meth:`get_model` lists a model's), or one
        row (or number) for every item. Shapes are checked against the model before sending.
        """
        dims = self.dims(model, version)
        s, p, n = convert.batch(dims, states, params)
        request = safety_pb2.EvaluateValueRequest(
            model=convert.model_ref(model, version), states=s, params=p, out_of_domain=convert.policy(out_of_domain)
        )
        return convert.evaluation(self._unary(lambda r: r.safety.EvaluateValue, request, timeout), dims, n)

    def tracking_control(
        self,
        model: str,
        states: npt.ArrayLike,
        params: npt.ArrayLike,
        *,
        out_of_domain: convert.OutOfDomain = "default",
        version: int = 0,
        timeout: float | None = None,
    ) -> results.TrackingControl:
        """The optimal tracking control u* (with V and TEB membership) for a batch; arguments as :meth:`evaluate`."""
        dims = self.dims(model, version)
        s, p, n = convert.batch(dims, states, params)
        request = safety_pb2.TrackingControlRequest(
            model=convert.model_ref(model, version), states=s, params=p, out_of_domain=convert.policy(out_of_domain)
        )
        return convert.tracking_control(self._unary(lambda r: r.safety.TrackingControl, request, timeout), dims, n)

    def track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> TrackStream:
        """Opens a ``Track`` stream for one robot on the next replica that takes it (no deadline; the server
        closes it after ``idle_timeout`` seconds without a tick, 0: the server's default). Use as ``with
        client.track("dubins4d") as robot``. The stream moves to another replica when its own goes away
        (see :mod:`fastrack.track`)."""
        dims = self.dims(model, version)
        open_request = convert.open_stream(model, version, idle_timeout)
        return TrackStream(self._track_stubs, self._streams, self.settings.metadata, dims, open_request)

    def _track_stubs(self) -> list[tuple[str, SyncTrackStub]]:
        return [(replica.endpoint, replica.safety.Track) for replica in self._replicas.rotation()]

    def load_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin, on the next replica only: loads a model from its repository (version 0: every version); the
        loaded versions."""
        request = models_pb2.LoadModelRequest(name=name, version=version)
        return list(self._unary(lambda r: r.admin.LoadModel, request, timeout, idempotent=False).loaded_versions)

    def unload_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin: stops serving a model (version 0: every version); the unloaded versions."""
        request = models_pb2.UnloadModelRequest(name=name, version=version)
        return list(self._unary(lambda r: r.admin.UnloadModel, request, timeout, idempotent=False).unloaded_versions)

    def reload_model(self, name: str = "", *, timeout: float | None = None) -> list[models_pb2.ReloadOutcome]:
        """Admin: re-reads a model (empty name: the whole repository) from disk; one outcome per version."""
        request = models_pb2.ReloadModelRequest(name=name)
        return list(self._unary(lambda r: r.admin.ReloadModel, request, timeout, idempotent=False).outcomes)

    def close(self) -> None:
        """Closes the connections (open streams end)."""
        for replica in self._replicas.replicas:
            replica.channel.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

