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

mod elementwise;
mod gather;
mod layout;
mod matmul;
mod pad;
mod reduce;
#[cfg(test)]
mod tests;

use elementwise::*;
use gather::*;
use layout::*;
use matmul::*;
use pad::*;
use reduce::*;

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
pub(super) const PAR_MIN_LEN: usize = 4 * 1024;

/// Multiply-adds from which one matrix product is split into blocks of rows.
pub(super) const MATMUL_PAR_WORK: usize = 1 << 18;

/// Length of the blocks that a full sum adds up separately before adding the partial sums. Fixed,
/// so that the rounding does not depend on the number of threads.
pub(super) const SUM_BLOCK: usize = 16 * 1024;

/// `f32`s in a 64-byte cache line: the unit in which parallel scatters split columns, so that
/// threads rarely write to one line.
pub(super) const CACHE_LINE_F32: usize = 16;

pub(super) type Tensor<T> = ArcArray<T, IxDyn>;

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
            UnaryOp::Relu => map(t, super::relu),
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
}
