"""A ROS 2 node that runs a robot's tracking controller on the fastrack service (one ``Track`` stream).

Parameters:
    endpoint  server address, ``host:port`` (default ``127.0.0.1:50051``)
    model     model name (default ``dubins4d``)
    token     bearer token, empty for none
Subscribes:
    tracker_state      std_msgs/Float64MultiArray  tracker state s (dubins4d: x m, y m, heading rad, speed m/s)
    planner_state      std_msgs/Float64MultiArray  planner state p (dubins4d: x m, y m)
    obstacle_distance  std_msgs/Float64            distance to the nearest sensed obstacle, m (optional;
                                                   negative: none sensed)
Publishes, once per tracker_state message (after a planner_state has arrived):
    control              std_msgs/Float64MultiArray  optimal control u* (dubins4d: omega rad/s, alpha m/s^2)
    planner_speed_bound  std_msgs/Float64            beta_query: the speed bound (m/s) the planner must keep
    tracking_bound       std_msgs/Float64            dteb_radius: the TEB radius (m) at that speed

The ROS-free logic is :class:`TrackingController`; ROS 2 (``rclpy``, ``std_msgs``) is needed only for
:func:`main` and :class:`FastrackNode` (``pip install 'fastrack-client[ros]'`` brings them from PyPI, or
source a ROS 2 installation). Run: ``python examples/ros2_node.py --ros-args -p endpoint:=127.0.0.1:50051``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import fastrack

try:
    import rclpy
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_msgs.msg import Float64, Float64MultiArray

    HAVE_ROS = True
except ImportError:  # the controller below works without ROS 2
    HAVE_ROS = False


@dataclass(frozen=True)
class ControlStep:
    """What the node publishes for one tracker state."""

    control: list[float]
    """Optimal control u*, the controls' units."""
    beta_query: float
    """Planner speed bound, m/s."""
    dteb_radius: float
    """TEB radius at ``beta_query``, m."""
    in_teb: bool
    """The relative state lies in the TEB."""


class TrackingController:
    """Holds the latest planner state and obstacle distance; turns each tracker state into a control
    through a ``Track`` stream. A tick the server rejects is reported (``last_error``) and skipped."""

    def __init__(self, stream: fastrack.TrackStream) -> None:
        self.stream = stream
        self.planner_state: list[float] | None = None
        self.d_obs: float | None = None
        self.last_error: fastrack.FastrackError | None = None

    def on_planner_state(self, state: Sequence[float]) -> None:
        self.planner_state = list(state)

    def on_obstacle_distance(self, distance: float) -> None:
        """Distance to the nearest obstacle in metres; negative means none sensed."""
        self.d_obs = distance if distance >= 0.0 else None

    def on_tracker_state(self, state: Sequence[float]) -> ControlStep | None:
        """The control for this tracker state; None before the first planner state or if the tick failed."""
        if self.planner_state is None:
            return None
        try:
            reply = self.stream.tick(list(state), self.planner_state, self.d_obs)
        except fastrack.FastrackError as e:
            self.last_error = e
            return None
        self.last_error = None
        return ControlStep([float(u) for u in reply.control], reply.beta_query, reply.dteb_radius, reply.in_teb)


if HAVE_ROS:

    class FastrackNode(Node):
        """The ROS 2 wrapper of :class:`TrackingController` (topics and parameters in the module doc)."""

        def __init__(self, parameter_overrides: list[Parameter[str]] | None = None) -> None:
            super().__init__("fastrack_tracker", parameter_overrides=parameter_overrides)
            endpoint = str(self.declare_parameter("endpoint", "127.0.0.1:50051").value)
            model = str(self.declare_parameter("model", "dubins4d").value)
            token = str(self.declare_parameter("token", "").value) or None
            self.client = fastrack.Client(endpoint, token=token)
            self.controller = TrackingController(self.client.track(model))
            self.control = self.create_publisher(Float64MultiArray, "control", 10)
            self.speed_bound = self.create_publisher(Float64, "planner_speed_bound", 10)
            self.bound = self.create_publisher(Float64, "tracking_bound", 10)
            self.create_subscription(Float64MultiArray, "planner_state", self._planner, 10)
            self.create_subscription(Float64, "obstacle_distance", self._obstacle, 10)
            self.create_subscription(Float64MultiArray, "tracker_state", self._tracker, 10)
            self.get_logger().info(f"tracking with {model} on {endpoint}")

        def _planner(self, message: Float64MultiArray) -> None:
            self.controller.on_planner_state(list(message.data))

        def _obstacle(self, message: Float64) -> None:
            self.controller.on_obstacle_distance(float(message.data))

        def _tracker(self, message: Float64MultiArray) -> None:
            step = self.controller.on_tracker_state(list(message.data))
            if step is None:
                if self.controller.last_error is not None:
                    self.get_logger().warning(f"tick refused: {self.controller.last_error}")
                return
            self.control.publish(Float64MultiArray(data=step.control))
            self.speed_bound.publish(Float64(data=step.beta_query))
            self.bound.publish(Float64(data=step.dteb_radius))

        def destroy_node(self) -> None:
            self.controller.stream.close()
            self.client.close()
            super().destroy_node()


def main() -> int:
    if not HAVE_ROS:
        print("ros2_node: rclpy is not installed; pip install 'fastrack-client[ros]' or source ROS 2", file=sys.stderr)
        return 1
    rclpy.init(args=sys.argv)
    try:
        node = FastrackNode()
    except fastrack.FastrackError as e:
        print(f"ros2_node: {e}", file=sys.stderr)
        rclpy.shutdown()
        return 2
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
