//! What generating a world needs of each dimension's obstacles: a random obstacle, a wall across the
//! workspace with one opening, a pop-up ball, and what bounds every world (nothing in the plane; the floor
//! and the ceiling in space).

use fastrack_online::geometry::{Obstacle, PlaneObstacle, Point, SpaceObstacle};
use rand::rngs::StdRng;
use rand::Rng;
use serde::de::DeserializeOwned;
use serde::Serialize;

/// Obstacles a world of `D` axes is made of, and how the generator draws them.
pub trait WorldObstacle<const D: usize>: Obstacle<D> + Serialize + DeserializeOwned + 'static {
    /// The obstacles every generated world of the workspace `(min, max)` holds besides its own: none in the
    /// plane; in space the floor at the lowest height and the ceiling at the highest.
    fn enclosure(bounds: (Point<D>, Point<D>)) -> Vec<Self>;

    /// One obstacle of a random kind, placed uniformly in the workspace, of a size drawn from `sizes`: a
    /// circle's or sphere's radius, a rectangle's or box's half side (geometric mean), a quarter of a wall's
    /// length, a pillar's radius between half of it and all of it.
    fn random(rng: &mut StdRng, bounds: (Point<D>, Point<D>), sizes: (f64, f64)) -> Self;

    /// A wall across the workspace at `x` (0.3 m thick, past its sides), open only where a square of side
    /// `opening` (in the plane: a gap of that width) lets the robot through, placed at random.
    fn wall_with_opening(rng: &mut StdRng, bounds: (Point<D>, Point<D>), x: f64, opening: f64) -> Vec<Self>;

    /// A disc or ball.
    fn ball(center: Point<D>, radius: f64) -> Self;
}

/// Half the thickness of a narrow-passage wall (m).
const WALL_HALF_THICKNESS: f64 = 0.15;

/// Where an opening of `opening` starts along an axis from `lo` to `hi`, keeping 1 m from both ends (at 1 m
/// from the low end when the axis is too short for that).
fn opening_start(rng: &mut StdRng, lo: f64, hi: f64, opening: f64) -> f64 {
    let (first, last) = (lo + 1.0, hi - 1.0 - opening);
    if last > first {
        rng.random_range(first..last)
    } else {
        first
    }
}

impl WorldObstacle<2> for PlaneObstacle {
    fn enclosure(_: (Point<2>, Point<2>)) -> Vec<Self> {
        Vec::new()
    }

    fn random(rng: &mut StdRng, (lo, hi): (Point<2>, Point<2>), sizes: (f64, f64)) -> Self {
        let center = [rng.random_range(lo[0]..hi[0]), rng.random_range(lo[1]..hi[1])];
        let extent = rng.random_range(sizes.0..=sizes.1);
        match rng.random_range(0..3) {
            0 => PlaneObstacle::Circle { center, radius: extent },
            1 => {
                let aspect: f64 = rng.random_range(0.5..2.0);
                let (hx, hy) = (extent * aspect.sqrt(), extent / aspect.sqrt());
                PlaneObstacle::Rectangle {
                    min: [center[0] - hx, center[1] - hy],
                    max: [center[0] + hx, center[1] + hy],
                }
            }
            _ => {
                let angle = rng.random_range(0.0..std::f64::consts::PI);
                let (dx, dy) = (2.0 * extent * angle.cos(), 2.0 * extent * angle.sin());
                PlaneObstacle::Wall {
                    from: [center[0] - dx, center[1] - dy],
                    to: [center[0] + dx, center[1] + dy],
                    thickness: rng.random_range(0.1..0.3),
                }
            }
        }
    }

    fn wall_with_opening(rng: &mut StdRng, (lo, hi): (Point<2>, Point<2>), x: f64, opening: f64) -> Vec<Self> {
        let low = opening_start(rng, lo[1], hi[1], opening);
        let h = WALL_HALF_THICKNESS;
        vec![
            PlaneObstacle::Rectangle { min: [x - h, lo[1] - 1.0], max: [x + h, low] },
            PlaneObstacle::Rectangle { min: [x - h, low + opening], max: [x + h, hi[1] + 1.0] },
        ]
    }

    fn ball(center: Point<2>, radius: f64) -> Self {
        PlaneObstacle::Circle { center, radius }
    }
}

impl WorldObstacle<3> for SpaceObstacle {
    fn enclosure((lo, hi): (Point<3>, Point<3>)) -> Vec<Self> {
        vec![SpaceObstacle::Floor { height: lo[2] }, SpaceObstacle::Ceiling { height: hi[2] }]
    }

    fn random(rng: &mut StdRng, (lo, hi): (Point<3>, Point<3>), sizes: (f64, f64)) -> Self {
        let center: Point<3> = std::array::from_fn(|axis| rng.random_range(lo[axis]..hi[axis]));
        let extent = rng.random_range(sizes.0..=sizes.1);
        match rng.random_range(0..3) {
            0 => SpaceObstacle::Sphere { center, radius: extent },
            1 => {
                let aspect: f64 = rng.random_range(0.5..2.0);
                let half = [extent * aspect.sqrt(), extent / aspect.sqrt(), extent * rng.random_range(0.5..2.0)];
                SpaceObstacle::Box {
                    min: std::array::from_fn(|axis| center[axis] - half[axis]),
                    max: std::array::from_fn(|axis| center[axis] + half[axis]),
                }
            }
            _ => {
                // From the floor to somewhere between half the height and past the ceiling.
                let top = lo[2] + (hi[2] - lo[2]) * rng.random_range(0.5..1.2);
                let radius = extent * rng.random_range(0.5..1.0);
                SpaceObstacle::Pillar { center: [center[0], center[1]], radius, bottom: lo[2] - 1.0, top }
            }
        }
    }

    fn wall_with_opening(rng: &mut StdRng, (lo, hi): (Point<3>, Point<3>), x: f64, opening: f64) -> Vec<Self> {
        let (y, z) = (opening_start(rng, lo[1], hi[1], opening), opening_start(rng, lo[2], hi[2], opening));
        let (x0, x1) = (x - WALL_HALF_THICKNESS, x + WALL_HALF_THICKNESS);
        let (y_lo, y_hi, z_lo, z_hi) = (lo[1] - 1.0, hi[1] + 1.0, lo[2] - 1.0, hi[2] + 1.0);
        vec![
            // Beside the opening, across the whole height.
            SpaceObstacle::Box { min: [x0, y_lo, z_lo], max: [x1, y, z_hi] },
            SpaceObstacle::Box { min: [x0, y + opening, z_lo], max: [x1, y_hi, z_hi] },
            // Below and above it.
            SpaceObstacle::Box { min: [x0, y, z_lo], max: [x1, y + opening, z] },
            SpaceObstacle::Box { min: [x0, y, z + opening], max: [x1, y + opening, z_hi] },
        ]
    }

    fn ball(center: Point<3>, radius: f64) -> Self {
        SpaceObstacle::Sphere { center, radius }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_online::geometry::{clearance, segment_is_free};
    use rand::SeedableRng;

    #[test]
    fn a_wall_in_space_lets_through_only_its_opening() {
        let mut rng = StdRng::seed_from_u64(3);
        let bounds = ([0.0, 0.0, 0.0], [30.0, 20.0, 6.0]);
        let wall = SpaceObstacle::wall_with_opening(&mut rng, bounds, 10.0, 2.0);
        // A point well inside the wall's plane away from the opening is blocked; the opening's centre, found
        // as the point of the plane farthest from the wall, keeps 1 m (half the opening) from it.
        let mut best = ([0.0; 3], 0.0);
        for j in 0..=200 {
            for k in 0..=60 {
                let p = [10.0, 20.0 * j as f64 / 200.0, 6.0 * k as f64 / 60.0];
                let gap = clearance(&wall, p);
                if gap > best.1 {
                    best = (p, gap);
                }
            }
        }
        assert!((best.1 - 1.0).abs() < 0.06, "the opening's centre keeps {} m: {best:?}", best.1);
        let (through, beside) = (best.0, [10.0, (best.0[1] + 10.0) % 20.0, best.0[2]]);
        assert!(segment_is_free(&wall, [5.0, through[1], through[2]], [15.0, through[1], through[2]], 0.9));
        assert!(!segment_is_free(&wall, [5.0, beside[1], beside[2]], [15.0, beside[1], beside[2]], 0.0));
    }

    #[test]
    fn random_solids_lie_in_the_workspace_and_exist() {
        let mut rng = StdRng::seed_from_u64(5);
        let bounds = ([0.0, 0.0, 0.0], [30.0, 20.0, 6.0]);
        let kinds: Vec<&str> = (0..60)
            .map(|_| {
                let obstacle = SpaceObstacle::random(&mut rng, bounds, (0.5, 1.0));
                obstacle.validate().unwrap();
                match obstacle {
                    SpaceObstacle::Sphere { .. } => "sphere",
                    SpaceObstacle::Box { .. } => "box",
                    SpaceObstacle::Pillar { bottom, .. } => {
                        assert!(bottom < 0.0, "a pillar stands on the floor");
                        "pillar"
                    }
                    other => panic!("{other:?} drawn"),
                }
            })
            .collect();
        for kind in ["sphere", "box", "pillar"] {
            assert!(kinds.contains(&kind), "no {kind} in 60 draws");
        }
        assert_eq!(SpaceObstacle::enclosure(bounds).len(), 2);
    }
}
