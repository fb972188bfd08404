//! Line charts as PNG (plotters, bitmap backend). Text uses DejaVu Sans from the system font folder when it
//! is there; without it the chart is drawn without text rather than failing.

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::path::Path;
use std::sync::OnceLock;

/// Where the label font is looked for.
const FONT_CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

/// Registers DejaVu Sans for `sans-serif` once; true if text can be drawn.
pub fn fonts_available() -> bool {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        FONT_CANDIDATES.iter().find_map(|p| std::fs::read(p).ok()).is_some_and(|bytes| {
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            register_font("sans-serif", FontStyle::Normal, bytes).is_ok()
        })
    })
}

/// One named series of `(x, y)` points.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points.
    pub points: Vec<(f64, f64)>,
    /// Draw markers instead of a line.
    pub markers: bool,
}

/// A chart: title, axis labels, log-scaled y.
pub struct Chart<'a> {
    /// Title.
    pub title: &'a str,
    /// x-axis label.
    pub x_label: &'a str,
    /// y-axis label.
    pub y_label: &'a str,
    /// Logarithmic y axis.
    pub log_y: bool,
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Draws `series` into a 900x560 PNG at `path`.
pub fn line_chart(path: &Path, chart: &Chart<'_>, series: &[Series]) -> Result<(), String> {
    let points = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite() && (!chart.log_y || *y > 0.0));
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in points {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 || y0 > y1 {
        return Err(format!("nothing to plot in {}", path.display()));
    }
    // Points at a single x (e.g. one parameter value) get an x range around it.
    let (x0, x1) = if x0 == x1 { (x0 - 0.1 * x0.abs().max(1.0), x1 + 0.1 * x1.abs().max(1.0)) } else { (x0, x1) };
    let pad = if chart.log_y { 0.0 } else { 0.05 * (y1 - y0).max(1e-9) };
    let (y0, y1) = if chart.log_y { (y0 * 0.8, y1 * 1.25) } else { (y0 - pad, y1 + pad) };
    let text = fonts_available();
    let root = BitMapBackend::new(path, (900, 560)).into_drawing_area();
    let fail = |e: &dyn std::fmt::Display| format!("drawing {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(16).x_label_area_size(if text { 40 } else { 10 }).y_label_area_size(if text { 70 } else { 10 });
    if text {
        builder.caption(chart.title, ("sans-serif", 22));
    }
    macro_rules! draw {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            let mut mesh = ctx.configure_mesh();
            if text {
                mesh.x_desc(chart.x_label).y_desc(chart.y_label).label_style(("sans-serif", 14));
            } else {
                mesh.disable_x_axis().disable_y_axis();
            }
            mesh.draw().map_err(|e| fail(&e))?;
            for (i, s) in series.iter().enumerate() {
                let color = PALETTE[i % PALETTE.len()];
                let data = s
                    .points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite() && (!chart.log_y || *y > 0.0));
                let drawn = if s.markers {
                    ctx.draw_series(data.map(|p| Circle::new(p, 4, color.filled()))).map_err(|e| fail(&e))?
                } else {
                    ctx.draw_series(LineSeries::new(data, color.stroke_width(2))).map_err(|e| fail(&e))?
                };
                drawn
                    .label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3)));
            }
            if text {
                ctx.configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .label_font(("sans-serif", 14))
                    .draw()
                    .map_err(|e| fail(&e))?;
            }
        }};
    }
    if chart.log_y {
        draw!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()).map_err(|e| fail(&e))?);
    } else {
        draw!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| fail(&e))?);
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chart_of_points_at_one_x_is_drawn_and_one_without_finite_points_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart { title: "t", x_label: "x", y_label: "y", log_y: false };
        let single = [Series { label: "a".into(), points: vec![(1.0, 1.0), (1.0, 1.2)], markers: true }];
        let path = dir.path().join("single.png");
        line_chart(&path, &chart, &single).unwrap();
        assert!(std::fs::metadata(&path).unwrap().len() > 0);
        let empty = [Series { label: "a".into(), points: vec![(f64::NAN, 1.0)], markers: true }];
        assert!(line_chart(&dir.path().join("empty.png"), &chart, &empty).is_err());
    }
}
