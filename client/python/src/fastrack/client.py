"""The synchronous client, :class:`Client`."""

from __future__ import annotations

import time
from types import TracebackType
from typing import TypeVar

import grpc
import numpy.typing as npt
from grpc_health.v1 import health_pb2

from . import calls, convert, results
from .calls import Call, Connection
from .channel import Endpoint
from .replicas import not_ready, replicas_wanted
from .track import SyncTrackStub, TrackStream
from .v1 import models_pb2

Result = TypeVar("Result")


class Client(Connection[grpc.Channel]):
    """A connection to a fastrack server, or to its replicas (``fastrack.v1`` over gRPC); thread-safe, cheap
    to share.

    ``address`` is ``host:port`` (or ``http://host:port``; ``https://host:port`` with ``tls``), several of
    them separated by commas, or a host name resolving to several addresses (e.g. a Kubernetes headless
    Service): each address is a replica, and calls go round-robin over them (see :mod:`fastrack.replicas`).
    ``timeout`` is the default deadline of unary calls in seconds (each method takes its own ``timeout``
    too), and how long a replica may take to open a ``Track`` stream or answer a tick; ``token`` is sent as
    ``authorization: Bearer <token>``; ``retry`` says how idempotent unary calls are retried on
    ``UNAVAILABLE`` (never ``Track`` nor the admin calls); ``max_reconnect_backoff`` is the
    longest wait between reconnection attempts to a lost replica, seconds. Use as a context manager, or call
    :meth:`close`. Models are named by ``model`` (e.g. ``"dubins4d"``) and ``version`` (0: the server's
    default version).
    """

    def _open(self, endpoint: Endpoint, credentials: grpc.ChannelCredentials | None) -> grpc.Channel:
        return self.settings.sync_channel(endpoint, credentials)

    def _send(self, call: Call[calls.Reply, Result], timeout: float | None) -> Result:
        """One unary call with the token and deadline, over the replicas as :class:`fastrack.calls.Attempts`
        says."""
        attempts = self._attempts(call.idempotent)
        for wait, replicas in attempts.passes():
            time.sleep(wait)
            for replica in replicas:
                try:
                    deadline = self._deadline(timeout)
                    reply = call.rpc(replica)(call.request, timeout=deadline, metadata=self.settings.metadata)
                except grpc.RpcError as e:
                    attempts.failed(replica, e)
                else:
                    return call.finish(reply)
        raise attempts.exhausted()

    def health(self, service: str = "", *, timeout: float | None = None) -> str:
        """The health (``grpc.health.v1``) of the next replica: ``"SERVING"``, ``"NOT_SERVING"``, ..."""
        return self._send(calls.health(service), timeout)

    def serving_replicas(self, *, timeout: float | None = None) -> list[str]:
        """The endpoints of the replicas whose health is ``SERVING`` now (each asked once)."""
        deadline = self._deadline(timeout)
        serving = []
        for replica in self._replicas.replicas:
            try:
                request = health_pb2.HealthCheckRequest()
                reply = replica.health(request, timeout=deadline, metadata=self.settings.metadata)
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
        return self._send(calls.list_models(), timeout)

    def get_model(self, model: str, version: int = 0, *, timeout: float | None = None) -> models_pb2.ModelInfo:
        """One model version's description: state, parameters, controls (with units and bounds), TEB table."""
        return self._remember(model, version, self._send(calls.get_model(model, version), timeout))

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
        return self._send(calls.query_planner_control(model, version, d_obs, planner_clearance), timeout)

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
        return self._send(calls.tracking_error_bound(model, version, beta, boundary_points), timeout)

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
        batch = calls.Batch(self.dims(model, version), model, version, states, params, out_of_domain)
        return self._send(calls.evaluate(batch), timeout)

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
        batch = calls.Batch(self.dims(model, version), model, version, states, params, out_of_domain)
        return self._send(calls.tracking_control(batch), timeout)

    def track(self, model: str, *, version: int = 0, idle_timeout: float = 0.0) -> TrackStream:
        """Opens a ``Track`` stream for one robot on the next replica that takes it (no deadline; the server
        closes it after ``idle_timeout`` seconds without a tick, 0: the server's default). Use as ``with
        client.track("dubins4d") as robot``. The stream moves to another replica when its own goes away
        (see :mod:`fastrack.track`)."""
        self.dims(model, version)  # fetches the sizes the stream checks its ticks against
        return TrackStream(self._opening(self._track_stubs, model, version, idle_timeout))

    def _track_stubs(self) -> list[tuple[str, SyncTrackStub]]:
        return [(replica.endpoint, replica.safety.Track) for replica in self._replicas.rotation()]

    def load_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin, on the next replica only: loads a model from its repository (version 0: every version); the
        loaded versions."""
        return self._send(calls.load_model(name, version), timeout)

    def unload_model(self, name: str, version: int = 0, *, timeout: float | None = None) -> list[int]:
        """Admin: stops serving a model (version 0: every version); the unloaded versions."""
        return self._send(calls.unload_model(name, version), timeout)

    def reload_model(self, name: str = "", *, timeout: float | None = None) -> list[models_pb2.ReloadOutcome]:
        """Admin: re-reads a model (empty name: the whole repository) from disk; one outcome per version."""
        return self._send(calls.reload_model(name), timeout)

    def close(self) -> None:
        """Closes the connections (open streams end)."""
        for replica in self._replicas.replicas:
            replica.channel.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

