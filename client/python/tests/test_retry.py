"""Retries: an idempotent call survives a server restart within its retry window; ``Track`` is never retried."""

from __future__ import annotations

import threading
import time

import pytest

import fastrack
from conftest import MODEL, Server


def test_a_call_retried_until_the_restarted_server_is_back() -> None:
    server = Server().start().wait_serving()
    retry = fastrack.Retry(attempts=60, initial_backoff=0.05, max_backoff=0.25)
    restart = threading.Timer(0.5, server.start)
    try:
        with fastrack.Client(server.address, retry=retry, max_reconnect_backoff=0.2) as client:
            assert client.query_planner_control(MODEL, 2.5).beta_query == pytest.approx(0.75)
            with client.track(MODEL) as robot:
                robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])
                server.stop()
                started = time.monotonic()
                with pytest.raises(fastrack.Unavailable):  # the stream is not retried
                    robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])
                assert time.monotonic() - started < 2.0
            with fastrack.Client(server.address, retry=fastrack.Retry(attempts=1)) as once:
                with pytest.raises(fastrack.Unavailable):
                    once.query_planner_control(MODEL, 2.5)
            restart.start()
            started = time.monotonic()
            answer = client.query_planner_control(MODEL, 2.5)  # fails while the server is down, then succeeds
            waited = time.monotonic() - started
            restart.join()
            assert answer.beta_query == pytest.approx(0.75)
            assert waited >= 0.5, f"answered after {waited:.2f} s, before the server was restarted"
    finally:
        restart.cancel()
        if restart.is_alive():
            restart.join()
        server.close()


def test_backoff_is_jittered_and_capped() -> None:
    retry = fastrack.Retry(attempts=5, initial_backoff=0.1, max_backoff=0.3, multiplier=2.0)
    for attempt, ceiling in enumerate([0.1, 0.2, 0.3, 0.3]):
        delays = {retry.delay(attempt) for _ in range(50)}
        assert all(0.5 * ceiling <= d <= ceiling for d in delays)
        assert len(delays) > 1  # jittered
