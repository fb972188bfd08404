"""The paper's online loop (Parametric FaSTrack, Alg. 3), one control step at a time, over one ``Track``
stream: the Python twin of the Rust ``fastrack_online::online_loop`` (see ``docs/online-loop.md``).

Each :meth:`OnlineLoop.step` takes the tracker state and the obstacles sensed now, and

1. measures ``d_obs``, the distance from the tracker's position ``Q^T s`` to the nearest obstacle sensed
   so far (None while none has been sensed);
2. keeps ``beta_old`` and applies queryPlannerControl to its copy of the model's TEB table (the rule the
   server applies: :func:`query_planner_control`), giving ``beta_query``, ``dTEBmax`` and the sTEB;
3. replans the raw path around the obstacles inflated by the sTEB when an obstacle is newly sensed or the
   replan flag is set (the :class:`RawPathPlanner` of your choice: :class:`GridAStar` by default, or
   :class:`StraightLine`);
4. adjusts the planner (adjustPlannerControl): when ``beta_query < beta_old``, keeps ``p*``, the state of the
   planner and its raw path closest to the tracker, if ``s - Q p*`` lies in the certified set of
   ``beta_query`` (the server's ``in_teb``, ``V <= set level``: where ``dTEBmax`` holds; branch ``"keep"``),
   else resets the planner to a free point of the inflated map with ``s - Q p`` in that set and flags a
   replan (branch ``"reset"``), else (no such point: the tracker's speed or heading
   lies outside the smaller set) holds: the planner waits where it is with ``beta_old`` and its bound still
   in force, and the drop is tried again at the next step (branch ``"hold"``); otherwise moves the planner
   along the raw path for one control period, each axis at most ``beta_query dt`` (branch ``"advance"``),
   except on a rise whose new relative state the faster row's certified set does not hold: then it moves at
   ``beta_old``, whose row stays in force (branch ``"steady"``), as it does under the planner rule on a rise
   whose path ahead, within the faster row's bound, does not keep that bound clear; and when the relative
   state has stayed outside the certified set of the row in force for half the verification horizon, the
   planner is reset into it under that row, a rise waiting for the next step (or holds). Every planner state a step ends with lies
   farther than the bound then in force from every sensed obstacle: a keep, a reset point or a move that
   would not is refused (a move on a rise then goes at ``beta_old``; otherwise the planner holds);
5. reads ``u*`` at ``r_next = s - Q p_next`` under ``beta_query`` (``beta_old`` on a hold or a steady step).

The tick that carries ``p_next`` (or the candidate ``p*``) returns ``beta_query``, the bound's membership
and ``u*`` together, so the common branch costs one round trip; a reset asks about all its candidates in
one ``TrackingControl`` batch and then ticks the chosen one; a hold reads its control with one more
``TrackingControl`` call under ``beta_old``. The server's ``beta_query`` is checked against the local one: a
table that changed under the loop (the model was reloaded) is fetched again and the step taken again, once.

>>> import fastrack
>>> from fastrack.geometry import Circle
>>> from fastrack.online import OnlineLoop
>>> with fastrack.Client("127.0.0.1:50051") as client:  # doctest: +SKIP
...     with OnlineLoop(client, "dubins4d", start=(2.0, 10.0), goal=(28.0, 10.0),
...                     bounds=((0.0, 0.0), (30.0, 20.0)), control_period=0.01) as online:
...         report = online.step([2.0, 10.0, 1.5708, 0.5], [Circle((6.0, 10.0), 1.0)])
...         # apply report.control for one control period; report.dteb_radius bounds the error meanwhile
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from types import TracebackType
from typing import Literal, Protocol

import grpc
import numpy as np
import numpy.typing as npt

from .client import Client
from .errors import ConfigError, FastrackError, InvalidArgument
from .geometry import (
    OBSTACLE_KINDS,
    Floats,
    Obstacle,
    Point,
    PointLike,
    clearance,
    clearances,
    norm,
    point,
    remember,
    segment_is_free,
    sub,
)
from .results import TrackingControl, TrackReply
from .track import TrackStream
from .v1 import models_pb2

Branch = Literal["advance", "steady", "keep", "reset", "hold"]
"""adjustPlannerControl's branch: ``"advance"`` (``beta_query >= beta_old``: the planner moved along the raw
path; on a rise only when the faster row's certified set holds the new relative state), ``"steady"``
(``beta_query > beta_old`` but the rise was refused, because that set does not hold it, the move would bring
the planner within the faster bound of a sensed obstacle, or under the planner rule the path ahead within that
bound does not keep it clear: the planner moved at ``beta_old``, whose row stays in force), ``"keep"`` (``beta_query < beta_old`` and ``s - Q p*`` in the certified set of ``beta_query``: the
planner jumped to ``p*``), ``"reset"`` (``s - Q p*`` outside it: the planner was reset to a free point inside
it, a replan flagged), ``"hold"`` (the planner waited where it is, ``beta_old`` and its bound still in force:
no free point within ``dTEBmax`` of the tracker puts the relative state in it, or a move would have brought
the planner within the bound of a sensed obstacle)."""


# --- errors -------------------------------------------------------------------------------------------------


class OnlineLoopError(FastrackError):
    """A step of the online loop could not be taken for a reason the loop found itself (the server's own
    refusals arrive as their usual classes: :class:`~fastrack.InvalidArgument`, :class:`~fastrack.Unavailable`...)."""

    default_code = grpc.StatusCode.FAILED_PRECONDITION


class LoopSetupError(ConfigError, OnlineLoopError):
    """The loop's settings are unusable (a control period <= 0, no reset candidates, a bad goal), or the
    model cannot drive the loop (a planner that is not 2-D, an empty TEB table)."""


class TrackerStateError(InvalidArgument, OnlineLoopError):
    """The tracker state does not fit the model: the wrong length, or a value that is not finite."""


class PlanError(OnlineLoopError):
    """The raw path could not be planned (the planner failed, or returned something that is not a path)."""


class GoalBlocked(PlanError):
    """The goal lies within the inflation of an obstacle, or outside the workspace."""


class NoPath(PlanError):
    """No path keeps the inflation from every sensed obstacle."""


class TableMismatch(OnlineLoopError):
    """The server's ``beta_query`` still differed from the loop's after the table was fetched again."""

    def __init__(self, local: float, server: float) -> None:
        self.local = local
        self.server = server
        super().__init__(
            f"the server chose beta {server} where the table gives {local}: the model changes under the loop"
        )


# --- queryPlannerControl on a TEB table (fastrack_proto::planner_speed) -------------------------------------


@dataclass(frozen=True)
class SpeedRow:
    """One row of a TEB table as the rules read it."""

    beta: float
    """Planner speed bound ``beta``."""
    bound: float
    """The row's tracking error bound: the TEB radius at ``beta``, metres."""

    @classmethod
    def of(cls, row: models_pb2.TebRow) -> SpeedRow:
        """The row of a ``GetModel`` table, as the Rust ``SpeedRow::from`` reads it: the speed rule needs
        the bound; membership (``TebRow.set_level``) is the server's ``in_teb``."""
        return cls(beta=row.beta, bound=row.bound)


def speed_rows(info: models_pb2.ModelInfo) -> list[SpeedRow]:
    """The TEB table of a model description, slowest row first (raises :class:`LoopSetupError` if empty)."""
    rows = [SpeedRow.of(row) for row in info.teb_table]
    if not rows:
        raise LoopSetupError(f"model {info.name}/{info.version} has an empty TEB table")
    return rows


@dataclass(frozen=True)
class _Answer:
    """The model's answer at one relative state, read off a ``TrackingControl`` batch (a tick's reply carries
    the same fields)."""

    relative_state: npt.NDArray[np.float64]
    value: float
    in_teb: bool
    in_domain: bool
    control: npt.NDArray[np.float64]

    @staticmethod
    def of_batch(batch: TrackingControl, i: int, relative_state: Sequence[float]) -> _Answer:
        """Item ``i`` of ``batch``, asked at ``relative_state``."""
        return _Answer(
            relative_state=np.array(relative_state, dtype=np.float64),
            value=float(batch.values[i]),
            in_teb=bool(batch.in_teb[i]),
            in_domain=bool(batch.in_domain[i]),
            control=np.asarray(batch.controls[i], dtype=np.float64),
        )


@dataclass(frozen=True)
class PlannerSpeed:
    """What queryPlannerControl chose."""

    beta: float
    """The planner speed bound to use, ``beta_query``."""
    row: int
    """Index of its row in the table."""
    dteb_radius: float
    """TEB radius at ``beta`` (the dTEB, ``dTEBmax`` in the paper's Alg. 3)."""
    steb_radius: float
    """TEB radius at ``beta_l`` (the sTEB)."""
    steb_exceeds_half_distance: bool
    """The sTEB does not fit in the ball of radius ``d_obs / 2`` (under :func:`planner_rule`: in the planner's
    clearance)."""


def query_planner_control(rows: Sequence[SpeedRow], d_obs: float | None) -> PlannerSpeed:
    """queryPlannerControl: with no obstacle sensed (``d_obs`` None) the fastest row; otherwise, if the sTEB
    radius exceeds ``d_obs / 2``, the slowest row (``beta_l``), else the largest ``beta`` whose radius is at
    most ``d_obs / 2``. ``rows`` must be non-empty, sorted by ``beta``, with monotone bounds (as ``GetModel``
    gives them)."""
    steb_radius = rows[0].bound
    if d_obs is None:
        row = len(rows) - 1
    else:
        row = next((i for i in range(len(rows) - 1, -1, -1) if rows[i].bound <= d_obs / 2.0), 0)
    return PlannerSpeed(
        beta=rows[row].beta,
        row=row,
        dteb_radius=rows[row].bound,
        steb_radius=steb_radius,
        steb_exceeds_half_distance=d_obs is not None and steb_radius > d_obs / 2.0,
    )


def planner_rule(rows: Sequence[SpeedRow], planner_clearance: float) -> PlannerSpeed:
    """The planner rule: the largest ``beta`` whose radius is less than ``planner_clearance`` (the planner's
    distance to the nearest sensed obstacle less the farthest one control period can move it), or ``beta_l``
    when none is: a tracker within the bound of a planner farther than the bound from every obstacle touches
    none of them."""
    steb_radius = rows[0].bound
    row = next((i for i in range(len(rows) - 1, -1, -1) if rows[i].bound < planner_clearance), 0)
    return PlannerSpeed(
        beta=rows[row].beta,
        row=row,
        dteb_radius=rows[row].bound,
        steb_radius=steb_radius,
        steb_exceeds_half_distance=steb_radius >= planner_clearance,
    )


SpeedRule = Literal["half-distance", "planner"]
"""The rule that picks ``beta_query``: ``"half-distance"`` (the paper's queryPlannerControl on the tracker's
distance to the nearest sensed obstacle) or ``"planner"`` (:func:`planner_rule` on the planner's own clearance,
less one control period's reach at ``beta_u``; a rise is taken only where the raw path within the faster row's
bound ahead keeps that bound clear as well)."""


REANCHOR_SHARE = 0.5
"""Share of the certificate horizon after which a loop whose relative state stayed outside the certified set of
the row in force moves the planner back into it (a reset under that row, or a hold)."""

DROP_PATIENCE = 2.0
"""How long a drop may hold (s) before it is tried one row slower at each further step: a hold waits for the
tracker to move into the smaller set, and a tracker that settles outside it would wait for ever. Any row below
the rule's keeps its smaller bound clear, so a slower drop is as safe."""


def certificate_horizon(info: models_pb2.ModelInfo) -> float | None:
    """The horizon over which the model's rows were verified, seconds: the shortest of them (None: no row
    verified). From a relative state in a row's certified set the error stays within its bound for this long
    while the planner obeys its ``beta``."""
    horizons = [row.verification.horizon for row in info.teb_table if row.HasField("verification")]
    return min(horizons) if horizons else None


def row_for(rows: Sequence[SpeedRow], beta: float) -> int | None:
    """The row answering for ``beta``: the first whose ``beta`` is at least the requested one. None if
    ``beta`` exceeds the last row."""
    return next((i for i, row in enumerate(rows) if row.beta >= beta - 1e-12 * max(abs(row.beta), 1.0)), None)


# --- raw-path planners (fastrack_online::raw_path) ----------------------------------------------------------


class RawPathPlanner(Protocol):
    """Plans raw paths: a list of planner states from ``start`` to ``goal``, both included, every segment
    keeping more than ``inflation`` from every obstacle (the start may lie closer: the path leaves it), inside
    the workspace ``bounds`` = ``(min, max)``. Raise :class:`PlanError` (or :class:`GoalBlocked`,
    :class:`NoPath`) when no path can be planned; any other exception is reported as a :class:`PlanError`."""

    def plan(
        self,
        start: Point,
        goal: Point,
        obstacles: Sequence[Obstacle],
        inflation: float,
        bounds: tuple[Point, Point],
    ) -> Sequence[PointLike]: ...


def _inside(bounds: tuple[Point, Point], p: Point) -> bool:
    (lo, hi) = bounds
    return lo[0] <= p[0] <= hi[0] and lo[1] <= p[1] <= hi[1]


def _goal_blocked(goal: Point, inflation: float) -> GoalBlocked:
    return GoalBlocked(
        f"the goal {goal} is not free: it lies within {inflation} m of an obstacle or outside the workspace"
    )


def _no_path(start: Point, goal: Point, inflation: float) -> NoPath:
    return NoPath(f"no path from {start} to {goal} keeps {inflation} m from every sensed obstacle")


@dataclass
class StraightLine:
    """The straight segment from the start to the goal. With ``check`` (the default) it refuses a goal that
    is not free (:class:`GoalBlocked`) and a segment that comes within the inflation of an obstacle
    (:class:`NoPath`); a start already within the inflation may keep its own clearance but not lose any.
    Use it in open worlds, or as the simplest planner to test a loop with."""

    check: bool = True

    def plan(
        self,
        start: Point,
        goal: Point,
        obstacles: Sequence[Obstacle],
        inflation: float,
        bounds: tuple[Point, Point],
    ) -> list[Point]:
        if self.check:
            if not (_inside(bounds, goal) and clearance(obstacles, goal) > inflation):
                raise _goal_blocked(goal, inflation)
            keep = min(inflation, clearance(obstacles, start) - 1e-9)
            if not segment_is_free(obstacles, start, goal, keep):
                raise _no_path(start, goal, inflation)
        return [start, goal]


_COST_SCALE = 1e6
"""Grid costs are integers: micrometres (as the Rust planner's)."""

_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def _round(x: float) -> int:
    """Rounds half away from zero (Rust's ``f64::round``)."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


@dataclass
class GridAStar:
    """A* over the cells of a ``cell``-metre grid of the workspace (8-connected, octile costs), every cell
    and step keeping more than the inflation from every obstacle, then shortened by line of sight (from each
    kept point, the farthest later point whose segment is free). A start within the inflation is left by
    steps that strictly gain clearance. The port of the Rust ``GridAStar`` (same grid, costs and rules; among
    paths of equal cost the two may pick different ones)."""

    cell: float = 0.1

    def plan(
        self,
        start: Point,
        goal: Point,
        obstacles: Sequence[Obstacle],
        inflation: float,
        bounds: tuple[Point, Point],
    ) -> list[Point]:
        cell = self.cell
        if not (math.isfinite(cell) and cell > 0.0):
            raise PlanError(f"planner settings: cell = {cell}; must be a finite size > 0")
        lo, hi = bounds
        if not (_inside(bounds, goal) and clearance(obstacles, goal) > inflation):
            raise _goal_blocked(goal, inflation)
        columns = math.ceil((hi[0] - lo[0]) / cell) + 1
        rows = math.ceil((hi[1] - lo[1]) / cell) + 1
        # Every cell centre's clearance at once; inside(centre) holds for all but the last row and column
        # (which may stick out of the workspace by less than a cell).
        xs = lo[0] + np.arange(columns) * cell
        ys = lo[1] + np.arange(rows) * cell
        grid_x, grid_y = np.meshgrid(xs, ys, indexing="ij")
        gaps: Floats = clearances(obstacles, np.stack([grid_x.ravel(), grid_y.ravel()], axis=1)).reshape(
            columns, rows
        )
        inside = (grid_x <= hi[0]) & (grid_y <= hi[1])
        free_cells = inside & (gaps > inflation)
        gap = gaps.tolist()
        free = free_cells.tolist()
        is_inside = inside.tolist()

        def centre(c: tuple[int, int]) -> Point:
            return (lo[0] + c[0] * cell, lo[1] + c[1] * cell)

        def cell_of(p: Point) -> tuple[int, int]:
            return (_round((p[0] - lo[0]) / cell), _round((p[1] - lo[1]) / cell))

        def on_grid(c: tuple[int, int]) -> bool:
            return 0 <= c[0] < columns and 0 <= c[1] < rows

        def gap_at(c: tuple[int, int]) -> float:
            # Only the start's cell may lie off the grid (a planner outside the workspace).
            return float(gap[c[0]][c[1]]) if on_grid(c) else clearance(obstacles, centre(c))

        def free_at(c: tuple[int, int]) -> bool:
            return bool(free[c[0]][c[1]]) if on_grid(c) else False

        start_cell, goal_cell = cell_of(start), cell_of(goal)

        def segment_free(a: tuple[int, int], b: tuple[int, int], keep: float, length: float) -> bool:
            # Exact; skipped when both ends keep more than `keep` + half the step (the distance to an obstacle
            # is 1-Lipschitz: no point of the step comes closer than that).
            if min(gap_at(a), gap_at(b)) > keep + 0.5 * length + 1e-12:
                return True
            return segment_is_free(obstacles, centre(a), centre(b), keep)

        def step_free(a: tuple[int, int], b: tuple[int, int], length: float) -> bool:
            if not on_grid(b):
                return False
            if free_at(a) or a == goal_cell:
                return (free_at(b) or b == goal_cell) and segment_free(a, b, inflation, length)
            here = gap_at(a)
            return bool(is_inside[b[0]][b[1]]) and gap_at(b) > here and segment_free(a, b, here - 1e-9, length)

        def octile(a: tuple[int, int], b: tuple[int, int]) -> int:
            dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
            return int((max(dx, dy) + (math.sqrt(2.0) - 1.0) * min(dx, dy)) * cell * _COST_SCALE)

        # A* as the Rust grid planner runs it: the smallest estimate first, then the largest cost so far.
        costs: dict[tuple[int, int], int] = {start_cell: 0}
        parents: dict[tuple[int, int], tuple[int, int]] = {}
        order = 0
        heap: list[tuple[int, int, int, tuple[int, int]]] = [(octile(start_cell, goal_cell), 0, order, start_cell)]
        found = False
        while heap:
            _, minus_cost, _, a = heapq.heappop(heap)
            if a == goal_cell:
                found = True
                break
            if -minus_cost > costs[a]:
                continue
            for di, dj in _NEIGHBOURS:
                b = (a[0] + di, a[1] + dj)
                step = octile(a, b)
                new_cost = -minus_cost + step
                if new_cost >= costs.get(b, new_cost + 1):
                    continue
                if not step_free(a, b, cell * math.hypot(di, dj)):
                    continue
                costs[b] = new_cost
                parents[b] = a
                order += 1
                heapq.heappush(heap, (new_cost + octile(b, goal_cell), -new_cost, order, b))
        if not found:
            raise _no_path(start, goal, inflation)
        cells = [goal_cell]
        while cells[-1] != start_cell:
            cells.append(parents[cells[-1]])
        points = [centre(c) for c in reversed(cells)]
        points[0] = start
        points[-1] = goal
        return shortcut(points, obstacles, inflation)


def shortcut(points: Sequence[Point], obstacles: Sequence[Obstacle], inflation: float) -> list[Point]:
    """The path shortened by line of sight: from each kept point, the farthest later point whose segment
    keeps the inflation from every obstacle (the next point always qualifies, as the path's segments do)."""
    kept = [points[0]]
    i = 0
    while i + 1 < len(points):
        j = next(
            (
                j
                for j in range(len(points) - 1, i, -1)
                if j == i + 1 or segment_is_free(obstacles, points[i], points[j], inflation)
            ),
            i + 1,
        )
        kept.append(points[j])
        i = j
    return kept


def advance_along(p: Point, path: deque[Point], budget: float) -> Point:
    """Moves a planner at ``p`` along ``path`` (the states ahead of it, consumed from the left as they are
    reached) for one control period at per-axis speed at most ``beta``, where ``budget = beta dt``: a
    segment of direction ``d`` is crossed at speed ``beta / max(|d_x|, |d_y|)``, so neither axis moves more
    than ``budget``. Returns the new state (the last one when the path runs out)."""
    remaining = budget
    while path:
        target = path[0]
        delta = sub(target, p)
        per_axis = max(abs(delta[0]), abs(delta[1]))
        if per_axis <= remaining:
            remaining -= per_axis
            p = target
            path.popleft()
        else:
            t = remaining / per_axis
            return (p[0] + t * delta[0], p[1] + t * delta[1])
    return p


def path_length(points: Sequence[Point]) -> float:
    """The length of a path."""
    return math.fsum(norm(sub(b, a)) for a, b in zip(points, points[1:]))


# --- the loop -----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StepReport:
    """What one step decided."""

    d_obs: float | None
    """Distance from the tracker to the nearest obstacle sensed so far, metres (None: none sensed)."""
    beta_old: float
    """The previous step's ``beta_query`` (``beta_u`` before the first step), m/s."""
    beta_query: float
    """This step's planner speed bound, m/s (``beta_old`` on a hold)."""
    dteb_radius: float
    """``dTEBmax``: the TEB radius at ``beta_query``, the bound the tracking error keeps this step, metres."""
    steb_radius: float
    """The sTEB radius (at ``beta_l``), by which obstacles are inflated, metres."""
    replanned: bool
    """True if the raw path was planned again at this step."""
    branch: Branch
    """adjustPlannerControl's branch."""
    planner: Floats
    """The planner state after the step, ``p_next``, shape [2]."""
    control: Floats
    """The optimal tracking control at ``r_next = s - Q p_next`` under ``beta_query``, shape [n_control]."""
    relative_state: Floats
    """The relative state ``r_next``, shape [n_state]."""
    value: float
    """``V(r_next; beta_query)``."""
    in_teb: bool
    """``r_next`` lies in the certified set of ``beta_query`` (``V <= TebRow.set_level``), from which
    ``dTEBmax`` holds."""
    in_domain: bool
    """``r_next`` lies inside the model's trained domain (False: treat the control as unsupported)."""
    round_trips: int
    """Ticks and calls sent in this step (1 on the common branch)."""
    certificate_age: float
    """Seconds since the relative state last lay in the certified set of the row in force, with that row in
    force since (0 when it lies there now): the certificate from that state covers the step while this is
    below the verification horizon."""


def reset_candidates(position: Point, radius: float, count: int) -> list[Point]:
    """``count`` reset candidates in the disc of radius ``radius`` around ``position``: the position itself
    first, then a sunflower spiral, point ``k`` at distance ``radius sqrt((k - 1/2) / (count - 1))`` and angle
    ``k`` times the golden angle ``pi (3 - sqrt 5)``. The same points as the Rust core's
    ``fastrack_online::core::reset_candidates``, so both loops ask about the same states."""
    golden_angle = math.pi * (3.0 - math.sqrt(5.0))
    rest = float(max(count - 1, 0))
    points = [position] if count > 0 else []
    for k in range(1, count):
        distance, angle = radius * math.sqrt((k - 0.5) / rest), k * golden_angle
        points.append((position[0] + distance * math.cos(angle), position[1] + distance * math.sin(angle)))
    return points


class OnlineLoop:
    """The online loop of one robot (Alg. 3) over one ``Track`` stream of ``model``.

    ``start`` is the planner's initial state ``p_0`` and ``goal`` where it goes (planner coordinates:
    metres for ``dubins4d``); ``bounds`` = ``(min, max)`` the workspace the raw path stays in;
    ``control_period`` the control period ``dt`` in seconds (the planner moves at most ``beta_query dt``
    per axis per step); ``planner`` the raw-path planner (:class:`GridAStar` by default);
    ``reset_candidates`` how many reset candidates a reset asks about before the planner holds (the points of
    :func:`reset_candidates`).
    The model's description (its TEB table, ``Q``) is fetched with ``GetModel`` and its stream opened at
    once; use the loop as a context manager, or call :meth:`close`.
    """

    def __init__(
        self,
        client: Client,
        model: str,
        *,
        start: PointLike,
        goal: PointLike,
        bounds: tuple[PointLike, PointLike],
        control_period: float,
        planner: RawPathPlanner | None = None,
        reset_candidates: int = 256,
        rule: SpeedRule = "half-distance",
        version: int = 0,
        idle_timeout: float = 0.0,
    ) -> None:
        if rule not in ("half-distance", "planner"):
            raise LoopSetupError(f"rule = {rule!r}; must be 'half-distance' or 'planner'")
        if not (isinstance(control_period, (int, float)) and math.isfinite(control_period) and control_period > 0):
            raise LoopSetupError(f"control_period = {control_period}; must be a finite number of seconds > 0")
        if not (isinstance(reset_candidates, int) and reset_candidates >= 1):
            raise LoopSetupError(f"reset_candidates = {reset_candidates}; must be an integer >= 1")
        try:
            low, high = point(bounds[0], "bounds[0] (min)"), point(bounds[1], "bounds[1] (max)")
            self._start, self._goal = point(start, "start"), point(goal, "goal")
        except InvalidArgument as e:
            raise LoopSetupError(e.message) from None
        if not (low[0] < high[0] and low[1] < high[1]):
            raise LoopSetupError(f"bounds: min {low} must lie below and left of max {high}")
        self.client = client
        self.model = model
        self.version = version
        self.control_period = float(control_period)
        self.bounds: tuple[Point, Point] = (low, high)
        self.planner: RawPathPlanner = planner if planner is not None else GridAStar()
        self.reset_candidates = reset_candidates
        self.rule: SpeedRule = rule
        info = client.get_model(model, version)
        if info.planner_dim != 2:
            raise LoopSetupError(
                f"model {info.name}/{info.version} has a {info.planner_dim}-D planner; the online loop plans in "
                "the plane (2-D planners)"
            )
        self._speeds = speed_rows(info)
        self._state_names = tuple(d.name for d in info.state)
        self._n_state = len(info.state)
        self._n_params = len(info.params)
        q = list(info.planner_to_state)
        if len(q) != 2 * self._n_state:
            raise LoopSetupError(
                f"model {info.name}/{info.version}: planner_to_state has {len(q)} entries; expected "
                f"n_state x 2 = {2 * self._n_state}"
            )
        self._q = q
        self._beta_query = self._speeds[-1].beta
        self._certificate_horizon = certificate_horizon(info)
        # The robot starts at rest on the planner.
        self._certificate_age = 0.0
        # How long the drop under way has held (s).
        self._drop_held = 0.0
        self._replan_flag = True
        self._planner_state: Point = self._start
        self._raw_path: deque[Point] = deque()
        self._obstacles: list[Obstacle] = []
        self._stream: TrackStream = client.track(model, version=version, idle_timeout=idle_timeout)

    # -- state ------------------------------------------------------------------------------------------------

    @property
    def planner_state(self) -> Point:
        """The planner's current state ``p``."""
        return self._planner_state

    @property
    def raw_path(self) -> list[Point]:
        """What is left of the raw path after the planner's state."""
        return list(self._raw_path)

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The obstacles sensed so far."""
        return tuple(self._obstacles)

    @property
    def goal(self) -> Point:
        """Where the planner goes."""
        return self._goal

    @property
    def beta_query(self) -> float:
        """The last step's planner speed bound (``beta_u`` before the first step)."""
        return self._beta_query

    @property
    def speeds(self) -> tuple[SpeedRow, ...]:
        """The loop's copy of the model's TEB table, slowest row first."""
        return tuple(self._speeds)

    @property
    def replan_flag(self) -> bool:
        """True if the next step plans the raw path again (at the start, and after a reset)."""
        return self._replan_flag

    def tracker_position(self, tracker_state: npt.ArrayLike) -> Point:
        """The tracker's position in the planner's plane, ``Q^T s``."""
        return self._position(self._tracker(tracker_state))

    def _position(self, s: Sequence[float]) -> Point:
        q = self._q
        return (
            sum(q[2 * i] * s[i] for i in range(self._n_state)),
            sum(q[2 * i + 1] * s[i] for i in range(self._n_state)),
        )

    def _tracker(self, tracker_state: npt.ArrayLike) -> list[float]:
        try:
            s = np.asarray(tracker_state, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise TrackerStateError(f"tracker state must be an array of numbers: {e}") from None
        names = ", ".join(self._state_names)
        if s.ndim != 1 or s.shape[0] != self._n_state:
            got = f"{s.shape[0]} values" if s.ndim == 1 else f"shape {list(s.shape)}"
            raise TrackerStateError(
                f"tracker state has {got}; model {self.model} has {self._n_state} state values ({names})"
            )
        bad = np.flatnonzero(~np.isfinite(s))
        if bad.size:
            i = int(bad[0])
            raise TrackerStateError(f"tracker[{i}] ({self._state_names[i]}) = {s[i]}; must be finite")
        values: list[float] = s.tolist()
        return values

    # -- one step ---------------------------------------------------------------------------------------------

    def step(self, tracker_state: npt.ArrayLike, sensed: Iterable[Obstacle] = ()) -> StepReport:
        """One control step of Alg. 3 for the tracker state ``s`` [n_state] (dubins4d: x m, y m, heading
        rad, speed m/s) and the obstacles sensed now (circles, rectangles, walls of
        :mod:`fastrack.geometry`). Apply ``report.control`` for one control period."""
        tracker = self._tracker(tracker_state)
        sensed = list(sensed)
        for i, obstacle in enumerate(sensed):
            if not isinstance(obstacle, OBSTACLE_KINDS):
                raise InvalidArgument(
                    f"sensed[{i}] is a {type(obstacle).__name__}; obstacles are fastrack.geometry Circle, "
                    "Rectangle or Wall"
                )
        newly_sensed = remember(self._obstacles, sensed)
        try:
            report = self._decide(tracker, newly_sensed)
        except TableMismatch:
            self._speeds = speed_rows(self.client.get_model(self.model, self.version))
            # The new table's sTEB may differ: plan again with it.
            report = self._decide(tracker, True)
        if report.branch != "hold":
            self._drop_held = 0.0
        return report

    def _decide(self, tracker: list[float], newly_sensed: bool) -> StepReport:
        position = self._position(tracker)
        d_obs = clearance(self._obstacles, position) if self._obstacles else None
        beta_old = self._beta_query
        planner_clearance = self._planner_clearance()
        if planner_clearance is None:
            speed = query_planner_control(self._speeds, d_obs)
        else:
            speed = planner_rule(self._speeds, planner_clearance)
        rule_row = speed.row
        if speed.beta < beta_old:
            speed = self._slower_after_patience(speed)
        # Below the rule's row the server's tick would choose the rule's row: ask in batches instead.
        below_rule = speed.row < rule_row
        # The flag stays set until a path is planned: a step that failed to plan plans again next time.
        self._replan_flag = self._replan_flag or newly_sensed
        replanned = self._replan_flag
        if replanned:
            path = self._plan(speed.steb_radius)
            self._raw_path = deque(path[1:])
            self._replan_flag = False
        round_trips = 0
        branch: Branch
        horizon = self._certificate_horizon
        stale = horizon is not None and self._certificate_age >= REANCHOR_SHARE * horizon
        if speed.beta >= beta_old and stale:
            return self._reanchor(tracker, position, d_obs, beta_old, speed, replanned)
        if speed.beta < beta_old:
            index, p_star = self._closest_path_state(position)
            reply: TrackReply | _Answer | None = None
            # A planner kept at p* must keep the smaller bound clear of the sensed obstacles.
            if clearance(self._obstacles, p_star) > speed.dteb_radius:
                round_trips += 1
                if below_rule:
                    reply = self._batch_of_one(tracker, p_star, speed.beta)
                else:
                    reply = self._tick(tracker, p_star, d_obs, planner_clearance, speed.beta)
            if reply is not None and reply.in_teb:
                for _ in range(index):
                    self._raw_path.popleft()
                branch, p_next = "keep", p_star
            else:
                row = SpeedRow(speed.beta, speed.dteb_radius)
                found, calls = self._candidates(tracker, position, row, speed.steb_radius)
                round_trips += calls
                if found is None:
                    return self._hold(tracker, d_obs, beta_old, speed, replanned, round_trips)
                p_next, batch, i = found
                if below_rule:
                    # The batch that found the candidate answers for it.
                    reply = _Answer.of_batch(batch, i, self._relative_state(tracker, p_next))
                else:
                    round_trips += 1
                    reply = self._tick(tracker, p_next, d_obs, planner_clearance, speed.beta)
                self._raw_path.clear()
                self._replan_flag = True
                branch = "reset"
        else:
            # The path is consumed only once the server has answered: a step taken again (the table changed)
            # starts from the same planner state and path.
            ahead = deque(self._raw_path)
            p_next = advance_along(self._planner_state, ahead, speed.beta * self.control_period)
            if clearance(self._obstacles, p_next) <= speed.dteb_radius:
                # One period along the path would bring the planner within the bound of a sensed obstacle: on
                # a rise it moves at beta_old instead, otherwise it waits where it is.
                if speed.beta > beta_old:
                    return self._steady(tracker, d_obs, beta_old, speed, replanned, 0)
                return self._hold(tracker, d_obs, beta_old, speed, replanned, 0)
            if speed.beta > beta_old and not self._path_allows(speed):
                # The path ahead would take the faster row away again within its bound: a rise refused, the
                # planner moves at beta_old.
                return self._steady(tracker, d_obs, beta_old, speed, replanned, 0)
            round_trips += 1
            reply = self._tick(tracker, p_next, d_obs, planner_clearance, speed.beta)
            if speed.beta > beta_old and not reply.in_teb:
                return self._steady(tracker, d_obs, beta_old, speed, replanned, round_trips)
            self._raw_path = ahead
            branch = "advance"
        self._beta_query = speed.beta
        self._planner_state = p_next
        return StepReport(
            d_obs=d_obs,
            beta_old=beta_old,
            beta_query=speed.beta,
            dteb_radius=speed.dteb_radius,
            steb_radius=speed.steb_radius,
            replanned=replanned,
            branch=branch,
            planner=np.array(p_next, dtype=np.float64),
            control=reply.control,
            relative_state=reply.relative_state,
            value=reply.value,
            in_teb=reply.in_teb,
            in_domain=reply.in_domain,
            round_trips=round_trips,
            certificate_age=self._age(reply.in_teb),
        )

    def _slower_after_patience(self, speed: PlannerSpeed) -> PlannerSpeed:
        """The drop's row: the rule's own, or, once the drop has held for :data:`DROP_PATIENCE`, one row slower
        for each further step it has held (down to ``beta_l``)."""
        past = self._drop_held - DROP_PATIENCE
        if past < -1e-9:
            return speed
        row = max(speed.row - 1 - math.floor(past / self.control_period + 1e-9), 0)
        chosen = self._speeds[row]
        return replace(speed, beta=chosen.beta, row=row, dteb_radius=chosen.bound)

    def _age(self, in_teb: bool) -> float:
        """The certificate's age after a step whose relative state lies in the set of the row now in force
        (``in_teb``) or not: every branch that changes the row puts it in the new row's set."""
        self._certificate_age = 0.0 if in_teb else self._certificate_age + self.control_period
        return self._certificate_age

    def _steady(
        self,
        tracker: list[float],
        d_obs: float | None,
        beta_old: float,
        speed: PlannerSpeed,
        replanned: bool,
        round_trips: int,
    ) -> StepReport:
        """A refused rise (the faster row's certified set does not hold the new relative state, or the planner
        would not keep its bound clear of the sensed obstacles): the planner moves along the raw path at
        ``beta_old`` and ``u*`` is read under its row, whose certificate still runs; or it waits where it is
        (a hold) if that would bring it within the row's bound of a sensed obstacle."""
        index = row_for(self._speeds, beta_old)
        if index is None:
            raise TableMismatch(local=beta_old, server=self._speeds[-1].beta)
        row = self._speeds[index]
        ahead = deque(self._raw_path)
        p_next = advance_along(self._planner_state, ahead, row.beta * self.control_period)
        if clearance(self._obstacles, p_next) <= row.bound:
            return self._hold(tracker, d_obs, beta_old, speed, replanned, round_trips)
        r = self._relative_state(tracker, p_next)
        params = np.full((1, self._n_params), row.beta)
        answer = self.client.tracking_control(self.model, [r], params, out_of_domain="flag", version=self.version)
        self._raw_path = ahead
        self._beta_query = row.beta
        self._planner_state = p_next
        in_teb = bool(answer.in_teb[0])
        return StepReport(
            d_obs=d_obs,
            beta_old=beta_old,
            beta_query=row.beta,
            dteb_radius=row.bound,
            steb_radius=speed.steb_radius,
            replanned=replanned,
            branch="steady",
            planner=np.array(p_next, dtype=np.float64),
            control=answer.controls[0],
            relative_state=np.array(r, dtype=np.float64),
            value=float(answer.values[0]),
            in_teb=in_teb,
            in_domain=bool(answer.in_domain[0]),
            round_trips=round_trips + 1,
            certificate_age=self._age(in_teb),
        )

    def _plan(self, inflation: float) -> list[Point]:
        """The raw path from the planner's state to the goal, checked: at least one point, each finite."""
        try:
            path = self.planner.plan(self._planner_state, self._goal, tuple(self._obstacles), inflation, self.bounds)
        except FastrackError:
            raise
        except Exception as e:  # noqa: BLE001 - a user's planner may fail in any way; say which
            raise PlanError(f"the raw-path planner {type(self.planner).__name__} failed: {e!r}") from e
        try:
            points = [point(p, f"raw path point {k}") for k, p in enumerate(path)]
        except InvalidArgument as e:
            name = type(self.planner).__name__
            raise PlanError(f"the raw-path planner {name} returned a bad path: {e.message}") from None
        if not points:
            raise PlanError(f"the raw-path planner {type(self.planner).__name__} returned an empty path")
        return points

    def _closest_path_state(self, position: Point) -> tuple[int, Point]:
        """``p*``: the state of the planner and the raw path closest to the tracker, with the number of
        raw-path states up to it (0: the planner's own state)."""
        best, best_distance = (0, self._planner_state), norm(sub(self._planner_state, position))
        for k, p in enumerate(self._raw_path, start=1):
            distance = norm(sub(p, position))
            if distance < best_distance:
                best, best_distance = (k, p), distance
        return best

    def _candidates(
        self, tracker: list[float], position: Point, row: SpeedRow, steb_radius: float
    ) -> tuple[tuple[Point, TrackingControl, int] | None, int]:
        """The first free reset candidate (inside the workspace, farther than the sTEB and the row's bound from
        every sensed obstacle) with ``s - Q p`` in the certified set of ``row`` and the trained domain, with the
        batch's answer and its index there: the tracker's own position first, then points of
        :func:`reset_candidates` in the disc of the row's radius around it, the free ones asked about in one
        ``TrackingControl`` batch. Also returns the calls made."""
        candidates = reset_candidates(position, row.bound, self.reset_candidates)
        keep = max(steb_radius, row.bound)
        free = [p for p in candidates if _inside(self.bounds, p) and clearance(self._obstacles, p) > keep]
        if not free:
            return None, 0
        states = np.array([self._relative_state(tracker, p) for p in free])
        params = np.full((len(free), self._n_params), row.beta)
        answer = self.client.tracking_control(self.model, states, params, out_of_domain="flag", version=self.version)
        # Inside the bound and the trained domain: a membership read off an extrapolated value is no reset.
        for i, (p, teb, domain) in enumerate(zip(free, answer.in_teb, answer.in_domain)):
            if teb and domain:
                return (p, answer, i), 1
        return None, 1

    def _reanchor(
        self,
        tracker: list[float],
        position: Point,
        d_obs: float | None,
        beta_old: float,
        speed: PlannerSpeed,
        replanned: bool,
    ) -> StepReport:
        """The relative state has stayed outside the certified set of the row in force for half the
        verification horizon: the planner moves back into that row's set (a reset under the same row,
        answered by the batch that found it), or holds if no free point is in it. A rise waits for the next
        step."""
        index = row_for(self._speeds, beta_old)
        if index is None:
            raise TableMismatch(local=beta_old, server=self._speeds[-1].beta)
        row = self._speeds[index]
        found, calls = self._candidates(tracker, position, row, speed.steb_radius)
        if found is None:
            return self._hold(tracker, d_obs, beta_old, speed, replanned, calls)
        candidate, answer, i = found
        self._raw_path.clear()
        self._replan_flag = True
        self._beta_query = row.beta
        self._planner_state = candidate
        return StepReport(
            d_obs=d_obs,
            beta_old=beta_old,
            beta_query=row.beta,
            dteb_radius=row.bound,
            steb_radius=speed.steb_radius,
            replanned=replanned,
            branch="reset",
            planner=np.array(candidate, dtype=np.float64),
            control=answer.controls[i],
            relative_state=np.array(self._relative_state(tracker, candidate), dtype=np.float64),
            value=float(answer.values[i]),
            in_teb=True,
            in_domain=True,
            round_trips=calls,
            certificate_age=self._age(True),
        )

    def _hold(
        self,
        tracker: list[float],
        d_obs: float | None,
        beta_old: float,
        speed: PlannerSpeed,
        replanned: bool,
        round_trips: int,
    ) -> StepReport:
        """The hold branch: the planner waits at its state, and ``u*`` is read under ``beta_old`` (the row
        answering for it in the current table), whose bound stays in force. A drop's hold adds to how long the
        drop has held."""
        index = row_for(self._speeds, beta_old)
        if index is None:
            raise TableMismatch(local=beta_old, server=self._speeds[-1].beta)
        row = self._speeds[index]
        self._drop_held = self._drop_held + self.control_period if speed.beta < beta_old else 0.0
        r = self._relative_state(tracker, self._planner_state)
        params = np.full((1, self._n_params), row.beta)
        answer = self.client.tracking_control(self.model, [r], params, out_of_domain="flag", version=self.version)
        self._beta_query = row.beta
        in_teb = bool(answer.in_teb[0])
        return StepReport(
            d_obs=d_obs,
            beta_old=beta_old,
            beta_query=row.beta,
            dteb_radius=row.bound,
            steb_radius=speed.steb_radius,
            replanned=replanned,
            branch="hold",
            planner=np.array(self._planner_state, dtype=np.float64),
            control=answer.controls[0],
            relative_state=np.array(r, dtype=np.float64),
            value=float(answer.values[0]),
            in_teb=in_teb,
            in_domain=bool(answer.in_domain[0]),
            round_trips=round_trips + 1,
            certificate_age=self._age(in_teb),
        )

    def _relative_state(self, tracker: list[float], p: Point) -> list[float]:
        """``r = s - Q p``."""
        q = self._q
        return [tracker[i] - q[2 * i] * p[0] - q[2 * i + 1] * p[1] for i in range(self._n_state)]

    def _planner_clearance(self) -> float | None:
        """The planner rule's clearance: the planner's distance to the nearest sensed obstacle less the farthest
        one control period can move it (None: the paper's rule, or nothing sensed)."""
        if self.rule != "planner" or not self._obstacles:
            return None
        return max(clearance(self._obstacles, self._planner_state) - self._reach(), 0.0)

    def _reach(self) -> float:
        """The farthest one control period can move the planner: ``beta_u dt`` on each axis."""
        return math.sqrt(2.0) * self._speeds[-1].beta * self.control_period

    def _path_allows(self, speed: PlannerSpeed) -> bool:
        """Whether a rise to ``speed`` may be taken as far as the path ahead goes: under the planner rule, the raw
        path within that row's bound ahead of the planner must keep the bound clear by one period's reach, as
        the rule asks of the planner's own state; under the paper's rule, always."""
        return self.rule != "planner" or self._path_clearance(speed.dteb_radius) - self._reach() > speed.dteb_radius

    def _path_clearance(self, ahead: float) -> float:
        """The least clearance of the planner's state and its raw path within ``ahead`` metres along it."""
        least = clearance(self._obstacles, self._planner_state)
        start, left = self._planner_state, ahead
        for to in self._raw_path:
            if left <= 0.0:
                break
            length = norm(sub(to, start))
            t = min(left / length, 1.0) if length > 0.0 else 1.0
            end = (start[0] + t * (to[0] - start[0]), start[1] + t * (to[1] - start[1]))
            least = min([least, *(o.segment_distance(start, end) for o in self._obstacles)])
            start, left = to, left - length
        return least

    def _batch_of_one(self, tracker: list[float], p: Point, beta: float) -> _Answer:
        """The model's answer for planner state ``p`` under ``beta``, in a ``TrackingControl`` batch of one."""
        r = self._relative_state(tracker, p)
        params = np.full((1, self._n_params), beta)
        answer = self.client.tracking_control(self.model, [r], params, out_of_domain="flag", version=self.version)
        return _Answer.of_batch(answer, 0, r)

    def _tick(
        self, tracker: list[float], p: Point, d_obs: float | None, planner_clearance: float | None, beta: float
    ) -> TrackReply:
        """One tick with planner state ``p``; checks the server's ``beta_query`` against ``beta``."""
        reply = self._stream.tick(tracker, p, d_obs, planner_clearance=planner_clearance)
        if reply.beta_query != beta:
            raise TableMismatch(local=beta, server=reply.beta_query)
        return reply

    # -- lifetime ---------------------------------------------------------------------------------------------

    def close(self, cancel: bool = False) -> None:
        """Ends the loop's ``Track`` stream."""
        self._stream.close(cancel=cancel)

    def __enter__(self) -> OnlineLoop:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.close(cancel=error is not None)


__all__ = [
    "DROP_PATIENCE",
    "Branch",
    "GoalBlocked",
    "GridAStar",
    "LoopSetupError",
    "NoPath",
    "OnlineLoop",
    "OnlineLoopError",
    "PlanError",
    "PlannerSpeed",
    "RawPathPlanner",
    "SpeedRow",
    "StepReport",
    "StraightLine",
    "TableMismatch",
    "TrackerStateError",
    "advance_along",
    "path_length",
    "query_planner_control",
    "row_for",
    "shortcut",
    "speed_rows",
]
