"""The asyncio client, :class:`AsyncClient` (on ``grpc.aio``): the same calls as :class:`fastrack.Client`,
awaited. Create it inside the event loop that uses it."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from types import TracebackType
from typing import TypeVar

import grpc
import grpc.aio
import numpy.typing as npt
from google.protobuf.message import Message
from grpc_health.v1 import health_pb2

from . import convert, results
from .channel import DEFAULT_TIMEOUT_S, NO_RETRY, Retry, Settings, Tls
from .client import HEALTH_CHECK
from .errors import FastrackError, Unavailable, from_rpc_error
from .replicas import Rotation, StreamCounts, all_unavailable, not_ready, replicas_wanted
from .track import AsyncTrackStream, AsyncTrackStub
from .v1 import models_pb2, models_pb2_grpc, safety_pb2, safety_pb2_grpc

Request = TypeVar("Request", bound=Message)
Response = TypeVar("Response", bound=Message)


class AsyncReplica:
    """One server of an :class:`AsyncClient`: its endpoint, its channel and the stubs on it."""

    def __init__(self, endpoint: str, channel: grpc.aio.Channel) -> None:
        self.endpoint = endpoint
        self.channel = channel
        self.models = models_pb2_grpc.ModelServiceStub(channel)
        self.admin = models_pb2_grpc.ModelAdminServiceStub(channel)
        self.safety = safety_pb2_grpc.SafetyServiceStub(channel)
        self.health: grpc.aio.UnaryUnaryMultiCallable[health_pb2.HealthCheckRequest, health_pb2.HealthCheckResponse]
        self.health = channel.unary_unary(
            HEALTH_CHECK,
            request_serializer=health_pb2.HealthCheckRequest.SerializeToString,
            response_deserializer=health_pb2.HealthCheckResponse.FromString,
        )


class AsyncClient:
    """An asyncio connection to a fastrack server or its replicas; arguments and methods as
    :class:`fastrack.Client`.

    Use as ``async with AsyncClient("127.0.0.1:50051") as client``; many coroutines may share it (e.g. one
    ``async with client.track(...)`` per robot).
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
        replicas = [AsyncReplica(e.target, self.settings.aio_channel(e, credentials)) for e in endpoints]
        self._replicas = Rotation(replicas)
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
    def channel(self) -> grpc.aio.Channel:
        """The gRPC channel to the first replica (for stubs of one's own)."""
        return self._replicas.replicas[0].channel

    async def _unary(
        self,
        rpc: Callable[[AsyncReplica], grpc.aio.UnaryUnaryMultiCallable[Request, Response]],
        request: Request,
        timeout: float | None,
        idempotent: bool = True,
    ) -> Response:
        """One unary call with the token and deadline, over the replicas as :meth:`fastrack.Client._unary`."""
        policy = self.settings.retry if idempotent else NO_RETRY
        deadline = self.settings.timeout if timeout is None else timeout
        for attempt in range(policy.attempts):
            failures: list[tuple[str, FastrackError]] = []
            for replica in self._replicas.rotation() if idempotent else [self._replicas.next()]:
                try:
                    return await rpc(replica)(request, timeout=deadline, metadata=self.settings.metadata)
                except grpc.RpcError as e:
                    error = from_rpc_error(e)
                if not isinstance(error, Unavailable):
                    raise error
                failures.append((replica.endpoint, error))
            if attempt + 1 == policy.attempts:
                raise all_unavailable(failures)
            await asyncio.sleep(policy.delay(attempt))
        raise AssertionError("unreachable: Retry.attempts >= 1")

    async def health(self, service: str = "", *, timeout: float | None = None) -> str:
        """The health (``grpc.health.v1``) of the next replica: ``"SERVING"``, ``"NOT_SERVING"``, ..."""
        request = health_pb2.HealthCheckRequest(service=service)
        reply = await self._unary(lambda r: r.health, request, timeout, idempotent=False)
        return health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)

    async def serving_replicas(self, *, timeout: float | None = None) -> list[str]:
        """The endpoints of the replicas whose health is ``SERVING`` now (asked at once)."""
        deadline = self.settings.timeout if timeout is None else timeout

        async def serving(replica: AsyncReplica) -> bool:
            try:
                request = health_pb2.HealthCheckRequest()
                reply = await replica.health(request, timeout=deadline, metadata=self.settings.metadata)
            except grpc.RpcError:
                return False
            return reply.status == health_pb2.HealthCheckResponse.SERVING

        replicas = self._replicas.replicas
        answers = await asyncio.gather(*(serving(replica) for replica in replicas))
        return [replica.endpoint for replica, ok in zip(replicas, answers) if ok]

    async def wait_until_serving(self, timeout: float = 30.0, *, quorum: int | None = None) -> None:
        """Polls every replica's health until all of them (or ``quorum`` of them, clamped to 1 .. the number of
        replicas) are ``SERVING``; raises :class:`Unavailable` after ``timeout`` seconds, saying how many were."""
        wanted = replicas_wanted(quorum, len(self._replicas.replicas))
        end = time.monotonic() + timeout
        while True:
            serving = await self.serving_replicas(timeout=max(0.05, min(1.0, end - time.monotonic())))
            if len(serving) >= wanted:
                return
            if time.monotonic() >= end:
                raise not_ready(self.settings.address, serving, len(self._replicas.replicas), wanted, timeout)
            await asyncio.sleep(0.05)

    async def list_models(self, *, timeout: float | None = None) -> list[models_pb2.ModelInfo]:
        """Every loaded model version, by name then version."""
        return list((await self._unary(lambda r: r.models.ListModels, models_pb2.ListModelsRequest(), timeout)).models)

    async def get_model(self, model: str, version: int = 0, *, timeout: float | None = None) -> models_pb2.ModelInfo:
        """One model version's description: state, parameters, controls (with units and bounds), TEB table."""
        request = models_pb2.GetModelRequest(model=convert.model_ref(model, version))
        info = (await self._unary(lambda r: r.models.GetModel, request, timeout)).model
        self._dims[(model, version)] = convert.Dims.of(info)
        return info

    async def dims(self, model: str, version: int = 0) -> convert.Dims:
        """The model's vector sizes, fetched once (``GetModel``) and cached."""
        found = self._dims.get((model, version))
        if found is None:
            await self.get_model(model, version)
            found = self._dims[(model, version)]
        return found

    async def query_planner_control(
        self,
        model: str,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
        version: int = 0,
        timeout: float | None = None,
    ) -> results.PlannerControl:
        """queryPlannerControl for an obstacle at ``d_obs`` metres (None: none sensed), or the planner rule
        on ``planner_clearance`` (see :meth:`fastrack.Client.query_planner_control`)."""
        request = convert.planner_speed_request(model, version, d_obs, planner_clearance)
        return convert.planner_control(await self._unary(lambda r: r.safety.QueryPlannerControl, request, timeout))

    async def tracking_error_bound(
        self,
        model: str,
        beta: convert.Real,
        boundary_points: int = 0,
        *,
        version: int = 0,
        timeout: float | None = None,
    ) -> results.TrackingErrorBound:
        """The tracking error bound for planner speed bound ``beta`` (m/s)."""
        request = safety_pb2.GetTrackingErrorBoundRequest(
            model=convert.model_ref(model, version), beta=float(beta), boundary_points=boundary_points
        )
        reply = await self._unary(lambda r: r.safety.GetTrackingErrorBound, request, timeout)
        return convert.tracking_error_bound(reply)

    async def evaluate(
        self,
        model: str,
        states: npt.ArrayLike,
        params: npt.ArrayLike,
        *,
        out_of_domain: convert.OutOfDomain = "default",
        version: int = 0,
        timeout: float | None = None,
    ) -> results.Evaluation:
        """V, dV/dr, u* and TEB membership for a batch (see :meth:`fastrack.Client.evaluate`)."""
        dims = await self.dims(model, version)
        s, p, n = convert.batch(dims, states, params)
        request = safety_pb2.EvaluateValueRequest(
            model=convert.model_ref(model, version), states=s, params=p, out_of_domain=convert.policy(out_of_domain)
        )
        return convert.evaluation(await self._unary(lambda r: r.safety.EvaluateValue, request, timeout), dims, n)

    async def tracking_control(
        self,
        model: str,
        states: npt.ArrayLike,
        params: npt.ArrayLike,
        *,
        out_of_domain: convert.OutOfDomain = "default",
        version: int = 0,
        timeout: float | None = None,
    ) -> results.TrackingControl:
        """The optimal tracking control u* for a batch (see :meth:`fastrack.Client.evaluate`)."""
        dims = await self.dims(model, version)
        s, p, n = convert.batch(dims, states, params)
        request = safety_pb2.TrackingControlRequest(
            model=convert.model_ref(model, version), states=s, params=p, out_of_domain=convert.policy(out_of_domain)
        )
        reply = await self._unary(lambda r: r.safety.TrackingControl, request, timeout)
        return convert.tracking_control(reply, dims, n)

    def track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> _TrackOpener:
        """A ``Track`` stream for one robot: ``async with client.track("dubins4d") as robot``."""
        return _TrackOpener(self, model, version, idle_timeout)

    async def open_track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> AsyncTrackStream:
        """Opens a ``Track`` stream on the next replica that takes it (close it with ``await
        stream.close()``); :meth:`track` does both."""
        dims = await self.dims(model, version)
        open_request = convert.open_stream(model, version, idle_timeout)
        return await AsyncTrackStream(self._track_stubs, self._streams, self.settings.metadata, dims, open_request).open()

    def _track_stubs(self) -> list[tuple[str, AsyncTrackStub]]:
        return [(replica.endpoint, replica.safety.Track) for replica in self._replicas.rotation()]

    async def load_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin, on the next replica only: loads a model (version 0: every version); the loaded versions."""
        request = models_pb2.LoadModelRequest(name=name, version=version)
        reply = await self._unary(lambda r: r.admin.LoadModel, request, timeout, idempotent=False)
        return list(reply.loaded_versions)

    async def unload_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin: stops serving a model (version 0: every version); the unloaded versions."""
        request = models_pb2.UnloadModelRequest(name=name, version=version)
        reply = await self._unary(lambda r: r.admin.UnloadModel, request, timeout, idempotent=False)
        return list(reply.unloaded_versions)

    async def reload_model(self, name: str = "", *, timeout: float | None = None) -> list[models_pb2.ReloadOutcome]:
        """Admin: re-reads a model (empty name: the whole repository) from disk."""
        request = models_pb2.ReloadModelRequest(name=name)
        reply = await self._unary(lambda r: r.admin.ReloadModel, request, timeout, idempotent=False)
        return list(reply.outcomes)

    async def close(self) -> None:
        """Closes the connections (open streams end)."""
        for replica in self._replicas.replicas:
            await replica.channel.close()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(
        self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()


class _TrackOpener:
    """``async with client.track(...) as robot``: opens the stream on entry, closes it on exit."""

    def __init__(self, client: AsyncClient, model: str, version: int, idle_timeout: float) -> None:
        self._client, self._model, self._version, self._idle_timeout = client, model, version, idle_timeout
        self._stream: AsyncTrackStream | None = None

    async def __aenter__(self) -> AsyncTrackStream:
        self._stream = await self._client.open_track(
            self._model, version=self._version, idle_timeout=self._idle_timeout
        )
        return self._stream

    async def __aexit__(
        self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._stream is not None:
            await self._stream.close(cancel=error is not None)
