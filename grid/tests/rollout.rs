//! Rollouts of a grid solution's own tracker policy against the double integrator's closed-form TEB.

use fastrack_grid::grid::Grid;
use fastrack_grid::rollout::{roll_out_solution, RolloutError, RolloutOptions};
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_valuefn::system::double_integrator::{closed_form_teb, system};

#[test]
fn planners_sustain_the_closed_form_teb_against_a_converged_policy() {
    // A converged solve (201x101, tolerance 0.02 beta: V_min 1.9% above the closed form). Planners that do not
    // push would leave the error near 0; a policy that does not track would let it run to the domain's edge.
    let system = system();
    let beta = 1.0;
    let grid = Grid::for_system(&system, &[201, 101]).unwrap();
    let config = SolverConfig { tolerance: 0.02 * beta, ..SolverConfig::default() };
    let solution = solve(&system, &[beta], &grid, &config, false).unwrap();
    let options = RolloutOptions { horizon: 30.0, ..RolloutOptions::default() };
    let report = roll_out_solution(&system, &solution, &options).unwrap();
    let teb = closed_form_teb(beta);
    eprintln!("{report:?}, closed form {teb}");
    assert_eq!(report.left_domain, 0);
    assert!(report.starts > 50, "{} starts", report.starts);
    let random = report.sustained_random.expect("4 random planners per start by default");
    for (planner, sustained) in [("worst-case", report.sustained_worst_case), ("random", random)] {
        let ratio = sustained / teb;
        assert!((0.95..1.08).contains(&ratio), "{planner} planners sustain {ratio:.4} of the closed-form TEB");
    }
}

#[test]
fn bad_options_and_a_solution_of_another_system_are_refused_and_no_random_planners_report_none() {
    let system = system();
    let grid = Grid::for_system(&system, &[21, 11]).unwrap();
    let config = SolverConfig { horizon_cap: 0.1, ..SolverConfig::default() };
    let solution = solve(&system, &[1.0], &grid, &config, false).unwrap();
    for options in [
        RolloutOptions { horizon: f64::NAN, ..RolloutOptions::default() },
        RolloutOptions { step: 0.0, ..RolloutOptions::default() },
        RolloutOptions { horizon: 0.01, step: 0.01, ..RolloutOptions::default() },
        RolloutOptions { start_margin: -0.1, ..RolloutOptions::default() },
        RolloutOptions { max_starts: 0, ..RolloutOptions::default() },
    ] {
        assert!(
            matches!(roll_out_solution(&system, &solution, &options), Err(RolloutError::Setting(_))),
            "{options:?}"
        );
    }
    let worst_case_only = RolloutOptions { horizon: 1.0, random_planners: 0, ..RolloutOptions::default() };
    let report = roll_out_solution(&system, &solution, &worst_case_only).unwrap();
    assert_eq!(report.sustained_random, None);
    assert_eq!(report.sustained(), report.sustained_worst_case);
    let dubins = fastrack_valuefn::system::by_id("dubins4d").unwrap();
    let error = roll_out_solution(&dubins, &solution, &RolloutOptions::default()).unwrap_err();
    assert!(matches!(error, RolloutError::System { .. }), "{error}");
}
