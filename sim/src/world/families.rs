//! World families: the kinds of world a seed generates (scattered, dense, narrow passages, open field, pop-up
//! obstacles), in the plane or in space, each checked feasible for the sTEB-inflated map.

use super::{default_goal_radius, default_start_speed, feasibility_cell, invalid, World, WorldError, WorldObstacle};
use super::{MAX_WORKSPACE_CELLS, MAX_WORKSPACE_SIDE};
use fastrack_online::geometry::{lerp, norm, sub, Point};
use fastrack_online::raw_path::{GridAStar, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::SpeedRule;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// The kind of world a seed generates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorldFamily {
    /// Obstacles of random kinds (circles, rectangles, walls; in space spheres, boxes, pillars) placed
    /// uniformly: `density` per 100 m^2 of ground, sizes in `size_range`.
    #[default]
    Scattered,
    /// Dense clutter: three times the density, of obstacles half the size.
    Dense,
    /// Narrow passages: walls across the workspace, about one per 10 m, each with one opening only a little
    /// wider than the inflated robot (`2 inflation` plus 0.6-1.2 m: a gap in the plane, a square window in
    /// space), and sparse small obstacles between them.
    Narrow,
    /// An open field: a quarter of the density, of obstacles two and a half times the size.
    Open,
    /// Obstacles that pop up late: a sparse scattered world plus 2-3 discs or balls placed on its shortest
    /// path farther than `popup_beyond` from the start, outside the sensor's reach when the run starts.
    PopUp,
}

impl WorldFamily {
    /// Every family, in the order tables list them.
    pub const ALL: [WorldFamily; 5] =
        [WorldFamily::Scattered, WorldFamily::Dense, WorldFamily::Narrow, WorldFamily::Open, WorldFamily::PopUp];

    /// Its name on the command line and in records.
    pub fn name(self) -> &'static str {
        match self {
            WorldFamily::Scattered => "scattered",
            WorldFamily::Dense => "dense",
            WorldFamily::Narrow => "narrow",
            WorldFamily::Open => "open",
            WorldFamily::PopUp => "pop-up",
        }
    }
}

impl std::fmt::Display for WorldFamily {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for WorldFamily {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|f| f.name() == text).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|f| f.name()).collect();
            format!("unknown world family `{text}`; one of {}", names.join(", "))
        })
    }
}

/// How to generate a world of `D` axes.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldSpec<const D: usize> {
    /// Seed (the same seed gives the same world).
    pub seed: u64,
    /// The kind of world.
    pub family: WorldFamily,
    /// Workspace width, depth (and height) (m), from the origin.
    pub size: Point<D>,
    /// Obstacles per 100 m^2 of the workspace's ground (x, y) (the scattered family's; the others scale it).
    pub density: f64,
    /// Range of an obstacle's size (m): circle or sphere radius, rectangle or box half side (geometric
    /// mean), a quarter of a wall's length, up to a pillar's radius (the scattered family's; the others scale
    /// it).
    pub size_range: (f64, f64),
    /// The inflation a generated world must be feasible for (the model's sTEB).
    pub inflation: f64,
    /// Pop-up obstacles lie on the shortest path, farther than this from the start (m): beyond the sensor's
    /// reach at the start (the simulator's default range, twice the dTEB at `beta_u`, is 4.0 m on
    /// `dubins4d`/4).
    pub popup_beyond: f64,
    /// Worlds drawn before giving up.
    pub attempts: usize,
}

impl<const D: usize> Default for WorldSpec<D> {
    /// A scattered world 30 m by 20 m (by 10 m high in space: the quadcopter's bound at `beta_u` is about
    /// 4.5 m, so a lower world leaves FaSTrack at `beta_u` no free space between floor and ceiling).
    fn default() -> Self {
        const { assert!(D == 2 || D == 3, "worlds lie in the plane or in space") };
        Self {
            seed: 1,
            family: WorldFamily::Scattered,
            size: std::array::from_fn(|axis| [30.0, 20.0, 10.0][axis]),
            density: 2.0,
            size_range: (0.4, 1.5),
            inflation: 1.0,
            popup_beyond: 6.0,
            attempts: 200,
        }
    }
}

impl<const D: usize> WorldSpec<D> {
    /// A feasible world of the spec's family: start and goal at the middle of the left and right edges (and
    /// half way up), obstacles drawn as the family says (in space within the floor and the ceiling),
    /// redrawn until the sTEB-inflated map has a path. The tracker starts at 0.5 m/s along +x in the plane,
    /// at rest in space.
    pub fn generate<O: WorldObstacle<D>>(&self) -> Result<World<O, D>, WorldError> {
        let (lo, hi) = self.size_range;
        if !(lo > 0.0 && lo <= hi && hi.is_finite() && self.density >= 0.0 && self.density.is_finite()) {
            return invalid(
                "spec",
                format!(
                    "size range {:?} must be positive and increasing, density {} >= 0",
                    self.size_range, self.density
                ),
            );
        }
        if !self.size.iter().all(|&side| side > 4.0 && side <= MAX_WORKSPACE_SIDE) {
            return invalid(
                "spec.size",
                format!(
                    "{:?}: the workspace must be more than 4 m and at most {MAX_WORKSPACE_SIDE} m each way",
                    self.size
                ),
            );
        }
        if !(self.inflation.is_finite() && self.inflation >= 0.0 && self.popup_beyond.is_finite()) {
            return invalid(
                "spec",
                format!("inflation {} must be >= 0, pop-up distance {} finite", self.inflation, self.popup_beyond),
            );
        }
        let cells: f64 = self.size.iter().map(|side| side / feasibility_cell::<D>()).product();
        if cells > MAX_WORKSPACE_CELLS {
            return invalid(
                "spec.size",
                format!("{:?}: more than {MAX_WORKSPACE_CELLS} cells for the planner", self.size),
            );
        }
        let mut rng = StdRng::seed_from_u64(self.seed);
        let bounds = ([0.0; D], self.size);
        let middle: Point<D> = self.size.map(|side| side / 2.0);
        for _ in 0..self.attempts {
            let mut obstacles = O::enclosure(bounds);
            obstacles.extend(self.obstacles(&mut rng, bounds));
            let world = World {
                min: bounds.0,
                max: bounds.1,
                start: std::array::from_fn(|axis| if axis == 0 { 2.0 } else { middle[axis] }),
                start_heading: std::f64::consts::FRAC_PI_2,
                // A car starts rolling; a quadcopter starts hovering.
                start_speed: if D == 2 { default_start_speed() } else { 0.0 },
                goal: std::array::from_fn(|axis| if axis == 0 { self.size[0] - 2.0 } else { middle[axis] }),
                goal_radius: default_goal_radius(),
                obstacles,
            };
            if world.validate().is_err() || world.check_feasible(self.inflation).is_err() {
                continue;
            }
            if self.family != WorldFamily::PopUp {
                return Ok(world);
            }
            if let Some(world) = self.with_popups(world, &mut rng) {
                return Ok(world);
            }
        }
        Err(WorldError::Generation { attempts: self.attempts })
    }

    /// The obstacles of one draw in `bounds` (the pop-up family's before its pop-ups).
    fn obstacles<O: WorldObstacle<D>>(&self, rng: &mut StdRng, bounds: (Point<D>, Point<D>)) -> Vec<O> {
        let size = self.size;
        let (lo, hi) = self.size_range;
        let count = |density: f64| (density * size[0] * size[1] / 100.0).round() as usize;
        let scattered = |rng: &mut StdRng, density: f64, range: (f64, f64)| -> Vec<O> {
            (0..count(density)).map(|_| O::random(rng, bounds, range)).collect()
        };
        match self.family {
            WorldFamily::Scattered => scattered(rng, self.density, (lo, hi)),
            WorldFamily::Dense => scattered(rng, 3.0 * self.density, (0.5 * lo, 0.5 * hi)),
            WorldFamily::Open => scattered(rng, 0.25 * self.density, (2.5 * lo, 2.5 * hi)),
            WorldFamily::PopUp => scattered(rng, 0.5 * self.density, (lo, hi)),
            WorldFamily::Narrow => {
                let walls = ((size[0] / 10.0).round() as usize).max(1);
                let mut obstacles = scattered(rng, 0.25 * self.density, (0.5 * lo, 0.5 * hi));
                for k in 1..=walls {
                    let x = size[0] * k as f64 / (walls + 1) as f64;
                    let opening = 2.0 * self.inflation + rng.random_range(0.6..1.2);
                    obstacles.extend(O::wall_with_opening(rng, bounds, x, opening));
                }
                obstacles
            }
        }
    }

    /// `world` with 2-3 obstacles on its shortest path farther than `popup_beyond` from the start (at least
    /// 3 m apart and 3 m short of the goal), if it stays feasible.
    fn with_popups<O: WorldObstacle<D>>(&self, mut world: World<O, D>, rng: &mut StdRng) -> Option<World<O, D>> {
        let request = PlanRequest {
            start: world.start,
            goal: world.goal,
            obstacles: &world.obstacles,
            inflation: self.inflation,
            bounds: world.bounds(),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        let path = GridAStar { cell: feasibility_cell::<D>() }.plan(&request).ok()?;
        let along = arc_lengths(&path);
        let total = *along.last()?;
        let wanted = rng.random_range(2..=3);
        let mut placed = Vec::new();
        let mut s = self.popup_beyond + rng.random_range(0.0..1.0);
        while placed.len() < wanted && s < total - 3.0 {
            let point = point_at(&path, &along, s);
            let mut center = point;
            center[1] += rng.random_range(-0.3..0.3);
            let popup = O::ball(center, rng.random_range(0.4..1.0));
            // Out of the sensor's reach at the start, whatever the path's detours.
            if popup.distance(world.start) > self.popup_beyond {
                placed.push(popup);
            }
            s += rng.random_range(3.0..6.0);
        }
        if placed.len() < 2 {
            return None;
        }
        world.obstacles.extend(placed);
        (world.validate().is_ok() && world.check_feasible(self.inflation).is_ok()).then_some(world)
    }
}

/// Arc length from the first point to each point of `path`.
fn arc_lengths<const D: usize>(path: &[Point<D>]) -> Vec<f64> {
    let mut along = Vec::with_capacity(path.len());
    let mut s = 0.0;
    for (i, p) in path.iter().enumerate() {
        if i > 0 {
            s += norm(sub(*p, path[i - 1]));
        }
        along.push(s);
    }
    along
}

/// The point at arc length `s` along `path` (`along`: its arc lengths), clamped to its ends.
fn point_at<const D: usize>(path: &[Point<D>], along: &[f64], s: f64) -> Point<D> {
    let i = along.partition_point(|&a| a < s).clamp(1, path.len() - 1);
    let (a, b) = (path[i - 1], path[i]);
    let span = along[i] - along[i - 1];
    let t = if span > 0.0 { ((s - along[i - 1]) / span).clamp(0.0, 1.0) } else { 0.0 };
    lerp(a, b, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::PlaneWorld;
    use fastrack_online::geometry::{Obstacle, PlaneObstacle, SpaceObstacle};

    #[test]
    fn generated_worlds_are_seeded_and_feasible() {
        let spec = WorldSpec { seed: 7, inflation: 0.9, ..WorldSpec::default() };
        let (a, b): (PlaneWorld, PlaneWorld) = (spec.generate().unwrap(), spec.generate().unwrap());
        assert_eq!(a, b, "same seed, same world");
        assert_ne!(a, WorldSpec { seed: 8, ..spec.clone() }.generate().unwrap());
        a.check_feasible(0.9).unwrap();
        assert_eq!(a.obstacles.len(), 12, "2 per 100 m^2 of 600 m^2");
        let impossible = WorldSpec { density: 40.0, attempts: 3, ..spec };
        assert!(matches!(impossible.generate::<PlaneObstacle>(), Err(WorldError::Generation { attempts: 3 })));
    }

    #[test]
    fn every_family_generates_seeded_feasible_worlds_of_its_kind_in_the_plane() {
        let inflation = 0.75;
        let spec = |family, seed| WorldSpec { seed, family, inflation, ..WorldSpec::default() };
        for family in WorldFamily::ALL {
            assert_eq!(family.name().parse::<WorldFamily>(), Ok(family));
            for seed in 1..=3 {
                let world: PlaneWorld =
                    spec(family, seed).generate().unwrap_or_else(|e| panic!("{family} seed {seed}: {e}"));
                assert_eq!(world, spec(family, seed).generate().unwrap(), "{family}: same seed, same world");
                world.check_feasible(inflation).unwrap();
                let n = world.obstacles.len();
                match family {
                    WorldFamily::Scattered => assert_eq!(n, 12),
                    WorldFamily::Dense => assert_eq!(n, 36, "three times 12"),
                    WorldFamily::Open => {
                        assert_eq!(n, 3, "a quarter of 12");
                        assert!(world.obstacles.iter().all(|o| size_of(o) >= 1.0 - 1e-9), "{:?}", world.obstacles);
                    }
                    WorldFamily::Narrow => {
                        // 3 walls of two rectangles each, across the whole height but for one gap.
                        let walls: Vec<&PlaneObstacle> = world.obstacles[n - 6..].iter().collect();
                        for pair in walls.chunks(2) {
                            let (PlaneObstacle::Rectangle { max: low, .. }, PlaneObstacle::Rectangle { min: high, .. }) =
                                (pair[0], pair[1])
                            else {
                                panic!("a wall is two rectangles: {pair:?}");
                            };
                            let gap = high[1] - low[1];
                            assert!((2.0 * inflation + 0.6..2.0 * inflation + 1.2).contains(&gap), "gap {gap}");
                        }
                    }
                    WorldFamily::PopUp => {
                        // The base world's 6 obstacles, then pop-ups on its shortest path out of reach.
                        let (base, popups) = world.obstacles.split_at(6);
                        assert!((2..=3).contains(&popups.len()), "{} pop-ups", popups.len());
                        let request = PlanRequest {
                            start: world.start,
                            goal: world.goal,
                            obstacles: base,
                            inflation,
                            bounds: world.bounds(),
                            speeds: &[],
                            rule: SpeedRule::HalfDistance,
                        };
                        let path = GridAStar::default().plan(&request).unwrap();
                        for popup in popups {
                            assert!(popup.distance(world.start) > 6.0, "{popup:?}");
                            let on_path = path.windows(2).any(|s| popup.segment_distance(s[0], s[1]) == 0.0);
                            assert!(on_path, "{popup:?} blocks the base world's path");
                        }
                    }
                }
            }
        }
        let unknown = "maze".parse::<WorldFamily>().unwrap_err();
        assert!(unknown.contains("scattered, dense, narrow, open, pop-up"), "{unknown}");
    }

    #[test]
    fn every_family_generates_seeded_feasible_worlds_of_its_kind_in_space() {
        let inflation = 0.75;
        let spec = |family, seed| WorldSpec::<3> { seed, family, inflation, ..WorldSpec::default() };
        for family in WorldFamily::ALL {
            let world: World<SpaceObstacle, 3> = spec(family, 1).generate().unwrap_or_else(|e| panic!("{family}: {e}"));
            assert_eq!(world, spec(family, 1).generate().unwrap(), "{family}: same seed, same world");
            world.check_feasible(inflation).unwrap();
            assert_eq!((world.start, world.goal), ([2.0, 10.0, 5.0], [28.0, 10.0, 5.0]));
            assert_eq!(world.start_speed, 0.0, "a quadcopter starts hovering");
            let (enclosure, own) = world.obstacles.split_at(2);
            assert_eq!(enclosure, [SpaceObstacle::Floor { height: 0.0 }, SpaceObstacle::Ceiling { height: 10.0 }]);
            let n = own.len();
            match family {
                WorldFamily::Scattered => assert_eq!(n, 12, "2 per 100 m^2 of 600 m^2 of ground"),
                WorldFamily::Dense => assert_eq!(n, 36),
                WorldFamily::Open => assert_eq!(n, 3),
                WorldFamily::Narrow => {
                    // 3 walls of four boxes each around a square window.
                    for wall in own[n - 12..].chunks(4) {
                        let [SpaceObstacle::Box { max: left, .. }, SpaceObstacle::Box { min: right, .. }, SpaceObstacle::Box { max: below, .. }, SpaceObstacle::Box { min: above, .. }] =
                            wall
                        else {
                            panic!("a wall is four boxes: {wall:?}");
                        };
                        let (wide, high) = (right[1] - left[1], above[2] - below[2]);
                        assert!((wide - high).abs() < 1e-12, "a square window: {wide} x {high}");
                        assert!((2.0 * inflation + 0.6..2.0 * inflation + 1.2).contains(&wide), "window {wide}");
                    }
                }
                WorldFamily::PopUp => {
                    let popups = &own[6..];
                    assert!((2..=3).contains(&popups.len()), "{} pop-ups", popups.len());
                    for popup in popups {
                        assert!(matches!(popup, SpaceObstacle::Sphere { .. }), "{popup:?}");
                        assert!(popup.distance(world.start) > 6.0, "{popup:?} is within the sensor's first reach");
                    }
                }
            }
        }
    }

    /// The size the generator drew an obstacle at: a circle's radius, the geometric mean of a rectangle's
    /// half sides, a quarter of a wall's length.
    fn size_of(obstacle: &PlaneObstacle) -> f64 {
        match obstacle {
            PlaneObstacle::Circle { radius, .. } => *radius,
            PlaneObstacle::Rectangle { min, max } => 0.5 * ((max[0] - min[0]) * (max[1] - min[1])).sqrt(),
            PlaneObstacle::Wall { from, to, .. } => 0.25 * norm(sub(*to, *from)),
        }
    }
}
