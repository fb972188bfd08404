"""A client of several replicas: calls go round-robin, unary calls skip a dead replica, and when a replica
dies mid-run every robot's ``Track`` stream moves to another one and goes on, each tick answered exactly
once, in order."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import fastrack
from conftest import MODEL, Server, free_port
from fastrack.replicas import StreamCounts
from test_track import robot_state

TICKS = 300
"""Ticks per robot; the replica is killed once every robot has sent ``KILL_AFTER`` of them."""
KILL_AFTER = 50
RECOVERY_S = 5.0
"""Every robot on the killed replica must be answered again this soon after the kill."""
PAUSE_S = 0.002
"""The robots' pause between ticks (a control loop, not a flood)."""


@dataclass
class Robot:
    """What one robot saw."""

    first_endpoint: str = ""
    seqs: list[int] = field(default_factory=list)
    reopened: int = 0
    resent: int = 0
    recovery: float | None = None
    """Seconds from the kill to this robot's first reply after its stream moved."""
    beta_after_move: tuple[int, float] | None = None
    """That reply's tick and ``beta_query``: the new replica answers the tick alone, as the old one would."""


@dataclass
class Kill:
    """Kills ``victim`` once ``robots`` robots have sent ``KILL_AFTER`` ticks each."""

    victim: Server
    robots: int
    ready: int = 0
    at: float | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    go: threading.Event = field(default_factory=threading.Event)

    def robot_ready(self) -> None:
        with self.lock:
            self.ready += 1
            if self.ready == self.robots:
                self.go.set()

    def kill(self) -> None:
        self.at = time.monotonic()
        self.victim.stop(signal.SIGKILL)

    def since(self) -> float:
        assert self.at is not None, "a stream moved before the replica was killed"
        return time.monotonic() - self.at


def check(seen: list[Robot], victim: Server, addresses: list[str], beta_for: dict[int, float]) -> float:
    """Every tick answered once, in order; the robots of the killed replica moved once, the others never;
    the streams were spread over the replicas. Returns the slowest recovery, seconds."""
    per_replica = Counter(robot.first_endpoint for robot in seen)
    assert sorted(per_replica) == sorted(addresses), per_replica
    fair = len(seen) // len(addresses)
    assert all(fair <= n <= fair + 1 for n in per_replica.values()), per_replica  # round-robin opens
    for i, robot in enumerate(seen):
        assert robot.seqs == list(range(TICKS)), f"robot {i}: each tick answered once, in order"
        on_victim = robot.first_endpoint == victim.address
        assert robot.reopened == int(on_victim), f"robot {i} on {robot.first_endpoint}"
        assert (robot.recovery is not None) == on_victim, f"robot {i}"
        assert robot.resent <= 1, f"robot {i}: one tick in flight at a time, {robot.resent} resent"
        if on_victim:
            assert robot.beta_after_move is not None, f"robot {i}"
            seq, beta = robot.beta_after_move
            d_obs = robot_state(seq, i)[2]  # 1.0 + seq % 7
            assert beta == beta_for[round(d_obs)], f"robot {i}: tick {seq} answered from the tick alone"
    slowest = max(robot.recovery for robot in seen if robot.recovery is not None)
    resent = sum(robot.resent for robot in seen)
    print(
        f"{per_replica[victim.address]} of {len(seen)} robots moved off the killed replica, {resent} ticks resent;"
        f" every robot served again within {slowest * 1000:.0f} ms"
    )
    assert slowest < RECOVERY_S, f"a robot waited {slowest:.2f} s after the kill"
    return slowest


def test_sync_robots_on_a_killed_replica_move_and_every_tick_is_answered_once(replicas: list[Server]) -> None:
    addresses = [server.address for server in replicas]
    robots = 20
    kill = Kill(replicas[1], robots)
    with fastrack.Client(",".join(addresses), timeout=10.0) as client:
        assert client.endpoints == addresses
        beta_for = {d: client.query_planner_control(MODEL, d).beta_query for d in range(1, 8)}
        client.dims(MODEL)
        seen = [Robot() for _ in range(robots)]
        failures: list[BaseException] = []

        def robot(index: int) -> None:
            me = seen[index]
            try:
                with client.track(MODEL) as stream:
                    me.first_endpoint = stream.endpoint
                    for seq in range(TICKS):
                        if seq == KILL_AFTER:
                            kill.robot_ready()
                        before = stream.reopened
                        reply = stream.tick(*robot_state(seq, index))
                        if stream.reopened > before:
                            me.recovery, me.beta_after_move = kill.since(), (seq, reply.beta_query)
                        me.seqs.append(reply.seq)
                        time.sleep(PAUSE_S)
                    me.reopened, me.resent = stream.reopened, stream.resent
            except BaseException as e:  # noqa: BLE001 - reported by the test's thread
                failures.append(e)
                kill.go.set()

        threads = [threading.Thread(target=robot, args=(i,)) for i in range(robots)]
        for thread in threads:
            thread.start()
        assert kill.go.wait(timeout=60)
        kill.kill()
        for thread in threads:
            thread.join(timeout=120)
        assert not failures, failures
        check(seen, replicas[1], addresses, beta_for)

        # Unary calls skip the dead replica: every one succeeds, even without retries (the replica hops are
        # not retries).
        with fastrack.Client(",".join(addresses), retry=fastrack.Retry(attempts=1)) as once:
            for _ in range(9):
                assert once.query_planner_control(MODEL, 3.0).beta_query > 0
                assert client.tracking_control(MODEL, [[0.1, 0.0, 1.5, 1.0]], 0.6).controls.shape == (1, 2)


async def test_async_robots_on_a_killed_replica_move_and_every_tick_is_answered_once(replicas: list[Server]) -> None:
    addresses = [server.address for server in replicas]
    robots = 50
    kill = Kill(replicas[2], robots)
    async with fastrack.AsyncClient(",".join(addresses), timeout=10.0) as client:
        beta_for = {d: (await client.query_planner_control(MODEL, d)).beta_query for d in range(1, 8)}
        await client.dims(MODEL)

        async def robot(index: int) -> Robot:
            me = Robot()
            async with client.track(MODEL) as stream:
                me.first_endpoint = stream.endpoint
                for seq in range(TICKS):
                    if seq == KILL_AFTER:
                        kill.robot_ready()
                    before = stream.reopened
                    reply = await stream.tick(*robot_state(seq, index))
                    if stream.reopened > before:
                        me.recovery, me.beta_after_move = kill.since(), (seq, reply.beta_query)
                    me.seqs.append(reply.seq)
                    await asyncio.sleep(PAUSE_S)
                me.reopened, me.resent = stream.reopened, stream.resent
            return me

        async def killer() -> None:
            while not kill.go.is_set():
                await asyncio.sleep(0.005)
            kill.kill()

        kill_task = asyncio.create_task(killer())
        try:
            seen = await asyncio.gather(*(robot(i) for i in range(robots)))
            await kill_task
        finally:
            kill_task.cancel()
        check(seen, replicas[2], addresses, beta_for)
        for _ in range(9):
            assert (await client.query_planner_control(MODEL, 3.0)).beta_query > 0
        assert (await client.evaluate(MODEL, [[0.1, 0.0, 1.5, 1.0]], 0.6)).values.shape == (1,)


def test_a_draining_replica_hands_its_streams_over(replicas: list[Server]) -> None:
    with fastrack.Client(",".join(server.address for server in replicas[:2])) as client:
        with client.track(MODEL) as robot:
            assert robot.tick(*robot_state(0, 0)).seq == 0
            draining = next(server for server in replicas if server.address == robot.endpoint)
            draining.stop(signal.SIGTERM)  # "the server is shutting down; reconnect to continue"
            sent = [robot.send(*robot_state(seq, 0)) for seq in range(1, 6)]
            assert [robot.recv().seq for _ in sent] == sent
            assert robot.reopened == 1 and robot.endpoint != draining.address
            assert robot.resent <= len(sent)


def test_a_stream_no_replica_takes_fails_then_reopens_when_one_is_back(replicas: list[Server]) -> None:
    first, second = replicas[:2]
    with fastrack.Client(f"{first.address},{second.address}") as client:
        with client.track(MODEL) as robot:
            assert robot.tick(*robot_state(0, 0)).seq == 0
            first.stop()
            second.stop()
            with pytest.raises(fastrack.Unavailable, match="no replica took the stream again") as lost:
                robot.tick(*robot_state(1, 0))
            assert "went away" in lost.value.message, lost.value.message
            with pytest.raises(fastrack.FastrackError, match="recv\\(\\) without a tick"):
                robot.recv()  # the tick that no replica took was dropped
            second.start().wait_serving()
            client.wait_until_serving(timeout=10, quorum=1)  # the client's channel to it connected again
            seq = robot.send(*robot_state(2, 0))  # the next tick opens the stream again
            assert robot.recv().seq == seq and robot.endpoint == second.address and robot.reopened == 1


async def test_an_async_stream_no_replica_takes_fails_then_reopens(replicas: list[Server]) -> None:
    first, second = replicas[:2]
    async with fastrack.AsyncClient(f"{first.address},{second.address}") as client:
        async with client.track(MODEL) as robot:
            assert (await robot.tick(*robot_state(0, 0))).seq == 0
            first.stop()
            second.stop()
            with pytest.raises(fastrack.Unavailable, match="went away .*; no replica took the stream again"):
                await robot.tick(*robot_state(1, 0))
            first.start().wait_serving()
            await client.wait_until_serving(timeout=10, quorum=1)
            seq = await robot.send(*robot_state(2, 0))
            assert (await robot.recv()).seq == seq and robot.endpoint == first.address and robot.reopened == 1


def test_a_dead_address_beside_a_live_one(server: Server) -> None:
    dead = f"127.0.0.1:{free_port()}"
    with fastrack.Client(f"{dead}, http://{server.address}") as client:
        assert client.endpoints == [dead, server.address]
        with pytest.raises(fastrack.Unavailable, match=f"1 of 2 replicas .* SERVING after 0.3 s, 2 wanted \\(serving: {server.address}\\)"):
            client.wait_until_serving(timeout=0.3)  # all of them, by default
        client.wait_until_serving(timeout=5, quorum=1)
        assert client.serving_replicas() == [server.address]
        for _ in range(4):
            assert client.get_model(MODEL).name == MODEL
        for _ in range(3):  # whichever replica is next, the stream opens on the live one
            with client.track(MODEL) as robot:
                assert robot.endpoint == server.address
                assert robot.tick(*robot_state(0, 0)).seq == 0
        # Admin calls go to one replica, once: of two in a row, one reaches the dead replica and fails.
        outcomes = set()
        for _ in range(2):
            try:
                client.unload_model("no-such-model")
            except fastrack.FastrackError as e:
                outcomes.add(type(e))
        assert outcomes == {fastrack.Unavailable, fastrack.NotFound}


async def test_async_dead_address_beside_a_live_one(server: Server) -> None:
    dead = f"127.0.0.1:{free_port()}"
    async with fastrack.AsyncClient(f"{server.address},{dead}") as client:
        with pytest.raises(fastrack.Unavailable, match="1 of 2 replicas .* SERVING after 0.3 s, 2 wanted"):
            await client.wait_until_serving(timeout=0.3)
        await client.wait_until_serving(timeout=5, quorum=1)
        assert await client.serving_replicas() == [server.address]
        for _ in range(4):
            assert (await client.tracking_error_bound(MODEL, 1.0)).radius > 0
        for _ in range(3):
            async with client.track(MODEL) as robot:
                assert robot.endpoint == server.address
                assert (await robot.tick(*robot_state(0, 0))).seq == 0


@contextlib.contextmanager
def silent_replica() -> Iterator[str]:
    """An address that takes connections and never says a word (a frozen server)."""
    listener = socket.create_server(("127.0.0.1", 0))
    held: list[socket.socket] = []

    def hold() -> None:
        with contextlib.suppress(OSError):
            while True:
                held.append(listener.accept()[0])

    threading.Thread(target=hold, daemon=True).start()
    try:
        yield f"127.0.0.1:{listener.getsockname()[1]}"
    finally:
        listener.close()
        for connection in held:
            connection.close()


def test_a_replica_that_never_answers_is_passed_over_by_calls_and_stream_opens(server: Server) -> None:
    with silent_replica() as silent, fastrack.Client(f"{silent},{server.address}", timeout=0.5) as client:
        # An idempotent unary call that meets the silent replica goes on to the next once its deadline passes.
        for _ in range(2):
            assert client.get_model(MODEL).name == MODEL
        started = time.monotonic()
        for i in range(4):
            with client.track(MODEL) as robot:
                assert robot.endpoint == server.address
                assert robot.tick(*robot_state(0, i)).seq == 0
        # Round-robin sent two of the four opens to the silent replica first: each waited out the deadline.
        assert time.monotonic() - started >= 1.0


async def test_async_a_replica_that_never_answers_is_passed_over_by_calls_and_stream_opens(server: Server) -> None:
    with silent_replica() as silent:
        async with fastrack.AsyncClient(f"{silent},{server.address}", timeout=0.5) as client:
            for _ in range(2):
                assert (await client.get_model(MODEL)).name == MODEL
            started = time.monotonic()
            for i in range(4):
                async with client.track(MODEL) as robot:
                    assert robot.endpoint == server.address
                    assert (await robot.tick(*robot_state(0, i))).seq == 0
            assert time.monotonic() - started >= 1.0


def all_threads_stopped(pid: int) -> bool:
    """True when every thread of process ``pid`` is stopped (state T): a stop is delivered, not immediate."""
    tasks = Path(f"/proc/{pid}/task")
    return all((task / "stat").read_text().rsplit(")", 1)[1].split()[0] == "T" for task in tasks.iterdir())


@contextlib.contextmanager
def frozen(server: Server) -> Iterator[None]:
    """The server stopped (SIGSTOP): it keeps its connections and answers nothing, until thawed."""
    assert server.process is not None
    server.process.send_signal(signal.SIGSTOP)
    end = time.monotonic() + 5
    while not all_threads_stopped(server.process.pid):
        assert time.monotonic() < end, "the server did not stop within 5 s"
        time.sleep(0.001)
    try:
        yield
    finally:
        server.process.send_signal(signal.SIGCONT)


def test_a_stream_whose_replica_freezes_moves_once_a_tick_goes_unanswered(replicas: list[Server]) -> None:
    address = ",".join(r.address for r in replicas[:2])
    with fastrack.Client(address, timeout=0.5) as client, client.track(MODEL) as robot:
        for seq in range(3):
            assert robot.tick(*robot_state(seq, 0)).seq == seq
        holder = next(r for r in replicas if r.address == robot.endpoint)
        with frozen(holder):
            started = time.monotonic()
            assert robot.tick(*robot_state(3, 0)).seq == 3
            waited = time.monotonic() - started
            assert robot.endpoint != holder.address and (robot.reopened, robot.resent) == (1, 1)
            assert 0.5 <= waited < 3.0, waited
            assert robot.tick(*robot_state(4, 0)).seq == 4


async def test_async_a_stream_whose_replica_freezes_moves_once_a_tick_goes_unanswered(replicas: list[Server]) -> None:
    address = ",".join(r.address for r in replicas[:2])
    async with fastrack.AsyncClient(address, timeout=0.5) as client:
        async with client.track(MODEL) as robot:
            for seq in range(3):
                assert (await robot.tick(*robot_state(seq, 0))).seq == seq
            holder = next(r for r in replicas if r.address == robot.endpoint)
            with frozen(holder):
                started = time.monotonic()
                assert (await robot.tick(*robot_state(3, 0))).seq == 3
                waited = time.monotonic() - started
                assert robot.endpoint != holder.address and (robot.reopened, robot.resent) == (1, 1)
                assert 0.5 <= waited < 3.0, waited
                assert (await robot.tick(*robot_state(4, 0))).seq == 4


def test_a_replica_that_never_answers_alone_fails_once_with_its_deadline() -> None:
    with silent_replica() as silent, fastrack.Client(silent, timeout=0.3, retry=fastrack.Retry(attempts=3)) as client:
        started = time.monotonic()
        with pytest.raises(fastrack.DeadlineExceeded):
            client.list_models()
        assert time.monotonic() - started < 0.3 * 2, "no second pass after a deadline"
        with pytest.raises(fastrack.DeadlineExceeded):
            client.unload_model("no-such-model")  # not idempotent: raised as it is


def test_only_dead_addresses_fail_clearly() -> None:
    dead, dead_too = f"127.0.0.1:{free_port()}", f"127.0.0.1:{free_port()}"
    with fastrack.Client(dead, retry=fastrack.Retry(attempts=1)) as client:
        with pytest.raises(fastrack.Unavailable, match="failed to connect"):
            client.list_models()
        with pytest.raises(fastrack.Unavailable, match="failed to connect"):
            client.track(MODEL)
        with pytest.raises(fastrack.Unavailable, match=f"0 of 1 replicas of {dead} SERVING after 0.3 s, 1 wanted"):
            client.wait_until_serving(timeout=0.3)
    with fastrack.Client(f"{dead},{dead_too}", retry=fastrack.Retry(attempts=2, initial_backoff=0.01)) as client:
        with pytest.raises(fastrack.Unavailable) as both:
            client.query_planner_control(MODEL)
        assert both.value.message.startswith("no replica answered: ")
        assert f"{dead}: failed to connect" in both.value.message and f"{dead_too}: " in both.value.message


def test_addresses_are_checked_and_names_resolved(server: Server) -> None:
    with pytest.raises(fastrack.ConfigError, match="item 2 of the comma-separated list is empty"):
        fastrack.Client(f"{server.address},,127.0.0.1:1")
    with pytest.raises(fastrack.ConfigError, match="item 2 of the comma-separated list is empty"):
        fastrack.Client(f"{server.address}, ")
    with pytest.raises(fastrack.ConfigError, match="'127.0.0.1': expected host:port"):
        fastrack.Client(f"{server.address},127.0.0.1")
    with pytest.raises(fastrack.ConfigError, match="https://127.0.0.1:2: an https:// address needs TLS"):
        fastrack.Client("127.0.0.1:1,https://127.0.0.1:2")
    assert fastrack.Client("[::1]:7,127.0.0.1:8").endpoints == ["[::1]:7", "127.0.0.1:8"]
    port = server.port
    with fastrack.Client(f"localhost:{port}") as named:  # every address localhost has is a replica
        assert named.endpoints and all(e.endswith(f":{port}") for e in named.endpoints), named.endpoints
        assert f"127.0.0.1:{port}" in named.endpoints
        assert named.query_planner_control(MODEL, 2.5).beta_query == pytest.approx(0.75)


def test_a_replica_at_its_stream_limit_passes_new_streams_to_another(server: Server) -> None:
    full = Server("--max-track-streams", "1").start().wait_serving()
    try:
        with fastrack.Client(f"{full.address},{server.address}") as client:
            robots = [client.track(MODEL) for _ in range(4)]
            try:
                for k, robot in enumerate(robots):
                    assert robot.tick(*robot_state(0, k)).seq == 0
                places = [robot.endpoint for robot in robots]
                assert (places.count(full.address), places.count(server.address)) == (1, 3), places
            finally:
                for robot in robots:
                    robot.close()
        # With every replica full, the open fails with the limit's own status.
        with fastrack.Client(full.address) as alone, alone.track(MODEL) as first:
            assert first.tick(*robot_state(0, 9)).seq == 0
            with pytest.raises(fastrack.ResourceExhausted, match="max_track_streams"):
                alone.track(MODEL)
    finally:
        full.stop()


def within(limit_s: float, what: str, done: Callable[[], bool]) -> None:
    """Polls ``done`` every 50 ms until it holds; fails after ``limit_s`` seconds, saying ``what``."""
    end = time.monotonic() + limit_s
    while not done():
        assert time.monotonic() < end, f"{what} not within {limit_s} s"
        time.sleep(0.05)


def counts_holding(open_streams: list[int]) -> StreamCounts:
    counts = StreamCounts([f"r{i}" for i in range(len(open_streams))])
    for i, n in enumerate(open_streams):
        for _ in range(n):
            counts.moved(None, f"r{i}")
    return counts


def test_streams_looking_at_once_plan_only_the_moves_that_even_the_load() -> None:
    # Six streams on r1 look at [0, 6, 3] at the same moment: three moves to r0 even it (without counting the
    # planned moves all six would leave, and the load would swing from replica to replica).
    counts = counts_holding([0, 6, 3])
    plans = [move for move in (counts.plan_move("r1") for _ in range(6)) if move is not None]
    assert [(m.source, m.to) for m in plans] == [("r1", "r0")] * 3
    assert counts.plan_move("r2") is None, "r2 holds its share once the plans count"
    assert counts.counts() == [0, 6, 3], "a plan is not a move"
    for move in plans:
        move.release()
        move.release()  # once only
    again = counts.plan_move("r1")
    assert again is not None and again.to == "r0", "released plans leave the balance"


def test_a_replica_that_refused_is_left_out_and_one_move_narrows_the_gap() -> None:
    counts = counts_holding([0, 6, 3])
    counts.refused("r0")
    plans = [move for move in (counts.plan_move("r1") for _ in range(6)) if move is not None]
    assert [(m.source, m.to) for m in plans] == [("r1", "r2")], "[0, 5, 4] after one move"
    assert counts_holding([2, 1]).plan_move("r0") is None, "a gap of one is as even as it gets"


def test_streams_spread_over_the_replicas_and_come_back_to_one_that_returns(replicas: list[Server]) -> None:
    victim = replicas[0]
    with fastrack.Client(",".join(r.address for r in replicas)) as client:
        client.wait_until_serving(timeout=30)
        at = client.endpoints.index(victim.address)
        stop, lock = threading.Event(), threading.Lock()
        moves: Counter[str] = Counter()
        errors: list[BaseException] = []

        def robot(i: int) -> None:
            try:
                with client.track(MODEL) as stream:
                    seq = 0
                    while not stop.is_set():
                        assert stream.tick(*robot_state(seq, i)).seq == seq  # every tick answered once, in order
                        seq += 1
                        time.sleep(0.01)
                    with lock:
                        moves.update(reopened=stream.reopened, rebalanced=stream.rebalanced)
            except BaseException as e:  # noqa: BLE001 - reported below
                errors.append(e)

        threads = [threading.Thread(target=robot, args=(i,)) for i in range(12)]
        for thread in threads:
            thread.start()
        within(30, "twelve streams spread evenly", lambda: client.stream_counts == [4, 4, 4])
        victim.stop(signal.SIGKILL)
        within(30, "the dead replica's streams moved", lambda: client.stream_counts[at] == 0)
        victim.start().wait_serving()
        within(60, "the load even again", lambda: client.stream_counts == [4, 4, 4])
        stop.set()
        for thread in threads:
            thread.join(timeout=30)
        assert not errors, errors
        assert moves["reopened"] == 4, moves
        assert moves["rebalanced"] >= 4, moves
        assert client.stream_counts == [0, 0, 0]


async def test_async_streams_come_back_to_a_replica_that_returns(replicas: list[Server]) -> None:
    victim = replicas[0]
    async with fastrack.AsyncClient(",".join(r.address for r in replicas)) as client:
        await client.wait_until_serving(timeout=30)
        at = client.endpoints.index(victim.address)
        stop = asyncio.Event()

        async def robot(i: int) -> tuple[int, int]:
            async with client.track(MODEL) as stream:
                seq = 0
                while not stop.is_set():
                    assert (await stream.tick(*robot_state(seq, i))).seq == seq
                    seq += 1
                    await asyncio.sleep(0.01)
                return stream.reopened, stream.rebalanced

        async def until(limit_s: float, what: str, done: Callable[[], bool]) -> None:
            end = time.monotonic() + limit_s
            while not done():
                assert time.monotonic() < end, f"{what} not within {limit_s} s: {client.stream_counts}"
                await asyncio.sleep(0.05)

        robots = [asyncio.create_task(robot(i)) for i in range(9)]
        await until(30, "nine streams spread evenly", lambda: client.stream_counts == [3, 3, 3])
        victim.stop(signal.SIGKILL)
        await until(30, "the dead replica's streams moved", lambda: client.stream_counts[at] == 0)
        await asyncio.to_thread(lambda: victim.start().wait_serving())
        await until(60, "the load even again", lambda: client.stream_counts == [3, 3, 3])
        stop.set()
        moved = await asyncio.gather(*robots)
        assert sum(r for r, _ in moved) == 3 and sum(b for _, b in moved) >= 3, moved
