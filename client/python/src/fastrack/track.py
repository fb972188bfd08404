"""``Track`` streams: one bidirectional stream per robot, one tick per control step, replies in order.

The stream object numbers the ticks (``seq`` 0, 1, 2, ...) and checks that every reply answers the oldest
tick still waiting. ``tick`` sends and waits; ``send`` and ``recv`` pipeline. A tick the server rejects
(``TrackReply.error``) raises its exception and the stream stays open; a stream the server ends (idle
timeout, shutdown) raises on the next ``tick`` or ``recv``.
"""

from __future__ import annotations

import asyncio
import queue
from collections import deque
from types import TracebackType

import grpc
import grpc.aio
import numpy.typing as npt

from . import convert
from .errors import FastrackError, Internal, Unavailable, from_rpc_error
from .results import TrackReply
from .v1 import safety_pb2

TrackCall = grpc.aio.StreamStreamCall[safety_pb2.TrackRequest, safety_pb2.TrackResponse]


class _Sequence:
    """Numbers ticks and matches replies to them, in order."""

    def __init__(self) -> None:
        self.next_seq = 0
        self.pending: deque[int] = deque()

    def sent(self) -> int:
        seq = self.next_seq
        self.pending.append(seq)
        self.next_seq += 1
        return seq

    def expect(self) -> int:
        if not self.pending:
            raise FastrackError("recv() without a tick awaiting its reply: send() first")
        return self.pending.popleft()

    @staticmethod
    def answer(expected: int, response: object) -> TrackReply:
        if not isinstance(response, safety_pb2.TrackResponse):
            raise Unavailable("the server closed the Track stream")
        if response.reply.seq != expected:
            raise Internal(f"the reply to tick {response.reply.seq} arrived while tick {expected} was due")
        return convert.track_reply(response.reply)


class TrackStream:
    """A sync ``Track`` stream; use as a context manager (``with client.track("dubins4d") as robot``)."""

    def __init__(
        self,
        stub: grpc.StreamStreamMultiCallable[safety_pb2.TrackRequest, safety_pb2.TrackResponse],
        metadata: tuple[tuple[str, str], ...],
        dims: convert.Dims,
        open_request: safety_pb2.TrackRequest,
    ) -> None:
        self._dims = dims
        self._requests: queue.SimpleQueue[safety_pb2.TrackRequest | None] = queue.SimpleQueue()
        self._requests.put(open_request)
        self._sequence = _Sequence()
        self._closed = False
        self._call = stub(iter(self._requests.get, None), metadata=metadata)

    def send(self, tracker_state: npt.ArrayLike, planner_state: npt.ArrayLike, d_obs: float | None = None) -> int:
        """Sends one tick without waiting for its reply; returns its ``seq``.

        ``tracker_state`` is the tracker's state s [n_state] (dubins4d: x m, y m, heading rad, speed m/s),
        ``planner_state`` the planner's p [planner_dim] (dubins4d: x, y in metres), ``d_obs`` the distance to
        the nearest sensed obstacle in metres (None: none sensed).
        """
        if self._closed:
            raise Unavailable("the Track stream is closed")
        request = convert.tick(self._dims, self._sequence.next_seq, tracker_state, planner_state, d_obs)
        self._requests.put(request)
        return self._sequence.sent()

    def recv(self) -> TrackReply:
        """The reply to the oldest tick still waiting (raises the tick's error, or the stream's)."""
        expected = self._sequence.expect()
        try:
            response: object = next(self._call)
        except StopIteration:
            response = None
        except grpc.RpcError as e:
            raise from_rpc_error(e) from None
        return self._sequence.answer(expected, response)

    def tick(self, tracker_state: npt.ArrayLike, planner_state: npt.ArrayLike, d_obs: float | None = None) -> TrackReply:
        """Sends one tick and waits for its reply (see :meth:`send` for the arguments)."""
        self.send(tracker_state, planner_state, d_obs)
        return self.recv()

    def close(self, cancel: bool = False) -> None:
        """Ends the stream: no more ticks; replies not yet read are dropped. Without ``cancel`` the server
        answers the ticks in flight and ends the call normally; with it the call is cancelled at once."""
        if self._closed:
            return
        self._closed = True
        self._requests.put(None)
        if cancel:
            self._call.cancel()
            return
        try:
            for _ in self._call:
                pass
        except grpc.RpcError:
            pass  # the stream had already failed; its error was (or would have been) raised by recv()

    def __enter__(self) -> TrackStream:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close(cancel=error is not None)


class AsyncTrackStream:
    """An asyncio ``Track`` stream; use with ``async with client.track("dubins4d") as robot``."""

    def __init__(self, call: TrackCall, dims: convert.Dims, open_request: safety_pb2.TrackRequest) -> None:
        self._call = call
        self._dims = dims
        self._open_request = open_request
        self._sequence = _Sequence()

    async def _write(self, request: safety_pb2.TrackRequest) -> None:
        try:
            await self._call.write(request)
        except grpc.RpcError as e:
            raise from_rpc_error(e) from None
        except asyncio.InvalidStateError:
            raise Unavailable("the Track stream is closed") from None

    async def open(self) -> AsyncTrackStream:
        """Sends the stream's ``open`` message (done by ``async with``)."""
        await self._write(self._open_request)
        return self

    async def send(
        self, tracker_state: npt.ArrayLike, planner_state: npt.ArrayLike, d_obs: float | None = None
    ) -> int:
        """Sends one tick without waiting for its reply; returns its ``seq`` (arguments as :meth:`TrackStream.send`)."""
        await self._write(convert.tick(self._dims, self._sequence.next_seq, tracker_state, planner_state, d_obs))
        return self._sequence.sent()

    async def recv(self) -> TrackReply:
        """The reply to the oldest tick still waiting (raises the tick's error, or the stream's)."""
        expected = self._sequence.expect()
        try:
            response = await self._call.read()
        except grpc.RpcError as e:
            raise from_rpc_error(e) from None
        return self._sequence.answer(expected, response)

    async def tick(
        self, tracker_state: npt.ArrayLike, planner_state: npt.ArrayLike, d_obs: float | None = None
    ) -> TrackReply:
        """Sends one tick and waits for its reply."""
        await self.send(tracker_state, planner_state, d_obs)
        return await self.recv()

    async def close(self, cancel: bool = False) -> None:
        """Ends the stream: no more ticks; replies not yet read are dropped. Without ``cancel`` the server
        answers the ticks in flight and ends the call normally; with it the call is cancelled at once."""
        if cancel or self._call.done():
            self._call.cancel()
            return
        try:
            await self._call.done_writing()
            while await self._call.read() is not grpc.aio.EOF:
                pass
        except (grpc.RpcError, asyncio.InvalidStateError):
            pass  # the stream had already failed; its error was (or would have been) raised by recv()

    async def __aenter__(self) -> AsyncTrackStream:
        return await self.open()

    async def __aexit__(
        self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close(cancel=error is not None)
