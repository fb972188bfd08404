//! A navigation simulator around the fastrack service, for the online half of Parametric FaSTrack, in the
//! plane or in space by the model's planner: [`world`]s from files or seeds, the tracker's true dynamics and a range sensor ([`tracker`]), the
//! methods compared ([`methods`]: Parametric FaSTrack over the `Track` stream, FaSTrack at fixed speeds,
//! Meta-FaSTrack, MPPI), where they get their answers ([`backend`]: the service, or the model in this
//! process), one run of a method through a world ([`episode`]), the benchmark's summaries ([`bench`]), the
//! relative states the online loop visited ([`visits`]), its golden traces ([`trace`]), the served promise checked in closed loop row by row
//! ([`promise`]), the figures ([`plot`]) and a run in space to turn in a browser ([`viewer`]).

#![warn(missing_docs)]

pub mod backend;
pub mod bench;
pub mod episode;
#[cfg(feature = "in-process")]
pub mod in_process;
pub mod methods;
pub mod plot;
pub mod promise;
pub mod trace;
pub mod tracker;
pub mod viewer;
pub mod visits;
pub mod world;
