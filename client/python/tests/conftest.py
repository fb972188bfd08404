"""Fixtures: the real ``fastrack-server`` binary on free loopback ports, with the shipped ``models/``.

The binaries are taken from ``target/debug`` (or ``$FASTRACK_BIN_DIR``); the ONNX Runtime library from
``scripts/setup-onnxruntime.sh``. A missing binary fails the tests: nothing is skipped.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import pytest

import fastrack

ROOT = Path(__file__).resolve().parents[3]
MODELS = ROOT / "models"
MODEL = "dubins4d"
VERSION = 5  # the shipped version of MODEL, its default
USER_TOKEN = "user-token-7f3a9c2e"
ADMIN_TOKEN = "admin-token-5d8e0a4f"


def binary(name: str) -> Path:
    """A workspace binary (``target/debug/<name>`` unless ``$FASTRACK_BIN_DIR`` says otherwise)."""
    path = Path(os.environ.get("FASTRACK_BIN_DIR", ROOT / "target" / "debug")) / name
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it first (cargo build --workspace --bins)")
    return path


@cache
def ort_library() -> str:
    """The ONNX Runtime library the server loads (installed by the project's script if missing)."""
    script = ROOT / "scripts" / "setup-onnxruntime.sh"
    done = subprocess.run(["bash", str(script)], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.fail(f"{script} failed:\n{done.stderr}")
    return done.stdout.strip().splitlines()[-1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class Server:
    """One ``fastrack-server`` process; ``stop()`` kills it, ``start()`` starts it again on the same port."""

    def __init__(self, *args: str, port: int | None = None) -> None:
        self.args = list(args)
        self.port = port or free_port()
        self.address = f"127.0.0.1:{self.port}"
        self._logs = tempfile.TemporaryDirectory(prefix="fastrack-server-")
        self.log = Path(self._logs.name) / "server.log"
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> Server:
        command = [str(binary("fastrack-server")), "--listen", self.address, "--models", str(MODELS)]
        command += ["--poll-interval-s", "0", *self.args]
        env = dict(os.environ, FASTRACK_ORT_LIB=ort_library(), FASTRACK_LOG="info")
        with self.log.open("ab") as log:
            self.process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=log, env=env, cwd=ROOT)
        return self

    def wait_serving(self, timeout: float = 60.0, tls: fastrack.Tls | None = None) -> Server:
        """Waits until health is SERVING (``tls`` for TLS servers)."""
        end = time.monotonic() + timeout
        with fastrack.Client(self.address, tls=tls) as client:
            while True:
                if self.process is not None and self.process.poll() is not None:
                    pytest.fail(f"fastrack-server exited with {self.process.returncode}; log:\n{self.log_text()}")
                try:
                    client.wait_until_serving(timeout=1.0)
                    return self
                except fastrack.Unavailable:
                    if time.monotonic() > end:
                        pytest.fail(f"fastrack-server never became SERVING; log:\n{self.log_text()}")

    def stop(self, sig: int = signal.SIGKILL) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(sig)
            self.process.wait(timeout=30)
        self.process = None

    def log_text(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""

    def close(self) -> None:
        self.stop()
        assert "panicked" not in self.log_text(), f"the server panicked:\n{self.log_text()}"
        self._logs.cleanup()


@pytest.fixture(scope="session")
def server() -> Iterator[Server]:
    """The plain server (no TLS, no tokens) with the shipped models."""
    process = Server().start().wait_serving()
    yield process
    process.close()


@pytest.fixture(scope="session")
def client(server: Server) -> Iterator[fastrack.Client]:
    with fastrack.Client(server.address) as c:
        yield c


@pytest.fixture(scope="session")
def auth_server() -> Iterator[Server]:
    """A server that needs bearer tokens: ``USER_TOKEN`` (user) and ``ADMIN_TOKEN`` (admin)."""
    process = Server("--tokens", f"user:{USER_TOKEN},admin:{ADMIN_TOKEN}").start().wait_serving()
    yield process
    process.close()


@pytest.fixture
def replicas() -> Iterator[list[Server]]:
    """Three plain servers on free loopback ports, started together: replicas of one service (a test may
    kill some, so each test gets its own)."""
    servers = [Server().start() for _ in range(3)]
    try:
        yield [server.wait_serving() for server in servers]
    finally:
        for server in servers:
            server.close()
