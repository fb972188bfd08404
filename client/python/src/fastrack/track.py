"""``Track`` streams: one bidirectional stream per robot, one tick per control step, replies in order, and
failover to another replica when the stream's own goes away.

The stream object numbers the ticks (``seq`` 0, 1, 2, ...) and checks that every reply answers the oldest
tick still waiting. ``tick`` sends and waits; ``send`` and ``recv`` pipeline. A tick the server rejects
(``TrackReply.error``) raises its exception and the stream stays open; a stream the server ends for a reason
of its own (idle timeout) raises on the next ``tick`` or ``recv``.

The stream remembers the ticks it sent that are not answered yet. When its replica goes away (the stream
ends with ``UNAVAILABLE``, as a draining server's do with "the server is shutting down; reconnect to
continue"; its connection breaks, as a killed server's does; or it closes with ticks unanswered), it reopens
on the client's next replica (each other replica tried once, the lost one last), sends its ``open`` message
and the unanswered ticks again, and carries on: the robot sees every tick answered exactly once, in order.
A replica lost while no tick was waiting is noticed at the next ``send``, which reopens first.
A replica that does not answer an open, or leaves a tick unanswered, within the client's ``timeout`` (one
that takes the connection and says nothing, as a frozen server does) is passed over as gone. ``endpoint``
is the replica serving the stream now, ``reopened`` how often it moved and ``resent`` how many ticks were
sent again. When no replica takes the stream, :class:`~fastrack.Unavailable` says what ended it; the ticks
still waiting are dropped, and the next ``send`` tries the replicas again.

Nothing else needs carrying over: a reply depends on its tick alone, and the bound in force (``beta_old``)
is the robot's own online loop's.

For the same reason a stream moves when nothing is lost, to keep a client's streams spread over the replicas
that serve: at most once a second, a stream on a replica holding at least two more of the client's streams
than another opens a second stream there in the background (a thread, or a task), and moves to it at its
next ``send`` with every earlier tick answered; so a replica that returns after a failure gets its share
back, and the robot never waits for the move. ``rebalanced`` counts these moves.

A stream is used by one thread (or task) at a time: ``send`` and ``recv`` may both move it.
"""

from __future__ import annotations

import asyncio
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Generic, TypeAlias, TypeVar

import grpc
import grpc.aio
import numpy.typing as npt

from . import convert
from .errors import FastrackError, Internal, Unavailable, from_rpc_error, from_status
from .replicas import BALANCE_EVERY_S, PlannedMove, StreamCounts, all_unavailable, replica_lost
from .results import TrackReply
from .v1 import safety_pb2

TrackCall = grpc.aio.StreamStreamCall[safety_pb2.TrackRequest, safety_pb2.TrackResponse]
SyncTrackStub: TypeAlias = "grpc.StreamStreamMultiCallable[safety_pb2.TrackRequest, safety_pb2.TrackResponse]"
AsyncTrackStub: TypeAlias = "grpc.aio.StreamStreamMultiCallable[safety_pb2.TrackRequest, safety_pb2.TrackResponse]"
Stub = TypeVar("Stub")


class _BalancePace:
    """When a stream looks at the balance of the replicas: at most once every ``BALANCE_EVERY_S``."""

    def __init__(self) -> None:
        self._checked = time.monotonic()

    def target(self, counts: StreamCounts, stubs: dict[str, Stub], endpoint: str) -> tuple[PlannedMove, Stub] | None:
        """The move (planned in ``counts``) and the stub of the replica a stream on ``endpoint`` should move to,
        if it is time to look and one has at least two fewer of the client's streams. ``stubs`` are the
        client's, by endpoint: looking must not turn the client's round-robin, which places new streams."""
        if time.monotonic() - self._checked < BALANCE_EVERY_S:
            return None
        self._checked = time.monotonic()
        move = counts.plan_move(endpoint)
        return None if move is None else (move, stubs[move.to])


SyncReply: TypeAlias = "safety_pb2.TrackResponse | grpc.RpcError | None"
"""What a sync stream's reader hands on: a reply, the error the call ended with, or None when the server
closed it."""


class _SyncOpened:
    """A sync stream open on one replica: its endpoint, the queue feeding its ticks, the call, and the queue
    its replies arrive in (read by a thread of its own, so that a wait for one can have a deadline)."""

    def __init__(
        self,
        endpoint: str,
        requests: queue.SimpleQueue[safety_pb2.TrackRequest | None],
        call: grpc._CallIterator[safety_pb2.TrackResponse],
    ) -> None:
        self.endpoint, self.requests, self.call = endpoint, requests, call
        self.replies: queue.SimpleQueue[SyncReply] = queue.SimpleQueue()
        threading.Thread(target=self._read, name="fastrack-track-replies", daemon=True).start()

    def _read(self) -> None:
        try:
            for response in self.call:
                self.replies.put(response)
        except grpc.RpcError as e:
            self.replies.put(e)
            return
        self.replies.put(None)


def _discard(opened: _SyncOpened | None) -> None:
    """Ends a stream opened for a move that is not made."""
    if opened is not None:
        opened.requests.put(None)
        opened.call.cancel()


class _Sequence:
    """Numbers ticks, remembers those not answered yet, and matches replies to them in order."""

    def __init__(self) -> None:
        self.next_seq = 0
        self.pending: deque[tuple[int, safety_pb2.TrackRequest]] = deque()

    def add(self, request: safety_pb2.TrackRequest) -> int:
        seq = self.next_seq
        self.pending.append((seq, request))
        self.next_seq += 1
        return seq

    def withdraw(self) -> None:
        """Forgets the newest tick: it could not be sent."""
        self.pending.pop()
        self.next_seq -= 1

    def requests(self) -> list[safety_pb2.TrackRequest]:
        return [request for _, request in self.pending]

    def check_waiting(self) -> None:
        if not self.pending:
            raise FastrackError("recv() without a tick awaiting its reply: send() first")

    def answer(self, response: safety_pb2.TrackResponse) -> TrackReply:
        expected, _ = self.pending.popleft()
        if response.reply.seq != expected:
            raise Internal(f"the reply to tick {response.reply.seq} arrived while tick {expected} was due")
        return convert.track_reply(response.reply)


def _answered_within(call: grpc._CallIterator[safety_pb2.TrackResponse], seconds: float) -> bool:
    """Waits at most ``seconds`` for the server's answer to an open (its headers, or the end of the call);
    False if none came. Raises what waiting raised."""
    failure: list[BaseException] = []

    def wait() -> None:
        try:
            call.initial_metadata()
        except BaseException as e:  # handed to the caller's thread
            failure.append(e)

    waiting = threading.Thread(target=wait, name="fastrack-track-open", daemon=True)
    waiting.start()
    waiting.join(seconds)
    if failure:
        raise failure[0]
    return not waiting.is_alive()


def _order(replicas: list[tuple[str, Stub]], lost: str | None) -> list[tuple[str, Stub]]:
    """The replicas to try, the one just lost last (it may be back, but the others are likelier to answer)."""
    return [r for r in replicas if r[0] != lost] + [r for r in replicas if r[0] == lost]


def _movable(error: FastrackError) -> bool:
    """True when the stream may go on elsewhere: its replica is gone, or it closed without being asked to
    (a status OK before the robot closed it)."""
    return replica_lost(error) or error.code == grpc.StatusCode.OK


def _passed_over(error: FastrackError) -> bool:
    """True when a replica that refused to open a stream may be passed over for the next: it is gone, or it
    holds all the streams it allows (``RESOURCE_EXHAUSTED``)."""
    return _movable(error) or error.code == grpc.StatusCode.RESOURCE_EXHAUSTED


def _no_replica(why: str, detail: str) -> Unavailable:
    return Unavailable(f"{why}; no replica took the stream again ({detail})")


def _refused(why: str, failures: list[tuple[str, FastrackError]], raise_as_is: bool) -> FastrackError:
    """The error of an open that every replica refused as gone or full (``failures``): as a unary call's at
    the first open (``raise_as_is``; a full replica's own ``RESOURCE_EXHAUSTED`` when all were full), else
    saying ``why`` the stream had to move."""
    if raise_as_is:
        if failures and all(e.code == grpc.StatusCode.RESOURCE_EXHAUSTED for _, e in failures):
            return failures[-1][1]  # every replica holds all the streams it allows: say so, as it did
        return all_unavailable(failures) if failures else Unavailable("no replica to open a Track stream on")
    detail = "; ".join(f"{where}: {e.code.name}: {e.message}" for where, e in failures)
    return _no_replica(why, detail or "no replica to open it on")


def _why(error: FastrackError) -> str:
    return f"the stream's replica went away ({error.code.name}: {error.message})"


@dataclass(frozen=True)
class Opening(Generic[Stub]):
    """What a client gives a stream it opens."""

    replicas: Callable[[], list[tuple[str, Stub]]]
    """The replicas to open on, in the order to try them: ``(endpoint, Track stub)`` pairs."""
    counts: StreamCounts
    """The client's open streams per replica."""
    metadata: tuple[tuple[str, str], ...]
    """Call metadata (the bearer token)."""
    dims: convert.Dims
    """The model's vector sizes."""
    open_request: safety_pb2.TrackRequest
    """The stream's first message."""
    deadline: float
    """Seconds a replica may take to answer the open, or a tick, before it is passed over as gone (a replica
    that takes the connection and never answers is as good as gone)."""


class _Stream(Generic[Stub]):
    """What both kinds of stream keep: how they open, the ticks not answered yet, and the counts of moves."""

    def __init__(self, opening: Opening[Stub]) -> None:
        self._replicas = opening.replicas
        self._counts = opening.counts
        self._metadata = opening.metadata
        self._dims = opening.dims
        self._open_request = opening.open_request
        self._deadline = opening.deadline
        self._sequence = _Sequence()
        self._closed = False
        self._lost = False
        self._replica_count = 1
        self._pace = _BalancePace()
        self._planned: PlannedMove | None = None
        """The move to a lighter replica being opened, counted in the client's balance until made or given up."""
        self._stubs: dict[str, Stub] = {}
        self.reopened = 0
        """How often the stream moved to another replica."""
        self.resent = 0
        """Ticks sent again after a move, because their first replica never answered them."""
        self.rebalanced = 0
        """How often the stream moved, with nothing lost, to even the load over the replicas."""
        self.endpoint = ""
        """The replica serving the stream now."""

    def _tick_request(
        self,
        tracker_state: npt.ArrayLike,
        planner_state: npt.ArrayLike,
        d_obs: convert.Real | None,
        planner_clearance: convert.Real | None,
    ) -> safety_pb2.TrackRequest:
        """The next tick, its vectors checked against the model."""
        seq = self._sequence.next_seq
        return convert.tick(self._dims, seq, tracker_state, planner_state, d_obs, planner_clearance)

    def _candidates(self, lost: str | None) -> list[tuple[str, Stub]]:
        """The replicas to open on now, ``lost`` last; remembers how many there are and their stubs."""
        candidates = self._replicas()
        self._replica_count, self._stubs = len(candidates), dict(candidates)
        return _order(candidates, lost)

    def _opened(self, lost: str | None, resent: int) -> None:
        """Counts a move after ``lost`` went away, with ``resent`` ticks sent again."""
        if lost is not None:
            self.reopened += 1
            self.resent += resent

    def _balance_target(self) -> tuple[str, Stub] | None:
        """The lighter replica (endpoint and stub) to open a second stream on, when it is time to look and one
        is; the move is planned in the client's balance until :meth:`_move_settled`."""
        target = self._pace.target(self._counts, self._stubs, self.endpoint)
        if target is None:
            return None
        self._planned, stub = target
        return self._planned.to, stub

    def _move_settled(self) -> None:
        """The planned move was made or given up: it leaves the client's balance."""
        if self._planned is not None:
            self._planned.release()
            self._planned = None

    def _silent(self, endpoint: str) -> Unavailable:
        """The error of a replica that did not answer an open in time."""
        return Unavailable(f"{endpoint} did not open the stream within {self._deadline} s")

    def _unanswered(self) -> str:
        """Why a stream moves whose replica left a tick unanswered past the deadline."""
        return f"no reply within {self._deadline} s"

    def _give_up(self) -> None:
        """No replica took the stream: the ticks waiting are dropped, the next send tries again."""
        self._lost = True
        self._sequence.pending.clear()


class TrackStream(_Stream[SyncTrackStub]):
    """A sync ``Track`` stream; use as a context manager (``with client.track("dubins4d") as robot``)."""

    def __init__(self, opening: Opening[SyncTrackStub]) -> None:
        super().__init__(opening)
        self._move: list[_SyncOpened | None] | None = None
        """A stream being opened in the background on a lighter replica: empty until the thread is done."""
        self._requests: queue.SimpleQueue[safety_pb2.TrackRequest | None] = queue.SimpleQueue()
        self._replies: queue.SimpleQueue[SyncReply] = queue.SimpleQueue()
        self._call: grpc._CallIterator[safety_pb2.TrackResponse] | None = None
        self._open_somewhere(None, raise_as_is=True)

    def _open_somewhere(self, lost: str | None, raise_as_is: bool = False, why: str = "") -> None:
        """Opens on the first replica that takes the stream (each tried once, ``lost`` last) and sends the
        unanswered ticks there. Raises the error of a replica that refuses the stream (``raise_as_is``) or
        :class:`Unavailable` saying ``why`` the stream had to move."""
        failures: list[tuple[str, FastrackError]] = []
        for endpoint, stub in self._candidates(lost):
            opened = self._open_on(endpoint, stub)
            if isinstance(opened, FastrackError):
                if not _passed_over(opened):
                    raise opened if raise_as_is else _no_replica(why, f"{endpoint}: {opened.code.name}: {opened.message}")
                failures.append((endpoint, opened))
                continue
            resend = self._sequence.requests()
            for request in resend:
                opened.requests.put(request)
            self._switch(opened)
            self._opened(lost, len(resend))
            return
        raise _refused(why, failures, raise_as_is)

    def _open_on(self, endpoint: str, stub: SyncTrackStub) -> _SyncOpened | FastrackError:
        """Opens the stream on one replica: the open call, or the error it ended with at once."""
        requests: queue.SimpleQueue[safety_pb2.TrackRequest | None] = queue.SimpleQueue()
        requests.put(self._open_request)
        call = stub(iter(requests.get, None), metadata=self._metadata)
        # The server answers the open with its headers, or ends the call; one that does neither is gone.
        if not _answered_within(call, self._deadline):
            requests.put(None)
            call.cancel()
            return self._silent(endpoint)
        if not call.is_active():
            requests.put(None)  # ends the thread feeding the call
            return from_status(call.code(), call.details() or "the Track stream ended at once")
        return _SyncOpened(endpoint, requests, call)

    def _switch(self, opened: _SyncOpened) -> None:
        """Serves the stream from ``opened`` from now on, counting the move in the client's balance."""
        self._counts.moved(self.endpoint or None, opened.endpoint)
        self._requests, self._replies, self._call = opened.requests, opened.replies, opened.call
        self.endpoint, self._lost = opened.endpoint, False

    def _balance(self) -> None:
        """With every tick answered: moves to the stream opened in the background, if it is open; else, at most
        once a second, starts opening one on a replica with at least two fewer of the client's streams."""
        if self._sequence.pending:
            return
        if self._move is not None:
            if self._move:
                opened, self._move = self._move[0], None
                if opened is not None:
                    self._abandon()
                    self._switch(opened)
                    self.rebalanced += 1
                self._move_settled()
            return
        target = self._balance_target()
        if target is None:
            return
        lighter, stub = target
        move: list[_SyncOpened | None] = []

        def open_there() -> None:
            try:
                opened = self._open_on(lighter, stub)
            except (grpc.RpcError, ValueError) as e:  # a channel that broke or closed meanwhile
                opened = Unavailable(f"{lighter}: {e}")
            if isinstance(opened, FastrackError):
                self._counts.refused(lighter)
                move.append(None)
            elif self._closed:
                _discard(opened)  # the robot closed its stream meanwhile
            else:
                move.append(opened)

        self._move = move
        threading.Thread(target=open_there, name="fastrack-track-balance", daemon=True).start()

    def _reopen(self, why: str) -> None:
        """Moves the stream to another replica after ``why`` ended it; on failure drops the waiting ticks."""
        self._abandon()
        try:
            self._open_somewhere(self.endpoint, why=why)
        except FastrackError:
            self._give_up()
            raise

    def _abandon(self) -> None:
        self._requests.put(None)
        if self._call is not None:
            self._call.cancel()

    def _ended(self) -> FastrackError | None:
        """The stream's status if it has ended (without blocking), else None."""
        if self._call is None or self._call.is_active():
            return None
        return from_status(self._call.code(), self._call.details() or "the Track stream ended")

    def send(
        self,
        tracker_state: npt.ArrayLike,
        planner_state: npt.ArrayLike,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
    ) -> int:
        """Sends one tick without waiting for its reply; returns its ``seq``.

        ``tracker_state`` is the tracker's state s [n_state] (dubins4d: x m, y m, heading rad, speed m/s),
        ``planner_state`` the planner's p [planner_dim] (dubins4d: x, y in metres), ``d_obs`` the distance to
        the nearest sensed obstacle in metres (None: none sensed); ``planner_clearance`` asks for the planner
        rule instead (:meth:`fastrack.Client.query_planner_control`).
        """
        if self._closed:
            raise Unavailable("the Track stream is closed")
        request = self._tick_request(tracker_state, planner_state, d_obs, planner_clearance)
        ended = self._ended()
        if self._lost:
            self._reopen("the stream's replica went away earlier")
        elif ended is not None and _movable(ended):
            self._reopen(_why(ended))
        else:
            self._balance()
        seq = self._sequence.add(request)
        self._requests.put(request)
        return seq

    def recv(self) -> TrackReply:
        """The reply to the oldest tick still waiting (raises the tick's error, or the stream's)."""
        self._sequence.check_waiting()
        moves = 0
        while True:
            try:
                reply = self._replies.get(timeout=self._deadline)
            except queue.Empty:
                why = self._unanswered()
            else:
                if reply is None:
                    why = "the server closed the stream with ticks unanswered"
                elif isinstance(reply, grpc.RpcError):
                    error = from_rpc_error(reply)
                    if not _movable(error):
                        self._sequence.pending.popleft()
                        raise error from None
                    why = _why(error)
                else:
                    return self._sequence.answer(reply)
            moves += 1
            if moves > self._replica_count:  # every replica took the stream and lost it without answering
                self._abandon()
                self._give_up()
                raise _no_replica(why, "every replica took it and lost it again without answering")
            self._reopen(why)

    def tick(
        self,
        tracker_state: npt.ArrayLike,
        planner_state: npt.ArrayLike,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
    ) -> TrackReply:
        """Sends one tick and waits for its reply (see :meth:`send` for the arguments)."""
        self.send(tracker_state, planner_state, d_obs, planner_clearance=planner_clearance)
        return self.recv()

    def close(self, cancel: bool = False) -> None:
        """Ends the stream: no more ticks; replies not yet read are dropped. Without ``cancel`` the server
        answers the ticks in flight and ends the call normally; with it the call is cancelled at once."""
        if self._closed:
            return
        self._closed = True
        self._counts.moved(self.endpoint or None, None)
        if self._move:
            _discard(self._move[0])
        self._move_settled()
        self._requests.put(None)
        if self._call is None:
            return
        if cancel or self._lost:
            self._call.cancel()
            return
        # The server answers the ticks in flight and ends the call; an error it ends with instead was (or would
        # have been) raised by recv(). A replica silent past the deadline is left.
        try:
            while isinstance(self._replies.get(timeout=self._deadline), safety_pb2.TrackResponse):
                pass
        except queue.Empty:
            self._call.cancel()

    def __enter__(self) -> TrackStream:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close(cancel=error is not None)


class AsyncTrackStream(_Stream[AsyncTrackStub]):
    """An asyncio ``Track`` stream; use with ``async with client.track("dubins4d") as robot``."""

    def __init__(self, opening: Opening[AsyncTrackStub]) -> None:
        super().__init__(opening)
        self._call: TrackCall | None = None
        self._move: asyncio.Task[tuple[str, TrackCall] | None] | None = None
        """A stream being opened on a lighter replica, for the next move."""

    @staticmethod
    async def _status(call: TrackCall, fallback: FastrackError | None = None) -> FastrackError:
        """The ended call's status as an exception (``fallback`` if it has not ended)."""
        if not call.done() and fallback is not None:
            return fallback
        return from_status(await call.code(), await call.details() or "the Track stream ended")

    async def _open_somewhere(self, lost: str | None, raise_as_is: bool = False, why: str = "") -> None:
        """As :meth:`TrackStream._open_somewhere`."""
        failures: list[tuple[str, FastrackError]] = []
        for endpoint, stub in self._candidates(lost):
            resend = self._sequence.requests()
            call, error = await self._open_on(endpoint, stub, resend)
            if error is None:
                self._switch(endpoint, call)
                self._opened(lost, len(resend))
                return
            if not _passed_over(error):
                raise error if raise_as_is else _no_replica(why, f"{endpoint}: {error.code.name}: {error.message}")
            failures.append((endpoint, error))
        raise _refused(why, failures, raise_as_is)

    async def _open_on(
        self, endpoint: str, stub: AsyncTrackStub, resend: list[safety_pb2.TrackRequest]
    ) -> tuple[TrackCall, FastrackError | None]:
        """Opens the stream on one replica and sends ``resend`` there: the call, and the error it ended with
        at once (None: open)."""
        call = stub(metadata=self._metadata)

        async def answered() -> None:
            await call.write(self._open_request)
            await call.initial_metadata()

        try:
            # The server answers the open with its headers, or ends the call; one that does neither (or never
            # takes the connection) is gone.
            await asyncio.wait_for(answered(), self._deadline)
            if not call.done():
                for request in resend:
                    await call.write(request)
        except grpc.RpcError as e:
            error: FastrackError | None = from_rpc_error(e)
        except asyncio.InvalidStateError:
            error = None
        except asyncio.TimeoutError:  # the builtin TimeoutError from Python 3.11 on
            call.cancel()
            return call, self._silent(endpoint)
        else:
            error = None
        if call.done():
            error = await self._status(call, error)
        if error is not None:
            call.cancel()
        return call, error

    def _switch(self, endpoint: str, call: TrackCall) -> None:
        """Serves the stream from ``call`` on ``endpoint`` from now on, counting the move in the balance."""
        self._counts.moved(self.endpoint or None, endpoint)
        self._call, self.endpoint, self._lost = call, endpoint, False

    async def _balance(self) -> None:
        """As :meth:`TrackStream._balance`, with a task instead of a thread."""
        if self._sequence.pending:
            return
        if self._move is not None:
            if self._move.done():
                move, self._move = self._move, None
                try:
                    opened = move.result()
                except (asyncio.CancelledError, grpc.RpcError, ValueError):
                    opened = None  # no move: the stream stays where it is
                if opened is not None:
                    if self._call is not None:
                        self._call.cancel()
                    self._switch(*opened)
                    self.rebalanced += 1
                self._move_settled()
            return
        target = self._balance_target()
        if target is None:
            return

        async def open_there(endpoint: str, stub: AsyncTrackStub) -> tuple[str, TrackCall] | None:
            call, error = await self._open_on(endpoint, stub, [])
            if error is not None:
                self._counts.refused(endpoint)
                return None
            return endpoint, call

        self._move = asyncio.create_task(open_there(*target))

    async def _reopen(self, why: str) -> None:
        if self._call is not None:
            self._call.cancel()
        try:
            await self._open_somewhere(self.endpoint, why=why)
        except FastrackError:
            self._give_up()
            raise

    async def open(self) -> AsyncTrackStream:
        """Opens the stream on the client's next replica that takes it (done by ``async with``)."""
        if self._call is None:
            await self._open_somewhere(None, raise_as_is=True)
        return self

    def _live_call(self) -> TrackCall:
        if self._call is None:
            raise Unavailable("the Track stream is not open: use `async with client.track(...)`")
        return self._call

    async def send(
        self,
        tracker_state: npt.ArrayLike,
        planner_state: npt.ArrayLike,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
    ) -> int:
        """Sends one tick without waiting for its reply; returns its ``seq`` (arguments as :meth:`TrackStream.send`)."""
        request = self._tick_request(tracker_state, planner_state, d_obs, planner_clearance)
        call = self._live_call()
        if self._lost:
            await self._reopen("the stream's replica went away earlier")
        elif call.done():
            ended = await self._status(call)
            if _movable(ended):
                await self._reopen(_why(ended))
        else:
            await self._balance()
        seq = self._sequence.add(request)
        try:
            await self._live_call().write(request)
        except (grpc.RpcError, asyncio.InvalidStateError) as e:
            closed = Unavailable("the Track stream is closed")
            fallback = from_rpc_error(e) if isinstance(e, grpc.RpcError) else closed
            error = await self._status(self._live_call(), fallback)
            if not _movable(error):
                self._sequence.withdraw()
                raise error from None
            await self._reopen(_why(error))  # sends this tick again with the others unanswered
        return seq

    async def recv(self) -> TrackReply:
        """The reply to the oldest tick still waiting (raises the tick's error, or the stream's)."""
        self._sequence.check_waiting()
        moves = 0
        while True:
            call = self._live_call()
            try:
                response = await asyncio.wait_for(call.read(), self._deadline)
            except asyncio.TimeoutError:
                why = self._unanswered()
            except grpc.RpcError as e:
                error = from_rpc_error(e)
                if not _movable(error):
                    self._sequence.pending.popleft()
                    raise error from None
                why = _why(error)
            except asyncio.InvalidStateError:
                error = await self._status(call, Unavailable("the Track stream is closed"))
                if not _movable(error):
                    self._sequence.pending.popleft()
                    raise error from None
                why = _why(error)
            else:
                if isinstance(response, safety_pb2.TrackResponse):
                    return self._sequence.answer(response)
                why = "the server closed the stream with ticks unanswered"
            moves += 1
            if moves > self._replica_count:  # every replica took the stream and lost it without answering
                call.cancel()
                self._give_up()
                raise _no_replica(why, "every replica took it and lost it again without answering")
            await self._reopen(why)

    async def tick(
        self,
        tracker_state: npt.ArrayLike,
        planner_state: npt.ArrayLike,
        d_obs: convert.Real | None = None,
        *,
        planner_clearance: convert.Real | None = None,
    ) -> TrackReply:
        """Sends one tick and waits for its reply."""
        await self.send(tracker_state, planner_state, d_obs, planner_clearance=planner_clearance)
        return await self.recv()

    async def close(self, cancel: bool = False) -> None:
        """Ends the stream: no more ticks; replies not yet read are dropped. Without ``cancel`` the server
        answers the ticks in flight and ends the call normally; with it the call is cancelled at once."""
        call = self._call
        if call is None or self._closed:
            return
        self._closed = True
        self._counts.moved(self.endpoint or None, None)
        if self._move is not None:
            move, self._move = self._move, None
            move.cancel()
            if move.done() and not move.cancelled() and (opened := move.result()) is not None:
                opened[1].cancel()
        self._move_settled()
        if cancel or self._lost or call.done():
            call.cancel()
            return
        try:
            await call.done_writing()
            while await call.read() is not grpc.aio.EOF:
                pass
        except (grpc.RpcError, asyncio.InvalidStateError):
            pass  # the stream had already failed; its error was (or would have been) raised by recv()

    async def __aenter__(self) -> AsyncTrackStream:
        return await self.open()

    async def __aexit__(
        self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close(cancel=error is not None)
