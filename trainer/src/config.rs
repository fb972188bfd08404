//! The training configuration: one TOML file holds every hyperparameter; validated before any work.

use anyhow::{bail, ensure, Context};
use fastrack_gridfile::spec::{SolveSeries, DEFAULT_STORE};
use fastrack_valuefn::network::PeriodicEncoding;
use fastrack_valuefn::system::{by_id, AffineSystem, SYSTEM_IDS};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How the value is built from the network output `y`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LossForm {
    /// The paper's: `V = y`, boundary loss `|V - l|` at `tau = 0` plus `lambda` times the HJI-VI residual,
    /// after boundary-only pretraining.
    Paper,
    /// `V = l + tau * y`: the boundary condition holds exactly; residual only.
    ExactBoundary,
}

/// Which residual of the HJI variational inequality is minimised.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Residual {
    /// DeepReach's differential form `min(V - l, dV/dtau - H(r, dV/dr))`. It also vanishes almost
    /// everywhere on functions other than the viscosity solution (on a flat plateau `dV/dr = 0`, so `H = 0`
    /// and `dV/dtau = 0` satisfy it), and training can settle on one.
    #[default]
    Differential,
    /// The semi-Lagrangian (dynamic-programming) step
    /// `(V(r, tau) - max{l(r), min_u max_{u_p, d} V(r + h r'(u, u_p, d), tau - h)}) / dt`, `h = min(dt, tau)`,
    /// over the vertices of the input boxes: a monotone scheme, so the value it is consistent with is the
    /// viscosity solution (to `O(dt)`). Uses values only, no input gradient. On the double integrator it
    /// fitted no better than the differential form (the network's error, not the scheme's, dominates).
    SemiLagrangian,
}

fn default_time_step() -> f64 {
    0.05
}

fn default_causal_epsilon() -> f64 {
    1.0
}

/// How pointwise residuals are averaged into the loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualNorm {
    /// Mean absolute residual (DeepReach's).
    #[default]
    L1,
    /// Mean squared residual: large, localised violations (a wrong kink) cost more.
    L2,
}

/// How the planner bounds enter the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParameterMode {
    /// One input per planner bound (the paper's `beta_1`, `beta_2`).
    Full,
    /// One shared `beta` for every planner input (`beta_1 = beta_2`), halving the parameter space.
    Diagonal,
}

/// Every hyperparameter of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// System id.
    pub system: String,
    /// Parameter inputs.
    pub parameter_mode: ParameterMode,
    /// Random seed (initialisation and sampling).
    pub seed: u64,
    /// Network.
    pub network: NetworkConfig,
    /// Loss.
    pub loss: LossConfig,
    /// Sampling.
    pub sampling: SamplingConfig,
    /// Optimisation.
    pub optimizer: OptimizerConfig,
    /// Checkpoints and logs.
    pub checkpoint_every: u64,
    /// Bundle written by `export`.
    pub export: ExportConfig,
    /// Supervision by grid solutions beside the residual (absent: the residual alone, pure DeepReach).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supervision: Option<SupervisionConfig>,
}

/// Network shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkConfig {
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// SIREN frequency.
    pub omega_0: f64,
    /// Output scale: `y` is multiplied by it.
    pub output_scale: f64,
    /// Output offset added after scaling.
    pub output_offset: f64,
    /// Multiplies the first layer's initial weights (default 1): the first layer's frequency becomes
    /// `first_layer_scale * omega_0` at initialisation, for value functions with features finer than SIREN's
    /// default initialisation resolves (the exported network keeps one `omega_0`).
    #[serde(default = "default_first_layer_scale")]
    pub first_layer_scale: f64,
    /// How periodic coordinates (the heading) enter the network: `circle` (default; `(cos, sin)`, periodic by
    /// construction) or `wrap` (the wrapped angle as one input, as the first bundles were trained).
    #[serde(default)]
    pub periodic_encoding: PeriodicEncoding,
}

fn default_first_layer_scale() -> f64 {
    1.0
}

/// Loss.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossConfig {
    /// Which form.
    pub form: LossForm,
    /// Weight of the residual term (paper form).
    pub lambda: f64,
    /// Boundary-only iterations before the residual enters (paper form).
    pub pretrain_iterations: u64,
    /// Which residual (default `differential`).
    #[serde(default)]
    pub residual: Residual,
    /// How residuals are averaged (default `l1`).
    #[serde(default)]
    pub norm: ResidualNorm,
    /// Time step `dt` (s) of the semi-Lagrangian residual (default 0.05); unused by the differential one.
    #[serde(default = "default_time_step")]
    pub time_step: f64,
    /// Causal training (Wang, Sankaran & Perdikaris 2022): the sampled horizon is split into this many
    /// equal bins and each bin's residual is weighted by `exp(-causal_epsilon * sum of the mean residuals of
    /// the earlier bins)` (weights held constant in the gradient), so later horizons are fitted once earlier
    /// ones are. 0 (the default) turns it off.
    #[serde(default)]
    pub causal_bins: usize,
    /// Causal weighting strength `epsilon` (default 1).
    #[serde(default = "default_causal_epsilon")]
    pub causal_epsilon: f64,
}

/// Collocation points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamplingConfig {
    /// Points per iteration.
    pub points: usize,
    /// Share of them at `tau = 0`.
    pub boundary_share: f64,
    /// Largest horizon trained (s); the graph is exported at this horizon.
    pub tau_max: f64,
    /// Iterations over which the sampled horizon grows linearly from 0 to `tau_max` (after pretraining).
    pub curriculum_iterations: u64,
    /// Share of the points (after the `tau = 0` ones) whose state is drawn from the domain shrunk by
    /// `focus_scale` about its centre (periodic coordinates keep their full period), where the value's
    /// minimum, the tracking error bound, lies. Default 0.
    #[serde(default)]
    pub focus_share: f64,
    /// Shrink factor of the focus box, in `(0, 1]` (default 0.5).
    #[serde(default = "default_focus_scale")]
    pub focus_scale: f64,
    /// Horizons are drawn as `tau_limit * u^tau_exponent`, `u` uniform in `[0, 1)`: 1 (the default) is
    /// uniform; above 1 crowds points at short horizons, where the value changes fastest and whose errors
    /// every longer horizon inherits.
    #[serde(default = "default_tau_exponent")]
    pub tau_exponent: f64,
}

fn default_tau_exponent() -> f64 {
    1.0
}

fn default_focus_scale() -> f64 {
    0.5
}

/// Adam and its schedule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizerConfig {
    /// Total iterations.
    pub iterations: u64,
    /// Initial learning rate.
    pub learning_rate: f64,
    /// Learning rate at the last iteration (exponential decay in between).
    pub final_learning_rate: f64,
    /// Clip the gradient norm to this value, if set.
    pub gradient_clip_norm: Option<f64>,
}

/// Grid solutions (`.ftgrid`, written by `fastrack-grid`) whose values (and optionally `dV/dr`) supervise the
/// network at their horizon; see `crate::supervision`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupervisionConfig {
    /// The solutions, by spec (what each solve is; `fastrack-grid solve --config <this file>` makes the
    /// missing ones).
    pub solutions: SolveSeries,
    /// The directory the solutions are kept in, relative to the working directory (default
    /// `target/grid-solutions`).
    #[serde(default = "default_store")]
    pub store: PathBuf,
    /// Weight of the mean squared error to the grid values, added to the residual loss.
    pub weight: f64,
    /// Weight of the mean squared error of `dV/dr` to the grid's central differences (Sobolev training; the
    /// control is read off `dV/dr`). Default 0: values only.
    #[serde(default)]
    pub gradient_weight: f64,
    /// Targets drawn per iteration.
    pub points: usize,
    /// Share of the nodes drawn from `{V <= focus_factor * V_min}` of their solution (default 0).
    #[serde(default)]
    pub focus_share: f64,
    /// Level factor of that set (default 2).
    #[serde(default = "default_focus_factor")]
    pub focus_factor: f64,
    /// Share of the targets drawn at a solution's own parameters, anywhere in its grid (default 0). A target
    /// blended between two solutions must lie in both grids, so where a grid reaches past the one at the next
    /// lower `beta` (domains scaled to each `beta`'s error set), only these rows supervise its outer part.
    #[serde(default)]
    pub own_grid_share: f64,
    /// Share of the targets drawn on the zero-error slice (every error coordinate at 0, the others anywhere
    /// in the grid; default 0): where every start and every planner reset puts a robot, so where a value
    /// below the truth admits states into a certified set that the error then leaves.
    #[serde(default)]
    pub slice_share: f64,
    /// Multiplies the squared value error where the network is below the grid (default 1: symmetric). A
    /// value below the truth makes the tracking error bound too small, the unsafe side; above 1 the fit
    /// settles on the grid from above where it cannot match it exactly.
    #[serde(default = "default_under_weight")]
    pub under_weight: f64,
    /// How the error of `dV/dr` is measured across the state axes (default `euclidean`).
    #[serde(default)]
    pub gradient_metric: GradientMetric,
}

/// How the supervision's `dV/dr` error is weighted across the state axes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GradientMetric {
    /// Every axis alike: `sum_j (dV/dr_j - target_j)^2`.
    #[default]
    Euclidean,
    /// Each axis by how much it moves the Hamiltonian: `sum_j w_j (dV/dr_j - target_j)^2` with
    /// `w_j = n alpha_j^2 / sum_k alpha_k^2` at the point, `alpha_j >= |dH/dp_j|` its dissipation bound. Since
    /// `|H(p) - H(q)| <= sum_j alpha_j |p_j - q_j|`, this is the error that changes the optimal control and the
    /// HJI residual; an axis a strong control drives (dubins4d's heading) weighs most. The weights average 1
    /// over the axes, so `gradient_weight` keeps its scale.
    Hamiltonian,
}

fn default_store() -> PathBuf {
    PathBuf::from(DEFAULT_STORE)
}

fn default_under_weight() -> f64 {
    1.0
}

fn default_focus_factor() -> f64 {
    2.0
}

/// Where the trained model goes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportConfig {
    /// Model name.
    pub name: String,
    /// Model version.
    pub version: u32,
}

impl TrainConfig {
    /// Reads and validates a TOML config.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let config: TrainConfig = toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        config.validate().with_context(|| format!("invalid config {}", path.display()))?;
        Ok(config)
    }

    /// The system being trained, in the chosen parameter mode.
    pub fn system(&self) -> anyhow::Result<AffineSystem> {
        let system = by_id(&self.system)
            .with_context(|| format!("unknown system {:?}; known: {}", self.system, SYSTEM_IDS.join(", ")))?;
        Ok(match self.parameter_mode {
            ParameterMode::Full => system,
            ParameterMode::Diagonal => system.with_shared_parameter(),
        })
    }

    /// Checks every field before any work starts.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.system()?.check_limits().map_err(anyhow::Error::msg).context("the system's state limits")?;
        let n = &self.network;
        ensure!(!n.hidden.is_empty(), "network.hidden must list at least one layer");
        ensure!(!n.hidden.contains(&0), "network.hidden widths must be > 0, got {:?}", n.hidden);
        ensure!(n.omega_0 > 0.0 && n.omega_0.is_finite(), "network.omega_0 must be > 0");
        ensure!(
            n.output_scale.is_finite() && n.output_scale != 0.0,
            "network.output_scale must be finite and non-zero"
        );
        ensure!(n.output_offset.is_finite(), "network.output_offset must be finite");
        ensure!(n.first_layer_scale.is_finite() && n.first_layer_scale > 0.0, "network.first_layer_scale must be > 0");
        let l = &self.loss;
        ensure!(l.lambda.is_finite() && l.lambda > 0.0, "loss.lambda must be > 0");
        ensure!(l.time_step.is_finite() && l.time_step > 0.0, "loss.time_step must be > 0");
        ensure!(l.causal_epsilon.is_finite() && l.causal_epsilon >= 0.0, "loss.causal_epsilon must be >= 0");
        let s = &self.sampling;
        ensure!(s.points >= 2, "sampling.points must be at least 2");
        ensure!((0.0..1.0).contains(&s.boundary_share), "sampling.boundary_share must be in [0, 1)");
        ensure!(s.tau_max.is_finite() && s.tau_max > 0.0, "sampling.tau_max must be > 0");
        ensure!(l.time_step < s.tau_max, "loss.time_step must be below sampling.tau_max");
        ensure!((0.0..=1.0).contains(&s.focus_share), "sampling.focus_share must be in [0, 1]");
        ensure!(s.focus_scale > 0.0 && s.focus_scale <= 1.0, "sampling.focus_scale must be in (0, 1]");
        ensure!(s.tau_exponent.is_finite() && s.tau_exponent > 0.0, "sampling.tau_exponent must be > 0");
        if l.form == LossForm::Paper && s.boundary_share * (s.points as f64) < 1.0 {
            bail!("the paper loss needs boundary points: sampling.boundary_share * sampling.points must be >= 1");
        }
        let o = &self.optimizer;
        ensure!(o.iterations > 0, "optimizer.iterations must be > 0");
        ensure!(o.learning_rate > 0.0 && o.final_learning_rate > 0.0, "learning rates must be > 0");
        ensure!(o.gradient_clip_norm.is_none_or(|c| c > 0.0), "optimizer.gradient_clip_norm must be > 0 when set");
        ensure!(self.checkpoint_every > 0, "checkpoint_every must be > 0");
        if let Some(sup) = &self.supervision {
            ensure!(!sup.solutions.solves.is_empty(), "supervision.solutions.solves must list at least one solve");
            for spec in sup.solutions.specs() {
                spec.grid().and_then(|_| spec.params()).context("supervision.solutions")?;
            }
            ensure!(sup.weight.is_finite() && sup.weight > 0.0, "supervision.weight must be > 0");
            ensure!(
                sup.gradient_weight.is_finite() && sup.gradient_weight >= 0.0,
                "supervision.gradient_weight must be >= 0"
            );
            ensure!(sup.points > 0, "supervision.points must be > 0");
            ensure!((0.0..=1.0).contains(&sup.focus_share), "supervision.focus_share must be in [0, 1]");
            ensure!(sup.focus_factor.is_finite() && sup.focus_factor >= 1.0, "supervision.focus_factor must be >= 1");
            ensure!((0.0..=1.0).contains(&sup.own_grid_share), "supervision.own_grid_share must be in [0, 1]");
            ensure!(
                (0.0..=1.0).contains(&sup.slice_share) && sup.slice_share + sup.own_grid_share <= 1.0,
                "supervision.slice_share must be in [0, 1 - own_grid_share]"
            );
            ensure!(sup.under_weight.is_finite() && sup.under_weight >= 1.0, "supervision.under_weight must be >= 1");
        }
        ensure!(!self.export.name.is_empty() && self.export.version > 0, "export needs a name and a positive version");
        Ok(())
    }

    /// Learning rate at `iteration` (exponential decay).
    pub fn learning_rate(&self, iteration: u64) -> f64 {
        let o = &self.optimizer;
        let progress = iteration as f64 / o.iterations as f64;
        o.learning_rate * (o.final_learning_rate / o.learning_rate).powf(progress)
    }

    /// Largest horizon sampled at `iteration` (the curriculum).
    pub fn tau_limit(&self, iteration: u64) -> f64 {
        let start = if self.loss.form == LossForm::Paper { self.loss.pretrain_iterations } else { 0 };
        let s = &self.sampling;
        if iteration < start {
            return 0.0;
        }
        if s.curriculum_iterations == 0 {
            return s.tau_max;
        }
        s.tau_max * ((iteration - start) as f64 / s.curriculum_iterations as f64).min(1.0)
    }
}
