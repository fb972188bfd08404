"""The online loop (Alg. 3) in Python: its geometry, raw-path planners and speed rule on their own, then the
loop against the real server on the shipped ``dubins4d`` (the scenarios of the Rust
``tests/tests/online_loop.rs``), a cross-check of its speed choice with ``QueryPlannerControl``, and one
closed-loop run of a simulated dubins4d robot through a small world."""

from __future__ import annotations

import math
import subprocess
import sys
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np
import numpy.typing as npt
import pytest

import fastrack
from conftest import MODEL, Server
from fastrack.geometry import (
    Circle,
    Obstacle,
    Point,
    PointLike,
    Rectangle,
    Wall,
    clearance,
    clearances,
    remember,
    segment_is_free,
)
from fastrack.online import (
    DROP_PATIENCE,
    GoalBlocked,
    GridAStar,
    LoopSetupError,
    NoPath,
    OnlineLoop,
    PlanError,
    RawPathPlanner,
    SpeedRow,
    StepReport,
    StraightLine,
    TableMismatch,
    TrackerStateError,
    advance_along,
    SpeedRule,
    path_length,
    planner_rule,
    query_planner_control,
    row_for,
)
from fastrack.v1 import models_pb2

ALONG_X = math.pi / 2
"""dubins4d heading along +x (``x' = v sin theta``)."""

Vector = npt.NDArray[np.float64]


def online(
    client: fastrack.Client,
    *,
    goal: Point = (10.0, 0.0),
    bounds: tuple[Point, Point] = ((-2.0, -6.0), (12.0, 6.0)),
    control_period: float = 0.1,
    planner: RawPathPlanner | None = None,
    reset_candidates: int = 64,
    rule: SpeedRule = "half-distance",
) -> OnlineLoop:
    """The Rust tests' settings: start (0, 0), goal (10, 0), workspace [-2, 12] x [-6, 6], dt 0.1 s, 64 reset
    candidates; A* raw paths."""
    return OnlineLoop(
        client,
        MODEL,
        start=(0.0, 0.0),
        goal=goal,
        bounds=bounds,
        control_period=control_period,
        planner=planner,
        reset_candidates=reset_candidates,
        rule=rule,
    )


# --- geometry ------------------------------------------------------------------------------------------------


def test_distances_match_closed_forms() -> None:
    circle = Circle((1.0, 1.0), 0.5)
    assert circle.distance((3.0, 1.0)) == pytest.approx(1.5, abs=1e-12)
    assert circle.distance((1.2, 1.1)) == 0.0
    rectangle = Rectangle((0.0, 0.0), (2.0, 1.0))
    assert rectangle.distance((3.0, 2.0)) == pytest.approx(math.sqrt(2.0), abs=1e-12)
    assert rectangle.distance((1.0, -0.5)) == pytest.approx(0.5, abs=1e-12)
    assert rectangle.distance((1.0, 0.5)) == 0.0
    wall = Wall((0.0, 0.0), (4.0, 0.0), 0.2)
    assert wall.distance((2.0, 1.0)) == pytest.approx(0.9, abs=1e-12)
    assert wall.distance((5.0, 0.0)) == pytest.approx(0.9, abs=1e-12)
    assert wall.bounds() == ((-0.1, -0.1), (4.1, 0.1)) and circle.bounds() == ((0.5, 0.5), (1.5, 1.5))


def test_segment_distances_see_crossings_and_near_misses() -> None:
    rectangle = Rectangle((0.0, 0.0), (1.0, 1.0))
    assert rectangle.segment_distance((-1.0, 0.5), (2.0, 0.5)) == 0.0  # through it, no end inside
    assert rectangle.segment_distance((-1.0, 1.25), (2.0, 1.25)) == pytest.approx(0.25, abs=1e-12)
    circle = Circle((0.0, 0.0), 1.0)
    assert circle.segment_distance((-2.0, 2.0), (2.0, 2.0)) == pytest.approx(1.0, abs=1e-12)
    assert segment_is_free([circle], (-2.0, 2.0), (2.0, 2.0), 0.9)
    assert not segment_is_free([circle], (-2.0, 2.0), (2.0, 2.0), 1.0)
    wall = Wall((0.0, 0.0), (1.0, 2.0), 0.3)
    a, b = (2.0, -1.0), (3.0, 3.0)
    brute = min(wall.distance((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))) for t in np.linspace(0, 1, 10_001))
    assert wall.segment_distance(a, b) == pytest.approx(brute, abs=1e-6)


def test_vectorised_distances_match_the_scalar_ones() -> None:
    obstacles: list[Obstacle] = [
        Circle((1.0, 2.0), 0.7),
        Rectangle((-2.0, -1.0), (0.5, 0.0)),
        Wall((2.0, -2.0), (4.0, 1.0), 0.3),
    ]
    points = np.random.default_rng(3).uniform(-4.0, 5.0, size=(500, 2))
    scalar = [clearance(obstacles, (float(x), float(y))) for x, y in points]
    np.testing.assert_allclose(clearances(obstacles, points), scalar, rtol=0, atol=1e-12)
    assert clearance([], (0.0, 0.0)) == math.inf


def test_impossible_obstacles_are_refused_and_equal_ones_remembered_once() -> None:
    with pytest.raises(fastrack.InvalidArgument, match="circle center"):
        Circle((0.0, math.nan), 1.0)
    with pytest.raises(fastrack.InvalidArgument, match="circle radius = -1.0"):
        Circle((0.0, 0.0), -1.0)
    with pytest.raises(fastrack.InvalidArgument, match="below and left"):
        Rectangle((1.0, 0.0), (0.0, 1.0))
    with pytest.raises(fastrack.InvalidArgument, match="wall thickness = 0.0"):
        Wall((0.0, 0.0), (1.0, 0.0), 0.0)
    known: list[Obstacle] = []
    assert remember(known, [Circle((1, 2), 0.5)])  # ints and lists are normalised to float tuples
    assert not remember(known, [Circle((1.0, 2.0), 0.5)])
    assert remember(known, [Circle((1.0, 2.0), 0.5), Wall((0, 0), (1, 0), 0.1)]) and len(known) == 2


# --- queryPlannerControl and raw paths -------------------------------------------------------------------------


def test_query_planner_control_follows_the_rule() -> None:
    table = [SpeedRow(beta=0.5 + 0.05 * k, bound=0.2 + 0.1 * k) for k in range(16)]
    fastest = query_planner_control(table, None)
    assert (fastest.beta, fastest.row) == (0.5 + 0.05 * 15, 15) and fastest.dteb_radius == pytest.approx(1.7)
    assert fastest.steb_radius == pytest.approx(0.2) and not fastest.steb_exceeds_half_distance
    for d in (0.0, 0.1, 0.399):
        slowest = query_planner_control(table, d)
        assert (slowest.beta, slowest.row, slowest.steb_exceeds_half_distance) == (0.5, 0, True), d
    fits = query_planner_control(table, 1.5)  # d/2 = 0.75: bounds up to 0.7 fit
    assert fits.beta == pytest.approx(0.75) and fits.dteb_radius == pytest.approx(0.7)
    assert query_planner_control(table, 1.6).beta == pytest.approx(0.8)  # exactly on a bound: it fits
    assert (row_for(table, 0.5), row_for(table, 0.51), row_for(table, 1.3)) == (0, 1, None)


def test_advancing_moves_no_axis_more_than_the_budget() -> None:
    path: deque[Point] = deque([(1.0, 0.0), (1.0, 2.0)])
    assert advance_along((0.0, 0.0), path, 0.5) == (0.5, 0.0)
    assert advance_along((0.5, 0.0), path, 0.75) == (1.0, 0.25) and len(path) == 1  # across the corner
    assert advance_along((0.0, 0.0), deque([(2.0, 2.0)]), 0.5) == (0.5, 0.5)  # diagonal: both at the budget
    short: deque[Point] = deque([(0.1, 0.0)])
    assert advance_along((0.0, 0.0), short, 1.0) == (0.1, 0.0) and not short  # the path's end is where it stops


def plan(planner: GridAStar | StraightLine, obstacles: Sequence[Obstacle], inflation: float) -> list[Point]:
    return planner.plan((0.0, 0.0), (10.0, 0.0), obstacles, inflation, ((-1.0, -6.0), (11.0, 6.0)))


def test_grid_astar_goes_around_keeping_the_inflation() -> None:
    assert plan(GridAStar(), [], 0.5) == [(0.0, 0.0), (10.0, 0.0)]
    disc = [Circle((5.0, 0.0), 1.0)]
    path = plan(GridAStar(), disc, 0.5)
    assert all(segment_is_free(disc, a, b, 0.5) for a, b in zip(path, path[1:])), path
    assert 10.0 < path_length(path) < 12.3, path
    # A start 0.3 m from a disc, inside the 0.5 m inflation: the path leaves it, never closing in.
    near = [Circle((0.0, -1.3), 1.0)]
    path = plan(GridAStar(), near, 0.5)
    assert path[0] == (0.0, 0.0)
    assert min(near[0].segment_distance(a, b) for a, b in zip(path, path[1:])) >= 0.3 - 1e-9
    escaped = next(i for i, p in enumerate(path) if clearance(near, p) > 0.5)
    assert all(segment_is_free(near, a, b, 0.5) for a, b in zip(path[escaped:], path[escaped + 1 :]))


def test_blocked_worlds_are_plan_errors() -> None:
    with pytest.raises(NoPath, match="keeps 0.3 m"):
        plan(GridAStar(), [Wall((5.0, -7.0), (5.0, 7.0), 0.2)], 0.3)
    with pytest.raises(GoalBlocked, match=r"the goal \(10.0, 0.0\) is not free"):
        plan(GridAStar(), [Circle((10.0, 0.2), 0.5)], 0.3)
    with pytest.raises(PlanError, match="cell = 0.0"):
        plan(GridAStar(cell=0.0), [], 0.3)
    assert plan(StraightLine(), [Circle((5.0, 2.0), 1.0)], 0.5) == [(0.0, 0.0), (10.0, 0.0)]
    with pytest.raises(NoPath):
        plan(StraightLine(), [Circle((5.0, 1.0), 1.0)], 0.5)
    assert len(plan(StraightLine(check=False), [Circle((5.0, 0.0), 1.0)], 0.5)) == 2


# --- the loop against the server (tests/tests/online_loop.rs) ---------------------------------------------------


def test_the_planner_advances_at_most_beta_dt_per_axis(client: fastrack.Client) -> None:
    with online(client) as loop:
        first = loop.step([0.0, 0.0, ALONG_X, 1.0], [])
        assert (first.branch, first.replanned, first.round_trips) == ("advance", True, 1)
        assert first.beta_query == 1.25 and first.d_obs is None, "no obstacle: beta_u"
        np.testing.assert_allclose(first.planner, [0.125, 0.0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(first.relative_state, [-0.125, 0.0, ALONG_X, 1.0], rtol=0, atol=1e-12)
    # A goal off the axis: the straight path moves both axes, the larger one at exactly beta dt.
    with online(client, goal=(6.0, 3.0), planner=StraightLine()) as diagonal:
        step = diagonal.step([0.0, 0.0, ALONG_X, 1.0])
        np.testing.assert_allclose(step.planner, [0.125, 0.0625], rtol=0, atol=1e-12)
        # A planner 0.14 m ahead after one 0.1 s period leaves the tracker on the edge of the tight set at
        # beta_u: the reply says where it is, inside the trained domain.
        assert step.control.shape == (2,) and step.in_domain and math.isfinite(step.value)
    # Around a disc (the A* path turns): every advance step moves each axis at most beta dt.
    with online(client, control_period=0.05) as loop:
        disc = Circle((5.0, 0.3), 1.0)
        previous, advances = np.array(loop.planner_state), 0
        for _ in range(100):
            # The tracker on the planner, slow (0.5 m/s): inside every row's set, so no drop has to hold.
            step = loop.step([*loop.planner_state, ALONG_X, 0.5], [disc])
            if step.branch == "advance":
                advances += 1
                assert step.round_trips == 1
                assert np.max(np.abs(step.planner - previous)) <= step.beta_query * 0.05 + 1e-12
            previous = step.planner
        # beta drops step by step as the disc nears (each drop a keep); the path bends below the disc.
        assert advances >= 80 and previous[0] > 2.0 and previous[1] < -0.5, "the planner went along the detour"


def test_a_drop_in_beta_keeps_p_star_when_the_tracker_is_inside_the_smaller_bound(client: fastrack.Client) -> None:
    with online(client) as loop:
        tracker = [0.0, 0.0, ALONG_X, 1.0]
        loop.step(tracker)
        obstacle = Circle((3.1, 0.0), 0.5)  # 2.6 m ahead: beta drops to the largest row whose bound fits 1.3 m
        step = loop.step(tracker, [obstacle])
        assert step.d_obs == 2.6
        assert step.beta_query < step.beta_old and step.dteb_radius <= 1.3, step
        assert step.replanned, "a newly sensed obstacle is planned around"
        assert step.branch == "keep" and step.round_trips == 1, step
        assert step.in_teb and step.value <= step.dteb_radius
        # p* is the raw-path state closest to the tracker: the planner's own state, 0.125 m ahead.
        np.testing.assert_allclose(step.planner, [0.125, 0.0], rtol=0, atol=1e-12)
        assert loop.raw_path and all(clearance([obstacle], p) > step.steb_radius for p in loop.raw_path)
        again = loop.step(tracker, [obstacle])  # sensed again: nothing new, no replan
        assert not again.replanned and again.branch == "advance" and again.beta_old == step.beta_query


def test_a_move_that_would_bring_the_planner_within_the_bound_of_an_obstacle_holds(client: fastrack.Client) -> None:
    with online(client) as loop:
        first = loop.step([0.0, 0.0, ALONG_X, 1.0])
        bound = first.dteb_radius
        # An obstacle whose edge lies 0.3 m inside beta_u's bound of the planner, the tracker so far behind it
        # that the half-distance rule still allows beta_u: one more period along the path would leave the
        # planner within the bound of the obstacle, so it waits where it is under the row in force.
        edge = first.planner[0] + bound - 0.3
        obstacle = Circle((edge + 0.5, 0.0), 0.5)
        tracker = [edge - 2.0 * bound - 0.5, 0.0, ALONG_X, 1.0]
        step = loop.step(tracker, [obstacle])
        assert step.beta_query == step.beta_old == first.beta_query, step
        assert step.branch == "hold" and step.round_trips == 1, step
        np.testing.assert_allclose(step.planner, first.planner, rtol=0, atol=0)
        assert clearance([obstacle], (float(step.planner[0]), float(step.planner[1]))) > 0.0


def test_the_planner_rule_picks_beta_by_the_planners_own_clearance(client: fastrack.Client) -> None:
    with online(client, rule="planner") as loop:
        first = loop.step([0.0, 0.0, ALONG_X, 1.0])
        assert first.branch == "advance" and first.beta_query == loop.speeds[-1].beta
        # An obstacle 0.3 m inside beta_u's bound of the planner, the tracker so far behind that the paper's rule
        # on its distance would keep beta_u: the planner rule reads the planner's clearance less one period's
        # reach at beta_u, and drops to the row whose bound fits it.
        bound = first.dteb_radius
        edge = first.planner[0] + bound - 0.3
        obstacle = Circle((edge + 0.5, 0.0), 0.5)
        tracker = [edge - 2.0 * bound - 0.5, 0.0, ALONG_X, 1.0]
        reach = math.sqrt(2.0) * loop.speeds[-1].beta * 0.1
        planner_clearance = clearance([obstacle], (float(first.planner[0]), float(first.planner[1]))) - reach
        expected = planner_rule(loop.speeds, planner_clearance)
        assert query_planner_control(loop.speeds, 2.0 * bound + 0.5).beta == first.beta_query
        step = loop.step(tracker, [obstacle])
        assert step.beta_query == expected.beta < step.beta_old, step
        asked = client.query_planner_control(MODEL, planner_clearance=planner_clearance)
        assert asked.beta_query == expected.beta and asked.dteb_radius == expected.dteb_radius
        assert clearance([obstacle], (float(step.planner[0]), float(step.planner[1]))) > step.dteb_radius
    with pytest.raises(LoopSetupError, match="rule = 'fastest'"):
        online(client, rule="fastest")  # type: ignore[arg-type]


def test_the_planner_rule_takes_a_rise_only_where_the_path_ahead_keeps_the_faster_bound_clear(
    client: fastrack.Client,
) -> None:
    for ahead, rises in [(0.5, False), (1.5, True)]:
        with online(client, rule="planner", planner=StraightLine()) as loop:
            slow, fast = loop.speeds[0], loop.speeds[-1]
            reach = math.sqrt(2.0) * fast.beta * 0.1
            # beta_l in force, the planner at the origin on a straight path along +x; an obstacle beside the
            # path, its nearest point to the path `ahead` m beyond beta_u's bound: 0.2 m too close for beta_u
            # from the path's point at that bound when ahead = 0.5, clear of it when ahead = 1.5.
            loop._beta_query = slow.beta
            side = math.sqrt((fast.bound + reach + 0.5 - 0.2) ** 2 - 0.5**2)
            obstacle = Circle((fast.bound + ahead, side), 0.5)
            own = clearance([obstacle], (0.0, 0.0)) - reach
            assert planner_rule(loop.speeds, own).beta == fast.beta, "the planner's own clearance allows beta_u"
            # A tracker speed at which beta_u's certified set holds the state after the move, so that only the
            # path can refuse the rise.
            moved = [[-fast.beta * 0.1, 0.0, ALONG_X, v] for v in np.linspace(0.1, 2.9, 29)]
            held = client.evaluate(MODEL, moved, fast.beta, out_of_domain="flag").in_teb
            assert held.any(), "beta_u's set holds no tracker on its planner"
            speed = moved[int(np.argmax(held))][3]
            step = loop.step([0.0, 0.0, ALONG_X, speed], [obstacle])
            if rises:
                assert step.branch == "advance" and step.beta_query == fast.beta, step
            else:
                assert step.branch == "steady" and step.beta_query == step.beta_old == slow.beta, step
                np.testing.assert_allclose(step.planner, [slow.beta * 0.1, 0.0], rtol=0, atol=1e-12)


def test_a_drop_in_beta_far_from_the_plan_resets_the_planner_inside_the_bound(client: fastrack.Client) -> None:
    with online(client) as loop:
        loop.step([0.0, 0.0, ALONG_X, 1.0])
        # The tracker 2.5 m off the plan, an obstacle 2.5 m beyond it: the smaller bound cannot hold p*.
        tracker = [0.0, 2.5, ALONG_X, 1.0]
        obstacle = Circle((0.0, 5.5), 0.5)
        step = loop.step(tracker, [obstacle])
        assert step.beta_query < step.beta_old and step.branch == "reset", step
        assert step.round_trips >= 2, "p* and at least one reset candidate were asked"
        assert step.in_teb and step.value <= step.dteb_radius, "the reset planner state is inside dTEBmax"
        offset = math.hypot(step.planner[0] - tracker[0], step.planner[1] - tracker[1])
        assert offset <= step.dteb_radius, "the reset point lies within dTEBmax of the tracker"
        assert clearance([obstacle], (float(step.planner[0]), float(step.planner[1]))) > step.steb_radius
        assert loop.replan_flag and not loop.raw_path
        after = loop.step(tracker, [obstacle])
        assert after.replanned, "the reset flags a replan"
        assert not loop.replan_flag and loop.raw_path[-1] == (10.0, 0.0)


def test_a_tracker_past_the_workspace_edge_is_reset_inside_the_workspace(client: fastrack.Client) -> None:
    # As above, but the workspace ends at y = 2.2, 0.3 m short of the tracker: its own position is no reset
    # point (no path would lead back from it), a candidate inside the workspace is.
    with online(client, bounds=((-2.0, -6.0), (12.0, 2.2))) as loop:
        loop.step([0.0, 0.0, ALONG_X, 1.0])
        tracker = [0.0, 2.5, ALONG_X, 1.0]
        step = loop.step(tracker, [Circle((0.0, 5.6), 0.5)])  # 2.6 m: beta drops to 0.8, whose set has room
        assert step.branch == "reset", step
        assert step.planner[1] <= 2.2, "the reset point lies inside the workspace"
        assert math.hypot(step.planner[0] - tracker[0], step.planner[1] - tracker[1]) <= step.dteb_radius
        assert step.in_teb and step.value <= step.dteb_radius


def held_control(client: fastrack.Client, step: StepReport) -> np.ndarray:
    """``u*`` at the step's relative state under its (held) ``beta_query``, asked of the server directly."""
    n_params = len(client.get_model(MODEL).params)
    params = np.full((1, n_params), step.beta_query)
    answer = client.tracking_control(MODEL, [step.relative_state], params, out_of_domain="flag")
    return np.asarray(answer.controls[0], dtype=np.float64)


def test_no_free_reset_point_holds_the_planner_under_the_old_bound(client: fastrack.Client) -> None:
    with online(client, reset_candidates=8) as loop:
        first = loop.step([0.0, 0.0, ALONG_X, 1.0])
        # The tracker on the edge of a block 3 m off the plan: every point within dTEBmax = sTEB of it lies
        # within the sTEB of the block.
        step = loop.step([0.0, 3.0, ALONG_X, 1.0], [Rectangle((-1.0, 3.0), (1.0, 4.0))])
        assert step.branch == "hold", step
        assert (step.beta_old, step.beta_query, step.dteb_radius) == (first.beta_query,) * 2 + (first.dteb_radius,)
        np.testing.assert_array_equal(step.planner, first.planner)
        assert step.round_trips == 2, "p*, then the held control: no candidate was free to ask about"
        np.testing.assert_allclose(step.relative_state, [-0.125, 3.0, ALONG_X, 1.0], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(step.control, held_control(client, step))


def test_a_fast_tracker_outside_every_smaller_set_holds_until_it_slows(client: fastrack.Client) -> None:
    with online(client) as loop:
        fast = [0.0, 0.0, ALONG_X, 2.5]
        first = loop.step(fast)
        obstacle = Circle((3.6, 0.0), 0.5)
        step = loop.step(fast, [obstacle])
        assert step.branch == "hold" and step.beta_query == first.beta_query, step
        assert step.d_obs is not None and step.dteb_radius > step.d_obs / 2, "the old bound stays in force"
        assert step.round_trips == 3, "p*, one batch of reset candidates, the held control"
        np.testing.assert_array_equal(step.control, held_control(client, step))
        slow = [float(step.planner[0]), float(step.planner[1]), ALONG_X, 1.0]
        after = loop.step(slow, [obstacle])
        assert after.branch == "keep" and after.beta_query < after.beta_old and after.in_teb, after


def test_a_drop_that_held_for_the_patience_is_tried_one_row_slower_at_each_step(client: fastrack.Client) -> None:
    with online(client) as loop:
        # At 1.5 m/s the tracker lies outside beta 0.9's set even on its planner: the drop to 0.9 holds.
        fast = [0.0, 0.0, ALONG_X, 1.5]
        assert not held_on_its_planner(client, fast, 0.9)
        first = loop.step(fast)
        # 2.9 m from the tracker: half of it fits beta 0.9's bound, not 0.95's.
        obstacle = Circle((0.0, 3.4), 0.5)
        for _ in range(round(DROP_PATIENCE / 0.1)):
            step = loop.step(fast, [obstacle])
            assert step.branch == "hold" and step.beta_query == first.beta_query, step
        # One row slower (0.85), asked in batches: the server's tick would choose the rule's 0.9.
        step = loop.step(fast, [obstacle])
        assert step.branch in ("keep", "reset") and step.beta_query == 0.85 and step.in_teb, step
        assert step.d_obs is not None and step.dteb_radius < step.d_obs / 2, "a slower row's bound fits as well"
        np.testing.assert_array_equal(step.control, held_control(client, step))


def held_on_its_planner(client: fastrack.Client, tracker: list[float], beta: float) -> bool:
    """Whether ``beta``'s certified set holds the tracker with no position error."""
    answer = client.tracking_control(MODEL, [[0.0, 0.0, *tracker[2:]]], [[beta]], out_of_domain="flag")
    return bool(answer.in_teb[0])


def test_bad_tracker_states_and_settings_are_clear_errors(client: fastrack.Client) -> None:
    with online(client) as loop:
        with pytest.raises(TrackerStateError, match=r"tracker state has 3 values; model dubins4d has 4 .*x_r, y_r"):
            loop.step([0.0, 0.0, 1.0])
        with pytest.raises(TrackerStateError, match=r"tracker\[1\] \(y_r\) = nan; must be finite"):
            loop.step([0.0, math.nan, 1.0, 1.0])
        with pytest.raises(fastrack.InvalidArgument, match="shape"):
            loop.step([[0.0, 0.0, 1.0, 1.0]])
        with pytest.raises(fastrack.InvalidArgument, match=r"sensed\[0\] is a tuple"):
            loop.step([0.0, 0.0, 1.0, 1.0], [((3.0, 0.0), 0.5)])  # type: ignore[list-item]
        assert loop.step([0.0, 0.0, ALONG_X, 1.0]).round_trips == 1, "the loop still runs after refusals"
    with pytest.raises(LoopSetupError, match="control_period = 0.0"):
        online(client, control_period=0.0)
    with pytest.raises(LoopSetupError, match="reset_candidates = 0"):
        online(client, reset_candidates=0)
    with pytest.raises(LoopSetupError, match=r"goal = \[nan, 0.0\]"):
        online(client, goal=(math.nan, 0.0))
    with pytest.raises(LoopSetupError, match="below and left"):
        online(client, bounds=((0.0, 0.0), (0.0, 5.0)))
    with pytest.raises(fastrack.NotFound):
        OnlineLoop(client, "no-such-model", start=(0, 0), goal=(1, 0), bounds=((0, 0), (2, 2)), control_period=0.1)


@dataclass
class ScriptedPlanner:
    """A planner that returns what it is told to, or raises it."""

    answer: Sequence[PointLike] | Exception
    calls: list[tuple[Point, float]] = field(default_factory=list)

    def plan(
        self, start: Point, goal: Point, obstacles: Sequence[Obstacle], inflation: float, bounds: tuple[Point, Point]
    ) -> Sequence[PointLike]:
        self.calls.append((start, inflation))
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


def test_planner_failures_are_plan_errors(client: fastrack.Client) -> None:
    tracker = [0.0, 0.0, ALONG_X, 1.0]
    cases: list[tuple[Sequence[PointLike] | Exception, str]] = [
        (ValueError("grid too small"), r"ScriptedPlanner failed: ValueError\('grid too small'\)"),
        ([], "returned an empty path"),
        ([(0.0, 0.0), (math.inf, 1.0)], r"raw path point 1 = \[inf, 1.0\]; must be finite"),
        ([(0.0, 0.0, 0.0)], r"raw path point 0 has shape \[3\]"),
    ]
    for answer, pattern in cases:
        with online(client, planner=ScriptedPlanner(answer)) as loop:
            with pytest.raises(PlanError, match=pattern):
                loop.step(tracker)
    with online(client, planner=ScriptedPlanner(NoPath("walled in"))) as loop:
        with pytest.raises(NoPath, match="walled in"):
            loop.step(tracker)
    # A planner of one's own: the loop hands it the planner state, the goal and the sTEB, drops the start.
    scripted = ScriptedPlanner([(0.0, 0.0), (0.0, 1.0), (10.0, 0.0)])
    with online(client, planner=scripted) as loop:
        step = loop.step(tracker)
        assert scripted.calls == [((0.0, 0.0), step.steb_radius)]
        np.testing.assert_allclose(step.planner, [0.0, 0.125], rtol=0, atol=1e-12)
        assert loop.raw_path == [(0.0, 1.0), (10.0, 0.0)]


class SkewedClient(fastrack.Client):
    """A client whose ``GetModel`` answers the first ``skewed`` times with the TEB betas raised by 0.01 m/s:
    the loop's table disagrees with the server's, as after a reload with another table."""

    def __init__(self, address: str, skewed: int) -> None:
        super().__init__(address)
        self.skewed = skewed
        self.fetches = 0

    def get_model(self, model: str, version: int = 0, *, timeout: float | None = None) -> models_pb2.ModelInfo:
        info = super().get_model(model, version, timeout=timeout)
        self.fetches += 1
        if self.fetches <= self.skewed:
            for row in info.teb_table:
                row.beta += 0.01
        return info


def test_a_table_that_changed_is_fetched_again_once(server: Server) -> None:
    client = SkewedClient(server.address, skewed=1)
    with client, online(client) as loop:
        assert loop.speeds[-1].beta == pytest.approx(1.26)
        step = loop.step([0.0, 0.0, ALONG_X, 1.0])
        assert client.fetches == 2 and step.beta_query == 1.25 and loop.speeds[-1].beta == 1.25
        assert step.replanned and step.round_trips == 1
    client = SkewedClient(server.address, skewed=2)
    with client, online(client) as loop:
        with pytest.raises(TableMismatch, match="the server chose beta 1.25 where the table gives 1.26") as caught:
            loop.step([0.0, 0.0, ALONG_X, 1.0])
        assert client.fetches == 2 and caught.value.server == 1.25


def test_a_vanished_server_is_unavailable() -> None:
    own = Server().start().wait_serving()
    try:
        with fastrack.Client(own.address, retry=fastrack.Retry(attempts=1)) as client, online(client) as loop:
            assert loop.step([0.0, 0.0, ALONG_X, 1.0]).round_trips == 1
            own.stop()
            with pytest.raises(fastrack.Unavailable):
                loop.step([0.0, 0.0, ALONG_X, 1.0])
    finally:
        own.close()


def test_speed_choice_agrees_with_query_planner_control(client: fastrack.Client) -> None:
    """The same inputs through the loop and through ``QueryPlannerControl``, the server's own rule."""
    obstacles: list[Obstacle] = [
        Circle((6.0, 0.5), 0.6),
        Rectangle((9.0, -3.0), (10.0, -1.5)),
        Wall((3.0, 3.0), (8.0, 4.0), 0.2),
    ]
    seen: list[Obstacle] = []
    branches: set[str] = set()
    with online(client, goal=(11.0, 0.0), control_period=0.05) as loop:
        for k in range(40):
            x = 0.3 * k
            tracker = [x, 0.4 * math.sin(0.5 * k), ALONG_X, 1.0]
            sensed = [o for o in obstacles if o.distance((tracker[0], tracker[1])) <= 4.0]
            remember(seen, sensed)
            step = loop.step(tracker, sensed)
            branches.add(step.branch)
            expected_d = clearance(seen, (tracker[0], tracker[1])) if seen else None
            assert step.d_obs == expected_d
            served = client.query_planner_control(MODEL, step.d_obs)
            if step.branch == "hold":  # the old row stays in force, above the rule's choice
                assert step.beta_query == step.beta_old > served.beta_query, k
            elif step.branch == "steady":  # a refused rise: the old row stays in force, below the rule's choice
                assert step.beta_query == step.beta_old < served.beta_query, k
                assert step.dteb_radius < served.dteb_radius, k
            else:
                assert (step.beta_query, step.dteb_radius, step.steb_radius) == (
                    served.beta_query,
                    served.dteb_radius,
                    served.steb_radius,
                ), k
            r = np.array(tracker) - np.array([*step.planner, 0.0, 0.0])
            np.testing.assert_allclose(step.relative_state[:2], r[:2], rtol=0, atol=1e-12)
    assert {"advance", "keep"} <= branches, branches


# --- closed loop -------------------------------------------------------------------------------------------------


@dataclass
class ClosedLoopRun:
    reached_at: float | None = None
    steps: int = 0
    round_trips: int = 0
    replans: int = 0
    branches: dict[str, int] = field(default_factory=dict)
    min_clearance: float = math.inf
    worst_excess: float = -math.inf
    """Largest tracking error minus the step's dTEBmax over every sub-step (must stay <= 0)."""
    out_of_domain: int = 0
    betas: set[float] = field(default_factory=set)


def test_closed_loop_run_reaches_the_goal_safely(client: fastrack.Client) -> None:
    """A dubins4d robot through a small world: a disc on the straight line, a block and a wall beside it,
    sensed within twice the dTEB at beta_u (the paper's assumption), A* raw paths, dt 0.01 s, 4 RK4 sub-steps
    per period. Every sub-step keeps the true obstacles and the tracking error within the step's dTEBmax."""
    world: list[Obstacle] = [
        Circle((5.0, 5.3), 0.8),
        Rectangle((8.5, 1.0), (9.5, 3.6)),
        Wall((11.5, 6.3), (11.5, 9.5), 0.2),
    ]
    start, goal, dt, substeps, time_limit = (1.0, 5.0), (15.0, 5.0), 0.01, 4, 40.0
    s = [start[0], start[1], ALONG_X, 0.5]
    rk4 = example().rk4  # the example's RK4 of the dubins4d tracker
    run = ClosedLoopRun()
    with OnlineLoop(
        client, MODEL, start=start, goal=goal, bounds=((0.0, 0.0), (16.0, 10.0)), control_period=dt
    ) as loop:
        sensor_range = 2.0 * loop.speeds[-1].bound
        for k in range(int(time_limit / dt)):
            position = (s[0], s[1])
            if math.dist(position, goal) <= 1.0:
                run.reached_at = k * dt
                break
            sensed = [o for o in world if o.distance(position) <= sensor_range]
            step: StepReport = loop.step(s, sensed)
            run.steps += 1
            run.round_trips += step.round_trips
            run.replans += step.replanned
            run.branches[step.branch] = run.branches.get(step.branch, 0) + 1
            run.out_of_domain += not step.in_domain
            run.betas.add(step.beta_query)
            planner = (float(step.planner[0]), float(step.planner[1]))
            control = step.control.tolist()
            for _ in range(substeps):
                s = rk4(s, control, dt / substeps)
                run.min_clearance = min(run.min_clearance, clearance(world, (s[0], s[1])))
                error = math.dist((s[0], s[1]), planner)
                run.worst_excess = max(run.worst_excess, error - step.dteb_radius)
    print(run)
    assert run.reached_at is not None, f"the goal was not reached in {time_limit} s: {run}"
    assert run.min_clearance > 0.0, f"collision: {run}"
    assert run.worst_excess <= 1e-9, f"the tracking error left dTEBmax: {run}"
    assert run.out_of_domain == 0
    assert len(run.betas) > 1 and min(run.betas) < 1.25, "the speed adapted to the obstacles"
    assert run.replans >= 2, "each newly sensed obstacle is planned around"
    assert run.round_trips <= run.steps + 2 * (run.branches.get("reset", 0) + run.branches.get("hold", 0))


# --- the example ----------------------------------------------------------------------------------------------

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example() -> ModuleType:
    """The example ``examples/online_loop.py`` as a module."""
    sys.path.insert(0, str(EXAMPLES))
    try:
        import online_loop
    finally:
        sys.path.remove(str(EXAMPLES))
    return online_loop


def test_the_example_drives_a_small_world_with_the_straight_line(client: fastrack.Client) -> None:
    online_loop = example()
    world = online_loop.World(
        bounds=((0.0, 0.0), (8.0, 6.0)), start=(1.0, 3.0), goal=(6.5, 3.0), obstacles=(Circle((3.5, 5.0), 0.6),)
    )
    outcome = online_loop.simulate(client, world, planner=StraightLine(), time_limit=15.0)
    assert outcome.reached and outcome.safe and outcome.failure is None, outcome
    # The disc is sensed at the start: one plan, and one more after each reset. A reset or a hold (a drop that
    # found the relative state outside the smaller row's certified set) costs the candidates' batch and one
    # more tick or the held control; every other step one round trip.
    resets, holds = outcome.branches.get("reset", 0), outcome.branches.get("hold", 0)
    assert outcome.replans == 1 + resets, outcome
    assert outcome.steps <= outcome.round_trips <= outcome.steps + 2 * (resets + holds), outcome


def test_the_example_drives_its_world_faster_under_the_planner_rule(client: fastrack.Client) -> None:
    online_loop = example()
    world = online_loop.World(
        bounds=((0.0, 0.0), (12.0, 6.0)), start=(1.0, 3.0), goal=(10.5, 3.0), obstacles=(Circle((5.5, 5.4), 0.6),)
    )
    half = online_loop.simulate(client, world, time_limit=30.0)
    planner = online_loop.simulate(client, world, time_limit=30.0, rule="planner")
    assert half.reached and half.safe and planner.reached and planner.safe, (half, planner)
    # The disc 2.4 m off the line (17.5 s against 11.4 s when written): half of the tracker's distance holds
    # beta below beta_u near it, the planner's own clearance does not.
    assert planner.time < half.time, (planner.time, half.time)


def test_the_example_reports_a_run_out_of_time(server: Server) -> None:
    command = [sys.executable, str(EXAMPLES / "online_loop.py"), "--server", server.address, "--time-limit", "0.5"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 1, done.stderr
    assert "stopped after 0.50 s simulated (50 steps" in done.stdout and "1.000 round trips per step" in done.stdout
    assert "failed: the goal was not reached within 0.5 s" in done.stderr
