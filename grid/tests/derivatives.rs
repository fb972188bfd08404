//! The one-sided derivative operators converge at their orders on smooth periodic functions, and the
//! interpolation reproduces multilinear functions.

use fastrack_grid::grid::{Axis, Grid};
use fastrack_grid::upwind::{gather, one_sided, Accuracy, Line, Stencil};

/// Max error of the left and right derivatives of `sin(2x) + cos(x)` on a periodic grid of `n` nodes.
fn max_error(accuracy: Accuracy, n: usize) -> f64 {
    let axis = Axis { name: "x".into(), min: 0.0, max: 2.0 * std::f64::consts::PI, n, periodic: true };
    let h = axis.spacing();
    let values: Vec<f64> = (0..n).map(|i| (2.0 * axis.coord(i)).sin() + axis.coord(i).cos()).collect();
    let mut stencil: Stencil = [0.0; 7];
    (0..n)
        .map(|i| {
            let x = axis.coord(i);
            let exact = 2.0 * (2.0 * x).cos() - x.sin();
            gather(
                &values,
                Line { flat: i, node: i, n, stride: 1, periodic: true },
                accuracy.half_width(),
                &mut stencil,
            );
            let (left, right) = one_sided(accuracy, &stencil, h);
            (left - exact).abs().max((right - exact).abs())
        })
        .fold(0.0, f64::max)
}

#[test]
fn derivatives_converge_at_their_orders() {
    for (accuracy, expected) in [(Accuracy::First, 1.0), (Accuracy::Eno2, 2.0), (Accuracy::Weno5, 5.0)] {
        let errors: Vec<f64> = [40, 80, 160].iter().map(|&n| max_error(accuracy, n)).collect();
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        eprintln!("{accuracy}: errors {errors:?}, observed orders {orders:?}");
        let last = *orders.last().unwrap();
        assert!(last > expected - 0.3, "{accuracy}: observed order {last:.2}, expected about {expected}");
        assert!(errors[2] < errors[0], "{accuracy}: the error does not shrink under refinement");
    }
}

#[test]
fn extrapolated_boundary_is_exact_for_linear_functions() {
    // A positive function growing linearly towards both edges is continued exactly by the ghost nodes.
    let n = 9;
    let values: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * (i as f64 - 4.0).abs()).collect();
    let mut stencil: Stencil = [0.0; 7];
    for accuracy in Accuracy::ALL {
        for node in [0, 1, n - 2, n - 1] {
            gather(
                &values,
                Line { flat: node, node, n, stride: 1, periodic: false },
                accuracy.half_width(),
                &mut stencil,
            );
            let (left, right) = one_sided(accuracy, &stencil, 1.0);
            let slope = if node < 4 { -0.5 } else { 0.5 };
            assert!(
                (left - slope).abs() < 1e-12 && (right - slope).abs() < 1e-12,
                "{accuracy} at node {node}: {left} {right}"
            );
        }
    }
}

#[test]
fn interpolation_reproduces_multilinear_functions_and_wraps() {
    let grid = Grid::new(vec![
        Axis { name: "a".into(), min: -1.0, max: 1.0, n: 5, periodic: false },
        Axis { name: "b".into(), min: 0.0, max: 4.0, n: 4, periodic: true },
        Axis { name: "c".into(), min: 0.0, max: 2.0, n: 6, periodic: false },
    ])
    .unwrap();
    let f = |x: &[f64]| 1.0 + 2.0 * x[0] - x[2] + 0.5 * x[0] * x[2];
    let mut r = [0.0; 3];
    let values: Vec<f64> = (0..grid.num_points())
        .map(|i| {
            grid.point(i, &mut r);
            f(&r)
        })
        .collect();
    for x in [[0.3, 1.7, 0.55], [-0.99, 0.1, 1.99], [0.0, 3.5, 1.0]] {
        let got = grid.interpolate(&values, &x);
        assert!((got - f(&x)).abs() < 1e-12, "at {x:?}: {got} vs {}", f(&x));
    }
    // A periodic axis wraps: b = 5.5 is b = 1.5.
    assert!((grid.interpolate(&values, &[0.2, 5.5, 0.4]) - grid.interpolate(&values, &[0.2, 1.5, 0.4])).abs() < 1e-12);
}
