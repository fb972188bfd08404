//! PNG figures (plotters, bitmap backend): line charts and side-by-side value-function slices.
//!
//! Text needs a font: plotters' pure-Rust `ab_glyph` renderer is given DejaVu Sans (or Liberation Sans)
//! from the system font folders when one is installed; without one, figures are drawn without text (axes,
//! lines and colours only) and the numbers live in the markdown records beside them.

use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// A figure could not be drawn or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plot {path}: {problem}")]
pub struct PlotError {
    /// The PNG file.
    pub path: String,
    /// What failed.
    pub problem: String,
}

/// Font files tried, in order.
const FONT_FILES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// Registers a system font for `sans-serif` once; true if text can be drawn.
fn text_available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        FONT_FILES.iter().any(|path| match std::fs::read(path) {
            Ok(bytes) => plotters::style::register_font("sans-serif", FontStyle::Normal, bytes.leak()).is_ok(),
            Err(_) => false,
        })
    })
}

/// One line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub label: String,
    /// `(x, y)` points.
    pub points: Vec<(f64, f64)>,
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn fail(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError { path: path.display().to_string(), problem: e.to_string() }
}

fn padded(lo: f64, hi: f64) -> std::ops::Range<f64> {
    let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
    (lo - pad)..(hi + pad)
}

/// A line chart of `series` with a title and axis labels (text only when a font is available).
pub fn line_chart(path: &Path, title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<(), PlotError> {
    let text = text_available();
    let all = series.iter().flat_map(|s| s.points.iter());
    let (x0, x1, y0, y1) = all.fold((f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY), |a, p| {
        (a.0.min(p.0), a.1.max(p.0), a.2.min(p.1), a.3.max(p.1))
    });
    if !(x0.is_finite() && y0.is_finite()) {
        return Err(fail(path, "no finite points to draw"));
    }
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(path, e))?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(20);
    if text {
        builder.caption(title, ("sans-serif", 22)).x_label_area_size(45).y_label_area_size(70);
    }
    let mut chart = builder.build_cartesian_2d(padded(x0, x1), padded(y0, y1)).map_err(|e| fail(path, e))?;
    if text {
        chart.configure_mesh().x_desc(x_label).y_desc(y_label).draw().map_err(|e| fail(path, e))?;
    } else {
        chart.configure_mesh().x_labels(0).y_labels(0).draw().map_err(|e| fail(path, e))?;
    }
    for (k, s) in series.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        chart.draw_series(s.points.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(|e| fail(path, e))?;
        let drawn = chart
            .draw_series(LineSeries::new(s.points.iter().copied(), color.stroke_width(2)))
            .map_err(|e| fail(path, e))?;
        if text {
            drawn.label(s.label.clone()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| fail(path, e))?;
    }
    root.present().map_err(|e| fail(path, e))
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
    let text = text_available();
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
