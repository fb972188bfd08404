//! Obstacles in space (`[x, y, z]`, z up): spheres, axis-aligned boxes, pillars (vertical cylinders), and the
//! floor and ceiling (the half-spaces below and above a height). Distances from points are closed forms;
//! from segments, closed forms for spheres and half-spaces and the convex minimum along the segment for boxes
//! and pillars.

use super::{norm, point_segment_distance, sub, Obstacle, ObstacleError, Point};
use serde::{Deserialize, Serialize};

/// One obstacle in space.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SpaceObstacle {
    /// A ball.
    Sphere {
        /// Centre.
        center: Point<3>,
        /// Radius (> 0).
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// The corner of smallest coordinates.
        min: Point<3>,
        /// The corner of largest coordinates.
        max: Point<3>,
    },
    /// A vertical cylinder: the points within `radius` of the vertical line through `center` (x, y), between
    /// the heights `bottom` and `top`.
    Pillar {
        /// The axis' position in the ground plane.
        center: [f64; 2],
        /// Radius (> 0).
        radius: f64,
        /// Lowest height.
        bottom: f64,
        /// Highest height (> bottom).
        top: f64,
    },
    /// Everything at or below `height`.
    Floor {
        /// The floor's surface.
        height: f64,
    },
    /// Everything at or above `height`.
    Ceiling {
        /// The ceiling's surface.
        height: f64,
    },
}

impl Obstacle<3> for SpaceObstacle {
    fn validate(&self) -> Result<(), ObstacleError> {
        let finite = |p: &[f64]| p.iter().all(|x| x.is_finite());
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let bad = |what: String| Err(ObstacleError(what));
        match self {
            SpaceObstacle::Sphere { center, radius } => {
                if !finite(center) {
                    return bad(format!("sphere center {center:?} must be finite"));
                }
                if !positive(*radius) {
                    return bad(format!("sphere radius = {radius}; must be a finite number > 0"));
                }
            }
            SpaceObstacle::Box { min, max } => {
                if !(finite(min) && finite(max)) {
                    return bad(format!("box corners {min:?}, {max:?} must be finite"));
                }
                if !(0..3).all(|axis| min[axis] < max[axis]) {
                    return bad(format!("box min {min:?} must lie below max {max:?} on every axis"));
                }
            }
            SpaceObstacle::Pillar { center, radius, bottom, top } => {
                if !finite(center) {
                    return bad(format!("pillar center {center:?} must be finite"));
                }
                if !positive(*radius) {
                    return bad(format!("pillar radius = {radius}; must be a finite number > 0"));
                }
                if !(bottom.is_finite() && top.is_finite() && bottom < top) {
                    return bad(format!("pillar bottom = {bottom}, top = {top}; must be finite with bottom < top"));
                }
            }
            SpaceObstacle::Floor { height } | SpaceObstacle::Ceiling { height } => {
                if !height.is_finite() {
                    return bad(format!("floor or ceiling height = {height}; must be finite"));
                }
            }
        }
        Ok(())
    }

    fn distance(&self, p: Point<3>) -> f64 {
        match self {
            SpaceObstacle::Sphere { center, radius } => (norm(sub(p, *center)) - radius).max(0.0),
            SpaceObstacle::Box { min, max } => {
                norm::<3>(std::array::from_fn(|axis| (min[axis] - p[axis]).max(p[axis] - max[axis]).max(0.0)))
            }
            SpaceObstacle::Pillar { center, radius, bottom, top } => {
                let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
                let radial = ((dx * dx + dy * dy).sqrt() - radius).max(0.0);
                let vertical = (bottom - p[2]).max(p[2] - top).max(0.0);
                (radial * radial + vertical * vertical).sqrt()
            }
            SpaceObstacle::Floor { height } => (p[2] - height).max(0.0),
            SpaceObstacle::Ceiling { height } => (height - p[2]).max(0.0),
        }
    }

    fn segment_distance(&self, a: Point<3>, b: Point<3>) -> f64 {
        match self {
            SpaceObstacle::Sphere { center, radius } => (point_segment_distance(*center, a, b) - radius).max(0.0),
            // Monotone in the height, so least at an end.
            SpaceObstacle::Floor { .. } | SpaceObstacle::Ceiling { .. } => self.distance(a).min(self.distance(b)),
            SpaceObstacle::Box { .. } | SpaceObstacle::Pillar { .. } => {
                super::convex_segment_minimum(|p| self.distance(p), a, b)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{lerp, segment_is_free};

    /// The least distance over 20,001 points of the segment.
    fn brute_segment_distance(obstacle: &SpaceObstacle, a: Point<3>, b: Point<3>) -> f64 {
        (0..=20_000).map(|k| obstacle.distance(lerp(a, b, k as f64 / 20_000.0))).fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn distances_match_closed_forms() {
        let sphere = SpaceObstacle::Sphere { center: [1.0, 1.0, 1.0], radius: 0.5 };
        assert!((sphere.distance([1.0, 3.0, 1.0]) - 1.5).abs() < 1e-12);
        assert_eq!(sphere.distance([1.2, 1.1, 0.9]), 0.0);
        let cuboid = SpaceObstacle::Box { min: [0.0, 0.0, 0.0], max: [2.0, 1.0, 1.0] };
        assert!((cuboid.distance([3.0, 2.0, 3.0]) - 6f64.sqrt()).abs() < 1e-12);
        assert!((cuboid.distance([1.0, 0.5, 1.25]) - 0.25).abs() < 1e-12);
        assert_eq!(cuboid.distance([1.0, 0.5, 0.5]), 0.0);
        let pillar = SpaceObstacle::Pillar { center: [0.0, 0.0], radius: 1.0, bottom: 0.0, top: 3.0 };
        assert!((pillar.distance([3.0, 0.0, 1.0]) - 2.0).abs() < 1e-12, "beside it");
        assert!((pillar.distance([0.5, 0.0, 4.0]) - 1.0).abs() < 1e-12, "above its top");
        assert!((pillar.distance([0.0, 4.0, 7.0]) - 5.0).abs() < 1e-12, "above and beside: 3-4-5");
        assert_eq!(pillar.distance([0.5, 0.5, 2.0]), 0.0);
        assert!((SpaceObstacle::Floor { height: 0.0 }.distance([5.0, 5.0, 1.5]) - 1.5).abs() < 1e-12);
        assert_eq!(SpaceObstacle::Floor { height: 0.0 }.distance([5.0, 5.0, -1.0]), 0.0);
        assert!((SpaceObstacle::Ceiling { height: 4.0 }.distance([0.0, 0.0, 1.5]) - 2.5).abs() < 1e-12);
    }

    #[test]
    fn segment_distances_match_a_brute_force_minimum() {
        let obstacles = [
            SpaceObstacle::Sphere { center: [1.0, 2.0, 0.0], radius: 0.5 },
            SpaceObstacle::Box { min: [0.0, 0.0, 0.0], max: [1.0, 1.0, 2.0] },
            SpaceObstacle::Pillar { center: [2.0, -1.0], radius: 0.3, bottom: 0.0, top: 1.0 },
            SpaceObstacle::Floor { height: -1.0 },
            SpaceObstacle::Ceiling { height: 5.0 },
        ];
        let segments = [
            ([-2.0, -1.0, 3.0], [3.0, 2.5, 0.5]),
            ([2.0, 2.0, 2.5], [4.0, -3.0, 1.5]),
            ([-1.0, 0.5, 1.0], [3.0, 0.5, 1.0]),
            ([0.5, 0.5, 2.5], [0.5, 0.5, 2.5]),
        ];
        for obstacle in &obstacles {
            for &(a, b) in &segments {
                let (exact, brute) = (obstacle.segment_distance(a, b), brute_segment_distance(obstacle, a, b));
                // The brute force samples every 1/20,000 of a segment of at most 6.2 m.
                assert!(exact <= brute + 1e-12 && brute - exact < 4e-4, "{obstacle:?} {a:?}-{b:?}: {exact} vs {brute}");
            }
        }
        // Crossing the box without an end inside it.
        assert_eq!(obstacles[1].segment_distance([-1.0, 0.5, 1.0], [3.0, 0.5, 1.0]), 0.0);
    }

    #[test]
    fn line_of_sight_sees_a_pillar_between_two_points() {
        let pillar = [SpaceObstacle::Pillar { center: [0.0, 0.0], radius: 0.5, bottom: 0.0, top: 2.0 }];
        assert!(!segment_is_free(&pillar, [-2.0, 0.0, 1.0], [2.0, 0.0, 1.0], 0.1), "through it");
        assert!(segment_is_free(&pillar, [-2.0, 0.0, 2.5], [2.0, 0.0, 2.5], 0.4), "0.5 m over its top");
        assert!(!segment_is_free(&pillar, [-2.0, 0.0, 2.5], [2.0, 0.0, 2.5], 0.5), "not more than 0.5 m over it");
        assert!(segment_is_free(&pillar, [-2.0, 1.0, 1.0], [2.0, 1.0, 1.0], 0.49), "0.5 m beside it");
    }

    #[test]
    fn impossible_obstacles_are_named() {
        let bad = [
            (SpaceObstacle::Sphere { center: [0.0, f64::NAN, 0.0], radius: 1.0 }, "sphere center"),
            (SpaceObstacle::Sphere { center: [0.0; 3], radius: 0.0 }, "sphere radius"),
            (SpaceObstacle::Box { min: [0.0, 0.0, 1.0], max: [1.0, 1.0, 1.0] }, "box min"),
            (SpaceObstacle::Pillar { center: [0.0, 0.0], radius: -1.0, bottom: 0.0, top: 1.0 }, "pillar radius"),
            (SpaceObstacle::Pillar { center: [0.0, 0.0], radius: 1.0, bottom: 2.0, top: 1.0 }, "pillar bottom"),
            (SpaceObstacle::Ceiling { height: f64::INFINITY }, "height"),
        ];
        for (obstacle, field) in bad {
            let why = obstacle.validate().expect_err("an impossible obstacle was accepted").0;
            assert!(why.contains(field), "{why} does not name {field}");
        }
        let file = r#"{"kind": "pillar", "center": [1, 2], "radius": 0.4, "bottom": 0, "top": 3}"#;
        let pillar: SpaceObstacle = serde_json::from_str(file).unwrap();
        assert!(pillar.validate().is_ok());
        assert!(serde_json::from_str::<SpaceObstacle>(r#"{"kind": "cone", "radius": 1}"#).is_err());
    }
}
