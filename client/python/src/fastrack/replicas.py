"""The replicas a client talks to, taken round-robin call by call.

A server address lists one endpoint or several separated by commas (``10.0.0.5:50051,10.0.0.6:50051``), or
names a host that resolves to several addresses (a Kubernetes headless Service): each address is a replica,
with its own gRPC channel. Names are resolved once, when the client is made: a client made before a scale-up
does not see the new replicas until it is made again.

Calls go round-robin over the replicas, the first to a random one (so that the clients of a fleet spread
their first calls too). Idempotent unary calls that find a replica gone (``UNAVAILABLE``) are made again on
the next ones, each replica at most once per pass (:class:`fastrack.Retry` says how many passes); admin
calls and health checks go to one replica, once; ``Track`` streams move to another replica when theirs goes
away (:mod:`fastrack.track`).
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Sequence
from typing import Generic, TypeVar

import grpc

from .errors import FastrackError, Unavailable

T = TypeVar("T")

CORE_INTERNAL_ERROR = "Internal error from Core"
"""The details grpc.aio gives a call whose write failed because its connection broke: the call is ended
with INTERNAL by the client library itself, not by a server."""


class Rotation(Generic[T]):
    """Round-robin over a fixed list of replicas, from a random start; thread-safe."""

    def __init__(self, replicas: Sequence[T]) -> None:
        if not replicas:
            raise ValueError("a client needs at least one replica")
        self.replicas: tuple[T, ...] = tuple(replicas)
        self._next = random.randrange(len(self.replicas))
        self._lock = threading.Lock()

    def next(self) -> T:
        """The next replica in turn."""
        return self.rotation()[0]

    def rotation(self) -> list[T]:
        """Every replica once, from the next in turn on: where a call goes, then where it goes again if that
        replica is gone."""
        with self._lock:
            start = self._next
            self._next = (start + 1) % len(self.replicas)
        count = len(self.replicas)
        return [self.replicas[(start + k) % count] for k in range(count)]


BALANCE_EVERY_S = 1.0
"""Least time between two looks of a ``Track`` stream at the balance of the replicas."""
REFUSED_PAUSE_S = 5.0
"""How long a replica that refused a stream is left out of balancing."""


class StreamCounts:
    """A client's open ``Track`` streams per replica, by which streams balance themselves over the replicas
    that serve (a replica that returns gets its share back); thread-safe.

    Moves planned to even the load and not made yet count where they go, so that streams looking at the
    balance at the same moment do not all leave for the same lighter replica."""

    def __init__(self, endpoints: Sequence[str]) -> None:
        self.endpoints = tuple(endpoints)
        self._open = dict.fromkeys(self.endpoints, 0)
        self._incoming = dict.fromkeys(self.endpoints, 0)
        self._outgoing = dict.fromkeys(self.endpoints, 0)
        self._refused: dict[str, float] = {}
        self._lock = threading.Lock()

    def counts(self) -> list[int]:
        """Open streams per replica, in the order of the client's endpoints."""
        with self._lock:
            return [self._open[e] for e in self.endpoints]

    def moved(self, old: str | None, new: str | None) -> None:
        """Counts a stream opened on ``new`` (None: closed) that was on ``old`` (None: new)."""
        with self._lock:
            if old is not None:
                self._open[old] -= 1
            if new is not None:
                self._open[new] += 1

    def refused(self, endpoint: str) -> None:
        """Remembers that ``endpoint`` refused a stream: balancing leaves it alone for a while."""
        with self._lock:
            self._refused[endpoint] = time.monotonic()

    def plan_move(self, endpoint: str) -> PlannedMove | None:
        """Plans a move that evens the load for a stream on ``endpoint``: to the replica with the fewest of the
        client's streams, if it has at least two fewer (one move then narrows the gap) and has not refused a
        stream lately. The move counts where it goes until :meth:`PlannedMove.release`."""
        now = time.monotonic()
        with self._lock:
            def load(e: str) -> int:
                return self._open.get(e, 0) + self._incoming.get(e, 0) - self._outgoing.get(e, 0)

            candidates = [
                e for e in self.endpoints
                if e != endpoint and now - self._refused.get(e, -REFUSED_PAUSE_S) >= REFUSED_PAUSE_S
            ]
            lightest = min(candidates, key=load, default=None)
            if lightest is None or load(lightest) + 2 > load(endpoint):
                return None
            self._incoming[lightest] += 1
            self._outgoing[endpoint] += 1
            return PlannedMove(self, endpoint, lightest)

    def _release(self, move: PlannedMove) -> None:
        with self._lock:
            self._incoming[move.to] -= 1
            self._outgoing[move.source] -= 1


class PlannedMove:
    """A move planned by :meth:`StreamCounts.plan_move`, counted in the balance until released (made or
    given up)."""

    def __init__(self, counts: StreamCounts, source: str, to: str) -> None:
        self._counts, self.source, self.to = counts, source, to
        self._released = False

    def release(self) -> None:
        """Takes the move out of the balance (once; later calls do nothing)."""
        if not self._released:
            self._released = True
            self._counts._release(self)


def replica_lost(error: FastrackError) -> bool:
    """True when a stream's ``error`` means its replica is gone (so the stream may go on elsewhere) rather
    than the stream refused: ``UNAVAILABLE`` (unreachable, a broken connection, or a draining server), or
    the INTERNAL status grpc.aio makes up when a write meets a broken connection."""
    return error.code == grpc.StatusCode.UNAVAILABLE or (
        error.code == grpc.StatusCode.INTERNAL and error.message.startswith(CORE_INTERNAL_ERROR)
    )


def all_unavailable(failures: list[tuple[str, FastrackError]]) -> FastrackError:
    """The error of a call that every replica it tried answered with ``UNAVAILABLE``: the error itself for
    one replica, else one naming each replica and its answer."""
    if len(failures) == 1:
        return failures[0][1]
    return Unavailable("no replica answered: " + "; ".join(f"{where}: {e.message}" for where, e in failures))


def replicas_wanted(quorum: int | None, count: int) -> int:
    """How many replicas a wait for ``quorum`` of ``count`` needs: all of them for None, else ``quorum``
    clamped to 1 .. ``count``."""
    return count if quorum is None else max(1, min(quorum, count))


def not_ready(address: str, serving: list[str], count: int, wanted: int, timeout: float) -> Unavailable:
    """The error of a wait that ended with fewer than ``wanted`` of ``count`` replicas ``SERVING``."""
    return Unavailable(
        f"{len(serving)} of {count} replicas of {address} SERVING after {timeout} s, {wanted} wanted"
        f" (serving: {', '.join(serving) or 'none'})"
    )
