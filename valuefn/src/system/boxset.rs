//! Axis-aligned boxes: their extreme points in a direction.

/// A box `{x : lo <= x <= hi}`.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSet {
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl BoxSet {
    /// A box from its corners; `lo[i] <= hi[i]` is the caller's invariant.
    pub fn new(lo: Vec<f64>, hi: Vec<f64>) -> Self {
        debug_assert_eq!(lo.len(), hi.len());
        Self { lo, hi }
    }

    /// Lower corner.
    pub fn lo(&self) -> &[f64] {
        &self.lo
    }

    /// Upper corner.
    pub fn hi(&self) -> &[f64] {
        &self.hi
    }

    /// `min_{x in box} c . x`.
    pub fn min_dot(&self, c: &[f64]) -> f64 {
        (0..c.len()).map(|i| (c[i] * self.lo[i]).min(c[i] * self.hi[i])).sum()
    }

    /// `max_{x in box} c . x`.
    pub fn max_dot(&self, c: &[f64]) -> f64 {
        (0..c.len()).map(|i| (c[i] * self.lo[i]).max(c[i] * self.hi[i])).sum()
    }

    /// A minimiser of `c . x`: `lo` where `c > 0`, `hi` where `c < 0`, the midpoint where `c = 0`.
    pub fn argmin_dot(&self, c: &[f64]) -> Vec<f64> {
        (0..c.len())
            .map(|i| {
                if c[i] > 0.0 {
                    self.lo[i]
                } else if c[i] < 0.0 {
                    self.hi[i]
                } else {
                    0.5 * (self.lo[i] + self.hi[i])
                }
            })
            .collect()
    }

    /// A maximiser of `c . x` (the mirror of [`BoxSet::argmin_dot`]).
    pub fn argmax_dot(&self, c: &[f64]) -> Vec<f64> {
        let neg: Vec<f64> = c.iter().map(|x| -x).collect();
        self.argmin_dot(&neg)
    }

    /// `max_{x in box} |x_i|` per coordinate.
    pub fn abs_max(&self) -> Vec<f64> {
        self.lo.iter().zip(&self.hi).map(|(l, h)| l.abs().max(h.abs())).collect()
    }

    /// Every vertex of the box (`2^n` points), for brute-force checks.
    pub fn vertices(&self) -> Vec<Vec<f64>> {
        let n = self.lo.len();
        (0..1usize << n)
            .map(|mask| (0..n).map(|i| if mask >> i & 1 == 1 { self.hi[i] } else { self.lo[i] }).collect())
            .collect()
    }
}
