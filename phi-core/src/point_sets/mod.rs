//! Distances between point sets: losses for optimisation and metrics for evaluation.
//!
//! A point set is `[N, d]` in domain units; two sets may differ in size except where a function
//! pairs point `i` with point `i`. The losses ([`l2_loss`], [`sinkhorn_divergence`]) are built from
//! tensor operations and return a one-element tensor `[1]`, so they are differentiable on the
//! autodiff backends; the metrics ([`chamfer_distance`], [`set_distances`], the exact
//! [`earth_movers_distance`]) run on host data and report how far a simulated liquid is from a
//! target or a rollout from its ground truth.
//!
//! ```
//! use phi_core::Backend;
//! use phi_core::backend::ndarray::NdArray;
//! use phi_core::point_sets::{chamfer_distance, l2_loss};
//! use phi_core::Tensor;
//!
//! let device = NdArray::default_device();
//! let a = Tensor::<NdArray>::from_vec(vec![0.0, 0.0, 1.0, 0.0], &[2, 2], &device)?;
//! let b = Tensor::<NdArray>::from_vec(vec![0.0, 1.0, 1.0, 1.0], &[2, 2], &device)?;
//! // Each point is 1 away from its partner: ½ (1 + 1).
//! assert_eq!(l2_loss(&a, &b)?.to_scalar()?, 1.0);
//! assert_eq!(chamfer_distance(&a.to_vec(), &b.to_vec(), 2), 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod chamfer;
mod emd;
mod l2;
mod sinkhorn;

pub use chamfer::chamfer_distance;
pub use emd::{EmdSolver, GroundCost, SolveStats, earth_movers_distance};
pub use l2::l2_loss;
pub use sinkhorn::{SinkhornOptions, sinkhorn_divergence, sinkhorn_divergence_host};

use thiserror::Error;

use crate::backend::Backend;
use crate::error::TensorError;
use crate::tensor::Tensor;

/// What can go wrong when comparing point sets: sets that cannot be compared (empty, of
/// different dimensions, of different counts where points are paired) or an option out of range,
/// and errors of the tensor operations underneath.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PointSetError {
    /// Inputs the distance `what` cannot take, and why.
    #[error("{what}: {reason}")]
    Invalid {
        /// The distance (`"l2 loss"`, `"sinkhorn divergence"`, ...).
        what: &'static str,
        /// What is wrong with the inputs.
        reason: String,
    },
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] TensorError),
}

/// The result type of this module.
pub type Result<T, E = PointSetError> = std::result::Result<T, E>;

/// Checks that `a` and `b` are non-empty `[·, d]` point sets of the same `d`, for the distance
/// `what` (named in the error); returns `(N, M, d)`.
///
/// # Errors
/// [`PointSetError::Invalid`] for a tensor that is not of rank 2, different dimensions or an empty
/// set.
pub fn check_point_sets<B: Backend>(
    what: &'static str,
    a: &Tensor<B>,
    b: &Tensor<B>,
) -> Result<(usize, usize, usize)> {
    let (sa, sb) = (a.shape(), b.shape());
    let invalid = |reason: String| Err(PointSetError::Invalid { what, reason });
    if sa.len() != 2 || sb.len() != 2 {
        return invalid(format!(
            "point sets are [N, d] tensors, got shapes {sa:?} and {sb:?}"
        ));
    }
    if sa[1] != sb[1] {
        return invalid(format!(
            "the particles are {}-dimensional but the target points are {}-dimensional",
            sa[1], sb[1]
        ));
    }
    if sa[0] == 0 || sb[0] == 0 {
        return invalid(format!(
            "empty point set ({} particles, {} target points)",
            sa[0], sb[0]
        ));
    }
    Ok((sa[0], sb[0], sa[1]))
}

/// Distances between point sets on the host, for reporting (not differentiable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetDistances {
    /// Symmetric Chamfer distance: the mean over both sets of the distance to the nearest point
    /// of the other set (domain units).
    pub chamfer: f32,
    /// An earth mover's estimate: `√(2 S_ε)` with a small `ε` (`0.01` domain units²), close to
    /// the 2-Wasserstein distance between the uniform measures (domain units).
    pub wasserstein: f32,
}

/// [`SetDistances`] between `a` and `b` (host data `[N·d]`, `[M·d]`).
///
/// # Errors
/// [`PointSetError::Invalid`] for empty sets or lengths that are not multiples of `d`.
pub fn set_distances(a: &[f32], b: &[f32], d: usize) -> Result<SetDistances> {
    if d == 0
        || a.is_empty()
        || b.is_empty()
        || !a.len().is_multiple_of(d)
        || !b.len().is_multiple_of(d)
    {
        return Err(PointSetError::Invalid {
            what: "set distances",
            reason: format!(
                "need non-empty sets of {d}-dimensional points, got {} and {} values",
                a.len(),
                b.len()
            ),
        });
    }
    let chamfer = chamfer_distance(a, b, d);
    let options = SinkhornOptions {
        max_iterations: 300,
        ..SinkhornOptions::new(0.01)
    };
    let s = sinkhorn::host_sinkhorn_divergence(a, b, d, &options);
    Ok(SetDistances {
        chamfer,
        wasserstein: (2.0 * s.max(0.0)).sqrt() as f32,
    })
}

#[cfg(test)]
mod tests;
