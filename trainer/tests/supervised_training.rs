//! Grid-supervised training on the double integrator against the closed-form TEB `V_min(beta) = beta^2 / a`:
//! grid solutions at three `beta` are solved here, the committed supervised config is trained on them, and
//! every one of the 16 table rows, most of them between the solved `beta`, must lie within 10% of the closed
//! form. Targets between the solutions come from blending them in `beta`; supervising each solution at its own
//! `beta` only left rows between them off by up to 113% (measured), which this assertion catches.
//!
//! The supervision carries the value at the horizon, so the table alone does not show that the HJI residual
//! was trained right: with the Hamiltonian's sign flipped the rows stay within 10% (measured: -6.0% to
//! +2.9%). The trained function must therefore also satisfy the HJI-VI over the whole horizon, checked here in
//! f64 with the system's own Hamiltonian (`AffineSystem::hamiltonian`, not the trainer's tensor one), and the
//! same run with the sign flipped must fail that check.

use burn::tensor::Device;
use fastrack_grid::spec::SolutionStore;
use fastrack_grid::store::solve_or_load;
use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::train::{train, RunDir, TrainOptions};
use fastrack_valuefn::network::ValueNetwork;
use fastrack_valuefn::system::double_integrator::closed_form_teb;
use fastrack_valuefn::system::AffineSystem;
use fastrack_valuefn::teb::{teb_table, AtHorizon, TebOptions};
use rand::{Rng, SeedableRng};

/// Largest relative TEB error accepted on any row (the target).
const TOLERANCE: f64 = 0.10;

/// Largest mean `|min(V - l, dV/dtau - H(r, dV/dr))|` accepted over the sampled `(tau, r, beta)`, in m/s
/// (measured: 0.22-0.25 over seeds 1-3; 0.71 with the sign flipped).
const RESIDUAL_TOLERANCE: f64 = 0.4;

/// Random points at which the HJI-VI residual is measured.
const RESIDUAL_SAMPLES: usize = 20_000;

/// What one supervised training run gave.
struct Outcome {
    /// `(beta, learned V_min / closed form - 1)` per table row.
    row_errors: Vec<(f64, f64)>,
    /// Mean absolute HJI-VI residual of the trained function over the domain and horizon.
    mean_residual: f64,
}

impl Outcome {
    /// `Ok` when every row is within [`TOLERANCE`] and the residual within [`RESIDUAL_TOLERANCE`]; otherwise
    /// what missed.
    fn check(&self) -> Result<(), String> {
        let mut failures: Vec<String> = self
            .row_errors
            .iter()
            .filter(|(_, error)| error.abs() >= TOLERANCE)
            .map(|(beta, error)| format!("beta {beta}: learned V_min {:+.1}% from the closed form", 100.0 * error))
            .collect();
        if self.mean_residual >= RESIDUAL_TOLERANCE {
            failures.push(format!("mean |HJI-VI residual| {:.4} (allowed {RESIDUAL_TOLERANCE})", self.mean_residual));
        }
        if failures.is_empty() {
            Ok(())
        } else {
            Err(failures.join("; "))
        }
    }
}

/// Mean `|min(V - l, dV/dtau - H(r, dV/dr; beta))|` of `network` at uniform random `tau` in `[0, tau_max]`,
/// states in the domain and parameters in their ranges.
fn mean_hji_residual(network: &ValueNetwork, system: &AffineSystem, tau_max: f64) -> f64 {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let total: f64 = (0..RESIDUAL_SAMPLES)
        .map(|_| {
            let tau = rng.random_range(0.0..tau_max);
            let r: Vec<f64> = system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect();
            let params: Vec<f64> = system.params.iter().map(|d| rng.random_range(d.min..=d.max)).collect();
            let v = network.evaluate(tau, &r, &params);
            let gap = v.value - system.tracking_error(&r);
            gap.min(v.grad_tau - system.hamiltonian(&r, &v.grad_state, &params)).abs()
        })
        .sum();
    total / RESIDUAL_SAMPLES as f64
}

/// Solves the config's grids into a temporary folder, trains
/// `configs/experiments/double_integrator_supervised.toml` on
/// them with the Hamiltonian multiplied by `sign`, and measures the table and the residual.
fn train_supervised(sign: f64) -> Outcome {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/experiments/double_integrator_supervised.toml");
    let mut config = TrainConfig::load(&path).unwrap();
    let system = config.system().unwrap();
    let dir = tempfile::tempdir().unwrap();

    // The solutions the config names, solved by their specs into a store in the temporary folder.
    let supervision = config.supervision.as_mut().expect("the config is supervised");
    supervision.store = dir.path().join("grid-solutions");
    let store = SolutionStore::new(&supervision.store);
    for spec in supervision.solutions.specs() {
        let (solution, _) = solve_or_load(&store, &spec, false).unwrap();
        let v_min = solution.v_min();
        eprintln!("grid beta {}: V_min {v_min:.4} (closed form {:.4})", spec.beta, closed_form_teb(spec.beta));
    }

    let run = RunDir(dir.path().join("run"));
    let options = TrainOptions { hamiltonian_sign: sign, ..TrainOptions::new(&run) };
    let (network, _) = train(&config, &Device::flex().autodiff(), options).expect("training runs");
    let oracle = AtHorizon { network: &network, tau: config.sampling.tau_max };
    let report = teb_table(&oracle, &system, &TebOptions::default()).expect("a table");
    assert!(report.rows.len() >= 16);
    let outcome = Outcome {
        row_errors: report
            .rows
            .iter()
            .map(|row| (row.beta, row.measured_min / closed_form_teb(row.beta) - 1.0))
            .collect(),
        mean_residual: mean_hji_residual(&network, &system, config.sampling.tau_max),
    };
    eprintln!(
        "sign {sign}: relative TEB errors by beta {:.3?}, mean |HJI-VI residual| {:.4}",
        outcome.row_errors, outcome.mean_residual
    );
    outcome
}

#[test]
fn supervised_double_integrator_is_within_10_percent_of_the_closed_form_and_satisfies_the_hji_vi() {
    train_supervised(1.0).check().unwrap();
}

#[test]
fn supervised_training_with_a_wrong_hamiltonian_sign_fails_the_check() {
    let outcome = train_supervised(-1.0);
    assert!(outcome.check().is_err(), "a wrong sign passed: mean residual {:.4}", outcome.mean_residual);
}
