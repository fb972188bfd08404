//! An interactive view of a run in space: one self-contained HTML file (no network, no library) holding the
//! world and the run as JSON and a small script that draws them on a canvas, turned by dragging and zoomed by
//! the wheel: the solids as wireframes, the floor as a grid, the tracker's path coloured by `beta` as in the
//! figures, the planner's path dotted, and the bound in force around the planner every few seconds.

use crate::episode::Run;
use crate::world::World;
use serde::Serialize;
use serde_json::json;
use std::path::Path;

/// Most path samples the page holds: a longer run is thinned evenly.
pub const MAX_SAMPLES: usize = 5_000;

/// Writes the page for `run` through `world` into `path`; `beta_l` sets the path's colours (blue at
/// `beta_l`, purple up to 1 m/s, red above) and a bound is drawn every `every` seconds.
pub fn write_html<O: Serialize, const D: usize>(
    path: &Path,
    world: &World<O, D>,
    run: &Run<O, D>,
    beta_l: f64,
    every: f64,
) -> std::io::Result<()> {
    let stride = run.samples.len().div_ceil(MAX_SAMPLES).max(1);
    let bound_stride = ((every / run.control_period).round() as usize).max(1);
    let samples: Vec<serde_json::Value> = run
        .samples
        .iter()
        .enumerate()
        .filter(|(k, _)| k % stride == 0 || k + 1 == run.samples.len())
        .map(|(k, s)| {
            // One bound per `every` seconds: on the first kept sample of each such span.
            let bound = if k % bound_stride < stride { s.bound } else { None };
            json!({"p": s.position.to_vec(), "q": s.planner.map(|q| q.to_vec()), "beta": s.beta, "bound": bound})
        })
        .collect();
    let title = format!("{}: {} after {:.1} s", run.method, run.outcome.label(), run.time);
    let data = json!({
        "title": title, "min": world.min.to_vec(), "max": world.max.to_vec(), "start": world.start.to_vec(),
        "goal": world.goal.to_vec(), "goal_radius": world.goal_radius, "obstacles": world.obstacles,
        "samples": samples, "beta_l": beta_l,
    });
    // `</` cannot end the script early inside a JSON string.
    let data = serde_json::to_string(&data).map_err(std::io::Error::other)?.replace("</", "<\\/");
    std::fs::write(path, PAGE.replace("/*DATA*/null", &data))
}

/// The page; `/*DATA*/null` is replaced by the run's JSON.
const PAGE: &str = r##"<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>fastrack run</title>
<style>body{margin:0;font:14px sans-serif;background:#fff}#info{position:absolute;left:12px;top:8px}
canvas{display:block;cursor:grab}</style></head>
<body><div id="info"></div><canvas id="view"></canvas>
<script>
const data = /*DATA*/null;
const canvas = document.getElementById("view"), ctx = canvas.getContext("2d");
document.getElementById("info").textContent = data.title +
  " (drag to turn, wheel to zoom; blue: beta_l, purple: up to 1 m/s, red: faster; orange: the bound)";
const centre = data.min.map((lo, i) => (lo + data.max[i]) / 2);
const span = Math.max(...data.min.map((lo, i) => data.max[i] - lo));
let yaw = -0.6, pitch = 0.5, zoom = 1;
function project(p) {
  const x = p[0] - centre[0], y = p[1] - centre[1], z = (p[2] || 0) - centre[2];
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const u = cy * x - sy * y, w = sy * x + cy * y;
  const scale = zoom * 0.8 * Math.min(canvas.width, canvas.height) / span;
  return [canvas.width / 2 + scale * u, canvas.height / 2 - scale * (cp * z - sp * w)];
}
function scale() { return zoom * 0.8 * Math.min(canvas.width, canvas.height) / span; }
function line(points, colour, width, dashed) {
  ctx.beginPath(); ctx.strokeStyle = colour; ctx.lineWidth = width; ctx.setLineDash(dashed ? [3, 4] : []);
  points.forEach((p, i) => { const [x, y] = project(p); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
  ctx.stroke();
}
function ring(c, r, axes, colour) {
  const pts = [];
  for (let k = 0; k <= 48; k++) {
    const a = 2 * Math.PI * k / 48, p = c.slice();
    p[axes[0]] += r * Math.cos(a); p[axes[1]] += r * Math.sin(a); pts.push(p);
  }
  line(pts, colour, 1);
}
function box(lo, hi, colour) {
  const c = (i, j, k) => [[lo[0], hi[0]][i], [lo[1], hi[1]][j], [lo[2], hi[2]][k]];
  for (let a = 0; a < 2; a++) for (let b = 0; b < 2; b++) {
    line([c(0, a, b), c(1, a, b)], colour, 1); line([c(a, 0, b), c(a, 1, b)], colour, 1);
    line([c(a, b, 0), c(a, b, 1)], colour, 1);
  }
}
function obstacle(o) {
  const grey = "#777";
  const z = h => Math.min(Math.max(h, data.min[2]), data.max[2]);
  if (o.kind === "sphere") { [[0, 1], [0, 2], [1, 2]].forEach(ax => ring(o.center, o.radius, ax, grey)); }
  else if (o.kind === "box") { box(o.min.map((v, i) => Math.max(v, data.min[i])), o.max.map((v, i) => Math.min(v, data.max[i])), grey); }
  else if (o.kind === "pillar") {
    const [b, t] = [z(o.bottom), z(o.top)];
    ring([o.center[0], o.center[1], b], o.radius, [0, 1], grey); ring([o.center[0], o.center[1], t], o.radius, [0, 1], grey);
    for (let k = 0; k < 4; k++) {
      const a = k * Math.PI / 2, x = o.center[0] + o.radius * Math.cos(a), y = o.center[1] + o.radius * Math.sin(a);
      line([[x, y, b], [x, y, t]], grey, 1);
    }
  } else if (o.kind === "floor" || o.kind === "ceiling") {
    const h = o.height, n = 10, colour = o.kind === "floor" ? "#ccc" : "#e4e4e4";
    for (let k = 0; k <= n; k++) {
      const x = data.min[0] + (data.max[0] - data.min[0]) * k / n, y = data.min[1] + (data.max[1] - data.min[1]) * k / n;
      line([[x, data.min[1], h], [x, data.max[1], h]], colour, 1); line([[data.min[0], y, h], [data.max[0], y, h]], colour, 1);
    }
  }
}
function colour(beta) {
  if (beta === null) return "#000";
  return beta <= data.beta_l + 1e-9 ? "#1f77b4" : beta <= 1.0 ? "#9467bd" : "#d62728";
}
function draw() {
  canvas.width = window.innerWidth; canvas.height = window.innerHeight;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  box(data.min, data.max, "#eee");
  data.obstacles.forEach(obstacle);
  [[0, 1], [0, 2], [1, 2]].forEach(ax => ring(data.goal, data.goal_radius, ax, "#2ca02c"));
  const planner = data.samples.filter(s => s.q).map(s => s.q);
  if (planner.length) line(planner, "#555", 1, true);
  let previous = data.start;
  data.samples.forEach(s => { line([previous, s.p], colour(s.beta), 3); previous = s.p; });
  data.samples.filter(s => s.q && s.bound).forEach(s => {
    const [x, y] = project(s.q);
    ctx.beginPath(); ctx.setLineDash([]); ctx.strokeStyle = "#ff7f0e"; ctx.lineWidth = 1;
    ctx.arc(x, y, s.bound * scale(), 0, 2 * Math.PI); ctx.stroke();
  });
}
let dragging = null;
canvas.addEventListener("mousedown", e => { dragging = [e.clientX, e.clientY]; });
window.addEventListener("mouseup", () => { dragging = null; });
window.addEventListener("mousemove", e => {
  if (!dragging) return;
  yaw += (e.clientX - dragging[0]) * 0.01;
  pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - dragging[1]) * 0.01));
  dragging = [e.clientX, e.clientY]; draw();
});
canvas.addEventListener("wheel", e => { e.preventDefault(); zoom *= Math.exp(-e.deltaY * 0.001); draw(); });
window.addEventListener("resize", draw);
draw();
</script></body></html>
"##;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{Outcome, Sample};
    use fastrack_online::geometry::SpaceObstacle;

    #[test]
    fn the_page_holds_the_world_and_the_run_and_needs_nothing_else() {
        let world = World::<SpaceObstacle, 3> {
            min: [0.0; 3],
            max: [10.0, 8.0, 4.0],
            start: [1.0, 4.0, 2.0],
            start_heading: 0.0,
            start_speed: 0.0,
            goal: [9.0, 4.0, 2.0],
            goal_radius: 1.0,
            obstacles: vec![
                SpaceObstacle::Floor { height: 0.0 },
                SpaceObstacle::Pillar { center: [5.0, 4.0], radius: 0.5, bottom: 0.0, top: 4.0 },
            ],
        };
        let sample = |k: usize| Sample {
            t: k as f64 * 0.01,
            position: [1.0 + 0.001 * k as f64, 4.0, 2.0],
            planner: Some([1.0 + 0.001 * k as f64, 4.0, 2.0]),
            beta: Some(0.5),
            bound: Some(0.4),
            error: Some(0.0),
            clearance: 1.0,
            sensed: 1,
        };
        let mut run = Run::<SpaceObstacle, 3>::starting("PF", 4.0, 0.4, 0.01);
        (run.outcome, run.time, run.samples) = (Outcome::Reached, 120.0, (0..12_000).map(sample).collect());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.html");
        write_html(&path, &world, &run, 0.5, 2.0).unwrap();
        let page = std::fs::read_to_string(&path).unwrap();
        assert!(!page.contains("src=") && !page.contains("http"), "the page loads something");
        let start = page.find("const data = ").unwrap() + "const data = ".len();
        let end = start + page[start..].find(";\n").unwrap();
        let data: serde_json::Value = serde_json::from_str(&page[start..end]).unwrap();
        assert_eq!(data["obstacles"][1]["kind"], "pillar");
        assert_eq!(data["goal"], json!([9.0, 4.0, 2.0]));
        // 12,000 samples thinned to every third (4,000) and the last; a bound every 2 s of 0.01 s periods.
        let samples = data["samples"].as_array().unwrap();
        assert_eq!(samples.len(), 4_001);
        assert_eq!(samples.last().unwrap()["p"][0], json!(1.0 + 0.001 * 11_999.0));
        assert_eq!(samples.iter().filter(|s| !s["bound"].is_null()).count(), 60);
    }
}
