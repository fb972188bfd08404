"""``mypy --strict`` over the package, the examples, the benchmark and these tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import ROOT

HERE = Path(__file__).resolve().parents[1]


def test_mypy_strict() -> None:
    command = [sys.executable, "-m", "mypy", "--strict", "--cache-dir", str(ROOT / ".cache" / "python" / "mypy")]
    command += ["src/fastrack", "examples", "bench", "tests"]
    done = subprocess.run(command, cwd=HERE, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("Success: no issues found")
