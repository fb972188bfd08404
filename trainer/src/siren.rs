//! The SIREN value network in burn, with its input gradient written as explicit tensor operations (burn
//! has first-order autodiff only, and DeepReach's loss needs `dV/dinput` inside the loss).

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use fastrack_valuefn::network::{Dense, ValueNetwork};

/// Trainable parameters: sine layers then a linear output layer. Weights are `[n_in, n_out]` (`y = x W + b`).
#[derive(Module, Debug)]
pub struct Siren {
    weights: Vec<Param<Tensor<2>>>,
    biases: Vec<Param<Tensor<1>>>,
}

/// Network outputs for a batch of first-layer features (the normalised inputs as `crate::features` encodes
/// them).
pub struct Forward {
    /// Network output `y` `[N, 1]`.
    pub output: Tensor<2>,
    /// `dy/dx` with respect to the features `[N, n_in]`.
    pub input_grad: Tensor<2>,
}

fn tensor2(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// `(sin z, cos z)` with each transcendental evaluated once: the values are computed on a detached copy and
/// the first-order derivatives attached as `f(z0) + (z - z0) f'(z0)`, exact at `z = z0`, so the backward
/// pass multiplies by stored tensors instead of evaluating `cos` and `sin` again. On the CPU backend both
/// come from one vectorised pass ([`crate::sincos`]); GPU backends use their own kernels.
fn sin_cos_once(z: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let z0 = z.clone().detach();
    let device = z0.device();
    let (sin0, cos0) = if device == Device::flex() {
        let shape = z0.dims();
        let values: Vec<f32> = z0.clone().into_data().try_into_vec().expect("f32 pre-activations");
        let (sin, cos) = crate::sincos::sin_cos(&values);
        (tensor2(sin, shape, &device), tensor2(cos, shape, &device))
    } else {
        (z0.clone().sin(), z0.clone().cos())
    };
    let dz = z - z0;
    (sin0.clone() + dz.clone().mul(cos0.clone()), cos0 - dz.mul(sin0))
}

impl Siren {
    /// The burn copy of a reference network's weights (transposed to `[n_in, n_out]`).
    pub fn from_network(network: &ValueNetwork, device: &Device) -> Self {
        let weights = network
            .layers
            .iter()
            .map(|layer| {
                let transposed: Vec<f32> = (0..layer.n_in)
                    .flat_map(|i| (0..layer.n_out).map(move |o| layer.weight[o * layer.n_in + i] as f32))
                    .collect();
                Param::from_tensor(tensor2(transposed, [layer.n_in, layer.n_out], device))
            })
            .collect();
        let biases = network
            .layers
            .iter()
            .map(|layer| {
                let bias: Vec<f32> = layer.bias.iter().map(|&b| b as f32).collect();
                Param::from_tensor(Tensor::from_data(TensorData::new(bias, [layer.n_out]), device))
            })
            .collect();
        Self { weights, biases }
    }

    /// Writes the trained weights back into `network` (same architecture).
    pub fn write_into(&self, network: &mut ValueNetwork) {
        for (k, layer) in network.layers.iter_mut().enumerate() {
            let w: Vec<f32> = self.weights[k].val().into_data().try_to_vec().expect("f32 weights");
            let b: Vec<f32> = self.biases[k].val().into_data().try_to_vec().expect("f32 biases");
            let (n_in, n_out) = (layer.n_in, layer.n_out);
            let w = &w;
            *layer = Dense {
                n_in,
                n_out,
                weight: (0..n_out).flat_map(|o| (0..n_in).map(move |i| f64::from(w[i * n_out + o]))).collect(),
                bias: b.iter().map(|&x| f64::from(x)).collect(),
            };
        }
    }

    /// `y` alone for features `x` `[N, n_in]` (no input gradient).
    pub fn output(&self, x: Tensor<2>, omega_0: f64) -> Tensor<2> {
        let last = self.weights.len() - 1;
        let h = (0..last).fold(x, |h, k| {
            (h.matmul(self.weights[k].val()) + self.biases[k].val().unsqueeze::<2>()).mul_scalar(omega_0).sin()
        });
        h.matmul(self.weights[last].val()) + self.biases[last].val().unsqueeze::<2>()
    }

    /// `y` and `dy/dx` for features `x` `[N, n_in]`: forward through `sin(omega_0 (x W + b))`
    /// layers, then the backward pass `g = W_L^T; g = (omega_0 cos(omega_0 z_k) * g) W_k^T` as tensor ops,
    /// so autodiff can differentiate the loss through both.
    pub fn forward(&self, x: Tensor<2>, omega_0: f64) -> Forward {
        let n_layers = self.weights.len();
        let mut h = x;
        let mut scaled_cos = Vec::with_capacity(n_layers - 1);
        for k in 0..n_layers - 1 {
            let z = (h.matmul(self.weights[k].val()) + self.biases[k].val().unsqueeze::<2>()).mul_scalar(omega_0);
            let (sin, cos) = sin_cos_once(z);
            scaled_cos.push(cos.mul_scalar(omega_0));
            h = sin;
        }
        let last = n_layers - 1;
        let output = h.matmul(self.weights[last].val()) + self.biases[last].val().unsqueeze::<2>();
        // d y / d h_L = W_out^T, broadcast over the batch.
        let mut g = scaled_cos[last - 1].clone().mul(self.weights[last].val().transpose());
        for k in (0..last).rev() {
            g = g.matmul(self.weights[k].val().transpose());
            if k > 0 {
                g = g.mul(scaled_cos[k - 1].clone());
            }
        }
        Forward { output, input_grad: g }
    }
}

#[cfg(test)]
mod tests {
    use super::sin_cos_once;
    use burn::tensor::{Device, Tensor, TensorData};

    #[test]
    fn sin_cos_once_has_the_values_and_derivatives_of_sin_and_cos() {
        let device = Device::flex().autodiff();
        let z: Vec<f32> = (0..64).map(|i| -40.0 + 1.27 * i as f32).collect();
        let (a, b): (Vec<f32>, Vec<f32>) = (0..64).map(|i| (0.3 + 0.01 * i as f32, 1.0 - 0.02 * i as f32)).unzip();
        let tensor = |v: &[f32]| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [8, 8]), &device);
        let input = tensor(&z).require_grad();
        let (sin, cos) = sin_cos_once(input.clone());
        let values = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();
        let (sin_values, cos_values) = (values(sin.clone()), values(cos.clone()));
        let grads = (sin.mul(tensor(&a)) + cos.mul(tensor(&b))).sum().backward();
        let gradient = values(input.grad(&grads).unwrap());
        for i in 0..z.len() {
            let x = f64::from(z[i]);
            assert!(
                (f64::from(sin_values[i]) - x.sin()).abs() < 1e-6 && (f64::from(cos_values[i]) - x.cos()).abs() < 1e-6
            );
            // d/dz (a sin z + b cos z) = a cos z - b sin z.
            let expected = f64::from(a[i]) * x.cos() - f64::from(b[i]) * x.sin();
            assert!((f64::from(gradient[i]) - expected).abs() < 1e-5, "z = {x}: {} vs {expected}", gradient[i]);
        }
    }
}
