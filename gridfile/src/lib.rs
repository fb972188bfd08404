//! Grid value functions as files: what the grid solver writes and what the trainer and the comparison
//! tools read, without the solver itself.
//!
//! - [`grid`]: axes, row-major indexing and multilinear interpolation.
//! - [`settings`]: the scheme and convergence settings a solution records.
//! - [`solution`]: a value function on a grid with the record of how it was solved.
//! - [`format`]: the `.ftgrid` file.
//! - [`spec`]: what a solve is ([`spec::SolveSpec`]) and where its file is kept ([`spec::SolutionStore`]).

#![warn(missing_docs)]

pub mod format;
pub mod grid;
pub mod settings;
pub mod solution;
pub mod spec;
