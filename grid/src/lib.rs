//! Grid Hamilton-Jacobi level-set solver for fastrack's tracking value functions: numerical ground truth
//! for learned models.
//!
//! The module split follows hj_reachability: [`grid`] (axes, indexing, interpolation; with [`format`], the
//! `.ftgrid` file, and [`spec`], what a solve is, from the `fastrack-gridfile` crate), [`upwind`] (finite
//! differences: first order, ENO2, WENO5, boundary conditions), [`hamiltonian`] (the system's Hamiltonian
//! and Lax-Friedrichs dissipation), [`scheme`] (the parallel semi-discrete right-hand side), [`integrate`]
//! (TVD Runge-Kutta), [`solver`] (the tracking value iteration to convergence). Around it: [`store`]
//! (solutions by spec, solved when missing), [`analysis`] (TEB of a solution), [`compare`] (a model bundle
//! against grid solutions), [`verify`] (scenario verification of a bundle's TEB table), [`rollout`] (what
//! planners force against a grid solution's own policy), [`reference`] (ground-truth bounds for a bundle's
//! rows), [`slice_plot`] (PNG figures).

#![warn(missing_docs)]

pub mod analysis;
pub mod compare;
pub mod hamiltonian;
pub mod integrate;
pub mod reference;
pub mod rollout;
pub mod scheme;
pub mod slice_plot;
pub mod solver;
pub mod store;
pub mod upwind;
pub mod verify;

pub use fastrack_gridfile::{format, grid, spec};
