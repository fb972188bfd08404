//! Obstacles in the planner's plane: circles, axis-aligned rectangles and walls (segments with a thickness),
//! with closed-form distances from points and segments.

use super::{norm, point_segment_distance, sub, Obstacle, ObstacleError, Point};
use serde::{Deserialize, Serialize};

/// One obstacle of the plane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PlaneObstacle {
    /// A disc.
    Circle {
        /// Centre.
        center: Point,
        /// Radius (> 0).
        radius: f64,
    },
    /// An axis-aligned rectangle.
    Rectangle {
        /// Lower-left corner.
        min: Point,
        /// Upper-right corner.
        max: Point,
    },
    /// A wall: the points within `thickness / 2` of the segment `from`-`to`.
    Wall {
        /// One end of the wall's centre line.
        from: Point,
        /// The other end.
        to: Point,
        /// Thickness (> 0).
        thickness: f64,
    },
}

impl Obstacle<2> for PlaneObstacle {
    fn validate(&self) -> Result<(), ObstacleError> {
        let finite = |p: &Point| p.iter().all(|x| x.is_finite());
        let bad = |what: String| Err(ObstacleError(what));
        match self {
            PlaneObstacle::Circle { center, radius } => {
                if !finite(center) {
                    return bad(format!("circle center {center:?} must be finite"));
                }
                if !(radius.is_finite() && *radius > 0.0) {
                    return bad(format!("circle radius = {radius}; must be a finite number > 0"));
                }
            }
            PlaneObstacle::Rectangle { min, max } => {
                if !(finite(min) && finite(max)) {
                    return bad(format!("rectangle corners {min:?}, {max:?} must be finite"));
                }
                if !(min[0] < max[0] && min[1] < max[1]) {
                    return bad(format!("rectangle min {min:?} must lie below and left of max {max:?}"));
                }
            }
            PlaneObstacle::Wall { from, to, thickness } => {
                if !(finite(from) && finite(to)) {
                    return bad(format!("wall ends {from:?}, {to:?} must be finite"));
                }
                if !(thickness.is_finite() && *thickness > 0.0) {
                    return bad(format!("wall thickness = {thickness}; must be a finite number > 0"));
                }
            }
        }
        Ok(())
    }

    fn distance(&self, p: Point) -> f64 {
        match self {
            PlaneObstacle::Circle { center, radius } => (norm(sub(p, *center)) - radius).max(0.0),
            PlaneObstacle::Rectangle { min, max } => {
                let dx = (min[0] - p[0]).max(p[0] - max[0]).max(0.0);
                let dy = (min[1] - p[1]).max(p[1] - max[1]).max(0.0);
                dx.hypot(dy)
            }
            PlaneObstacle::Wall { from, to, thickness } => {
                (point_segment_distance(p, *from, *to) - thickness / 2.0).max(0.0)
            }
        }
    }

    fn segment_distance(&self, a: Point, b: Point) -> f64 {
        match self {
            PlaneObstacle::Circle { center, radius } => (point_segment_distance(*center, a, b) - radius).max(0.0),
            PlaneObstacle::Rectangle { min, max } => {
                if super::inside(a, (*min, *max)) || super::inside(b, (*min, *max)) {
                    return 0.0;
                }
                let corners = [*min, [max[0], min[1]], *max, [min[0], max[1]]];
                (0..4)
                    .map(|i| segment_segment_distance(a, b, corners[i], corners[(i + 1) % 4]))
                    .fold(f64::INFINITY, f64::min)
            }
            PlaneObstacle::Wall { from, to, thickness } => {
                (segment_segment_distance(a, b, *from, *to) - thickness / 2.0).max(0.0)
            }
        }
    }
}

/// Distance between the segments `a`-`b` and `c`-`d` (0 if they cross).
pub fn segment_segment_distance(a: Point, b: Point, c: Point, d: Point) -> f64 {
    let cross = |o: Point, p: Point, q: Point| (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0]);
    let (d1, d2, d3, d4) = (cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return 0.0;
    }
    point_segment_distance(a, c, d)
        .min(point_segment_distance(b, c, d))
        .min(point_segment_distance(c, a, b))
        .min(point_segment_distance(d, a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::segment_is_free;

    #[test]
    fn distances_match_closed_forms() {
        let circle = PlaneObstacle::Circle { center: [1.0, 1.0], radius: 0.5 };
        assert!((circle.distance([3.0, 1.0]) - 1.5).abs() < 1e-12);
        assert_eq!(circle.distance([1.2, 1.1]), 0.0);
        let rectangle = PlaneObstacle::Rectangle { min: [0.0, 0.0], max: [2.0, 1.0] };
        assert!((rectangle.distance([3.0, 2.0]) - 2f64.sqrt()).abs() < 1e-12);
        assert!((rectangle.distance([1.0, -0.5]) - 0.5).abs() < 1e-12);
        assert_eq!(rectangle.distance([1.0, 0.5]), 0.0);
        let wall = PlaneObstacle::Wall { from: [0.0, 0.0], to: [4.0, 0.0], thickness: 0.2 };
        assert!((wall.distance([2.0, 1.0]) - 0.9).abs() < 1e-12);
        assert!((wall.distance([5.0, 0.0]) - 0.9).abs() < 1e-12);
    }

    #[test]
    fn segment_distances_see_crossings_and_near_misses() {
        let rectangle = PlaneObstacle::Rectangle { min: [0.0, 0.0], max: [1.0, 1.0] };
        // Crossing through the rectangle without an end inside it.
        assert_eq!(rectangle.segment_distance([-1.0, 0.5], [2.0, 0.5]), 0.0);
        // Passing 0.25 above it.
        assert!((rectangle.segment_distance([-1.0, 1.25], [2.0, 1.25]) - 0.25).abs() < 1e-12);
        let circle = PlaneObstacle::Circle { center: [0.0, 0.0], radius: 1.0 };
        assert!((circle.segment_distance([-2.0, 2.0], [2.0, 2.0]) - 1.0).abs() < 1e-12);
        assert!(segment_is_free(std::slice::from_ref(&circle), [-2.0, 2.0], [2.0, 2.0], 0.9));
        assert!(!segment_is_free(&[circle], [-2.0, 2.0], [2.0, 2.0], 1.0));
        // Against a brute-force minimum over points of the segment.
        let wall = PlaneObstacle::Wall { from: [0.0, 0.0], to: [1.0, 2.0], thickness: 0.3 };
        let (a, b) = ([2.0, -1.0], [3.0, 3.0]);
        let brute = (0..=10_000)
            .map(|k| {
                let t = k as f64 / 10_000.0;
                wall.distance([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])])
            })
            .fold(f64::INFINITY, f64::min);
        assert!((wall.segment_distance(a, b) - brute).abs() < 1e-6, "{} vs {brute}", wall.segment_distance(a, b));
    }

    #[test]
    fn impossible_obstacles_are_named() {
        let bad = [
            PlaneObstacle::Circle { center: [0.0, f64::NAN], radius: 1.0 },
            PlaneObstacle::Circle { center: [0.0, 0.0], radius: -1.0 },
            PlaneObstacle::Rectangle { min: [1.0, 0.0], max: [0.0, 1.0] },
            PlaneObstacle::Wall { from: [0.0, 0.0], to: [1.0, 0.0], thickness: 0.0 },
        ];
        for obstacle in bad {
            assert!(obstacle.validate().is_err(), "{obstacle:?} was accepted");
        }
        assert!(PlaneObstacle::Wall { from: [0.0, 0.0], to: [1.0, 0.0], thickness: 0.1 }.validate().is_ok());
    }
}
