//! Where the samples of a grid lie ([`SampleLattice`]), how particles reach them ([`Transfer`]),
//! and the multilinear stencil that both directions of a particle ↔ grid transfer share.
//!
//! For `N` points and a regular set of sample points of shape `[s₀, ..., s_{d−1}]` (cell centres
//! or the faces of one staggered component), the stencil holds the flat indices of the `2^d`
//! surrounding samples of each point and their multilinear (tent) weights. Points are first
//! turned into continuous sample indices `(x − origin) / Δx` and **clamped to `[0, sᵢ − 1]`**: a
//! point beyond the outermost sample takes that sample's value (constant extrapolation), and its
//! gradient with respect to the position is zero along the clamped axis. The weights are
//! differentiable in the positions; the indices are not (they are piecewise constant).

use crate::backend::{Backend, IntBinaryOp, ReduceOp};
use crate::error::Result;
use crate::tensor::{IntTensor, Tensor};

use super::domain::Domain;

/// How particle values are transferred to a grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Transfer {
    /// Each particle adds its value with multilinear (tent) weights to the `2^d` nearest samples;
    /// each sample is the weighted mean `Σ w v / Σ w`, 0 where no particle reaches. Exact for
    /// linear fields where the particles surround the sample.
    Linear,
    /// Each particle adds its value to the single nearest sample (Φ_Flow 2.1.4's scatter);
    /// each sample is the mean of its particles, 0 where there are none. Not differentiable in
    /// the positions.
    NearestFace,
}

/// Where the samples of a grid lie: `origin + k Δx` for `k` in `0..shape` along each axis (the
/// cell centres of a domain, or the faces of one staggered component). What
/// [`LatticeKernels::float_lattice_sample`] and [`LatticeKernels::float_lattice_splat`] work on.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleLattice {
    /// The position of sample `0`.
    pub origin: Vec<f32>,
    /// The distance between neighbouring samples per axis.
    pub spacing: Vec<f32>,
    /// Samples per axis.
    pub shape: Vec<usize>,
}

impl SampleLattice {
    /// The cell centres (`face_axis = None`) or the faces of staggered component `axis`.
    pub(super) fn of(domain: &Domain, face_axis: Option<usize>) -> Self {
        let dx = domain.cell_size();
        let origin = (0..domain.dim())
            .map(|i| {
                let offset = if face_axis == Some(i) { 0.0 } else { 0.5 };
                domain.lower()[i] + offset * dx[i]
            })
            .collect();
        let shape = match face_axis {
            None => domain.resolution().to_vec(),
            Some(axis) => domain.staggered_shape(axis),
        };
        Self {
            origin,
            spacing: dx,
            shape,
        }
    }

    pub(super) fn dim(&self) -> usize {
        self.shape.len()
    }

    /// Row-major strides of the flattened samples.
    pub(super) fn strides(&self) -> Vec<i64> {
        let mut strides = vec![1i64; self.dim()];
        for axis in (0..self.dim().saturating_sub(1)).rev() {
            strides[axis] = strides[axis + 1] * self.shape[axis + 1] as i64;
        }
        strides
    }

    /// Continuous sample indices `(x − origin) / Δx` of `points [N, d]`, clamped to
    /// `[0, s − 1]` per axis: `[N, d]`.
    pub(super) fn continuous_indices<B: Backend>(&self, points: &Tensor<B>) -> Result<Tensor<B>> {
        let device = points.device();
        let d = self.dim();
        let origin = Tensor::from_slice(&self.origin, &[1, d], &device)?;
        let inv: Vec<f32> = self.spacing.iter().map(|s| 1.0 / s).collect();
        let inv = Tensor::from_vec(inv, &[1, d], &device)?;
        let upper: Vec<f32> = self.shape.iter().map(|&s| (s - 1) as f32).collect();
        let upper = Tensor::from_vec(upper, &[1, d], &device)?;
        let index = (points - &origin) * &inv;
        index.relu().minimum(&upper)
    }

    /// Flat indices `[N]` of integer sample indices `[N, d]`.
    pub(super) fn flatten<B: Backend>(&self, index: &IntTensor<B>) -> Result<IntTensor<B>> {
        let d = self.dim();
        let n = index.shape()[0];
        let strides = IntTensor::from_vec(self.strides(), &[1, d], &index.device())?;
        let weighted = index.binary(IntBinaryOp::Mul, &strides)?;
        weighted.reduce_axis(ReduceOp::Sum, 1)?.reshape(&[n])
    }

    /// The multilinear stencil of `points [N, d]`.
    pub(super) fn linear_stencil<B: Backend>(&self, points: &Tensor<B>) -> Result<Stencil<B>> {
        let d = self.dim();
        let n = points.shape()[0];
        let device = points.device();
        let index = self.continuous_indices(points)?;
        // The lower corner, at most s − 2 so that the upper corner exists (0 for a single sample).
        let highest_base: Vec<f32> = self
            .shape
            .iter()
            .map(|&s| s.saturating_sub(2) as f32)
            .collect();
        let highest_base = Tensor::from_vec(highest_base, &[1, d], &device)?;
        let base = index.detach().floor().minimum(&highest_base)?;
        let fraction = &index - &base;
        let base_flat = self.flatten(&base.to_int())?;
        let strides = self.strides();
        let columns = (0..d)
            .map(|axis| fraction.narrow(1, axis..axis + 1)?.reshape(&[n]))
            .collect::<Result<Vec<_>>>()?;
        let corners = 1usize << d;
        let mut indices = Vec::with_capacity(corners);
        let mut weights = Vec::with_capacity(corners);
        for corner in 0..corners {
            let mut offset = 0i64;
            let mut weight: Option<Tensor<B>> = None;
            for axis in 0..d {
                let upper = (corner >> (d - 1 - axis)) & 1 == 1;
                if upper && self.shape[axis] > 1 {
                    offset += strides[axis];
                }
                let factor = if upper {
                    columns[axis].clone()
                } else {
                    1.0 - &columns[axis]
                };
                weight = Some(match weight {
                    None => factor,
                    Some(w) => w * factor,
                });
            }
            indices.push(&base_flat + offset);
            weights.push(weight.expect("at least one axis"));
        }
        Ok(Stencil {
            indices: IntTensor::concat(&indices, 0)?,
            weights: Tensor::stack(&weights, 0)?,
            corners,
            points: n,
        })
    }

    /// The nearest-sample stencil of `points [N, d]` (weight 1).
    pub(super) fn nearest_stencil<B: Backend>(&self, points: &Tensor<B>) -> Result<Stencil<B>> {
        let n = points.shape()[0];
        let index = self.continuous_indices(&points.detach())?;
        let nearest = (index + 0.5).floor();
        let upper: Vec<f32> = self.shape.iter().map(|&s| (s - 1) as f32).collect();
        let upper = Tensor::from_vec(upper, &[1, self.dim()], &points.device())?;
        let nearest = nearest.minimum(&upper)?;
        Ok(Stencil {
            indices: self.flatten(&nearest.to_int())?,
            weights: Tensor::ones(&[1, n], &points.device()),
            corners: 1,
            points: n,
        })
    }

    pub(super) fn stencil<B: Backend>(
        &self,
        points: &Tensor<B>,
        transfer: Transfer,
    ) -> Result<Stencil<B>> {
        match transfer {
            Transfer::Linear => self.linear_stencil(points),
            Transfer::NearestFace => self.nearest_stencil(points),
        }
    }
}

/// For each of `points` points, `corners` samples: flat indices `[corners · points]`
/// (corner-major) and weights `[corners, points]`.
pub(super) struct Stencil<B: Backend> {
    pub(super) indices: IntTensor<B>,
    weights: Tensor<B>,
    corners: usize,
    points: usize,
}

impl<B: Backend> Stencil<B> {
    /// `Σ_corners w · grid[index]` for a flattened grid `[samples, c]`: `[points, c]`.
    pub(super) fn gather(&self, flat: &Tensor<B>) -> Result<Tensor<B>> {
        let c = flat.shape()[1];
        let picked = flat
            .gather_rows(&self.indices)?
            .reshape(&[self.corners, self.points, c])?;
        let weights = self.weights.reshape(&[self.corners, self.points, 1])?;
        (picked * weights).sum_axis(0)
    }

    /// `(Σ w v, Σ w)` scattered onto `samples` flat samples, for values `[points, c]`:
    /// `([samples, c], [samples, 1])`.
    pub(super) fn scatter(
        &self,
        values: &Tensor<B>,
        samples: usize,
    ) -> Result<(Tensor<B>, Tensor<B>)> {
        let c = values.shape()[1];
        let device = values.device();
        let weights = self.weights.reshape(&[self.corners, self.points, 1])?;
        let weighted =
            (values.unsqueeze(0)? * &weights).reshape(&[self.corners * self.points, c])?;
        let sums =
            Tensor::zeros(&[samples, c], &device).scatter_add_rows(&self.indices, &weighted)?;
        let weights = if self.corners == 1 {
            Tensor::ones(&[self.points, 1], &device)
        } else {
            weights.reshape(&[self.corners * self.points, 1])?
        };
        let weight_sums =
            Tensor::zeros(&[samples, 1], &device).scatter_add_rows(&self.indices, &weights)?;
        Ok((sums, weight_sums))
    }
}

/// [`LatticeKernels::float_lattice_sample`] from tensor operations (the default of every backend;
/// differentiable in the values and the points).
pub(super) fn composite_lattice_sample<B: Backend>(
    lattice: &SampleLattice,
    values: B::Float,
    points: B::Float,
) -> Result<B::Float> {
    let points = Tensor::<B>::from_primitive(points);
    let values = Tensor::<B>::from_primitive(values);
    Ok(lattice
        .linear_stencil(&points)?
        .gather(&values)?
        .into_primitive())
}

/// [`LatticeKernels::float_lattice_splat`] from tensor operations (the default of every backend).
pub(super) fn composite_lattice_splat<B: Backend>(
    lattice: &SampleLattice,
    points: B::Float,
    values: B::Float,
    transfer: Transfer,
) -> Result<(B::Float, B::Float)> {
    let points = Tensor::<B>::from_primitive(points);
    let values = Tensor::<B>::from_primitive(values);
    let samples = lattice.shape.iter().product();
    let (sums, weights) = lattice
        .stencil(&points, transfer)?
        .scatter(&values, samples)?;
    Ok((sums.into_primitive(), weights.into_primitive()))
}

/// The lattices of the components of a staggered grid on `domain`.
pub(crate) fn staggered_lattices(domain: &Domain) -> Vec<SampleLattice> {
    (0..domain.dim())
        .map(|axis| SampleLattice::of(domain, Some(axis)))
        .collect()
}
