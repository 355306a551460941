//! Encode-process-decode (Battaglia et al. 2018; DeepMind's `graph_network.py`): an MLP encoder
//! per nodes and edges, `M` unshared interaction networks with residual connections, an MLP
//! decoder on the nodes.

use phi_core::tensor::{IntTensor, Tensor};

use super::kernels::{Dense, EdgeInput, Norm};
use super::{GnsKernels, ModelError, Parameters};

/// The dense layers `{prefix}.{i}` for `i` in `layers`.
fn dense_layers<B: GnsKernels>(
    params: &Parameters<B>,
    prefix: &str,
    layers: std::ops::RangeInclusive<usize>,
) -> Vec<Dense<B::Float>> {
    layers
        .map(|i| Dense {
            weight: params
                .get(&format!("{prefix}.{i}.weight"))
                .primitive()
                .clone(),
            bias: params
                .get(&format!("{prefix}.{i}.bias"))
                .primitive()
                .clone(),
        })
        .collect()
}

/// The LayerNorm `{prefix}.ln`.
fn layer_norm<B: GnsKernels>(params: &Parameters<B>, prefix: &str) -> Norm<B::Float> {
    Norm {
        gamma: params
            .get(&format!("{prefix}.ln.weight"))
            .primitive()
            .clone(),
        beta: params.get(&format!("{prefix}.ln.bias")).primitive().clone(),
    }
}

/// An MLP of `hidden_layers + 1` dense layers with ReLU between them, the dense layers named
/// `{prefix}.{i}`, and a LayerNorm `{prefix}.ln` on the output when `with_norm`.
pub(crate) fn mlp<B: GnsKernels>(
    params: &Parameters<B>,
    prefix: &str,
    hidden_layers: usize,
    with_norm: bool,
    input: &Tensor<B>,
) -> Result<Tensor<B>, ModelError> {
    let layers = dense_layers(params, prefix, 0..=hidden_layers);
    let norm = with_norm.then(|| layer_norm(params, prefix));
    Ok(Tensor::from_primitive(B::gns_mlp(
        input.primitive().clone(),
        &layers,
        norm.as_ref(),
    )?))
}

/// One interaction network `processor.{step}` (DeepMind's `InteractionNetwork` with residuals):
/// `e′ = φ_e([e, v_s, v_r])`, `v′ = φ_v([v, Σ_{edges into v} e′])`, returning `(v + v′, e + e′)`.
///
/// The first layer of `φ_e` is applied split (see [`GnsKernels::gns_edge_input_layer`]): the node
/// latents are projected once per node and gathered, instead of concatenated per edge.
pub(crate) fn interaction_network<B: GnsKernels>(
    params: &Parameters<B>,
    step: usize,
    hidden_layers: usize,
    nodes: &Tensor<B>,
    edges: &Tensor<B>,
    senders: &IntTensor<B>,
    receivers: &IntTensor<B>,
) -> Result<(Tensor<B>, Tensor<B>), ModelError> {
    let edge = format!("processor.{step}.edge");
    let latent = nodes.shape()[1];
    let weight = params.get(&format!("{edge}.0.weight"));
    let out = weight.shape()[0];
    let block = |k: usize| weight.slice(&[0..out, k * latent..(k + 1) * latent]);
    let (edge_weight, sender_weight, receiver_weight) = (block(0)?, block(1)?, block(2)?);
    let input = EdgeInput {
        edge_weight: edge_weight.into_primitive(),
        bias: params.get(&format!("{edge}.0.bias")).primitive().clone(),
        sender_projection: nodes.matmul(&sender_weight.transpose()?)?.into_primitive(),
        receiver_projection: nodes
            .matmul(&receiver_weight.transpose()?)?
            .into_primitive(),
        senders: senders.primitive().clone(),
        receivers: receivers.primitive().clone(),
    };
    let rest = dense_layers(params, &edge, 1..=hidden_layers);
    let (messages, updated_edges) = B::gns_edge_update(
        edges.primitive().clone(),
        &input,
        &rest,
        Some(&layer_norm(params, &edge)),
    )?;
    let (messages, updated_edges) = (
        Tensor::<B>::from_primitive(messages),
        Tensor::<B>::from_primitive(updated_edges),
    );
    let aggregated = Tensor::from_primitive(B::gns_sum_by_receiver(
        messages.primitive().clone(),
        receivers.primitive().clone(),
        nodes.shape()[0],
    )?);
    let node_input = Tensor::concat(&[nodes.clone(), aggregated], 1)?;
    let node_update = mlp(
        params,
        &format!("processor.{step}.node"),
        hidden_layers,
        true,
        &node_input,
    )?;
    Ok((nodes + node_update, updated_edges))
}

/// The whole network: node features `[N, F]` and edge features `[E, dim + 1]` to the normalised
/// acceleration `[N, dim]`.
pub(crate) fn encode_process_decode<B: GnsKernels>(
    params: &Parameters<B>,
    hidden_layers: usize,
    message_passing_steps: usize,
    node_features: &Tensor<B>,
    edge_features: &Tensor<B>,
    senders: &IntTensor<B>,
    receivers: &IntTensor<B>,
) -> Result<Tensor<B>, ModelError> {
    let mut nodes = mlp(params, "encoder.node", hidden_layers, true, node_features)?;
    let mut edges = mlp(params, "encoder.edge", hidden_layers, true, edge_features)?;
    for step in 0..message_passing_steps {
        (nodes, edges) = interaction_network(
            params,
            step,
            hidden_layers,
            &nodes,
            &edges,
            senders,
            receivers,
        )?;
    }
    mlp(params, "decoder", hidden_layers, false, &nodes)
}
