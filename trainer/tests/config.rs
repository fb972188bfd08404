//! Bad configurations are rejected, with the field named, before any work starts; a resumed run continues
//! exactly where an uninterrupted one would be.

use fastrack_trainer::config::TrainConfig;
use fastrack_trainer::train::{train, RunDir, TrainOptions};
use std::path::Path;

fn base_text() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/experiments/double_integrator.toml"))
        .unwrap()
}

fn load(text: &str) -> Result<TrainConfig, String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.toml");
    std::fs::write(&path, text).unwrap();
    TrainConfig::load(&path).map_err(|e| format!("{e:#}"))
}

#[test]
fn every_config_in_the_repository_is_valid() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut checked = 0;
    for dir in [root.clone(), root.join("experiments")] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                TrainConfig::load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
                checked += 1;
            }
        }
    }
    assert!(checked >= 7, "only {checked} configs found in {} and its experiments/", root.display());
}

#[test]
fn bad_configs_name_what_is_wrong() {
    let cases = [
        ("system = \"double_integrator\"", "system = \"unicycle\"", "unknown system \"unicycle\""),
        ("hidden = [64, 64, 64]", "hidden = [64, 0]", "network.hidden widths must be > 0"),
        ("hidden = [64, 64, 64]", "hidden = []", "network.hidden must list at least one layer"),
        ("tau_max = 6.0", "tau_max = 0.0", "sampling.tau_max must be > 0"),
        ("points = 4000", "points = 0", "sampling.points must be at least 2"),
        ("iterations = 3000", "iterations = 0", "optimizer.iterations must be > 0"),
        ("learning_rate = 1e-3", "learning_rate = -1e-3", "learning rates must be > 0"),
        ("omega_0 = 30.0", "omega_0 = 30.0\ncolour = 3", "unknown field `colour`"),
        ("time_step = 0.05", "time_step = 0.0", "loss.time_step must be > 0"),
        ("time_step = 0.05", "time_step = 7.0", "loss.time_step must be below sampling.tau_max"),
        ("causal_epsilon = 1.0", "causal_epsilon = -1.0", "loss.causal_epsilon must be >= 0"),
        ("norm = \"l2\"", "norm = \"l3\"", "unknown variant `l3`"),
        ("tau_exponent = 2.0", "tau_exponent = 0.0", "sampling.tau_exponent must be > 0"),
        ("focus_share = 0.0", "focus_share = 2.0", "sampling.focus_share must be in [0, 1]"),
        ("focus_scale = 0.5", "focus_scale = 0.0", "sampling.focus_scale must be in (0, 1]"),
        ("first_layer_scale = 1.0", "first_layer_scale = 0.0", "network.first_layer_scale must be > 0"),
    ];
    let base = base_text();
    for (from, to, expected) in cases {
        assert!(base.contains(from), "fixture lacks {from:?}");
        let err = load(&base.replacen(from, to, 1)).expect_err(expected);
        assert!(err.contains(expected), "{to:?}: error {err:?} lacks {expected:?}");
    }
}

#[test]
fn bad_supervision_sections_name_what_is_wrong() {
    let good = "\n[supervision]\nweight = 1.0\npoints = 10\nsolutions = { system = \"double_integrator\", \
                resolution = [9], solves = [{ beta = 0.5 }], solver = { accuracy = \"weno5\", rk = \"3\", cfl = 0.75, \
                horizon_cap = 1.0, tolerance = 1e-3, tracking = true } }\n";
    let base = base_text() + good;
    assert!(load(&base).is_ok());
    let cases = [
        ("solves = [{ beta = 0.5 }]", "solves = []", "supervision.solutions.solves must list at least one solve"),
        ("resolution = [9]", "resolution = [9, 9, 9]", "supervision.solutions: resolution has 3 entries; give 1 or 2"),
        ("beta = 0.5", "beta = -0.5", "supervision.solutions: beta = -0.5 must be a positive number"),
        ("weight = 1.0", "weight = 0.0", "supervision.weight must be > 0"),
        ("weight = 1.0", "weight = 1.0\ngradient_weight = -1.0", "supervision.gradient_weight must be >= 0"),
        ("points = 10", "points = 0", "supervision.points must be > 0"),
        ("points = 10", "points = 10\nfocus_share = 1.5", "supervision.focus_share must be in [0, 1]"),
        ("points = 10", "points = 10\nfocus_factor = 0.5", "supervision.focus_factor must be >= 1"),
        ("points = 10", "points = 10\nown_grid_share = 1.5", "supervision.own_grid_share must be in [0, 1]"),
        (
            "points = 10",
            "points = 10\nown_grid_share = 0.6\nslice_share = 0.5",
            "supervision.slice_share must be in [0, 1 - own_grid_share]",
        ),
        ("points = 10", "points = 10\nunder_weight = 0.5", "supervision.under_weight must be >= 1"),
    ];
    let section = base.rfind("[supervision]").unwrap();
    for (from, to, expected) in cases {
        let edited = format!("{}{}", &base[..section], base[section..].replacen(from, to, 1));
        let err = load(&edited).expect_err(expected);
        assert!(err.contains(expected), "{to:?}: error {err:?} lacks {expected:?}");
    }
}

#[test]
fn a_resumed_run_matches_an_uninterrupted_one() {
    let mut config = load(&base_text()).unwrap();
    config.network.hidden = vec![16, 16];
    config.sampling.points = 256;
    config.optimizer.iterations = 40;
    config.checkpoint_every = 10;
    let device = burn::tensor::Device::flex().autodiff();
    fn options(run: &RunDir, resume: bool, max_iterations: Option<u64>) -> TrainOptions<'_> {
        TrainOptions { resume, max_iterations, ..TrainOptions::new(run) }
    }
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (whole_run, split_run) = (RunDir(a.path().into()), RunDir(b.path().into()));
    let (whole, _) = train(&config, &device, options(&whole_run, false, None)).unwrap();
    train(&config, &device, options(&split_run, false, Some(25))).unwrap();
    assert_eq!(split_run.load_state().unwrap().iteration, 25);
    let (resumed, state) = train(&config, &device, options(&split_run, true, None)).unwrap();
    assert_eq!(state.iteration, 40);
    let worst = whole
        .layers
        .iter()
        .zip(&resumed.layers)
        .flat_map(|(x, y)| x.weight.iter().zip(&y.weight))
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "weights after 25 + 15 iterations differ from 40 straight by {worst:e}");
}
