"""Benchmark of the Python client beside the Rust client, on one server in one run.

Measures, closed loop (one call or tick outstanding), random in-domain inputs drawn like the Rust load
generator's (relative state in the domain box less a 1% margin, planner within 5 m, d_obs up to 4x the
largest TEB level):

- ticks/s of one Python ``Track`` stream (sync ``Client``; the asyncio client too, for reference);
- unary ``TrackingControl`` p50/p99 latency and calls/s at batch 1 and 64 (sync ``Client``);
- the same three figures from the Rust load generator (``fastrack load --concurrency 1``).

It starts its own server (release binaries if built, else debug; ``--bin-dir`` to choose) unless given
``--server``. ``--record`` writes ``bench/results/python-client.{json,md}``; without it nothing is written.

    .cache/python/venv/bin/python client/python/bench/bench_client.py --duration-s 5
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import fastrack

ROOT = Path(__file__).resolve().parents[3]
MODEL = "dubins4d"
POOL = 256  # distinct inputs cycled through, generated before the clock starts
Array = npt.NDArray[np.float64]


class Inputs:
    """Random in-domain inputs of a model, drawn once."""

    def __init__(self, info: fastrack.v1.models_pb2.ModelInfo, seed: int) -> None:
        rng = np.random.default_rng(seed)
        lo = np.array([d.bounds.min for d in info.state])
        hi = np.array([d.bounds.max for d in info.state])
        margin = np.where([d.periodic for d in info.state], 0.0, 0.01 * (hi - lo))
        self.rng, self.lo, self.hi = rng, lo + margin, hi - margin
        self.beta = (info.params[0].range.min, info.params[0].range.max)
        self.n_params = len(info.params)
        self.q = np.array(info.planner_to_state).reshape(len(info.state), info.planner_dim)
        self.d_obs_max = 4.0 * max(row.bound for row in info.teb_table)

    def batch(self, n: int) -> tuple[Array, Array]:
        states = self.rng.uniform(self.lo, self.hi, (n, len(self.lo)))
        return states, self.rng.uniform(*self.beta, (n, self.n_params))

    def ticks(self) -> list[tuple[list[float], list[float], float]]:
        relative, _ = self.batch(POOL)
        planner = self.rng.uniform(-5.0, 5.0, (POOL, self.q.shape[1]))
        tracker = relative + planner @ self.q.T
        d_obs = self.rng.uniform(0.0, self.d_obs_max, POOL)
        return [(tracker[i].tolist(), planner[i].tolist(), float(d_obs[i])) for i in range(POOL)]


def percentiles(latencies: list[float], elapsed: float, items: int) -> dict[str, float]:
    ms = np.array(latencies) * 1e3
    return {
        "requests": len(latencies),
        "requests_per_s": len(latencies) / elapsed,
        "items_per_s": items * len(latencies) / elapsed,
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
    }


def closed_loop(step: Callable[[int], object], duration: float, warmup: float, items: int = 1) -> dict[str, float]:
    """Runs ``step(i)`` back to back: ``warmup`` seconds unmeasured, then ``duration`` seconds measured."""
    i = 0
    end_warmup = time.perf_counter() + warmup
    while time.perf_counter() < end_warmup:
        step(i)
        i += 1
    latencies = []
    start = time.perf_counter()
    end = start + duration
    while (now := time.perf_counter()) < end:
        step(i)
        latencies.append(time.perf_counter() - now)
        i += 1
    return percentiles(latencies, time.perf_counter() - start, items)


def python_figures(address: str, duration: float, warmup: float, seed: int) -> dict[str, dict[str, float]]:
    figures: dict[str, dict[str, float]] = {}
    with fastrack.Client(address) as client:
        inputs = Inputs(client.get_model(MODEL), seed)
        ticks = inputs.ticks()
        with client.track(MODEL) as robot:
            figures["track"] = closed_loop(lambda i: robot.tick(*ticks[i % POOL]), duration, warmup)
        for batch in (1, 64):
            payloads = [inputs.batch(batch) for _ in range(8)]
            figures[f"unary_batch_{batch}"] = closed_loop(
                lambda i: client.tracking_control(MODEL, *payloads[i % 8]), duration, warmup, batch
            )
    figures["track_asyncio"] = asyncio.run(async_track(address, ticks, duration, warmup))
    return figures


async def async_track(address: str, ticks: list[tuple[list[float], list[float], float]], duration: float,
                      warmup: float) -> dict[str, float]:
    async with fastrack.AsyncClient(address) as client, client.track(MODEL) as robot:
        i = 0
        end_warmup = time.perf_counter() + warmup
        while time.perf_counter() < end_warmup:
            await robot.tick(*ticks[i % POOL])
            i += 1
        latencies = []
        start = time.perf_counter()
        while (now := time.perf_counter()) < start + duration:
            await robot.tick(*ticks[i % POOL])
            latencies.append(time.perf_counter() - now)
            i += 1
        return percentiles(latencies, time.perf_counter() - start, 1)


def rust_figures(cli: Path, address: str, duration: float, warmup: float, seed: int) -> dict[str, dict[str, float]]:
    figures = {}
    for name, workload in [("track", ["--workload", "track"]),
                           ("unary_batch_1", ["--workload", "unary", "--batch", "1"]),
                           ("unary_batch_64", ["--workload", "unary", "--batch", "64"])]:
        command = [str(cli), "--server", f"http://{address}", "--json", "load", "--model", MODEL, *workload,
                   "--concurrency", "1", "--duration-s", str(duration), "--warmup-s", str(warmup), "--seed", str(seed)]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise SystemExit(f"bench: {' '.join(command)} failed:\n{done.stderr}")
        run: dict[str, Any] = json.loads(done.stdout)["runs"][0]
        figures[name] = {
            "requests": run["requests"],
            "requests_per_s": run["requests_per_s"],
            "items_per_s": run["items_per_s"],
            "p50_ms": run["latency"]["p50_ms"],
            "p99_ms": run["latency"]["p99_ms"],
        }
    return figures


@contextmanager
def own_server(bin_dir: Path) -> Iterator[str]:
    """Starts ``fastrack-server`` on a free port with the shipped models; yields its address."""
    ort = subprocess.run(["bash", str(ROOT / "scripts" / "setup-onnxruntime.sh")], capture_output=True, text=True,
                         check=True).stdout.split()[-1]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{s.getsockname()[1]}"
    with tempfile.TemporaryFile() as log:
        server = subprocess.Popen(
            [str(bin_dir / "fastrack-server"), "--listen", address, "--models", str(ROOT / "models"),
             "--poll-interval-s", "0"],
            stdout=subprocess.DEVNULL, stderr=log, env=dict(os.environ, FASTRACK_ORT_LIB=ort), cwd=ROOT,
        )
        try:
            with fastrack.Client(address) as client:
                client.wait_until_serving(timeout=60.0)
            yield address
        finally:
            server.terminate()
            server.wait(timeout=30)


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores, {model}"


def revision() -> str:
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD") or "unknown"
    return head + ("-dirty" if git("status", "--porcelain") else "")


ROWS = [("track", "Track stream, ticks"), ("unary_batch_1", "unary TrackingControl, batch 1"),
        ("unary_batch_64", "unary TrackingControl, batch 64")]


def table(python: dict[str, dict[str, float]], rust: dict[str, dict[str, float]]) -> str:
    lines = ["| workload (one stream / one caller) | client | requests/s | p50 (ms) | p99 (ms) | Python / Rust rate |",
             "| --- | --- | --- | --- | --- | --- |"]
    for key, label in ROWS:
        for client, figures in (("Rust", rust), ("Python", python)):
            f = figures[key]
            ratio = f"{python[key]['requests_per_s'] / rust[key]['requests_per_s']:.2f}" if client == "Python" else ""
            lines.append(f"| {label} | {client} | {f['requests_per_s']:.0f} | {f['p50_ms']:.3f} | {f['p99_ms']:.3f} "
                         f"| {ratio} |")
    a = python["track_asyncio"]
    lines.append(f"| Track stream, ticks | Python asyncio | {a['requests_per_s']:.0f} | {a['p50_ms']:.3f} "
                 f"| {a['p99_ms']:.3f} | {a['requests_per_s'] / rust['track']['requests_per_s']:.2f} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--server", help="address of a running server (default: start one)")
    parser.add_argument("--bin-dir", type=Path, help="folder of fastrack-server and fastrack (default: "
                        "target/release if built, else target/debug)")
    parser.add_argument("--duration-s", type=float, default=5.0, help="measured seconds per figure")
    parser.add_argument("--warmup-s", type=float, default=1.0, help="unmeasured seconds before each figure")
    parser.add_argument("--seed", type=int, default=7, help="seed of the random inputs")
    parser.add_argument("--record", action="store_true", help="write bench/results/python-client.{json,md}")
    parser.add_argument("--results-dir", type=Path, default=ROOT / "bench" / "results",
                        help="where --record writes (default: bench/results)")
    args = parser.parse_args()
    release = ROOT / "target" / "release"
    bin_dir: Path = args.bin_dir or (release if (release / "fastrack-server").is_file() else ROOT / "target" / "debug")
    for name in ("fastrack", "fastrack-server"):
        if not (bin_dir / name).is_file():
            print(f"bench: {bin_dir / name} is missing: build it (cargo build --release --bins)", file=sys.stderr)
            return 1
    try:
        with own_server(bin_dir) if args.server is None else nullcontext(args.server) as address:
            python = python_figures(address, args.duration_s, args.warmup_s, args.seed)
            rust = rust_figures(bin_dir / "fastrack", address, args.duration_s, args.warmup_s, args.seed)
    except fastrack.FastrackError as e:
        print(f"bench: {e}", file=sys.stderr)
        return 2
    text = table(python, rust)
    print(text)
    if args.record:
        command = "python client/python/bench/bench_client.py " + " ".join(sys.argv[1:])
        when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        record = {
            "name": "python-client",
            "command": command.strip(),
            "config": {
                "model": f"models/{MODEL} (default version)",
                "server": f"{bin_dir.relative_to(ROOT) if bin_dir.is_relative_to(ROOT) else bin_dir}/fastrack-server,"
                          " defaults" if args.server is None else args.server,
                "python_client": "fastrack.Client (sync) and fastrack.AsyncClient, closed loop, one connection",
                "rust_client": "fastrack load --concurrency 1 (the Rust client library)",
                "duration_s": args.duration_s,
                "warmup_s": args.warmup_s,
                "seed": args.seed,
                "python": platform.python_version(),
            },
            "figures": {"python": python, "rust": rust},
            "date": when,
            "machine": machine(),
            "source_revision": revision(),
        }
        results: Path = args.results_dir
        (results / "python-client.json").write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
        (results / "python-client.md").write_text(
            f"# python-client\n\n`{record['command']}`\n\n{record['machine']}, {when}, revision "
            f"{record['source_revision']}\n\n## One Python stream or caller beside the Rust client's\n\n{text}\n"
        )
        print(f"recorded {results / 'python-client.json'} and .md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
