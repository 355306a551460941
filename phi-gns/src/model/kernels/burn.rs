//! The GNS kernels of [`Burn<Flex>`](Burn): the host kernels of `kernels/host.rs` on Flex's
//! buffers, each registered with Burn's autodiff as one operation with a hand-written backward
//! pass.
//!
//! The composites build a dense layer from three Burn operations and LayerNorm from nine, each
//! one pass over `[E, 128]` on one thread, and autodiff keeps most of their results for the
//! backward pass. Here a dense layer (with its ReLU), a LayerNorm, the split first edge layer and
//! the sum over receivers are one operation each, run in parallel, and keep only what their
//! backward pass reads: a dense layer its input and its ReLU's output, a LayerNorm the
//! normalised rows and their inverse deviations. An input of an unexpected shape goes to the
//! composite, which reports it.

use std::borrow::Cow;

use burn_autodiff::NodeId;
use burn_autodiff::checkpoint::base::Checkpointer;
use burn_autodiff::checkpoint::strategy::NoCheckpointing;
use burn_autodiff::grads::Gradients;
use burn_autodiff::ops::{Backward, Ops, OpsKind};
use burn_backend::{AutodiffBackend as _, TensorData};
use burn_flex::{Flex, FlexTensor};
use phi_core::backend::Backend;
use phi_core::backend::burn::Burn;
use phi_core::error::{Result, TensorError};

use super::{GnsKernels, host};

type Float = <Burn<Flex> as Backend>::Float;
type Ad = burn_autodiff::Autodiff<Flex>;

/// The inner Flex tensor of a tracked one (a shared buffer, not a copy).
fn inner(tensor: &Float) -> FlexTensor {
    Ad::inner(tensor.clone())
}

/// The `f32` values of a Flex tensor, row-major (a copy only for a strided view).
fn values(tensor: &FlexTensor) -> Result<Cow<'_, [f32]>> {
    if let Some(values) = tensor.as_slice::<f32>() {
        return Ok(Cow::Borrowed(values));
    }
    let contiguous = tensor.to_contiguous();
    match contiguous.as_slice::<f32>() {
        Some(values) => Ok(Cow::Owned(values.to_vec())),
        None => Err(TensorError::Backend {
            backend: "burn",
            message: format!("a GNS kernel needs f32 tensors, not {:?}", tensor.dtype()),
        }),
    }
}

/// The `i64` values of a Flex index tensor.
fn indices(tensor: &FlexTensor) -> Result<Cow<'_, [i64]>> {
    if let Some(values) = tensor.as_slice::<i64>() {
        return Ok(Cow::Borrowed(values));
    }
    let contiguous = tensor.to_contiguous();
    match contiguous.as_slice::<i64>() {
        Some(values) => Ok(Cow::Owned(values.to_vec())),
        None => Err(TensorError::Backend {
            backend: "burn",
            message: format!("GNS indices must be i64, not {:?}", tensor.dtype()),
        }),
    }
}

/// Values read in a backward pass, which cannot report an error: the tensors are this module's
/// own f32 results and the f32 gradients Burn hands back.
fn backward_values(tensor: &FlexTensor) -> Cow<'_, [f32]> {
    values(tensor).expect("autodiff gradients of f32 tensors are f32")
}

fn backward_indices(tensor: &FlexTensor) -> Cow<'_, [i64]> {
    indices(tensor).expect("the index tensors were read as i64 in the forward pass")
}

fn flex(values: Vec<f32>, shape: &[usize]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape.to_vec()))
}

fn dims(tensor: &Float) -> Vec<usize> {
    Burn::<Flex>::float_shape(tensor)
}

/// The first index outside `0..bound`, as the error the composites give.
fn check_range(index: &[i64], bound: usize, op: &'static str) -> Result<()> {
    match index.iter().find(|&&i| i < 0 || i as usize >= bound) {
        Some(&index) => Err(TensorError::IndexOutOfRange { op, index, bound }),
        None => Ok(()),
    }
}

/// `out` as the result of `op` on `parents`, tracked with `state()` when any parent is.
fn finish<const N: usize, O: Backward<Flex, N>>(
    op: O,
    parents: [&Float; N],
    state: impl FnOnce() -> O::State,
    out: FlexTensor,
) -> Float {
    let nodes = parents.map(|p| p.node());
    match op
        .prepare::<NoCheckpointing>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => prep.finish(state(), out),
        OpsKind::UnTracked(prep) => prep.finish(out),
    }
}

/// Registers `value` (of `shape`) as the gradient of `parent`, if it is tracked.
fn register(
    grads: &mut Gradients,
    parent: Option<NodeId>,
    value: impl FnOnce() -> Vec<f32>,
    shape: &[usize],
) {
    if let Some(id) = parent {
        grads.register::<Flex>(id, flex(value(), shape));
    }
}

// ------------------------------------------------------------------------------- dense layer

#[derive(Debug)]
struct DenseBackward;

#[derive(Debug, Clone)]
struct DenseState {
    input: FlexTensor,
    weight: FlexTensor,
    /// The output, for the ReLU's mask.
    output: Option<FlexTensor>,
    rows: usize,
    inputs: usize,
    outputs: usize,
}

impl Backward<Flex, 3> for DenseBackward {
    type State = DenseState;

    fn backward(self, ops: Ops<DenseState, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let s = ops.state;
        let [input, weight, bias] = ops.parents.map(|p| p.map(|n| n.id));
        let dy = grads.consume::<Flex>(&ops.node);
        let output = s.output.as_ref().map(backward_values);
        let g = host::dense_backward(
            &backward_values(&dy),
            output.as_deref(),
            &backward_values(&s.input),
            (s.rows, s.inputs, s.outputs),
            &backward_values(&s.weight),
            input.is_some(),
        );
        let dx = g.input;
        register(grads, input, || dx.unwrap_or_default(), &[s.rows, s.inputs]);
        register(grads, weight, || g.weight, &[s.outputs, s.inputs]);
        register(grads, bias, || g.bias, &[s.outputs]);
    }
}

// -------------------------------------------------------------------------------- LayerNorm

#[derive(Debug)]
struct LayerNormBackward;

#[derive(Debug, Clone)]
struct LayerNormState {
    normalised: FlexTensor,
    inverse: FlexTensor,
    gamma: FlexTensor,
    shape: Vec<usize>,
}

impl Backward<Flex, 3> for LayerNormBackward {
    type State = LayerNormState;

    fn backward(self, ops: Ops<LayerNormState, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let s = ops.state;
        let [input, gamma, beta] = ops.parents.map(|p| p.map(|n| n.id));
        let dy = grads.consume::<Flex>(&ops.node);
        let (dx, dgamma, dbeta) = host::layer_norm_backward(
            &backward_values(&dy),
            &backward_values(&s.normalised),
            &backward_values(&s.inverse),
            &backward_values(&s.gamma),
            input.is_some(),
        );
        let k = s.shape.last().copied().unwrap_or(0);
        register(grads, input, || dx.unwrap_or_default(), &s.shape);
        register(grads, gamma, || dgamma, &[k]);
        register(grads, beta, || dbeta, &[k]);
    }
}

// ------------------------------------------------------------------- split first edge layer

#[derive(Debug)]
struct EdgeInputBackward;

#[derive(Debug, Clone)]
struct EdgeInputState {
    edges: FlexTensor,
    edge_weight: FlexTensor,
    output: Option<FlexTensor>,
    senders: FlexTensor,
    receivers: FlexTensor,
    rows: usize,
    inputs: usize,
    outputs: usize,
    nodes: usize,
}

impl Backward<Flex, 5> for EdgeInputBackward {
    type State = EdgeInputState;

    fn backward(self, ops: Ops<EdgeInputState, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let s = ops.state;
        let [
            edges,
            edge_weight,
            bias,
            sender_projection,
            receiver_projection,
        ] = ops.parents.map(|p| p.map(|n| n.id));
        let dy = grads.consume::<Flex>(&ops.node);
        let output = s.output.as_ref().map(backward_values);
        let g = host::edge_input_backward(
            &backward_values(&dy),
            output.as_deref(),
            &backward_values(&s.edges),
            (s.rows, s.inputs, s.outputs),
            &backward_values(&s.edge_weight),
            &backward_indices(&s.senders),
            &backward_indices(&s.receivers),
            s.nodes,
            edges.is_some(),
        );
        let de = g.edges;
        register(grads, edges, || de.unwrap_or_default(), &[s.rows, s.inputs]);
        register(grads, edge_weight, || g.edge_weight, &[s.outputs, s.inputs]);
        register(grads, bias, || g.bias, &[s.outputs]);
        let projection = [s.nodes, s.outputs];
        register(
            grads,
            sender_projection,
            || g.sender_projection,
            &projection,
        );
        register(
            grads,
            receiver_projection,
            || g.receiver_projection,
            &projection,
        );
    }
}

// -------------------------------------------------------------------------- sum by receiver

#[derive(Debug)]
struct SumByReceiverBackward;

#[derive(Debug, Clone)]
struct SumByReceiverState {
    receivers: FlexTensor,
    width: usize,
}

impl Backward<Flex, 1> for SumByReceiverBackward {
    type State = SumByReceiverState;

    fn backward(
        self,
        ops: Ops<SumByReceiverState, 1>,
        grads: &mut Gradients,
        _: &mut Checkpointer,
    ) {
        let s = ops.state;
        let [edges] = ops.parents.map(|p| p.map(|n| n.id));
        let dy = grads.consume::<Flex>(&ops.node);
        let receivers = backward_indices(&s.receivers);
        register(
            grads,
            edges,
            || host::gather_rows(&backward_values(&dy), s.width, &receivers),
            &[receivers.len(), s.width],
        );
    }
}

impl GnsKernels for Burn<Flex> {
    fn gns_linear(x: Float, weight: Float, bias: Float, relu: bool) -> Result<Float> {
        let (xs, ws, bs) = (dims(&x), dims(&weight), dims(&bias));
        let fits = xs.len() == 2 && ws.len() == 2 && ws[1] == xs[1] && bs == [ws[0]];
        if !fits {
            return super::composite_linear::<Self>(x, weight, bias, relu);
        }
        let (rows, inputs, outputs) = (xs[0], xs[1], ws[0]);
        let (input, w, b) = (inner(&x), inner(&weight), inner(&bias));
        let out = host::dense_forward(&values(&input)?, rows, &values(&w)?, &values(&b)?, relu);
        let out = flex(out, &[rows, outputs]);
        let output = relu.then(|| out.clone());
        Ok(finish(
            DenseBackward,
            [&x, &weight, &bias],
            || DenseState {
                input,
                weight: w,
                output,
                rows,
                inputs,
                outputs,
            },
            out,
        ))
    }

    fn gns_layer_norm(x: Float, gamma: Float, beta: Float, eps: f32) -> Result<Float> {
        let shape = dims(&x);
        let k = shape.last().copied().unwrap_or(0);
        if shape.len() != 2 || dims(&gamma) != [k] || dims(&beta) != [k] || k == 0 {
            return super::composite_layer_norm::<Self>(x, gamma, beta, eps);
        }
        let (input, g) = (inner(&x), inner(&gamma));
        let (out, normalised, inverse) =
            host::layer_norm_forward(&values(&input)?, &values(&g)?, &values(&inner(&beta))?, eps);
        let rows = shape[0];
        Ok(finish(
            LayerNormBackward,
            [&x, &gamma, &beta],
            || LayerNormState {
                normalised: flex(normalised, &shape),
                inverse: flex(inverse, &[rows]),
                gamma: g,
                shape: shape.clone(),
            },
            flex(out, &shape),
        ))
    }

    fn gns_edge_input_layer(
        edges: Float,
        edge_weight: Float,
        bias: Float,
        sender_projection: Float,
        receiver_projection: Float,
        senders: FlexTensor,
        receivers: FlexTensor,
        relu: bool,
    ) -> Result<Float> {
        const OP: &str = "gns_edge_input_layer";
        let (es, ws, bs) = (dims(&edges), dims(&edge_weight), dims(&bias));
        let (ps, rs) = (dims(&sender_projection), dims(&receiver_projection));
        let rows = es.first().copied().unwrap_or(0);
        let fits = es.len() == 2
            && ws.len() == 2
            && ws[1] == es[1]
            && bs == [ws[0]]
            && ps.len() == 2
            && ps[1] == ws[0]
            && rs == ps
            && Burn::<Flex>::int_shape(&senders) == [rows]
            && Burn::<Flex>::int_shape(&receivers) == [rows];
        if !fits {
            return super::composite_edge_input_layer::<Self>(
                edges,
                edge_weight,
                bias,
                sender_projection,
                receiver_projection,
                senders,
                receivers,
                relu,
            );
        }
        let (inputs, outputs, nodes) = (es[1], ws[0], ps[0]);
        let (s, r) = (indices(&senders)?, indices(&receivers)?);
        check_range(&s, nodes, OP)?;
        check_range(&r, nodes, OP)?;
        let (e, w) = (inner(&edges), inner(&edge_weight));
        let out = host::edge_input_forward(
            &values(&e)?,
            rows,
            &values(&w)?,
            &values(&inner(&bias))?,
            &values(&inner(&sender_projection))?,
            &values(&inner(&receiver_projection))?,
            &s,
            &r,
            relu,
        );
        drop((s, r));
        let out = flex(out, &[rows, outputs]);
        let output = relu.then(|| out.clone());
        Ok(finish(
            EdgeInputBackward,
            [
                &edges,
                &edge_weight,
                &bias,
                &sender_projection,
                &receiver_projection,
            ],
            || EdgeInputState {
                edges: e,
                edge_weight: w,
                output,
                senders,
                receivers,
                rows,
                inputs,
                outputs,
                nodes,
            },
            out,
        ))
    }

    fn gns_sum_by_receiver(edges: Float, receivers: FlexTensor, nodes: usize) -> Result<Float> {
        const OP: &str = "gns_sum_by_receiver";
        let shape = dims(&edges);
        if shape.len() != 2 || Burn::<Flex>::int_shape(&receivers) != [shape[0]] {
            return super::composite_sum_by_receiver::<Self>(edges, receivers, nodes);
        }
        let width = shape[1];
        let r = indices(&receivers)?;
        check_range(&r, nodes, OP)?;
        let out = host::sum_rows_by_index(&values(&inner(&edges))?, width, &r, nodes);
        drop(r);
        Ok(finish(
            SumByReceiverBackward,
            [&edges],
            || SumByReceiverState { receivers, width },
            flex(out, &[nodes, width]),
        ))
    }
}
