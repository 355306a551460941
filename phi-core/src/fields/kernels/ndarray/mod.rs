//! [`NdArray`]'s fused [`LatticeKernels`]: the particle ↔ grid transfers, RK4 through a
//! staggered velocity and the valid-region growth as loops over host slices, doing the composite
//! defaults' arithmetic in the same order, so the values agree with them bit for bit (tested in
//! `fields::tests` and below).

use std::borrow::Cow;

use super::{
    Integrator, LatticeKernels, composite_extrapolate_valid, composite_lattice_sample_columns,
    lattice_splat_columns_one_by_one,
};
use crate::backend::Backend;
use crate::backend::ndarray::{NdArray, NdArrayDevice};
use crate::error::Result;
use crate::fields::lattice::{SampleLattice, Transfer};

mod extrapolate;
mod transfer;

use extrapolate::{box_sum_in_place, extrapolate_frontier, unit_mask};
use transfer::{
    LatticeIndexer, advect_kernel, sample_columns_kernel, sample_kernel, splat_columns_kernel,
    splat_kernel,
};

type Float = <NdArray as Backend>::Float;

/// The values of `tensor` in row-major order, borrowed where its layout allows.
fn standard(tensor: &Float) -> Cow<'_, [f32]> {
    NdArray::float_host_values(tensor)
}

/// A tensor of `shape` holding `data` in row-major order.
fn from_vec(data: Vec<f32>, shape: &[usize]) -> Float {
    NdArray::float_from_vec(data, shape, &NdArrayDevice)
}

impl LatticeKernels for NdArray {
    fn float_lattice_sample(
        lattice: &SampleLattice,
        values: Self::Float,
        points: Self::Float,
    ) -> Result<Self::Float> {
        let c = values.shape()[1];
        let n = points.shape()[0];
        let (v, p) = (standard(&values), standard(&points));
        let indexer = LatticeIndexer::new(lattice);
        let mut out = vec![0.0f32; n * c];
        match lattice.shape.len() {
            1 => sample_kernel::<1>(&indexer, &v, &p, c, &mut out),
            2 => sample_kernel::<2>(&indexer, &v, &p, c, &mut out),
            _ => sample_kernel::<3>(&indexer, &v, &p, c, &mut out),
        }
        Ok(from_vec(out, &[n, c]))
    }

    fn float_lattice_sample_columns(
        lattices: &[SampleLattice],
        components: &[Self::Float],
        points: Self::Float,
    ) -> Result<Self::Float> {
        let d = lattices.len();
        let fused = (1..=3).contains(&d)
            && points.shape()[1] == d
            && lattices.iter().all(|l| l.shape.len() == d)
            && components.iter().all(|c| c.shape()[1] == 1);
        if !fused {
            return composite_lattice_sample_columns::<Self>(lattices, components, points);
        }
        let n = points.shape()[0];
        let p = standard(&points);
        let values: Vec<Cow<'_, [f32]>> = components.iter().map(standard).collect();
        let values: Vec<&[f32]> = values.iter().map(|v| &v[..]).collect();
        let out = match d {
            1 => sample_columns_kernel::<1>(lattices, &values, &p),
            2 => sample_columns_kernel::<2>(lattices, &values, &p),
            _ => sample_columns_kernel::<3>(lattices, &values, &p),
        };
        Ok(from_vec(out, &[n, d]))
    }

    fn float_lattice_splat(
        lattice: &SampleLattice,
        points: Self::Float,
        values: Self::Float,
        transfer: Transfer,
    ) -> Result<(Self::Float, Self::Float)> {
        let c = values.shape()[1];
        let samples: usize = lattice.shape.iter().product();
        let (v, p) = (standard(&values), standard(&points));
        let indexer = LatticeIndexer::new(lattice);
        let mut sums = vec![0.0f32; samples * c];
        let mut weights = vec![0.0f32; samples];
        let out = (&mut sums[..], &mut weights[..]);
        match lattice.shape.len() {
            1 => splat_kernel::<1>(&indexer, &v, &p, c, transfer, out),
            2 => splat_kernel::<2>(&indexer, &v, &p, c, transfer, out),
            _ => splat_kernel::<3>(&indexer, &v, &p, c, transfer, out),
        }
        Ok((
            from_vec(sums, &[samples, c]),
            from_vec(weights, &[samples, 1]),
        ))
    }

    fn float_lattice_splat_columns(
        lattices: &[SampleLattice],
        points: Self::Float,
        values: Self::Float,
        transfer: Transfer,
    ) -> Result<Vec<(Self::Float, Self::Float)>> {
        let d = lattices.len();
        let fused = transfer == Transfer::Linear
            && values.shape()[1] == d
            && (d == 2 || d == 3)
            && lattices.iter().all(|l| l.shape.len() == d);
        if !fused {
            return lattice_splat_columns_one_by_one::<Self>(lattices, points, values, transfer);
        }
        let (v, p) = (standard(&values), standard(&points));
        let out = match d {
            2 => splat_columns_kernel::<2>(lattices, &v, &p),
            _ => splat_columns_kernel::<3>(lattices, &v, &p),
        };
        Ok(out
            .into_iter()
            .map(|(sums, weights)| {
                let samples = weights.len();
                (
                    from_vec(sums, &[samples, 1]),
                    from_vec(weights, &[samples, 1]),
                )
            })
            .collect())
    }

    fn float_advect_points(
        lattices: &[SampleLattice],
        components: &[Self::Float],
        points: Self::Float,
        dt: f32,
        integrator: Integrator,
    ) -> Result<Self::Float> {
        let shape = points.shape().to_vec();
        let p = standard(&points);
        let values: Vec<Cow<'_, [f32]>> = components.iter().map(standard).collect();
        let values: Vec<&[f32]> = values.iter().map(|v| &v[..]).collect();
        let out = match lattices.len() {
            1 => advect_kernel::<1>(lattices, &values, &p, dt, integrator),
            2 => advect_kernel::<2>(lattices, &values, &p, dt, integrator),
            _ => advect_kernel::<3>(lattices, &values, &p, dt, integrator),
        };
        Ok(from_vec(out, &shape))
    }

    fn float_extrapolate_valid(
        values: Self::Float,
        valid: Self::Float,
        spatial_dims: usize,
        cells: usize,
    ) -> Result<(Self::Float, Self::Float)> {
        let (shape, mask_shape) = (values.shape().to_vec(), valid.shape().to_vec());
        let sites: usize = shape[..spatial_dims].iter().product();
        let channels: usize = shape[spatial_dims..].iter().product();
        // One mask per site, or one per value: the fused kernel's layouts. Other broadcasts take
        // the composite path.
        let mask_channels = if mask_shape == shape {
            channels
        } else if mask_shape[spatial_dims..].iter().all(|&m| m == 1) {
            1
        } else {
            return composite_extrapolate_valid::<Self>(values, valid, spatial_dims, cells);
        };
        let grid = &shape[..spatial_dims];
        if mask_channels == 1 {
            let (v, mask) =
                extrapolate_frontier(&standard(&values), &standard(&valid), grid, channels, cells);
            return Ok((from_vec(v, &shape), from_vec(mask, &mask_shape)));
        }
        let mut v = standard(&values).into_owned();
        let mut mask: Vec<f32> = standard(&valid).iter().map(|&m| unit_mask(m)).collect();
        let mut sum = vec![0.0f32; sites * channels];
        let mut count = vec![0.0f32; sites * mask_channels];
        let mut scratch = Vec::new();
        for _ in 0..cells {
            if mask_channels == 1 {
                for ((s, value), &m) in sum
                    .chunks_exact_mut(channels)
                    .zip(v.chunks_exact(channels))
                    .zip(&mask)
                {
                    for (s, &x) in s.iter_mut().zip(value) {
                        *s = x * m;
                    }
                }
            } else {
                for ((s, &x), &m) in sum.iter_mut().zip(&v).zip(&mask) {
                    *s = x * m;
                }
            }
            count.copy_from_slice(&mask);
            box_sum_in_place(&mut sum, grid, channels, &mut scratch);
            box_sum_in_place(&mut count, grid, mask_channels, &mut scratch);
            for site in 0..sites {
                for k in 0..channels {
                    let mk = if mask_channels == 1 {
                        site
                    } else {
                        site * channels + k
                    };
                    let (n, was_valid) = (count[mk], mask[mk]);
                    let reached = if n > 0.0 { 1.0 } else { 0.0 };
                    let empty = if n <= 0.0 { 1.0 } else { 0.0 };
                    if reached - reached * was_valid != 0.0 {
                        v[site * channels + k] = sum[site * channels + k] / (n + empty);
                    }
                }
            }
            for (m, &n) in mask.iter_mut().zip(&count) {
                *m = if n > 0.0 { 1.0 } else { 0.0 };
            }
        }
        Ok((from_vec(v, &shape), from_vec(mask, &mask_shape)))
    }
}
