//! The GNS kernels of [`Tch`]: libtorch's own fused operations, each with libtorch's backward.
//!
//! The composites build a dense layer from a product and a broadcast add, and LayerNorm from
//! nine elementwise operations, each a pass over `[E, 128]` that autograd keeps for the backward
//! pass. libtorch has them as single operations with hand-written backward passes: `linear`
//! (one `addmm`), `layer_norm` (which keeps only the row means and inverse deviations) and an
//! in-place ReLU on the product (which `addmm`'s backward does not read).

use phi_core::backend::tch::{Tch, TchIntTensor, TchTensor};
use phi_core::error::{Result, TensorError};
use tch::TchError;

use super::GnsKernels;

fn backend_error(err: TchError) -> TensorError {
    TensorError::Backend {
        backend: "tch",
        message: err.to_string(),
    }
}

/// `x Wᵀ + b` as one `addmm`, with the ReLU in place when `relu`.
fn linear(
    x: &tch::Tensor,
    weight: &tch::Tensor,
    bias: &tch::Tensor,
    relu: bool,
) -> Result<tch::Tensor> {
    let mut y = x.f_linear(weight, Some(bias)).map_err(backend_error)?;
    if relu {
        y = y.f_relu_().map_err(backend_error)?;
    }
    Ok(y)
}

impl GnsKernels for Tch {
    fn gns_linear(
        x: TchTensor,
        weight: TchTensor,
        bias: TchTensor,
        relu: bool,
    ) -> Result<TchTensor> {
        Ok(TchTensor(linear(&x.0, &weight.0, &bias.0, relu)?))
    }

    fn gns_layer_norm(
        x: TchTensor,
        gamma: TchTensor,
        beta: TchTensor,
        eps: f32,
    ) -> Result<TchTensor> {
        let width = x.0.size().last().copied().unwrap_or(0);
        x.0.f_layer_norm(
            [width],
            Some(&gamma.0),
            Some(&beta.0),
            f64::from(eps),
            false,
        )
        .map(TchTensor)
        .map_err(backend_error)
    }

    fn gns_edge_input_layer(
        edges: TchTensor,
        edge_weight: TchTensor,
        bias: TchTensor,
        sender_projection: TchTensor,
        receiver_projection: TchTensor,
        senders: TchIntTensor,
        receivers: TchIntTensor,
        relu: bool,
    ) -> Result<TchTensor> {
        use phi_core::tensor::{IntTensor, Tensor};
        // The gathers of the front end check the indices; libtorch's `index_select` is the same
        // operation.
        let from_senders = Tensor::<Self>::from_primitive(sender_projection)
            .gather_rows(&IntTensor::from_primitive(senders))?;
        let from_receivers = Tensor::<Self>::from_primitive(receiver_projection)
            .gather_rows(&IntTensor::from_primitive(receivers))?;
        let mut y = linear(&edges.0, &edge_weight.0, &bias.0, false)?;
        y = y
            .f_add_(&from_senders.primitive().0)
            .map_err(backend_error)?;
        y = y
            .f_add_(&from_receivers.primitive().0)
            .map_err(backend_error)?;
        if relu {
            y = y.f_relu_().map_err(backend_error)?;
        }
        Ok(TchTensor(y))
    }
}
