"""Obstacles in the planner's plane: circles, axis-aligned rectangles and walls (segments with a thickness),
with exact distances from points and segments, so that inflation by a bound and line-of-sight checks are
exact rather than sampled. A port of the Rust ``fastrack_online::geometry``.

Points are ``(x, y)`` tuples of floats in the planner's position coordinates (metres for ``dubins4d``).
Obstacles are frozen dataclasses: equal obstacles compare (and hash) equal, so the same obstacle sensed
twice is remembered once (:func:`remember`). An impossible obstacle (a NaN, a radius <= 0, a rectangle
whose ``min`` is not below and left of its ``max``) raises :class:`~fastrack.InvalidArgument` when built.

>>> Circle((1.0, 1.0), 0.5).distance((3.0, 1.0))
1.5
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import SupportsFloat, TypeAlias

import numpy as np
import numpy.typing as npt

from .errors import InvalidArgument

Point: TypeAlias = tuple[float, float]
"""A point of the plane ``(x, y)``, in the planner's position coordinates."""

PointLike: TypeAlias = Sequence[SupportsFloat] | npt.NDArray[np.float64]
"""Anything with two numbers: a tuple, a list, a numpy array of shape [2]."""

Floats: TypeAlias = npt.NDArray[np.float64]


def point(value: PointLike, what: str = "point") -> Point:
    """``value`` as a :data:`Point` of two finite floats (raises :class:`~fastrack.InvalidArgument` if not)."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidArgument(f"{what} must be two numbers (x, y): {e}") from None
    if array.shape != (2,):
        raise InvalidArgument(f"{what} has shape {list(array.shape)}; a point of the plane needs [2] (x, y)")
    if not np.all(np.isfinite(array)):
        raise InvalidArgument(f"{what} = {array.tolist()}; must be finite")
    return (float(array[0]), float(array[1]))


def _positive(value: SupportsFloat, what: str) -> float:
    number = float(value)
    if not (math.isfinite(number) and number > 0.0):
        raise InvalidArgument(f"{what} = {number}; must be a finite number > 0")
    return number


@dataclass(frozen=True)
class Circle:
    """A disc of centre ``center`` and radius ``radius`` (> 0)."""

    center: Point
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", point(self.center, "circle center"))
        object.__setattr__(self, "radius", _positive(self.radius, "circle radius"))

    def distance(self, p: Point) -> float:
        """Distance from ``p`` to the disc (0 inside it)."""
        return max(norm(sub(p, self.center)) - self.radius, 0.0)

    def segment_distance(self, a: Point, b: Point) -> float:
        """Distance from the segment ``a``-``b`` to the disc (0 if they touch)."""
        return max(point_segment_distance(self.center, a, b) - self.radius, 0.0)

    def distances(self, points: Floats) -> Floats:
        """:meth:`distance` of every row of ``points`` [N, 2], vectorised: shape [N]."""
        d = np.hypot(points[:, 0] - self.center[0], points[:, 1] - self.center[1]) - self.radius
        result: Floats = np.maximum(d, 0.0)
        return result

    def bounds(self) -> tuple[Point, Point]:
        """The bounding box, ``(min, max)``."""
        (x, y), r = self.center, self.radius
        return (x - r, y - r), (x + r, y + r)


@dataclass(frozen=True)
class Rectangle:
    """An axis-aligned rectangle from its lower-left corner ``min`` to its upper-right corner ``max``."""

    min: Point
    max: Point

    def __post_init__(self) -> None:
        low, high = point(self.min, "rectangle min"), point(self.max, "rectangle max")
        if not (low[0] < high[0] and low[1] < high[1]):
            raise InvalidArgument(f"rectangle min {low} must lie below and left of max {high}")
        object.__setattr__(self, "min", low)
        object.__setattr__(self, "max", high)

    def distance(self, p: Point) -> float:
        """Distance from ``p`` to the rectangle (0 inside it)."""
        dx = max(self.min[0] - p[0], p[0] - self.max[0], 0.0)
        dy = max(self.min[1] - p[1], p[1] - self.max[1], 0.0)
        return math.hypot(dx, dy)

    def segment_distance(self, a: Point, b: Point) -> float:
        """Distance from the segment ``a``-``b`` to the rectangle (0 if they touch)."""
        if self._contains(a) or self._contains(b):
            return 0.0
        (x0, y0), (x1, y1) = self.min, self.max
        corners = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
        return min(segment_segment_distance(a, b, corners[i], corners[(i + 1) % 4]) for i in range(4))

    def distances(self, points: Floats) -> Floats:
        """:meth:`distance` of every row of ``points`` [N, 2], vectorised: shape [N]."""
        x, y = points[:, 0], points[:, 1]
        dx = np.maximum(np.maximum(self.min[0] - x, x - self.max[0]), 0.0)
        dy = np.maximum(np.maximum(self.min[1] - y, y - self.max[1]), 0.0)
        result: Floats = np.hypot(dx, dy)
        return result

    def bounds(self) -> tuple[Point, Point]:
        """The bounding box, ``(min, max)``."""
        return self.min, self.max

    def _contains(self, p: Point) -> bool:
        return self.min[0] <= p[0] <= self.max[0] and self.min[1] <= p[1] <= self.max[1]


@dataclass(frozen=True)
class Wall:
    """A wall: the points within ``thickness / 2`` of the segment ``start``-``end`` (Rust: ``from``-``to``)."""

    start: Point
    end: Point
    thickness: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", point(self.start, "wall start"))
        object.__setattr__(self, "end", point(self.end, "wall end"))
        object.__setattr__(self, "thickness", _positive(self.thickness, "wall thickness"))

    def distance(self, p: Point) -> float:
        """Distance from ``p`` to the wall (0 inside it)."""
        return max(point_segment_distance(p, self.start, self.end) - self.thickness / 2.0, 0.0)

    def segment_distance(self, a: Point, b: Point) -> float:
        """Distance from the segment ``a``-``b`` to the wall (0 if they touch)."""
        return max(segment_segment_distance(a, b, self.start, self.end) - self.thickness / 2.0, 0.0)

    def distances(self, points: Floats) -> Floats:
        """:meth:`distance` of every row of ``points`` [N, 2], vectorised: shape [N]."""
        (ax, ay), (bx, by) = self.start, self.end
        abx, aby = bx - ax, by - ay
        length2 = abx * abx + aby * aby
        px, py = points[:, 0] - ax, points[:, 1] - ay
        t = np.clip((px * abx + py * aby) / length2, 0.0, 1.0) if length2 > 0.0 else np.zeros(len(points))
        result: Floats = np.maximum(np.hypot(px - t * abx, py - t * aby) - self.thickness / 2.0, 0.0)
        return result

    def bounds(self) -> tuple[Point, Point]:
        """The bounding box, ``(min, max)``."""
        h = self.thickness / 2.0
        (ax, ay), (bx, by) = self.start, self.end
        return (min(ax, bx) - h, min(ay, by) - h), (max(ax, bx) + h, max(ay, by) + h)


Obstacle: TypeAlias = Circle | Rectangle | Wall
"""One obstacle of the planner's plane."""

OBSTACLE_KINDS = (Circle, Rectangle, Wall)


def remember(known: list[Obstacle], sensed: Iterable[Obstacle]) -> bool:
    """Adds to ``known`` the obstacles of ``sensed`` it does not hold yet; True if there were any (an
    obstacle is newly sensed)."""
    before = len(known)
    for obstacle in sensed:
        if obstacle not in known:
            known.append(obstacle)
    return len(known) > before


def clearance(obstacles: Sequence[Obstacle], p: Point) -> float:
    """The smallest distance from ``p`` to any of ``obstacles`` (infinite for none)."""
    return min((o.distance(p) for o in obstacles), default=math.inf)


def clearances(obstacles: Sequence[Obstacle], points: Floats) -> Floats:
    """:func:`clearance` of every row of ``points`` [N, 2], vectorised: shape [N] (infinite for none)."""
    result: Floats = np.full(len(points), np.inf)
    for o in obstacles:
        result = np.minimum(result, o.distances(points))
    return result


def segment_is_free(obstacles: Sequence[Obstacle], a: Point, b: Point, inflation: float) -> bool:
    """True if the segment ``a``-``b`` keeps more than ``inflation`` from every obstacle."""
    return all(o.segment_distance(a, b) > inflation for o in obstacles)


def sub(a: Point, b: Point) -> Point:
    """``a - b``."""
    return (a[0] - b[0], a[1] - b[1])


def norm(a: Point) -> float:
    """Euclidean norm."""
    return math.hypot(a[0], a[1])


def point_segment_distance(p: Point, a: Point, b: Point) -> float:
    """Distance from ``p`` to the segment ``a``-``b``."""
    abx, aby = b[0] - a[0], b[1] - a[1]
    length2 = abx * abx + aby * aby
    t = min(max(((p[0] - a[0]) * abx + (p[1] - a[1]) * aby) / length2, 0.0), 1.0) if length2 > 0.0 else 0.0
    return math.hypot(p[0] - (a[0] + t * abx), p[1] - (a[1] + t * aby))


def _cross(o: Point, p: Point, q: Point) -> float:
    return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])


def segment_segment_distance(a: Point, b: Point, c: Point, d: Point) -> float:
    """Distance between the segments ``a``-``b`` and ``c``-``d`` (0 if they cross)."""
    d1, d2, d3, d4 = _cross(c, d, a), _cross(c, d, b), _cross(a, b, c), _cross(a, b, d)
    if ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)) and ((d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)):
        return 0.0
    return min(
        point_segment_distance(a, c, d),
        point_segment_distance(b, c, d),
        point_segment_distance(c, a, b),
        point_segment_distance(d, a, b),
    )
