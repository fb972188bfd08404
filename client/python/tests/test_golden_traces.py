"""The Python online loop held to the Rust core by golden traces.

``fastrack sim bench --methods pf --traces DIR`` runs the Rust loop (the simulator's Parametric FaSTrack)
through 20 seeded worlds against the test server and writes, per world, what the loop was given and what it
decided at every control period. Here the Python loop is given the same (its start, goal and workspace, then
each period's tracker state and newly sensed obstacles) against the same server, and must decide the same,
period after period: the branch, ``beta_old``, ``beta_query``, the bound, the replan flag, the questions asked,
the membership and the planner state. The first differing decision fails the test, naming it.
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import MODEL, ROOT, Server, binary, ort_library

import fastrack
from fastrack.geometry import Circle, Obstacle, Rectangle, Wall
from fastrack.online import OnlineLoop

WORLDS = 20
FORMAT = "fastrack-loop-trace/1"
PLANNER_TOLERANCE = 1e-9
"""Metres: the planner states of both loops, made of the same operations on the same numbers."""


def obstacle(entry: dict[str, Any]) -> Obstacle:
    """An obstacle of a trace (the Rust simulator's JSON: tagged by ``kind``)."""
    kind = entry["kind"]
    if kind == "circle":
        return Circle(tuple(entry["center"]), entry["radius"])
    if kind == "rectangle":
        return Rectangle(tuple(entry["min"]), tuple(entry["max"]))
    if kind == "wall":
        return Wall(tuple(entry["from"]), tuple(entry["to"]), entry["thickness"])
    raise ValueError(f"unknown obstacle kind {kind!r}")


@pytest.fixture(scope="module")
def traces(server: Server, tmp_path_factory: pytest.TempPathFactory) -> Iterator[list[Path]]:
    """The Rust loop's traces of PF on ``WORLDS`` seeded worlds against the test server."""
    out = tmp_path_factory.mktemp("traces")
    command = [str(binary("fastrack")), "sim", "bench", "--worlds", str(WORLDS), "--methods", "pf"]
    command += ["--traces", str(out / "traces"), "--results-dir", str(out / "records"), "--jobs", "2"]
    env = dict(os.environ, FASTRACK_SERVER=f"http://{server.address}", FASTRACK_ORT_LIB=ort_library())
    done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=ROOT, check=False)
    assert done.returncode == 0, done.stderr
    yield sorted((out / "traces").glob("pf-world-*.json"), key=lambda p: int(p.stem.rsplit("-", 1)[1]))


def replay(client: fastrack.Client, path: Path) -> int:
    """Gives the Python loop what the trace's loop was given; fails at the first differing decision. Returns
    the periods replayed."""
    trace = json.loads(path.read_text())
    assert trace["format"] == FORMAT, path
    (low, high) = trace["bounds"]
    with OnlineLoop(
        client,
        trace["model"],
        version=trace["version"],
        start=tuple(trace["start"]),
        goal=tuple(trace["goal"]),
        bounds=(tuple(low), tuple(high)),
        control_period=trace["control_period"],
        reset_candidates=trace["reset_candidates"],
    ) as loop:
        for k, step in enumerate(trace["steps"]):
            report = loop.step(step["tracker"], [obstacle(o) for o in step["sensed"]])
            where = f"{path.name}, period {k}"
            python = (report.branch, report.beta_old, report.beta_query, report.dteb_radius, report.replanned)
            rust = (step["branch"], step["beta_old"], step["beta_query"], step["dteb_radius"], step["replanned"])
            assert python == rust, f"{where}: (branch, beta_old, beta_query, bound, replanned) {python} vs {rust}"
            assert (report.round_trips, report.in_teb) == (step["round_trips"], step["in_teb"]), where
            gap = max(abs(report.planner[0] - step["planner"][0]), abs(report.planner[1] - step["planner"][1]))
            assert gap <= PLANNER_TOLERANCE, f"{where}: planner {list(report.planner)} vs {step['planner']}"
            assert abs(report.certificate_age - step["certificate_age"]) <= 1e-9, where
        return len(trace["steps"])


def test_the_python_loop_decides_as_the_rust_core_on_twenty_worlds(
    client: fastrack.Client, traces: list[Path]
) -> None:
    assert len(traces) == WORLDS, traces
    branches: dict[str, int] = {}
    periods = 0
    for path in traces:
        periods += replay(client, path)
        for step in json.loads(path.read_text())["steps"]:
            branches[step["branch"]] = branches.get(step["branch"], 0) + 1
    print(f"{periods} periods replayed on {WORLDS} worlds: {branches}")
    # The traces exercise the loop's branches, not only the common one.
    assert branches.get("advance", 0) > 0 and branches.get("keep", 0) + branches.get("reset", 0) > 0, branches
    assert MODEL == json.loads(traces[0].read_text())["model"]
