//! Solutions by spec: a [`SolutionStore`]'s solution of a [`SolveSpec`], solved and saved when the store
//! lacks it or holds another solve under its name.

use crate::solver::{solve, SolveError};
use fastrack_gridfile::format::{save, FormatError};
use fastrack_gridfile::solution::Solution;
use fastrack_gridfile::spec::{SolutionStore, SolveSpec, SpecError, StoreError};

/// A spec's solution that can be neither loaded nor made.
#[derive(Debug, thiserror::Error)]
pub enum StoreSolveError {
    /// The spec is not solvable.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// The solve failed.
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// The solution could not be saved.
    #[error(transparent)]
    Save(#[from] FormatError),
    /// The store's directory could not be made.
    #[error("creating {path}: {source}")]
    Directory {
        /// The directory.
        path: std::path::PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// Whether [`solve_or_load`] read the solution or made it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolutionSource {
    /// Read from the store.
    Store,
    /// Solved now and saved to the store.
    Solver,
}

/// The solution of `spec`: read from `store` when its file holds that solve, else solved (with a progress
/// bar when `progress`) and saved there, replacing a file of another solve or an unreadable one.
pub fn solve_or_load(
    store: &SolutionStore,
    spec: &SolveSpec,
    progress: bool,
) -> Result<(Solution, SolutionSource), StoreSolveError> {
    match store.load(spec) {
        Ok(solution) => {
            tracing::info!(path = %store.path(spec).display(), "reusing solution");
            return Ok((solution, SolutionSource::Store));
        }
        Err(StoreError::Spec(e)) => return Err(e.into()),
        Err(StoreError::Missing { .. }) => {}
        Err(e) => tracing::warn!(error = %e, "solving again"),
    }
    let (system, params, grid) = (spec.system()?, spec.params()?, spec.grid()?);
    tracing::info!(system = system.id, beta = spec.beta, resolution = ?spec.resolution, accuracy = %spec.solver.accuracy, "solving");
    let solution = solve(&system, &params, &grid, &spec.solver, progress)?;
    std::fs::create_dir_all(store.dir())
        .map_err(|source| StoreSolveError::Directory { path: store.dir().into(), source })?;
    save(&solution, &store.path(spec))?;
    Ok((solution, SolutionSource::Solver))
}
