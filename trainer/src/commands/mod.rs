//! The subcommands of `fastrack-trainer`, one file each.

pub mod bench;
pub mod compose;
pub mod export;
pub mod plot_teb;
pub mod random_bundle;
pub mod train;
