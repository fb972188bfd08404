//! Causal training weights (Wang, Sankaran & Perdikaris 2022, "Respecting causality is all you need for
//! training physics-informed neural networks"): the horizon is split into equal bins and each bin's loss is
//! weighted by `exp(-epsilon * sum of the mean losses of the earlier bins)`, so a horizon is fitted only once
//! the shorter ones it depends on are.

/// Per-point weights for pointwise losses `losses` at horizons `taus` drawn from `[0, tau_limit]`, with
/// `bins` bins (at least 1) and strength `epsilon`.
pub fn causal_weights(taus: &[f32], losses: &[f32], tau_limit: f64, bins: usize, epsilon: f64) -> Vec<f32> {
    let bin = |tau: f32| ((f64::from(tau) / tau_limit * bins as f64).max(0.0) as usize).min(bins - 1);
    let mut sums = vec![(0.0f64, 0usize); bins];
    for (&tau, &loss) in taus.iter().zip(losses) {
        let entry = &mut sums[bin(tau)];
        *entry = (entry.0 + f64::from(loss), entry.1 + 1);
    }
    let mut earlier = 0.0;
    let weights: Vec<f64> = sums
        .iter()
        .map(|&(sum, count)| {
            let weight = (-epsilon * earlier).exp();
            earlier += sum / count.max(1) as f64;
            weight
        })
        .collect();
    taus.iter().map(|&tau| weights[bin(tau)] as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::causal_weights;

    #[test]
    fn later_bins_wait_for_earlier_ones() {
        let taus = [0.1, 0.2, 1.1, 1.2, 2.5];
        let losses = [0.5, 0.3, 1.0, 1.0, 7.0];
        let w = causal_weights(&taus, &losses, 3.0, 3, 2.0);
        assert_eq!(&w[..2], &[1.0, 1.0]);
        assert!((w[2] - (-2.0f32 * 0.4).exp()).abs() < 1e-6 && w[2] == w[3]);
        assert!((w[4] - (-2.0f32 * 1.4).exp()).abs() < 1e-6);
    }
}
