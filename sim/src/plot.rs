//! Figures of runs (PNG, plotters): a trajectory like the paper's Fig. 3 (the path coloured by `beta`, the
//! sTEB and the dTEB drawn along it, the sensing range, obstacles sensed and not), every method on one world
//! (Fig. 4), and `beta`, clearance, tracking error and bound over time.

use crate::episode::PlaneRun;
use crate::world::PlaneWorld;
use fastrack_lab::plot::{fonts_available, line_chart, Chart, Series};
use fastrack_online::geometry::{Obstacle, PlaneObstacle, Point};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

const UNSENSED: RGBColor = RGBColor(215, 215, 215);
const SENSED: RGBColor = RGBColor(110, 110, 110);
const STEB: RGBColor = RGBColor(44, 160, 44);
const DTEB: RGBColor = RGBColor(255, 127, 14);
const METHOD_COLOURS: [RGBColor; 5] =
    [RGBColor(31, 119, 180), RGBColor(148, 103, 189), RGBColor(140, 86, 75), RGBColor(214, 39, 40), RGBColor(0, 0, 0)];

/// The paper's colours for the planner speed: `beta_l` blue, up to 1 m/s purple, above red.
fn beta_colour(beta: Option<f64>, beta_l: f64) -> RGBColor {
    match beta {
        None => BLACK,
        Some(b) if b <= beta_l + 1e-9 => RGBColor(31, 119, 180),
        Some(b) if b <= 1.0 => RGBColor(148, 103, 189),
        Some(_) => RGBColor(214, 39, 40),
    }
}

/// A drawing error as text.
fn drawing<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> String {
    e.to_string()
}

/// `n` points on a circle.
fn circle(centre: Point, radius: f64, n: usize) -> Vec<(f64, f64)> {
    (0..=n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            (centre[0] + radius * a.cos(), centre[1] + radius * a.sin())
        })
        .collect()
}

/// The outline of an obstacle as a polygon.
fn outline(obstacle: &PlaneObstacle) -> Vec<(f64, f64)> {
    match obstacle {
        PlaneObstacle::Circle { center, radius } => circle(*center, *radius, 48),
        PlaneObstacle::Rectangle { min, max } => {
            vec![(min[0], min[1]), (max[0], min[1]), (max[0], max[1]), (min[0], max[1])]
        }
        PlaneObstacle::Wall { from, to, thickness } => {
            let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
            let length = dx.hypot(dy).max(1e-12);
            let (nx, ny) = (-dy / length * thickness / 2.0, dx / length * thickness / 2.0);
            vec![
                (from[0] + nx, from[1] + ny),
                (to[0] + nx, to[1] + ny),
                (to[0] - nx, to[1] - ny),
                (from[0] - nx, from[1] - ny),
            ]
        }
    }
}

/// Obstacles of `world` some sample of `run` came within sensing range of.
fn ever_sensed<'a>(world: &'a PlaneWorld, run: &PlaneRun) -> Vec<&'a PlaneObstacle> {
    world
        .obstacles
        .iter()
        .filter(|o| {
            o.distance(world.start) <= run.sensor_range
                || run.samples.iter().any(|s| o.distance(s.position) <= run.sensor_range)
        })
        .collect()
}

fn draw_world<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    world: &PlaneWorld,
    sensed: &[&PlaneObstacle],
) -> Result<(), String> {
    for obstacle in &world.obstacles {
        let colour = if sensed.contains(&obstacle) { SENSED } else { UNSENSED };
        chart.draw_series(std::iter::once(Polygon::new(outline(obstacle), colour.filled()))).map_err(drawing)?;
    }
    chart
        .draw_series(std::iter::once(PathElement::new(circle(world.goal, world.goal_radius, 24), STEB.stroke_width(3))))
        .map_err(drawing)?;
    Ok(())
}

/// The world's workspace as a white chart in metres on `root`, captioned and with axes when fonts exist.
fn world_chart<'r, 'b>(
    root: &'r DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    world: &PlaneWorld,
    caption: &str,
    text: bool,
) -> Result<ChartContext<'r, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut builder = ChartBuilder::on(root);
    builder.margin(20);
    if text {
        builder.caption(caption, ("sans-serif", 22));
        builder.x_label_area_size(35).y_label_area_size(45);
    }
    let mut chart = builder
        .build_cartesian_2d(world.min[0]..world.max[0], world.min[1]..world.max[1])
        .map_err(|e| e.to_string())?;
    if text {
        chart.configure_mesh().disable_mesh().x_desc("x (m)").y_desc("y (m)").draw().map_err(|e| e.to_string())?;
    }
    Ok(chart)
}

/// Draws one run through `world` into a 1100x760 PNG: the tracker's path coloured by `beta`, the planner
/// dotted, the sTEB (green) and the dTEB (orange) around the planner every `every` seconds, the sensing
/// range (dashed grey) at the same places, sensed obstacles dark, the others light, the goal green.
pub fn trajectory(path: &Path, world: &PlaneWorld, run: &PlaneRun, beta_l: f64, every: f64) -> Result<(), String> {
    let text = fonts_available();
    let root = BitMapBackend::new(path, (1100, 760)).into_drawing_area();
    let caption = format!("{}: {} after {:.1} s", run.method, run.outcome.label(), run.time);
    let mut chart = world_chart(&root, world, &caption, text)?;
    draw_world(&mut chart, world, &ever_sensed(world, run))?;
    let stride = ((every / run.control_period).round() as usize).max(1);
    for sample in run.samples.iter().step_by(stride) {
        let Some(planner) = sample.planner else { continue };
        chart
            .draw_series(std::iter::once(PathElement::new(circle(planner, run.steb_radius, 48), STEB.stroke_width(1))))
            .map_err(drawing)?;
        if let Some(bound) = sample.bound {
            chart
                .draw_series(std::iter::once(PathElement::new(circle(planner, bound, 48), DTEB.stroke_width(1))))
                .map_err(drawing)?;
        }
        let dashes = circle(sample.position, run.sensor_range, 96);
        chart
            .draw_series(
                dashes.chunks(2).map(|pair| PathElement::new(pair.to_vec(), RGBColor(160, 160, 160).stroke_width(1))),
            )
            .map_err(drawing)?;
    }
    let mut previous = world.start;
    for sample in &run.samples {
        let colour = beta_colour(sample.beta, beta_l);
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(previous[0], previous[1]), (sample.position[0], sample.position[1])],
                colour.stroke_width(3),
            )))
            .map_err(drawing)?;
        previous = sample.position;
    }
    let planner: Vec<(f64, f64)> = run.samples.iter().filter_map(|s| s.planner).map(|p| (p[0], p[1])).collect();
    chart.draw_series(planner.iter().step_by(10).map(|&p| Circle::new(p, 1, BLACK.filled()))).map_err(drawing)?;
    root.present().map_err(|e| e.to_string())
}

/// Draws every run through the same `world` into one PNG, one colour per method (the paper's Fig. 4).
pub fn methods_on_one_world(path: &Path, world: &PlaneWorld, runs: &[&PlaneRun]) -> Result<(), String> {
    let text = fonts_available();
    let root = BitMapBackend::new(path, (1100, 760)).into_drawing_area();
    let mut chart = world_chart(&root, world, "every method through one world", text)?;
    let sensed: Vec<&PlaneObstacle> = runs.iter().flat_map(|r| ever_sensed(world, r)).collect();
    draw_world(&mut chart, world, &sensed)?;
    for (i, run) in runs.iter().enumerate() {
        let colour = METHOD_COLOURS[i % METHOD_COLOURS.len()];
        let points: Vec<(f64, f64)> = std::iter::once((world.start[0], world.start[1]))
            .chain(run.samples.iter().map(|s| (s.position[0], s.position[1])))
            .collect();
        let series =
            chart.draw_series(std::iter::once(PathElement::new(points, colour.stroke_width(3)))).map_err(drawing)?;
        if text {
            series
                .label(format!("{} ({}, {:.1} s)", run.method, run.outcome.label(), run.time))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(3)));
        }
    }
    if text {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// `beta`, clearance, tracking error and the bound in force over time.
pub fn over_time(path: &Path, run: &PlaneRun) -> Result<(), String> {
    let series = |label: &str, f: &dyn Fn(&crate::episode::Sample<2>) -> Option<f64>| Series {
        label: label.into(),
        points: run.samples.iter().filter_map(|s| f(s).map(|y| (s.t, y))).collect(),
        markers: false,
    };
    let all = [
        series("beta (m/s)", &|s| s.beta),
        series("clearance (m)", &|s| Some(s.clearance.min(10.0))),
        series("tracking error (m)", &|s| s.error),
        series("bound in force (m)", &|s| s.bound),
    ];
    let drawn: Vec<Series> = all.into_iter().filter(|s| !s.points.is_empty()).collect();
    let title = format!("{}: beta, clearance, error and bound", run.method);
    line_chart(path, &Chart { title: &title, x_label: "t (s)", y_label: "", log_y: false }, &drawn)
}

/// Time to goal per world, one marker series per method (runs that did not reach the goal are left out).
pub fn time_to_goal(path: &Path, methods: &[&str], runs_by_method: &[Vec<&PlaneRun>]) -> Result<(), String> {
    let drawn: Vec<Series> = methods
        .iter()
        .zip(runs_by_method)
        .map(|(label, runs)| Series {
            label: (*label).into(),
            points: runs
                .iter()
                .enumerate()
                .filter(|(_, r)| r.outcome == crate::episode::Outcome::Reached)
                .map(|(w, r)| ((w + 1) as f64, r.time))
                .collect(),
            markers: true,
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    let chart =
        Chart { title: "time to goal per world", x_label: "world (seed)", y_label: "time to goal (s)", log_y: false };
    line_chart(path, &chart, &drawn)
}
