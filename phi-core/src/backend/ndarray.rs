//! [`NdArray`]: the fast CPU backend, on [`ndarray`] arrays with [`rayon`] for the large kernels.
//!
//! Forward only (no autodiff). Tensors are reference-counted [`ArcArray`]s, so the by-value
//! arguments of the [`Backend`] trait cost a reference count, and permutes, slices and reshapes of
//! row-major tensors are views that share the buffer. Every result computed here is row-major
//! (C-contiguous); views with other strides are read correctly wherever they show up.
//!
//! Work is split over rayon's thread pool only above [`PAR_THRESHOLD`] elements, so the many small
//! tensors of a simulation step stay on the calling thread. The parallel kernels are
//! deterministic: each output element is computed by one task, with the same operations in the
//! same order as on one thread, so results do not depend on the number of threads.

use std::borrow::Cow;
use std::ops::Range;

use ndarray::linalg::general_mat_mul;
use ndarray::{
    ArcArray, Array, ArrayView1, ArrayView2, ArrayViewMut2, Axis, Ix2, IxDyn, Order, Slice, Zip,
};
use rayon::prelude::*;

use super::{Backend, BinaryOp, CompareOp, IntBinaryOp, PadMode, ReduceOp, UnaryOp};
use crate::error::{Result, TensorError};
use crate::fields::{Integrator, SampleLattice, Transfer};

/// The CPU backend on ndarray and rayon. Forward only: gradients need the Burn or tch backend.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NdArray;

/// The one device of [`NdArray`]: the CPU (its threads are rayon's global pool).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NdArrayDevice;

/// Element count from which element-wise kernels, reductions, gathers and scatters use rayon.
/// Below it the cost of waking threads exceeds the work.
pub const PAR_THRESHOLD: usize = 32 * 1024;

/// Smallest piece of a parallel element-wise loop, so that rayon does not split down to single
/// elements.
const PAR_MIN_LEN: usize = 4 * 1024;

/// Multiply-adds from which one matrix product is split into blocks of rows.
const MATMUL_PAR_WORK: usize = 1 << 18;

/// Length of the blocks that a full sum adds up separately before adding the partial sums. Fixed,
/// so that the rounding does not depend on the number of threads.
const SUM_BLOCK: usize = 16 * 1024;

/// `f32`s in a 64-byte cache line: the unit in which parallel scatters split columns, so that
/// threads rarely write to one line.
const CACHE_LINE_F32: usize = 16;

type Tensor<T> = ArcArray<T, IxDyn>;

impl Backend for NdArray {
    type Float = ArcArray<f32, IxDyn>;
    type Int = ArcArray<i64, IxDyn>;
    type Device = NdArrayDevice;

    // ---------------------------------------------------------------- devices and host transfer

    fn name() -> &'static str {
        "ndarray"
    }

    fn default_device() -> NdArrayDevice {
        NdArrayDevice
    }

    fn float_device(_tensor: &Self::Float) -> NdArrayDevice {
        NdArrayDevice
    }

    fn float_to_device(tensor: Self::Float, _device: &NdArrayDevice) -> Self::Float {
        tensor
    }

    fn int_device(_tensor: &Self::Int) -> NdArrayDevice {
        NdArrayDevice
    }

    fn int_to_device(tensor: Self::Int, _device: &NdArrayDevice) -> Self::Int {
        tensor
    }

    fn float_shape(tensor: &Self::Float) -> Vec<usize> {
        tensor.shape().to_vec()
    }

    fn int_shape(tensor: &Self::Int) -> Vec<usize> {
        tensor.shape().to_vec()
    }

    fn float_to_vec(tensor: &Self::Float) -> Vec<f32> {
        standard(tensor).into_owned()
    }

    fn float_host_values(tensor: &Self::Float) -> Cow<'_, [f32]> {
        standard(tensor)
    }

    fn int_to_vec(tensor: &Self::Int) -> Vec<i64> {
        standard(tensor).into_owned()
    }

    // ---------------------------------------------------------------- creation

    fn float_from_vec(data: Vec<f32>, shape: &[usize], _device: &NdArrayDevice) -> Self::Float {
        from_vec(data, shape)
    }

    fn int_from_vec(data: Vec<i64>, shape: &[usize], _device: &NdArrayDevice) -> Self::Int {
        from_vec(data, shape)
    }

    fn float_full(shape: &[usize], value: f32, _device: &NdArrayDevice) -> Self::Float {
        ArcArray::from_elem(IxDyn(shape), value)
    }

    // ---------------------------------------------------------------- shape

    fn float_reshape(tensor: Self::Float, shape: &[usize]) -> Self::Float {
        reshape(tensor, shape)
    }

    fn float_permute(tensor: Self::Float, axes: &[usize]) -> Self::Float {
        tensor.permuted_axes(axes)
    }

    fn float_slice(tensor: Self::Float, ranges: &[Range<usize>]) -> Self::Float {
        slice(tensor, ranges)
    }

    fn float_concat(tensors: Vec<Self::Float>, axis: usize) -> Self::Float {
        concat(tensors, axis)
    }

    fn float_broadcast_to(tensor: Self::Float, shape: &[usize]) -> Self::Float {
        if tensor.shape() == shape {
            return tensor;
        }
        if out_len(shape) < PAR_THRESHOLD {
            return from_vec(strided_map(&tensor, shape, |x| x), shape);
        }
        let view = tensor
            .broadcast(shape)
            .expect("the front end checked the broadcast");
        let mut out = Array::from_elem(IxDyn(shape), 0.0);
        if out.len() >= PAR_THRESHOLD {
            Zip::from(&mut out).and(&view).par_for_each(|o, &x| *o = x);
        } else {
            out.assign(&view);
        }
        out.into_shared()
    }

    fn float_pad(tensor: Self::Float, widths: &[(usize, usize)], mode: PadMode) -> Self::Float {
        pad(tensor, widths, mode)
    }

    // ---------------------------------------------------------------- element-wise maths

    fn float_unary(op: UnaryOp, tensor: Self::Float) -> Self::Float {
        let t = &tensor;
        match op {
            UnaryOp::Neg => map(t, |x| -x),
            UnaryOp::Sqrt => map(t, f32::sqrt),
            UnaryOp::Exp => map(t, f32::exp),
            UnaryOp::Log => map(t, f32::ln),
            UnaryOp::Abs => map(t, f32::abs),
            UnaryOp::Sin => map(t, f32::sin),
            UnaryOp::Cos => map(t, f32::cos),
            UnaryOp::Tanh => map(t, f32::tanh),
            UnaryOp::Floor => map(t, f32::floor),
            UnaryOp::Sign => map(t, |x| UnaryOp::Sign.apply(x)),
            UnaryOp::Relu => map(t, |x| x.max(0.0)),
            UnaryOp::Recip => map(t, |x| 1.0 / x),
        }
    }

    fn float_binary(op: BinaryOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        let (a, b) = (&lhs, &rhs);
        // The common operators get their own loop each, so that the compiler vectorises them.
        match op {
            BinaryOp::Add => zip2(a, b, |x, y| x + y),
            BinaryOp::Sub => zip2(a, b, |x, y| x - y),
            BinaryOp::Mul => zip2(a, b, |x, y| x * y),
            BinaryOp::Div => zip2(a, b, |x, y| x / y),
            BinaryOp::Min => zip2(a, b, f32::min),
            BinaryOp::Max => zip2(a, b, f32::max),
            BinaryOp::Pow | BinaryOp::Atan2 => zip2(a, b, move |x, y| op.apply(x, y)),
        }
    }

    fn float_binary_scalar(op: BinaryOp, lhs: Self::Float, rhs: f32) -> Self::Float {
        let t = &lhs;
        match op {
            BinaryOp::Add => map(t, move |x| x + rhs),
            BinaryOp::Sub => map(t, move |x| x - rhs),
            BinaryOp::Mul => map(t, move |x| x * rhs),
            BinaryOp::Div => map(t, move |x| x / rhs),
            BinaryOp::Min => map(t, move |x| x.min(rhs)),
            BinaryOp::Max => map(t, move |x| x.max(rhs)),
            BinaryOp::Pow if rhs == 2.0 => map(t, |x| x * x),
            BinaryOp::Pow | BinaryOp::Atan2 => map(t, move |x| op.apply(x, rhs)),
        }
    }

    fn float_clamp(tensor: Self::Float, min: f32, max: f32) -> Self::Float {
        // Comparisons rather than `f32::clamp`, which panics on odd bounds; NaN stays NaN.
        map(&tensor, move |x| {
            if x < min {
                min
            } else if x > max {
                max
            } else {
                x
            }
        })
    }

    // ---------------------------------------------------------------- comparisons and selection

    fn float_compare(op: CompareOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        let (a, b) = (&lhs, &rhs);
        match op {
            CompareOp::Greater => zip2(a, b, |x, y| mask(x > y)),
            CompareOp::GreaterEqual => zip2(a, b, |x, y| mask(x >= y)),
            CompareOp::Less => zip2(a, b, |x, y| mask(x < y)),
            CompareOp::LessEqual => zip2(a, b, |x, y| mask(x <= y)),
            CompareOp::Equal => zip2(a, b, |x, y| mask(x == y)),
            CompareOp::NotEqual => zip2(a, b, |x, y| mask(x != y)),
        }
    }

    fn float_compare_scalar(op: CompareOp, lhs: Self::Float, rhs: f32) -> Self::Float {
        let t = &lhs;
        match op {
            CompareOp::Greater => map(t, move |x| mask(x > rhs)),
            CompareOp::GreaterEqual => map(t, move |x| mask(x >= rhs)),
            CompareOp::Less => map(t, move |x| mask(x < rhs)),
            CompareOp::LessEqual => map(t, move |x| mask(x <= rhs)),
            CompareOp::Equal => map(t, move |x| mask(x == rhs)),
            CompareOp::NotEqual => map(t, move |x| mask(x != rhs)),
        }
    }

    fn float_where(mask: Self::Float, on_true: Self::Float, on_false: Self::Float) -> Self::Float {
        let select = |m: f32, t: f32, f: f32| if m != 0.0 { t } else { f };
        let shape = mask.shape();
        if shape == on_true.shape()
            && shape == on_false.shape()
            && let (Some(m), Some(t), Some(f)) =
                (mask.as_slice(), on_true.as_slice(), on_false.as_slice())
        {
            let data = if m.len() >= PAR_THRESHOLD {
                (m, t, f)
                    .into_par_iter()
                    .with_min_len(PAR_MIN_LEN)
                    .map(|(&m, &t, &f)| select(m, t, f))
                    .collect()
            } else {
                m.iter()
                    .zip(t)
                    .zip(f)
                    .map(|((&m, &t), &f)| select(m, t, f))
                    .collect()
            };
            return from_vec(data, shape);
        }
        let shape = broadcast_shape(&broadcast_shape(shape, on_true.shape()), on_false.shape());
        let views = (
            mask.broadcast(shape.as_slice()),
            on_true.broadcast(shape.as_slice()),
            on_false.broadcast(shape.as_slice()),
        );
        let (Some(m), Some(t), Some(f)) = views else {
            unreachable!("the front end checked that the shapes broadcast")
        };
        let mut out = Array::from_elem(IxDyn(&shape), 0.0);
        let zip = Zip::from(&mut out).and(&m).and(&t).and(&f);
        if out_len(&shape) >= PAR_THRESHOLD {
            zip.par_for_each(|o, &m, &t, &f| *o = select(m, t, f));
        } else {
            zip.for_each(|o, &m, &t, &f| *o = select(m, t, f));
        }
        out.into_shared()
    }

    // ---------------------------------------------------------------- reductions

    fn float_reduce(op: ReduceOp, tensor: Self::Float) -> Self::Float {
        let data = standard(&tensor);
        let value = match op {
            ReduceOp::Sum => sum(&data),
            ReduceOp::Mean => sum(&data) / data.len() as f32,
            ReduceOp::Max => extreme(&data, f32::NEG_INFINITY, f32::max),
            ReduceOp::Min => extreme(&data, f32::INFINITY, f32::min),
        };
        from_vec(vec![value], &[1])
    }

    fn float_reduce_axis(op: ReduceOp, tensor: Self::Float, axis: usize) -> Self::Float {
        let n = tensor.shape()[axis];
        match op {
            ReduceOp::Sum => reduce_axis(&tensor, axis, Some(0.0), |a, b| a + b),
            ReduceOp::Mean => {
                let sums = reduce_axis(&tensor, axis, Some(0.0), |a, b| a + b);
                let count = n as f32;
                map(&sums, move |s| s / count)
            }
            ReduceOp::Max => reduce_axis(&tensor, axis, None, f32::max),
            ReduceOp::Min => reduce_axis(&tensor, axis, None, f32::min),
        }
    }

    // ---------------------------------------------------------------- matmul

    fn float_matmul(lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        matmul(&lhs, &rhs)
    }

    // ---------------------------------------------------------------- gather and scatter

    fn float_gather_rows(tensor: Self::Float, indices: Self::Int) -> Result<Self::Float> {
        gather_rows(&tensor, &indices, "gather_rows")
    }

    fn float_scatter_add_rows(
        tensor: Self::Float,
        indices: Self::Int,
        values: Self::Float,
    ) -> Result<Self::Float> {
        let rows = standard(&indices);
        check_indices(&rows, tensor.shape()[0], "scatter_add_rows")?;
        Ok(scatter_add(tensor, &rows, &values))
    }

    fn float_gather_nd(tensor: Self::Float, indices: Self::Int) -> Result<Self::Float> {
        let shape = tensor.shape().to_vec();
        let (flat_shape, rows) = flat_nd_indices(&shape, &indices, "gather_nd")?;
        let source = reshape(tensor, &flat_shape);
        let rows = from_vec(rows, &[indices.shape()[0]]);
        gather_rows(&source, &rows, "gather_nd")
    }

    fn float_scatter_add_nd(
        tensor: Self::Float,
        indices: Self::Int,
        values: Self::Float,
    ) -> Result<Self::Float> {
        let shape = tensor.shape().to_vec();
        let (flat_shape, rows) = flat_nd_indices(&shape, &indices, "scatter_add_nd")?;
        let out = scatter_add(reshape(tensor, &flat_shape), &rows, &values);
        Ok(reshape(out, &shape))
    }

    // ---------------------------------------------------------------- casts

    fn float_to_int(tensor: Self::Float) -> Self::Int {
        // `as` rounds toward zero (and saturates, NaN → 0).
        map(&tensor, |x| x as i64)
    }

    fn int_to_float(tensor: Self::Int) -> Self::Float {
        map(&tensor, |x| x as f32)
    }

    // ---------------------------------------------------------------- integer tensors

    fn int_reshape(tensor: Self::Int, shape: &[usize]) -> Self::Int {
        reshape(tensor, shape)
    }

    fn int_slice(tensor: Self::Int, ranges: &[Range<usize>]) -> Self::Int {
        slice(tensor, ranges)
    }

    fn int_concat(tensors: Vec<Self::Int>, axis: usize) -> Self::Int {
        concat(tensors, axis)
    }

    fn int_binary(op: IntBinaryOp, lhs: Self::Int, rhs: Self::Int) -> Self::Int {
        let (a, b) = (&lhs, &rhs);
        // Wrapping arithmetic and a zero result for a zero divisor: the contract leaves overflow and
        // division by zero unspecified, and a panic inside a rayon task would take the caller down.
        match op {
            IntBinaryOp::Add => zip2(a, b, i64::wrapping_add),
            IntBinaryOp::Sub => zip2(a, b, i64::wrapping_sub),
            IntBinaryOp::Mul => zip2(a, b, i64::wrapping_mul),
            IntBinaryOp::FloorDiv => zip2(a, b, floor_div),
            IntBinaryOp::Rem => zip2(a, b, floor_rem),
            IntBinaryOp::Min => zip2(a, b, i64::min),
            IntBinaryOp::Max => zip2(a, b, i64::max),
        }
    }

    fn int_binary_scalar(op: IntBinaryOp, lhs: Self::Int, rhs: i64) -> Self::Int {
        let t = &lhs;
        match op {
            IntBinaryOp::Add => map(t, move |x| x.wrapping_add(rhs)),
            IntBinaryOp::Sub => map(t, move |x| x.wrapping_sub(rhs)),
            IntBinaryOp::Mul => map(t, move |x| x.wrapping_mul(rhs)),
            IntBinaryOp::FloorDiv => map(t, move |x| floor_div(x, rhs)),
            IntBinaryOp::Rem => map(t, move |x| floor_rem(x, rhs)),
            IntBinaryOp::Min => map(t, move |x| x.min(rhs)),
            IntBinaryOp::Max => map(t, move |x| x.max(rhs)),
        }
    }

    fn int_clamp(tensor: Self::Int, min: i64, max: i64) -> Self::Int {
        // Not `Ord::clamp`, which panics when `min > max`.
        map(&tensor, move |x| x.max(min).min(max))
    }

    fn int_reduce_axis(op: ReduceOp, tensor: Self::Int, axis: usize) -> Self::Int {
        let n = tensor.shape()[axis] as i64;
        match op {
            ReduceOp::Sum => reduce_axis(&tensor, axis, Some(0), i64::wrapping_add),
            ReduceOp::Mean => {
                let sums = reduce_axis(&tensor, axis, Some(0), i64::wrapping_add);
                // Integer division rounds toward zero, as documented; nothing to average gives 0.
                map(&sums, move |s| s.checked_div(n).unwrap_or(0))
            }
            ReduceOp::Max => reduce_axis(&tensor, axis, None, i64::max),
            ReduceOp::Min => reduce_axis(&tensor, axis, None, i64::min),
        }
    }

    fn int_gather_rows(tensor: Self::Int, indices: Self::Int) -> Result<Self::Int> {
        gather_rows(&tensor, &indices, "int_gather_rows")
    }

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
            return crate::fields::sample::composite_lattice_sample_columns::<Self>(
                lattices, components, points,
            );
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
            return crate::fields::sample::lattice_splat_columns_one_by_one::<Self>(
                lattices, points, values, transfer,
            );
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
            return crate::fields::extrapolate::composite_extrapolate_valid::<Self>(
                values,
                valid,
                spatial_dims,
                cells,
            );
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

// -------------------------------------------------------------------- extrapolation kernel

/// The extrapolation of [`Backend::float_extrapolate_valid`] for one mask per site, layer by
/// layer over the frontier only: the invalid sites next to the valid region. Each frontier site
/// takes its box sums in the order [`box_sum_in_place`] adds them over the whole grid (axis 0
/// first, `(below + centre) + above`, zeros beyond the edges), so the values are bit for bit the
/// composite's, at a cost that follows the frontier instead of the grid. Takes the values and
/// the mask (any nonzero entry is valid) and returns both grown.
fn extrapolate_frontier(
    v: &[f32],
    mask: &[f32],
    grid: &[usize],
    channels: usize,
    cells: usize,
) -> (Vec<f32>, Vec<f32>) {
    match grid.len() {
        1 => frontier_kernel::<1>(v, mask, grid, channels, cells),
        2 => frontier_kernel::<2>(v, mask, grid, channels, cells),
        3 => frontier_kernel::<3>(v, mask, grid, channels, cells),
        _ => unreachable!("grids have one to three dimensions"),
    }
}

/// [`extrapolate_frontier`] on a `D`-dimensional grid. It works on a copy padded by one site
/// beyond every side (mask and values 0, never queued), so that every site's `3^D` box lies in
/// the array and the loops need no bounds tests: a padding site adds the zero the composite
/// adds beyond the edge.
#[allow(clippy::needless_range_loop)] // box positions index several arrays
fn frontier_kernel<const D: usize>(
    v: &[f32],
    mask: &[f32],
    grid: &[usize],
    channels: usize,
    cells: usize,
) -> (Vec<f32>, Vec<f32>) {
    let sites: usize = grid.iter().product();
    if sites == 0 || cells == 0 {
        return (v.to_vec(), mask.iter().map(|&m| unit_mask(m)).collect());
    }
    let padded: [usize; D] = std::array::from_fn(|axis| grid[axis] + 2);
    let mut strides = [1usize; D];
    for axis in (0..D.saturating_sub(1)).rev() {
        strides[axis] = strides[axis + 1] * padded[axis + 1];
    }
    let padded_sites: usize = padded.iter().product();
    // The interior: padded index of each grid site, row by row along the last axis.
    let row = grid[D - 1];
    let row_starts = || {
        (0..sites / row).map(move |r| {
            let (mut rest, mut at) = (r, 0);
            for axis in (0..D - 1).rev() {
                at += (rest % grid[axis] + 1) * strides[axis];
                rest /= grid[axis];
            }
            (r * row, at + 1)
        })
    };
    let mut pv = vec![0.0f32; padded_sites * channels];
    let mut pm = vec![0.0f32; padded_sites];
    let mut queued = vec![true; padded_sites];
    for (site, at) in row_starts() {
        pv[at * channels..(at + row) * channels]
            .copy_from_slice(&v[site * channels..(site + row) * channels]);
        for (m, &valid) in pm[at..at + row].iter_mut().zip(&mask[site..site + row]) {
            *m = unit_mask(valid);
        }
        queued[at..at + row].fill(false);
    }
    // The 3^D box around a site, itself included: per box position `k` (row-major over the
    // per-axis steps −1, 0, +1, axis 0 slowest), its flat offset.
    let positions = 3usize.pow(D as u32);
    let mut box_offset = [0isize; 27];
    for (k, offset) in box_offset[..positions].iter_mut().enumerate() {
        let mut rest = k;
        for axis in (0..D).rev() {
            let step = (rest % 3) as isize - 1;
            rest /= 3;
            *offset += step * strides[axis] as isize;
        }
    }
    let box_offset = &box_offset[..positions];
    // The box sum of the gathered `values` (one per box position) in box_sum_in_place's order:
    // axis 0 first, each as `(below + centre) + above`. Sums in place; the result is `values[0]`.
    let reduce_box = |values: &mut [f32]| {
        let mut len = values.len();
        for _ in 0..D {
            len /= 3;
            for j in 0..len {
                values[j] = (values[j] + values[len + j]) + values[2 * len + j];
            }
        }
        values[0]
    };
    // The first frontier: the invalid sites that see a valid one. Whether a site sees one is the
    // count of valid sites in its box, summed axis by axis over the whole padded array (long
    // vectorised runs; each pass covers every site whose neighbours along its axis lie in the
    // array, which includes all that a later pass reads for an interior site).
    let mut seen = pm.clone();
    let mut pass = vec![0.0f32; padded_sites];
    for &stride in &strides {
        let n = padded_sites;
        for ((out, below), (centre, above)) in pass[stride..n - stride]
            .iter_mut()
            .zip(&seen[..n - 2 * stride])
            .zip(seen[stride..n - stride].iter().zip(&seen[2 * stride..]))
        {
            *out = (below + centre) + above;
        }
        std::mem::swap(&mut seen, &mut pass);
    }
    // Most runs of sites hold no frontier site: each run of 16 is tested at once (vectorised),
    // and only runs with one are walked site by site.
    let mut frontier = Vec::new();
    for (_, at) in row_starts() {
        for start in (at..at + row).step_by(16) {
            let end = (start + 16).min(at + row);
            let hit = pm[start..end]
                .iter()
                .zip(&seen[start..end])
                .fold(false, |hit, (&m, &count)| {
                    hit | ((m == 0.0) & (count != 0.0))
                });
            if !hit {
                continue;
            }
            for site in start..end {
                if pm[site] == 0.0 && seen[site] != 0.0 {
                    queued[site] = true;
                    frontier.push(site);
                }
            }
        }
    }
    let mut updates = Vec::new();
    let mut count_box = [0.0f32; 27];
    let mut sum_box = vec![0.0f32; positions * channels];
    let mut next = Vec::new();
    for _ in 0..cells {
        if frontier.is_empty() {
            break;
        }
        updates.clear();
        for &site in &frontier {
            // Gather the mask and the masked values over the box.
            for (k, &offset) in box_offset.iter().enumerate() {
                let nb = site.wrapping_add_signed(offset);
                let m = pm[nb];
                count_box[k] = m;
                for ch in 0..channels {
                    sum_box[ch * positions + k] = pv[nb * channels + ch] * m;
                }
            }
            let count = reduce_box(&mut count_box[..positions]);
            // A frontier site has a valid neighbour: count > 0, and the composite divides by
            // `count + 0`.
            for sums in sum_box.chunks_exact_mut(positions) {
                updates.push(reduce_box(sums) / (count + 0.0));
            }
        }
        for (&site, new) in frontier.iter().zip(updates.chunks_exact(channels)) {
            for (ch, &x) in new.iter().enumerate() {
                pv[site * channels + ch] = x;
            }
            pm[site] = 1.0;
        }
        next.clear();
        for &site in &frontier {
            for &offset in box_offset {
                let nb = site.wrapping_add_signed(offset);
                if pm[nb] == 0.0 && !queued[nb] {
                    queued[nb] = true;
                    next.push(nb);
                }
            }
        }
        std::mem::swap(&mut frontier, &mut next);
    }
    let mut values = Vec::with_capacity(sites * channels);
    let mut valid = Vec::with_capacity(sites);
    for (_, at) in row_starts() {
        values.extend_from_slice(&pv[at * channels..(at + row) * channels]);
        valid.extend_from_slice(&pm[at..at + row]);
    }
    (values, valid)
}

/// A mask entry as `0` or `1` (any nonzero entry is valid).
#[inline(always)]
fn unit_mask(m: f32) -> f32 {
    if m != 0.0 { 1.0 } else { 0.0 }
}

/// Replaces `data` (`[grid..., channels]`, row-major) by its sum over the `3^d` box around each
/// site (zero beyond the edges), one axis after the other, each as `(x[i−1] + x[i]) + x[i+1]`:
/// the order of the composite `box_sum`, so the results agree bit for bit.
fn box_sum_in_place(data: &mut [f32], grid: &[usize], channels: usize, scratch: &mut Vec<f32>) {
    for (axis, &n) in grid.iter().enumerate() {
        let inner = grid[axis + 1..].iter().product::<usize>() * channels;
        let block = n * inner;
        if block == 0 {
            return;
        }
        scratch.clear();
        scratch.extend_from_slice(data);
        for (src, dst) in scratch
            .chunks_exact(block)
            .zip(data.chunks_exact_mut(block))
        {
            // Rows of `inner` values along the axis; missing neighbours are zeros. The rows with
            // both neighbours form one contiguous run, summed as one flat loop (vectorised, and
            // cheap when `inner` is small, as along the last axis).
            if n == 1 {
                for (o, &c) in dst.iter_mut().zip(src) {
                    *o = (0.0 + c) + 0.0;
                }
                continue;
            }
            let interior = (n - 2) * inner;
            let (first, rest) = dst.split_at_mut(inner);
            let (middle, last) = rest.split_at_mut(interior);
            for ((o, &c), &a) in first
                .iter_mut()
                .zip(&src[..inner])
                .zip(&src[inner..2 * inner])
            {
                *o = (0.0 + c) + a;
            }
            let below = &src[..interior];
            let centre = &src[inner..inner + interior];
            let above = &src[2 * inner..2 * inner + interior];
            for (((o, &b), &c), &a) in middle.iter_mut().zip(below).zip(centre).zip(above) {
                *o = (b + c) + a;
            }
            let end = n * inner;
            for ((o, &b), &c) in last
                .iter_mut()
                .zip(&src[end - 2 * inner..end - inner])
                .zip(&src[end - inner..end])
            {
                *o = (b + c) + 0.0;
            }
        }
    }
}

// -------------------------------------------------------------------- layout and shape helpers

/// A tensor of `shape` holding `data` in row-major order.
fn from_vec<T>(data: Vec<T>, shape: &[usize]) -> Tensor<T> {
    ArcArray::from_shape_vec(IxDyn(shape), data).expect("the front end checked the data length")
}

/// The number of elements of `shape`.
fn out_len(shape: &[usize]) -> usize {
    shape.iter().product()
}

/// The elements of `tensor` in row-major order: borrowed when the tensor is row-major already,
/// else copied (with a strided loop rather than element-by-element index arithmetic).
fn standard<T: Copy + Default + Send + Sync>(tensor: &Tensor<T>) -> Cow<'_, [T]> {
    if let Some(slice) = tensor.as_slice() {
        return Cow::Borrowed(slice);
    }
    if tensor.len() < PAR_THRESHOLD {
        return Cow::Owned(strided_map(tensor, tensor.shape(), |x| x));
    }
    let mut out = Array::from_elem(tensor.raw_dim(), T::default());
    Zip::from(&mut out).and(tensor).par_for_each(|o, &x| *o = x);
    Cow::Owned(out.into_raw_vec_and_offset().0)
}

/// `tensor` under `shape`: a view of the same buffer when the tensor is row-major.
fn reshape<T: Copy + Default + Send + Sync>(tensor: Tensor<T>, shape: &[usize]) -> Tensor<T> {
    if tensor.is_standard_layout() {
        return tensor
            .into_shape_with_order(IxDyn(shape))
            .expect("the front end checked the element count");
    }
    from_vec(standard(&tensor).into_owned(), shape)
}

/// A view of the block `ranges` (no copy).
fn slice<T>(mut tensor: Tensor<T>, ranges: &[Range<usize>]) -> Tensor<T> {
    tensor.slice_each_axis_inplace(|axis| Slice::from(ranges[axis.axis.index()].clone()));
    tensor
}

/// The tensors joined along `axis`, copied block by block: for each index of the axes before
/// `axis`, one contiguous run of every tensor.
fn concat<T: Copy + Default + Send + Sync>(tensors: Vec<Tensor<T>>, axis: usize) -> Tensor<T> {
    if tensors.len() == 1 {
        return tensors.into_iter().next().expect("one tensor");
    }
    let mut shape = tensors[0].shape().to_vec();
    shape[axis] = tensors.iter().map(|t| t.shape()[axis]).sum();
    let outer: usize = shape[..axis].iter().product();
    let inner: usize = shape[axis + 1..].iter().product();
    let parts: Vec<(Cow<'_, [T]>, usize)> = tensors
        .iter()
        .map(|t| (standard(t), t.shape()[axis] * inner))
        .collect();
    let row: usize = parts.iter().map(|(_, block)| block).sum();
    let mut data = vec![T::default(); out_len(&shape)];
    if row == 0 {
        return from_vec(data, &shape);
    }
    // Two or three columns (per-axis samples joined into points): interleaved in one pass.
    if parts.iter().all(|(_, block)| *block == 1) {
        let columns: Vec<&[T]> = parts.iter().map(|(part, _)| &part[..]).collect();
        match columns[..] {
            [a, b] => {
                for ((out, &a), &b) in data.chunks_exact_mut(2).zip(a).zip(b) {
                    out.copy_from_slice(&[a, b]);
                }
                return from_vec(data, &shape);
            }
            [a, b, c] => {
                for (((out, &a), &b), &c) in data.chunks_exact_mut(3).zip(a).zip(b).zip(c) {
                    out.copy_from_slice(&[a, b, c]);
                }
                return from_vec(data, &shape);
            }
            _ => {}
        }
    }
    let mut at = 0;
    for (part, block) in &parts {
        if *block == 1 {
            // Columns (e.g. per-axis samples joined into points): element by element, without a
            // slice copy per element.
            for (out, &x) in data[at..].iter_mut().step_by(row).zip(part.iter()) {
                *out = x;
            }
        } else if *block > 0 {
            for (o, out) in data.chunks_exact_mut(row).enumerate().take(outer) {
                out[at..at + block].copy_from_slice(&part[o * block..(o + 1) * block]);
            }
        }
        at += block;
    }
    from_vec(data, &shape)
}

/// The shape that `a` and `b` broadcast to (NumPy rules; the front end checked that they do).
fn broadcast_shape(a: &[usize], b: &[usize]) -> Vec<usize> {
    let rank = a.len().max(b.len());
    (0..rank)
        .map(|i| {
            let da = if i + a.len() >= rank {
                a[i + a.len() - rank]
            } else {
                1
            };
            let db = if i + b.len() >= rank {
                b[i + b.len() - rank]
            } else {
                1
            };
            if da == 1 { db } else { da }
        })
        .collect()
}

// -------------------------------------------------------------------- element-wise kernels

/// `1.0` for true, `0.0` for false.
fn mask(condition: bool) -> f32 {
    if condition { 1.0 } else { 0.0 }
}

/// `⌊a / b⌋` as Python's `//`, without the panics of `i64` division (zero divisor, overflow).
fn floor_div(a: i64, b: i64) -> i64 {
    if b == 0 {
        return 0;
    }
    let q = a.wrapping_div(b);
    if a.wrapping_rem(b) != 0 && ((a < 0) != (b < 0)) {
        q - 1
    } else {
        q
    }
}

/// `a - b·⌊a / b⌋` as Python's `%` (the sign of `b`), without the panics of `i64` division.
fn floor_rem(a: i64, b: i64) -> i64 {
    if b == 0 {
        return 0;
    }
    let r = a.wrapping_rem(b);
    if r != 0 && ((r < 0) != (b < 0)) {
        r + b
    } else {
        r
    }
}

/// `f` applied to every element, in a row-major result.
fn map<T, U, F>(tensor: &Tensor<T>, f: F) -> Tensor<U>
where
    T: Copy + Send + Sync,
    U: Copy + Default + Send + Sync,
    F: Fn(T) -> U + Send + Sync,
{
    let data = match tensor.as_slice() {
        Some(s) if s.len() >= PAR_THRESHOLD => s
            .par_iter()
            .with_min_len(PAR_MIN_LEN)
            .map(|&x| f(x))
            .collect(),
        Some(s) => s.iter().map(|&x| f(x)).collect(),
        None if tensor.len() < PAR_THRESHOLD => strided_map(tensor, tensor.shape(), f),
        None => {
            let mut out = Array::from_elem(tensor.raw_dim(), U::default());
            Zip::from(&mut out)
                .and(tensor)
                .par_for_each(|o, &x| *o = f(x));
            return out.into_shared();
        }
    };
    from_vec(data, tensor.shape())
}

/// `f(a, b)` element by element with NumPy broadcasting, in a row-major result.
fn zip2<T, U, F>(a: &Tensor<T>, b: &Tensor<T>, f: F) -> Tensor<U>
where
    T: Copy + Send + Sync,
    U: Copy + Default + Send + Sync,
    F: Fn(T, T) -> U + Send + Sync,
{
    let shape = broadcast_shape(a.shape(), b.shape());
    // Fast paths: two row-major operands of one shape, or one operand against a single value.
    if a.shape() == b.shape()
        && let (Some(x), Some(y)) = (a.as_slice(), b.as_slice())
    {
        let data = if x.len() >= PAR_THRESHOLD {
            (x, y)
                .into_par_iter()
                .with_min_len(PAR_MIN_LEN)
                .map(|(&x, &y)| f(x, y))
                .collect()
        } else {
            x.iter().zip(y).map(|(&x, &y)| f(x, y)).collect()
        };
        return from_vec(data, &shape);
    }
    if b.len() == 1 && a.shape() == shape.as_slice() {
        let y = *b.iter().next().expect("one element");
        return map(a, |x| f(x, y));
    }
    if a.len() == 1 && b.shape() == shape.as_slice() {
        let x = *a.iter().next().expect("one element");
        return map(b, |y| f(x, y));
    }
    if out_len(&shape) < PAR_THRESHOLD {
        return from_vec(strided_zip(a, b, &shape, f), &shape);
    }
    let (Some(x), Some(y)) = (a.broadcast(shape.as_slice()), b.broadcast(shape.as_slice())) else {
        unreachable!("the front end checked that the shapes broadcast")
    };
    let mut out = Array::from_elem(IxDyn(&shape), U::default());
    let zip = Zip::from(&mut out).and(&x).and(&y);
    if out_len(&shape) >= PAR_THRESHOLD {
        zip.par_for_each(|o, &x, &y| *o = f(x, y));
    } else {
        zip.for_each(|o, &x, &y| *o = f(x, y));
    }
    out.into_shared()
}

// -------------------------------------------------------------------- reductions

/// The sum of `data`, in fixed blocks (vectorised within a block), so that the result is the
/// same with and without threads.
fn sum(data: &[f32]) -> f32 {
    let block_sum = |block: &[f32]| ArrayView1::from(block).sum();
    let partials: Vec<f32> = if data.len() >= PAR_THRESHOLD {
        data.par_chunks(SUM_BLOCK).map(block_sum).collect()
    } else {
        data.chunks(SUM_BLOCK).map(block_sum).collect()
    };
    partials.iter().sum()
}

/// The fold of `data` with `pick` (`f32::max` or `f32::min`), which is exact in any order.
fn extreme(data: &[f32], init: f32, pick: fn(f32, f32) -> f32) -> f32 {
    if data.len() >= PAR_THRESHOLD {
        data.par_chunks(SUM_BLOCK)
            .map(|c| c.iter().fold(init, |a, &b| pick(a, b)))
            .reduce(|| init, pick)
    } else {
        data.iter().fold(init, |a, &b| pick(a, b))
    }
}

/// `f` folded over `axis` (kept with length 1). `init` starts the fold, or the first element along
/// the axis does when it is `None` (max, min).
///
/// The tensor is seen as `[outer, n, inner]`; each output row `[inner]` accumulates the `n` input
/// rows in order, which vectorises over `inner` and keeps the rounding independent of threads.
fn reduce_axis<T, F>(tensor: &Tensor<T>, axis: usize, init: Option<T>, f: F) -> Tensor<T>
where
    T: Copy + Default + Send + Sync,
    F: Fn(T, T) -> T + Send + Sync,
{
    let shape = tensor.shape();
    let n = shape[axis];
    let outer: usize = shape[..axis].iter().product();
    let inner: usize = shape[axis + 1..].iter().product();
    let mut out_shape = shape.to_vec();
    out_shape[axis] = 1;
    if outer * inner == 0 {
        return from_vec(Vec::new(), &out_shape);
    }
    if n == 0 {
        // Max and min of nothing are never asked for; the sum of nothing is `init`.
        return from_vec(vec![init.unwrap_or_default(); outer * inner], &out_shape);
    }
    let data = standard(tensor);
    let mut out = vec![T::default(); outer * inner];
    // Columns `cols` of the `n` rows in `src` ([n, inner]) folded into `dst`.
    let fold_block = |src: &[T], cols: Range<usize>, dst: &mut [T]| {
        let first = match init {
            Some(value) => {
                dst.fill(value);
                0
            }
            None => {
                dst.copy_from_slice(&src[cols.clone()]);
                1
            }
        };
        for k in first..n {
            let row = &src[k * inner + cols.start..k * inner + cols.end];
            for (d, &s) in dst.iter_mut().zip(row) {
                *d = f(*d, s);
            }
        }
    };
    let block = n * inner;
    if data.len() < PAR_THRESHOLD {
        for (src, dst) in data.chunks(block).zip(out.chunks_mut(inner)) {
            fold_block(src, 0..inner, dst);
        }
    } else if outer >= rayon::current_num_threads() {
        let min_len = (PAR_MIN_LEN / block).max(1);
        data.par_chunks(block)
            .zip(out.par_chunks_mut(inner))
            .with_min_len(min_len)
            .for_each(|(src, dst)| fold_block(src, 0..inner, dst));
    } else {
        // Few output rows (a reduction over a leading axis): split the columns instead.
        let cols = (PAR_MIN_LEN / n).clamp(16, inner.max(16));
        for (src, dst) in data.chunks(block).zip(out.chunks_mut(inner)) {
            dst.par_chunks_mut(cols).enumerate().for_each(|(c, dst)| {
                let start = c * cols;
                fold_block(src, start..start + dst.len(), dst);
            });
        }
    }
    from_vec(out, &out_shape)
}

// -------------------------------------------------------------------- particle ↔ grid kernels

/// The index arithmetic of the multilinear stencil, operation for operation as the composite
/// default in `fields::sample` does it (so the fused kernels give the same values).
struct LatticeIndexer {
    origin: Vec<f32>,
    inverse_spacing: Vec<f32>,
    /// `shape − 1`: the clamp of continuous indices.
    upper: Vec<f32>,
    /// `max(shape − 2, 0)`: the highest lower corner.
    highest_base: Vec<usize>,
    strides: Vec<usize>,
    shape: Vec<usize>,
}

impl LatticeIndexer {
    fn new(lattice: &SampleLattice) -> Self {
        let d = lattice.shape.len();
        let mut strides = vec![1usize; d];
        for axis in (0..d.saturating_sub(1)).rev() {
            strides[axis] = strides[axis + 1] * lattice.shape[axis + 1];
        }
        Self {
            origin: lattice.origin.clone(),
            inverse_spacing: lattice.spacing.iter().map(|s| 1.0 / s).collect(),
            upper: lattice.shape.iter().map(|&s| (s - 1) as f32).collect(),
            highest_base: lattice.shape.iter().map(|&s| s.saturating_sub(2)).collect(),
            strides,
            shape: lattice.shape.clone(),
        }
    }
}

/// The flat offset of each corner from the lower corner (independent of the point).
fn corner_offsets<const D: usize>(indexer: &LatticeIndexer) -> [usize; 8] {
    let mut offsets = [0usize; 8];
    for (corner, offset) in offsets.iter_mut().enumerate().take(1 << D) {
        for axis in 0..D {
            if (corner >> (D - 1 - axis)) & 1 == 1 && indexer.shape[axis] > 1 {
                *offset += indexer.strides[axis];
            }
        }
    }
    offsets
}

/// [`LatticeIndexer`] in fixed-size arrays for a `D`-dimensional lattice, so the per-point loops
/// keep everything in registers (no bounds checks, unrolled axes).
struct FixedIndexer<const D: usize> {
    origin: [f32; D],
    inverse_spacing: [f32; D],
    upper: [f32; D],
    /// `max(shape − 2, 0)` as an integer: the highest lower corner.
    highest_base: [i32; D],
    strides: [usize; D],
    /// `strides` in `i32`, for the vectorised lower corners: a lattice has at most `i32::MAX`
    /// samples (checked in `new`), so every flat index fits.
    strides_i32: [i32; D],
    /// `highest_base` and `strides` in `f32`, for lattices whose flat indices are all exact in
    /// `f32` (`exact_in_f32`): there the lower corners need no integer multiplications or
    /// minima, which x86-64's baseline SSE2 lacks for 32-bit lanes.
    highest_base_f32: [f32; D],
    strides_f32: [f32; D],
    exact_in_f32: bool,
}

impl<const D: usize> FixedIndexer<D> {
    fn new(indexer: &LatticeIndexer) -> Self {
        let pick = |v: &[f32]| std::array::from_fn(|axis| v[axis]);
        // The lower corners are computed in `i32` (below): the lattice must index within it.
        assert!(
            indexer.shape.iter().product::<usize>() <= i32::MAX as usize,
            "lattice too large"
        );
        Self {
            origin: pick(&indexer.origin),
            inverse_spacing: pick(&indexer.inverse_spacing),
            upper: pick(&indexer.upper),
            highest_base: std::array::from_fn(|axis| indexer.highest_base[axis] as i32),
            strides: std::array::from_fn(|axis| indexer.strides[axis]),
            strides_i32: std::array::from_fn(|axis| indexer.strides[axis] as i32),
            highest_base_f32: std::array::from_fn(|axis| indexer.highest_base[axis] as f32),
            strides_f32: std::array::from_fn(|axis| indexer.strides[axis] as f32),
            // Every flat index and every partial sum of one is below the sample count.
            exact_in_f32: indexer.shape.iter().product::<usize>() <= 1 << f32::MANTISSA_DIGITS,
        }
    }

    /// The continuous sample index of coordinate `x` along `axis`, `(x − origin) / spacing`
    /// clamped to `[0, shape − 1]`, as the composite computes it.
    #[inline(always)]
    fn continuous(&self, x: f32, axis: usize) -> f32 {
        ((x - self.origin[axis]) * self.inverse_spacing[axis])
            .max(0.0)
            .min(self.upper[axis])
    }

    /// The lower corner along `axis` of a continuous index `t` (from
    /// [`continuous`](Self::continuous)) and the fraction beyond it: `min(trunc(t), shape − 2)`
    /// in integers. `t` is clamped to `[0, shape − 1]`, so truncation is the floor, and these
    /// integers convert to `f32` exactly, which makes it the composite's
    /// `min(floor(t), shape − 2)` bit for bit.
    #[inline(always)]
    fn base(&self, t: f32, axis: usize) -> (i32, f32) {
        // SAFETY: `t` comes from `continuous`, which clamps it into `[0, shape − 1]` (a NaN
        // coordinate becomes 0 there, as `f32::max` returns the other operand), so it is finite
        // and, with `new`'s check on the lattice size, representable in `i32`. The unchecked
        // conversion then equals `t as i32`, without the saturation fix-ups that keep the lane
        // loops from vectorising.
        let whole: i32 = unsafe { t.to_int_unchecked() };
        let b = whole.min(self.highest_base[axis]);
        (b, t - b as f32)
    }

    /// The flat lower corner and the fractions of `point`: the continuous index
    /// `(x − origin) / spacing` clamped to `[0, shape − 1]`, its integer part capped at
    /// `shape − 2`, as the composite computes it.
    #[inline(always)]
    fn lower_corner(&self, point: &[f32]) -> (usize, [f32; D]) {
        let mut flat = 0;
        let mut fraction = [0.0f32; D];
        for axis in 0..D {
            let (b, f) = self.base(self.continuous(point[axis], axis), axis);
            flat += b as usize * self.strides[axis];
            fraction[axis] = f;
        }
        (flat, fraction)
    }

    /// [`lower_corner`](Self::lower_corner) of a block of points `x` (coordinate-major:
    /// `x[axis][point]`): the flat lower corners and the fractions (`fraction[axis][point]`).
    /// The arithmetic runs lane by lane over the block, which the compiler vectorises; the flat
    /// indices are summed in 32-bit lanes (a lattice has at most `i32::MAX` samples, checked in
    /// `new`), as 64-bit multiplications would not vectorise.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
    fn lower_corners(&self, x: &[Lane; D]) -> ([u32; LANES], [Lane; D]) {
        let mut fraction = [[0.0f32; LANES]; D];
        if self.exact_in_f32 {
            // The same corners in `f32`: `trunc(min(t, highest))` is `min(trunc(t), highest)`
            // for `t ≥ 0` and an integer `highest`, and the flat index and its partial sums are
            // integers below `2^24`, so every product and sum is exact.
            let mut flat = [0.0f32; LANES];
            for axis in 0..D {
                for i in 0..LANES {
                    let t = self.continuous(x[axis][i], axis);
                    let capped = t.min(self.highest_base_f32[axis]);
                    // SAFETY: `t` is clamped into `[0, shape − 1]` by `continuous` (a NaN
                    // coordinate becomes 0 there), so `capped` is finite and fits `i32`.
                    let b = unsafe { capped.to_int_unchecked::<i32>() } as f32;
                    flat[i] += b * self.strides_f32[axis];
                    fraction[axis][i] = t - b;
                }
            }
            // SAFETY: every entry is an exact non-negative integer below `2^24`.
            return (
                flat.map(|f| unsafe { f.to_int_unchecked::<i32>() } as u32),
                fraction,
            );
        }
        let mut flat = [0i32; LANES];
        for axis in 0..D {
            for i in 0..LANES {
                let (b, f) = self.base(self.continuous(x[axis][i], axis), axis);
                flat[i] += b * self.strides_i32[axis];
                fraction[axis][i] = f;
            }
        }
        // Non-negative: every lower corner and stride is.
        (flat.map(|f| f as u32), fraction)
    }
}

/// The tent weight of `corner`, multiplied in axis order as the composite does.
#[inline(always)]
fn corner_weight<const D: usize>(corner: usize, fraction: &[f32; D]) -> f32 {
    let mut weight = 1.0f32;
    for (axis, &f) in fraction.iter().enumerate() {
        let factor = if (corner >> (D - 1 - axis)) & 1 == 1 {
            f
        } else {
            1.0 - f
        };
        weight = if axis == 0 { factor } else { weight * factor };
    }
    weight
}

/// [`Backend::float_lattice_sample`] on a `D`-dimensional lattice: `out [N, c]` from values
/// `v [samples, c]` at points `p [N, D]`, corners summed in the composite's order.
fn sample_kernel<const D: usize>(
    indexer: &LatticeIndexer,
    v: &[f32],
    p: &[f32],
    c: usize,
    out: &mut [f32],
) {
    let offsets = corner_offsets::<D>(indexer);
    let fixed = FixedIndexer::<D>::new(indexer);
    if c == 1 {
        // One channel (a staggered component): blocks of points, corners in the same order.
        let sampler = ComponentSampler::<D>::new(indexer, v);
        for_each_block::<D>(p, |first, x, count| {
            let values = sampler.sample_block(x);
            out[first..first + count].copy_from_slice(&values[..count]);
        });
        return;
    }
    for (point, row) in p.chunks_exact(D).zip(out.chunks_exact_mut(c)) {
        let (flat, fraction) = fixed.lower_corner(point);
        for (corner, &offset) in offsets.iter().enumerate().take(1 << D) {
            let weight = corner_weight::<D>(corner, &fraction);
            let at = (flat + offset) * c;
            for (o, &x) in row.iter_mut().zip(&v[at..at + c]) {
                *o += x * weight;
            }
        }
    }
}

/// Points per block of the vectorised point loops ([`ComponentSampler::sample_block`] and the
/// kernels built on it). Each step of the interpolation runs over a whole block before the next,
/// in structure-of-arrays layout, so that the compiler turns the arithmetic into SIMD
/// instructions and the independent points keep the pipeline full.
const LANES: usize = 16;

/// One coordinate (or velocity component) of a block of [`LANES`] points.
type Lane = [f32; LANES];

/// One staggered component (or one channel of a lattice) ready for point queries: the lattice's
/// index arithmetic, its corner offsets and its values `[samples]`.
struct ComponentSampler<'a, const D: usize> {
    indexer: FixedIndexer<D>,
    offsets: [usize; 8],
    values: &'a [f32],
}

impl<'a, const D: usize> ComponentSampler<'a, D> {
    fn new(indexer: &LatticeIndexer, values: &'a [f32]) -> Self {
        let samples: usize = indexer.shape.iter().product();
        assert_eq!(values.len(), samples, "one value per lattice sample");
        Self {
            indexer: FixedIndexer::new(indexer),
            offsets: corner_offsets::<D>(indexer),
            values,
        }
    }

    /// The values at a block of points `x` (coordinate-major: `x[axis][point]`), each as
    /// [`sample_kernel`] computes it with one channel: first the lower corners and fractions of
    /// the whole block ([`FixedIndexer::lower_corners`], vectorised), then corner by corner the
    /// scalar loads, the tent weights and the running sums, in the composite's corner order.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
    fn sample_block(&self, x: &[Lane; D]) -> Lane {
        let (flat, fraction) = self.indexer.lower_corners(x);
        let mut out = [0.0f32; LANES];
        for corner in 0..(1 << D) {
            let offset = self.offsets[corner];
            for i in 0..LANES {
                let f: [f32; D] = std::array::from_fn(|axis| fraction[axis][i]);
                let at = flat[i] as usize + offset;
                debug_assert!(at < self.values.len());
                // SAFETY: along each axis the lower corner is at most `max(shape − 2, 0)`
                // (`FixedIndexer::base`), and a corner's offset steps one sample further only
                // along axes with more than one sample, so `at ≤ Σ (shape − 1) · stride =
                // samples − 1`; `new` checked that `values` holds `samples` values.
                let value = unsafe { *self.values.get_unchecked(at) };
                out[i] += value * corner_weight::<D>(corner, &f);
            }
        }
        out
    }
}

/// The points `p [N, D]` (row-major) in blocks of [`LANES`], coordinate-major: `f` gets each
/// block and the number of real points in it. The last block is padded with zeros (a valid
/// position: queries are clamped to the lattice), whose results `f` ignores.
#[allow(clippy::needless_range_loop)] // the axes of a point, unrolled
fn for_each_block<const D: usize>(p: &[f32], mut f: impl FnMut(usize, &[Lane; D], usize)) {
    for (block, points) in p.chunks(D * LANES).enumerate() {
        let mut x = [[0.0f32; LANES]; D];
        for (i, point) in points.chunks_exact(D).enumerate() {
            for axis in 0..D {
                x[axis][i] = point[axis];
            }
        }
        f(block * LANES, &x, points.len() / D);
    }
}

/// [`Backend::float_lattice_sample_columns`] for `D` one-channel lattices of dimension `D` (a
/// staggered grid's components) at points `p [N, D]`: `[N, D]`, each column as [`sample_kernel`]
/// computes it, written in place of the composite's joined columns.
fn sample_columns_kernel<const D: usize>(
    lattices: &[SampleLattice],
    values: &[&[f32]],
    p: &[f32],
) -> Vec<f32> {
    let components: Vec<ComponentSampler<'_, D>> = lattices
        .iter()
        .zip(values)
        .map(|(lattice, values)| ComponentSampler::new(&LatticeIndexer::new(lattice), values))
        .collect();
    let mut out = vec![0.0f32; p.len()];
    for_each_block::<D>(p, |first, x, count| {
        let columns: [Lane; D] = std::array::from_fn(|axis| components[axis].sample_block(x));
        for (i, o) in out[first * D..(first + count) * D]
            .chunks_exact_mut(D)
            .enumerate()
        {
            for (axis, o) in o.iter_mut().enumerate() {
                *o = columns[axis][i];
            }
        }
    });
    out
}

/// Points moved through a staggered velocity as
/// [`composite_advect_points`](crate::fields::sample::composite_advect_points) moves them: the
/// same operations in the same order, so the same values, on blocks of [`LANES`] points stage by
/// stage (each stage depends on the one before, so the independent points of a block are what
/// keeps the pipeline full, and the element-wise steps vectorise).
#[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
fn advect_kernel<const D: usize>(
    lattices: &[SampleLattice],
    values: &[&[f32]],
    p: &[f32],
    dt: f32,
    integrator: Integrator,
) -> Vec<f32> {
    let components: Vec<ComponentSampler<'_, D>> = lattices
        .iter()
        .zip(values)
        .map(|(lattice, values)| ComponentSampler::new(&LatticeIndexer::new(lattice), values))
        .collect();
    let components = &components[..D];
    #[inline(always)]
    fn velocity<const D: usize>(
        components: &[ComponentSampler<'_, D>],
        x: &[Lane; D],
    ) -> [Lane; D] {
        std::array::from_fn(|axis| components[axis].sample_block(x))
    }
    /// `x + k h`, lane by lane.
    #[inline(always)]
    fn step<const D: usize>(x: &[Lane; D], k: &[Lane; D], h: f32) -> [Lane; D] {
        let mut y = [[0.0f32; LANES]; D];
        for axis in 0..D {
            for i in 0..LANES {
                y[axis][i] = x[axis][i] + k[axis][i] * h;
            }
        }
        y
    }
    let (half, sixth) = (0.5 * dt, dt / 6.0);
    let mut out = vec![0.0f32; p.len()];
    for_each_block::<D>(p, |first, x, count| {
        let moved = match integrator {
            Integrator::Euler => step(x, &velocity(components, x), dt),
            Integrator::Rk4 => {
                let k1 = velocity(components, x);
                let k2 = velocity(components, &step(x, &k1, half));
                let k3 = velocity(components, &step(x, &k2, half));
                let k4 = velocity(components, &step(x, &k3, dt));
                let mut moved = [[0.0f32; LANES]; D];
                for axis in 0..D {
                    let [k1, k2, k3, k4] = [&k1[axis], &k2[axis], &k3[axis], &k4[axis]];
                    for i in 0..LANES {
                        moved[axis][i] =
                            x[axis][i] + (k1[i] + k4[i] + (k2[i] + k3[i]) * 2.0) * sixth;
                    }
                }
                moved
            }
        };
        for (i, o) in out[first * D..(first + count) * D]
            .chunks_exact_mut(D)
            .enumerate()
        {
            for axis in 0..D {
                o[axis] = moved[axis][i];
            }
        }
    });
    out
}

/// The tent stencils of `p [N, D]` on a lattice, block by block (vectorised): each point's lower
/// corner (flat index) and its weight per corner (`corner_weights[corner][point]`).
fn linear_stencils<const D: usize>(
    fixed: &FixedIndexer<D>,
    p: &[f32],
) -> (Vec<u32>, Vec<Vec<f32>>) {
    let n = p.len() / D;
    // Whole blocks are appended (a fixed-size copy, inlined, where the `count` real points of the
    // last block would call `memcpy` for every block), and the padding of the last block is cut
    // off afterwards.
    let padded = n.div_ceil(LANES) * LANES;
    let mut flats = Vec::with_capacity(padded);
    let mut corner_weights: Vec<Vec<f32>> =
        (0..1 << D).map(|_| Vec::with_capacity(padded)).collect();
    for_each_block::<D>(p, |_, x, _| {
        let (flat, fraction) = fixed.lower_corners(x);
        flats.extend_from_slice(&flat);
        for (corner, out) in corner_weights.iter_mut().enumerate() {
            let w: Lane = std::array::from_fn(|i| {
                corner_weight::<D>(corner, &std::array::from_fn(|axis| fraction[axis][i]))
            });
            out.extend_from_slice(&w);
        }
    });
    flats.truncate(n);
    for out in &mut corner_weights {
        out.truncate(n);
    }
    (flats, corner_weights)
}

/// [`Backend::float_lattice_splat_columns`] with tent weights for `D` columns onto `D` lattices
/// of dimension `D` (a staggered grid's components): `(sums, weights)` per lattice. The stencils
/// are those of [`splat_kernel`]; the adds of the `D` lattices are interleaved point by point.
/// Each lattice still receives its adds corner-major in point order, so its sums round exactly
/// as [`splat_kernel`]'s; but where consecutive points add to the same sample, each add waits
/// for the one before (through memory), and the other lattices' adds fill that wait.
#[allow(clippy::needless_range_loop)] // corners and lattices index several arrays
fn splat_columns_kernel<const D: usize>(
    lattices: &[SampleLattice],
    v: &[f32],
    p: &[f32],
) -> Vec<(Vec<f32>, Vec<f32>)> {
    let n = p.len() / D;
    assert!(lattices.len() == D && v.len() == n * D);
    let indexers: Vec<LatticeIndexer> = lattices.iter().map(LatticeIndexer::new).collect();
    let stencils: Vec<(Vec<u32>, Vec<Vec<f32>>)> = indexers
        .iter()
        .map(|indexer| linear_stencils(&FixedIndexer::<D>::new(indexer), p))
        .collect();
    let offsets: Vec<[usize; 8]> = indexers.iter().map(corner_offsets::<D>).collect();
    let mut out: Vec<(Vec<f32>, Vec<f32>)> = indexers
        .iter()
        .map(|indexer| {
            let samples: usize = indexer.shape.iter().product();
            (vec![0.0; samples], vec![0.0; samples])
        })
        .collect();
    let flats: [&[u32]; D] = std::array::from_fn(|j| &stencils[j].0[..n]);
    for corner in 0..1 << D {
        let weights: [&[f32]; D] = std::array::from_fn(|j| &stencils[j].1[corner][..n]);
        let offset: [usize; D] = std::array::from_fn(|j| offsets[j][corner]);
        let mut sinks: [(&mut [f32], &mut [f32]); D] = {
            let mut rest = &mut out[..];
            std::array::from_fn(|_| {
                let (first, tail) = std::mem::take(&mut rest)
                    .split_first_mut()
                    .expect("one output per lattice");
                rest = tail;
                (&mut first.0[..], &mut first.1[..])
            })
        };
        for (k, point) in v.chunks_exact(D).enumerate() {
            for j in 0..D {
                let at = flats[j][k] as usize + offset[j];
                let weight = weights[j][k];
                let (sums, sample_weights) = &mut sinks[j];
                debug_assert!(at < sums.len() && at < sample_weights.len());
                // SAFETY: `at` is a corner of a lower corner from `lower_corners`, at most
                // `samples − 1` of lattice `j` (see `ComponentSampler::sample_block`), and both
                // arrays hold that lattice's `samples` values.
                unsafe {
                    *sums.get_unchecked_mut(at) += point[j] * weight;
                    *sample_weights.get_unchecked_mut(at) += weight;
                }
            }
        }
    }
    out
}

/// [`Backend::float_lattice_splat`] on a `D`-dimensional lattice into `(sums [samples, c],
/// weights [samples])`. Tent weights are added corner-major, as the composite scatter adds, so
/// that the sums round the same.
fn splat_kernel<const D: usize>(
    indexer: &LatticeIndexer,
    v: &[f32],
    p: &[f32],
    c: usize,
    transfer: Transfer,
    (sums, weights): (&mut [f32], &mut [f32]),
) {
    let fixed = FixedIndexer::<D>::new(indexer);
    /// Adds `weight · value` to the sums of sample `at` and `weight` to its weight.
    #[inline(always)]
    fn add(sums: &mut [f32], weights: &mut [f32], at: usize, value: &[f32], weight: f32) {
        let c = value.len();
        for (s, &x) in sums[at * c..(at + 1) * c].iter_mut().zip(value) {
            *s += x * weight;
        }
        weights[at] += weight;
    }
    match transfer {
        Transfer::NearestFace => {
            for (point, value) in p.chunks_exact(D).zip(v.chunks_exact(c)) {
                add(sums, weights, nearest_sample(&fixed, point), value, 1.0);
            }
        }
        Transfer::Linear => {
            let offsets = corner_offsets::<D>(indexer);
            let (flats, corner_weights) = linear_stencils(&fixed, p);
            let samples: usize = indexer.shape.iter().product();
            assert!(sums.len() == samples * c && weights.len() == samples);
            for (&offset, corner_weights) in offsets.iter().zip(&corner_weights) {
                let stencils = flats.iter().zip(corner_weights);
                if c == 1 {
                    // One channel (a staggered component): no row slices.
                    for ((&flat, &weight), &x) in stencils.zip(v) {
                        let at = flat as usize + offset;
                        debug_assert!(at < samples);
                        // SAFETY: `at` is a corner of a lower corner from `lower_corners`, at
                        // most `samples − 1` (see `ComponentSampler::sample_block`), and both
                        // arrays hold `samples` values (checked above).
                        unsafe {
                            *sums.get_unchecked_mut(at) += x * weight;
                            *weights.get_unchecked_mut(at) += weight;
                        }
                    }
                } else {
                    for ((&flat, &weight), value) in stencils.zip(v.chunks_exact(c)) {
                        add(sums, weights, flat as usize + offset, value, weight);
                    }
                }
            }
        }
    }
}

/// The flat index of the sample nearest to `point`.
#[inline(always)]
fn nearest_sample<const D: usize>(indexer: &FixedIndexer<D>, point: &[f32]) -> usize {
    (0..D)
        .map(|axis| {
            let t = indexer.continuous(point[axis], axis) + 0.5;
            (t as u32 as f32).min(indexer.upper[axis]) as usize * indexer.strides[axis]
        })
        .sum()
}

// -------------------------------------------------------------------- strided loops
//
// Views (slices, permutes, broadcasts) are read with one loop per row of a collapsed index space
// rather than ndarray's per-element dynamic-rank iteration, which dominates small kernels.

/// Element strides of `t` seen in the (broadcast) `shape`, right-aligned: 0 along the axes where
/// `t` has length 1 or no axis at all.
fn strides_in<T>(t: &Tensor<T>, shape: &[usize]) -> Vec<isize> {
    let offset = shape.len() - t.ndim();
    (0..shape.len())
        .map(|i| {
            if i < offset {
                return 0;
            }
            let k = i - offset;
            if t.shape()[k] == 1 { 0 } else { t.strides()[k] }
        })
        .collect()
}

/// `shape` with its length-1 axes dropped and neighbouring axes merged wherever every operand
/// walks them as one (`stride[i − 1] = stride[i] · shape[i]`); at least one axis is left.
fn collapse<const K: usize>(
    shape: &[usize],
    strides: [Vec<isize>; K],
) -> (Vec<usize>, [Vec<isize>; K]) {
    let mut out_shape: Vec<usize> = Vec::with_capacity(shape.len());
    let mut out: [Vec<isize>; K] = std::array::from_fn(|_| Vec::with_capacity(shape.len()));
    for (i, &n) in shape.iter().enumerate() {
        if n == 1 {
            continue;
        }
        let merge = !out_shape.is_empty()
            && (0..K).all(|k| out[k].last() == Some(&(strides[k][i] * n as isize)));
        if merge {
            *out_shape.last_mut().expect("not empty") *= n;
            for k in 0..K {
                *out[k].last_mut().expect("not empty") = strides[k][i];
            }
        } else {
            out_shape.push(n);
            for k in 0..K {
                out[k].push(strides[k][i]);
            }
        }
    }
    if out_shape.is_empty() {
        out_shape.push(1);
        for stride in &mut out {
            stride.push(0);
        }
    }
    (out_shape, out)
}

/// Calls `row(offsets, len, strides)` for each row of the last axis of a collapsed index space,
/// in row-major order: `offsets` are the operands' element offsets of the row's start.
fn for_each_row<const K: usize>(
    shape: &[usize],
    strides: &[Vec<isize>; K],
    mut row: impl FnMut([isize; K], usize, [isize; K]),
) {
    let last = shape.len() - 1;
    let inner_strides = std::array::from_fn(|k| strides[k][last]);
    let outer: usize = shape[..last].iter().product();
    let mut index = vec![0usize; last];
    let mut offsets = [0isize; K];
    for _ in 0..outer {
        row(offsets, shape[last], inner_strides);
        for axis in (0..last).rev() {
            index[axis] += 1;
            for k in 0..K {
                offsets[k] += strides[k][axis];
            }
            if index[axis] < shape[axis] {
                break;
            }
            for k in 0..K {
                offsets[k] -= strides[k][axis] * shape[axis] as isize;
            }
            index[axis] = 0;
        }
    }
}

/// `f` of each element of `t` broadcast to `shape`, in row-major order.
fn strided_map<T: Copy, U>(t: &Tensor<T>, shape: &[usize], f: impl Fn(T) -> U) -> Vec<U> {
    let (cshape, [st]) = collapse(shape, [strides_in(t, shape)]);
    let mut out = Vec::with_capacity(out_len(shape));
    let base = t.as_ptr();
    for_each_row(&cshape, &[st], |[o], len, [s]| {
        // SAFETY: `strides_in` and `collapse` only re-describe `t`'s own index space (broadcast
        // axes have stride 0), so every offset addresses an element of `t`.
        unsafe {
            if s == 1 {
                let row = std::slice::from_raw_parts(base.offset(o), len);
                out.extend(row.iter().map(|&x| f(x)));
            } else {
                out.extend((0..len).map(|k| f(*base.offset(o + k as isize * s))));
            }
        }
    });
    out
}

/// `f(a, b)` over `shape` (both broadcast to it), in row-major order.
fn strided_zip<T: Copy, U>(
    a: &Tensor<T>,
    b: &Tensor<T>,
    shape: &[usize],
    f: impl Fn(T, T) -> U,
) -> Vec<U> {
    let (cshape, strides) = collapse(shape, [strides_in(a, shape), strides_in(b, shape)]);
    // One row-major operand against one row repeated (a `[1, k]` bias or bound against points
    // `[N, k]`): long loops against the row repeated (`zip_rows`).
    if let ([outer, inner], [sa, sb]) = (&cshape[..], &strides) {
        let (outer, inner) = (*outer, *inner);
        let row = [inner as isize, 1];
        let repeated = [0, 1];
        if sa[..] == row && sb[..] == repeated {
            let (x, y) = (rows_of(a, outer * inner), rows_of(b, inner));
            return zip_rows(x, y, inner, &f);
        }
        if sa[..] == repeated && sb[..] == row {
            let (x, y) = (rows_of(a, inner), rows_of(b, outer * inner));
            return zip_rows(y, x, inner, |y, x| f(x, y));
        }
    }
    let mut out = Vec::with_capacity(out_len(shape));
    let (pa, pb) = (a.as_ptr(), b.as_ptr());
    for_each_row(&cshape, &strides, |[oa, ob], len, [sa, sb]| {
        // SAFETY: as in `strided_map`, every offset addresses an element of its operand.
        unsafe {
            match (sa, sb) {
                (1, 1) => {
                    let x = std::slice::from_raw_parts(pa.offset(oa), len);
                    let y = std::slice::from_raw_parts(pb.offset(ob), len);
                    out.extend(x.iter().zip(y).map(|(&x, &y)| f(x, y)));
                }
                (1, 0) => {
                    let x = std::slice::from_raw_parts(pa.offset(oa), len);
                    let y = *pb.offset(ob);
                    out.extend(x.iter().map(|&x| f(x, y)));
                }
                (0, 1) => {
                    let x = *pa.offset(oa);
                    let y = std::slice::from_raw_parts(pb.offset(ob), len);
                    out.extend(y.iter().map(|&y| f(x, y)));
                }
                _ => out.extend((0..len).map(|k| {
                    let k = k as isize;
                    f(*pa.offset(oa + k * sa), *pb.offset(ob + k * sb))
                })),
            }
        }
    });
    out
}

/// The first `len` elements of `t` in memory order, from its first element (for a view whose
/// collapsed strides say that they are consecutive).
fn rows_of<T>(t: &Tensor<T>, len: usize) -> &[T] {
    assert!(len <= t.len(), "a view holds its own elements");
    // SAFETY: the caller's collapsed strides walk `len` consecutive elements from `t`'s first
    // one, all within `t`'s buffer (its elements, as `strided_map` reads them); checked above
    // that `t` has that many.
    unsafe { std::slice::from_raw_parts(t.as_ptr(), len) }
}

/// `f(x, y)` for each row of `rows` (row-major, rows of `inner`) against the one row `y`.
fn zip_rows<T: Copy, U>(rows: &[T], y: &[T], inner: usize, f: impl Fn(T, T) -> U) -> Vec<U> {
    if inner == 0 {
        return Vec::new();
    }
    // Short rows (point coordinates) are repeated into a pattern of at least 16 values, so that
    // each chunk is one long loop over two slices, which the compiler vectorises.
    let pattern: Vec<T> = y
        .iter()
        .copied()
        .cycle()
        .take(inner * 16usize.div_ceil(inner))
        .collect();
    let mut out = Vec::with_capacity(rows.len());
    let mut chunks = rows.chunks_exact(pattern.len());
    for chunk in &mut chunks {
        out.extend(chunk.iter().zip(&pattern).map(|(&x, &y)| f(x, y)));
    }
    // A whole number of rows: the pattern lines up with it as with every chunk.
    let rest = chunks.remainder();
    out.extend(rest.iter().zip(&pattern).map(|(&x, &y)| f(x, y)));
    out
}

// -------------------------------------------------------------------- matmul

/// Batched matrix product; see [`Backend::float_matmul`].
fn matmul(lhs: &Tensor<f32>, rhs: &Tensor<f32>) -> Tensor<f32> {
    let rank = lhs.ndim();
    let (m, k, n) = (
        lhs.shape()[rank - 2],
        lhs.shape()[rank - 1],
        rhs.shape()[rank - 1],
    );
    let batch: usize = lhs.shape()[..rank - 2].iter().product();
    let mut out_shape = lhs.shape()[..rank - 2].to_vec();
    out_shape.extend([m, n]);
    let mut out = vec![0.0; batch * m * n];
    if out.is_empty() || k == 0 {
        return from_vec(out, &out_shape);
    }
    if rank == 2 {
        // Any strides will do for the gemm kernel: no copy for transposed or sliced operands.
        let a = lhs.view().into_dimensionality::<Ix2>().expect("rank 2");
        let b = rhs.view().into_dimensionality::<Ix2>().expect("rank 2");
        gemm(a, b, &mut out);
        return from_vec(out, &out_shape);
    }
    let a = lhs
        .to_shape(((batch, m, k), Order::RowMajor))
        .expect("same element count");
    let b = rhs
        .to_shape(((batch, k, n), Order::RowMajor))
        .expect("same element count");
    let one = |(i, dst): (usize, &mut [f32])| {
        gemm(a.index_axis(Axis(0), i), b.index_axis(Axis(0), i), dst);
    };
    if batch > 1 && batch * m * n * k >= MATMUL_PAR_WORK {
        out.par_chunks_mut(m * n).enumerate().for_each(one);
    } else {
        out.chunks_mut(m * n).enumerate().for_each(one);
    }
    from_vec(out, &out_shape)
}

/// `out = a · b` for one matrix pair (`out` row-major `[m, n]`), split into blocks of rows on
/// rayon when the product is large. matrixmultiply itself runs on one thread.
fn gemm(a: ArrayView2<'_, f32>, b: ArrayView2<'_, f32>, out: &mut [f32]) {
    let ((m, k), n) = (a.dim(), b.ncols());
    let threads = rayon::current_num_threads();
    if m * k * n < MATMUL_PAR_WORK || threads == 1 || m < 32 {
        let mut c = ArrayViewMut2::from_shape((m, n), out).expect("output sized m × n");
        general_mat_mul(1.0, &a, &b, 0.0, &mut c);
        return;
    }
    // Several blocks per thread for balance, each a multiple of the kernel's 16-row tiles.
    let rows = m.div_ceil(threads * 4).max(32).next_multiple_of(16);
    out.par_chunks_mut(rows * n)
        .enumerate()
        .for_each(|(i, dst)| {
            let start = i * rows;
            let count = dst.len() / n;
            let a = a.slice_axis(Axis(0), Slice::from(start..start + count));
            let mut c =
                ArrayViewMut2::from_shape((count, n), dst).expect("output block sized rows × n");
            general_mat_mul(1.0, &a, &b, 0.0, &mut c);
        });
}

// -------------------------------------------------------------------- gather and scatter

/// `Ok` when every index lies in `0..bound`, else the first one that does not.
fn check_indices(indices: &[i64], bound: usize, op: &'static str) -> Result<()> {
    // A branch-free pass first (negative indices wrap to huge unsigned values), which vectorises;
    // the search for the culprit only runs on failure.
    let valid = indices
        .iter()
        .fold(true, |valid, &i| valid & ((i as u64) < bound as u64));
    if valid {
        return Ok(());
    }
    let outside = |&&i: &&i64| usize::try_from(i).map_or(true, |i| i >= bound);
    match indices.iter().find(outside) {
        Some(&index) => Err(TensorError::IndexOutOfRange { op, index, bound }),
        None => Ok(()),
    }
}

/// Rows of `tensor` picked by `indices` (checked here); see [`Backend::float_gather_rows`].
fn gather_rows<T: Copy + Default + Send + Sync>(
    tensor: &Tensor<T>,
    indices: &Tensor<i64>,
    op: &'static str,
) -> Result<Tensor<T>> {
    let rows = standard(indices);
    check_indices(&rows, tensor.shape()[0], op)?;
    let mut out_shape = tensor.shape().to_vec();
    out_shape[0] = rows.len();
    let width: usize = tensor.shape()[1..].iter().product();
    if width == 0 || rows.is_empty() {
        return Ok(from_vec(Vec::new(), &out_shape));
    }
    let source = standard(tensor);
    let mut data = vec![T::default(); rows.len() * width];
    if data.len() >= PAR_THRESHOLD {
        // Tasks of a few thousand elements: a single narrow row is too little work to schedule.
        let per_task = (PAR_MIN_LEN / width).max(1);
        data.par_chunks_mut(per_task * width)
            .zip(rows.par_chunks(per_task))
            .for_each(|(dst, rows)| gather_into(&source, width, rows, dst));
    } else {
        gather_into(&source, width, &rows, &mut data);
    }
    Ok(from_vec(data, &out_shape))
}

/// `dst[i] = source[rows[i]]` for rows of `width` elements.
fn gather_into<T: Copy>(source: &[T], width: usize, rows: &[i64], dst: &mut [T]) {
    // Narrow rows (scalars, 2-D and 3-D vectors) as fixed-size arrays: one register move per row
    // rather than a call to memcpy.
    match width {
        1 => gather_fixed::<T, 1>(source, rows, dst),
        2 => gather_fixed::<T, 2>(source, rows, dst),
        3 => gather_fixed::<T, 3>(source, rows, dst),
        4 => gather_fixed::<T, 4>(source, rows, dst),
        _ => {
            for (dst, &r) in dst.chunks_exact_mut(width).zip(rows) {
                dst.copy_from_slice(&source[r as usize * width..(r as usize + 1) * width]);
            }
        }
    }
}

/// [`gather_into`] for rows of `W` elements.
fn gather_fixed<T: Copy, const W: usize>(source: &[T], rows: &[i64], dst: &mut [T]) {
    let (source, _) = source.as_chunks::<W>();
    let (dst, _) = dst.as_chunks_mut::<W>();
    for (dst, &r) in dst.iter_mut().zip(rows) {
        *dst = source[r as usize];
    }
}

/// `dst[rows[i]] += values[i]` for rows of `width` elements, in the order of `i`.
fn scatter_add_into(dst: &mut [f32], width: usize, rows: &[i64], values: &[f32]) {
    match width {
        1 => scatter_add_fixed::<1>(dst, rows, values),
        2 => scatter_add_fixed::<2>(dst, rows, values),
        3 => scatter_add_fixed::<3>(dst, rows, values),
        4 => scatter_add_fixed::<4>(dst, rows, values),
        _ => {
            for (&r, src) in rows.iter().zip(values.chunks_exact(width)) {
                let row = &mut dst[r as usize * width..(r as usize + 1) * width];
                for (d, &v) in row.iter_mut().zip(src) {
                    *d += v;
                }
            }
        }
    }
}

/// [`scatter_add_into`] for rows of `W` elements.
fn scatter_add_fixed<const W: usize>(dst: &mut [f32], rows: &[i64], values: &[f32]) {
    let (dst, _) = dst.as_chunks_mut::<W>();
    let (values, _) = values.as_chunks::<W>();
    for (&r, src) in rows.iter().zip(values) {
        for (d, &v) in dst[r as usize].iter_mut().zip(src) {
            *d += v;
        }
    }
}

/// `tensor` with `values[i]` added to row `rows[i]` (rows already checked); repeated rows
/// accumulate in the order of `i`.
///
/// In parallel, each task owns a disjoint part of the output and applies the updates that fall
/// into it in the original order, so the result is bit for bit the sequential one, with no
/// atomics and no write conflicts. Wide rows are split by columns, narrow rows by destination row
/// ranges.
fn scatter_add(tensor: Tensor<f32>, rows: &[i64], values: &Tensor<f32>) -> Tensor<f32> {
    // Reuses the buffer when this is its only owner and it is row-major, else copies once.
    let mut out = if tensor.is_standard_layout() {
        tensor.into_owned()
    } else {
        tensor.as_standard_layout().into_owned()
    };
    let n = out.shape()[0];
    let width: usize = out.shape()[1..].iter().product();
    if width == 0 || rows.is_empty() {
        return out.into_shared();
    }
    let values = standard(values);
    let dst = out.as_slice_mut().expect("row-major");
    let add = |dst: &mut [f32], i: usize| {
        for (d, &v) in dst.iter_mut().zip(&values[i * width..(i + 1) * width]) {
            *d += v;
        }
    };
    let threads = rayon::current_num_threads();
    let work = rows.len() * width;
    // Wide rows: split the columns in whole cache lines. Every task streams through all the
    // values in order, which keeps the hardware prefetcher busy, and load is even however the
    // indices cluster.
    let blocks = threads.min(width / CACHE_LINE_F32);
    if work >= PAR_THRESHOLD && blocks >= 2 {
        let cols = width.div_ceil(blocks).next_multiple_of(CACHE_LINE_F32);
        let mut grid = ArrayViewMut2::from_shape((n, width), dst).expect("rows × width");
        grid.axis_chunks_iter_mut(Axis(1), cols)
            .into_par_iter()
            .enumerate()
            .for_each(|(c, mut block)| {
                let (start, len) = (c * cols, block.ncols());
                for (i, &r) in rows.iter().enumerate() {
                    let dst = block.row_mut(r as usize).into_slice().expect("unit stride");
                    let src = &values[i * width + start..i * width + start + len];
                    for (d, &v) in dst.iter_mut().zip(src) {
                        *d += v;
                    }
                }
            });
        return out.into_shared();
    }
    // Narrow rows: one destination row range per thread; every task scans all the indices and
    // applies those in its range. Scanning costs far less than sorting the updates by range
    // (which would be a sequential pass as slow as the scatter itself), but it is repeated per
    // thread, so it pays only for more work than the other kernels need.
    if work < 4 * PAR_THRESHOLD || threads == 1 || n < 2 {
        scatter_add_into(dst, width, rows, &values);
        return out.into_shared();
    }
    let per_range = n.div_ceil(threads);
    dst.par_chunks_mut(per_range * width)
        .enumerate()
        .for_each(|(b, dst)| {
            let base = b * per_range;
            for (i, &r) in rows.iter().enumerate() {
                // Rows below `base` wrap around to huge values and fail the test too.
                let local = (r as usize).wrapping_sub(base);
                if local < per_range {
                    add(&mut dst[local * width..(local + 1) * width], i);
                }
            }
        });
    out.into_shared()
}

/// Row indices into `tensor` reshaped to `[d₀·…·d_{k-1}, rest...]` for multi-indices `[m, k]`,
/// each component checked against its own axis (an out-of-range component could otherwise alias a
/// valid flat row). Returns the reshaped shape and the flat indices.
fn flat_nd_indices(
    shape: &[usize],
    indices: &Tensor<i64>,
    op: &'static str,
) -> Result<(Vec<usize>, Vec<i64>)> {
    let (m, k) = (indices.shape()[0], indices.shape()[1]);
    let data = standard(indices);
    let mut flat = Vec::with_capacity(m);
    if k > 0 {
        for multi in data.chunks_exact(k) {
            let mut row = 0i64;
            for (&index, &bound) in multi.iter().zip(shape) {
                if usize::try_from(index).map_or(true, |i| i >= bound) {
                    return Err(TensorError::IndexOutOfRange { op, index, bound });
                }
                row = row * bound as i64 + index;
            }
            flat.push(row);
        }
    }
    let mut flat_shape = vec![shape[..k].iter().product()];
    flat_shape.extend_from_slice(&shape[k..]);
    Ok((flat_shape, flat))
}

// -------------------------------------------------------------------- padding

/// The source index along an axis of length `n` for output cell `o`, padded by `before` cells
/// in front; `None` for a constant cell.
fn pad_source(o: usize, n: usize, before: usize, mode: PadMode) -> Option<usize> {
    if (before..before + n).contains(&o) {
        return Some(o - before);
    }
    if n == 0 {
        return None;
    }
    match mode {
        PadMode::Constant(_) => None,
        PadMode::Edge => Some(if o < before { 0 } else { n - 1 }),
        PadMode::Periodic => Some((o as isize - before as isize).rem_euclid(n as isize) as usize),
        PadMode::Symmetric => {
            // Mirror around the edge cell, reflecting again for widths beyond the axis.
            let period = 2 * n;
            let offset = (o as isize - before as isize).rem_euclid(period as isize) as usize;
            Some(if offset < n {
                offset
            } else {
                period - 1 - offset
            })
        }
    }
}

/// What [`pad_fill`] needs besides its position: the source and, per axis, where each output
/// cell comes from.
struct PadPlan<'a> {
    source: &'a [f32],
    source_strides: Vec<usize>,
    /// Per axis, the source index of each output cell (`None`: the constant).
    maps: Vec<Vec<Option<usize>>>,
    /// Per axis, the untouched run: output offset, source length.
    interior: Vec<(usize, usize)>,
    fill: f32,
}

/// Fills `out` (one output block spanning `axis..`) from the source block at `offset`.
fn pad_fill(plan: &PadPlan<'_>, axis: usize, offset: usize, out: &mut [f32]) {
    let map = &plan.maps[axis];
    if axis + 1 == plan.maps.len() {
        let (before, n) = plan.interior[axis];
        out[before..before + n].copy_from_slice(&plan.source[offset..offset + n]);
        let edges = (0..before).chain(before + n..map.len());
        for o in edges {
            out[o] = map[o].map_or(plan.fill, |s| plan.source[offset + s]);
        }
        return;
    }
    let block = out.len() / map.len();
    for (o, out) in out.chunks_exact_mut(block).enumerate() {
        pad_entry(plan, axis, o, offset, out);
    }
}

/// Fills output entry `o` of `axis` (`out` spans the axes after it).
fn pad_entry(plan: &PadPlan<'_>, axis: usize, o: usize, offset: usize, out: &mut [f32]) {
    match plan.maps[axis][o] {
        Some(s) => pad_fill(plan, axis + 1, offset + s * plan.source_strides[axis], out),
        None => out.fill(plan.fill),
    }
}

/// Native padding in one pass over the output; see [`Backend::float_pad`].
fn pad(tensor: Tensor<f32>, widths: &[(usize, usize)], mode: PadMode) -> Tensor<f32> {
    if widths
        .iter()
        .all(|&(before, after)| before == 0 && after == 0)
    {
        return tensor;
    }
    let shape = tensor.shape().to_vec();
    let out_shape: Vec<usize> = shape
        .iter()
        .zip(widths)
        .map(|(&n, &(before, after))| before + n + after)
        .collect();
    let total = out_len(&out_shape);
    if total == 0 {
        return from_vec(Vec::new(), &out_shape);
    }
    let source = standard(&tensor);
    let mut source_strides = vec![1; shape.len()];
    for axis in (0..shape.len().saturating_sub(1)).rev() {
        source_strides[axis] = source_strides[axis + 1] * shape[axis + 1];
    }
    let plan = PadPlan {
        source: &source,
        source_strides,
        maps: shape
            .iter()
            .zip(&out_shape)
            .zip(widths)
            .map(|((&n, &len), &(before, _))| {
                (0..len).map(|o| pad_source(o, n, before, mode)).collect()
            })
            .collect(),
        interior: shape
            .iter()
            .zip(widths)
            .map(|(&n, &(before, _))| (before, n))
            .collect(),
        fill: match mode {
            PadMode::Constant(value) => value,
            _ => 0.0,
        },
    };
    let mut out = vec![0.0; total];
    if shape.len() > 1 && total >= PAR_THRESHOLD {
        let block = total / out_shape[0];
        out.par_chunks_mut(block)
            .enumerate()
            .for_each(|(o, out)| pad_entry(&plan, 0, o, 0, out));
    } else {
        pad_fill(&plan, 0, 0, &mut out);
    }
    from_vec(out, &out_shape)
}

#[cfg(test)]
mod tests {
    use super::*;

    type B = NdArray;
    const D: NdArrayDevice = NdArrayDevice;

    fn f(data: &[f32], shape: &[usize]) -> Tensor<f32> {
        B::float_from_vec(data.to_vec(), shape, &D)
    }

    fn i(data: &[i64], shape: &[usize]) -> Tensor<i64> {
        B::int_from_vec(data.to_vec(), shape, &D)
    }

    fn seq(n: usize) -> Vec<f32> {
        (0..n).map(|x| x as f32).collect()
    }

    /// The lower corners in `f32` (lattices whose flat indices are exact there) equal the
    /// integer ones, which larger lattices take: points inside, on the upper edges (where the
    /// corner is capped) and beyond, including NaN, in 1D to 3D.
    #[test]
    fn lower_corners_in_f32_equal_the_integer_ones() {
        fn check<const D: usize>(shape: &[usize]) {
            let lattice = SampleLattice {
                origin: vec![0.25; D],
                spacing: (0..D).map(|axis| 0.5 + 0.25 * axis as f32).collect(),
                shape: shape.to_vec(),
            };
            let fast = FixedIndexer::<D>::new(&LatticeIndexer::new(&lattice));
            assert!(fast.exact_in_f32);
            let integer = FixedIndexer::<D> {
                exact_in_f32: false,
                ..FixedIndexer::<D>::new(&LatticeIndexer::new(&lattice))
            };
            let mut x = [[0.0f32; LANES]; D];
            for (axis, lane) in x.iter_mut().enumerate() {
                let (step, upper) = (lattice.spacing[axis], shape[axis] as f32 - 1.0);
                for (i, v) in lane.iter_mut().enumerate() {
                    // Sample positions, halfway points, the upper edge and beyond.
                    *v = lattice.origin[axis] + step * (i as f32 * 0.5 - 1.0).min(upper + 1.0);
                }
                lane[LANES - 2] = lattice.origin[axis] + step * upper;
            }
            x[0][LANES - 1] = f32::NAN;
            let (flat, fraction) = fast.lower_corners(&x);
            let (flat_integer, fraction_integer) = integer.lower_corners(&x);
            assert_eq!(flat, flat_integer, "{shape:?}");
            let bits = |f: &[Lane; D]| f.map(|lane| lane.map(f32::to_bits));
            assert_eq!(bits(&fraction), bits(&fraction_integer), "{shape:?}");
        }
        check::<1>(&[9]);
        check::<1>(&[1]);
        check::<2>(&[7, 5]);
        check::<2>(&[6, 1]);
        check::<3>(&[4, 6, 5]);
    }

    /// Reference broadcasting by index arithmetic.
    fn reference_binary(
        a: &[f32],
        sa: &[usize],
        b: &[f32],
        sb: &[usize],
        g: fn(f32, f32) -> f32,
    ) -> Vec<f32> {
        let shape = broadcast_shape(sa, sb);
        let rank = shape.len();
        let pick = |data: &[f32], s: &[usize], index: &[usize]| {
            let offset = rank - s.len();
            let mut flat = 0;
            for (axis, &len) in s.iter().enumerate() {
                flat = flat * len + if len == 1 { 0 } else { index[axis + offset] };
            }
            data[flat]
        };
        let mut out = Vec::new();
        for flat in 0..out_len(&shape) {
            let mut index = vec![0; rank];
            let mut rest = flat;
            for axis in (0..rank).rev() {
                index[axis] = rest % shape[axis];
                rest /= shape[axis];
            }
            out.push(g(pick(a, sa, &index), pick(b, sb, &index)));
        }
        out
    }

    #[test]
    fn broadcasting_across_ranks() {
        let cases: [(&[usize], &[usize]); 10] = [
            (&[3], &[2, 1]),
            (&[2, 1, 3], &[4, 1]),
            (&[1], &[2, 3]),
            (&[2, 3], &[1, 1, 1]),
            (&[5, 1, 4], &[5, 3, 1]),
            (&[0, 3], &[1, 3]),
            // One row against rows of 2, 3 and 5 (the points-against-bounds fast path).
            (&[7, 2], &[1, 2]),
            (&[3], &[4, 3]),
            (&[6, 5], &[5]),
            (&[1, 2], &[9, 2]),
        ];
        for (sa, sb) in cases {
            let (a, b) = (
                seq(out_len(sa)),
                seq(out_len(sb)).iter().map(|x| x + 0.5).collect::<Vec<_>>(),
            );
            let out = B::float_binary(BinaryOp::Sub, f(&a, sa), f(&b, sb));
            assert_eq!(
                B::float_shape(&out),
                broadcast_shape(sa, sb),
                "{sa:?} {sb:?}"
            );
            assert_eq!(
                B::float_to_vec(&out),
                reference_binary(&a, sa, &b, sb, |x, y| x - y)
            );
            let cmp = B::float_compare(CompareOp::Greater, f(&b, sb), f(&a, sa));
            assert_eq!(
                B::float_to_vec(&cmp),
                reference_binary(&b, sb, &a, sa, |x, y| mask(x > y))
            );
        }
        // Large enough for the parallel path.
        let a = seq(300 * 128);
        let b = seq(128);
        let out = B::float_binary(BinaryOp::Mul, f(&a, &[300, 128]), f(&b, &[128]));
        assert_eq!(
            B::float_to_vec(&out),
            reference_binary(&a, &[300, 128], &b, &[128], |x, y| x * y)
        );
    }

    #[test]
    fn where_broadcasts_all_three() {
        let m = f(&[1.0, 0.0], &[2, 1]);
        let t = f(&[1.0, 2.0, 3.0], &[3]);
        let e = f(&[-1.0], &[1, 1, 1]);
        let out = B::float_where(m, t, e);
        assert_eq!(B::float_shape(&out), vec![1, 2, 3]);
        assert_eq!(B::float_to_vec(&out), vec![1.0, 2.0, 3.0, -1.0, -1.0, -1.0]);
    }

    #[test]
    fn views_read_in_row_major_order() {
        let t = f(&seq(24), &[2, 3, 4]);
        let p = B::float_permute(t.clone(), &[2, 0, 1]);
        assert_eq!(B::float_shape(&p), vec![4, 2, 3]);
        let expected: Vec<f32> = (0..4)
            .flat_map(|k| {
                (0..2).flat_map(move |a| (0..3).map(move |b| (a * 12 + b * 4 + k) as f32))
            })
            .collect();
        assert_eq!(B::float_to_vec(&p), expected);
        assert_eq!(
            B::float_to_vec(&B::float_reshape(p.clone(), &[8, 3])),
            expected
        );
        assert_eq!(
            B::float_to_vec(&B::float_unary(UnaryOp::Neg, p)),
            expected.iter().map(|x| -x).collect::<Vec<_>>()
        );

        let s = B::float_slice(t.clone(), &[1..2, 0..3, 1..3]);
        assert_eq!(
            B::float_to_vec(&s),
            vec![13.0, 14.0, 17.0, 18.0, 21.0, 22.0]
        );
        let empty = B::float_slice(t.clone(), &[0..2, 3..3, 0..4]);
        assert_eq!(B::float_shape(&empty), vec![2, 0, 4]);
        assert!(B::float_to_vec(&empty).is_empty());

        let b = B::float_broadcast_to(f(&[1.0, 2.0], &[2, 1]), &[3, 2, 2]);
        assert_eq!(B::float_to_vec(&b), [1.0, 1.0, 2.0, 2.0].repeat(3));

        let c = B::float_concat([s.clone(), f(&[0.5, 0.5, 0.5], &[1, 3, 1])].into(), 2);
        assert_eq!(
            B::float_to_vec(&c),
            vec![13.0, 14.0, 0.5, 17.0, 18.0, 0.5, 21.0, 22.0, 0.5]
        );
    }

    #[test]
    fn scatter_add_accumulates_repeated_indices() {
        let t = f(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], &[3, 2]);
        let out =
            B::float_scatter_add_rows(t, i(&[2, 0, 2, 2], &[4]), f(&seq(8), &[4, 2])).unwrap();
        assert_eq!(B::float_to_vec(&out), vec![3.0, 4.0, 1.0, 1.0, 11.0, 14.0]);

        // Parallel paths (narrow and wide rows, clustered and spread indices) against a plain loop.
        for (width, m) in [(1, 150_000), (2, 70_000), (40, 4000), (128, 1000)] {
            let n = 1000;
            let rows: Vec<i64> = (0..m)
                .map(|k| ((k * 7919) % n / if k % 3 == 0 { 50 } else { 1 }) as i64)
                .collect();
            let values: Vec<f32> = (0..m * width)
                .map(|k| ((k % 97) as f32) * 0.37 - 3.0)
                .collect();
            let base: Vec<f32> = (0..n * width).map(|k| (k % 13) as f32).collect();
            let mut expected = base.clone();
            for (k, &r) in rows.iter().enumerate() {
                for c in 0..width {
                    expected[r as usize * width + c] += values[k * width + c];
                }
            }
            let out = B::float_scatter_add_rows(
                f(&base, &[n, width]),
                i(&rows, &[m]),
                f(&values, &[m, width]),
            )
            .unwrap();
            assert_eq!(B::float_to_vec(&out), expected);
        }

        let nd = B::float_scatter_add_nd(
            B::float_zeros(&[2, 3], &D),
            i(&[1, 2, 0, 0, 1, 2], &[3, 2]),
            f(&[1.0, 2.0, 3.0], &[3]),
        )
        .unwrap();
        assert_eq!(B::float_to_vec(&nd), vec![2.0, 0.0, 0.0, 0.0, 0.0, 4.0]);
    }

    #[test]
    fn gathers_pick_rows() {
        let t = f(&seq(6), &[3, 2]);
        let out = B::float_gather_rows(t.clone(), i(&[2, 2, 0], &[3])).unwrap();
        assert_eq!(B::float_to_vec(&out), vec![4.0, 5.0, 4.0, 5.0, 0.0, 1.0]);
        let nd = B::float_gather_nd(t, i(&[2, 1, 0, 0], &[2, 2])).unwrap();
        assert_eq!(B::float_to_vec(&nd), vec![5.0, 0.0]);
        let big = f(&seq(1000 * 64), &[1000, 64]);
        let rows: Vec<i64> = (0..2000).map(|k| (k * 31) % 1000).collect();
        let out = B::float_to_vec(&B::float_gather_rows(big, i(&rows, &[2000])).unwrap());
        let expected: Vec<f32> = rows
            .iter()
            .flat_map(|&r| (0..64).map(move |c| (r * 64 + c) as f32))
            .collect();
        assert_eq!(out, expected);
    }

    #[test]
    fn bad_indices_are_errors() {
        let t = f(&seq(6), &[3, 2]);
        let err = B::float_gather_rows(t.clone(), i(&[0, 3], &[2])).unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "gather_rows",
                index: 3,
                bound: 3
            }
        );
        let err = B::float_scatter_add_rows(t.clone(), i(&[-1], &[1]), f(&[0.0, 0.0], &[1, 2]))
            .unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "scatter_add_rows",
                index: -1,
                bound: 3
            }
        );
        // [0, 2] would be the valid flat row 2; the second component is checked against its axis.
        let err = B::float_gather_nd(t.clone(), i(&[0, 2], &[1, 2])).unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "gather_nd",
                index: 2,
                bound: 2
            }
        );
        let err = B::int_gather_rows(i(&[1, 2], &[2]), i(&[5], &[1])).unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "int_gather_rows",
                index: 5,
                bound: 2
            }
        );
    }

    #[test]
    fn pad_modes() {
        let t = f(&[1.0, 2.0, 3.0], &[3]);
        let cases = [
            (PadMode::Constant(9.0), vec![9.0, 9.0, 1.0, 2.0, 3.0, 9.0]),
            (PadMode::Edge, vec![1.0, 1.0, 1.0, 2.0, 3.0, 3.0]),
            (PadMode::Periodic, vec![2.0, 3.0, 1.0, 2.0, 3.0, 1.0]),
            (PadMode::Symmetric, vec![2.0, 1.0, 1.0, 2.0, 3.0, 3.0]),
        ];
        for (mode, expected) in cases {
            assert_eq!(
                B::float_to_vec(&B::float_pad(t.clone(), &[(2, 1)], mode)),
                expected,
                "{mode:?}"
            );
        }
        let grid = B::float_pad(f(&seq(4), &[2, 2]), &[(1, 0), (0, 1)], PadMode::Periodic);
        assert_eq!(
            B::float_to_vec(&grid),
            vec![2.0, 3.0, 2.0, 0.0, 1.0, 0.0, 2.0, 3.0, 2.0]
        );
        let empty = B::float_pad(f(&[], &[0, 2]), &[(1, 1), (0, 0)], PadMode::Constant(1.0));
        assert_eq!(B::float_to_vec(&empty), vec![1.0; 4]);
    }

    #[test]
    fn reductions_and_empty_tensors() {
        let t = f(&seq(6), &[2, 3]);
        assert_eq!(
            B::float_to_vec(&B::float_reduce_axis(ReduceOp::Sum, t.clone(), 0)),
            vec![3.0, 5.0, 7.0]
        );
        assert_eq!(
            B::float_to_vec(&B::float_reduce_axis(ReduceOp::Max, t.clone(), 1)),
            vec![2.0, 5.0]
        );
        let p = B::float_permute(t, &[1, 0]);
        assert_eq!(
            B::float_to_vec(&B::float_reduce_axis(ReduceOp::Min, p, 1)),
            vec![0.0, 1.0, 2.0]
        );
        let e = f(&[], &[0, 3]);
        assert_eq!(
            B::float_to_vec(&B::float_reduce(ReduceOp::Sum, e.clone())),
            vec![0.0]
        );
        assert!(B::float_to_vec(&B::float_reduce(ReduceOp::Mean, e.clone()))[0].is_nan());
        assert_eq!(
            B::float_to_vec(&B::float_reduce_axis(ReduceOp::Sum, e.clone(), 0)),
            vec![0.0; 3]
        );
        assert_eq!(
            B::float_shape(&B::float_reduce_axis(ReduceOp::Sum, e, 1)),
            vec![0, 1]
        );
        // Parallel paths: many rows, and few rows with long columns.
        let big: Vec<f32> = (0..64 * 1024).map(|k| (k % 7) as f32).collect();
        let rows = B::float_reduce_axis(ReduceOp::Sum, f(&big, &[1024, 64]), 1);
        let expected: Vec<f32> = big.chunks(64).map(|c| c.iter().sum()).collect();
        assert_eq!(B::float_to_vec(&rows), expected);
        let cols = B::float_reduce_axis(ReduceOp::Max, f(&big, &[2, 512, 64]), 1);
        let big = &big;
        let expected: Vec<f32> = (0..2)
            .flat_map(|a| {
                (0..64).map(move |c| {
                    (0..512)
                        .map(|k| big[a * 512 * 64 + k * 64 + c])
                        .fold(0.0, f32::max)
                })
            })
            .collect();
        assert_eq!(B::float_to_vec(&cols), expected);
    }

    #[test]
    fn integer_division_follows_python() {
        let a = [-7, 7, -7, 7, 0, -6, 6];
        let b = [2, -2, -2, 2, 3, 3, -3];
        for op in [IntBinaryOp::FloorDiv, IntBinaryOp::Rem] {
            let out = B::int_to_vec(&B::int_binary(op, i(&a, &[7]), i(&b, &[7])));
            let expected: Vec<i64> = a.iter().zip(&b).map(|(&x, &y)| op.apply(x, y)).collect();
            assert_eq!(out, expected, "{op:?}");
        }
        assert_eq!(
            B::int_to_vec(&B::float_to_int(f(&[-1.7, 1.7, -0.2], &[3]))),
            vec![-1, 1, 0]
        );
        let mean = B::int_reduce_axis(ReduceOp::Mean, i(&[-3, 0, 2, 5], &[2, 2]), 1);
        assert_eq!(B::int_to_vec(&mean), vec![-1, 3]);
    }

    #[test]
    fn matmul_batched_and_parallel() {
        let a = f(&seq(12), &[2, 2, 3]);
        let b = f(&seq(12), &[2, 3, 2]);
        let out = B::float_matmul(a, b);
        assert_eq!(
            B::float_to_vec(&out),
            vec![10.0, 13.0, 28.0, 40.0, 172.0, 193.0, 244.0, 274.0]
        );
        // A transposed right operand and a product large enough to be split.
        let (m, k, n) = (300, 40, 50);
        let a: Vec<f32> = (0..m * k).map(|x| (x % 11) as f32 - 5.0).collect();
        let bt: Vec<f32> = (0..n * k).map(|x| (x % 7) as f32 - 3.0).collect();
        let b = B::float_permute(f(&bt, &[n, k]), &[1, 0]);
        let out = B::float_to_vec(&B::float_matmul(f(&a, &[m, k]), b));
        for (r, c) in [(0, 0), (123, 17), (m - 1, n - 1)] {
            let expected: f32 = (0..k).map(|j| a[r * k + j] * bt[c * k + j]).sum();
            assert_eq!(out[r * n + c], expected);
        }
        let empty = B::float_matmul(f(&[], &[2, 0]), f(&[], &[0, 3]));
        assert_eq!(B::float_to_vec(&empty), vec![0.0; 6]);
    }
}
