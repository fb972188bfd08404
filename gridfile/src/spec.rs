//! What a grid solution is, and where it is kept: a [`SolveSpec`] names one solve (system, `beta`, grid,
//! scheme, horizon, tolerances), a [`SolveSeries`] the solves a training run is supervised by, and a
//! [`SolutionStore`] maps each spec to its file in a directory and loads it, checked against the spec.
//!
//! Solving what a store lacks needs the solver (`fastrack-grid`'s `store` module); this crate only names and
//! reads.

use crate::format::{load, FormatError};
use crate::grid::{Grid, GridError};
use crate::settings::{Flux, SolverConfig};
use crate::solution::Solution;
use fastrack_valuefn::system::{by_id, AffineSystem, SYSTEM_IDS};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One axis' bounds in place of the system's domain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisBounds {
    /// The axis' name, as the system names its state coordinates (e.g. `x_r`).
    pub axis: String,
    /// Lower bound.
    pub min: f64,
    /// Upper bound.
    pub max: f64,
}

/// One grid solve: equal specs make the same solution and name the same file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolveSpec {
    /// System id (see `fastrack_valuefn::system::by_id`).
    pub system: String,
    /// Planner speed bound; every parameter of the system is set to it.
    pub beta: f64,
    /// Nodes per axis: one number for every axis, or one per axis.
    pub resolution: Vec<usize>,
    /// Axes whose bounds differ from the system's domain.
    #[serde(default)]
    pub bounds: Vec<AxisBounds>,
    /// Scheme, horizon and convergence test.
    pub solver: SolverConfig,
}

/// A spec that names no solvable grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// The system id is unknown.
    #[error("unknown system `{given}`; known: {known}")]
    UnknownSystem {
        /// The id given.
        given: String,
        /// The ids known.
        known: String,
    },
    /// `beta` is not a positive number.
    #[error("beta = {0} must be a positive number")]
    Beta(f64),
    /// The resolution has neither one entry nor one per axis.
    #[error("resolution has {given} entries; give 1 or {axes} (one per axis of {system})")]
    Resolution {
        /// The system.
        system: String,
        /// Its axes.
        axes: usize,
        /// Entries given.
        given: usize,
    },
    /// A bounds override names no axis of the system.
    #[error("bounds of `{given}`: no such axis; axes: {axes}")]
    UnknownAxis {
        /// The axis named.
        given: String,
        /// The system's axes.
        axes: String,
    },
    /// The grid cannot be built.
    #[error(transparent)]
    Grid(#[from] GridError),
}

impl SolveSpec {
    /// The system solved.
    pub fn system(&self) -> Result<AffineSystem, SpecError> {
        by_id(&self.system)
            .ok_or_else(|| SpecError::UnknownSystem { given: self.system.clone(), known: SYSTEM_IDS.join(", ") })
    }

    /// The parameters solved at: every one equal to `beta`.
    pub fn params(&self) -> Result<Vec<f64>, SpecError> {
        if !self.beta.is_finite() || self.beta <= 0.0 {
            return Err(SpecError::Beta(self.beta));
        }
        Ok(vec![self.beta; self.system()?.n_params()])
    }

    /// Nodes on each axis of the system.
    pub fn axis_resolution(&self) -> Result<Vec<usize>, SpecError> {
        let n = self.system()?.n_state();
        match self.resolution.len() {
            1 => Ok(vec![self.resolution[0]; n]),
            k if k == n => Ok(self.resolution.clone()),
            given => Err(SpecError::Resolution { system: self.system.clone(), axes: n, given }),
        }
    }

    /// The grid: the system's domain at the spec's resolution, with its bounds overrides.
    pub fn grid(&self) -> Result<Grid, SpecError> {
        let system = self.system()?;
        let mut axes = Grid::for_system(&system, &self.axis_resolution()?)?.axes().to_vec();
        for bounds in &self.bounds {
            let axis = axes.iter_mut().find(|a| a.name == bounds.axis).ok_or_else(|| SpecError::UnknownAxis {
                given: bounds.axis.clone(),
                axes: system.state.iter().map(|d| d.name).collect::<Vec<_>>().join(", "),
            })?;
            (axis.min, axis.max) = (bounds.min, bounds.max);
        }
        Ok(Grid::new(axes)?)
    }

    /// The file name the spec is kept under: readable, and different for every setting the solve depends on
    /// but the CFL number (a store checks the whole spec on load).
    pub fn file_name(&self) -> String {
        let config = &self.solver;
        let resolution = self.axis_resolution().unwrap_or_else(|_| self.resolution.clone());
        let resolution = resolution.iter().map(|n| n.to_string()).collect::<Vec<_>>().join("x");
        let mut settings = match config.converge_on {
            Some(set) => format!("-set{}e{}", set.margin, set.edge_nodes),
            None => String::new(),
        };
        if config.rate_window > 0.0 {
            settings += &format!("-win{}", config.rate_window);
        }
        if config.settle_time > 0.0 {
            settings += &format!("-settle{}", config.settle_time);
        }
        if config.flux != Flux::LaxFriedrichs {
            settings += &format!("-{}", config.flux);
        }
        let bounds: Vec<String> = self.bounds.iter().map(|b| format!("{}{:?}{:?}", b.axis, b.min, b.max)).collect();
        let bounds = if bounds.is_empty() { String::new() } else { format!("-{}", bounds.join("_")) };
        format!(
            "{}-beta{}-n{resolution}-{}-rk{}-tol{}-cap{}{settings}{bounds}.ftgrid",
            self.system, self.beta, config.accuracy, config.rk, config.tolerance, config.horizon_cap
        )
    }

    /// Why `solution` is not this spec's solve, if it is not.
    pub fn mismatch(&self, solution: &Solution) -> Result<Option<String>, SpecError> {
        let info = &solution.info;
        Ok(if info.system != self.system {
            Some(format!("system `{}`, the spec `{}`", info.system, self.system))
        } else if info.params != self.params()? {
            Some(format!("parameters {:?}, the spec beta = {}", info.params, self.beta))
        } else if solution.grid != self.grid()? {
            Some(format!("grid {:?}, the spec's {:?}", solution.grid.axes(), self.grid()?.axes()))
        } else if info.config != self.solver {
            Some(format!("solver settings {:?}, the spec's {:?}", info.config, self.solver))
        } else {
            None
        })
    }
}

/// Solves that share everything but `beta` (and perhaps some axes' bounds): the grid solutions one training
/// run is supervised by.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolveSeries {
    /// System id.
    pub system: String,
    /// Nodes per axis: one number for every axis, or one per axis.
    pub resolution: Vec<usize>,
    /// Bounds overrides every solve shares.
    #[serde(default)]
    pub bounds: Vec<AxisBounds>,
    /// Scheme, horizon and convergence test.
    pub solver: SolverConfig,
    /// Each solve's `beta` and its own bounds overrides.
    pub solves: Vec<SeriesSolve>,
}

/// One solve of a [`SolveSeries`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeriesSolve {
    /// Planner speed bound.
    pub beta: f64,
    /// Bounds overrides of this solve alone, after the series' own (an axis named in both takes these).
    #[serde(default)]
    pub bounds: Vec<AxisBounds>,
}

impl SolveSeries {
    /// Each solve's full spec, in the series' order.
    pub fn specs(&self) -> Vec<SolveSpec> {
        self.solves
            .iter()
            .map(|solve| {
                let mut bounds = self.bounds.clone();
                for own in &solve.bounds {
                    bounds.retain(|b| b.axis != own.axis);
                    bounds.push(own.clone());
                }
                SolveSpec {
                    system: self.system.clone(),
                    beta: solve.beta,
                    resolution: self.resolution.clone(),
                    bounds,
                    solver: self.solver.clone(),
                }
            })
            .collect()
    }
}

/// A solution a store cannot hand out.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// No file for the spec.
    #[error("no solution for {spec} in {dir} (expected {path})")]
    Missing {
        /// The spec, in short.
        spec: String,
        /// The store's directory.
        dir: PathBuf,
        /// The file it would be.
        path: PathBuf,
    },
    /// The spec's file holds another solve.
    #[error("{path} is not the solve of its spec: {problem}")]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// How it differs.
        problem: String,
    },
    /// The spec is not solvable.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// The file is unreadable.
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// Where solutions are kept unless a command or config names another directory (relative to the working
/// directory).
pub const DEFAULT_STORE: &str = "target/grid-solutions";

/// Grid solutions kept in one directory, one file per spec.
#[derive(Debug, Clone, PartialEq)]
pub struct SolutionStore {
    dir: PathBuf,
}

impl SolutionStore {
    /// The store kept in `dir` (created when the first solution is saved).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The file `spec` is kept in.
    pub fn path(&self, spec: &SolveSpec) -> PathBuf {
        self.dir.join(spec.file_name())
    }

    /// The solution of `spec`, read from its file and checked to be that solve.
    pub fn load(&self, spec: &SolveSpec) -> Result<Solution, StoreError> {
        spec.grid()?;
        let path = self.path(spec);
        if !path.exists() {
            let short = format!("{} at beta {} on {:?} nodes", spec.system, spec.beta, spec.resolution);
            return Err(StoreError::Missing { spec: short, dir: self.dir.clone(), path });
        }
        let solution = load(&path)?;
        match spec.mismatch(&solution)? {
            Some(problem) => Err(StoreError::Mismatch { path, problem }),
            None => Ok(solution),
        }
    }
}
