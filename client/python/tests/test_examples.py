"""The examples: the numpy tracking loop as a subprocess, and the ROS 2 node (core logic and a real rclpy
graph) against the real server."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import fastrack
from conftest import MODEL, Server

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))

import ros2_node  # noqa: E402
import track_numpy  # noqa: E402


def test_track_numpy_stays_within_the_served_bound(server: Server) -> None:
    command = [sys.executable, str(EXAMPLES / "track_numpy.py"), "--server", server.address, "--steps", "300"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert "300 steps (3.00 s simulated)" in done.stdout and "within the served bound" in done.stdout


def test_track_numpy_reports_server_errors_without_a_traceback(server: Server) -> None:
    command = [sys.executable, str(EXAMPLES / "track_numpy.py"), "--server", server.address, "--model", "nope"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2
    assert done.stderr.startswith('fastrack: NOT_FOUND: model "nope" is not loaded') and "Traceback" not in done.stderr


def test_rk4_integrates_the_dubins_car() -> None:
    # Heading 0 is +y: straight ahead at 1 m/s for 1 s, then a quarter turn at constant speed.
    state = np.array([0.0, 0.0, 0.0, 1.0])
    for _ in range(100):
        state = track_numpy.rk4(state, np.array([0.0, 0.0]), 0.01)
    np.testing.assert_allclose(state, [0.0, 1.0, 0.0, 1.0], atol=1e-12)
    for _ in range(100):
        state = track_numpy.rk4(state, np.array([np.pi / 2, 0.0]), 0.01)
    radius = 1.0 / (np.pi / 2)
    np.testing.assert_allclose(state, [radius, 1.0 + radius, np.pi / 2, 1.0], atol=1e-8)


def test_ros_free_tracking_controller(client: fastrack.Client) -> None:
    with client.track(MODEL) as stream:
        controller = ros2_node.TrackingController(stream)
        assert controller.on_tracker_state([0.0, 0.0, 0.0, 1.0]) is None  # no planner state yet
        controller.on_planner_state([0.1, -0.2])
        controller.on_obstacle_distance(2.5)
        step = controller.on_tracker_state([0.3, -0.5, 1.0, 1.5])
        assert step is not None and step.beta_query == pytest.approx(0.75)
        expected = client.tracking_control(MODEL, [[0.2, -0.3, 1.0, 1.5]], step.beta_query).controls[0]
        np.testing.assert_allclose(step.control, expected, rtol=1e-9, atol=0)
        controller.on_obstacle_distance(-1.0)  # none sensed: the fastest speed
        step = controller.on_tracker_state([0.3, -0.5, 1.0, 1.5])
        assert step is not None and step.beta_query == pytest.approx(1.25)
        assert controller.on_tracker_state([float("nan"), 0.0, 0.0, 1.0]) is None
        assert isinstance(controller.last_error, fastrack.InvalidArgument)


def test_ros2_node_publishes_the_served_control(server: Server, client: fastrack.Client) -> None:
    assert ros2_node.HAVE_ROS, "rclpy is missing: setup-venv.sh installs it (extra `ros`)"
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import Float64, Float64MultiArray

    rclpy.init()
    try:
        node = ros2_node.FastrackNode([Parameter("endpoint", value=server.address), Parameter("model", value=MODEL)])
        robot = rclpy.create_node("robot")
        controls: list[list[float]] = []
        bounds: list[float] = []
        robot.create_subscription(Float64MultiArray, "control", lambda m: controls.append(list(m.data)), 10)
        robot.create_subscription(Float64, "tracking_bound", lambda m: bounds.append(m.data), 10)
        planner = robot.create_publisher(Float64MultiArray, "planner_state", 10)
        obstacle = robot.create_publisher(Float64, "obstacle_distance", 10)
        tracker = robot.create_publisher(Float64MultiArray, "tracker_state", 10)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.add_node(robot)
        end = time.monotonic() + 20
        while not controls and time.monotonic() < end:
            planner.publish(Float64MultiArray(data=[0.1, -0.2]))
            obstacle.publish(Float64(data=2.5))
            executor.spin_once(timeout_sec=0.05)
            tracker.publish(Float64MultiArray(data=[0.3, -0.5, 1.0, 1.5]))
            for _ in range(5):
                executor.spin_once(timeout_sec=0.02)
        assert controls, "the node published no control"
        expected = client.tracking_control(MODEL, [[0.2, -0.3, 1.0, 1.5]], 0.8).controls[0]
        np.testing.assert_allclose(controls[0], expected, rtol=1e-9, atol=0)
        assert bounds and bounds[0] == pytest.approx(client.query_planner_control(MODEL, 2.5).dteb_radius)
        executor.shutdown()
        node.destroy_node()
        robot.destroy_node()
    finally:
        rclpy.try_shutdown()
