//! Tracking-error-bound tables from a value function: `V_min(beta)` by dense sampling plus local
//! refinement, a conservative (monotone) level, the error set's extent and boundary radii.

use crate::manifest::{boundary_directions, TebRow, MIN_TEB_ROWS};
use crate::network::ValueNetwork;
use crate::system::AffineSystem;
use rand::{Rng, SeedableRng};

/// Anything that evaluates `V` and `dV/dr` on a batch (row-major states and params).
pub trait ValueOracle {
    /// Returns `(values [N], grads [N x n_state])`.
    fn values_and_grads(&self, states: &[f64], params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String>;
}

/// A network evaluated at a fixed horizon (f64 reference).
pub struct AtHorizon<'a> {
    /// The network.
    pub network: &'a ValueNetwork,
    /// The horizon.
    pub tau: f64,
}

impl ValueOracle for AtHorizon<'_> {
    fn values_and_grads(&self, states: &[f64], params: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let n_state = self.network.n_state();
        let n_params = params.len() / (states.len() / n_state).max(1);
        let mut values = Vec::new();
        let mut grads = Vec::new();
        for (s, p) in states.chunks(n_state).zip(params.chunks(n_params)) {
            let vg = self.network.evaluate(self.tau, s, p);
            values.push(vg.value);
            grads.extend(vg.grad_state);
        }
        Ok((values, grads))
    }
}

/// How hard to search.
#[derive(Debug, Clone, PartialEq)]
pub struct TebOptions {
    /// Number of `beta` rows (at least [`MIN_TEB_ROWS`]), evenly spaced over the range.
    pub rows: usize,
    /// Uniform samples over the domain per row.
    pub samples: usize,
    /// Best samples refined by projected gradient descent.
    pub refine_starts: usize,
    /// Descent iterations.
    pub refine_iters: usize,
    /// Directions for boundary radii in 2-D error spaces.
    pub boundary_directions: usize,
    /// Uniform non-error states per boundary probe (as many again about the resting state, for a system
    /// that rests).
    pub boundary_samples: usize,
    /// Random seed.
    pub seed: u64,
}

impl Default for TebOptions {
    fn default() -> Self {
        Self {
            rows: MIN_TEB_ROWS,
            samples: 20_000,
            refine_starts: 32,
            refine_iters: 60,
            boundary_directions: 64,
            boundary_samples: 128,
            seed: 7,
        }
    }
}

/// A table and where the learned function was not monotone in `beta`.
#[derive(Debug, Clone, PartialEq)]
pub struct TebReport {
    /// The rows.
    pub rows: Vec<TebRow>,
    /// `(beta, measured minimum, level raised to)` where a row's minimum fell below an earlier row's.
    pub non_monotone: Vec<(f64, f64, f64)>,
    /// `(beta, level before, value at rest)` where the system's resting state
    /// ([`AffineSystem::resting_state`]) lay above the row's level and the level was raised to hold it.
    pub raised_to_rest: Vec<(f64, f64, f64)>,
}

fn uniform_states(system: &AffineSystem, n: usize, rng: &mut impl Rng) -> Vec<f64> {
    (0..n).flat_map(|_| system.state.iter().map(|d| rng.random_range(d.min..d.max)).collect::<Vec<_>>()).collect()
}

fn project(system: &AffineSystem, r: &mut [f64]) {
    for (x, d) in r.iter_mut().zip(&system.state) {
        if !d.periodic {
            *x = x.clamp(d.min, d.max);
        }
    }
    system.wrap(r);
}

/// Minimum of `V(., params)` over the domain: dense uniform sampling, then projected gradient descent with
/// per-start backtracking from the best samples. Returns `(V_min, argmin)`.
pub(crate) fn minimise(
    oracle: &dyn ValueOracle,
    system: &AffineSystem,
    params: &[f64],
    options: &TebOptions,
    rng: &mut impl Rng,
) -> Result<(f64, Vec<f64>), String> {
    let n_state = system.n_state();
    let states = uniform_states(system, options.samples, rng);
    let all_params: Vec<f64> = params.iter().copied().cycle().take(options.samples * params.len()).collect();
    let (values, _) = oracle.values_and_grads(&states, &all_params)?;
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let k = options.refine_starts.min(order.len());
    let mut points: Vec<f64> =
        order[..k].iter().flat_map(|&i| states[i * n_state..(i + 1) * n_state].to_vec()).collect();
    let start_params: Vec<f64> = params.iter().copied().cycle().take(k * params.len()).collect();
    let (mut current, mut grads) = oracle.values_and_grads(&points, &start_params)?;
    let scale: f64 = system.state.iter().map(|d| d.max - d.min).fold(0.0, f64::max);
    let mut steps = vec![0.01 * scale; k];
    for _ in 0..options.refine_iters {
        let mut trial = points.clone();
        for j in 0..k {
            let g = &grads[j * n_state..(j + 1) * n_state];
            let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
            let r = &mut trial[j * n_state..(j + 1) * n_state];
            for (x, gi) in r.iter_mut().zip(g) {
                *x -= steps[j] * gi / norm;
            }
            project(system, r);
        }
        let (values, new_grads) = oracle.values_and_grads(&trial, &start_params)?;
        for j in 0..k {
            if values[j] < current[j] {
                current[j] = values[j];
                points[j * n_state..(j + 1) * n_state].copy_from_slice(&trial[j * n_state..(j + 1) * n_state]);
                grads[j * n_state..(j + 1) * n_state].copy_from_slice(&new_grads[j * n_state..(j + 1) * n_state]);
                steps[j] *= 1.2;
            } else {
                steps[j] *= 0.5;
            }
        }
    }
    let best = (0..k).min_by(|&a, &b| current[a].total_cmp(&current[b])).ok_or("no samples")?;
    Ok((current[best], points[best * n_state..(best + 1) * n_state].to_vec()))
}

/// Non-error states a shape probe pairs with each error (whole states; the probe overwrites their error
/// coordinates): `m` uniform over the domain and, for a system that rests, its resting state and `m` states
/// scattered about it (each coordinate within a tenth of its range). In many dimensions uniform states almost
/// never lie in a set, while the resting state lies in every set the table certifies.
fn probe_states(system: &AffineSystem, m: usize, rng: &mut impl Rng) -> Vec<f64> {
    let mut states = uniform_states(system, m, rng);
    if let Some(rest) = system.resting_state() {
        states.extend_from_slice(&rest);
        for _ in 0..m {
            let mut r: Vec<f64> = rest
                .iter()
                .zip(&system.state)
                .map(|(x, d)| x + 0.1 * (d.max - d.min) * rng.random_range(-1.0..1.0))
                .collect();
            project(system, &mut r);
            states.extend(r);
        }
    }
    states
}

/// Extent and boundary radii of `{r : V(r) <= level}` projected onto the error coordinates: per direction,
/// the largest radius (bisection from the level, which bounds it since `V >= |e|`) at which some probe
/// state ([`probe_states`]) keeps `V <= level`.
fn error_set_shape(
    oracle: &dyn ValueOracle,
    system: &AffineSystem,
    params: &[f64],
    level: f64,
    options: &TebOptions,
    rng: &mut impl Rng,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let n_state = system.n_state();
    let n_error = system.error_coords.len();
    let directions = boundary_directions(n_error, options.boundary_directions);
    let axis_directions: Vec<Vec<f64>> = (0..n_error)
        .flat_map(|i| {
            [1.0, -1.0].map(|s| {
                let mut d = vec![0.0; n_error];
                d[i] = s;
                d
            })
        })
        .collect();
    let all: Vec<&Vec<f64>> = directions.iter().chain(axis_directions.iter()).collect();
    let others = probe_states(system, options.boundary_samples, rng);
    let probes = others.len() / n_state;
    let batch_params: Vec<f64> = params.iter().copied().cycle().take(probes * params.len()).collect();
    let mut radii = Vec::with_capacity(all.len());
    for direction in all {
        let (mut lo, mut hi) = (0.0, level);
        for _ in 0..10 {
            let mid = 0.5 * (lo + hi);
            let mut states = others.clone();
            for r in states.chunks_mut(n_state) {
                for (j, &i) in system.error_coords.iter().enumerate() {
                    r[i] = mid * direction[j];
                }
            }
            let (values, _) = oracle.values_and_grads(&states, &batch_params)?;
            if values.iter().any(|&v| v <= level) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        radii.push(lo);
    }
    let axis = radii.split_off(directions.len());
    let extent = (0..n_error).map(|i| axis[2 * i].max(axis[2 * i + 1])).collect();
    Ok((extent, radii))
}

/// Recomputes each row's extent and boundary radii at its set level ([`TebRow::set_level`]), as they must be
/// once verification has chosen the set it certifies: the shape clients draw is then that of the set inside
/// which the row's bound holds, not of the (smaller) learned minimum level set.
pub fn reshape_at_set_levels(
    oracle: &dyn ValueOracle,
    system: &AffineSystem,
    rows: &mut [TebRow],
    options: &TebOptions,
) -> Result<(), String> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    for row in rows.iter_mut() {
        let params = vec![row.beta; system.n_params()];
        let (extent, boundary_radii) = error_set_shape(oracle, system, &params, row.set_level(), options, &mut rng)?;
        row.extent = extent;
        row.boundary_radii = boundary_radii;
    }
    let shares = nested_shares(oracle, system, rows, &mut rng)?;
    for (row, share) in rows.iter_mut().zip(shares) {
        row.nested_share = share;
    }
    Ok(())
}

/// Uniform samples of a row's certified set behind its nested share.
const NESTING_SAMPLES: usize = 2_000;
/// Proposals per row before a set counts as too small to sample.
const NESTING_PROPOSALS: usize = 1_000_000;
/// Proposals per oracle call.
const NESTING_CHUNK: usize = 8_192;

/// For every row but the last, the share of its certified set `{V(.; beta_i) <= set level_i}` that lies in
/// the next row's `{V(.; beta_i+1) <= set level_i+1}`, from [`NESTING_SAMPLES`] uniform samples (rejection from
/// the state box with the error coordinates narrowed to `2.5` set levels, where a value of the tracking error
/// keeps the set); `None` for the last row and where fewer than a tenth of the samples were found.
pub fn nested_shares(
    oracle: &dyn ValueOracle,
    system: &AffineSystem,
    rows: &[TebRow],
    rng: &mut impl Rng,
) -> Result<Vec<Option<f64>>, String> {
    let n_state = system.n_state();
    let mut shares = vec![None; rows.len()];
    for (i, pair) in rows.windows(2).enumerate() {
        let (row, next) = (&pair[0], &pair[1]);
        let reach = 2.5 * row.set_level();
        let (lo, hi): (Vec<f64>, Vec<f64>) =
            system
                .state
                .iter()
                .enumerate()
                .map(|(k, d)| {
                    if system.error_coords.contains(&k) {
                        (d.min.max(-reach), d.max.min(reach))
                    } else {
                        (d.min, d.max)
                    }
                })
                .unzip();
        let (mut inside, mut proposed) = (Vec::new(), 0usize);
        while inside.len() < NESTING_SAMPLES * n_state && proposed < NESTING_PROPOSALS {
            let states: Vec<f64> =
                (0..NESTING_CHUNK * n_state).map(|k| rng.random_range(lo[k % n_state]..=hi[k % n_state])).collect();
            proposed += NESTING_CHUNK;
            let params = vec![row.beta; NESTING_CHUNK * system.n_params()];
            let (values, _) = oracle.values_and_grads(&states, &params)?;
            for (state, v) in states.chunks(n_state).zip(values) {
                if v <= row.set_level() && inside.len() < NESTING_SAMPLES * n_state {
                    inside.extend_from_slice(state);
                }
            }
        }
        let found = inside.len() / n_state;
        if found >= NESTING_SAMPLES / 10 {
            let params = vec![next.beta; found * system.n_params()];
            let (values, _) = oracle.values_and_grads(&inside, &params)?;
            let nested = values.iter().filter(|&&v| v <= next.set_level()).count();
            shares[i] = Some(nested as f64 / found as f64);
        }
    }
    Ok(shares)
}

/// Builds the TEB table of `oracle` for `system` (every parameter set to the row's `beta`). A row's level is
/// the largest learned minimum up to its `beta` (levels never fall as `beta` grows), raised where needed so
/// that the set holds the system's resting state: a hovering robot must start inside every row's set.
pub fn teb_table(oracle: &dyn ValueOracle, system: &AffineSystem, options: &TebOptions) -> Result<TebReport, String> {
    if options.rows < MIN_TEB_ROWS {
        return Err(format!("a TEB table needs at least {MIN_TEB_ROWS} rows, asked for {}", options.rows));
    }
    let (beta_l, beta_u) =
        system.params.iter().fold((f64::NEG_INFINITY, f64::INFINITY), |(lo, hi), p| (lo.max(p.min), hi.min(p.max)));
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    let mut rows = Vec::with_capacity(options.rows);
    let mut non_monotone = Vec::new();
    let mut raised_to_rest = Vec::new();
    let rest = system.resting_state();
    let mut running_max = f64::NEG_INFINITY;
    let mut previous_level = f64::NEG_INFINITY;
    for i in 0..options.rows {
        let beta = if i + 1 == options.rows {
            beta_u
        } else {
            beta_l + (beta_u - beta_l) * i as f64 / (options.rows - 1) as f64
        };
        let params = vec![beta; system.n_params()];
        let (measured_min, argmin) = minimise(oracle, system, &params, options, &mut rng)?;
        if measured_min.is_nan() || measured_min <= 0.0 {
            let at: Vec<String> =
                system.state.iter().zip(&argmin).map(|(d, x)| format!("{} = {x:.3}", d.name)).collect();
            return Err(format!(
                "V_min = {measured_min} at beta = {beta} ({}): a tracking value function satisfies V >= l(r) >= 0 and has a positive minimum; this one is wrong there",
                at.join(", ")
            ));
        }
        if measured_min < running_max {
            non_monotone.push((beta, measured_min, running_max));
        }
        running_max = running_max.max(measured_min);
        let mut level = running_max.max(previous_level);
        if let Some(rest) = &rest {
            let (at_rest, _) = oracle.values_and_grads(rest, &params)?;
            if at_rest[0] > level {
                raised_to_rest.push((beta, level, at_rest[0]));
                level = at_rest[0];
            }
        }
        previous_level = level;
        let (extent, boundary_radii) = error_set_shape(oracle, system, &params, level, options, &mut rng)?;
        rows.push(TebRow {
            beta,
            level,
            measured_min,
            extent,
            boundary_radii,
            verification: None,
            nested_share: None,
            reference: None,
        });
    }
    Ok(TebReport { rows, non_monotone, raised_to_rest })
}
