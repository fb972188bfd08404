"""A dubins4d robot driven by the online loop (Parametric FaSTrack, Alg. 3) through a small world.

The loop (``fastrack.online.OnlineLoop``) runs one ``Track`` tick per control step: it senses (here: every
obstacle within ``--sensor-range`` of the tracker, by default twice the TEB radius at the fastest speed,
the paper's assumption), picks the planner speed ``beta_query`` from the distance to the nearest obstacle,
plans a raw path around the obstacles inflated by the sTEB (A* on a 0.1 m grid, or the straight line),
moves the planner along it, and answers the optimal tracking control. The tracker is the dubins4d car,
state (x m, y m, heading rad from +y towards +x, speed m/s):

    x' = v sin(theta),  y' = v cos(theta),  theta' = omega,  v' = alpha

integrated with RK4 sub-steps, the control held for the control period. Every sub-step checks that the
robot keeps off the true obstacles and that its tracking error |(x, y) - planner| stays within the step's
bound ``dteb_radius``. Exit status: 0 when the goal is reached safely, 1 on a collision, an exceeded bound
or no arrival in time, 2 when the server or the loop refuses.

    python examples/online_loop.py --server 127.0.0.1:50051
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import fastrack
from fastrack.geometry import Circle, Obstacle, Point, Rectangle, Wall, clearance
from fastrack.online import GridAStar, OnlineLoop, RawPathPlanner, SpeedRule, StraightLine


@dataclass(frozen=True)
class World:
    """Where the robot drives: the workspace, its start (heading and speed) and goal, the true obstacles."""

    bounds: tuple[Point, Point]
    start: Point
    goal: Point
    obstacles: tuple[Obstacle, ...]
    start_heading: float = math.pi / 2  # along +x
    start_speed: float = 0.5
    goal_radius: float = 1.0


DEFAULT_WORLD = World(
    bounds=((0.0, 0.0), (16.0, 10.0)),
    start=(1.0, 5.0),
    goal=(15.0, 5.0),
    obstacles=(
        Circle((5.0, 5.3), 0.8),
        Rectangle((8.5, 1.0), (9.5, 3.6)),
        Wall((11.5, 6.3), (11.5, 9.5), 0.2),
    ),
)


@dataclass
class Outcome:
    """How a run went."""

    reached: bool = False
    time: float = 0.0
    """Simulated seconds until the goal (or the end of the run)."""
    steps: int = 0
    round_trips: int = 0
    replans: int = 0
    branches: dict[str, int] = field(default_factory=dict)
    min_clearance: float = math.inf
    """Smallest distance from the robot to a true obstacle over every sub-step, m."""
    worst_excess: float = -math.inf
    """Largest tracking error minus the step's bound over every sub-step, m (safe: <= 0)."""
    out_of_domain: int = 0
    failure: str | None = None

    @property
    def safe(self) -> bool:
        return self.min_clearance > 0.0 and self.worst_excess <= 1e-9


def dubins4d(s: Sequence[float], u: Sequence[float]) -> tuple[float, float, float, float]:
    """Time derivative of the tracker state (x, y, theta, v) under the control (omega, alpha)."""
    return (s[3] * math.sin(s[2]), s[3] * math.cos(s[2]), u[0], u[1])


def rk4(s: Sequence[float], u: Sequence[float], h: float) -> list[float]:
    """One RK4 step of ``h`` seconds with the control held."""
    k1 = dubins4d(s, u)
    k2 = dubins4d([a + 0.5 * h * b for a, b in zip(s, k1)], u)
    k3 = dubins4d([a + 0.5 * h * b for a, b in zip(s, k2)], u)
    k4 = dubins4d([a + h * b for a, b in zip(s, k3)], u)
    return [a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]


def simulate(
    client: fastrack.Client,
    world: World,
    *,
    model: str = "dubins4d",
    planner: RawPathPlanner | None = None,
    control_period: float = 0.01,
    substeps: int = 4,
    time_limit: float = 60.0,
    sensor_range: float | None = None,
    rule: SpeedRule = "half-distance",
) -> Outcome:
    """Drives the robot through ``world`` until it is within ``goal_radius`` of the goal, leaves the safe
    set, or ``time_limit`` simulated seconds pass."""
    s = [world.start[0], world.start[1], world.start_heading, world.start_speed]
    outcome = Outcome()
    with OnlineLoop(
        client,
        model,
        start=world.start,
        goal=world.goal,
        bounds=world.bounds,
        control_period=control_period,
        planner=planner,
        rule=rule,
    ) as loop:
        sensing = sensor_range if sensor_range is not None else 2.0 * loop.speeds[-1].bound
        for k in range(math.ceil(time_limit / control_period)):
            position = (s[0], s[1])
            outcome.time = k * control_period
            if math.dist(position, world.goal) <= world.goal_radius:
                outcome.reached = True
                break
            sensed = [o for o in world.obstacles if o.distance(position) <= sensing]
            step = loop.step(s, sensed)
            outcome.steps += 1
            outcome.round_trips += step.round_trips
            outcome.replans += step.replanned
            outcome.branches[step.branch] = outcome.branches.get(step.branch, 0) + 1
            outcome.out_of_domain += not step.in_domain
            planner_state = (float(step.planner[0]), float(step.planner[1]))
            control = step.control.tolist()
            for _ in range(substeps):
                s = rk4(s, control, control_period / substeps)
                outcome.min_clearance = min(outcome.min_clearance, clearance(world.obstacles, (s[0], s[1])))
                error = math.dist((s[0], s[1]), planner_state)
                outcome.worst_excess = max(outcome.worst_excess, error - step.dteb_radius)
            outcome.time = (k + 1) * control_period
            if not outcome.safe:
                outcome.failure = "collision" if outcome.min_clearance <= 0.0 else "tracking bound exceeded"
                break
    if not outcome.reached and outcome.failure is None:
        outcome.failure = f"the goal was not reached within {time_limit} s"
    return outcome


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="server address (host:port)")
    parser.add_argument("--model", default="dubins4d", help="model name")
    parser.add_argument("--planner", choices=["astar", "straight"], default="astar", help="raw-path planner")
    parser.add_argument("--dt", type=float, default=0.01, help="control period, seconds")
    parser.add_argument("--time-limit", type=float, default=60.0, help="simulated seconds before giving up")
    parser.add_argument("--sensor-range", type=float, default=None, help="m (default: 2 x the dTEB at beta_u)")
    parser.add_argument("--token", default=None, help="bearer token, if the server needs one")
    parser.add_argument(
        "--rule", choices=["half-distance", "planner"], default="half-distance", help="what picks beta_query"
    )
    args = parser.parse_args()
    planner: RawPathPlanner = GridAStar() if args.planner == "astar" else StraightLine()
    try:
        with fastrack.Client(args.server, token=args.token) as client:
            client.wait_until_serving(timeout=30.0)
            started = time.perf_counter()
            outcome = simulate(
                client,
                DEFAULT_WORLD,
                model=args.model,
                planner=planner,
                control_period=args.dt,
                time_limit=args.time_limit,
                sensor_range=args.sensor_range,
                rule=args.rule,
            )
            elapsed = time.perf_counter() - started
    except fastrack.FastrackError as e:
        print(f"fastrack: {e}", file=sys.stderr)
        return 2
    print(
        f"{'reached the goal' if outcome.reached else 'stopped'} after {outcome.time:.2f} s simulated "
        f"({outcome.steps} steps in {elapsed:.2f} s, {outcome.round_trips / max(outcome.steps, 1):.3f} round trips "
        f"per step, branches {outcome.branches}, {outcome.replans} replans); closest approach to an obstacle "
        f"{outcome.min_clearance:.3f} m; largest tracking error minus its bound {outcome.worst_excess:+.3f} m"
    )
    if outcome.failure is not None:
        print(f"failed: {outcome.failure}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
