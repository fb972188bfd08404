"""hj_reachability reference for `fastrack-grid bench`: the same dubins4d relative system, grid and scheme
(WENO5 + third-order TVD RK, CFL 0.75, V <- max(V, l)), timed over a fixed number of time steps.

Usage: python hj_bench.py <nodes per axis> <steps> <beta> <half width x,y> <v max>
Prints one JSON line: {"points", "steps", "wall_s", "point_updates_per_s", "jax", "hj_reachability", "devices"}.
"""
import json
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import hj_reachability as hj


class Dubins4dRelative(hj.ControlAndDisturbanceAffineDynamics):
    """x' = v sin(theta) - u_px, y' = v cos(theta) - u_py, theta' = omega, v' = alpha."""

    def __init__(self, beta):
        super().__init__(
            "min", "max",
            hj.sets.Box(jnp.array([-5.0, -1.0]), jnp.array([5.0, 1.0])),
            hj.sets.Box(jnp.array([-beta, -beta]), jnp.array([beta, beta])))

    def open_loop_dynamics(self, state, time):
        _, _, theta, v = state
        return jnp.array([v * jnp.sin(theta), v * jnp.cos(theta), 0.0, 0.0])

    def control_jacobian(self, state, time):
        return jnp.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])

    def disturbance_jacobian(self, state, time):
        return jnp.array([[-1.0, 0.0], [0.0, -1.0], [0.0, 0.0], [0.0, 0.0]])


def main():
    n, steps, beta, half, v_max = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
    jax.config.update("jax_enable_x64", True)
    domain = hj.sets.Box(np.array([-half, -half, -np.pi, 0.0]), np.array([half, half, np.pi, v_max]))
    grid = hj.Grid.from_lattice_parameters_and_boundary_conditions(domain, (n, n, n, n), periodic_dims=2)
    l = jnp.linalg.norm(grid.states[..., :2], axis=-1)
    dynamics = Dubins4dRelative(beta)
    settings = hj.SolverSettings.with_accuracy("very_high", value_postprocessor=hj.solver.static_obstacle(l))
    # The step hj_reachability takes: CFL / max(sum_i alpha_i / h_i), alpha from the global bounds.
    alpha = np.array([v_max + beta, v_max + beta, 5.0, 1.0])
    dt = 0.75 / float(np.sum(alpha / np.array([float(s) for s in grid.spacings])))
    values = l
    # Warm-up (compilation) on one step, then the timed run.
    hj.step(settings, dynamics, grid, 0.0, values, -dt, progress_bar=False).block_until_ready()
    start = time.perf_counter()
    out = hj.step(settings, dynamics, grid, 0.0, values, -steps * dt * (1 - 1e-9), progress_bar=False)
    out.block_until_ready()
    wall = time.perf_counter() - start
    points = n ** 4
    print(json.dumps({
        "points": points, "steps": steps, "wall_s": wall, "point_updates_per_s": points * steps / wall,
        "jax": jax.__version__, "hj_reachability": getattr(hj, "__version__", "unknown"),
        "devices": [str(d) for d in jax.devices()], "v_min": float(jnp.min(out)),
    }))


if __name__ == "__main__":
    main()
