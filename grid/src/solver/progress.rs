//! The solve's progress bar (indicatif), hidden when not asked for.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over the horizon `cap` (s), in milliseconds of horizon; hidden unless `show`.
pub(super) fn progress_bar(show: bool, cap: f64) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new((cap * 1000.0).ceil() as u64);
    let style = ProgressStyle::with_template("{elapsed_precise} [{bar:30}] tau {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    bar.set_style(style);
    bar
}
