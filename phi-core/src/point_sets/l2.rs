//! The L2 loss between paired point sets.

use super::{PointSetError, Result, check_point_sets};
use crate::backend::Backend;
use crate::tensor::Tensor;

/// `½ Σᵢ |xᵢ − tᵢ|²` over the points `i` of `positions` `[N, d]` and `target` `[N, d]` (Φ_Flow's
/// `l2_loss`, as in the thesis: with learning rate 1, a gradient step moves a particle by its
/// whole residual when the map is the identity). Returns `[1]`, in domain units².
///
/// # Errors
/// [`PointSetError::Invalid`] for empty sets, different dimensions or counts.
pub fn l2_loss<B: Backend>(positions: &Tensor<B>, target: &Tensor<B>) -> Result<Tensor<B>> {
    let (n, m, _) = check_point_sets("l2 loss", positions, target)?;
    if n != m {
        return Err(PointSetError::Invalid {
            what: "l2 loss",
            reason: format!(
                "compares particle i with target point i, but there are {n} particles and {m} \
                 target points (use loss = \"sinkhorn\" or \"density\" for sets of different size)"
            ),
        });
    }
    Ok((positions - target).square().sum() * 0.5)
}
