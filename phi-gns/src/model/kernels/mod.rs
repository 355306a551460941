//! [`GnsKernels`]: the fused kernels of the GNS, an extension of [`Backend`].
//!
//! A message-passing step spends its time in three places: the dense layers of the edge MLP
//! (`[E, 128] × [128, 128]` with ~30k edges), the LayerNorm after it, and the gather of node
//! latents onto edges and the sum of messages back onto receivers. Each is written once from the
//! primitives of [`Backend`] (the composite defaults below, differentiable on the autodiff
//! backends). [`NdArray`](phi_core::backend::ndarray::NdArray) fuses whole MLPs
//! (`kernels/ndarray.rs`); Burn on Flex runs each layer as one parallel host kernel with a
//! hand-written backward pass (`kernels/burn.rs`, on the row kernels of `kernels/host.rs`); tch
//! calls libtorch's own `linear` and `layer_norm` (`kernels/tch.rs`); Burn on wgpu keeps the
//! defaults.

use phi_core::backend::{Backend, BinaryOp, ReduceOp};
use phi_core::error::Result;
use phi_core::tensor::{IntTensor, Tensor};

#[cfg(feature = "burn")]
mod burn;
// The backward kernels serve Burn alone.
#[cfg_attr(not(feature = "burn"), allow(dead_code))]
mod host;
mod ndarray;
#[cfg(feature = "tch")]
mod tch;

/// LayerNorm's `eps`, PyTorch's and Sonnet's default.
pub const LAYER_NORM_EPS: f32 = 1e-5;

/// A dense layer's parameters in PyTorch's convention: `weight [out, in]`, `bias [out]`.
#[derive(Debug, Clone)]
pub struct Dense<F> {
    /// `W [out, in]`.
    pub weight: F,
    /// `b [out]`.
    pub bias: F,
}

/// A LayerNorm's scale and shift, each `[k]`.
#[derive(Debug, Clone)]
pub struct Norm<F> {
    /// The scale `γ`.
    pub gamma: F,
    /// The shift `β`.
    pub beta: F,
}

/// The split first layer of an edge MLP on `[e, v_s, v_r]` (see
/// [`GnsKernels::gns_edge_input_layer`]).
#[derive(Debug, Clone)]
pub struct EdgeInput<F, I> {
    /// `W_e [out, k]`, the columns of the layer's weight that multiply `e`.
    pub edge_weight: F,
    /// `b [out]`.
    pub bias: F,
    /// `v W_sᵀ [N, out]`.
    pub sender_projection: F,
    /// `v W_rᵀ [N, out]`.
    pub receiver_projection: F,
    /// `[E]`.
    pub senders: I,
    /// `[E]`, ascending.
    pub receivers: I,
}

/// The fused kernels of the GNS network (see the [module docs](self)). Every method has a
/// composite default built from the [`Backend`] primitives; a backend overrides a method only with
/// a kernel that gives the same values to float tolerance.
pub trait GnsKernels: Backend {
    /// A dense layer in PyTorch's convention, `y = x Wᵀ + b`, with the ReLU applied when `relu`:
    /// `x [n, in]`, `weight [out, in]`, `bias [out]` → `[n, out]`.
    ///
    /// # Errors
    /// Shape errors when the operands do not fit.
    fn gns_linear(
        x: Self::Float,
        weight: Self::Float,
        bias: Self::Float,
        relu: bool,
    ) -> Result<Self::Float> {
        composite_linear::<Self>(x, weight, bias, relu)
    }

    /// LayerNorm over the last axis of `x [n, k]`: `(x − mean) / √(var + eps) · gamma + beta`,
    /// with the biased variance (PyTorch's `nn.LayerNorm`); `gamma`, `beta` are `[k]`.
    ///
    /// # Errors
    /// Shape errors when the operands do not fit.
    fn gns_layer_norm(
        x: Self::Float,
        gamma: Self::Float,
        beta: Self::Float,
        eps: f32,
    ) -> Result<Self::Float> {
        composite_layer_norm::<Self>(x, gamma, beta, eps)
    }

    /// The first layer of an edge MLP on `[e, v_s, v_r]`, split so that node latents are
    /// projected once per node: `relu(e W_eᵀ + (v W_sᵀ)[s] + (v W_rᵀ)[r] + b)`, where
    /// `edges [E, k]`, `edge_weight` is `W_e [out, k]`, `sender_projection` and
    /// `receiver_projection` are `v W_sᵀ` and `v W_rᵀ` (`[N, out]`), `senders` and `receivers`
    /// are `[E]`, `bias [out]` → `[E, out]`; without the ReLU unless `relu`. Equal to the dense
    /// layer on the concatenation.
    ///
    /// # Errors
    /// Shape errors, and an index outside `0..N`.
    #[allow(clippy::too_many_arguments)]
    fn gns_edge_input_layer(
        edges: Self::Float,
        edge_weight: Self::Float,
        bias: Self::Float,
        sender_projection: Self::Float,
        receiver_projection: Self::Float,
        senders: Self::Int,
        receivers: Self::Int,
        relu: bool,
    ) -> Result<Self::Float> {
        composite_edge_input_layer::<Self>(
            edges,
            edge_weight,
            bias,
            sender_projection,
            receiver_projection,
            senders,
            receivers,
            relu,
        )
    }

    /// An MLP: the dense `layers` with a ReLU between consecutive ones (none after the last),
    /// then the LayerNorm `norm` (with [`LAYER_NORM_EPS`])
    /// if given. `x [n, in]` → `[n, out]`.
    ///
    /// # Errors
    /// Shape errors when the operands do not fit.
    fn gns_mlp(
        x: Self::Float,
        layers: &[Dense<Self::Float>],
        norm: Option<&Norm<Self::Float>>,
    ) -> Result<Self::Float> {
        composite_mlp::<Self>(x, layers, norm)
    }

    /// An edge MLP whose first layer is `input` (split, see
    /// [`GnsKernels::gns_edge_input_layer`]), followed by the dense `rest` (ReLU between layers,
    /// none after the last) and the LayerNorm `norm` if given. `edges [E, k]` → `[E, out]`.
    ///
    /// # Errors
    /// Shape errors, and an index outside `0..N`.
    fn gns_edge_mlp(
        edges: Self::Float,
        input: &EdgeInput<Self::Float, Self::Int>,
        rest: &[Dense<Self::Float>],
        norm: Option<&Norm<Self::Float>>,
    ) -> Result<Self::Float> {
        composite_edge_mlp::<Self>(edges, input, rest, norm)
    }

    /// The edge update of an interaction network: `e′ =` [`GnsKernels::gns_edge_mlp`] and the
    /// residual `e + e′`, returned as `(e′, e + e′)` (the messages are also summed onto the
    /// receivers). A kernel may form both while a block of edges is in cache.
    ///
    /// # Errors
    /// As [`GnsKernels::gns_edge_mlp`], and a shape error when `e′` is not of `e`'s shape.
    fn gns_edge_update(
        edges: Self::Float,
        input: &EdgeInput<Self::Float, Self::Int>,
        rest: &[Dense<Self::Float>],
        norm: Option<&Norm<Self::Float>>,
    ) -> Result<(Self::Float, Self::Float)> {
        let messages = Self::gns_edge_mlp(edges.clone(), input, rest, norm)?;
        let updated = Tensor::<Self>::from_primitive(edges).binary(
            BinaryOp::Add,
            &Tensor::<Self>::from_primitive(messages.clone()),
        )?;
        Ok((messages, updated.into_primitive()))
    }

    /// The sum of edge values `[E, k]` over the incoming edges of each of `nodes` receivers:
    /// `[nodes, k]`, zero for a node without incoming edges. `receivers [E]` is ascending (the
    /// order of [`crate::graph::RadiusGraph`]); a kernel may rely on that.
    ///
    /// # Errors
    /// Shape errors, and an index outside `0..nodes`.
    fn gns_sum_by_receiver(
        edges: Self::Float,
        receivers: Self::Int,
        nodes: usize,
    ) -> Result<Self::Float> {
        composite_sum_by_receiver::<Self>(edges, receivers, nodes)
    }
}

/// [`GnsKernels::gns_mlp`] from the per-layer kernels.
pub(crate) fn composite_mlp<B: GnsKernels>(
    mut x: B::Float,
    layers: &[Dense<B::Float>],
    norm: Option<&Norm<B::Float>>,
) -> Result<B::Float> {
    for (i, layer) in layers.iter().enumerate() {
        let relu = i + 1 < layers.len();
        x = B::gns_linear(x, layer.weight.clone(), layer.bias.clone(), relu)?;
    }
    match norm {
        Some(n) => B::gns_layer_norm(x, n.gamma.clone(), n.beta.clone(), LAYER_NORM_EPS),
        None => Ok(x),
    }
}

/// [`GnsKernels::gns_edge_mlp`] from the per-layer kernels.
pub(crate) fn composite_edge_mlp<B: GnsKernels>(
    edges: B::Float,
    input: &EdgeInput<B::Float, B::Int>,
    rest: &[Dense<B::Float>],
    norm: Option<&Norm<B::Float>>,
) -> Result<B::Float> {
    let first = B::gns_edge_input_layer(
        edges,
        input.edge_weight.clone(),
        input.bias.clone(),
        input.sender_projection.clone(),
        input.receiver_projection.clone(),
        input.senders.clone(),
        input.receivers.clone(),
        !rest.is_empty(),
    )?;
    composite_mlp::<B>(first, rest, norm)
}

/// [`GnsKernels::gns_linear`] from primitives.
pub fn composite_linear<B: Backend>(
    x: B::Float,
    weight: B::Float,
    bias: B::Float,
    relu: bool,
) -> Result<B::Float> {
    let x = Tensor::<B>::from_primitive(x);
    let weight = Tensor::<B>::from_primitive(weight);
    let bias = Tensor::<B>::from_primitive(bias);
    let y = x
        .matmul(&weight.transpose()?)?
        .binary(BinaryOp::Add, &bias)?;
    Ok(if relu { y.relu() } else { y }.into_primitive())
}

/// [`GnsKernels::gns_layer_norm`] from primitives.
pub fn composite_layer_norm<B: Backend>(
    x: B::Float,
    gamma: B::Float,
    beta: B::Float,
    eps: f32,
) -> Result<B::Float> {
    let x = Tensor::<B>::from_primitive(x);
    let last = x.rank().saturating_sub(1);
    let mean = x.reduce_axis(ReduceOp::Mean, last, true)?;
    let centred = x.binary(BinaryOp::Sub, &mean)?;
    let variance = centred.square().reduce_axis(ReduceOp::Mean, last, true)?;
    let inverse = (variance + eps).sqrt().recip();
    let normalised = centred.binary(BinaryOp::Mul, &inverse)?;
    let scaled = normalised.binary(BinaryOp::Mul, &Tensor::<B>::from_primitive(gamma))?;
    Ok(scaled
        .binary(BinaryOp::Add, &Tensor::<B>::from_primitive(beta))?
        .into_primitive())
}

/// [`GnsKernels::gns_edge_input_layer`] from primitives.
#[allow(clippy::too_many_arguments)]
pub fn composite_edge_input_layer<B: Backend>(
    edges: B::Float,
    edge_weight: B::Float,
    bias: B::Float,
    sender_projection: B::Float,
    receiver_projection: B::Float,
    senders: B::Int,
    receivers: B::Int,
    relu: bool,
) -> Result<B::Float> {
    let own = composite_linear::<B>(edges, edge_weight, bias, false)?;
    let own = Tensor::<B>::from_primitive(own);
    let from_senders = Tensor::<B>::from_primitive(sender_projection)
        .gather_rows(&IntTensor::from_primitive(senders))?;
    let from_receivers = Tensor::<B>::from_primitive(receiver_projection)
        .gather_rows(&IntTensor::from_primitive(receivers))?;
    let sum = own + from_senders + from_receivers;
    Ok(if relu { sum.relu() } else { sum }.into_primitive())
}

/// [`GnsKernels::gns_sum_by_receiver`] from primitives.
pub fn composite_sum_by_receiver<B: Backend>(
    edges: B::Float,
    receivers: B::Int,
    nodes: usize,
) -> Result<B::Float> {
    let edges = Tensor::<B>::from_primitive(edges);
    let mut shape = edges.shape();
    shape[0] = nodes;
    Ok(Tensor::<B>::zeros(&shape, &edges.device())
        .scatter_add_rows(&IntTensor::from_primitive(receivers), &edges)?
        .into_primitive())
}

#[cfg(feature = "wgpu")]
impl GnsKernels for phi_core::backend::burn::BurnWgpu {}
