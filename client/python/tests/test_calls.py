"""Every unary call against the real server; values compared with the Rust CLI (``fastrack --json``) on the
same inputs."""

from __future__ import annotations

import json
import subprocess
from typing import Any

import numpy as np
import pytest

import fastrack
from conftest import MODEL, VERSION, Server, binary

STATES = np.array(
    [
        [0.2, -0.1, 0.3, 1.0],
        [-0.5, 0.4, -2.0, 0.5],
        [1.1, 0.9, 3.0, 2.5],
        [0.0, 0.0, 0.0, 1.2],
    ]
)


def rust_cli(server: Server, *args: str) -> Any:
    """Runs ``fastrack --json`` against ``server``; its parsed output."""
    command = [str(binary("fastrack")), "--server", f"http://{server.address}", "--json", *args]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, f"{command} failed:\n{done.stderr}"
    return json.loads(done.stdout)


def state_args(states: np.ndarray) -> list[str]:
    return [f"--state={','.join(repr(float(x)) for x in row)}" for row in states]


def test_health_and_wait_until_serving(client: fastrack.Client) -> None:
    assert client.health() == "SERVING"
    assert client.health("fastrack.v1.SafetyService") == "SERVING"
    client.wait_until_serving(timeout=1.0)


def test_list_models(client: fastrack.Client) -> None:
    models = {(m.name, m.version): m for m in client.list_models()}
    assert ("dubins4d", VERSION) in models and ("untrained-dubins4d", 1) in models
    assert models[("dubins4d", VERSION)].is_default_version
    assert not models[("dubins4d", VERSION)].untrained and models[("untrained-dubins4d", 1)].untrained


def test_get_model_describes_dimensions_and_units(client: fastrack.Client) -> None:
    info = client.get_model(MODEL)
    assert info.version == VERSION and info.system == "dubins4d"
    assert [(d.name, d.unit) for d in info.state] == [("x_r", "m"), ("y_r", "m"), ("theta", "rad"), ("v", "m/s")]
    assert [c.name for c in info.controls] == ["omega", "alpha"]
    assert info.planner_dim == 2 and len(info.teb_table) >= 16
    dims = client.dims(MODEL)
    assert (len(dims.state), len(dims.params), len(dims.controls)) == (4, len(info.params), 2)


def test_query_planner_control_matches_the_rust_cli(client: fastrack.Client, server: Server) -> None:
    for d_obs in (2.5, 0.8, 10.0):
        answer = client.query_planner_control(MODEL, d_obs=d_obs)
        rust = rust_cli(server, "query", MODEL, "--d-obs", str(d_obs))
        assert answer.beta_query == rust["beta_query"]
        assert answer.dteb_radius == rust["dteb_radius"] and answer.steb_radius == rust["steb_radius"]
        assert answer.steb_exceeds_half_distance == rust["steb_exceeds_half_distance"]
        assert answer.model_version == VERSION
    # The documented answers of the shipped table.
    assert client.query_planner_control(MODEL, d_obs=2.5).beta_query == pytest.approx(0.75)
    slow = client.query_planner_control(MODEL, d_obs=0.8)
    assert slow.beta_query == pytest.approx(0.5) and slow.steb_exceeds_half_distance
    assert client.query_planner_control(MODEL).beta_query == pytest.approx(1.25)


def test_tracking_error_bound_matches_the_rust_cli(client: fastrack.Client, server: Server) -> None:
    teb = client.tracking_error_bound(MODEL, beta=0.91, boundary_points=16)
    rust = rust_cli(server, "teb", MODEL, "--beta", "0.91", "--boundary", "16")
    assert teb.level == rust["level"] and teb.radius == rust["radius"] and teb.table_beta == rust["table_beta"]
    np.testing.assert_array_equal(teb.extent, rust["extent"])
    assert teb.boundary.shape == (16, 2)
    np.testing.assert_array_equal(teb.boundary.ravel(), rust["boundary"])
    # The row's two numbers as GetModel serves them: the certified set's level and the bound from inside it,
    # never below the level (inside the set |e| <= V <= level already).
    row = next(r for r in client.get_model(MODEL).teb_table if r.beta >= 0.91)
    assert teb.table_beta == row.beta and (teb.level, teb.radius) == (row.set_level, row.bound)
    assert teb.radius >= teb.level
    # Counter-clockwise points on a set around the origin, inside the radius.
    assert np.all(np.hypot(teb.boundary[:, 0], teb.boundary[:, 1]) <= teb.radius + 1e-9)


def test_evaluate_matches_the_rust_cli(client: fastrack.Client, server: Server) -> None:
    result = client.evaluate(MODEL, STATES, 1.0, out_of_domain="reject")
    rust = rust_cli(server, "evaluate", MODEL, *state_args(STATES), "--beta", "1.0")
    n = len(STATES)
    assert result.values.shape == (n,) and result.gradients.shape == (n, 4) and result.controls.shape == (n, 2)
    np.testing.assert_allclose(result.values, rust["values"], rtol=1e-9, atol=0)
    np.testing.assert_allclose(result.gradients.ravel(), rust["gradients"], rtol=1e-9, atol=0)
    np.testing.assert_allclose(result.controls.ravel(), rust["controls"], rtol=1e-9, atol=0)
    assert result.in_teb.tolist() == rust["in_teb"] and result.in_domain.tolist() == rust["in_domain"]
    assert result.model_version == rust["model_version"] == VERSION
    # V never lies below the tracking error |e| by more than the shipped model's documented dip.
    assert np.all(result.values >= np.hypot(STATES[:, 0], STATES[:, 1]) - 0.02)


def test_tracking_control_matches_the_rust_cli_and_evaluate(client: fastrack.Client, server: Server) -> None:
    result = client.tracking_control(MODEL, STATES, [0.75], out_of_domain="reject")
    rust = rust_cli(server, "control", MODEL, *state_args(STATES), "--params", "0.75")
    np.testing.assert_allclose(result.controls.ravel(), rust["controls"], rtol=1e-9, atol=0)
    np.testing.assert_allclose(result.values, rust["values"], rtol=1e-9, atol=0)
    assert result.in_teb.tolist() == rust["in_teb"] and result.in_domain.tolist() == rust["in_domain"]
    # One beta per item: the same controls as EvaluateValue's.
    params = np.array([[0.5], [0.75], [1.0], [1.25]])
    result = client.tracking_control(MODEL, STATES, params)
    full = client.evaluate(MODEL, STATES, params)
    np.testing.assert_allclose(full.controls, result.controls, rtol=1e-9, atol=0)
    # Bang-bang controls on the box omega in [-5, 5] rad/s, alpha in [-1, 1] m/s^2 (alpha cut to 0 at limits).
    assert np.all(np.abs(result.controls[:, 0]) <= 5.0) and np.all(np.abs(result.controls[:, 1]) <= 1.0)


def test_out_of_domain_items_are_flagged_in_batches(client: fastrack.Client) -> None:
    states = np.array([[0.2, -0.1, 0.3, 1.0], [3.5, 0.0, 0.0, 1.0]])
    result = client.evaluate(MODEL, states, [1.0])
    assert result.in_domain.tolist() == [True, False]
    single = client.tracking_control(MODEL, states[1:], 1.0, out_of_domain="flag")
    assert single.in_domain.tolist() == [False]


def test_a_batch_of_64_and_a_version_pin(client: fastrack.Client) -> None:
    rng = np.random.default_rng(3)
    states = np.column_stack(
        [rng.uniform(-1, 1, 64), rng.uniform(-1, 1, 64), rng.uniform(-3, 3, 64), rng.uniform(0.5, 2.5, 64)]
    )
    result = client.tracking_control(MODEL, states, rng.uniform(0.5, 1.25, (64, 1)), version=VERSION)
    assert result.controls.shape == (64, 2) and result.model_version == VERSION
    assert result.in_domain.all()
