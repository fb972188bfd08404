"""The asyncio client, :class:`AsyncClient` (on ``grpc.aio``): the same calls as :class:`fastrack.Client`,
awaited. Create it inside the event loop that uses it."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable
from types import TracebackType
from typing import TypeVar, cast

import grpc
import grpc.aio
import numpy.typing as npt
from grpc_health.v1 import health_pb2

from . import calls, convert, results
from .calls import Call, Connection, Replica
from .channel import Endpoint
from .replicas import not_ready, replicas_wanted
from .track import AsyncTrackStream, AsyncTrackStub
from .v1 import models_pb2

Result = TypeVar("Result")


class AsyncClient(Connection[grpc.aio.Channel]):
    """An asyncio connection to a fastrack server or its replicas; arguments and methods as
    :class:`fastrack.Client`.

    Use as ``async with AsyncClient("127.0.0.1:50051") as client``; many coroutines may share it (e.g. one
    ``async with client.track(...)`` per robot).
    """

    def _open(self, endpoint: Endpoint, credentials: grpc.ChannelCredentials | None) -> grpc.aio.Channel:
        return self.settings.aio_channel(endpoint, credentials)

    async def _send(self, call: Call[calls.Reply, Result], timeout: float | None) -> Result:
        """One unary call with the token and deadline, over the replicas as :meth:`fastrack.Client._send`."""
        attempts = self._attempts(call.idempotent)
        for wait, replicas in attempts.passes():
            await asyncio.sleep(wait)
            for replica in replicas:
                try:
                    deadline = self._deadline(timeout)
                    pending = call.rpc(replica)(call.request, timeout=deadline, metadata=self.settings.metadata)
                    reply = await cast(Awaitable[calls.Reply], pending)
                except grpc.RpcError as e:
                    attempts.failed(replica, e)
                else:
                    return call.finish(reply)
        raise attempts.exhausted()

    async def health(self, service: str = "", *, timeout: float | None = None) -> str:
        """The health (``grpc.health.v1``) of the next replica: ``"SERVING"``, ``"NOT_SERVING"``, ..."""
        return await self._send(calls.health(service), timeout)

    async def serving_replicas(self, *, timeout: float | None = None) -> list[str]:
        """The endpoints of the replicas whose health is ``SERVING`` now (asked at once)."""
        deadline = self._deadline(timeout)

        async def serving(replica: Replica[grpc.aio.Channel]) -> bool:
            try:
                request = health_pb2.HealthCheckRequest()
                pending = replica.health(request, timeout=deadline, metadata=self.settings.metadata)
                reply = await cast(Awaitable[health_pb2.HealthCheckResponse], pending)
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
        return await self._send(calls.list_models(), timeout)

    async def get_model(self, model: str, version: int = 0, *, timeout: float | None = None) -> models_pb2.ModelInfo:
        """One model version's description: state, parameters, controls (with units and bounds), TEB table."""
        return self._remember(model, version, await self._send(calls.get_model(model, version), timeout))

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
        return await self._send(calls.query_planner_control(model, version, d_obs, planner_clearance), timeout)

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
        return await self._send(calls.tracking_error_bound(model, version, beta, boundary_points), timeout)

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
        batch = calls.Batch(await self.dims(model, version), model, version, states, params, out_of_domain)
        return await self._send(calls.evaluate(batch), timeout)

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
        batch = calls.Batch(await self.dims(model, version), model, version, states, params, out_of_domain)
        return await self._send(calls.tracking_control(batch), timeout)

    def track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> _TrackOpener:
        """A ``Track`` stream for one robot: ``async with client.track("dubins4d") as robot``."""
        return _TrackOpener(self, model, version, idle_timeout)

    async def open_track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> AsyncTrackStream:
        """Opens a ``Track`` stream on the next replica that takes it (close it with ``await
        stream.close()``); :meth:`track` does both."""
        await self.dims(model, version)  # fetches the sizes the stream checks its ticks against
        return await AsyncTrackStream(self._opening(self._track_stubs, model, version, idle_timeout)).open()

    def _track_stubs(self) -> list[tuple[str, AsyncTrackStub]]:
        return [(replica.endpoint, cast(AsyncTrackStub, replica.safety.Track)) for replica in self._replicas.rotation()]

    async def load_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin, on the next replica only: loads a model (version 0: every version); the loaded versions."""
        return await self._send(calls.load_model(name, version), timeout)

    async def unload_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin: stops serving a model (version 0: every version); the unloaded versions."""
        return await self._send(calls.unload_model(name, version), timeout)

    async def reload_model(self, name: str = "", *, timeout: float | None = None) -> list[models_pb2.ReloadOutcome]:
        """Admin: re-reads a model (empty name: the whole repository) from disk."""
        return await self._send(calls.reload_model(name), timeout)

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
