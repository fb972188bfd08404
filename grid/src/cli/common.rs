//! Options shared by the subcommands: the system, its grid and the solver settings.

use anyhow::{bail, Context};
use fastrack_grid::format::load;
use fastrack_grid::integrate::RkOrder;
use fastrack_grid::scheme::Flux;
use fastrack_grid::solver::Solution;
use fastrack_grid::solver::{ConvergenceSet, SolverConfig};
use fastrack_grid::spec::{AxisBounds, SolutionStore, SolveSpec, DEFAULT_STORE};
use fastrack_grid::store::solve_or_load;
use fastrack_grid::upwind::Accuracy;
use fastrack_lab::record::{write_record, MarkdownTable};
use fastrack_valuefn::system::{by_id, AffineSystem, DecomposedAxis, SYSTEM_IDS};
use std::path::{Path, PathBuf};

/// Where solutions are cached and measurement records written.
#[derive(clap::Args, Clone, Debug)]
pub struct StudyOutputs {
    /// The solution store: solutions found there with the same spec are reused, new ones saved.
    #[arg(long, default_value = DEFAULT_STORE)]
    pub solutions_dir: PathBuf,
    /// Record name (`<results-dir>/<record>.{json,md}` and PNG plots beside it; `compare` defaults to
    /// `grid-compare-<model>`, the other commands write no record without it).
    #[arg(long)]
    pub record: Option<String>,
    /// Folder of measurement records and plots.
    #[arg(long, default_value = "bench/results")]
    pub results_dir: PathBuf,
}

/// The grid and solver options of a solve.
#[derive(clap::Args, Clone, Debug)]
pub struct SolveOptions {
    /// System id (dubins4d, double_integrator, quad10d, and quad10d's axes quad10d_x, quad10d_z).
    #[arg(long, default_value = "dubins4d")]
    pub system: String,
    /// Nodes per axis: one number for every axis, or one per axis, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "31")]
    pub resolution: Vec<usize>,
    /// Override an axis' bounds, `name=min:max` (repeatable), e.g. `x_r=-2:2`.
    #[arg(long = "bounds")]
    pub bounds: Vec<String>,
    /// Derivative approximation: first, eno2, weno5.
    #[arg(long, default_value = "weno5")]
    pub accuracy: Accuracy,
    /// Numerical Hamiltonian: lax_friedrichs (any system) or godunov (every input acting on one state
    /// coordinate, as in dubins4d and the double integrator).
    #[arg(long, default_value = "lax_friedrichs")]
    pub flux: Flux,
    /// TVD Runge-Kutta order: 1, 2, 3.
    #[arg(long, default_value = "3")]
    pub rk: RkOrder,
    /// CFL number.
    #[arg(long, default_value_t = 0.75)]
    pub cfl: f64,
    /// Largest horizon integrated (s).
    #[arg(long, default_value_t = 30.0)]
    pub horizon_cap: f64,
    /// Converged when max |dV/dtau| over the grid (or the --converge-on set), measured over --rate-window,
    /// falls below this (m/s).
    #[arg(long, default_value_t = 0.01)]
    pub tolerance: f64,
    /// Where the convergence test looks: `grid` (every node) or `sublevel` ({V <= V_min (1 + --set-margin)}
    /// at least --edge-nodes nodes from every non-periodic edge).
    #[arg(long, default_value = "grid", value_parser = ["grid", "sublevel"])]
    pub converge_on: String,
    /// Relative margin of the sublevel convergence set above V_min.
    #[arg(long, default_value_t = ConvergenceSet::DIAGNOSTIC.margin)]
    pub set_margin: f64,
    /// Horizon (s) over which the rate is measured: max |V(tau) - V(tau - w)| / w at the end of each window;
    /// 0 measures every step on its own, which also counts the scheme's step-to-step oscillation.
    #[arg(long, default_value_t = 2.0)]
    pub rate_window: f64,
    /// Converged only once the rate has stayed below --tolerance for this long (s); 0 stops at the first step
    /// (or window) below it.
    #[arg(long, default_value_t = 0.0)]
    pub settle_time: f64,
    /// Nodes left out of the sublevel convergence set next to each non-periodic edge.
    #[arg(long, default_value_t = ConvergenceSet::DIAGNOSTIC.edge_nodes)]
    pub edge_nodes: usize,
}

impl SolveOptions {
    /// The system.
    pub fn system(&self) -> anyhow::Result<AffineSystem> {
        by_id(&self.system)
            .with_context(|| format!("unknown system `{}`; known: {}", self.system, SYSTEM_IDS.join(", ")))
    }

    /// The solver configuration.
    pub fn config(&self) -> SolverConfig {
        SolverConfig {
            accuracy: self.accuracy,
            flux: self.flux,
            rk: self.rk,
            cfl: self.cfl,
            horizon_cap: self.horizon_cap,
            tolerance: self.tolerance,
            rate_window: self.rate_window,
            tracking: true,
            converge_on: (self.converge_on == "sublevel")
                .then_some(ConvergenceSet { margin: self.set_margin, edge_nodes: self.edge_nodes }),
            settle_time: self.settle_time,
        }
    }

    /// The solve of `beta` these options name.
    pub fn spec(&self, beta: f64) -> anyhow::Result<SolveSpec> {
        let bounds = self.bounds.iter().map(|text| parse_bounds(text)).collect::<anyhow::Result<_>>()?;
        let spec = SolveSpec {
            system: self.system.clone(),
            beta,
            resolution: self.resolution.clone(),
            bounds,
            solver: self.config(),
        };
        spec.grid().context("--system, --resolution or --bounds")?;
        Ok(spec)
    }

    /// The solution of `beta` from the store in `dir`, solved and saved there if it lacks it.
    pub fn solve_or_load(&self, beta: f64, dir: &Path) -> anyhow::Result<Solution> {
        let spec = self.spec(beta)?;
        params_for(&spec.system()?, beta)?;
        Ok(solve_or_load(&SolutionStore::new(dir), &spec, true)?.0)
    }
}

/// `name=min:max` as an axis' bounds.
fn parse_bounds(text: &str) -> anyhow::Result<AxisBounds> {
    let expected = || format!("--bounds `{text}`: expected name=min:max");
    let (axis, range) = text.split_once('=').with_context(expected)?;
    let (min, max) = range.split_once(':').with_context(expected)?;
    Ok(AxisBounds {
        axis: axis.into(),
        min: min.trim().parse().with_context(|| format!("--bounds `{text}`: min is not a number"))?,
        max: max.trim().parse().with_context(|| format!("--bounds `{text}`: max is not a number"))?,
    })
}

/// Parameters for a `beta` query: every parameter equal to `beta`, checked against the system's range.
pub fn params_for(system: &AffineSystem, beta: f64) -> anyhow::Result<Vec<f64>> {
    if !beta.is_finite() || beta <= 0.0 {
        bail!("beta = {beta} must be a positive number");
    }
    for p in &system.params {
        if beta < p.min || beta > p.max {
            tracing::warn!("beta = {beta} is outside {}'s range [{}, {}] of {}", p.name, p.min, p.max, system.id);
        }
    }
    Ok(vec![beta; system.n_params()])
}

/// The command line as run, for records (`fastrack-grid <arguments>`, whatever the binary's path).
pub fn command_line() -> String {
    std::iter::once("fastrack-grid".to_string()).chain(std::env::args().skip(1)).collect::<Vec<_>>().join(" ")
}

/// Writes a measurement record of this command ([`write_record`] with its command line as run).
pub fn write_command_record(
    dir: &Path,
    name: &str,
    config: serde_json::Value,
    figures: serde_json::Value,
    tables: &[(&str, &MarkdownTable)],
) -> std::io::Result<PathBuf> {
    write_record(dir, name, &command_line(), config, figures, tables)
}

/// Solution files with their paths.
pub type LoadedSolutions = Vec<(PathBuf, Solution)>;

/// Loads the solution files of a decomposed system's axes (`id`, decomposed into `axes`), each checked to
/// solve one of its axis subsystems, and the `beta`s they were solved at, in order.
pub fn load_axis_solutions(
    id: &str,
    axes: &[DecomposedAxis],
    paths: &[PathBuf],
) -> anyhow::Result<(LoadedSolutions, Vec<f64>)> {
    let mut solutions = Vec::new();
    for path in paths {
        let solution = load(path).with_context(|| format!("loading {}", path.display()))?;
        if !axes.iter().any(|a| a.subsystem == solution.info.system) {
            bail!("{}: system `{}` is not an axis of {id}", path.display(), solution.info.system);
        }
        solutions.push((path.clone(), solution));
    }
    let mut betas: Vec<f64> = solutions.iter().map(|(_, s)| s.info.params[0]).collect();
    betas.sort_by(f64::total_cmp);
    betas.dedup();
    Ok((solutions, betas))
}

/// The axis solutions of one `beta`, in the decomposition's order.
pub fn axes_at<'a>(
    id: &str,
    axes: &[DecomposedAxis],
    solutions: &'a [(PathBuf, Solution)],
    beta: f64,
) -> anyhow::Result<Vec<(DecomposedAxis, &'a Solution)>> {
    axes.iter()
        .map(|axis| {
            let mut found =
                solutions.iter().filter(|(_, s)| s.info.system == axis.subsystem && s.info.params[0] == beta);
            let (path, solution) = found
                .next()
                .with_context(|| format!("{id} at beta {beta}: no solution of its axis `{}`", axis.subsystem))?;
            if let Some((other, _)) = found.next() {
                bail!(
                    "{id} at beta {beta}: two solutions of `{}` ({} and {}); give one per beta",
                    axis.subsystem,
                    path.display(),
                    other.display()
                );
            }
            Ok((axis.clone(), solution))
        })
        .collect()
}
