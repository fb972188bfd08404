//! A system's Hamiltonian and tracking error as tensor operations, derived from the same
//! [`AffineSystem`] definition as the f64 code (box extreme points in closed form:
//! `min_{u in box} c.u = c.mid - |c|.half`).

use burn::tensor::{Device, Tensor, TensorData};
use fastrack_valuefn::system::{AffineSystem, DriftTerm, Factor};

/// The tensor form of one system.
pub struct TensorDynamics {
    n_state: usize,
    drift: Vec<DriftTerm>,
    error_coords: Vec<usize>,
    g_control: Tensor<2>,
    control_mid: Tensor<2>,
    control_half: Tensor<2>,
    g_planner: Tensor<2>,
    planner_param_select: Tensor<2>,
    g_disturbance: Option<(Tensor<2>, Tensor<2>, Tensor<2>)>,
}

fn matrix(m: &nalgebra::DMatrix<f64>, device: &Device) -> Tensor<2> {
    let values: Vec<f32> = (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)] as f32)).collect();
    Tensor::from_data(TensorData::new(values, [m.nrows(), m.ncols()]), device)
}

fn row(values: impl Iterator<Item = f64>, device: &Device) -> Tensor<2> {
    let v: Vec<f32> = values.map(|x| x as f32).collect();
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [1, n]), device)
}

/// Every sign pattern of `{-1, 1}^n`.
fn sign_vertices(n: usize) -> Vec<Vec<f64>> {
    (0..1usize << n).map(|k| (0..n).map(|i| if (k >> i) & 1 == 1 { 1.0 } else { -1.0 }).collect()).collect()
}

fn column(r: &Tensor<2>, j: usize) -> Tensor<2> {
    r.clone().narrow(1, j, 1)
}

impl TensorDynamics {
    /// Uploads `system`'s matrices and boxes to `device`.
    pub fn new(system: &AffineSystem, device: &Device) -> Self {
        let select = nalgebra::DMatrix::from_fn(system.n_params(), system.planner_input_param.len(), |k, i| {
            if system.planner_input_param[i] == k {
                1.0
            } else {
                0.0
            }
        });
        let boxes = |dims: &[fastrack_valuefn::system::InputDim]| {
            (
                row(dims.iter().map(|d| 0.5 * (d.min + d.max)), device),
                row(dims.iter().map(|d| 0.5 * (d.max - d.min)), device),
            )
        };
        let (control_mid, control_half) = boxes(&system.controls);
        let g_disturbance = (!system.disturbances.is_empty()).then(|| {
            let (mid, half) = boxes(&system.disturbances);
            (matrix(&system.g_disturbance, device), mid, half)
        });
        Self {
            n_state: system.n_state(),
            drift: system.drift.terms.clone(),
            error_coords: system.error_coords.clone(),
            g_control: matrix(&system.g_control, device),
            control_mid,
            control_half,
            g_planner: matrix(&system.g_planner, device),
            planner_param_select: matrix(&select, device),
            g_disturbance,
        }
    }

    /// `f(r)` `[N, n_state]`.
    pub fn drift(&self, r: &Tensor<2>) -> Tensor<2> {
        let n = r.dims()[0];
        let columns = (0..self.n_state)
            .map(|i| {
                self.drift.iter().filter(|t| t.output == i).fold(Tensor::zeros([n, 1], &r.device()), |acc, term| {
                    let product = term.factors.iter().fold(Tensor::ones([n, 1], &r.device()), |p, factor| {
                        p.mul(match *factor {
                            Factor::Linear(j) => column(r, j),
                            Factor::Sin(j) => column(r, j).sin(),
                            Factor::Cos(j) => column(r, j).cos(),
                            Factor::Tan(j) => column(r, j).tan(),
                        })
                    });
                    acc + product.mul_scalar(term.coefficient)
                })
            })
            .collect();
        Tensor::cat(columns, 1)
    }

    /// `H(r, p; params) = min_u max_{u_p, d} p . r'` `[N, 1]` (horizon form).
    pub fn hamiltonian(&self, r: &Tensor<2>, p: &Tensor<2>, params: &Tensor<2>) -> Tensor<2> {
        let drift = p.clone().mul(self.drift(r)).sum_dim(1);
        let c = p.clone().matmul(self.g_control.clone());
        let control = (c.clone().mul(self.control_mid.clone()) - c.abs().mul(self.control_half.clone())).sum_dim(1);
        let betas = params.clone().matmul(self.planner_param_select.clone());
        let planner = p.clone().matmul(self.g_planner.clone()).abs().mul(betas).sum_dim(1);
        let mut h = drift + control + planner;
        if let Some((g_d, mid, half)) = &self.g_disturbance {
            let c = p.clone().matmul(g_d.clone());
            h = h + (c.clone().mul(mid.clone()) + c.abs().mul(half.clone())).sum_dim(1);
        }
        h
    }

    /// `r'(r, u, u_p, d)` `[N, n_state]` at every vertex of the input boxes: the outer list runs over the
    /// tracker's control vertices, the inner one over the planner's and the disturbance's vertices jointly.
    pub fn vertex_velocities(&self, r: &Tensor<2>, params: &Tensor<2>) -> Vec<Vec<Tensor<2>>> {
        let device = r.device();
        let drift = self.drift(r);
        let betas = params.clone().matmul(self.planner_param_select.clone());
        let box_vertices = |mid: &Tensor<2>, half: &Tensor<2>, g: &Tensor<2>| -> Vec<Tensor<2>> {
            sign_vertices(mid.dims()[1])
                .into_iter()
                .map(|signs| {
                    let input = mid.clone() + half.clone().mul(row(signs.into_iter(), &device));
                    input.matmul(g.clone().transpose())
                })
                .collect()
        };
        let controls = box_vertices(&self.control_mid, &self.control_half, &self.g_control);
        let planner: Vec<Tensor<2>> = sign_vertices(betas.dims()[1])
            .into_iter()
            .map(|signs| betas.clone().mul(row(signs.into_iter(), &device)).matmul(self.g_planner.clone().transpose()))
            .collect();
        let disturbances = match &self.g_disturbance {
            Some((g, mid, half)) => box_vertices(mid, half, g),
            None => vec![Tensor::zeros([1, self.n_state], &device)],
        };
        controls
            .iter()
            .map(|c| {
                let base = drift.clone() + c.clone();
                planner.iter().flat_map(|p| disturbances.iter().map(|d| base.clone() + p.clone() + d.clone())).collect()
            })
            .collect()
    }

    /// Tracking error `l(r)` `[N, 1]` and its gradient `[N, n_state]` (zero at `e = 0`).
    pub fn tracking_error(&self, r: &Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let n = r.dims()[0];
        let squares = self
            .error_coords
            .iter()
            .fold(Tensor::zeros([n, 1], &r.device()), |acc, &i| acc + column(r, i).powi_scalar(2));
        let l = squares.sqrt();
        let inv = l.clone().clamp_min(1e-6).recip();
        let columns = (0..self.n_state)
            .map(|i| {
                if self.error_coords.contains(&i) {
                    column(r, i).mul(inv.clone())
                } else {
                    Tensor::zeros([n, 1], &r.device())
                }
            })
            .collect();
        (l, Tensor::cat(columns, 1))
    }
}
