"""A dubins4d robot tracking a planner with the served optimal control, one ``Track`` tick per 0.01 s step.

The planner is a point moving at the served planner speed bound ``beta_query`` (m/s) along a gentle curve
(its direction turns at ``--turn-rate`` rad/s; 0 gives a straight line). The tracker is the dubins4d car:
state (x m, y m, heading theta rad, speed v m/s), heading measured from the +y axis towards +x:

    x' = v sin(theta),  y' = v cos(theta),  theta' = omega,  v' = alpha

with the served control u* = (omega rad/s, alpha m/s^2), held for one control period and integrated with
RK4. Every step checks that the tracking error |(x, y) - planner| stays within the served TEB radius
(``dteb_radius``); the script exits 1 if it does not, 2 if the server refuses.

    python examples/track_numpy.py --server 127.0.0.1:50051 --steps 1000
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import numpy.typing as npt

import fastrack

Vector = npt.NDArray[np.float64]


def dubins4d(state: Vector, control: Vector) -> Vector:
    """Time derivative of the tracker state (x, y, theta, v) under control (omega, alpha)."""
    _, _, theta, v = state
    omega, alpha = control
    return np.array([v * np.sin(theta), v * np.cos(theta), omega, alpha])


def rk4(state: Vector, control: Vector, dt: float) -> Vector:
    """One RK4 step of ``dt`` seconds with the control held constant."""
    k1 = dubins4d(state, control)
    k2 = dubins4d(state + 0.5 * dt * k1, control)
    k3 = dubins4d(state + 0.5 * dt * k2, control)
    k4 = dubins4d(state + dt * k3, control)
    result: Vector = state + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return result


def planner_velocity(t: float, beta: float, turn_rate: float) -> Vector:
    """Planner velocity (m/s) at time ``t``: speed ``beta`` along a direction that turns at ``turn_rate``.
    Each axis stays within ``beta``, the planner's per-axis speed bound."""
    direction = turn_rate * t
    return beta * np.array([np.sin(direction), np.cos(direction)])


def run(server: str, model: str, steps: int, dt: float, turn_rate: float, token: str | None) -> int:
    tracker = np.array([0.0, 0.0, 0.0, 1.0])  # at the planner, heading +y, 1 m/s
    planner = np.zeros(2)
    worst = (0.0, 0.0)  # largest error (m) and the bound (m) at that step
    with fastrack.Client(server, token=token) as client:
        client.wait_until_serving(timeout=30.0)
        started = time.perf_counter()
        with client.track(model) as robot:
            for step in range(steps):
                reply = robot.tick(tracker, planner)
                error = float(np.hypot(reply.relative_state[0], reply.relative_state[1]))
                if error > worst[0]:
                    worst = (error, reply.dteb_radius)
                if error > reply.dteb_radius:
                    print(
                        f"step {step}: tracking error {error:.3f} m exceeds the served bound "
                        f"{reply.dteb_radius:.3f} m (beta {reply.beta_query} m/s)",
                        file=sys.stderr,
                    )
                    return 1
                tracker = rk4(tracker, reply.control, dt)
                planner = planner + dt * planner_velocity(step * dt, reply.beta_query, turn_rate)
        elapsed = time.perf_counter() - started
    print(
        f"{steps} steps ({steps * dt:.2f} s simulated) in {elapsed:.2f} s ({steps / elapsed:.0f} ticks/s): "
        f"largest tracking error {worst[0]:.3f} m, within the served bound {worst[1]:.3f} m"
    )
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="server address (host:port)")
    parser.add_argument("--model", default="dubins4d", help="model name")
    parser.add_argument("--steps", type=int, default=1000, help="control steps")
    parser.add_argument("--dt", type=float, default=0.01, help="control period, seconds")
    parser.add_argument("--turn-rate", type=float, default=0.2, help="turn rate of the planner's path, rad/s")
    parser.add_argument("--token", default=None, help="bearer token, if the server needs one")
    args = parser.parse_args()
    if args.steps < 1 or not args.dt > 0:
        parser.error("--steps must be at least 1 and --dt positive")
    try:
        return run(args.server, args.model, args.steps, args.dt, args.turn_rate, args.token)
    except fastrack.FastrackError as e:
        print(f"fastrack: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
