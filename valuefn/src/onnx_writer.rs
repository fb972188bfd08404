//! Compiles a [`ValueNetwork`] and a system's control law into the ONNX graph of the bundle contract:
//! inputs `state [N, n_state]`, `params [N, n_params]` (physical units); outputs `value [N]`,
//! `grad [N, n_state]` (dV/dr, an explicit backward pass through the sine layers) and
//! `control [N, n_control]` (the box minimiser of `grad . G_u u`). The horizon is fixed inside the graph;
//! input normalisation, `omega_0`, the output scale and `tau` are folded into the weights.

use crate::composite::{Composite, VALUE_FLOOR};
use crate::network::{FeatureLayout, ValueNetwork};
use crate::system::AffineSystem;
use prost::Message;

#[allow(missing_docs, clippy::all)]
mod onnx {
    include!(concat!(env!("OUT_DIR"), "/onnx.rs"));
}

/// ONNX IR version written.
pub(crate) const IR_VERSION: i64 = 8;
/// Default-domain opset written.
pub(crate) const OPSET: i64 = 17;

const FLOAT: i32 = 1;
const INT64: i32 = 7;
const ATTR_INT: i32 = 2;

/// Incrementally builds a graph: named f32/i64 initialisers and nodes with generated output names.
struct GraphBuilder {
    nodes: Vec<onnx::NodeProto>,
    initializers: Vec<onnx::TensorProto>,
    next_id: usize,
}

impl GraphBuilder {
    fn new() -> Self {
        Self { nodes: Vec::new(), initializers: Vec::new(), next_id: 0 }
    }

    fn fresh(&mut self, hint: &str) -> String {
        self.next_id += 1;
        format!("{hint}_{}", self.next_id)
    }

    fn constant(&mut self, hint: &str, dims: &[usize], data: &[f64]) -> String {
        debug_assert_eq!(dims.iter().product::<usize>(), data.len());
        let name = self.fresh(hint);
        let raw: Vec<u8> = data.iter().flat_map(|&x| (x as f32).to_le_bytes()).collect();
        self.initializers.push(onnx::TensorProto {
            name: Some(name.clone()),
            data_type: Some(FLOAT),
            dims: dims.iter().map(|&d| d as i64).collect(),
            raw_data: Some(raw),
            ..Default::default()
        });
        name
    }

    fn constant_i64(&mut self, hint: &str, data: &[i64]) -> String {
        let name = self.fresh(hint);
        self.initializers.push(onnx::TensorProto {
            name: Some(name.clone()),
            data_type: Some(INT64),
            dims: vec![data.len() as i64],
            raw_data: Some(data.iter().flat_map(|x| x.to_le_bytes()).collect()),
            ..Default::default()
        });
        name
    }

    /// Adds `op(inputs)` with integer attributes and returns its (single) output name, or `output` if given.
    fn node_named(&mut self, op: &str, inputs: &[&str], ints: &[(&str, i64)], output: Option<&str>) -> String {
        let out = output.map_or_else(|| self.fresh(&op.to_lowercase()), str::to_string);
        let name = self.fresh(op);
        self.nodes.push(onnx::NodeProto {
            op_type: Some(op.into()),
            name: Some(name),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![out.clone()],
            attribute: ints
                .iter()
                .map(|(k, v)| onnx::AttributeProto {
                    name: Some(k.to_string()),
                    r#type: Some(ATTR_INT),
                    i: Some(*v),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        });
        out
    }

    fn node(&mut self, op: &str, inputs: &[&str]) -> String {
        self.node_named(op, inputs, &[], None)
    }

    /// `x W^T + b` for `W` `[n_out x n_in]` (Gemm with transB).
    fn dense(&mut self, x: &str, weight: &str, bias: &str) -> String {
        self.node_named("Gemm", &[x, weight, bias], &[("transB", 1)], None)
    }
}

/// The first-layer terms of the circle-encoded coordinates, and what the backward pass needs of them.
struct CircleFeatures {
    /// `cos(phi) A_cos^T + sin(phi) A_sin^T` `[N, width]`.
    contribution: String,
    /// `A_cos` `[width, n_circles]` (omega_0 folded in).
    weight_cos: String,
    /// `A_sin` `[width, n_circles]`.
    weight_sin: String,
    /// `cos(phi)` `[N, n_circles]`.
    cos: String,
    /// `sin(phi)` `[N, n_circles]`.
    sin: String,
    /// `d phi / d x` per circle `[n_circles]`.
    phase_scale: String,
    /// `[n_circles, n_state]`, 1 where a circle's coordinate sits: puts per-circle terms back into the state.
    scatter: String,
}

/// Emits the phases `phi = pi (x_j - c_j) / s_j` of the circle-encoded state coordinates (gathered from the
/// wrapped state) and their first-layer contribution.
fn write_circle_features(
    b: &mut GraphBuilder,
    layout: &FeatureLayout,
    network: &ValueNetwork,
    state_w: &str,
    n_state: usize,
) -> CircleFeatures {
    let first = &network.layers[0];
    let width1 = first.n_out;
    let n_circles = layout.circles.len();
    // Input index i is state coordinate i - 1.
    let columns: Vec<i64> = layout.circles.iter().map(|&i| i as i64 - 1).collect();
    let (c, s) = (&network.input.center, &network.input.half_range);
    let centre: Vec<f64> = layout.circles.iter().map(|&i| c[i]).collect();
    let scale: Vec<f64> = layout.circles.iter().map(|&i| std::f64::consts::PI / s[i]).collect();
    let pair_weights = |pick: fn((usize, usize)) -> usize| -> Vec<f64> {
        (0..width1)
            .flat_map(|o| {
                (0..n_circles)
                    .map(move |k| network.omega_0 * first.weight[o * first.n_in + pick(layout.circle_features(k))])
            })
            .collect()
    };
    let weight_cos = b.constant("w1_cos", &[width1, n_circles], &pair_weights(|(cos, _)| cos));
    let weight_sin = b.constant("w1_sin", &[width1, n_circles], &pair_weights(|(_, sin)| sin));
    let columns = &columns;
    let scatter: Vec<f64> = (0..n_circles)
        .flat_map(|k| (0..n_state).map(move |j| if columns[k] == j as i64 { 1.0 } else { 0.0 }))
        .collect();
    let scatter = b.constant("circle_scatter", &[n_circles, n_state], &scatter);
    let index = b.constant_i64("circle_columns", columns);
    let centre = b.constant("circle_centre", &[n_circles], &centre);
    let phase_scale = b.constant("circle_phase_scale", &[n_circles], &scale);
    let coordinates = b.node_named("Gather", &[state_w, &index], &[("axis", 1)], None);
    let centred = b.node("Sub", &[&coordinates, &centre]);
    let phase = b.node("Mul", &[&centred, &phase_scale]);
    let cos = b.node("Cos", &[&phase]);
    let sin = b.node("Sin", &[&phase]);
    let from_cos = b.node_named("Gemm", &[&cos, &weight_cos], &[("transB", 1)], None);
    let from_sin = b.node_named("Gemm", &[&sin, &weight_sin], &[("transB", 1)], None);
    let contribution = b.node("Add", &[&from_cos, &from_sin]);
    CircleFeatures { contribution, weight_cos, weight_sin, cos, sin, phase_scale, scatter }
}

/// The lower and upper ends of the control range allowed at each state (`[n_control]` constants for a
/// system without state limits, `[N, n_control]` otherwise), as [`AffineSystem::control_range`] defines it.
fn write_control_range(b: &mut GraphBuilder, system: &AffineSystem, state_w: &str) -> (String, String) {
    let (n_state, n_control) = (system.n_state(), system.n_control());
    let lo: Vec<f64> = system.controls.iter().map(|c| c.min).collect();
    let hi: Vec<f64> = system.controls.iter().map(|c| c.max).collect();
    let lo_c = b.constant("u_min", &[n_control], &lo);
    let hi_c = b.constant("u_max", &[n_control], &hi);
    if system.state.iter().all(|d| d.limits.is_none()) {
        return (lo_c, hi_c);
    }
    // Beyond f32's range where a coordinate has no limit, so the comparisons below never fire there.
    let far = f64::from(f32::MAX);
    let low: Vec<f64> = system.state.iter().map(|d| d.limits.map_or(-far, |l| l.0)).collect();
    let high: Vec<f64> = system.state.iter().map(|d| d.limits.map_or(far, |l| l.1)).collect();
    // drives[sign][i][j] = 1 where control j moves limited coordinate i in direction `sign`.
    let drives = |sign: f64| -> Vec<f64> {
        (0..n_state)
            .flat_map(|i| {
                (0..n_control).map(move |j| {
                    let limited = system.state[i].limits.is_some();
                    if limited && sign * system.g_control[(i, j)] > 0.0 {
                        1.0
                    } else {
                        0.0
                    }
                })
            })
            .collect()
    };
    let up = b.constant("drives_up", &[n_state, n_control], &drives(1.0));
    let down = b.constant("drives_down", &[n_state, n_control], &drives(-1.0));
    let low_c = b.constant("limit_low", &[n_state], &low);
    let high_c = b.constant("limit_high", &[n_state], &high);
    let at_high = b.node("GreaterOrEqual", &[state_w, &high_c]);
    let at_high = b.node_named("Cast", &[&at_high], &[("to", i64::from(FLOAT))], None);
    let at_low = b.node("LessOrEqual", &[state_w, &low_c]);
    let at_low = b.node_named("Cast", &[&at_low], &[("to", i64::from(FLOAT))], None);
    // A control is capped at zero from above if it would push a coordinate up past its high limit or down
    // past its low one, and from below in the mirror cases.
    let capped_above = {
        let a = b.node("MatMul", &[&at_high, &up]);
        let c = b.node("MatMul", &[&at_low, &down]);
        b.node("Add", &[&a, &c])
    };
    let capped_below = {
        let a = b.node("MatMul", &[&at_high, &down]);
        let c = b.node("MatMul", &[&at_low, &up]);
        b.node("Add", &[&a, &c])
    };
    let zero = b.constant("zero_u", &[1], &[0.0]);
    let hi_cut = b.constant("u_max_cut", &[n_control], &hi.iter().map(|h| h.min(0.0)).collect::<Vec<_>>());
    let lo_cut = b.constant("u_min_cut", &[n_control], &lo.iter().map(|l| l.max(0.0)).collect::<Vec<_>>());
    let cap_above = b.node("Greater", &[&capped_above, &zero]);
    let cap_below = b.node("Greater", &[&capped_below, &zero]);
    let hi_row = b.node("Where", &[&cap_above, &hi_cut, &hi_c]);
    let lo_row = b.node("Where", &[&cap_below, &lo_cut, &lo_c]);
    (lo_row, hi_row)
}

fn tensor_info(name: &str, dims: &[Option<usize>]) -> onnx::ValueInfoProto {
    let dim = dims
        .iter()
        .map(|d| onnx::tensor_shape_proto::Dimension {
            value: Some(match d {
                Some(n) => onnx::tensor_shape_proto::dimension::Value::DimValue(*n as i64),
                None => onnx::tensor_shape_proto::dimension::Value::DimParam("N".into()),
            }),
            ..Default::default()
        })
        .collect();
    onnx::ValueInfoProto {
        name: Some(name.into()),
        r#type: Some(onnx::TypeProto {
            value: Some(onnx::type_proto::Value::TensorType(onnx::type_proto::Tensor {
                elem_type: Some(FLOAT),
                shape: Some(onnx::TensorShapeProto { dim }),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// Wraps the periodic coordinates of `state` (a `[N, n_state]` tensor of `system`'s coordinates):
/// `s - P floor((s - lo) / P)` on periodic coordinates, `s` elsewhere.
fn write_wrap(b: &mut GraphBuilder, system: &AffineSystem, state: &str) -> String {
    let n_state = system.n_state();
    let lo: Vec<f64> = system.state.iter().map(|d| d.min).collect();
    let period_safe: Vec<f64> = system.state.iter().map(|d| if d.periodic { d.max - d.min } else { 1.0 }).collect();
    let period_masked: Vec<f64> = system.state.iter().map(|d| if d.periodic { d.max - d.min } else { 0.0 }).collect();
    let lo_c = b.constant("domain_min", &[n_state], &lo);
    let ps_c = b.constant("period_safe", &[n_state], &period_safe);
    let pm_c = b.constant("period_masked", &[n_state], &period_masked);
    let shifted = b.node("Sub", &[state, &lo_c]);
    let cycles = b.node("Div", &[&shifted, &ps_c]);
    let cycles = b.node("Floor", &[&cycles]);
    let offset = b.node("Mul", &[&cycles, &pm_c]);
    b.node("Sub", &[state, &offset])
}

/// Emits `network` at horizon `tau` on the wrapped state `state_w` `[N, n_state]` and `params`
/// `[N, n_params]` of `system`; returns the value `[N, 1]` and its gradient `[N, n_state]`.
fn write_network(
    b: &mut GraphBuilder,
    network: &ValueNetwork,
    system: &AffineSystem,
    tau: f64,
    state_w: &str,
    params: &str,
) -> (String, String) {
    let n_state = system.n_state();
    let n_params = system.n_params();
    let n_error = system.error_coords.len();
    let state_w = state_w.to_string();

    // First layer with normalisation, omega_0 and the fixed tau folded in. Passthrough inputs enter through
    // `a_state` / `a_params`; each circle-encoded coordinate through the cos and sin of its phase.
    let w0 = network.omega_0;
    let first = &network.layers[0];
    let layout = network.feature_layout();
    let (c, s) = (&network.input.center, &network.input.half_range);
    let width1 = first.n_out;
    let feature_of: Vec<Option<usize>> =
        (0..layout.n_inputs).map(|i| layout.passthrough.iter().position(|&p| p == i)).collect();
    let col = |o: usize, i: usize| feature_of[i].map_or(0.0, |f| first.weight[o * first.n_in + f]);
    let a_state: Vec<f64> =
        (0..width1).flat_map(|o| (0..n_state).map(move |j| w0 * col(o, 1 + j) / s[1 + j])).collect();
    let a_params: Vec<f64> = (0..width1)
        .flat_map(|o| (0..n_params).map(move |k| w0 * col(o, 1 + n_state + k) / s[1 + n_state + k]))
        .collect();
    let b_first: Vec<f64> = (0..width1)
        .map(|o| {
            let centred: f64 = (1..layout.n_inputs).map(|i| col(o, i) * c[i] / s[i]).sum();
            w0 * (first.bias[o] + col(o, 0) * (tau - c[0]) / s[0] - centred)
        })
        .collect();
    let a_state_c = b.constant("w1_state", &[width1, n_state], &a_state);
    let a_params_c = b.constant("w1_params", &[width1, n_params], &a_params);
    let b_first_c = b.constant("b1", &[width1], &b_first);
    let from_params = b.node_named("Gemm", &[params, &a_params_c, &b_first_c], &[("transB", 1)], None);
    let from_state = b.node_named("Gemm", &[&state_w, &a_state_c], &[("transB", 1)], None);
    let mut z = b.node("Add", &[&from_state, &from_params]);
    let circles = if layout.circles.is_empty() {
        None
    } else {
        let circle = write_circle_features(b, &layout, network, &state_w, n_state);
        z = b.node("Add", &[&z, &circle.contribution]);
        Some(circle)
    };
    let mut pre_activations = vec![z.clone()];
    let mut h = b.node("Sin", &[&z]);

    // Hidden sine layers.
    let hidden = &network.layers[1..network.layers.len() - 1];
    let mut weight_names = Vec::new();
    for layer in hidden {
        let w: Vec<f64> = layer.weight.iter().map(|x| w0 * x).collect();
        let bias: Vec<f64> = layer.bias.iter().map(|x| w0 * x).collect();
        let w_c = b.constant("w", &[layer.n_out, layer.n_in], &w);
        let b_c = b.constant("b", &[layer.n_out], &bias);
        z = b.dense(&h, &w_c, &b_c);
        pre_activations.push(z.clone());
        weight_names.push(w_c);
        h = b.node("Sin", &[&z]);
    }

    // Linear output layer; tau and the output scale folded in for the exact boundary condition.
    let last = &network.layers[network.layers.len() - 1];
    let factor = if network.exact_boundary { tau } else { 1.0 };
    let w_out: Vec<f64> = last.weight.iter().map(|x| factor * network.output_scale * x).collect();
    let b_out = factor * (network.output_scale * last.bias[0] + network.output_offset);
    let w_out_c = b.constant("w_out", &[1, last.n_in], &w_out);
    let b_out_c = b.constant("b_out", &[1], &[b_out]);
    let mut value_2d = b.dense(&h, &w_out_c, &b_out_c);

    // Explicit backward pass: g = cos(z_k) * g, g = g W_k.
    let cos_last = b.node("Cos", &[pre_activations.last().unwrap()]);
    let mut g = b.node("Mul", &[&cos_last, &w_out_c]);
    for (k, w_c) in weight_names.iter().enumerate().rev() {
        let back = b.node("MatMul", &[&g, w_c]);
        let cos = b.node("Cos", &[&pre_activations[k]]);
        g = b.node("Mul", &[&cos, &back]);
    }
    let mut grad = b.node("MatMul", &[&g, &a_state_c]);
    if let Some(circle) = &circles {
        // dz1/dx_j through the phase phi = k (x_j - c): k (a_sin cos(phi) - a_cos sin(phi)).
        let via_cos = b.node("MatMul", &[&g, &circle.weight_cos]);
        let via_sin = b.node("MatMul", &[&g, &circle.weight_sin]);
        let along_sin = b.node("Mul", &[&via_sin, &circle.cos]);
        let along_cos = b.node("Mul", &[&via_cos, &circle.sin]);
        let d_phase = b.node("Sub", &[&along_sin, &along_cos]);
        let d_coordinate = b.node("Mul", &[&d_phase, &circle.phase_scale]);
        let scattered = b.node("MatMul", &[&d_coordinate, &circle.scatter]);
        grad = b.node("Add", &[&grad, &scattered]);
    }

    if network.exact_boundary {
        // V += l(r) = |E^T r|, dV/dr += E (E^T r) / max(l, eps).
        let select: Vec<f64> = (0..n_state)
            .flat_map(|i| (0..n_error).map(move |j| if system.error_coords[j] == i { 1.0 } else { 0.0 }))
            .collect();
        let select_t: Vec<f64> = (0..n_error)
            .flat_map(|j| (0..n_state).map(move |i| if system.error_coords[j] == i { 1.0 } else { 0.0 }))
            .collect();
        let sel_c = b.constant("error_select", &[n_state, n_error], &select);
        let sel_t_c = b.constant("error_select_t", &[n_error, n_state], &select_t);
        let axes = b.constant_i64("axes1", &[1]);
        let eps = b.constant("eps", &[1], &[1e-12]);
        let e = b.node("MatMul", &[&state_w, &sel_c]);
        let e2 = b.node("Mul", &[&e, &e]);
        let sum = b.node_named("ReduceSum", &[&e2, &axes], &[("keepdims", 1)], None);
        let l = b.node("Sqrt", &[&sum]);
        value_2d = b.node("Add", &[&value_2d, &l]);
        let l_safe = b.node("Max", &[&l, &eps]);
        let unit = b.node("Div", &[&e, &l_safe]);
        let grad_l = b.node("MatMul", &[&unit, &sel_t_c]);
        grad = b.node("Add", &[&grad, &grad_l]);
    }
    (value_2d, grad)
}

/// Emits `system`'s optimal control law `control [N, n_control]` on the wrapped state `state_w` for the
/// gradient `grad` `[N, n_state]`: `u_j = lo_j` if `c_j > 0`, `hi_j` if `c_j < 0`, the midpoint if `c_j = 0`,
/// with `c = grad G_u`, over the range allowed at the state (the box, cut at zero at the state's limits:
/// [`AffineSystem::control_range`]).
fn write_control_law(b: &mut GraphBuilder, system: &AffineSystem, state_w: &str, grad: &str) {
    let (n_state, n_control) = (system.n_state(), system.n_control());
    let g_u: Vec<f64> = (0..n_state).flat_map(|i| (0..n_control).map(move |j| system.g_control[(i, j)])).collect();
    let g_u_c = b.constant("g_control", &[n_state, n_control], &g_u);
    let (u_lo, u_hi) = write_control_range(b, system, state_w);
    let sum = b.node("Add", &[&u_lo, &u_hi]);
    let half = b.constant("half", &[1], &[0.5]);
    let u_mid = b.node("Mul", &[&sum, &half]);
    let zero = b.constant("zero", &[1], &[0.0]);
    let coeff = b.node("MatMul", &[grad, &g_u_c]);
    let positive = b.node("Greater", &[&coeff, &zero]);
    let negative = b.node("Less", &[&coeff, &zero]);
    let not_positive = b.node("Where", &[&negative, &u_hi, &u_mid]);
    b.node_named("Where", &[&positive, &u_lo, &not_positive], &[], Some("control"));
}

/// The serialised `ModelProto` of a graph of the bundle contract for `system`, its nodes and initialisers in `b`.
fn finish_model(b: GraphBuilder, system: &AffineSystem, doc: String) -> Vec<u8> {
    let (n_state, n_params, n_control) = (system.n_state(), system.n_params(), system.n_control());
    let graph = onnx::GraphProto {
        name: Some(format!("{}_value", system.id)),
        node: b.nodes,
        initializer: b.initializers,
        input: vec![tensor_info("state", &[None, Some(n_state)]), tensor_info("params", &[None, Some(n_params)])],
        output: vec![
            tensor_info("value", &[None]),
            tensor_info("grad", &[None, Some(n_state)]),
            tensor_info("control", &[None, Some(n_control)]),
        ],
        ..Default::default()
    };
    let model = onnx::ModelProto {
        ir_version: Some(IR_VERSION),
        opset_import: vec![onnx::OperatorSetIdProto { domain: Some(String::new()), version: Some(OPSET) }],
        producer_name: Some("fastrack".into()),
        producer_version: Some(env!("CARGO_PKG_VERSION").into()),
        doc_string: Some(doc),
        graph: Some(graph),
        ..Default::default()
    };
    model.encode_to_vec()
}

/// Writes the ONNX model (serialised `ModelProto`) for `network` evaluated at horizon `tau`, with the
/// optimal control law of `system`.
pub fn write_value_graph(network: &ValueNetwork, system: &AffineSystem, tau: f64) -> Vec<u8> {
    let mut b = GraphBuilder::new();
    let state_w = write_wrap(&mut b, system, "state");
    let (value_2d, grad) = write_network(&mut b, network, system, tau, &state_w, "params");
    let axes = b.constant_i64("squeeze_axes", &[1]);
    b.node_named("Squeeze", &[&value_2d, &axes], &[], Some("value"));
    b.node_named("Identity", &[&grad], &[], Some("grad"));
    write_control_law(&mut b, system, &state_w, "grad");
    finish_model(b, system, format!("SIREN value function of {} at horizon {tau} s", system.id))
}

/// Writes the ONNX model of a [`Composite`]: each axis network on its gathered coordinates and parameter,
/// combined into `value` and `grad` and the control law as [`Composite::evaluate`] does.
pub fn write_composite_graph(composite: &Composite) -> Vec<u8> {
    let system = composite.system();
    let n_state = system.n_state();
    let mut b = GraphBuilder::new();
    let state_w = write_wrap(&mut b, system, "state");
    let zero = b.constant("zero_value", &[1], &[0.0]);
    // Per axis: max(V_a, 0) [N, 1], dV_a/dr_a [N, k] and the [k, n_state] map back into the full state.
    let mut parts = Vec::new();
    let mut squares = zero.clone();
    for a in composite.axes() {
        let coords: Vec<i64> = a.axis.coords.iter().map(|&i| i as i64).collect();
        let coords_c = b.constant_i64("axis_coords", &coords);
        let sub_state = b.node_named("Gather", &[&state_w, &coords_c], &[("axis", 1)], None);
        let param_c = b.constant_i64("axis_param", &[a.axis.param as i64]);
        let sub_params = b.node_named("Gather", &["params", &param_c], &[("axis", 1)], None);
        let (value, grad) = write_network(&mut b, &a.network, &a.subsystem, a.tau, &sub_state, &sub_params);
        let value = b.node("Max", &[&value, &zero]);
        let square = b.node("Mul", &[&value, &value]);
        squares = b.node("Add", &[&squares, &square]);
        let k = coords.len();
        let scatter: Vec<f64> =
            (0..k).flat_map(|j| (0..n_state).map(move |i| if a.axis.coords[j] == i { 1.0 } else { 0.0 })).collect();
        let scatter_c = b.constant("axis_scatter", &[k, n_state], &scatter);
        parts.push((value, grad, scatter_c));
    }
    let value_2d = b.node("Sqrt", &[&squares]);
    let floor = b.constant("value_floor", &[1], &[VALUE_FLOOR]);
    let value_safe = b.node("Max", &[&value_2d, &floor]);
    let no_gradient = b.constant("zero_gradient", &[1, n_state], &vec![0.0; n_state]);
    let (mut grad, mut axis_grad) = (no_gradient.clone(), no_gradient);
    for (value, axis_gradient, scatter) in parts {
        let weight = b.node("Div", &[&value, &value_safe]);
        let weighted = b.node("Mul", &[&axis_gradient, &weight]);
        let placed = b.node("MatMul", &[&weighted, &scatter]);
        let placed_raw = b.node("MatMul", &[&axis_gradient, &scatter]);
        grad = b.node("Add", &[&grad, &placed]);
        axis_grad = b.node("Add", &[&axis_grad, &placed_raw]);
    }
    let axes = b.constant_i64("squeeze_axes", &[1]);
    b.node_named("Squeeze", &[&value_2d, &axes], &[], Some("value"));
    b.node_named("Identity", &[&grad], &[], Some("grad"));
    write_control_law(&mut b, system, &state_w, &axis_grad);
    let taus: Vec<String> = composite.axes().iter().map(|a| format!("{} at {} s", a.subsystem.id, a.tau)).collect();
    finish_model(b, system, format!("{} composed of SIREN axis value functions: {}", system.id, taus.join(", ")))
}
