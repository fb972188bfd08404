//! Figures of runs (PNG, plotters): a trajectory like the paper's Fig. 3 (the path coloured by `beta`, the
//! sTEB and the dTEB drawn along it, the sensing range, obstacles sensed and not), every method on one world
//! (Fig. 4), and `beta`, clearance, tracking error and bound over time. A world in space is drawn in a
//! [`View`]: from above (x, y) or from the side (x, z), its solids as their outlines in that plane.

use crate::episode::Run;
use crate::world::World;
use fastrack_lab::plot::{fonts_available, line_chart, Chart, Series};
use fastrack_online::geometry::{Obstacle, PlaneObstacle, Point, SpaceObstacle};
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

/// Two axes of the workspace a figure is drawn in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct View {
    /// The horizontal and the vertical axis of the figure (0: x, 1: y, 2: z).
    pub axes: [usize; 2],
}

impl View {
    /// The plane itself, or a world in space from above.
    pub const TOP: View = View { axes: [0, 1] };
    /// A world in space from the side: x across, z up.
    pub const SIDE: View = View { axes: [0, 2] };

    /// The views a world of `D` axes is drawn in, each with the extension of its figure's file: the plane
    /// as it is (`png`); space from above (`png`) and from the side (`side.png`).
    pub fn all<const D: usize>() -> &'static [(&'static str, View)] {
        if D == 2 {
            &[("png", View::TOP)]
        } else {
            &[("png", View::TOP), ("side.png", View::SIDE)]
        }
    }

    /// The point's coordinates in the view.
    fn of<const D: usize>(self, p: &Point<D>) -> (f64, f64) {
        (p[self.axes[0]], p[self.axes[1]])
    }

    /// An axis' label.
    fn label(axis: usize) -> &'static str {
        ["x (m)", "y (m)", "z (m)"][axis]
    }
}

/// An obstacle as a figure draws it.
pub trait Outlined<const D: usize>: Obstacle<D> {
    /// Its outline in `view` as a polygon (`None`: nothing to draw there), the workspace `bounds` closing
    /// what is unbounded (a floor, a ceiling).
    fn outline(&self, view: View, bounds: (Point<D>, Point<D>)) -> Option<Vec<(f64, f64)>>;
}

/// `n` points on a circle.
fn circle(centre: (f64, f64), radius: f64, n: usize) -> Vec<(f64, f64)> {
    (0..=n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            (centre.0 + radius * a.cos(), centre.1 + radius * a.sin())
        })
        .collect()
}

/// A rectangle's corners.
fn rectangle((x0, y0): (f64, f64), (x1, y1): (f64, f64)) -> Vec<(f64, f64)> {
    vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
}

impl Outlined<2> for PlaneObstacle {
    fn outline(&self, _: View, _: (Point<2>, Point<2>)) -> Option<Vec<(f64, f64)>> {
        Some(plane_outline(self))
    }
}

impl Outlined<3> for SpaceObstacle {
    fn outline(&self, view: View, (lo, hi): (Point<3>, Point<3>)) -> Option<Vec<(f64, f64)>> {
        let [a, b] = view.axes;
        Some(match self {
            SpaceObstacle::Sphere { center, radius } => circle(view.of(center), *radius, 48),
            SpaceObstacle::Box { min, max } => rectangle(view.of(min), view.of(max)),
            SpaceObstacle::Pillar { center, radius, bottom, top } => {
                let at = |axis: usize| if axis == 2 { None } else { Some(center[axis]) };
                match (at(a), at(b)) {
                    (Some(x), Some(y)) => circle((x, y), *radius, 48),
                    (Some(x), None) => rectangle((x - radius, *bottom), (x + radius, *top)),
                    (None, Some(y)) => rectangle((*bottom, y - radius), (*top, y + radius)),
                    (None, None) => return None,
                }
            }
            SpaceObstacle::Floor { height } | SpaceObstacle::Ceiling { height } => {
                // A band below the floor or above the ceiling, seen only from the side.
                if b != 2 {
                    return None;
                }
                let (low, high) = match self {
                    SpaceObstacle::Floor { .. } => (height - (hi[2] - lo[2]), *height),
                    _ => (*height, height + (hi[2] - lo[2])),
                };
                rectangle((lo[a] - 1.0, low), (hi[a] + 1.0, high))
            }
        })
    }
}

/// The outline of a planar obstacle as a polygon.
fn plane_outline(obstacle: &PlaneObstacle) -> Vec<(f64, f64)> {
    match obstacle {
        PlaneObstacle::Circle { center, radius } => circle((center[0], center[1]), *radius, 48),
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
fn ever_sensed<'a, O: Obstacle<D>, const D: usize>(world: &'a World<O, D>, run: &Run<O, D>) -> Vec<&'a O> {
    world
        .obstacles
        .iter()
        .filter(|o| {
            o.distance(world.start) <= run.sensor_range
                || run.samples.iter().any(|s| o.distance(s.position) <= run.sensor_range)
        })
        .collect()
}

fn draw_world<DB: DrawingBackend, O: Outlined<D>, const D: usize>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    world: &World<O, D>,
    sensed: &[&O],
    view: View,
) -> Result<(), String> {
    for obstacle in &world.obstacles {
        let colour = if sensed.contains(&obstacle) { SENSED } else { UNSENSED };
        let Some(outline) = obstacle.outline(view, world.bounds()) else { continue };
        chart.draw_series(std::iter::once(Polygon::new(outline, colour.filled()))).map_err(drawing)?;
    }
    let goal = circle(view.of(&world.goal), world.goal_radius, 24);
    chart.draw_series(std::iter::once(PathElement::new(goal, STEB.stroke_width(3)))).map_err(drawing)?;
    Ok(())
}

/// The world's workspace as a white chart in metres on `root`, captioned and with axes when fonts exist.
fn world_chart<'r, 'b, O, const D: usize>(
    root: &'r DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    world: &World<O, D>,
    caption: &str,
    text: bool,
    view: View,
) -> Result<ChartContext<'r, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut builder = ChartBuilder::on(root);
    builder.margin(20);
    if text {
        builder.caption(caption, ("sans-serif", 22));
        builder.x_label_area_size(35).y_label_area_size(45);
    }
    let ((x0, y0), (x1, y1)) = (view.of(&world.min), view.of(&world.max));
    let mut chart = builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| e.to_string())?;
    if text {
        let [a, b] = view.axes;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(View::label(a))
            .y_desc(View::label(b))
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(chart)
}

/// Draws one run through `world` in `view` into a 1100x760 PNG: the tracker's path coloured by `beta`, the
/// planner dotted, the sTEB (green) and the dTEB (orange) around the planner every `every` seconds, the
/// sensing range (dashed grey) at the same places, sensed obstacles dark, the others light, the goal green.
pub fn trajectory<O: Outlined<D>, const D: usize>(
    path: &Path,
    world: &World<O, D>,
    run: &Run<O, D>,
    beta_l: f64,
    every: f64,
    view: View,
) -> Result<(), String> {
    let text = fonts_available();
    let root = BitMapBackend::new(path, (1100, 760)).into_drawing_area();
    let caption = format!("{}: {} after {:.1} s", run.method, run.outcome.label(), run.time);
    let mut chart = world_chart(&root, world, &caption, text, view)?;
    draw_world(&mut chart, world, &ever_sensed(world, run), view)?;
    let stride = ((every / run.control_period).round() as usize).max(1);
    for sample in run.samples.iter().step_by(stride) {
        let Some(planner) = sample.planner.as_ref().map(|p| view.of(p)) else { continue };
        chart
            .draw_series(std::iter::once(PathElement::new(circle(planner, run.steb_radius, 48), STEB.stroke_width(1))))
            .map_err(drawing)?;
        if let Some(bound) = sample.bound {
            chart
                .draw_series(std::iter::once(PathElement::new(circle(planner, bound, 48), DTEB.stroke_width(1))))
                .map_err(drawing)?;
        }
        let dashes = circle(view.of(&sample.position), run.sensor_range, 96);
        chart
            .draw_series(
                dashes.chunks(2).map(|pair| PathElement::new(pair.to_vec(), RGBColor(160, 160, 160).stroke_width(1))),
            )
            .map_err(drawing)?;
    }
    let mut previous = view.of(&world.start);
    for sample in &run.samples {
        let (colour, here) = (beta_colour(sample.beta, beta_l), view.of(&sample.position));
        chart
            .draw_series(std::iter::once(PathElement::new(vec![previous, here], colour.stroke_width(3))))
            .map_err(drawing)?;
        previous = here;
    }
    let planner: Vec<(f64, f64)> = run.samples.iter().filter_map(|s| s.planner.as_ref()).map(|p| view.of(p)).collect();
    chart.draw_series(planner.iter().step_by(10).map(|&p| Circle::new(p, 1, BLACK.filled()))).map_err(drawing)?;
    root.present().map_err(|e| e.to_string())
}

/// Draws every run through the same `world` in `view` into one PNG, one colour per method (the paper's
/// Fig. 4).
pub fn methods_on_one_world<O: Outlined<D>, const D: usize>(
    path: &Path,
    world: &World<O, D>,
    runs: &[&Run<O, D>],
    view: View,
) -> Result<(), String> {
    let text = fonts_available();
    let root = BitMapBackend::new(path, (1100, 760)).into_drawing_area();
    let mut chart = world_chart(&root, world, "every method through one world", text, view)?;
    let sensed: Vec<&O> = runs.iter().flat_map(|r| ever_sensed(world, r)).collect();
    draw_world(&mut chart, world, &sensed, view)?;
    for (i, run) in runs.iter().enumerate() {
        let colour = METHOD_COLOURS[i % METHOD_COLOURS.len()];
        let points: Vec<(f64, f64)> =
            std::iter::once(view.of(&world.start)).chain(run.samples.iter().map(|s| view.of(&s.position))).collect();
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
pub fn over_time<O, const D: usize>(path: &Path, run: &Run<O, D>) -> Result<(), String> {
    let series = |label: &str, f: &dyn Fn(&crate::episode::Sample<D>) -> Option<f64>| Series {
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
pub fn time_to_goal<O, const D: usize>(
    path: &Path,
    methods: &[&str],
    runs_by_method: &[Vec<&Run<O, D>>],
) -> Result<(), String> {
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
