//! The TEB table refuses a value function with a negative minimum, saying where it is: no tracking value
//! function has one (`V >= l >= 0`), and the state tells the model's author which region was not learned.

use fastrack_valuefn::system::double_integrator;
use fastrack_valuefn::teb::{teb_table, TebOptions, ValueOracle};

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
