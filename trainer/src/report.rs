//! Figures of a run: the loss curves from `losses.jsonl`, and a bundle's TEB radius against `beta`.

use crate::train::RunDir;
use anyhow::Context;
use fastrack_lab::plot::{line_chart, Chart, Series};
use fastrack_valuefn::manifest::TebRow;
use std::path::{Path, PathBuf};

/// Draws `<run>/losses.png` (total, boundary, residual and grid-supervision losses against iteration, log
/// scale; terms that stay 0 are left out).
pub fn plot_losses(run: &RunDir) -> anyhow::Result<PathBuf> {
    let text = std::fs::read_to_string(run.losses()).with_context(|| format!("reading {}", run.losses().display()))?;
    let mut series: Vec<Series> = ["loss", "boundary", "residual", "supervision", "supervision_gradient"]
        .iter()
        .map(|name| Series { label: (*name).into(), points: Vec::new(), markers: false })
        .collect();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let record: serde_json::Value = serde_json::from_str(line).context("a malformed line in losses.jsonl")?;
        let it = record["iteration"].as_f64().unwrap_or_default();
        for s in series.iter_mut() {
            if let Some(y) = record[s.label.as_str()].as_f64().filter(|y| *y > 0.0) {
                s.points.push((it, y));
            }
        }
    }
    series.retain(|s| !s.points.is_empty());
    let path = run.0.join("losses.png");
    let chart =
        Chart { title: "DeepReach training loss", x_label: "iteration", y_label: "loss (mean |.|)", log_y: true };
    line_chart(&path, &chart, &series).map_err(anyhow::Error::msg)?;
    Ok(path)
}

/// Draws the TEB radius (the row's bound) and the certified set's level against `beta`, with reference points
/// (e.g. a grid solution).
pub fn plot_teb(path: &Path, rows: &[TebRow], references: &[(&str, Vec<(f64, f64)>)]) -> anyhow::Result<()> {
    let mut series = vec![
        Series {
            label: "error bound (served radius)".into(),
            points: rows.iter().map(|r| (r.beta, r.bound())).collect(),
            markers: false,
        },
        Series {
            label: "certified set level (membership)".into(),
            points: rows.iter().map(|r| (r.beta, r.set_level())).collect(),
            markers: false,
        },
        Series {
            label: "learned V_min as measured".into(),
            points: rows.iter().map(|r| (r.beta, r.measured_min)).collect(),
            markers: true,
        },
    ];
    series.extend(references.iter().map(|(label, points)| Series {
        label: (*label).into(),
        points: points.clone(),
        markers: true,
    }));
    let chart = Chart {
        title: "Tracking error bound against planner speed",
        x_label: "beta (m/s)",
        y_label: "TEB radius, level (m)",
        log_y: false,
    };
    line_chart(path, &chart, &series).map_err(anyhow::Error::msg)
}
