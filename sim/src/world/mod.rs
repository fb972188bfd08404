//! Worlds: a workspace in the plane (`D = 2`) or in space (`D = 3`, z up), a start and a goal, and obstacles
//! of that dimension, read from TOML or JSON or generated from a seed ([`families`]); checked to be feasible
//! for the sTEB-inflated map.

mod coordinates;
pub mod families;
pub mod shapes;

pub use families::{WorldFamily, WorldSpec};
pub use shapes::WorldObstacle;

use fastrack_online::geometry::{clearance, inside, PlaneObstacle, Point};
use fastrack_online::raw_path::{GridAStar, PlanRequest, RawPathPlanner};
use fastrack_proto::planner_speed::SpeedRule;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A world in the plane.
pub type PlaneWorld = World<PlaneObstacle, 2>;

/// A world the simulated robot moves through: obstacles `O` in a workspace of `D` axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct World<O, const D: usize> {
    /// The workspace's corner of smallest coordinates (m).
    #[serde(with = "coordinates")]
    pub min: Point<D>,
    /// Its corner of largest coordinates (m).
    #[serde(with = "coordinates")]
    pub max: Point<D>,
    /// The tracker's start position; the planner starts there too.
    #[serde(with = "coordinates")]
    pub start: Point<D>,
    /// The tracker's start heading in the ground plane (rad; 0 along +y, pi/2 along +x): dubins4d's
    /// `theta`, the direction of a quadcopter's horizontal velocity.
    #[serde(default)]
    pub start_heading: f64,
    /// The tracker's start speed along that heading (m/s).
    #[serde(default = "default_start_speed")]
    pub start_speed: f64,
    /// The goal.
    #[serde(with = "coordinates")]
    pub goal: Point<D>,
    /// The run ends when the tracker is this close to the goal (m). The default, 1.5 m, exceeds the circle
    /// a Dubins car holds around a planner at rest under the learned control (about 1.1 m on `dubins4d`/3):
    /// no tracker is guaranteed closer to its planner than the sTEB.
    #[serde(default = "default_goal_radius")]
    pub goal_radius: f64,
    /// The obstacles.
    #[serde(default = "Vec::new")]
    pub obstacles: Vec<O>,
}

pub(crate) fn default_start_speed() -> f64 {
    0.5
}

pub(crate) fn default_goal_radius() -> f64 {
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
        start: Vec<f64>,
        /// The goal.
        goal: Vec<f64>,
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

/// Longest side of a world's workspace (m): the planner searches a grid of it, in the plane at most 2,000
/// cells of 0.1 m a side.
pub const MAX_WORKSPACE_SIDE: f64 = 200.0;
/// Most cells of the feasibility grid a workspace may hold: 200 x 200 m in the plane, 62,500 m^3 in space
/// (100 x 62.5 x 10 m), so that checking a world ends in seconds.
pub const MAX_WORKSPACE_CELLS: f64 = 4e6;
/// Most obstacles in a world: every planner step measures the clearance to each.
pub const MAX_OBSTACLES: usize = 10_000;

pub(crate) fn invalid<T>(field: impl Into<String>, problem: impl Into<String>) -> Result<T, WorldError> {
    Err(WorldError::Invalid { field: field.into(), problem: problem.into() })
}

impl<O, const D: usize> World<O, D> {
    /// The workspace as `(min, max)`.
    pub fn bounds(&self) -> (Point<D>, Point<D>) {
        (self.min, self.max)
    }

    /// True if `p` lies in the workspace.
    pub fn contains(&self, p: Point<D>) -> bool {
        inside(p, self.bounds())
    }
}

impl<O: WorldObstacle<D>, const D: usize> World<O, D> {
    /// Reads a world from a `.toml` or `.json` file (by extension) and checks its values.
    pub fn load(path: &Path) -> Result<Self, WorldError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| WorldError::Io { path: name.clone(), source })?;
        let parse = |problem: String| WorldError::Parse { path: name.clone(), problem };
        let world: Self = if path.extension().is_some_and(|x| x == "json") {
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

    /// Checks every value: finite numbers, a workspace with area (volume), sides of at most
    /// [`MAX_WORKSPACE_SIDE`] and at most [`MAX_WORKSPACE_CELLS`] cells of the feasibility grid, at most [`MAX_OBSTACLES`] obstacles that exist, start and goal inside the
    /// workspace and outside every obstacle.
    pub fn validate(&self) -> Result<(), WorldError> {
        let finite = |p: &Point<D>| p.iter().all(|x| x.is_finite());
        if !(finite(&self.min) && finite(&self.max) && (0..D).all(|i| self.min[i] < self.max[i])) {
            return invalid(
                "min/max",
                format!("the workspace {:?}..{:?} must be finite with min below max", self.min, self.max),
            );
        }
        if (0..D).any(|i| self.max[i] - self.min[i] > MAX_WORKSPACE_SIDE) {
            return invalid(
                "min/max",
                format!("the workspace {:?}..{:?} must be at most {MAX_WORKSPACE_SIDE} m a side", self.min, self.max),
            );
        }
        let cell = feasibility_cell::<D>();
        let cells: f64 = (0..D).map(|i| (self.max[i] - self.min[i]) / cell).product();
        if cells > MAX_WORKSPACE_CELLS {
            return invalid(
                "min/max",
                format!(
                    "the workspace {:?}..{:?} holds {cells:.0} cells of {cell} m a side for the planner; at most {MAX_WORKSPACE_CELLS}",
                    self.min, self.max
                ),
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
        GridAStar { cell: feasibility_cell::<D>() }.plan(&request).map(|_| ()).map_err(|_| WorldError::Infeasible {
            start: self.start.to_vec(),
            goal: self.goal.to_vec(),
            inflation,
        })
    }
}

/// The grid cell A* checks a world's feasibility (and places its pop-ups) on: 0.1 m in the plane, 0.25 m in
/// space, where a 0.1 m grid of a 30 x 20 x 6 m world would hold 3.6 million cells.
pub fn feasibility_cell<const D: usize>() -> f64 {
    if D == 2 {
        0.1
    } else {
        0.25
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fastrack_online::geometry::SpaceObstacle;

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
        let world = PlaneWorld::load(&path).unwrap();
        assert_eq!(world.obstacles.len(), 1);
        world.check_feasible(0.9).unwrap();
        let (_dir2, again) = write("again.toml", &world.to_toml());
        assert_eq!(PlaneWorld::load(&again).unwrap(), world);
        let (_dir3, json) = write("w.json", &serde_json::to_string(&world).unwrap());
        assert_eq!(PlaneWorld::load(&json).unwrap(), world);
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
            let error = PlaneWorld::load(&path).unwrap_err().to_string();
            assert!(error.contains(named), "{named}: {error}");
        }
        let missing = PlaneWorld::load(Path::new("/nonexistent/world.toml")).unwrap_err();
        assert!(matches!(missing, WorldError::Io { .. }));
        // A wall across the workspace: valid, but no path.
        let walled =
            format!("{GOOD}\n[[obstacles]]\nkind = \"wall\"\nfrom = [5.0, -1.0]\nto = [5.0, 11.0]\nthickness = 0.2\n");
        let (_dir, path) = write("walled.toml", &walled);
        let world = PlaneWorld::load(&path).unwrap();
        assert!(matches!(world.check_feasible(0.9), Err(WorldError::Infeasible { .. })));
        // A start too close to an obstacle for the sTEB.
        let near = GOOD.replace("center = [10.0, 5.0]", "center = [2.5, 5.0]");
        let (_dir, path) = write("near.toml", &near);
        let error = PlaneWorld::load(&path).unwrap().check_feasible(0.9).unwrap_err().to_string();
        assert!(error.contains("start"), "{error}");
    }

    const GOOD_IN_SPACE: &str = r#"
min = [0.0, 0.0, 0.0]
max = [20.0, 10.0, 5.0]
start = [1.0, 5.0, 2.5]
goal = [19.0, 5.0, 2.5]

[[obstacles]]
kind = "pillar"
center = [10.0, 5.0]
radius = 1.0
bottom = 0.0
top = 5.0

[[obstacles]]
kind = "floor"
height = 0.0
"#;

    #[test]
    fn a_world_in_space_round_trips_and_its_bad_files_are_named() {
        let (_dir, path) = write("w.toml", GOOD_IN_SPACE);
        let world = World::<SpaceObstacle, 3>::load(&path).unwrap();
        assert_eq!(world.obstacles.len(), 2);
        world.check_feasible(0.9).unwrap();
        let (_dir2, again) = write("again.toml", &world.to_toml());
        assert_eq!(World::load(&again).unwrap(), world);
        let cases = [
            (GOOD_IN_SPACE.replace("start = [1.0, 5.0, 2.5]", "start = [1.0, 5.0]"), "point of 3 coordinates"),
            (GOOD_IN_SPACE.replace("top = 5.0", "top = -1.0"), "`obstacles[0]`: pillar bottom"),
            (GOOD_IN_SPACE.replace("kind = \"pillar\"", "kind = \"circle\""), "circle"),
            (GOOD_IN_SPACE.replace("goal = [19.0, 5.0, 2.5]", "goal = [19.0, 5.0, 6.0]"), "goal"),
            (GOOD_IN_SPACE.replace("start = [1.0, 5.0, 2.5]", "start = [1.0, 5.0, -0.5]"), "start"),
        ];
        for (text, named) in cases {
            let (_dir, path) = write("bad.toml", &text);
            let error = World::<SpaceObstacle, 3>::load(&path).unwrap_err().to_string();
            assert!(error.contains(named), "{named}: {error}");
        }
        // A planar world file is no world in space, and the other way round.
        let (_dir, planar) = write("planar.toml", GOOD);
        assert!(World::<SpaceObstacle, 3>::load(&planar).is_err());
        assert!(PlaneWorld::load(&path).is_err());
        // A ceiling too low for the sTEB over the floor: no path.
        let low = format!("{GOOD_IN_SPACE}\n[[obstacles]]\nkind = \"ceiling\"\nheight = 3.0\n");
        let (_dir, path) = write("low.toml", &low);
        let error = World::<SpaceObstacle, 3>::load(&path).unwrap().check_feasible(1.3).unwrap_err().to_string();
        assert!(error.contains("start"), "{error}");
    }
}
