//! Request validation: every rejection names the field, the item and what is allowed.

use crate::loaded_model::LoadedModel;
use fastrack_proto::planner_speed::{planner_rule, query_planner_control, PlannerSpeed};
use fastrack_proto::v1::OutOfDomainPolicy;
use tonic::Status;

/// Largest batch accepted by one request.
pub const MAX_BATCH_ITEMS: usize = 65_536;
/// Most boundary points one GetTrackingErrorBound may ask for.
pub const MAX_BOUNDARY_POINTS: u32 = 4096;

/// A batch that passed validation, converted for the graph.
#[derive(Debug, Clone)]
pub struct ValidBatch {
    /// Items.
    pub n: usize,
    /// States `[N x n_state]`, f32.
    pub states: Vec<f32>,
    /// Params `[N x n_params]`, f32.
    pub params: Vec<f32>,
    /// Per item: inside the trained domain.
    pub in_domain: Vec<bool>,
    /// Per item: the largest parameter (its TEB is bounded by the table row of that `beta`).
    pub max_beta: Vec<f64>,
}

fn require_finite(field: &str, index: usize, item: usize, name: &str, x: f64) -> Result<(), Status> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(Status::invalid_argument(format!("{field}[{index}] (item {item}, {name}) is {x}; must be a finite number")))
    }
}

/// Checks lengths, finiteness, parameter ranges and the domain of a `(states, params)` batch.
pub fn batch(
    model: &LoadedModel,
    states: &[f64],
    params: &[f64],
    policy: OutOfDomainPolicy,
) -> Result<ValidBatch, Status> {
    let m = &model.manifest;
    let (ns, np) = (model.space.n_state(), m.n_params());
    // Names are joined only for error messages: this runs on every request and tick.
    let state_names = || m.state.iter().map(|d| d.name.as_str()).collect::<Vec<_>>().join(", ");
    let param_names = || m.params.iter().map(|d| d.name.as_str()).collect::<Vec<_>>().join(", ");
    if states.is_empty() || !states.len().is_multiple_of(ns) {
        return Err(Status::invalid_argument(format!(
            "states has {} values; must be a positive multiple of n_state = {ns} ({}), row-major [N x {ns}]",
            states.len(),
            state_names()
        )));
    }
    let n = states.len() / ns;
    if n > MAX_BATCH_ITEMS {
        return Err(Status::invalid_argument(format!("batch of {n} items exceeds the limit of {MAX_BATCH_ITEMS}")));
    }
    if params.len() != n * np {
        return Err(Status::invalid_argument(format!(
            "params has {} values; must be N x n_params = {n} x {np} = {} ({}) for the {n} states given",
            params.len(),
            n * np,
            param_names()
        )));
    }
    for (k, &x) in states.iter().enumerate() {
        require_finite("states", k, k / ns, &m.state[k % ns].name, x)?;
    }
    let mut max_beta = Vec::with_capacity(n);
    for (i, item) in params.chunks(np).enumerate() {
        for (j, (&x, dim)) in item.iter().zip(&m.params).enumerate() {
            require_finite("params", i * np + j, i, &dim.name, x)?;
            if x < dim.min || x > dim.max {
                return Err(Status::invalid_argument(format!(
                    "params[{}] (item {i}, {}) = {x} is outside the trained range [{}, {}] {}",
                    i * np + j,
                    dim.name,
                    dim.min,
                    dim.max,
                    dim.unit
                )));
            }
        }
        max_beta.push(item.iter().copied().fold(f64::NEG_INFINITY, f64::max));
    }
    let mut in_domain = Vec::with_capacity(n);
    for (i, item) in states.chunks(ns).enumerate() {
        let outside = model.space.first_outside(item);
        if let Some(j) = outside {
            let (x, d) = (item[j], &m.state[j]);
            let reject = match policy {
                OutOfDomainPolicy::Reject => true,
                OutOfDomainPolicy::Flag => false,
                OutOfDomainPolicy::Unspecified => n == 1,
            };
            if reject {
                return Err(Status::out_of_range(format!(
                    "states[{}] (item {i}, {}) = {x} is outside the trained domain [{}, {}] {}; the value there would be extrapolated (send batches with out_of_domain = FLAG to evaluate anyway, flagged)",
                    i * ns + j,
                    d.name,
                    d.min,
                    d.max,
                    d.unit
                )));
            }
        }
        in_domain.push(outside.is_none());
    }
    Ok(ValidBatch {
        n,
        // Periodic coordinates wrapped in double precision first: an angle the graph's single precision
        // cannot hold (1e300 rad, or one that loses its fraction) enters it as its residue.
        states: wrapped_f32(states, &model.space.coordinates),
        params: params.iter().map(|&x| x as f32).collect(),
        in_domain,
        max_beta,
    })
}

/// `states` (row-major, one row per item) in single precision, each periodic coordinate wrapped into its
/// period first; one allocation, sized up front (this runs on every request and tick).
fn wrapped_f32(states: &[f64], coordinates: &[fastrack_valuefn::system::Coordinate]) -> Vec<f32> {
    let mut out = Vec::with_capacity(states.len());
    for item in states.chunks(coordinates.len()) {
        out.extend(item.iter().zip(coordinates).map(|(&x, c)| c.wrapped(x) as f32));
    }
    out
}

/// Checks `d_obs` (absent is allowed).
pub fn d_obs(d: Option<f64>) -> Result<Option<f64>, Status> {
    match d {
        Some(x) if !x.is_finite() || x < 0.0 => Err(Status::invalid_argument(format!(
            "d_obs = {x}; must be a finite distance >= 0, or absent when no obstacle is sensed"
        ))),
        other => Ok(other),
    }
}

/// Checks a planner clearance (the planner rule's distance): absent, or finite and `>= 0`.
pub fn planner_clearance(c: Option<f64>) -> Result<Option<f64>, Status> {
    match c {
        Some(x) if !x.is_finite() || x < 0.0 => Err(Status::invalid_argument(format!(
            "planner_clearance = {x}; must be a finite distance >= 0, or absent for the paper's rule on d_obs"
        ))),
        other => Ok(other),
    }
}

/// The planner speed for a question's `d_obs` and `planner_clearance`, each checked: the planner rule when
/// the clearance is given, the paper's queryPlannerControl otherwise.
pub fn planner_speed(
    model: &LoadedModel,
    d_obs: Option<f64>,
    planner_clearance: Option<f64>,
) -> Result<PlannerSpeed, Status> {
    let d_obs = self::d_obs(d_obs)?;
    Ok(match self::planner_clearance(planner_clearance)? {
        Some(c) => planner_rule(&model.speeds, c),
        None => query_planner_control(&model.speeds, d_obs),
    })
}

/// Checks a table `beta` against the model's range `[beta_l, beta_u]`.
pub fn beta(model: &LoadedModel, beta: f64) -> Result<f64, Status> {
    let (lo, hi) = model.manifest.beta_range();
    if !beta.is_finite() || beta < lo || beta > hi {
        return Err(Status::invalid_argument(format!(
            "beta = {beta} is outside the model's parameter range [{lo}, {hi}] {}",
            model.manifest.params[0].unit
        )));
    }
    Ok(beta)
}

/// Checks the vector lengths and finiteness of one `Track` tick.
pub fn tick(model: &LoadedModel, tracker: &[f64], planner: &[f64]) -> Result<(), Status> {
    let (ns, npl) = (model.space.n_state(), model.space.planner_dim());
    if tracker.len() != ns {
        return Err(Status::invalid_argument(format!(
            "tracker_state has {} values; must have n_state = {ns}",
            tracker.len()
        )));
    }
    if planner.len() != npl {
        return Err(Status::invalid_argument(format!(
            "planner_state has {} values; must have planner_dim = {npl}",
            planner.len()
        )));
    }
    for (field, v) in [("tracker_state", tracker), ("planner_state", planner)] {
        if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
            return Err(Status::invalid_argument(format!("{field}[{i}] is {x}; must be a finite number")));
        }
    }
    Ok(())
}
