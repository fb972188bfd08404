//! `manifest.json` of a model bundle: versioned schema, serde types and validation with precise errors.

use crate::composite::Composite;
use crate::network::{PeriodicEncoding, ValueNetwork};
use crate::system::{AffineSystem, Coordinate, StateSpace};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Schema version written by this crate and the only one it accepts.
pub const SCHEMA_VERSION: u32 = 1;

/// Minimum number of rows of a TEB table.
pub const MIN_TEB_ROWS: usize = 16;

/// Everything the server needs to know about a bundle, with no knowledge of the robot behind it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Schema version, [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// Model name (the repository folder).
    pub name: String,
    /// Model version (the version folder), positive.
    pub version: u32,
    /// The system the value function belongs to.
    pub system: SystemInfo,
    /// Relative-state coordinates, in input order.
    pub state: Vec<StateDimension>,
    /// `Q`, `n_state` rows of `planner_dim` entries: `r = s - Q p`.
    pub planner_to_state: Vec<Vec<f64>>,
    /// Parameters (planner speed bounds), in input order.
    pub params: Vec<RangeDimension>,
    /// Tracker controls, in output order.
    pub controls: Vec<RangeDimension>,
    /// Horizon `tau` (s) fixed inside the graph.
    pub horizon: f64,
    /// The network the graph was written from.
    pub network: NetworkInfo,
    /// TEB table, rows by increasing `beta`.
    pub teb_table: Vec<TebRow>,
    /// True for a bundle written from an untrained (random) network.
    pub untrained: bool,
    /// Where the model came from.
    pub provenance: Provenance,
    /// SHA-256 of `model.onnx`, lowercase hex.
    pub onnx_sha256: String,
}

/// System identity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemInfo {
    /// System id, e.g. `dubins4d`.
    pub id: String,
    /// Description.
    pub description: String,
}

/// One relative-state coordinate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateDimension {
    /// Name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Domain lower end.
    pub min: f64,
    /// Domain upper end.
    pub max: f64,
    /// Wrapped into `[min, max)` instead of rejected.
    pub periodic: bool,
    /// Part of the tracking error `l(r)`.
    pub error_coordinate: bool,
    /// The tracker's own limits `[low, high]` on this coordinate, inside the domain: at or past a limit the
    /// graph's control never pushes the coordinate further out. Absent: unlimited.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<[f64; 2]>,
}

/// A named quantity with a closed range (parameter or control).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangeDimension {
    /// Name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Lower end.
    pub min: f64,
    /// Upper end.
    pub max: f64,
}

/// Description of the network inside the graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkInfo {
    /// Architecture: `siren` (one network), or [`COMPOSITE_KIND`] (one SIREN per axis of a decomposed system,
    /// combined as `sqrt(sum V_a^2)`; each described in `axes`).
    pub kind: String,
    /// Hidden layer widths (a composite: none; its axes have theirs).
    pub hidden: Vec<usize>,
    /// SIREN frequency `omega_0` (a composite: its first axis').
    pub omega_0: f64,
    /// `V = l(r) + tau * NN` (exact boundary condition) instead of `V = NN` (a composite: on every axis).
    pub exact_boundary: bool,
    /// How periodic state coordinates enter the first layer (bundles written before it was recorded: `wrap`).
    #[serde(default = "wrapped")]
    pub periodic_encoding: PeriodicEncoding,
    /// A composite's axis networks, in the decomposition's order (empty for one network).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub axes: Vec<AxisNetworkInfo>,
}

/// [`NetworkInfo::kind`] of a composite of axis networks.
pub const COMPOSITE_KIND: &str = "siren-axes";

/// One axis network of a composite bundle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisNetworkInfo {
    /// The subsystem the network was trained on.
    pub subsystem: String,
    /// Its coordinates in the full state.
    pub coords: Vec<usize>,
    /// The full system's parameter it takes.
    pub param: usize,
    /// The horizon it is evaluated at (s).
    pub horizon: f64,
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// SIREN frequency `omega_0`.
    pub omega_0: f64,
    /// Exact boundary condition.
    pub exact_boundary: bool,
}

fn wrapped() -> PeriodicEncoding {
    PeriodicEncoding::Wrap
}

impl NetworkInfo {
    /// The description of `network`.
    pub fn describe(network: &ValueNetwork) -> Self {
        Self {
            kind: "siren".into(),
            hidden: network.hidden_widths(),
            omega_0: network.omega_0,
            exact_boundary: network.exact_boundary,
            periodic_encoding: network.periodic_encoding,
            axes: Vec::new(),
        }
    }

    /// The description of a composite of axis networks.
    pub fn describe_composite(composite: &Composite) -> Self {
        let axes: Vec<AxisNetworkInfo> = composite
            .axes()
            .iter()
            .map(|a| AxisNetworkInfo {
                subsystem: a.subsystem.id.into(),
                coords: a.axis.coords.clone(),
                param: a.axis.param,
                horizon: a.tau,
                hidden: a.network.hidden_widths(),
                omega_0: a.network.omega_0,
                exact_boundary: a.network.exact_boundary,
            })
            .collect();
        Self {
            kind: COMPOSITE_KIND.into(),
            hidden: Vec::new(),
            omega_0: axes.first().map_or(0.0, |a| a.omega_0),
            exact_boundary: axes.iter().all(|a| a.exact_boundary),
            periodic_encoding: composite
                .axes()
                .first()
                .map_or(PeriodicEncoding::Circle, |a| a.network.periodic_encoding),
            axes,
        }
    }
}

/// One row of the TEB table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TebRow {
    /// Planner speed bound (every parameter equal to it).
    pub beta: f64,
    /// Conservative level `V_min` (monotone in `beta`).
    pub level: f64,
    /// The smallest value found by the search at this `beta`, before monotone correction.
    pub measured_min: f64,
    /// Half-widths of the bounding box of the certified set `{r : V(r) <= set_level}` along each error
    /// coordinate.
    pub extent: Vec<f64>,
    /// Radii of that set's projection onto the error coordinates along [`boundary_directions`] (for drawing).
    pub boundary_radii: Vec<f64>,
    /// Scenario verification of this row, once run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verification: Option<Verification>,
    /// Share of this row's certified set (uniform samples) that lies inside the next faster row's certified
    /// set: 1 where the two nest. From the states outside, a robot offered the faster row is refused it (the
    /// online loop advances under the bound in force instead). Absent for the last row, for a table not yet
    /// measured, and where the set was too small to sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nested_share: Option<f64>,
    /// The ground-truth bound at this row's `beta`, where the project has one: the served bound never lies
    /// below it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<Reference>,
}

/// A ground-truth bound for one row: a grid solution's `V_min`, a closed form, or their combination over a
/// decomposed system's axes, at the row's `beta` or the next solved `beta` above it (`V_min` grows with
/// `beta`, so that one is no smaller).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reference {
    /// The bound, a distance in the error coordinates.
    pub bound: f64,
    /// Where it comes from, e.g. `grid quad10d_x beta 1.1 (x, y); closed form beta^2 / a_up (z)`.
    pub source: String,
}

/// Which number set a row's [`bound`](TebRow::bound).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundSource {
    /// The learned level: the row is unverified.
    Learned,
    /// Verification: the largest error it reached, or the certified set's own level.
    Verification,
    /// The ground-truth reference, which lies above what verification reached.
    Reference,
}

impl BoundSource {
    /// The name the contract uses: `learned`, `verification` or `reference`.
    pub fn name(self) -> &'static str {
        match self {
            BoundSource::Learned => "learned",
            BoundSource::Verification => "verification",
            BoundSource::Reference => "reference",
        }
    }
}

impl TebRow {
    /// The level of the certified set `{r : V(r; beta) <= set_level}`: the set verification sampled from
    /// (its final round's `sampled_level`), or the learned `level` where the row is unverified. Membership
    /// in the row's bound is membership in this set; only from inside it does [`bound`](Self::bound) hold.
    /// With the `set` correction the sampled level rose with the error, so the set holds its own level and
    /// the two numbers coincide; with the `bound` correction the set is the one sampled and the bound the
    /// largest error of its samples.
    pub fn set_level(&self) -> f64 {
        self.verification.as_ref().and_then(|v| v.sampled_level).unwrap_or(self.level)
    }

    /// The tracking error bound (the TEB radius), a distance in the error coordinates: the largest error
    /// verification reached from the certified set (kept monotone in `beta`), and never below the set's own
    /// level (inside it `|e| <= V <= set_level` already at the start) nor the learned `level`; the learned
    /// `level` where the row is unverified. It is the number the speed rule compares with `d_obs / 2`, and it
    /// holds for relative states inside the set of [`set_level`](Self::set_level). With the `set` correction
    /// it equals the set level unless the verification's slack let the error pass it.
    /// Where the row has a ground-truth [`reference`](Self::reference) above that, the reference.
    pub fn bound(&self) -> f64 {
        self.verified_bound().max(self.reference.as_ref().map_or(0.0, |r| r.bound))
    }

    /// The bound verification alone gives (the learned level for an unverified row), before the reference.
    pub fn verified_bound(&self) -> f64 {
        let verified = self.verification.as_ref().map_or(0.0, |v| v.verified_level);
        self.level.max(self.set_level()).max(verified)
    }

    /// Which number set [`bound`](Self::bound).
    pub fn bound_source(&self) -> BoundSource {
        match (&self.reference, &self.verification) {
            (Some(reference), _) if reference.bound > self.verified_bound() => BoundSource::Reference,
            (_, Some(_)) => BoundSource::Verification,
            (_, None) => BoundSource::Learned,
        }
    }
}

/// Scenario-based verification of one TEB row (after Lin & Bansal): states are sampled from
/// `{V <= sampled_level}` and rolled out against every planner family. With the `set` correction (their
/// iterated level correction), while a round has samples whose error exceeds the level they were sampled
/// under, the level is raised to the largest error and the next round samples afresh; with the `bound`
/// correction one round rolls out every sample and its largest error is the bound.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Verification {
    /// Corrected level: the largest error reached from the final round's sampled set.
    pub verified_level: f64,
    /// Violation-probability bound epsilon.
    pub eps: f64,
    /// Confidence parameter delta.
    pub delta: f64,
    /// Number of sampled states (of the final round).
    pub samples: usize,
    /// Samples of the final round whose rollout exceeded the level they were sampled under (0 when the
    /// correction converged).
    pub violations: usize,
    /// Rollout horizon (s).
    pub horizon: f64,
    /// Integration step (s).
    pub step: f64,
    /// The level of the final round's sampled set `{V <= sampled_level}` (absent in bundles verified without
    /// the iterated correction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampled_level: Option<f64>,
    /// What the correction raised: `set` (the sampled set with the level: the set holds its own level),
    /// `bound` (one round: the bound on the error from the sampled set is its samples' largest error) or
    /// `by-axes` (a composed value: each axis bounds its error less its start's value, the bound is the set
    /// level plus those excesses combined); absent without the correction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<String>,
    /// Rounds of the iterated level correction (1: the first sampled level held).
    #[serde(default = "one_round")]
    pub rounds: usize,
    /// The planner families of the final round, with the largest error each forced.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub planners: Vec<PlannerResult>,
    /// The checks of the final round, each with its own start states: `uniform` (the set), and where they
    /// ran `zero-error-slice` and `falsification`. The row is verified only when every check holds.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub checks: Vec<CheckResult>,
}

/// One check of a verification round: where its start states came from and what they reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckResult {
    /// `uniform` (uniform states of the certified set), `zero-error-slice` (uniform states of its slice with
    /// every error coordinate at 0, where starts and planner resets put a robot; 0 samples: the set holds
    /// none) or `falsification` (a search over start states of the set towards the largest error); in a row
    /// verified `by-axes`, prefixed by the axis subsystem (`quad10d_x: uniform`).
    pub distribution: String,
    /// States rolled out (rollouts, for the falsification).
    pub samples: usize,
    /// Those whose error exceeded the round's level (with its slack).
    pub violations: usize,
    /// The largest tracking error reached (`by-axes`: the axis' largest error less its start's value).
    pub max_error: f64,
}

fn one_round() -> usize {
    1
}

impl Verification {
    /// The planner family that forced the largest error, if the families were recorded.
    pub fn hardest_planner(&self) -> Option<&PlannerResult> {
        self.planners.iter().max_by(|a, b| a.max_error.total_cmp(&b.max_error))
    }
}

/// What one planner family forced in a verification's final round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerResult {
    /// The family, e.g. `model-worst-case`, `grid-worst-case`, `random-bang-bang`, `search`.
    pub family: String,
    /// Rollouts it played.
    pub rollouts: usize,
    /// The largest tracking error it forced.
    pub max_error: f64,
}

/// Training provenance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// How the weights were made, e.g. `random-init` or `deepreach`.
    pub method: String,
    /// The full configuration used.
    pub config: serde_json::Value,
    /// Training iterations (0 for untrained).
    pub iterations: u64,
    /// Final loss terms by name.
    pub final_losses: BTreeMap<String, f64>,
    /// Wall time of training (s).
    pub wall_time_s: f64,
    /// Machine description (cores, CPU model).
    pub machine: String,
    /// Source revision (git) of the code that made the bundle.
    pub source_revision: String,
    /// Creation time, RFC 3339.
    pub created: String,
}

impl Provenance {
    /// The provenance of a network made without training, by `method` with `config`: no iterations, no
    /// losses, and no machine, revision or time recorded.
    pub fn untrained(method: impl Into<String>, config: serde_json::Value) -> Self {
        Self {
            method: method.into(),
            config,
            iterations: 0,
            final_losses: BTreeMap::new(),
            wall_time_s: 0.0,
            machine: String::new(),
            source_revision: String::new(),
            created: String::new(),
        }
    }
}

/// Directions of [`TebRow::boundary_radii`] for an error space of `n_error` dimensions: `±1` in 1-D,
/// `count` equally spaced angles from 0 (counter-clockwise) in 2-D, none otherwise.
pub fn boundary_directions(n_error: usize, count: usize) -> Vec<Vec<f64>> {
    match n_error {
        1 => vec![vec![1.0], vec![-1.0]],
        2 => (0..count)
            .map(|k| {
                let a = 2.0 * std::f64::consts::PI * k as f64 / count as f64;
                vec![a.cos(), a.sin()]
            })
            .collect(),
        _ => Vec::new(),
    }
}

/// A manifest that fails validation: which field, and what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("manifest field `{field}`: {problem}")]
pub struct ManifestError {
    /// JSON path of the offending field.
    pub field: String,
    /// What is wrong and what is allowed.
    pub problem: String,
}

fn fail<T>(field: impl Into<String>, problem: impl Into<String>) -> Result<T, ManifestError> {
    Err(ManifestError { field: field.into(), problem: problem.into() })
}

fn check_range(field: &str, min: f64, max: f64, strict: bool) -> Result<(), ManifestError> {
    if !min.is_finite() || !max.is_finite() {
        return fail(field, format!("bounds must be finite, got [{min}, {max}]"));
    }
    if min > max || (strict && min == max) {
        return fail(field, format!("min must be {} max, got [{min}, {max}]", if strict { "<" } else { "<=" }));
    }
    Ok(())
}

impl Manifest {
    /// Parses and validates manifest JSON.
    pub fn from_json(text: &str) -> Result<Self, ManifestError> {
        let manifest: Manifest = serde_json::from_str(text).map_err(|e| ManifestError {
            field: "(schema)".into(),
            problem: format!("does not match schema version {SCHEMA_VERSION}: {e}"),
        })?;
        manifest.validate()?;
        Ok(manifest)
    }

    /// Serialises to pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("manifest serialises")
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.params.len()
    }

    /// Number of controls.
    pub fn n_control(&self) -> usize {
        self.controls.len()
    }

    /// The relative-state space the bundle describes (domains, error coordinates, `Q`): the system a server
    /// builds from a manifest, knowing no robot. Call it on a validated manifest.
    pub fn state_space(&self) -> StateSpace {
        let columns = self.planner_to_state.first().map_or(0, Vec::len);
        StateSpace {
            coordinates: self
                .state
                .iter()
                .map(|d| Coordinate { min: d.min, max: d.max, periodic: d.periodic })
                .collect(),
            error_coords: self.error_coords(),
            planner_to_state: DMatrix::from_fn(self.state.len(), columns, |i, j| self.planner_to_state[i][j]),
        }
    }

    /// Indices of the error coordinates.
    pub fn error_coords(&self) -> Vec<usize> {
        (0..self.state.len()).filter(|&i| self.state[i].error_coordinate).collect()
    }

    /// `[beta_l, beta_u]`: the range every parameter shares for table queries (the intersection).
    pub fn beta_range(&self) -> (f64, f64) {
        self.params.iter().fold((f64::NEG_INFINITY, f64::INFINITY), |(lo, hi), p| (lo.max(p.min), hi.min(p.max)))
    }

    /// Checks every invariant the server relies on.
    pub fn validate(&self) -> Result<(), ManifestError> {
        if self.schema_version != SCHEMA_VERSION {
            return fail("schema_version", format!("must be {SCHEMA_VERSION}, got {}", self.schema_version));
        }
        if self.name.is_empty() || !self.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
            return fail("name", format!("must be non-empty [A-Za-z0-9_-], got {:?}", self.name));
        }
        if self.version == 0 {
            return fail("version", "must be a positive integer, got 0");
        }
        if self.state.is_empty() {
            return fail("state", "must list at least one coordinate");
        }
        for (i, dim) in self.state.iter().enumerate() {
            check_range(&format!("state[{i}] ({})", dim.name), dim.min, dim.max, true)?;
            if dim.periodic && dim.error_coordinate {
                return fail(format!("state[{i}] ({})", dim.name), "an error coordinate cannot be periodic");
            }
            if let Some([low, high]) = dim.limits {
                if dim.periodic || !(dim.min <= low && low < high && high <= dim.max) {
                    return fail(
                        format!("state[{i}] ({}).limits", dim.name),
                        format!(
                            "must be increasing and inside the domain [{}, {}] of a non-periodic coordinate, got [{low}, {high}]",
                            dim.min, dim.max
                        ),
                    );
                }
            }
        }
        if self.error_coords().is_empty() {
            return fail("state", "at least one coordinate must be an error coordinate");
        }
        if self.planner_to_state.len() != self.state.len() {
            return fail(
                "planner_to_state",
                format!(
                    "must have one row per state coordinate ({}), got {}",
                    self.state.len(),
                    self.planner_to_state.len()
                ),
            );
        }
        let planner_dim = self.planner_to_state.first().map_or(0, Vec::len);
        if planner_dim == 0 {
            return fail("planner_to_state", "rows must have at least one column");
        }
        for (i, row) in self.planner_to_state.iter().enumerate() {
            if row.len() != planner_dim || row.iter().any(|x| !x.is_finite()) {
                return fail(format!("planner_to_state[{i}]"), format!("must hold {planner_dim} finite numbers"));
            }
        }
        if self.params.is_empty() {
            return fail("params", "must list at least one parameter");
        }
        for (i, p) in self.params.iter().enumerate() {
            check_range(&format!("params[{i}] ({})", p.name), p.min, p.max, true)?;
        }
        let (beta_l, beta_u) = self.beta_range();
        if beta_l >= beta_u {
            return fail(
                "params",
                format!("parameter ranges must overlap, their intersection is [{beta_l}, {beta_u}]"),
            );
        }
        if self.controls.is_empty() {
            return fail("controls", "must list at least one control");
        }
        for (i, c) in self.controls.iter().enumerate() {
            check_range(&format!("controls[{i}] ({})", c.name), c.min, c.max, false)?;
        }
        if !(self.horizon.is_finite() && self.horizon > 0.0) {
            return fail("horizon", format!("must be finite and > 0, got {}", self.horizon));
        }
        if self.network.omega_0 <= 0.0 || self.network.hidden.contains(&0) {
            return fail("network", "omega_0 must be > 0 and hidden widths > 0");
        }
        if (self.network.kind == COMPOSITE_KIND) == self.network.axes.is_empty() {
            return fail("network.axes", format!("a `{COMPOSITE_KIND}` network lists its axes, and only it does"));
        }
        for (i, a) in self.network.axes.iter().enumerate() {
            if a.omega_0 <= 0.0
                || a.hidden.is_empty()
                || a.hidden.contains(&0)
                || !(a.horizon.is_finite() && a.horizon > 0.0)
            {
                return fail(format!("network.axes[{i}]"), "omega_0 and horizon must be > 0 and hidden widths > 0");
            }
            if let Some(&c) = a.coords.iter().find(|&&c| c >= self.state.len()) {
                return fail(
                    format!("network.axes[{i}].coords"),
                    format!("coordinate {c} is not below n_state = {}", self.state.len()),
                );
            }
            if a.param >= self.params.len() {
                return fail(
                    format!("network.axes[{i}].param"),
                    format!("{} is not below n_params = {}", a.param, self.params.len()),
                );
            }
        }
        self.validate_teb_table(beta_l, beta_u)?;
        if self.onnx_sha256.len() != 64
            || !self.onnx_sha256.chars().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
        {
            return fail("onnx_sha256", format!("must be 64 lowercase hex digits, got {:?}", self.onnx_sha256));
        }
        Ok(())
    }

    fn validate_teb_table(&self, beta_l: f64, beta_u: f64) -> Result<(), ManifestError> {
        let rows = &self.teb_table;
        if rows.len() < MIN_TEB_ROWS {
            return fail("teb_table", format!("must have at least {MIN_TEB_ROWS} rows, got {}", rows.len()));
        }
        let tol = 1e-9 * (beta_u - beta_l);
        if (rows[0].beta - beta_l).abs() > tol || (rows[rows.len() - 1].beta - beta_u).abs() > tol {
            return fail(
                "teb_table",
                format!(
                    "must span the parameter range [{beta_l}, {beta_u}], got [{}, {}]",
                    rows[0].beta,
                    rows[rows.len() - 1].beta
                ),
            );
        }
        let n_error = self.error_coords().len();
        for (i, row) in rows.iter().enumerate() {
            let field = format!("teb_table[{i}]");
            if i > 0 && row.beta <= rows[i - 1].beta {
                return fail(field, format!("beta must increase, {} follows {}", row.beta, rows[i - 1].beta));
            }
            if !(row.level.is_finite() && row.level > 0.0) {
                return fail(field, format!("level must be finite and > 0, got {}", row.level));
            }
            if i > 0 && row.bound() < rows[i - 1].bound() {
                return fail(field, "bounds must not decrease with beta (a conservative table is monotone)");
            }
            if row.extent.len() != n_error || row.extent.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return fail(field, format!("extent must hold {n_error} finite non-negative numbers"));
            }
            if row.boundary_radii.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return fail(field, "boundary_radii must be finite and non-negative");
            }
            if let Some(v) = &row.verification {
                if !v.verified_level.is_finite() || v.verified_level < 0.0 {
                    return fail(field, "verification.verified_level must be finite and >= 0");
                }
                if v.sampled_level.is_some_and(|l| !(l.is_finite() && l > 0.0)) {
                    return fail(field, "verification.sampled_level must be finite and > 0");
                }
            }
            if let Some(r) = &row.reference {
                if !(r.bound.is_finite() && r.bound > 0.0) {
                    return fail(field, format!("reference.bound must be finite and > 0, got {}", r.bound));
                }
                if r.source.trim().is_empty() {
                    return fail(field, "reference.source must say where the reference comes from");
                }
            }
        }
        Ok(())
    }

    /// State, parameter and control metadata taken from a system definition.
    pub fn describe_system(
        system: &AffineSystem,
    ) -> (Vec<StateDimension>, Vec<Vec<f64>>, Vec<RangeDimension>, Vec<RangeDimension>) {
        let state = system
            .state
            .iter()
            .enumerate()
            .map(|(i, d)| StateDimension {
                name: d.name.into(),
                unit: d.unit.into(),
                min: d.min,
                max: d.max,
                periodic: d.periodic,
                error_coordinate: system.error_coords.contains(&i),
                limits: d.limits.map(|(low, high)| [low, high]),
            })
            .collect();
        let q = (0..system.n_state())
            .map(|i| (0..system.planner_dim()).map(|j| system.planner_to_state[(i, j)]).collect())
            .collect();
        let params = system
            .params
            .iter()
            .map(|p| RangeDimension { name: p.name.into(), unit: p.unit.into(), min: p.min, max: p.max })
            .collect();
        let controls = system
            .controls
            .iter()
            .map(|c| RangeDimension { name: c.name.into(), unit: c.unit.into(), min: c.min, max: c.max })
            .collect();
        (state, q, params, controls)
    }
}
