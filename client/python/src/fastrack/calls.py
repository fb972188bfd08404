"""What both clients share, apart from how they wait: the replicas and their stubs (:class:`Replica`), the
state a client keeps (:class:`Connection`), what each unary call sends and how its reply becomes a result
(:class:`Call` and one function per call), and the passes a call makes over the replicas (:class:`Attempts`).
:class:`fastrack.Client` sends calls with blocking gRPC, :class:`fastrack.AsyncClient` awaits them."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeAlias, TypeVar, cast

import grpc
import grpc.aio
import numpy.typing as npt
from google.protobuf.message import Message
from grpc_health.v1 import health_pb2

from . import convert, results
from .channel import DEFAULT_TIMEOUT_S, NO_RETRY, Endpoint, Retry, Settings, Tls
from .errors import DeadlineExceeded, FastrackError, Unavailable, from_rpc_error
from .replicas import Rotation, StreamCounts, all_unavailable
from .track import Opening, Stub
from .v1 import models_pb2, models_pb2_grpc, safety_pb2, safety_pb2_grpc

HEALTH_CHECK = "/grpc.health.v1.Health/Check"

ChannelT = TypeVar("ChannelT", grpc.Channel, grpc.aio.Channel)
Reply = TypeVar("Reply", bound=Message)
Result = TypeVar("Result")

HealthCheck: TypeAlias = "grpc.UnaryUnaryMultiCallable[health_pb2.HealthCheckRequest, health_pb2.HealthCheckResponse]"


class Replica(Generic[ChannelT]):
    """One server: its endpoint, its channel and the stubs on it. The stubs are typed as the blocking ones;
    on an asyncio channel they return awaitables, which the asyncio client awaits."""

    def __init__(self, endpoint: str, channel: ChannelT) -> None:
        self.endpoint = endpoint
        self.channel: ChannelT = channel
        self.models: models_pb2_grpc.ModelServiceStub = models_pb2_grpc.ModelServiceStub(channel)
        self.admin: models_pb2_grpc.ModelAdminServiceStub = models_pb2_grpc.ModelAdminServiceStub(channel)
        self.safety: safety_pb2_grpc.SafetyServiceStub = safety_pb2_grpc.SafetyServiceStub(channel)
        health = channel.unary_unary(
            HEALTH_CHECK,
            request_serializer=health_pb2.HealthCheckRequest.SerializeToString,
            response_deserializer=health_pb2.HealthCheckResponse.FromString,
        )
        self.health = cast(HealthCheck, health)


class Connection(Generic[ChannelT]):
    """What a client keeps: its settings, its replicas (round-robin), its open streams per replica and the
    model sizes it has fetched. Arguments as :class:`fastrack.Client`."""

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
        endpoints = self.settings.endpoints()  # address errors first, then the TLS files
        credentials = self.settings.credentials()
        replicas = [Replica(e.target, self._open(e, credentials)) for e in endpoints]
        self._replicas: Rotation[Replica[ChannelT]] = Rotation(replicas)
        self._streams = StreamCounts(self.endpoints)
        self._dims: dict[tuple[str, int], convert.Dims] = {}

    def _open(self, endpoint: Endpoint, credentials: grpc.ChannelCredentials | None) -> ChannelT:
        """A channel to one replica, of the client's kind."""
        raise NotImplementedError

    @property
    def stream_counts(self) -> list[int]:
        """This client's open ``Track`` streams on each replica, in the order of :attr:`endpoints`."""
        return self._streams.counts()

    @property
    def endpoints(self) -> list[str]:
        """The replicas' endpoints (``host:port``), in round-robin order."""
        return [replica.endpoint for replica in self._replicas.replicas]

    @property
    def channel(self) -> ChannelT:
        """The gRPC channel to the first replica (for stubs of one's own)."""
        return self._replicas.replicas[0].channel

    def _attempts(self, idempotent: bool) -> Attempts[Replica[ChannelT]]:
        return Attempts(self.settings.retry if idempotent else NO_RETRY, self._replicas, idempotent)

    def _deadline(self, timeout: float | None) -> float:
        return self.settings.timeout if timeout is None else timeout

    def _opening(
        self, stubs: Callable[[], list[tuple[str, Stub]]], model: str, version: int, idle_timeout: float
    ) -> Opening[Stub]:
        """What a new ``Track`` stream needs (the model's sizes fetched already), opening on ``stubs``."""
        dims = self._dims[(model, version)]
        open_request = convert.open_stream(model, version, idle_timeout)
        return Opening(stubs, self._streams, self.settings.metadata, dims, open_request, self.settings.timeout)

    def _remember(self, model: str, version: int, info: models_pb2.ModelInfo) -> models_pb2.ModelInfo:
        self._dims[(model, version)] = convert.Dims.of(info)
        return info


R = TypeVar("R", bound=Replica[Any])


class Attempts(Generic[R]):
    """The passes one unary call makes over the replicas. Idempotent: each pass tries every replica once from
    the next in turn, and passes repeat with backoff as the retry policy says; otherwise one replica, once.
    A failure other than ``UNAVAILABLE`` ends the call at once, but for an idempotent call's
    ``DEADLINE_EXCEEDED``: a replica that does not answer in time (a frozen server) is passed over for the
    next, and no pass follows the one it happened in (each replica had its deadline)."""

    def __init__(self, policy: Retry, replicas: Rotation[R], idempotent: bool) -> None:
        self._policy = policy
        self._replicas = replicas
        self._idempotent = idempotent
        self._failures: list[tuple[str, FastrackError]] = []

    def passes(self) -> Iterator[tuple[float, list[R]]]:
        """Each pass: the seconds to wait before it, and the replicas it tries in order."""
        for attempt in range(self._policy.attempts):
            if any(isinstance(failure, DeadlineExceeded) for _, failure in self._failures):
                return
            self._failures = []
            wait = 0.0 if attempt == 0 else self._policy.delay(attempt - 1)
            yield wait, self._replicas.rotation() if self._idempotent else [self._replicas.next()]

    def failed(self, replica: R, error: grpc.RpcError) -> None:
        """Records a replica's failure, or raises it when it does not pass the call over to the next."""
        failure = from_rpc_error(error)
        passed_over = isinstance(failure, Unavailable) or (self._idempotent and isinstance(failure, DeadlineExceeded))
        if not passed_over:
            raise failure
        self._failures.append((replica.endpoint, failure))

    def exhausted(self) -> FastrackError:
        """The error of a call whose passes all failed."""
        return all_unavailable(self._failures)


@dataclass(frozen=True)
class Call(Generic[Reply, Result]):
    """One unary call: the stub method it goes to, its request, and what makes its result of the reply."""

    rpc: Callable[[Replica[Any]], grpc.UnaryUnaryMultiCallable[Any, Reply]]
    request: Message
    finish: Callable[[Reply], Result]
    idempotent: bool = True


def health(service: str) -> Call[health_pb2.HealthCheckResponse, str]:
    """``grpc.health.v1`` Check, on one replica: the status's name."""
    return Call(
        lambda r: r.health,
        health_pb2.HealthCheckRequest(service=service),
        lambda reply: health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status),
        idempotent=False,
    )


def list_models() -> Call[models_pb2.ListModelsResponse, list[models_pb2.ModelInfo]]:
    """``ListModels``: every loaded model version."""
    return Call(lambda r: r.models.ListModels, models_pb2.ListModelsRequest(), lambda reply: list(reply.models))


def get_model(model: str, version: int) -> Call[models_pb2.GetModelResponse, models_pb2.ModelInfo]:
    """``GetModel``: one model version's description."""
    request = models_pb2.GetModelRequest(model=convert.model_ref(model, version))
    return Call(lambda r: r.models.GetModel, request, lambda reply: reply.model)


def query_planner_control(
    model: str, version: int, d_obs: convert.Real | None, planner_clearance: convert.Real | None
) -> Call[safety_pb2.QueryPlannerControlResponse, results.PlannerControl]:
    """``QueryPlannerControl`` by the paper's rule on ``d_obs``, or by the planner rule on
    ``planner_clearance`` when it is given."""
    request = convert.planner_speed_request(model, version, d_obs, planner_clearance)
    return Call(lambda r: r.safety.QueryPlannerControl, request, convert.planner_control)


def tracking_error_bound(
    model: str, version: int, beta: convert.Real, boundary_points: int
) -> Call[safety_pb2.GetTrackingErrorBoundResponse, results.TrackingErrorBound]:
    """``GetTrackingErrorBound`` for one ``beta``, with ``boundary_points`` points on its boundary."""
    request = safety_pb2.GetTrackingErrorBoundRequest(
        model=convert.model_ref(model, version), beta=float(beta), boundary_points=boundary_points
    )
    return Call(lambda r: r.safety.GetTrackingErrorBound, request, convert.tracking_error_bound)


BatchRequest = TypeVar("BatchRequest", safety_pb2.EvaluateValueRequest, safety_pb2.TrackingControlRequest)


@dataclass(frozen=True)
class Batch:
    """A batch of relative states and parameters for one model version, as the caller gave them."""

    dims: convert.Dims
    model: str
    version: int
    states: npt.ArrayLike
    params: npt.ArrayLike
    out_of_domain: convert.OutOfDomain

    def request(self, kind: type[BatchRequest]) -> tuple[BatchRequest, int]:
        """The request of the given kind and the batch's size, its shapes checked against the model first."""
        s, p, n = convert.batch(self.dims, self.states, self.params)
        model = convert.model_ref(self.model, self.version)
        return kind(model=model, states=s, params=p, out_of_domain=convert.policy(self.out_of_domain)), n


def evaluate(batch: Batch) -> Call[safety_pb2.EvaluateValueResponse, results.Evaluation]:
    """``EvaluateValue`` for a batch."""
    request, n = batch.request(safety_pb2.EvaluateValueRequest)
    return Call(lambda r: r.safety.EvaluateValue, request, lambda reply: convert.evaluation(reply, batch.dims, n))


def tracking_control(batch: Batch) -> Call[safety_pb2.TrackingControlResponse, results.TrackingControl]:
    """``TrackingControl`` for a batch."""
    request, n = batch.request(safety_pb2.TrackingControlRequest)
    return Call(
        lambda r: r.safety.TrackingControl, request, lambda reply: convert.tracking_control(reply, batch.dims, n)
    )


def load_model(name: str, version: int) -> Call[models_pb2.LoadModelResponse, list[int]]:
    """Admin ``LoadModel``, on one replica: the loaded versions."""
    request = models_pb2.LoadModelRequest(name=name, version=version)
    return Call(lambda r: r.admin.LoadModel, request, lambda reply: list(reply.loaded_versions), idempotent=False)


def unload_model(name: str, version: int) -> Call[models_pb2.UnloadModelResponse, list[int]]:
    """Admin ``UnloadModel``, on one replica: the unloaded versions."""
    request = models_pb2.UnloadModelRequest(name=name, version=version)
    return Call(lambda r: r.admin.UnloadModel, request, lambda reply: list(reply.unloaded_versions), idempotent=False)


def reload_model(name: str) -> Call[models_pb2.ReloadModelResponse, list[models_pb2.ReloadOutcome]]:
    """Admin ``ReloadModel``, on one replica: one outcome per version."""
    request = models_pb2.ReloadModelRequest(name=name)
    return Call(lambda r: r.admin.ReloadModel, request, lambda reply: list(reply.outcomes), idempotent=False)
