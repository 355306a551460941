//! Encode-process-decode (Battaglia et al. 2018; DeepMind's `graph_network.py`): an MLP encoder
//! per nodes and edges, `M` unshared interaction networks with residual connections, an MLP
//! decoder on the nodes.

use phi_core::tensor::{IntTensor, Tensor};

use super::{GnsKernels, ModelError, Parameters};

/// Layer norm's `eps`, PyTorch's and Sonnet's default.
pub const LAYER_NORM_EPS: f32 = 1e-5;

/// An MLP of `hidden_layers + 1` dense layers with ReLU between them, the dense layers named
/// `{prefix}.{i}`, and a LayerNorm `{prefix}.ln` on the output when `layer_norm`.
pub(crate) fn mlp<B: GnsKernels>(
    params: &Parameters<B>,
    prefix: &str,
    hidden_layers: usize,
    layer_norm: bool,
    input: &Tensor<B>,
) -> Result<Tensor<B>, ModelError> {
    mlp_from(params, prefix, hidden_layers, layer_norm, input.clone(), 0)
}

/// The dense layers `first..=hidden_layers` of an MLP applied to `x` (the output of layer
/// `first − 1`, already through its ReLU), then the LayerNorm.
fn mlp_from<B: GnsKernels>(
    params: &Parameters<B>,
    prefix: &str,
    hidden_layers: usize,
    layer_norm: bool,
    mut x: Tensor<B>,
    first: usize,
) -> Result<Tensor<B>, ModelError> {
    for i in first..=hidden_layers {
        x = Tensor::from_primitive(B::gns_linear(
            x.into_primitive(),
            params
                .get(&format!("{prefix}.{i}.weight"))
                .primitive()
                .clone(),
            params
                .get(&format!("{prefix}.{i}.bias"))
                .primitive()
                .clone(),
            i < hidden_layers,
        )?);
    }
    if layer_norm {
        x = Tensor::from_primitive(B::gns_layer_norm(
            x.into_primitive(),
            params
                .get(&format!("{prefix}.ln.weight"))
                .primitive()
                .clone(),
            params.get(&format!("{prefix}.ln.bias")).primitive().clone(),
            LAYER_NORM_EPS,
        )?);
    }
    Ok(x)
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
    let sender_projection = nodes.matmul(&sender_weight.transpose()?)?;
    let receiver_projection = nodes.matmul(&receiver_weight.transpose()?)?;
    let first = Tensor::from_primitive(B::gns_edge_input_layer(
        edges.primitive().clone(),
        edge_weight.into_primitive(),
        params.get(&format!("{edge}.0.bias")).primitive().clone(),
        sender_projection.into_primitive(),
        receiver_projection.into_primitive(),
        senders.primitive().clone(),
        receivers.primitive().clone(),
        hidden_layers > 0,
    )?);
    let messages = mlp_from(params, &edge, hidden_layers, true, first, 1)?;
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
    Ok((nodes + node_update, edges + messages))
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
