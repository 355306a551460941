//! The [`Backend`] trait: the complete list of primitive operations phi uses.
//!
//! Everything above this module (tensors, fields, the FLIP solver, the GNS) is written once against
//! this trait. A backend supplies two tensor types, a float tensor (`f32`) and an integer tensor
//! (`i64`, used for indices), and implements each operation below on them. Shape checking is not
//! the backend's job: [`crate::tensor::Tensor`] checks every call before it reaches the backend,
//! so a backend may assume that its arguments are consistent with the documented contract, with
//! one exception: index values of gathers and scatters live in tensors and are checked by the
//! backend, which returns [`TensorError::IndexOutOfRange`].
//!
//! # Conventions
//! - Tensors are row-major, `f32` (float) or `i64` (int). Rank 0 does not exist: reductions over
//!   all elements return shape `[1]`.
//! - Operations take their tensor arguments by value (cloning is cheap for every backend: a
//!   reference count or a shallow handle) and return new tensors; nothing is modified in place.
//! - Element-wise binary operations, comparisons and [`Backend::float_where`] broadcast like NumPy:
//!   shapes are aligned at the trailing axis, missing leading axes count as 1, and an axis of
//!   length 1 stretches to the other operand's length.
//! - *Differentiable* means: on an [`AutodiffBackend`], gradients flow through the operation to
//!   its float inputs. Comparisons, casts to int and everything on int tensors are not
//!   differentiable.
//!
//! # Implementations
//! - [`ndarray::NdArray`] (feature `ndarray`): ndarray + rayon, forward only, the fast CPU path.
//! - [`burn::Burn`] (feature `burn`): Burn's autodiff over its CPU backend; wgpu devices with the
//!   `wgpu` feature.
//! - [`tch::Tch`] (feature `tch`): libtorch through tch, with libtorch's autograd; CPU, and CUDA
//!   in binaries that link libtorch's CUDA library (the `phi` package's `cuda` feature).

use std::fmt::Debug;
use std::ops::Range;
use std::sync::Arc;

use rand::SeedableRng;
use rand_distr::Distribution;

use crate::error::{Result, TensorError};
use crate::solve::{SolveError, SolveOptions, SolveStats, SparseMatrix};

#[cfg(feature = "burn")]
pub mod burn;
mod enabled;
#[cfg(feature = "ndarray")]
pub mod ndarray;
#[cfg(feature = "tch")]
pub mod tch;

#[cfg(any(feature = "ndarray", feature = "burn", feature = "tch"))]
pub use enabled::Host;

/// An element-wise function of one float tensor. All are differentiable (the derivative of
/// `Floor` and `Sign` is zero, of `Abs` at 0 and `Relu` at 0 is whatever the engine picks).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum UnaryOp {
    /// `-x`
    Neg,
    /// `√x`
    Sqrt,
    /// `eˣ`
    Exp,
    /// natural logarithm
    Log,
    /// `|x|`
    Abs,
    /// `sin x` (radians)
    Sin,
    /// `cos x` (radians)
    Cos,
    /// `tanh x`
    Tanh,
    /// largest integer `≤ x`
    Floor,
    /// `-1`, `0` or `1`
    Sign,
    /// `max(x, 0)`; NaN stays NaN (as in PyTorch), so a blown-up value is not hidden
    Relu,
    /// `1 / x`
    Recip,
}

impl UnaryOp {
    /// Every variant, for tests that cover the whole enum.
    pub const ALL: [UnaryOp; 12] = [
        UnaryOp::Neg,
        UnaryOp::Sqrt,
        UnaryOp::Exp,
        UnaryOp::Log,
        UnaryOp::Abs,
        UnaryOp::Sin,
        UnaryOp::Cos,
        UnaryOp::Tanh,
        UnaryOp::Floor,
        UnaryOp::Sign,
        UnaryOp::Relu,
        UnaryOp::Recip,
    ];

    /// The function on one `f32`, the reference that backends are tested against.
    pub fn apply(self, x: f32) -> f32 {
        match self {
            UnaryOp::Neg => -x,
            UnaryOp::Sqrt => x.sqrt(),
            UnaryOp::Exp => x.exp(),
            UnaryOp::Log => x.ln(),
            UnaryOp::Abs => x.abs(),
            UnaryOp::Sin => x.sin(),
            UnaryOp::Cos => x.cos(),
            UnaryOp::Tanh => x.tanh(),
            UnaryOp::Floor => x.floor(),
            UnaryOp::Sign => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            UnaryOp::Relu => relu(x),
            UnaryOp::Recip => 1.0 / x,
        }
    }
}

/// `max(x, 0)` keeping NaN (`f32::max` would turn NaN into 0, which would hide a blown-up
/// value from the checks downstream).
#[inline]
pub fn relu(x: f32) -> f32 {
    if x < 0.0 { 0.0 } else { x }
}

/// An element-wise function of two float tensors (broadcasting). All are differentiable in both
/// operands; `Pow` in its exponent only where the base is positive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BinaryOp {
    /// `a + b`
    Add,
    /// `a - b`
    Sub,
    /// `a · b`
    Mul,
    /// `a / b`
    Div,
    /// `aᵇ`
    Pow,
    /// `min(a, b)`
    Min,
    /// `max(a, b)`
    Max,
    /// `atan2(a, b)`: the angle of the point `(b, a)`, in `(-π, π]`
    Atan2,
}

impl BinaryOp {
    /// Every variant, for tests that cover the whole enum.
    pub const ALL: [BinaryOp; 8] = [
        BinaryOp::Add,
        BinaryOp::Sub,
        BinaryOp::Mul,
        BinaryOp::Div,
        BinaryOp::Pow,
        BinaryOp::Min,
        BinaryOp::Max,
        BinaryOp::Atan2,
    ];

    /// The function on two `f32`s, the reference that backends are tested against.
    pub fn apply(self, a: f32, b: f32) -> f32 {
        match self {
            BinaryOp::Add => a + b,
            BinaryOp::Sub => a - b,
            BinaryOp::Mul => a * b,
            BinaryOp::Div => a / b,
            BinaryOp::Pow => a.powf(b),
            BinaryOp::Min => a.min(b),
            BinaryOp::Max => a.max(b),
            BinaryOp::Atan2 => a.atan2(b),
        }
    }
}

/// An element-wise comparison (broadcasting). The result is a float mask: `1.0` where the
/// comparison holds, `0.0` elsewhere. Not differentiable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CompareOp {
    /// `a > b`
    Greater,
    /// `a ≥ b`
    GreaterEqual,
    /// `a < b`
    Less,
    /// `a ≤ b`
    LessEqual,
    /// `a = b`
    Equal,
    /// `a ≠ b`
    NotEqual,
}

impl CompareOp {
    /// Every variant, for tests that cover the whole enum.
    pub const ALL: [CompareOp; 6] = [
        CompareOp::Greater,
        CompareOp::GreaterEqual,
        CompareOp::Less,
        CompareOp::LessEqual,
        CompareOp::Equal,
        CompareOp::NotEqual,
    ];

    /// The comparison on two `f32`s, the reference that backends are tested against.
    pub fn apply(self, a: f32, b: f32) -> bool {
        match self {
            CompareOp::Greater => a > b,
            CompareOp::GreaterEqual => a >= b,
            CompareOp::Less => a < b,
            CompareOp::LessEqual => a <= b,
            CompareOp::Equal => a == b,
            CompareOp::NotEqual => a != b,
        }
    }
}

/// A reduction. `Sum` and `Mean` are differentiable; `Max` and `Min` pass the gradient to the
/// extreme element (which one on ties is the engine's choice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReduceOp {
    /// sum of the elements; 0 when there are none
    Sum,
    /// arithmetic mean; NaN when there are no elements
    Mean,
    /// largest element; needs at least one element
    Max,
    /// smallest element; needs at least one element
    Min,
}

impl ReduceOp {
    /// Every variant, for tests that cover the whole enum.
    pub const ALL: [ReduceOp; 4] = [ReduceOp::Sum, ReduceOp::Mean, ReduceOp::Max, ReduceOp::Min];
}

/// An element-wise function of two integer tensors (broadcasting).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IntBinaryOp {
    /// `a + b`
    Add,
    /// `a - b`
    Sub,
    /// `a · b`
    Mul,
    /// `⌊a / b⌋`, rounding toward negative infinity (Python's `//`)
    FloorDiv,
    /// `a - b·⌊a / b⌋`, with the sign of `b` (Python's `%`)
    Rem,
    /// `min(a, b)`
    Min,
    /// `max(a, b)`
    Max,
}

impl IntBinaryOp {
    /// Every variant, for tests that cover the whole enum.
    pub const ALL: [IntBinaryOp; 7] = [
        IntBinaryOp::Add,
        IntBinaryOp::Sub,
        IntBinaryOp::Mul,
        IntBinaryOp::FloorDiv,
        IntBinaryOp::Rem,
        IntBinaryOp::Min,
        IntBinaryOp::Max,
    ];

    /// The function on two `i64`s, the reference that backends are tested against. `b` must not
    /// be zero for `FloorDiv` and `Rem`.
    pub fn apply(self, a: i64, b: i64) -> i64 {
        match self {
            IntBinaryOp::Add => a + b,
            IntBinaryOp::Sub => a - b,
            IntBinaryOp::Mul => a * b,
            IntBinaryOp::FloorDiv => a.div_euclid(b) - i64::from(b < 0 && a.rem_euclid(b) != 0),
            IntBinaryOp::Rem => {
                let r = a % b;
                if r != 0 && ((r < 0) != (b < 0)) {
                    r + b
                } else {
                    r
                }
            }
            IntBinaryOp::Min => a.min(b),
            IntBinaryOp::Max => a.max(b),
        }
    }
}

/// How [`Backend::float_pad`] fills the new cells, like Φ_Flow's extrapolations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PadMode {
    /// A constant value (Φ_Flow's `ZERO`, `ONE`, ...).
    Constant(f32),
    /// Repeat the edge value (Φ_Flow's `BOUNDARY`, zero-gradient).
    Edge,
    /// Wrap around (Φ_Flow's `PERIODIC`).
    Periodic,
    /// Mirror including the edge value: `[a b c] → b a | a b c | c b` (Φ_Flow's `SYMMETRIC`).
    Symmetric,
}

/// The primitive operations of phi. See the [module docs](self) for the conventions.
///
/// Methods are grouped as: devices and host transfer; creation; shape; element-wise maths;
/// comparisons and selection; reductions; matmul; gather and scatter; casts; integer tensors.
/// Default methods are built from the required ones and are correct for every backend; a backend
/// overrides one where a native implementation is faster.
pub trait Backend: Copy + Clone + Debug + Default + Send + Sync + 'static {
    /// A float (`f32`) tensor.
    type Float: Clone + Debug + Send + 'static;
    /// An integer (`i64`) tensor, used for indices.
    type Int: Clone + Debug + Send + 'static;
    /// Where tensors live (CPU, a GPU).
    type Device: Clone + Debug + PartialEq + Send + Sync + 'static;

    // ---------------------------------------------------------------- devices and host transfer

    /// Short name of the backend, as the command line spells it (`ndarray`, `burn`, `tch`).
    fn name() -> &'static str;
    /// The device tensors are created on when none is named: the CPU.
    fn default_device() -> Self::Device;
    /// The device the command line names `name` (`cpu`; `cuda`, `cuda:N` where a backend has
    /// GPUs), or `None` where this backend has no such device in this process.
    fn device_by_name(name: &str) -> Option<Self::Device> {
        (name == "cpu").then(Self::default_device)
    }
    /// The device `tensor` lives on.
    fn float_device(tensor: &Self::Float) -> Self::Device;
    /// A copy of `tensor` on `device` (the same tensor if it is there already). Differentiable.
    fn float_to_device(tensor: Self::Float, device: &Self::Device) -> Self::Float;
    /// The device `tensor` lives on.
    fn int_device(tensor: &Self::Int) -> Self::Device;
    /// A copy of `tensor` on `device`.
    fn int_to_device(tensor: Self::Int, device: &Self::Device) -> Self::Int;
    /// The shape of `tensor`.
    fn float_shape(tensor: &Self::Float) -> Vec<usize>;
    /// The shape of `tensor`.
    fn int_shape(tensor: &Self::Int) -> Vec<usize>;
    /// The values of `tensor` in row-major order, copied to the host.
    fn float_to_vec(tensor: &Self::Float) -> Vec<f32>;
    /// The values of `tensor` in row-major order on the host: borrowed where the tensor already
    /// lives there in that order (ndarray), else copied as by [`Backend::float_to_vec`].
    fn float_host_values(tensor: &Self::Float) -> std::borrow::Cow<'_, [f32]> {
        std::borrow::Cow::Owned(Self::float_to_vec(tensor))
    }
    /// The values of `tensor` in row-major order, copied to the host.
    fn int_to_vec(tensor: &Self::Int) -> Vec<i64>;

    // ---------------------------------------------------------------- creation

    /// A tensor of `shape` holding `data` in row-major order; `data.len()` is the product of
    /// `shape`.
    fn float_from_vec(data: Vec<f32>, shape: &[usize], device: &Self::Device) -> Self::Float;
    /// An integer tensor of `shape` holding `data` in row-major order.
    fn int_from_vec(data: Vec<i64>, shape: &[usize], device: &Self::Device) -> Self::Int;
    /// A tensor of `shape` with every element `value`.
    fn float_full(shape: &[usize], value: f32, device: &Self::Device) -> Self::Float;

    /// A tensor of `shape` filled with zeros.
    fn float_zeros(shape: &[usize], device: &Self::Device) -> Self::Float {
        Self::float_full(shape, 0.0, device)
    }

    /// `[0, 1, ..., n-1]` as an integer tensor of shape `[n]`.
    fn int_arange(n: usize, device: &Self::Device) -> Self::Int {
        Self::int_from_vec((0..n as i64).collect(), &[n], device)
    }

    /// Uniform random values in `[low, high)` from a generator seeded by `seed`.
    ///
    /// The values are drawn on the host, so one seed gives the same tensor on every backend and
    /// device, whatever the number of threads. The generator is ChaCha8, whose stream is fixed by
    /// reference vectors (unlike `rand`'s `StdRng`, which may change in any release), so a seed
    /// also gives the same tensor in later versions.
    fn float_random_uniform(
        shape: &[usize],
        low: f32,
        high: f32,
        seed: u64,
        device: &Self::Device,
    ) -> Self::Float {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let dist = rand_distr::Uniform::new(low, high).unwrap_or_else(|_| {
            // An empty or inverted interval degenerates to the constant `low`.
            rand_distr::Uniform::new_inclusive(low, low).expect("a point interval is valid")
        });
        let n = shape.iter().product();
        let data = (0..n).map(|_| dist.sample(&mut rng)).collect();
        Self::float_from_vec(data, shape, device)
    }

    /// Normally distributed random values with `mean` and standard deviation `std` (≥ 0) from a
    /// generator seeded by `seed`; like [`Backend::float_random_uniform`], identical on every
    /// backend.
    fn float_random_normal(
        shape: &[usize],
        mean: f32,
        std: f32,
        seed: u64,
        device: &Self::Device,
    ) -> Self::Float {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let dist = rand_distr::Normal::new(mean, std.abs()).expect("std is finite");
        let n = shape.iter().product();
        let data = (0..n).map(|_| dist.sample(&mut rng)).collect();
        Self::float_from_vec(data, shape, device)
    }

    // ---------------------------------------------------------------- shape

    /// The same elements in row-major order under a new shape with as many elements.
    /// Differentiable.
    fn float_reshape(tensor: Self::Float, shape: &[usize]) -> Self::Float;
    /// Axes reordered: output axis `i` is input axis `axes[i]`; `axes` is a permutation.
    /// Differentiable.
    fn float_permute(tensor: Self::Float, axes: &[usize]) -> Self::Float;
    /// The block `ranges[0] × ranges[1] × ...`, one range per axis, each within its axis (an empty
    /// range gives an empty axis). Differentiable.
    fn float_slice(tensor: Self::Float, ranges: &[Range<usize>]) -> Self::Float;
    /// The tensors joined along `axis`; all have the same shape but along `axis`, and there is at
    /// least one. Differentiable.
    fn float_concat(tensors: Vec<Self::Float>, axis: usize) -> Self::Float;
    /// `tensor` repeated to `shape` by NumPy broadcasting. Differentiable (the gradient sums over
    /// the stretched axes).
    fn float_broadcast_to(tensor: Self::Float, shape: &[usize]) -> Self::Float;

    /// The tensors, all of one shape, joined along a new axis at position `axis`.
    /// Differentiable.
    fn float_stack(tensors: Vec<Self::Float>, axis: usize) -> Self::Float {
        let expanded = tensors
            .into_iter()
            .map(|t| {
                let mut shape = Self::float_shape(&t);
                shape.insert(axis, 1);
                Self::float_reshape(t, &shape)
            })
            .collect();
        Self::float_concat(expanded, axis)
    }

    /// `tensor` widened by `widths[axis] = (before, after)` cells on each side of each axis,
    /// filled according to `mode`. `Periodic` and `Symmetric` need `before` and `after` no longer
    /// than the axis. Differentiable.
    fn float_pad(tensor: Self::Float, widths: &[(usize, usize)], mode: PadMode) -> Self::Float {
        let mut result = tensor;
        for (axis, &(before, after)) in widths.iter().enumerate() {
            if before == 0 && after == 0 {
                continue;
            }
            let shape = Self::float_shape(&result);
            let n = shape[axis];
            let block = |range: Range<usize>, t: &Self::Float| {
                let mut ranges: Vec<Range<usize>> = shape.iter().map(|&s| 0..s).collect();
                ranges[axis] = range;
                Self::float_slice(t.clone(), &ranges)
            };
            let side = |width: usize, at_start: bool, t: &Self::Float| -> Vec<Self::Float> {
                let mut side_shape = shape.clone();
                side_shape[axis] = width;
                match mode {
                    PadMode::Constant(value) => {
                        let device = Self::float_device(t);
                        vec![Self::float_full(&side_shape, value, &device)]
                    }
                    PadMode::Edge => {
                        let edge = if at_start {
                            block(0..1, t)
                        } else {
                            block(n - 1..n, t)
                        };
                        vec![Self::float_broadcast_to(edge, &side_shape)]
                    }
                    PadMode::Periodic => {
                        let range = if at_start { n - width..n } else { 0..width };
                        vec![block(range, t)]
                    }
                    PadMode::Symmetric => {
                        // Mirrored copies one cell at a time, so that no flip primitive is needed.
                        let cells: Vec<usize> = if at_start {
                            (0..width).rev().collect()
                        } else {
                            (0..width).map(|k| n - 1 - k).collect()
                        };
                        cells.into_iter().map(|c| block(c..c + 1, t)).collect()
                    }
                }
            };
            let mut parts = Vec::new();
            if before > 0 {
                parts.extend(side(before, true, &result));
            }
            parts.push(result.clone());
            if after > 0 {
                parts.extend(side(after, false, &result));
            }
            result = Self::float_concat(parts, axis);
        }
        result
    }

    // ---------------------------------------------------------------- element-wise maths

    /// `op(tensor)` element by element. Differentiable.
    fn float_unary(op: UnaryOp, tensor: Self::Float) -> Self::Float;
    /// `op(lhs, rhs)` element by element, broadcasting. Differentiable.
    fn float_binary(op: BinaryOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float;
    /// `op(lhs, rhs)` with a scalar right-hand side. Differentiable in `lhs`.
    fn float_binary_scalar(op: BinaryOp, lhs: Self::Float, rhs: f32) -> Self::Float;
    /// Every element limited to `[min, max]` (`min ≤ max`). Differentiable (zero gradient where
    /// clamped).
    fn float_clamp(tensor: Self::Float, min: f32, max: f32) -> Self::Float;

    /// The same values cut off from the computation graph: no gradient flows through the result.
    /// The identity on backends without autodiff.
    fn float_detach(tensor: Self::Float) -> Self::Float {
        tensor
    }

    // ---------------------------------------------------------------- comparisons and selection

    /// `op(lhs, rhs)` element by element, broadcasting, as a `0.0`/`1.0` mask. Not
    /// differentiable.
    fn float_compare(op: CompareOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float;
    /// `op(lhs, rhs)` against a scalar, as a `0.0`/`1.0` mask. Not differentiable.
    fn float_compare_scalar(op: CompareOp, lhs: Self::Float, rhs: f32) -> Self::Float;
    /// `if mask ≠ 0 { on_true } else { on_false }` element by element, broadcasting all three.
    /// Differentiable in `on_true` and `on_false`.
    fn float_where(mask: Self::Float, on_true: Self::Float, on_false: Self::Float) -> Self::Float;

    // ---------------------------------------------------------------- reductions

    /// `op` over all elements, as shape `[1]`. Differentiable (see [`ReduceOp`]).
    fn float_reduce(op: ReduceOp, tensor: Self::Float) -> Self::Float;
    /// `op` over `axis`, which is kept with length 1. Differentiable (see [`ReduceOp`]).
    fn float_reduce_axis(op: ReduceOp, tensor: Self::Float, axis: usize) -> Self::Float;

    // ---------------------------------------------------------------- matmul

    /// Batched matrix product: `[..., m, k] × [..., k, n] → [..., m, n]`. Both operands have the
    /// same rank (≥ 2) and the same batch axes. Differentiable.
    fn float_matmul(lhs: Self::Float, rhs: Self::Float) -> Self::Float;

    // ---------------------------------------------------------------- gather and scatter

    /// Rows of `tensor` picked by `indices`: `[n, ...] × [m] → [m, ...]`, `out[i] =
    /// tensor[indices[i]]`. Indices may repeat. Differentiable in `tensor`.
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] for an index outside `0..n`.
    fn float_gather_rows(tensor: Self::Float, indices: Self::Int) -> Result<Self::Float>;

    /// `tensor` plus `values` added to the rows named by `indices`: `[n, ...] + ([m] → [m, ...])
    /// → [n, ...]`, `out[indices[i]] += values[i]`. Repeated indices accumulate. Differentiable in
    /// `tensor` and `values`.
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] for an index outside `0..n`.
    fn float_scatter_add_rows(
        tensor: Self::Float,
        indices: Self::Int,
        values: Self::Float,
    ) -> Result<Self::Float>;

    /// Elements (or sub-tensors) picked by multi-indices: `tensor [d₀, ..., d_{k-1}, rest...]`,
    /// `indices [m, k]` → `[m, rest...]`, `out[i] = tensor[indices[i, 0], ..., indices[i, k-1]]`.
    /// Differentiable in `tensor`.
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] where `indices[i, j]` is outside `0..d_j`.
    fn float_gather_nd(tensor: Self::Float, indices: Self::Int) -> Result<Self::Float> {
        let shape = Self::float_shape(&tensor);
        let (flat_shape, flat) = flatten_nd_indices::<Self>(&shape, indices, "gather_nd")?;
        Self::float_gather_rows(Self::float_reshape(tensor, &flat_shape), flat)
    }

    /// `tensor` plus `values` added at multi-indices: `tensor [d₀, ..., d_{k-1}, rest...]`,
    /// `indices [m, k]`, `values [m, rest...]`. Repeated indices accumulate. Differentiable in
    /// `tensor` and `values`.
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] where `indices[i, j]` is outside `0..d_j`.
    fn float_scatter_add_nd(
        tensor: Self::Float,
        indices: Self::Int,
        values: Self::Float,
    ) -> Result<Self::Float> {
        let shape = Self::float_shape(&tensor);
        let (flat_shape, flat) = flatten_nd_indices::<Self>(&shape, indices, "scatter_add_nd")?;
        let out =
            Self::float_scatter_add_rows(Self::float_reshape(tensor, &flat_shape), flat, values)?;
        Ok(Self::float_reshape(out, &shape))
    }

    // ---------------------------------------------------------------- casts

    /// Float to int, rounding toward zero (apply [`UnaryOp::Floor`] first for the floor).
    /// Not differentiable.
    fn float_to_int(tensor: Self::Float) -> Self::Int;
    /// Int to float (exact up to 2²⁴). Not differentiable.
    fn int_to_float(tensor: Self::Int) -> Self::Float;

    // ---------------------------------------------------------------- integer tensors

    /// Like [`Backend::float_reshape`].
    fn int_reshape(tensor: Self::Int, shape: &[usize]) -> Self::Int;
    /// Like [`Backend::float_slice`].
    fn int_slice(tensor: Self::Int, ranges: &[Range<usize>]) -> Self::Int;
    /// Like [`Backend::float_concat`].
    fn int_concat(tensors: Vec<Self::Int>, axis: usize) -> Self::Int;
    /// `op(lhs, rhs)` element by element, broadcasting. A zero divisor in `FloorDiv` or `Rem` is
    /// the caller's error (the result is unspecified).
    fn int_binary(op: IntBinaryOp, lhs: Self::Int, rhs: Self::Int) -> Self::Int;
    /// `op(lhs, rhs)` with a scalar right-hand side.
    fn int_binary_scalar(op: IntBinaryOp, lhs: Self::Int, rhs: i64) -> Self::Int;
    /// Every element limited to `[min, max]`.
    fn int_clamp(tensor: Self::Int, min: i64, max: i64) -> Self::Int;
    /// `op` over `axis` (kept with length 1). `Mean` rounds toward zero. Needs at least one
    /// element along `axis` for `Max` and `Min`.
    fn int_reduce_axis(op: ReduceOp, tensor: Self::Int, axis: usize) -> Self::Int;
    /// Rows picked by `indices`, like [`Backend::float_gather_rows`].
    ///
    /// # Errors
    /// [`TensorError::IndexOutOfRange`] for an index outside `0..n`.
    fn int_gather_rows(tensor: Self::Int, indices: Self::Int) -> Result<Self::Int>;

    // ---------------------------------------------------------------- sparse linear solves

    /// The solution `x` of `matrix · x = rhs` and what the solve did. `rhs` is `[n]` or `[n, k]`
    /// (`k` right-hand sides, one per column) with `n = matrix.nrows()` of a square matrix; `x`
    /// has the shape and device of `rhs`. The matrix is a host-side constant (`f64`); the solve
    /// follows `options` (see [`crate::solve`]).
    ///
    /// Differentiable in `rhs` on the autodiff backends, implicitly: the backward pass is one
    /// adjoint solve `Aᵀ y = ∂L/∂x`, giving `∂L/∂rhs = y`, never a differentiation through the
    /// iterations. The default copies `rhs` to the host, solves natively and copies the result
    /// back; it is not differentiable (the result is a fresh, untracked tensor), which is right
    /// for backends without autodiff and must be overridden by those with it.
    ///
    /// # Errors
    /// [`SolveError::NotConverged`] when the tolerance is not reached, [`SolveError::NonFinite`]
    /// for NaN or infinity in `rhs`, and the other [`SolveError`]s of [`crate::solve::solve`].
    fn float_linear_solve(
        matrix: Arc<SparseMatrix>,
        rhs: Self::Float,
        options: &SolveOptions,
    ) -> std::result::Result<(Self::Float, SolveStats), SolveError> {
        let shape = Self::float_shape(&rhs);
        let columns = shape.get(1).copied().unwrap_or(1);
        let data = Self::float_to_vec(&rhs);
        let (x, stats) = crate::solve::solve_f32(&matrix, &data, columns, options)?;
        Ok((
            Self::float_from_vec(x, &shape, &Self::float_device(&rhs)),
            stats,
        ))
    }
}

/// A backend that records operations and computes gradients by reverse-mode differentiation.
///
/// Gradients are asked for explicitly, with the tensors they are wanted for
/// ([`AutodiffBackend::gradients`]); nothing accumulates between calls, so there is no gradient
/// state to reset.
pub trait AutodiffBackend: Backend {
    /// A leaf with the values of `tensor` whose gradient is tracked (a parameter). The result is
    /// cut off from any history `tensor` had.
    fn float_require_grad(tensor: Self::Float) -> Self::Float;
    /// Whether gradients are tracked for `tensor` (a leaf from
    /// [`AutodiffBackend::float_require_grad`] or a result computed from one).
    fn float_is_tracked(tensor: &Self::Float) -> bool;
    /// Backward pass from `loss`, a one-element tensor: `∂loss/∂t` for each `t` in `wrt`, with
    /// the shape of `t`, as untracked tensors. Each `t` is a leaf made by
    /// [`AutodiffBackend::float_require_grad`]; one that `loss` does not depend on gets zeros.
    /// The graph behind `loss` is consumed: differentiate each loss once.
    ///
    /// # Errors
    /// [`TensorError::NotScalar`] when `loss` has more than one element;
    /// [`TensorError::Backend`] when a tensor in `wrt` is not such a leaf (an untracked tensor or
    /// an intermediate result), or when the engine refuses.
    fn gradients(loss: &Self::Float, wrt: &[&Self::Float]) -> Result<Vec<Self::Float>>;
}

/// Flat row indices for an n-d gather or scatter: checks `indices [m, k]` against the first `k`
/// axes of `shape` and returns the shape with those axes merged into one, and the merged indices.
fn flatten_nd_indices<B: Backend>(
    shape: &[usize],
    indices: B::Int,
    op: &'static str,
) -> Result<(Vec<usize>, B::Int)> {
    let index_shape = B::int_shape(&indices);
    let k = index_shape[1];
    let m = index_shape[0];
    // Checked per column, because an out-of-range index in one axis can alias a valid flat index.
    if m > 0 {
        let lowest = B::int_to_vec(&B::int_reduce_axis(ReduceOp::Min, indices.clone(), 0));
        let highest = B::int_to_vec(&B::int_reduce_axis(ReduceOp::Max, indices.clone(), 0));
        for axis in 0..k {
            for index in [lowest[axis], highest[axis]] {
                if index < 0 || index as usize >= shape[axis] {
                    return Err(TensorError::IndexOutOfRange {
                        op,
                        index,
                        bound: shape[axis],
                    });
                }
            }
        }
    }
    let mut strides = vec![1i64; k];
    for axis in (0..k.saturating_sub(1)).rev() {
        strides[axis] = strides[axis + 1] * shape[axis + 1] as i64;
    }
    let device = B::int_device(&indices);
    let strides = B::int_from_vec(strides, &[1, k], &device);
    let weighted = B::int_binary(IntBinaryOp::Mul, indices, strides);
    let flat = B::int_reduce_axis(ReduceOp::Sum, weighted, 1);
    let flat = B::int_reshape(flat, &[m]);
    let rows: usize = shape[..k].iter().product();
    let mut flat_shape = vec![rows];
    flat_shape.extend_from_slice(&shape[k..]);
    Ok((flat_shape, flat))
}
