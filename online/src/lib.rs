//! The online half of Parametric FaSTrack as a library a robot's own stack can call every control step:
//! [`core::LoopCore`] makes the decisions of the paper's Alg. 3 without any I/O, and
//! [`online_loop::OnlineLoop`] has its questions answered by an [`oracle::Oracle`] (the fastrack service over
//! one `Track` stream: [`track_oracle::TrackOracle`]), with any raw-path planner behind
//! [`raw_path::RawPathPlanner`] (A* on a grid by default, or [`fastest_path::FastestPath`], which plans for
//! speed) and the obstacles of [`geometry`].

#![warn(missing_docs)]

mod cell_astar;
pub mod core;
pub mod fastest_path;
pub mod geometry;
pub mod online_loop;
pub mod oracle;
pub mod raw_path;
pub mod track_oracle;

/// The guide's example (`docs/online-loop.md`), compiled as a doctest so that it cannot drift from this crate.
#[cfg(doctest)]
#[doc = include_str!("../../docs/online-loop.md")]
pub struct OnlineLoopGuide;
