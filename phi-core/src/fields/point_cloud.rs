//! [`PointCloud`]: values carried by particles, like Φ_Flow's `PointCloud`.

use crate::backend::Backend;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

/// `N` particles at `positions [N, d]` (physical units) carrying `values [N, c]` (velocities,
/// densities, ...). Immutable; methods return new clouds.
#[derive(Debug, Clone)]
pub struct PointCloud<B: Backend> {
    positions: Tensor<B>,
    values: Tensor<B>,
}

impl<B: Backend> PointCloud<B> {
    /// A cloud of `positions [N, d]` (`d` in 1..=3) carrying `values [N, c]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when `positions` is not `[N, d]` with `1 ≤ d ≤ 3`;
    /// [`TensorError::ShapeMismatch`] naming both shapes when `values` is not `[N, c]`.
    pub fn new(positions: Tensor<B>, values: Tensor<B>) -> Result<Self> {
        let p = positions.shape();
        if p.len() != 2 || !(1..=3).contains(&p[1]) {
            return Err(TensorError::InvalidArgument {
                op: "PointCloud::new",
                shape: p,
                reason: "positions must be [N, d] with d in 1..=3".into(),
            });
        }
        let v = values.shape();
        if v.len() != 2 || v[0] != p[0] {
            return Err(TensorError::ShapeMismatch {
                op: "PointCloud::new",
                lhs: p.clone(),
                rhs: v,
                reason: format!("values must be [{}, channels] for {} points", p[0], p[0]),
            });
        }
        Ok(Self { positions, values })
    }

    /// A cloud carrying no values (zero channels), for occupancy and counting.
    ///
    /// # Errors
    /// As [`PointCloud::new`].
    pub fn from_positions(positions: Tensor<B>) -> Result<Self> {
        let n = positions.shape().first().copied().unwrap_or(0);
        let values = Tensor::zeros(&[n, 0], &positions.device());
        Self::new(positions, values)
    }

    /// Positions, `[N, d]`.
    pub fn positions(&self) -> &Tensor<B> {
        &self.positions
    }

    /// Values, `[N, c]`.
    pub fn values(&self) -> &Tensor<B> {
        &self.values
    }

    /// Number of particles `N`.
    pub fn len(&self) -> usize {
        self.positions.shape()[0]
    }

    /// Whether there are no particles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Spatial dimension `d`.
    pub fn dim(&self) -> usize {
        self.positions.shape()[1]
    }

    /// Channels `c` of the values.
    pub fn channels(&self) -> usize {
        self.values.shape()[1]
    }

    /// The same particles carrying other values.
    ///
    /// # Errors
    /// As [`PointCloud::new`].
    pub fn with_values(&self, values: Tensor<B>) -> Result<Self> {
        Self::new(self.positions.clone(), values)
    }

    /// The same values at other positions.
    ///
    /// # Errors
    /// As [`PointCloud::new`].
    pub fn with_positions(&self, positions: Tensor<B>) -> Result<Self> {
        Self::new(positions, self.values.clone())
    }

    /// Both clouds' particles, `self`'s first (adding particles, as an inflow does).
    ///
    /// # Errors
    /// [`TensorError::ShapeMismatch`] when the dimensions or channel counts differ.
    pub fn concat(&self, other: &Self) -> Result<Self> {
        Self::new(
            Tensor::concat(&[self.positions.clone(), other.positions.clone()], 0)?,
            Tensor::concat(&[self.values.clone(), other.values.clone()], 0)?,
        )
    }
}
