//! The drift `f(r)` as a small sum-of-products expression, so that the same definition evaluates in f64
//! here and can be lowered to tensor operations by the trainer.

/// One factor of a drift term, applied to a state coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Factor {
    /// `r_j`
    Linear(usize),
    /// `sin(r_j)`
    Sin(usize),
    /// `cos(r_j)`
    Cos(usize),
    /// `tan(r_j)`
    Tan(usize),
}

impl Factor {
    /// Value of the factor at `r`.
    pub fn eval(self, r: &[f64]) -> f64 {
        match self {
            Factor::Linear(j) => r[j],
            Factor::Sin(j) => r[j].sin(),
            Factor::Cos(j) => r[j].cos(),
            Factor::Tan(j) => r[j].tan(),
        }
    }
}

/// `coefficient * prod(factors)` contributing to `f_i`.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftTerm {
    /// State derivative the term adds to.
    pub output: usize,
    /// Constant coefficient.
    pub coefficient: f64,
    /// Factors multiplied together (empty: a constant).
    pub factors: Vec<Factor>,
}

/// `f(r)`: a sum of [`DriftTerm`]s.
#[derive(Debug, Clone, PartialEq)]
pub struct Drift {
    /// Number of state coordinates.
    pub n_state: usize,
    /// The terms.
    pub terms: Vec<DriftTerm>,
}

impl Drift {
    /// Evaluates `f(r)` into `out` (length `n_state`).
    pub fn eval(&self, r: &[f64], out: &mut [f64]) {
        out.iter_mut().for_each(|o| *o = 0.0);
        for term in &self.terms {
            out[term.output] += term.coefficient * term.factors.iter().map(|f| f.eval(r)).product::<f64>();
        }
    }
}

/// Shorthand for a term.
pub(crate) fn term(output: usize, coefficient: f64, factors: &[Factor]) -> DriftTerm {
    DriftTerm { output, coefficient, factors: factors.to_vec() }
}
