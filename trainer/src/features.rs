//! The first layer's features as tensor operations: the normalised inputs with each circle-encoded periodic
//! coordinate replaced by its `(cos, sin)` pair ([`FeatureLayout`], shared with the f64 network and the ONNX
//! writer), and the chain rule from the features' gradient back to the inputs'.

use burn::tensor::Tensor;
use fastrack_valuefn::network::FeatureLayout;
use std::f64::consts::PI;

/// Encodes batches of normalised inputs `[N, n_inputs]` as first-layer features `[N, n_features]`.
pub struct TensorFeatures {
    layout: FeatureLayout,
}

impl TensorFeatures {
    /// Features laid out as `layout`.
    pub fn new(layout: FeatureLayout) -> Self {
        Self { layout }
    }

    /// The features of normalised inputs `x`.
    pub fn encode(&self, x: Tensor<2>) -> Tensor<2> {
        if self.layout.circles.is_empty() {
            return x;
        }
        let mut columns: Vec<Tensor<2>> = self.layout.passthrough.iter().map(|&i| x.clone().narrow(1, i, 1)).collect();
        for &i in &self.layout.circles {
            let phase = x.clone().narrow(1, i, 1).mul_scalar(PI);
            columns.push(phase.clone().cos());
            columns.push(phase.sin());
        }
        Tensor::cat(columns, 1)
    }

    /// `dy/dx` `[N, n_inputs]` from `dy/dfeatures` `[N, n_features]` at normalised inputs `x`.
    pub fn input_gradient(&self, x: &Tensor<2>, feature_gradient: Tensor<2>) -> Tensor<2> {
        if self.layout.circles.is_empty() {
            return feature_gradient;
        }
        let columns = (0..self.layout.n_inputs)
            .map(|i| {
                if let Some(f) = self.layout.passthrough.iter().position(|&p| p == i) {
                    return feature_gradient.clone().narrow(1, f, 1);
                }
                let k = self.layout.circles.iter().position(|&c| c == i).expect("every input is passthrough or circle");
                let (cos_feature, sin_feature) = self.layout.circle_features(k);
                let phase = x.clone().narrow(1, i, 1).mul_scalar(PI);
                let along_sin = feature_gradient.clone().narrow(1, sin_feature, 1).mul(phase.clone().cos());
                let along_cos = feature_gradient.clone().narrow(1, cos_feature, 1).mul(phase.sin());
                (along_sin - along_cos).mul_scalar(PI)
            })
            .collect();
        Tensor::cat(columns, 1)
    }
}
