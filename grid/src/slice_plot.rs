//! PNG figures (plotters, bitmap backend): side-by-side value-function slices. Line charts come from
//! `fastrack_lab::plot`, which also registers the label font.
//!
//! Text needs a font: plotters' pure-Rust `ab_glyph` renderer is given DejaVu Sans (or Liberation Sans)
//! from the system font folders when one is installed; without one, figures are drawn without text (axes,
//! lines and colours only) and the numbers live in the markdown records beside them.

use plotters::prelude::*;
use std::path::Path;

/// A figure could not be drawn or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plot {path}: {problem}")]
pub struct PlotError {
    /// The PNG file.
    pub path: String,
    /// What failed.
    pub problem: String,
}

fn fail(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError { path: path.display().to_string(), problem: e.to_string() }
}

/// Blue (low) to yellow (high).
fn colour(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    RGBColor((255.0 * t) as u8, (80.0 + 140.0 * t) as u8, (200.0 * (1.0 - t)) as u8)
}

/// Two value-function slices side by side on one colour scale (`n0 x n1` nodes, row-major, axis 1
/// fastest; axis 0 runs left to right, axis 1 bottom to top), with the contour `V = level` in white.
pub fn slice_pair(
    path: &Path,
    title: &str,
    panels: [(&str, &[f64]); 2],
    n0: usize,
    n1: usize,
    level: f64,
) -> Result<(), PlotError> {
    let text = fastrack_lab::plot::fonts_available();
    let (lo, hi) = panels
        .iter()
        .flat_map(|(_, v)| v.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let cell = (360 / n0.max(n1)).max(2) as i32;
    let (w, h) = (n0 as i32 * cell, n1 as i32 * cell);
    let top = if text { 60 } else { 20 };
    let root = BitMapBackend::new(path, ((2 * w + 60) as u32, (h + top + 20) as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(path, e))?;
    if text {
        root.draw(&Text::new(title.to_string(), (20, 8), ("sans-serif", 18))).map_err(|e| fail(path, e))?;
    }
    for (p, (name, values)) in panels.iter().enumerate() {
        let x_off = 20 + p as i32 * (w + 20);
        if text {
            root.draw(&Text::new(name.to_string(), (x_off, top - 24), ("sans-serif", 16)))
                .map_err(|e| fail(path, e))?;
        }
        for i in 0..n0 {
            for j in 0..n1 {
                let v = values[i * n1 + j];
                let below = v <= level;
                let edge = (i + 1 < n0 && (values[(i + 1) * n1 + j] <= level) != below)
                    || (j + 1 < n1 && (values[i * n1 + j + 1] <= level) != below);
                let c = if edge { WHITE } else { colour((v - lo) / (hi - lo).max(1e-12)) };
                let (x, y) = (x_off + i as i32 * cell, top + (n1 - 1 - j) as i32 * cell);
                root.draw(&Rectangle::new([(x, y), (x + cell, y + cell)], c.filled())).map_err(|e| fail(path, e))?;
            }
        }
    }
    root.present().map_err(|e| fail(path, e))
}
