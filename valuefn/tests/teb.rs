//! The TEB table refuses a value function with a negative minimum, saying where it is: no tracking value
//! function has one (`V >= l >= 0`), and the state tells the model's author which region was not learned.
//! Its levels hold the resting state of a system that has one, the sets' overlap is measured, and so is the
//! shape of a set too thin in many dimensions for uniform states to land in.

use fastrack_valuefn::manifest::TebRow;
use fastrack_valuefn::system::{double_integrator, quad10d};
use fastrack_valuefn::teb::{nested_shares, reshape_at_set_levels, teb_table, TebOptions, ValueOracle};
use rand::SeedableRng;

/// `V(r) = |r - c|^2 - 1`: negative around `c`, least (-1) at `c`.
struct Dip {
    centre: [f64; 2],
}

impl ValueOracle for Dip {
    fn values_and_grads(&self, states: &[f64], _params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let (mut values, mut grads) = (Vec::new(), Vec::new());
        for r in states.chunks(2) {
            let d = [r[0] - self.centre[0], r[1] - self.centre[1]];
            values.push(d[0] * d[0] + d[1] * d[1] - 1.0);
            grads.extend([2.0 * d[0], 2.0 * d[1]]);
        }
        Ok((values, grads))
    }
}

#[test]
fn a_negative_minimum_is_refused_with_the_state_where_it_lies() {
    let system = double_integrator::system();
    let oracle = Dip { centre: [0.5, -0.25] };
    let error = teb_table(&oracle, &system, &TebOptions::default()).unwrap_err();
    assert!(error.starts_with("V_min = -"), "{error}");
    let names: Vec<&str> = system.state.iter().map(|d| d.name).collect();
    // The refinement lands on the dip's centre: each coordinate named with its value to 3 decimals.
    let expected = format!("({} = 0.500, {} = -0.250)", names[0], names[1]);
    assert!(error.contains(&expected), "{error} should name {expected}");
}

/// `V(x, v; beta) = max(|x|, |v - shift(beta)|)`: each sublevel set a square in the `(x, v)` plane, centred
/// on the speed `shift(beta)`.
struct Squares;

fn shift(beta: f64) -> f64 {
    if beta < 0.6 {
        0.0
    } else {
        0.25
    }
}

impl ValueOracle for Squares {
    fn values_and_grads(&self, states: &[f64], params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let values =
            states.chunks(2).zip(params).map(|(r, &beta)| r[0].abs().max((r[1] - shift(beta)).abs())).collect();
        Ok((values, vec![0.0; states.len()]))
    }
}

#[test]
fn nested_shares_are_the_overlap_of_each_set_with_the_next_ones() {
    // Squares of half-width 0.5 at speeds 0 and 0.25 overlap in 0.75 of the first; the second lies inside the
    // third (half-width 0.8, the same centre); the last row has no next one.
    let row = |beta: f64, level: f64| TebRow {
        beta,
        level,
        measured_min: level,
        extent: vec![level],
        boundary_radii: Vec::new(),
        verification: None,
        nested_share: None,
        reference: None,
    };
    let rows = [row(0.5, 0.5), row(0.75, 0.5), row(1.0, 0.8)];
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let shares = nested_shares(&Squares, &double_integrator::system(), &rows, &mut rng).unwrap();
    let first = shares[0].expect("the first set is sampled");
    assert!((first - 0.75).abs() < 0.04, "overlap share {first}, expected 0.75");
    assert_eq!(shares[1], Some(1.0));
    assert_eq!(shares[2], None);
}

/// `V(r; beta) = beta (1 + |r - c|^2)` with `c` = 0.3 m of x error: least (`beta`) off the resting state,
/// `1.09 beta` at rest.
struct OffRest;

impl ValueOracle for OffRest {
    fn values_and_grads(&self, states: &[f64], params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let (mut values, mut grads) = (Vec::new(), Vec::new());
        for (r, p) in states.chunks(10).zip(params.chunks(3)) {
            let d: Vec<f64> = r.iter().enumerate().map(|(i, x)| if i == 0 { x - 0.3 } else { *x }).collect();
            values.push(p[0] * (1.0 + d.iter().map(|x| x * x).sum::<f64>()));
            grads.extend(d.iter().map(|x| 2.0 * p[0] * x));
        }
        Ok((values, grads))
    }
}

#[test]
fn every_level_holds_the_hovering_state() {
    let options = TebOptions { boundary_directions: 8, boundary_samples: 16, ..TebOptions::default() };
    let report = teb_table(&OffRest, &quad10d::system(), &options).unwrap();
    assert_eq!(report.raised_to_rest.len(), report.rows.len(), "{:?}", report.raised_to_rest);
    for (row, &(beta, before, at_rest)) in report.rows.iter().zip(&report.raised_to_rest) {
        assert_eq!(beta, row.beta);
        // The learned minimum (at least beta) stays as measured; the level is V at rest.
        assert!(row.measured_min >= row.beta && row.measured_min < at_rest, "{row:?}");
        assert!(before < at_rest && (at_rest - 1.09 * row.beta).abs() < 1e-12, "{before} {at_rest}");
        assert_eq!(row.level, at_rest);
    }
}

/// `V(r) = 0.1 + sqrt(|e|^2 + sum_i (r_i / s_i)^2)` on quad10d, `e` the position errors and `s_i` a
/// twentieth of each other coordinate's half-range: `V >= |e|`, and at level 1 the set reaches 0.9 m along
/// each error axis (at rest), while a uniform state's velocities, tilts and rates almost surely put it outside.
struct ThinSet;

impl ValueOracle for ThinSet {
    fn values_and_grads(&self, states: &[f64], _params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let system = quad10d::system();
        let values = states
            .chunks(10)
            .map(|r| {
                let squares = r.iter().zip(&system.state).enumerate().map(|(i, (x, d))| {
                    let scale = if system.error_coords.contains(&i) { 1.0 } else { (d.max - d.min) / 40.0 };
                    (x / scale).powi(2)
                });
                0.1 + squares.sum::<f64>().sqrt()
            })
            .collect();
        Ok((values, vec![0.0; states.len()]))
    }
}

#[test]
fn a_thin_set_in_many_dimensions_is_measured_from_the_resting_state() {
    let row = |beta: f64| TebRow {
        beta,
        level: 1.0,
        measured_min: 0.1,
        extent: vec![0.0; 3],
        boundary_radii: Vec::new(),
        verification: None,
        nested_share: None,
        reference: None,
    };
    let mut rows = [row(0.5), row(1.5)];
    reshape_at_set_levels(&ThinSet, &quad10d::system(), &mut rows, &TebOptions::default()).unwrap();
    for row in &rows {
        // Bisection from the level in 10 halvings: within 1/1024 below the true 0.9.
        assert!(row.extent.iter().all(|&e| (0.9 - 1.0 / 1024.0..=0.9).contains(&e)), "{:?}", row.extent);
    }
}
