//! Upwind finite differences: the left and right one-sided first derivatives of grid values along one axis
//! (first order, ENO2, WENO5), and the stencil gather with the boundary conditions (periodic wrap, or
//! linear extrapolation away from zero beyond a non-periodic edge).

pub use fastrack_gridfile::settings::{Accuracy, UnknownAccuracy};

/// Values at nodes `i - 3 ..= i + 3` of one axis (index 3 is the centre); only the accuracy's half-width
/// around the centre is read.
pub type Stencil = [f64; 7];

/// Where a line of nodes sits in the flat value array.
#[derive(Debug, Clone, Copy)]
pub struct Line {
    /// Flat index of the centre node.
    pub flat: usize,
    /// Node index of the centre along the axis.
    pub node: usize,
    /// Nodes on the axis.
    pub n: usize,
    /// Flat-index step along the axis.
    pub stride: usize,
    /// Wrap-around axis.
    pub periodic: bool,
}

/// Reads the stencil of `half` nodes either side of `line`'s centre, applying the boundary condition.
pub fn gather(values: &[f64], line: Line, half: usize, out: &mut Stencil) {
    let Line { flat, node, n, stride, periodic } = line;
    if node >= half && node + half < n {
        let start = flat - half * stride;
        for (o, slot) in out[3 - half..=3 + half].iter_mut().enumerate() {
            *slot = values[start + o * stride];
        }
        return;
    }
    let row = flat - node * stride;
    let at = |j: usize| values[row + j * stride];
    for (o, slot) in out[3 - half..=3 + half].iter_mut().enumerate() {
        let j = node as isize + o as isize - half as isize;
        *slot = if periodic {
            at(j.rem_euclid(n as isize) as usize)
        } else if j < 0 {
            extrapolate(at(0), at(1), (-j) as f64)
        } else if j >= n as isize {
            extrapolate(at(n - 1), at(n - 2), (j - n as isize + 1) as f64)
        } else {
            at(j as usize)
        };
    }
}

/// One row of nodes along the last axis whose stencils along `axis` are read at once.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// Flat index of the row's first node.
    pub start: usize,
    /// Nodes in the row (the last axis' length).
    pub len: usize,
    /// The row's node index along `axis` (ignored when `axis` is the last axis).
    pub node: usize,
    /// Nodes on `axis`.
    pub n: usize,
    /// Flat-index step along `axis` (1 for the last axis).
    pub stride: usize,
    /// Wrap-around axis.
    pub periodic: bool,
}

/// Fills `rows[o][i]` (`o` in `3 - half ..= 3 + half`) with the value `o - 3` nodes along the axis from node
/// `i` of `row`, applying the boundary condition: the stencils of a whole row, laid out so that the
/// derivative loops run over contiguous memory.
pub fn gather_rows(values: &[f64], row: Row, half: usize, rows: &mut [Vec<f64>; 7]) {
    let Row { start, len, node, n, stride, periodic } = row;
    let line = &values[start..start + len];
    if stride == 1 {
        // Along the row itself: a padded copy with ghosts at both ends, read through shifted windows.
        for (o, out) in rows.iter_mut().enumerate().take(3 + half + 1).skip(3 - half) {
            for (i, slot) in out[..len].iter_mut().enumerate() {
                let j = i as isize + o as isize - 3;
                *slot = if (0..len as isize).contains(&j) {
                    line[j as usize]
                } else if periodic {
                    line[j.rem_euclid(len as isize) as usize]
                } else if j < 0 {
                    extrapolate(line[0], line[1], (-j) as f64)
                } else {
                    extrapolate(line[len - 1], line[len - 2], (j - len as isize + 1) as f64)
                };
            }
        }
        return;
    }
    let row_at = |j: usize| &values[start - node * stride + j * stride..][..len];
    for (o, out) in rows.iter_mut().enumerate().take(3 + half + 1).skip(3 - half) {
        let j = node as isize + o as isize - 3;
        let out = &mut out[..len];
        if (0..n as isize).contains(&j) {
            out.copy_from_slice(row_at(j as usize));
        } else if periodic {
            out.copy_from_slice(row_at(j.rem_euclid(n as isize) as usize));
        } else {
            let (edge, inner, k) = if j < 0 {
                (row_at(0), row_at(1), (-j) as f64)
            } else {
                (row_at(n - 1), row_at(n - 2), (j - n as isize + 1) as f64)
            };
            for ((slot, &e), &i) in out.iter_mut().zip(edge).zip(inner) {
                *slot = extrapolate(e, i, k);
            }
        }
    }
}

/// Left and right derivatives at every node of a row from its stencil rows (see [`gather_rows`]).
pub fn one_sided_rows(accuracy: Accuracy, rows: &[Vec<f64>; 7], h: f64, left: &mut [f64], right: &mut [f64]) {
    let len = left.len().min(right.len());
    let r: [&[f64]; 7] = std::array::from_fn(|o| &rows[o][..len]);
    let at = |i: usize| -> Stencil { std::array::from_fn(|o| r[o][i]) };
    // One loop per accuracy so that each body is branch-free over the row.
    match accuracy {
        Accuracy::First => (0..len).for_each(|i| (left[i], right[i]) = one_sided(Accuracy::First, &at(i), h)),
        Accuracy::Eno2 => (0..len).for_each(|i| (left[i], right[i]) = one_sided(Accuracy::Eno2, &at(i), h)),
        Accuracy::Weno5 => (0..len).for_each(|i| (left[i], right[i]) = one_sided(Accuracy::Weno5, &at(i), h)),
    }
}

/// Ghost value `k` nodes beyond an edge node `edge` whose inner neighbour is `inner`: linear extrapolation
/// with the edge slope's magnitude, directed away from zero (the convention of helperOC and hj_reachability;
/// a tracking value `V >= 0` keeps growing outward).
fn extrapolate(edge: f64, inner: f64, k: f64) -> f64 {
    let slope = (edge - inner).abs();
    if edge >= 0.0 {
        edge + k * slope
    } else {
        edge - k * slope
    }
}

/// Left and right one-sided derivatives `(D-, D+)` at the stencil centre, node spacing `h`.
#[inline(always)]
pub fn one_sided(accuracy: Accuracy, s: &Stencil, h: f64) -> (f64, f64) {
    let inv_h = 1.0 / h;
    // d[k] = (s[k + 1] - s[k]) / h is the forward difference at node i - 3 + k.
    let d = |k: usize| (s[k + 1] - s[k]) * inv_h;
    match accuracy {
        Accuracy::First => (d(2), d(3)),
        Accuracy::Eno2 => {
            let smaller = |a: f64, b: f64| if a.abs() <= b.abs() { a } else { b };
            let (dm2, dm1, d0, dp1) = (d(1), d(2), d(3), d(4));
            let left = dm1 + 0.5 * smaller(dm1 - dm2, d0 - dm1);
            let right = d0 - 0.5 * smaller(d0 - dm1, dp1 - d0);
            (left, right)
        }
        Accuracy::Weno5 => {
            let left = weno5(d(0), d(1), d(2), d(3), d(4));
            let right = weno5(d(5), d(4), d(3), d(2), d(1));
            (left, right)
        }
    }
}

/// The WENO5 combination of the five differences `v1..v5` ordered in the upwind direction
/// (Osher & Fedkiw, "Level Set Methods", section 3.4).
#[inline(always)]
fn weno5(v1: f64, v2: f64, v3: f64, v4: f64, v5: f64) -> f64 {
    let p1 = v1 / 3.0 - 7.0 * v2 / 6.0 + 11.0 * v3 / 6.0;
    let p2 = -v2 / 6.0 + 5.0 * v3 / 6.0 + v4 / 3.0;
    let p3 = v3 / 3.0 + 5.0 * v4 / 6.0 - v5 / 6.0;
    let sq = |x: f64| x * x;
    let s1 = 13.0 / 12.0 * sq(v1 - 2.0 * v2 + v3) + 0.25 * sq(v1 - 4.0 * v2 + 3.0 * v3);
    let s2 = 13.0 / 12.0 * sq(v2 - 2.0 * v3 + v4) + 0.25 * sq(v2 - v4);
    let s3 = 13.0 / 12.0 * sq(v3 - 2.0 * v4 + v5) + 0.25 * sq(3.0 * v3 - 4.0 * v4 + v5);
    let eps = 1e-6 * [v1, v2, v3, v4, v5].iter().map(|v| v * v).fold(0.0, f64::max) + 1e-99;
    let a1 = 0.1 / sq(s1 + eps);
    let a2 = 0.6 / sq(s2 + eps);
    let a3 = 0.3 / sq(s3 + eps);
    (a1 * p1 + a2 * p2 + a3 * p3) / (a1 + a2 + a3)
}
