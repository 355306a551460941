//! [`LatticeKernels`]: the fused kernels of the fields layer, an extension of [`Backend`].
//!
//! The particle ↔ grid transfers, the advection of points through a staggered velocity and the
//! growth of a valid region are the hot loops of a FLIP step. Each is written once from the
//! primitives of [`Backend`] (the composite defaults below, differentiable on the autodiff
//! backends) and may be replaced per backend by a fused kernel that gives the same values: here
//! [`NdArray`](crate::backend::ndarray::NdArray) fuses all six (`kernels/ndarray/`), Burn and tch
//! keep the defaults.
//!
//! The core [`Backend`] trait knows nothing of this layer, so a backend author implements
//! `Backend` without any fields type; using the fields layer with a new backend takes one line,
//! `impl LatticeKernels for MyBackend {}`, and a fused kernel is an override of that impl. Crates
//! above phi-core add their own kernels the same way: a trait `: Backend` beside the code that
//! calls it, with composite defaults, implemented for each backend type.

use crate::backend::{Backend, CompareOp};
use crate::error::Result;
use crate::tensor::Tensor;

use super::lattice::{SampleLattice, Transfer, composite_lattice_sample, composite_lattice_splat};
use super::ops::{Ghost, pad_ghosts};

#[cfg(feature = "ndarray")]
mod ndarray;

/// The fused kernels that the fields layer calls (see the [module docs](self)). Every method has
/// a composite default built from the [`Backend`] primitives; a backend overrides a method only
/// with a kernel that gives the same values.
pub trait LatticeKernels: Backend {
    /// Multilinear (tent) interpolation of `values [samples, c]`, the samples of `lattice` in
    /// row-major order, at `points [N, d]`: `[N, c]`. Points are first turned into continuous
    /// sample indices `(x − origin) / spacing` and clamped to `[0, shape − 1]` per axis (constant
    /// extrapolation beyond the outermost samples). The default is differentiable in `values` and
    /// `points`.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_lattice_sample(
        lattice: &SampleLattice,
        values: Self::Float,
        points: Self::Float,
    ) -> Result<Self::Float> {
        composite_lattice_sample::<Self>(lattice, values, points)
    }

    /// [`LatticeKernels::float_lattice_sample`] of several one-channel lattices at the same
    /// `points [N, d]`: column `j` of the result `[N, k]` interpolates `components[j]`
    /// (`[samples_j, 1]`) on `lattices[j]` (`k` lattices; the components of a staggered grid).
    /// The default samples the lattices one by one and joins the columns; a backend may
    /// interleave them, with the same values.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_lattice_sample_columns(
        lattices: &[SampleLattice],
        components: &[Self::Float],
        points: Self::Float,
    ) -> Result<Self::Float> {
        composite_lattice_sample_columns::<Self>(lattices, components, points)
    }

    /// Particle → grid transfer onto the samples of `lattice`: `(Σ w v, Σ w)` with shapes
    /// `([samples, c], [samples, 1])` for `values [N, c]` at `points [N, d]`, where `w` are the
    /// tent weights of the `2^d` surrounding samples ([`Transfer::Linear`], indices clamped as in
    /// [`LatticeKernels::float_lattice_sample`]) or 1 for the nearest sample
    /// ([`Transfer::NearestFace`]). The default is differentiable in `values` and `points`.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_lattice_splat(
        lattice: &SampleLattice,
        points: Self::Float,
        values: Self::Float,
        transfer: Transfer,
    ) -> Result<(Self::Float, Self::Float)> {
        composite_lattice_splat::<Self>(lattice, points, values, transfer)
    }

    /// [`LatticeKernels::float_lattice_splat`] of each column of `values [N, k]` onto its own
    /// lattice: column `j` onto `lattices[j]` (`k` lattices; the components of a staggered grid),
    /// each returning its `(Σ w v [samples, 1], Σ w [samples, 1])`. The default splats the columns
    /// one by one; a backend may interleave them, with the same values.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_lattice_splat_columns(
        lattices: &[SampleLattice],
        points: Self::Float,
        values: Self::Float,
        transfer: Transfer,
    ) -> Result<Vec<(Self::Float, Self::Float)>> {
        lattice_splat_columns_one_by_one::<Self>(lattices, points, values, transfer)
    }

    /// `points [N, d]` moved over `dt` through a frozen staggered velocity by `integrator`
    /// ([`advect_points`](crate::fields::advect_points)): component `i` of the velocity is
    /// `components[i]` (`[samples_i, 1]`) on `lattices[i]`, sampled as
    /// [`LatticeKernels::float_lattice_sample`] samples. Returns `[N, d]`. The default is
    /// differentiable in the points and the velocity; a fused kernel spares the intermediate
    /// tensors of RK4's four stages.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_advect_points(
        lattices: &[SampleLattice],
        components: &[Self::Float],
        points: Self::Float,
        dt: f32,
        integrator: Integrator,
    ) -> Result<Self::Float> {
        composite_advect_points::<Self>(lattices, components, points, dt, integrator)
    }

    /// Grows the valid region of `values` by `cells` layers, as
    /// [`extrapolate_valid_tensor`](crate::fields::extrapolate_valid_tensor) documents: returns
    /// `(values, valid)`. `valid` is a `0/1` mask matching `values` on the first `spatial_dims`
    /// axes and broadcasting over the rest (the callers check the shapes). The default is
    /// differentiable in `values`.
    ///
    /// # Errors
    /// Only shape errors, which the callers in [`crate::fields`] rule out.
    fn float_extrapolate_valid(
        values: Self::Float,
        valid: Self::Float,
        spatial_dims: usize,
        cells: usize,
    ) -> Result<(Self::Float, Self::Float)> {
        composite_extrapolate_valid::<Self>(values, valid, spatial_dims, cells)
    }
}

/// Time integration scheme for [`advect_points`](crate::fields::advect_points).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Integrator {
    /// `x + Δt u(x)`.
    Euler,
    /// Classical fourth-order Runge-Kutta (the thesis' particle advection).
    Rk4,
}

// ---------------------------------------------------------------- composite defaults

/// [`LatticeKernels::float_advect_points`] from tensor operations (the default of every backend;
/// differentiable in the points and the velocity).
pub(super) fn composite_advect_points<B: LatticeKernels>(
    lattices: &[SampleLattice],
    components: &[B::Float],
    points: B::Float,
    dt: f32,
    integrator: Integrator,
) -> Result<B::Float> {
    let points = Tensor::<B>::from_primitive(points);
    let velocity = |at: &Tensor<B>| -> Result<Tensor<B>> {
        Ok(Tensor::from_primitive(B::float_lattice_sample_columns(
            lattices,
            components,
            at.primitive().clone(),
        )?))
    };
    let moved = match integrator {
        Integrator::Euler => &points + &(velocity(&points)? * dt),
        Integrator::Rk4 => {
            let k1 = velocity(&points)?;
            let k2 = velocity(&(&points + &(&k1 * (0.5 * dt))))?;
            let k3 = velocity(&(&points + &(&k2 * (0.5 * dt))))?;
            let k4 = velocity(&(&points + &(&k3 * dt)))?;
            let slope = (k1 + k4 + (k2 + k3) * 2.0) * (dt / 6.0);
            &points + &slope
        }
    };
    Ok(moved.into_primitive())
}

/// [`LatticeKernels::float_lattice_sample_columns`] one lattice at a time through
/// [`LatticeKernels::float_lattice_sample`], the columns joined (the default).
pub(super) fn composite_lattice_sample_columns<B: LatticeKernels>(
    lattices: &[SampleLattice],
    components: &[B::Float],
    points: B::Float,
) -> Result<B::Float> {
    let points = Tensor::<B>::from_primitive(points);
    let columns = lattices
        .iter()
        .zip(components)
        .map(|(lattice, values)| {
            let column =
                B::float_lattice_sample(lattice, values.clone(), points.primitive().clone())?;
            Ok(Tensor::<B>::from_primitive(column))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Tensor::concat(&columns, 1)?.into_primitive())
}

/// [`LatticeKernels::float_lattice_splat_columns`] one column at a time through
/// [`LatticeKernels::float_lattice_splat`] (the default, and the fallback of backends that interleave
/// only some cases).
pub(super) fn lattice_splat_columns_one_by_one<B: LatticeKernels>(
    lattices: &[SampleLattice],
    points: B::Float,
    values: B::Float,
    transfer: Transfer,
) -> Result<Vec<(B::Float, B::Float)>> {
    let n = B::float_shape(&values)[0];
    lattices
        .iter()
        .enumerate()
        .map(|(j, lattice)| {
            let column = B::float_slice(values.clone(), &[0..n, j..j + 1]);
            B::float_lattice_splat(lattice, points.clone(), column, transfer)
        })
        .collect()
}

/// [`LatticeKernels::float_extrapolate_valid`] from tensor operations (the default of every backend;
/// differentiable in `values`).
pub(super) fn composite_extrapolate_valid<B: Backend>(
    values: B::Float,
    valid: B::Float,
    spatial_dims: usize,
    cells: usize,
) -> Result<(B::Float, B::Float)> {
    let mut values = Tensor::<B>::from_primitive(values);
    let mut valid = Tensor::<B>::from_primitive(valid).compare_scalar(CompareOp::NotEqual, 0.0);
    for _ in 0..cells {
        let neighbour_sum = box_sum(&(&values * &valid), spatial_dims)?;
        let neighbour_count = box_sum(&valid, spatial_dims)?;
        let reached = neighbour_count.greater_scalar(0.0);
        let empty = neighbour_count.compare_scalar(CompareOp::LessEqual, 0.0);
        let mean = neighbour_sum / (&neighbour_count + &empty);
        let newly = &reached - &(&reached * &valid);
        values = Tensor::select(&newly, &mean, &values)?;
        valid = reached;
    }
    Ok((values.into_primitive(), valid.into_primitive()))
}

/// The sum over the `3^d` box around each sample of the first `d` axes (zero beyond the edges).
fn box_sum<B: Backend>(t: &Tensor<B>, spatial_dims: usize) -> Result<Tensor<B>> {
    let mut sum = t.clone();
    for axis in 0..spatial_dims {
        let n = sum.shape()[axis];
        let padded = pad_ghosts(&sum, axis, [Ghost::Zero, Ghost::Zero])?;
        sum = padded.narrow(axis, 0..n)?
            + padded.narrow(axis, 1..n + 1)?
            + padded.narrow(axis, 2..n + 2)?;
    }
    Ok(sum)
}

/// Burn keeps the composite kernels: they record the autodiff graph.
#[cfg(feature = "burn")]
impl<I: crate::backend::burn::BurnInner> LatticeKernels for crate::backend::burn::Burn<I> {}

/// libtorch keeps the composite kernels: they record the autograd graph.
#[cfg(feature = "tch")]
impl LatticeKernels for crate::backend::tch::Tch {}
