"""A regular install from a checkout, as a user of another project makes it: building writes nothing into
the checkout (so a read-only one works), the wheel carries the generated stubs, and code using the client
type-checks under ``mypy --strict`` in a fresh environment with numpy scalars where numbers go."""

from __future__ import annotations

import shutil
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

from conftest import ROOT

HERE = Path(__file__).resolve().parents[1]

USER_CODE = """
import numpy as np
import fastrack

def plan(client: fastrack.Client) -> float:
    speed = client.query_planner_control("dubins4d", d_obs=np.float32(2.5))
    bound = client.tracking_error_bound("dubins4d", beta=np.float32(speed.beta_query))
    with client.track("dubins4d") as robot:
        reply = robot.tick(np.zeros(4), np.zeros(2), d_obs=np.float64(1.0))
    radius: float = reply.dteb_radius + bound.radius
    return radius
"""


def snapshot(folder: Path) -> dict[str, float]:
    """Every path under ``folder`` with its modification time."""
    return {str(p.relative_to(folder)): p.stat().st_mtime for p in folder.rglob("*")}


def run(*command: str | Path, cwd: Path | None = None) -> str:
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, f"{command}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def test_a_wheel_from_a_checkout_leaves_it_untouched_and_types_user_code(tmp_path: Path) -> None:
    checkout = tmp_path / "checkout"
    shutil.copytree(ROOT / "proto", checkout / "proto")
    generated = shutil.ignore_patterns("*_pb2*", "*.egg-info", "build", "__pycache__", ".mypy_cache")
    shutil.copytree(HERE, checkout / "client" / "python", ignore=generated)
    before = snapshot(checkout)

    wheels = tmp_path / "wheels"
    run(sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "-w", wheels, checkout / "client" / "python")
    assert snapshot(checkout) == before, "the build wrote into the checkout"
    (wheel,) = wheels.glob("fastrack_client-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for stem in ("models", "safety"):
        for suffix in ("_pb2.py", "_pb2.pyi", "_pb2_grpc.py", "_pb2_grpc.pyi"):
            assert f"fastrack/v1/{stem}{suffix}" in names, f"{stem}{suffix} is missing from the wheel"

    env = tmp_path / "env"
    venv.create(env, with_pip=True)
    python = env / "bin" / "python"
    run(python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", f"{wheel}[typing]", "mypy>=1.13")
    (tmp_path / "user.py").write_text(USER_CODE)
    out = run(python, "-m", "mypy", "--strict", "--no-incremental", "user.py", cwd=tmp_path)
    assert out.startswith("Success: no issues found"), out
