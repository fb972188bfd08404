//! The operational distribution: relative states the online loop put trackers in, recorded from simulated
//! runs (`fastrack sim bench --visits FILE`), and a sampler that draws a row's check from those of them that
//! lie in the round's set.
//!
//! The file is CSV: a header `branch,beta,<the model's state coordinates, in order>` and one line per control
//! period, the branch of adjustPlannerControl that placed the planner (`advance`, `steady`, `keep`, `reset`,
//! `hold`), the `beta` whose row was in force, and the relative state the control was read at. Every recorded
//! state that lies in a row's set `{V <= c}` (and in the trained domain) is one the loop may hand that row,
//! whichever row was in force when it was recorded, so the check draws from all of them: `N` independent
//! draws, with replacement, from the empirical distribution of the recorded states inside the set.

use super::VerifyError;
use fastrack_valuefn::runtime::Evaluator;
use rand::rngs::StdRng;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// States per graph call when measuring which recorded states lie in a set.
const CHUNK: usize = 8192;

/// Relative states recorded from simulated runs of the online loop.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedStates {
    /// The states, row-major, in the model's state order.
    states: Vec<f64>,
    /// The `beta` in force when each state was recorded.
    betas: Vec<f64>,
    /// State coordinates per state.
    n_state: usize,
    /// How many states each branch of adjustPlannerControl recorded, by name.
    pub branches: BTreeMap<String, usize>,
}

impl RecordedStates {
    /// Reads a visits file whose state columns must be `state_names`, in order.
    pub fn read(path: &Path, state_names: &[String]) -> Result<Self, VerifyError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| VerifyError::Operational(format!("reading {}: {e}", path.display())))?;
        Self::parse(&text, state_names).map_err(|why| VerifyError::Operational(format!("{}: {why}", path.display())))
    }

    /// Parses a visits file's text (see the module's doc); the error names the line and the field.
    pub fn parse(text: &str, state_names: &[String]) -> Result<Self, String> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines.next().ok_or("the file is empty; expected a header `branch,beta,<state names>`")?;
        let expected: Vec<&str> =
            ["branch", "beta"].into_iter().chain(state_names.iter().map(String::as_str)).collect();
        let found: Vec<&str> = header.split(',').map(str::trim).collect();
        if found != expected {
            return Err(format!(
                "line 1: the header is `{}`; this model's visits have `{}`",
                found.join(","),
                expected.join(",")
            ));
        }
        let n_state = state_names.len();
        let (mut states, mut betas) = (Vec::new(), Vec::new());
        let mut branches = BTreeMap::new();
        for (index, line) in lines {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != expected.len() {
                return Err(format!("line {}: {} fields; expected {}", index + 1, fields.len(), expected.len()));
            }
            let branch = fields[0];
            if !matches!(branch, "advance" | "steady" | "keep" | "reset" | "hold") {
                return Err(format!(
                    "line {}: branch `{branch}`; expected advance, steady, keep, reset or hold",
                    index + 1
                ));
            }
            for (name, field) in expected.iter().zip(&fields).skip(1) {
                let value: f64 =
                    field.parse().map_err(|_| format!("line {}: `{name}` = `{field}` is not a number", index + 1))?;
                if !value.is_finite() {
                    return Err(format!("line {}: `{name}` = {value}; must be finite", index + 1));
                }
                if *name == "beta" {
                    betas.push(value);
                } else {
                    states.push(value);
                }
            }
            *branches.entry(branch.to_string()).or_insert(0) += 1;
        }
        if states.is_empty() {
            return Err("the file holds a header and no visit".into());
        }
        Ok(Self { states, betas, n_state, branches })
    }

    /// How many states were recorded.
    pub fn len(&self) -> usize {
        self.states.len() / self.n_state
    }

    /// Whether no state was recorded (never, for a parsed file).
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// Each state's projections on `groups` of its coordinates (the coordinates of the axes one axis
    /// subsystem serves), each projection a state of its own with its visit's `beta`; branch counts count
    /// the projections. A coordinate beyond the recorded state is an error naming it.
    pub fn projected(&self, groups: &[Vec<usize>]) -> Result<Self, String> {
        let n_state = match groups.first() {
            Some(first) if groups.iter().all(|g| g.len() == first.len()) && !first.is_empty() => first.len(),
            _ => return Err("the projection needs coordinate groups of one non-zero length".into()),
        };
        if let Some(&bad) = groups.iter().flatten().find(|&&c| c >= self.n_state) {
            return Err(format!("coordinate {bad} is beyond the recorded states' {} coordinates", self.n_state));
        }
        let (mut states, mut betas) = (Vec::new(), Vec::new());
        for (state, &beta) in self.states.chunks(self.n_state).zip(&self.betas) {
            for group in groups {
                states.extend(group.iter().map(|&c| state[c]));
                betas.push(beta);
            }
        }
        let branches = self.branches.iter().map(|(name, &count)| (name.clone(), count * groups.len())).collect();
        Ok(Self { states, betas, n_state, branches })
    }
}

/// The recorded states taken while a row was in force, and how many of them lie outside that row's set (or
/// the trained domain): how often the online loop ran on the row from states its certificate does not cover.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct InForce {
    /// States recorded with the row in force.
    pub recorded: usize,
    /// Of them, outside the row's set `{V <= c}` or the trained domain.
    pub outside: usize,
}

/// Draws states independently, with replacement, from the recorded states inside `{V <= level}` at one
/// parameter vector and inside the trained domain.
pub(super) struct RecordedSampler {
    inside: Vec<f64>,
    n_state: usize,
    recorded: usize,
    /// The states recorded with this row in force.
    pub in_force: InForce,
}

impl RecordedSampler {
    /// The recorded states of `recorded` that lie in the trained domain (`lo`..`hi`) and in `{V <= level}` at
    /// `params` (the row's `beta` in every parameter).
    pub fn new(
        evaluator: &Evaluator,
        params: &[f64],
        level: f64,
        recorded: &RecordedStates,
        (lo, hi): (&[f64], &[f64]),
    ) -> Result<Self, VerifyError> {
        let n_state = recorded.n_state;
        let row_beta = params[0];
        let in_force_here = |k: usize| (recorded.betas[k] - row_beta).abs() < 1e-9;
        let in_domain: Vec<(usize, &[f64])> = recorded
            .states
            .chunks(n_state)
            .enumerate()
            .filter(|(_, s)| s.iter().zip(lo.iter().zip(hi)).all(|(&x, (&l, &h))| (l..=h).contains(&x)))
            .collect();
        let recorded_here = (0..recorded.len()).filter(|&k| in_force_here(k)).count();
        let params32: Vec<f32> = params.iter().map(|&p| p as f32).collect();
        let (mut inside, mut inside_here) = (Vec::new(), 0);
        for chunk in in_domain.chunks(CHUNK) {
            let s: Vec<f32> = chunk.iter().flat_map(|(_, state)| state.iter().map(|&x| x as f32)).collect();
            let p: Vec<f32> = params32.iter().copied().cycle().take(chunk.len() * params32.len()).collect();
            let values = evaluator.evaluate(&s, &p)?.value;
            for ((k, state), &v) in chunk.iter().zip(&values) {
                if f64::from(v) <= level {
                    inside.extend_from_slice(state);
                    inside_here += usize::from(in_force_here(*k));
                }
            }
        }
        let in_force = InForce { recorded: recorded_here, outside: recorded_here - inside_here };
        Ok(Self { inside, n_state, recorded: recorded.len(), in_force })
    }

    /// How many recorded states lie in the set.
    pub fn inside(&self) -> usize {
        self.inside.len() / self.n_state
    }
}

impl super::sampling::StateSource for RecordedSampler {
    fn draw(&mut self, count: usize, rng: &mut StdRng) -> Result<Vec<f64>, VerifyError> {
        let n = self.inside();
        if n == 0 {
            return Err(VerifyError::Operational("no recorded state lies in the set".into()));
        }
        Ok((0..count)
            .flat_map(|_| {
                let k = rng.random_range(0..n);
                self.inside[k * self.n_state..(k + 1) * self.n_state].to_vec()
            })
            .collect())
    }

    fn acceptance(&self) -> f64 {
        self.inside() as f64 / self.recorded.max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        ["x_r", "y_r", "theta", "v"].iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_visits_file_parses_with_its_branch_counts() {
        let text =
            "branch,beta,x_r,y_r,theta,v\nadvance,1.0,0.1,0.0,0.2,1.0\nkeep,0.5,0,0,0,0.5\n\nadvance,1,1,2,3,4\n";
        let recorded = RecordedStates::parse(text, &names()).unwrap();
        assert_eq!(recorded.len(), 3);
        assert_eq!(recorded.states[4..8], [0.0, 0.0, 0.0, 0.5]);
        assert_eq!(recorded.betas, [1.0, 0.5, 1.0]);
        assert_eq!(recorded.branches.get("advance"), Some(&2));
        assert_eq!(recorded.branches.get("keep"), Some(&1));
    }

    #[test]
    fn a_projection_makes_one_state_per_group_with_its_visits_beta() {
        let text = "branch,beta,x_r,y_r,theta,v\nadvance,1.0,1,2,3,4\nhold,0.5,5,6,7,8\n";
        let recorded = RecordedStates::parse(text, &names()).unwrap();
        let projected = recorded.projected(&[vec![0, 2], vec![1, 3]]).unwrap();
        assert_eq!(projected.len(), 4);
        assert_eq!(projected.states, [1.0, 3.0, 2.0, 4.0, 5.0, 7.0, 6.0, 8.0]);
        assert_eq!(projected.betas, [1.0, 1.0, 0.5, 0.5]);
        assert_eq!(projected.branches.get("hold"), Some(&2));
        let why = recorded.projected(&[vec![0, 4]]).unwrap_err();
        assert!(why.contains("coordinate 4"), "{why}");
        assert!(recorded.projected(&[vec![0], vec![1, 2]]).is_err());
    }

    #[test]
    fn bad_visits_files_are_refused_naming_line_and_field() {
        let cases = [
            ("", "empty"),
            ("branch,beta,x_r,y_r,v,theta\n", "line 1: the header"),
            ("branch,beta,x_r,y_r,theta,v\n", "no visit"),
            ("branch,beta,x_r,y_r,theta,v\nadvance,1,0,0,0\n", "line 2: 5 fields; expected 6"),
            ("branch,beta,x_r,y_r,theta,v\nwander,1,0,0,0,0\n", "line 2: branch `wander`"),
            ("branch,beta,x_r,y_r,theta,v\nhold,1,0,x,0,0\n", "line 2: `y_r` = `x` is not a number"),
            ("branch,beta,x_r,y_r,theta,v\nhold,1,0,0,NaN,0\n", "line 2: `theta` = NaN; must be finite"),
            ("branch,beta,x_r,y_r,theta,v\nreset,inf,0,0,0,0\n", "line 2: `beta` = inf; must be finite"),
        ];
        for (text, expected) in cases {
            let why = RecordedStates::parse(text, &names()).unwrap_err();
            assert!(why.contains(expected), "{text:?}: {why}");
        }
    }
}
