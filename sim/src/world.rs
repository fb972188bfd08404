//! 2-D worlds: a workspace, a start and a goal, and obstacles (circles, rectangles, walls), read from TOML or
//! JSON or generated from a seed; checked to be feasible for the sTEB-inflated map.

use fastrack_online::geometry::{clearance, norm, sub, Obstacle, PlaneObstacle, Point};
use fastrack_online::raw_path::{GridAStar, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::SpeedRule;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A world the simulated robot drives through.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct World {
    /// Lower-left corner of the workspace (m).
    pub min: Point,
    /// Upper-right corner (m).
    pub max: Point,
    /// The tracker's start position; the planner starts there too.
    pub start: Point,
    /// The tracker's start heading (rad; dubins4d: 0 along +y, pi/2 along +x).
    #[serde(default)]
    pub start_heading: f64,
    /// The tracker's start speed (m/s).
    #[serde(default = "default_start_speed")]
    pub start_speed: f64,
    /// The goal.
    pub goal: Point,
    /// The run ends when the tracker is this close to the goal (m). The default, 1.5 m, exceeds the circle
    /// a Dubins car holds around a planner at rest under the learned control (about 1.1 m on `dubins4d`/3):
    /// no tracker is guaranteed closer to its planner than the sTEB.
    #[serde(default = "default_goal_radius")]
    pub goal_radius: f64,
    /// The obstacles.
    #[serde(default)]
    pub obstacles: Vec<PlaneObstacle>,
}

fn default_start_speed() -> f64 {
    0.5
}

fn default_goal_radius() -> f64 {
    1.5
}

/// A world that cannot be used: which field, and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// The file does not parse (unknown keys, wrong types).
    #[error("{path}: {problem}")]
    Parse {
        /// The file.
        path: String,
        /// The parser's message.
        problem: String,
    },
    /// A value is out of range.
    #[error("world field `{field}`: {problem}")]
    Invalid {
        /// The field, e.g. `obstacles[2]`.
        field: String,
        /// What is wrong and what is allowed.
        problem: String,
    },
    /// No path from the start to the goal keeps the inflation from every obstacle.
    #[error(
        "no path from the start {start:?} to the goal {goal:?} keeps {inflation} m (the sTEB) from every obstacle"
    )]
    Infeasible {
        /// The start.
        start: Point,
        /// The goal.
        goal: Point,
        /// The inflation.
        inflation: f64,
    },
    /// Generation found no feasible world.
    #[error("no feasible world after {attempts} attempts with these settings (fewer or smaller obstacles?)")]
    Generation {
        /// Worlds drawn.
        attempts: usize,
    },
}

/// Longest side of a world's workspace (m): the planner searches a 0.1 m grid of it, at most 2,000 cells a
/// side.
pub const MAX_WORKSPACE_SIDE: f64 = 200.0;
/// Most obstacles in a world: every planner step measures the clearance to each.
pub const MAX_OBSTACLES: usize = 10_000;

fn invalid<T>(field: impl Into<String>, problem: impl Into<String>) -> Result<T, WorldError> {
    Err(WorldError::Invalid { field: field.into(), problem: problem.into() })
}

impl World {
    /// Reads a world from a `.toml` or `.json` file (by extension) and checks its values.
    pub fn load(path: &Path) -> Result<Self, WorldError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| WorldError::Io { path: name.clone(), source })?;
        let parse = |problem: String| WorldError::Parse { path: name.clone(), problem };
        let world: World = if path.extension().is_some_and(|x| x == "json") {
            serde_json::from_str(&text).map_err(|e| parse(e.to_string()))?
        } else {
            toml::from_str(&text).map_err(|e| parse(e.to_string()))?
        };
        world.validate()?;
        Ok(world)
    }

    /// The world as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("a world serialises")
    }

    /// The workspace as `(min, max)`.
    pub fn bounds(&self) -> (Point, Point) {
        (self.min, self.max)
    }

    /// True if `p` lies in the workspace.
    pub fn contains(&self, p: Point) -> bool {
        p[0] >= self.min[0] && p[0] <= self.max[0] && p[1] >= self.min[1] && p[1] <= self.max[1]
    }

    /// Checks every value: finite numbers, a workspace with area and sides of at most
    /// [`MAX_WORKSPACE_SIDE`], at most [`MAX_OBSTACLES`] obstacles that exist, start and goal inside the
    /// workspace and outside every obstacle.
    pub fn validate(&self) -> Result<(), WorldError> {
        let finite = |p: &Point| p.iter().all(|x| x.is_finite());
        if !(finite(&self.min) && finite(&self.max) && self.min[0] < self.max[0] && self.min[1] < self.max[1]) {
            return invalid(
                "min/max",
                format!("the workspace {:?}..{:?} must be finite with min below max", self.min, self.max),
            );
        }
        if (0..2).any(|i| self.max[i] - self.min[i] > MAX_WORKSPACE_SIDE) {
            return invalid(
                "min/max",
                format!("the workspace {:?}..{:?} must be at most {MAX_WORKSPACE_SIDE} m a side", self.min, self.max),
            );
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return invalid("obstacles", format!("{} obstacles; at most {MAX_OBSTACLES}", self.obstacles.len()));
        }
        for (field, p) in [("start", self.start), ("goal", self.goal)] {
            if !(finite(&p) && self.contains(p)) {
                return invalid(field, format!("{p:?} must lie in the workspace {:?}..{:?}", self.min, self.max));
            }
        }
        if !(self.start_heading.is_finite() && self.start_speed.is_finite() && self.start_speed >= 0.0) {
            return invalid("start_heading/start_speed", "must be finite, the speed >= 0");
        }
        if !(self.goal_radius.is_finite() && self.goal_radius > 0.0) {
            return invalid("goal_radius", format!("{} must be > 0", self.goal_radius));
        }
        for (i, obstacle) in self.obstacles.iter().enumerate() {
            obstacle.validate().or_else(|e| invalid(format!("obstacles[{i}]"), e.0))?;
            for (field, p) in [("start", self.start), ("goal", self.goal)] {
                if obstacle.distance(p) == 0.0 {
                    return invalid(field, format!("{p:?} lies inside obstacles[{i}]"));
                }
            }
        }
        Ok(())
    }

    /// Checks that start and goal keep more than `inflation` (the sTEB) from every obstacle and that a path
    /// between them does too, on the whole map.
    pub fn check_feasible(&self, inflation: f64) -> Result<(), WorldError> {
        for (field, p) in [("start", self.start), ("goal", self.goal)] {
            let gap = clearance(&self.obstacles, p);
            if gap <= inflation {
                return invalid(
                    field,
                    format!("{p:?} lies {gap:.3} m from an obstacle; it needs more than the sTEB, {inflation} m"),
                );
            }
        }
        let request = PlanRequest {
            start: self.start,
            goal: self.goal,
            obstacles: &self.obstacles,
            inflation,
            bounds: self.bounds(),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        GridAStar::default().plan(&request).map(|_| ()).map_err(|_| WorldError::Infeasible {
            start: self.start,
            goal: self.goal,
            inflation,
        })
    }
}

/// The kind of world a seed generates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorldFamily {
    /// Obstacles of random kinds (circles, rectangles, walls) placed uniformly: `density` per 100 m^2,
    /// sizes in `size_range`.
    #[default]
    Scattered,
    /// Dense clutter: three times the density, of obstacles half the size.
    Dense,
    /// Narrow passages: walls across the workspace, about one per 10 m, each with one gap only a little
    /// wider than the inflated robot (`2 inflation` plus 0.6-1.2 m), and sparse small obstacles between them.
    Narrow,
    /// An open field: a quarter of the density, of obstacles two and a half times the size.
    Open,
    /// Obstacles that pop up late: a sparse scattered world plus 2-3 obstacles placed on its shortest path
    /// farther than `popup_beyond` from the start, outside the sensor's reach when the run starts.
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

/// How to generate a world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldSpec {
    /// Seed (the same seed gives the same world).
    pub seed: u64,
    /// The kind of world.
    pub family: WorldFamily,
    /// Workspace width and height (m), from the origin.
    pub size: Point,
    /// Obstacles per 100 m^2 of workspace (the scattered family's; the others scale it).
    pub density: f64,
    /// Range of an obstacle's size (m): circle radius, rectangle half side (geometric mean), a quarter of a
    /// wall's length (the scattered family's; the others scale it).
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

impl Default for WorldSpec {
    fn default() -> Self {
        Self {
            seed: 1,
            family: WorldFamily::Scattered,
            size: [30.0, 20.0],
            density: 2.0,
            size_range: (0.4, 1.5),
            inflation: 1.0,
            popup_beyond: 6.0,
            attempts: 200,
        }
    }
}

impl WorldSpec {
    /// A feasible world of the spec's family: start and goal at the middle of the left and right edges,
    /// obstacles drawn as the family says, redrawn until the sTEB-inflated map has a path.
    pub fn generate(&self) -> Result<World, WorldError> {
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
        if !(self.size[0] > 4.0 && self.size[1] > 4.0) {
            return invalid("spec.size", format!("{:?}: the workspace must be more than 4 m each way", self.size));
        }
        if !(self.inflation.is_finite() && self.inflation >= 0.0 && self.popup_beyond.is_finite()) {
            return invalid(
                "spec",
                format!("inflation {} must be >= 0, pop-up distance {} finite", self.inflation, self.popup_beyond),
            );
        }
        let mut rng = StdRng::seed_from_u64(self.seed);
        let (w, h) = (self.size[0], self.size[1]);
        for _ in 0..self.attempts {
            let world = World {
                min: [0.0, 0.0],
                max: [w, h],
                start: [2.0, h / 2.0],
                start_heading: std::f64::consts::FRAC_PI_2,
                start_speed: default_start_speed(),
                goal: [w - 2.0, h / 2.0],
                goal_radius: default_goal_radius(),
                obstacles: self.obstacles(&mut rng),
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

    /// The obstacles of one draw (the pop-up family's before its pop-ups).
    fn obstacles(&self, rng: &mut StdRng) -> Vec<PlaneObstacle> {
        let size = self.size;
        let (lo, hi) = self.size_range;
        let count = |density: f64| (density * size[0] * size[1] / 100.0).round() as usize;
        let scattered = |rng: &mut StdRng, density: f64, range: (f64, f64)| -> Vec<PlaneObstacle> {
            (0..count(density)).map(|_| random_obstacle(rng, size, range)).collect()
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
                    let gap = 2.0 * self.inflation + rng.random_range(0.6..1.2);
                    let low = rng.random_range(1.0..(size[1] - 1.0 - gap).max(1.0 + f64::EPSILON));
                    let half = 0.15;
                    obstacles.push(PlaneObstacle::Rectangle { min: [x - half, -1.0], max: [x + half, low] });
                    obstacles
                        .push(PlaneObstacle::Rectangle { min: [x - half, low + gap], max: [x + half, size[1] + 1.0] });
                }
                obstacles
            }
        }
    }

    /// `world` with 2-3 obstacles on its shortest path farther than `popup_beyond` from the start (at least
    /// 3 m apart and 3 m short of the goal), if it stays feasible.
    fn with_popups(&self, mut world: World, rng: &mut StdRng) -> Option<World> {
        let request = PlanRequest {
            start: world.start,
            goal: world.goal,
            obstacles: &world.obstacles,
            inflation: self.inflation,
            bounds: world.bounds(),
            speeds: &[],
            rule: SpeedRule::HalfDistance,
        };
        let path = GridAStar::default().plan(&request).ok()?;
        let along = arc_lengths(&path);
        let total = *along.last()?;
        let wanted = rng.random_range(2..=3);
        let mut placed = Vec::new();
        let mut s = self.popup_beyond + rng.random_range(0.0..1.0);
        while placed.len() < wanted && s < total - 3.0 {
            let point = point_at(&path, &along, s);
            let offset = rng.random_range(-0.3..0.3);
            let popup =
                PlaneObstacle::Circle { center: [point[0], point[1] + offset], radius: rng.random_range(0.4..1.0) };
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
fn arc_lengths(path: &[Point]) -> Vec<f64> {
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
fn point_at(path: &[Point], along: &[f64], s: f64) -> Point {
    let i = along.partition_point(|&a| a < s).clamp(1, path.len() - 1);
    let (a, b) = (path[i - 1], path[i]);
    let span = along[i] - along[i - 1];
    let t = if span > 0.0 { ((s - along[i - 1]) / span).clamp(0.0, 1.0) } else { 0.0 };
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

fn random_obstacle(rng: &mut StdRng, size: Point, (lo, hi): (f64, f64)) -> PlaneObstacle {
    let center = [rng.random_range(0.0..size[0]), rng.random_range(0.0..size[1])];
    let extent = rng.random_range(lo..=hi);
    match rng.random_range(0..3) {
        0 => PlaneObstacle::Circle { center, radius: extent },
        1 => {
            let aspect: f64 = rng.random_range(0.5..2.0);
            let (hx, hy) = (extent * aspect.sqrt(), extent / aspect.sqrt());
            PlaneObstacle::Rectangle { min: [center[0] - hx, center[1] - hy], max: [center[0] + hx, center[1] + hy] }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    const GOOD: &str = r#"
min = [0.0, 0.0]
max = [20.0, 10.0]
start = [1.0, 5.0]
goal = [19.0, 5.0]

[[obstacles]]
kind = "circle"
center = [10.0, 5.0]
radius = 1.0
"#;

    #[test]
    fn a_world_file_round_trips_and_is_feasible() {
        let (_dir, path) = write("w.toml", GOOD);
        let world = World::load(&path).unwrap();
        assert_eq!(world.obstacles.len(), 1);
        world.check_feasible(0.9).unwrap();
        let (_dir2, again) = write("again.toml", &world.to_toml());
        assert_eq!(World::load(&again).unwrap(), world);
        let (_dir3, json) = write("w.json", &serde_json::to_string(&world).unwrap());
        assert_eq!(World::load(&json).unwrap(), world);
    }

    #[test]
    fn bad_world_files_are_named() {
        let cases = [
            (GOOD.replace("radius = 1.0", "radius = -1.0"), "radius"),
            (GOOD.replace("goal = [19.0, 5.0]", "goal = [19.0, 5.0]\ncolour = \"red\""), "colour"),
            (GOOD.replace("start = [1.0, 5.0]", "start = [10.0, 5.2]"), "start"),
            (GOOD.replace("goal = [19.0, 5.0]", "goal = [25.0, 5.0]"), "goal"),
            (GOOD.replace("kind = \"circle\"", "kind = \"blob\""), "blob"),
            (GOOD.replace("max = [20.0, 10.0]", "max = [1e300, 10.0]"), "at most 200 m a side"),
        ];
        for (text, named) in cases {
            let (_dir, path) = write("bad.toml", &text);
            let error = World::load(&path).unwrap_err().to_string();
            assert!(error.contains(named), "{named}: {error}");
        }
        let missing = World::load(Path::new("/nonexistent/world.toml")).unwrap_err();
        assert!(matches!(missing, WorldError::Io { .. }));
        // A wall across the workspace: valid, but no path.
        let walled =
            format!("{GOOD}\n[[obstacles]]\nkind = \"wall\"\nfrom = [5.0, -1.0]\nto = [5.0, 11.0]\nthickness = 0.2\n");
        let (_dir, path) = write("walled.toml", &walled);
        let world = World::load(&path).unwrap();
        assert!(matches!(world.check_feasible(0.9), Err(WorldError::Infeasible { .. })));
        // A start too close to an obstacle for the sTEB.
        let near = GOOD.replace("center = [10.0, 5.0]", "center = [2.5, 5.0]");
        let (_dir, path) = write("near.toml", &near);
        let error = World::load(&path).unwrap().check_feasible(0.9).unwrap_err().to_string();
        assert!(error.contains("start"), "{error}");
    }

    #[test]
    fn generated_worlds_are_seeded_and_feasible() {
        let spec = WorldSpec { seed: 7, inflation: 0.9, ..WorldSpec::default() };
        let (a, b) = (spec.generate().unwrap(), spec.generate().unwrap());
        assert_eq!(a, b, "same seed, same world");
        assert_ne!(a, WorldSpec { seed: 8, ..spec.clone() }.generate().unwrap());
        a.check_feasible(0.9).unwrap();
        assert_eq!(a.obstacles.len(), 12, "2 per 100 m^2 of 600 m^2");
        let impossible = WorldSpec { density: 40.0, attempts: 3, ..spec };
        assert!(matches!(impossible.generate(), Err(WorldError::Generation { attempts: 3 })));
    }

    #[test]
    fn every_family_generates_seeded_feasible_worlds_of_its_kind() {
        let inflation = 0.75;
        let spec = |family, seed| WorldSpec { seed, family, inflation, ..WorldSpec::default() };
        for family in WorldFamily::ALL {
            assert_eq!(family.name().parse::<WorldFamily>(), Ok(family));
            for seed in 1..=3 {
                let world = spec(family, seed).generate().unwrap_or_else(|e| panic!("{family} seed {seed}: {e}"));
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
