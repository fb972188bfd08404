"""``Track`` streams, sync and asyncio, against the real server."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pytest

import fastrack
from conftest import MODEL, Server


def robot_state(seq: int, robot: int) -> tuple[list[float], list[float], float]:
    """Tick ``seq`` of robot ``robot``: tracker drifting around its planner, inside the trained domain."""
    phase = seq * 0.01 + robot
    tracker = [0.3 * math.sin(phase) + 0.001 * seq, 0.2 * math.cos(phase), phase % 3.0, 1.0 + 0.5 * math.sin(phase)]
    return tracker, [0.001 * seq, 0.0], 1.0 + seq % 7


def test_a_thousand_ticks_answered_in_order(client: fastrack.Client) -> None:
    beta_u = client.query_planner_control(MODEL).beta_query
    beta_for = {d: client.query_planner_control(MODEL, d).beta_query for d in np.arange(1.0, 8.0)}
    with client.track(MODEL) as robot:
        assert robot.tick(*robot_state(0, 0)[:2]).beta_query == beta_u  # nothing sensed: the fastest row
        for seq in range(1000):
            tracker, planner, d_obs = robot_state(seq, 0)
            reply = robot.tick(tracker, planner, d_obs)
            assert reply.seq == seq + 1
            expected_r = np.array(tracker) - np.array([planner[0], planner[1], 0.0, 0.0])  # r = s - Q p
            np.testing.assert_allclose(reply.relative_state, expected_r, rtol=0, atol=1e-12)
            assert reply.beta_query == beta_for[d_obs]
            assert reply.control.shape == (2,) and reply.in_domain


def test_pipelined_ticks_come_back_in_order(client: fastrack.Client) -> None:
    with client.track(MODEL) as robot:
        sent = [robot.send(*robot_state(seq, 1)) for seq in range(20)]
        assert sent == list(range(20))
        assert [robot.recv().seq for _ in range(20)] == sent
        with pytest.raises(fastrack.FastrackError, match="recv\\(\\) without a tick"):
            robot.recv()


def test_track_matches_tracking_control(client: fastrack.Client) -> None:
    tracker, planner = [0.4, -0.3, 1.0, 1.5], [0.1, 0.2]
    with client.track(MODEL) as robot:
        reply = robot.tick(tracker, planner, d_obs=2.5)
    assert reply.beta_query == pytest.approx(0.75)
    unary = client.tracking_control(MODEL, [[0.3, -0.5, 1.0, 1.5]], reply.beta_query)
    np.testing.assert_allclose(reply.control, unary.controls[0], rtol=1e-9, atol=0)
    assert reply.value == pytest.approx(unary.values[0], rel=1e-9)


def test_a_rejected_tick_raises_its_error_and_the_stream_stays_open(client: fastrack.Client) -> None:
    with client.track(MODEL) as robot:
        with pytest.raises(fastrack.InvalidArgument) as refused:
            robot.tick([float("nan"), 0.0, 0.0, 1.0], [0.0, 0.0])
        assert refused.value.message == "tracker_state[0] is NaN; must be a finite number"
        with pytest.raises(fastrack.InvalidArgument) as negative:
            robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0], d_obs=-1.0)
        assert "d_obs = -1" in negative.value.message
        assert robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0]).seq == 2


def test_tick_shapes_are_checked_before_sending(client: fastrack.Client) -> None:
    with client.track(MODEL) as robot:
        with pytest.raises(fastrack.InvalidArgument, match=r"tracker_state has shape \[3\]; .* needs \[4\]"):
            robot.tick([0.0, 0.0, 1.0], [0.0, 0.0])
        with pytest.raises(fastrack.InvalidArgument, match=r"planner_state has shape \[3\]; .* needs \[2\]"):
            robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0])
        assert robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0]).seq == 0  # nothing was sent


def test_unknown_model_and_idle_timeout(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.NotFound, match='model "dubins4x" is not loaded'):
        client.track("dubins4x")
    with client.track(MODEL, idle_timeout=0.2) as robot:
        robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])
        time.sleep(0.6)
        with pytest.raises(fastrack.DeadlineExceeded, match="no tick for"):
            robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])


async def test_fifty_async_robots_at_once(server: Server) -> None:
    ticks = 100

    async def robot(client: fastrack.AsyncClient, index: int) -> list[int]:
        seqs = []
        async with client.track(MODEL) as stream:
            for seq in range(ticks):
                reply = await stream.tick(*robot_state(seq, index))
                assert reply.control.shape == (2,)
                seqs.append(reply.seq)
        return seqs

    async with fastrack.AsyncClient(server.address) as client:
        started = time.perf_counter()
        answers = await asyncio.gather(*(robot(client, i) for i in range(50)))
        elapsed = time.perf_counter() - started
    assert answers == [list(range(ticks))] * 50
    assert elapsed < 60, f"50 x {ticks} ticks took {elapsed:.1f} s"


async def test_async_errors_and_pipelining(server: Server) -> None:
    async with fastrack.AsyncClient(server.address) as client:
        assert await client.health() == "SERVING"
        assert (await client.query_planner_control(MODEL, 2.5)).beta_query == pytest.approx(0.75)
        with pytest.raises(fastrack.NotFound):
            await client.get_model("dubins4x")
        async with client.track(MODEL) as robot:
            with pytest.raises(fastrack.FastrackError, match="recv\\(\\) without a tick"):
                await robot.recv()  # before any send: a usage error, not a wait forever
            sent = [await robot.send(*robot_state(seq, 2)) for seq in range(10)]
            assert [(await robot.recv()).seq for _ in sent] == sent
            with pytest.raises(fastrack.InvalidArgument, match="must be a finite number"):
                await robot.tick([0.0, float("inf"), 0.0, 1.0], [0.0, 0.0])
            assert (await robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])).seq == 11
