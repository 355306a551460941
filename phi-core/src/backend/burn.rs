//! [`Burn`]: phi's primitives over Burn's autodiff backend, generic over the inner Burn backend.
//!
//! The float tensor is Burn's autodiff tensor over the inner backend; int tensors are the inner
//! backend's int tensors (Burn does not track ints). Everything is written against Burn's backend
//! primitives (`FloatTensorOps`, `IntTensorOps`, `BoolTensorOps`), not its high-level `Tensor`.
//!
//! Burn's primitives are stricter than phi's contract in a few places, which this module papers
//! over:
//! - Binary operations need operands of equal rank; missing leading axes are prepended here.
//!   Selection (`mask_where`) gets all three operands expanded to the result's shape, so that no
//!   inner backend has to broadcast the mask.
//! - Backends need not handle empty slices, empty index lists or empty reductions; those are
//!   answered here without calling Burn.
//! - Burn's gathers and scatters do not report out-of-range indices (a CPU backend panics, a GPU
//!   one may read out of bounds); indices are checked on the host first.
//! - Burn's `float_detach` keeps a leaf's `require_grad`; phi's detach cuts the tensor off
//!   completely, so it re-wraps the inner primitive instead.
//! - Burn keeps gradients only for leaves (tensors from [`AutodiffBackend::float_require_grad`]);
//!   asking for the gradient of an intermediate result is an error rather than a wrong zero.

use std::fmt;
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::Arc;

use burn_autodiff::Autodiff;
use burn_autodiff::checkpoint::base::Checkpointer;
use burn_autodiff::checkpoint::strategy::NoCheckpointing;
use burn_autodiff::grads::Gradients;
use burn_autodiff::ops::{Backward, Ops, OpsKind, unary};
use burn_backend::ops::{ActivationOps, FloatTensorOps};
use burn_backend::tensor::IndexingUpdateOp;
use burn_backend::{
    AutodiffBackend as BurnAutodiffBackend, BackendTypes, BoolDType, DType, FloatDType, IntDType,
    Scalar, Shape, Slice, TensorData, TensorMetadata, get_or_init_device_settings, try_read_sync,
};
use burn_flex::Flex;

use super::{AutodiffBackend, Backend, BinaryOp, CompareOp, IntBinaryOp, ReduceOp, UnaryOp};
use crate::error::{Result, TensorError};
use crate::solve::{SolveError, SolveOptions, SolveStats, SparseMatrix};

/// The autodiff backend phi drives.
type Ad<I> = Autodiff<I>;
/// The float primitive: Burn's autodiff tensor over `I`.
type FloatPrim<I> = <Autodiff<I> as BackendTypes>::FloatTensorPrimitive;
/// The int primitive, the inner backend's (Burn's autodiff passes ints through untouched).
type IntPrim<I> = <I as BackendTypes>::IntTensorPrimitive;
/// The inner backend's bool primitive.
type BoolPrim<I> = <I as BackendTypes>::BoolTensorPrimitive;

mod sealed {
    /// Keeps [`super::BurnInner`] closed: each inner backend needs a tested command-line name.
    pub trait Sealed {}
}

/// An inner Burn backend that [`Burn`] can run on.
pub trait BurnInner: burn_backend::Backend + sealed::Sealed {
    /// The backend's name on the command line.
    const NAME: &'static str;
}

impl sealed::Sealed for Flex {}

impl BurnInner for Flex {
    const NAME: &'static str = "burn";
}

#[cfg(feature = "wgpu")]
impl sealed::Sealed for burn_wgpu::Wgpu {}

#[cfg(feature = "wgpu")]
impl BurnInner for burn_wgpu::Wgpu {
    const NAME: &'static str = "burn-wgpu";
}

/// Burn's autodiff over the inner backend `I`: Flex (portable CPU) by default.
pub struct Burn<I = Flex>(PhantomData<fn() -> I>);

/// [`Burn`] on a GPU through wgpu (Vulkan, Metal, DX12).
#[cfg(feature = "wgpu")]
pub type BurnWgpu = Burn<burn_wgpu::Wgpu>;

// Written out because derives would demand the bounds of `I` itself.
impl<I> Clone for Burn<I> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<I> Copy for Burn<I> {}

impl<I> Default for Burn<I> {
    fn default() -> Self {
        Self(PhantomData)
    }
}

impl<I> fmt::Debug for Burn<I> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Burn<{}>", std::any::type_name::<I>())
    }
}

// ------------------------------------------------------------------------------------ helpers

fn shape_of(dims: &[usize]) -> Shape {
    Shape::from(dims.to_vec())
}

fn numel(dims: &[usize]) -> usize {
    dims.iter().product()
}

fn inner<I: BurnInner>(tensor: FloatPrim<I>) -> I::FloatTensorPrimitive {
    <Ad<I> as BurnAutodiffBackend>::inner(tensor)
}

/// An untracked autodiff tensor around an inner one.
fn wrap<I: BurnInner>(tensor: I::FloatTensorPrimitive) -> FloatPrim<I> {
    <Ad<I> as BurnAutodiffBackend>::from_inner(tensor)
}

fn bool_dtype<I: BurnInner>(device: &I::Device) -> BoolDType {
    get_or_init_device_settings::<I>(device).bool_dtype
}

/// `i64` where the device has it; wgpu devices often lack 64-bit integers, and there `i32` is
/// the only choice.
fn int_dtype<I: BurnInner>(device: &I::Device) -> IntDType {
    if I::supports_dtype(device, DType::I64) {
        IntDType::I64
    } else {
        IntDType::I32
    }
}

fn read<T>(future: impl Future<Output = std::result::Result<TensorData, T>>) -> TensorData
where
    T: fmt::Debug,
{
    try_read_sync(future)
        .expect("burn: the platform cannot read tensor data synchronously")
        .expect("burn: reading tensor data failed")
}

/// The NumPy broadcast of two shapes of equal rank (the front end has checked they fit).
fn broadcast_dims(lhs: &[usize], rhs: &[usize]) -> Vec<usize> {
    lhs.iter()
        .zip(rhs)
        .map(|(&a, &b)| if a == 1 { b } else { a })
        .collect()
}

/// `dims` with length-1 axes prepended up to `rank`.
fn padded_dims(dims: &[usize], rank: usize) -> Vec<usize> {
    let mut padded = vec![1; rank - dims.len()];
    padded.extend_from_slice(dims);
    padded
}

fn float_align<I: BurnInner>(tensor: FloatPrim<I>, rank: usize) -> FloatPrim<I> {
    let dims = tensor.shape().to_vec();
    if dims.len() == rank {
        tensor
    } else {
        Ad::<I>::float_reshape(tensor, shape_of(&padded_dims(&dims, rank)))
    }
}

fn inner_float_align<I: BurnInner>(
    tensor: I::FloatTensorPrimitive,
    rank: usize,
) -> I::FloatTensorPrimitive {
    let dims = tensor.shape().to_vec();
    if dims.len() == rank {
        tensor
    } else {
        I::float_reshape(tensor, shape_of(&padded_dims(&dims, rank)))
    }
}

fn int_align<I: BurnInner>(tensor: IntPrim<I>, rank: usize) -> IntPrim<I> {
    let dims = tensor.shape().to_vec();
    if dims.len() == rank {
        tensor
    } else {
        I::int_reshape(tensor, shape_of(&padded_dims(&dims, rank)))
    }
}

fn bool_align<I: BurnInner>(tensor: BoolPrim<I>, rank: usize) -> BoolPrim<I> {
    let dims = tensor.shape().to_vec();
    if dims.len() == rank {
        tensor
    } else {
        I::bool_reshape(tensor, shape_of(&padded_dims(&dims, rank)))
    }
}

/// Both operands brought to a common rank (Burn broadcasts only between equal ranks).
fn float_align_pair<I: BurnInner>(
    lhs: FloatPrim<I>,
    rhs: FloatPrim<I>,
) -> (FloatPrim<I>, FloatPrim<I>) {
    let rank = lhs.rank().max(rhs.rank());
    (float_align::<I>(lhs, rank), float_align::<I>(rhs, rank))
}

fn float_expand_to<I: BurnInner>(tensor: FloatPrim<I>, dims: &[usize]) -> FloatPrim<I> {
    if tensor.shape().as_slice() == dims {
        tensor
    } else {
        Ad::<I>::float_expand(tensor, shape_of(dims))
    }
}

fn int_expand_to<I: BurnInner>(tensor: IntPrim<I>, dims: &[usize]) -> IntPrim<I> {
    if tensor.shape().as_slice() == dims {
        tensor
    } else {
        I::int_expand(tensor, shape_of(dims))
    }
}

fn bool_expand_to<I: BurnInner>(tensor: BoolPrim<I>, dims: &[usize]) -> BoolPrim<I> {
    if tensor.shape().as_slice() == dims {
        tensor
    } else {
        I::bool_expand(tensor, shape_of(dims))
    }
}

/// `if mask { on_true } else { on_false }`, broadcasting all three, differentiable in both
/// branches.
fn float_select_where<I: BurnInner>(
    mask: BoolPrim<I>,
    on_true: FloatPrim<I>,
    on_false: FloatPrim<I>,
) -> FloatPrim<I> {
    let rank = mask.rank().max(on_true.rank()).max(on_false.rank());
    let mask = bool_align::<I>(mask, rank);
    let on_true = float_align::<I>(on_true, rank);
    let on_false = float_align::<I>(on_false, rank);
    let out = broadcast_dims(
        &broadcast_dims(mask.shape().as_slice(), on_true.shape().as_slice()),
        on_false.shape().as_slice(),
    );
    Ad::<I>::float_mask_where(
        float_expand_to::<I>(on_false, &out),
        bool_expand_to::<I>(mask, &out),
        float_expand_to::<I>(on_true, &out),
    )
}

/// Both int operands expanded to their common shape.
fn int_broadcast_pair<I: BurnInner>(
    lhs: IntPrim<I>,
    rhs: IntPrim<I>,
) -> (IntPrim<I>, IntPrim<I>, Vec<usize>) {
    let rank = lhs.rank().max(rhs.rank());
    let lhs = int_align::<I>(lhs, rank);
    let rhs = int_align::<I>(rhs, rank);
    let out = broadcast_dims(lhs.shape().as_slice(), rhs.shape().as_slice());
    (
        int_expand_to::<I>(lhs, &out),
        int_expand_to::<I>(rhs, &out),
        out,
    )
}

/// Python's floor division and remainder from whatever rounding the backend's `int_div` uses
/// (truncating on Flex, but the correction below also fixes flooring or Euclidean division):
/// wherever the remainder is non-zero and its sign differs from the divisor's, step the quotient
/// down by one and move the remainder into the divisor's sign.
fn int_floor_div_rem<I: BurnInner>(lhs: IntPrim<I>, rhs: IntPrim<I>) -> (IntPrim<I>, IntPrim<I>) {
    let (lhs, rhs, _) = int_broadcast_pair::<I>(lhs, rhs);
    let device = lhs.device();
    let bools = bool_dtype::<I>(&device);
    let ints = IntDType::from(lhs.dtype());
    let quotient = I::int_div(lhs.clone(), rhs.clone());
    let remainder = I::int_sub(lhs, I::int_mul(quotient.clone(), rhs.clone()));
    let nonzero = I::int_not_equal_elem(remainder.clone(), Scalar::from(0i64), bools);
    let remainder_negative = I::int_lower_elem(remainder.clone(), Scalar::from(0i64), bools);
    let divisor_negative = I::int_lower_elem(rhs.clone(), Scalar::from(0i64), bools);
    let fix = I::bool_and(
        nonzero,
        I::bool_not_equal(remainder_negative, divisor_negative),
    );
    let fix = I::bool_into_int(fix, ints);
    let quotient = I::int_sub(quotient, fix.clone());
    let remainder = I::int_add(remainder, I::int_mul(rhs, fix));
    (quotient, remainder)
}

fn int_empty<I: BurnInner>(dims: &[usize], device: &I::Device) -> IntPrim<I> {
    Burn::<I>::int_from_vec(vec![0; numel(dims)], dims, device)
}

/// Checks that every index lies in `0..bound`, reading only the extremes back to the host.
fn check_indices<I: BurnInner>(indices: &IntPrim<I>, bound: usize, op: &'static str) -> Result<()> {
    // One read for both extremes: every read is a device synchronisation.
    let extremes = I::int_cat(
        vec![I::int_min(indices.clone()), I::int_max(indices.clone())],
        0,
    );
    let extremes = Burn::<I>::int_to_vec(&extremes);
    for index in extremes {
        if index < 0 || index as u64 >= bound as u64 {
            return Err(TensorError::IndexOutOfRange { op, index, bound });
        }
    }
    Ok(())
}

/// Never finished, only prepared: preparing a step is the one public way to ask Burn whether a
/// tensor's node requires gradients, and an unfinished preparation registers nothing.
#[derive(Debug)]
struct TrackingProbe;

impl<B: burn_backend::Backend> Backward<B, 1> for TrackingProbe {
    type State = ();

    fn backward(self, _ops: Ops<(), 1>, _grads: &mut Gradients, _checkpointer: &mut Checkpointer) {}
}

/// The backward step of [`Backend::float_linear_solve`]: `x = A⁻¹ b`, so `∂L/∂b = A⁻ᵀ ∂L/∂x`,
/// one adjoint solve on the host (implicit differentiation; the forward iterations are not
/// unrolled). The matrix is a constant and gets no gradient.
#[derive(Debug)]
struct LinearSolveBackward;

/// What the adjoint solve needs: the matrix (shared, with its cached factorizations) and the
/// forward's options.
#[derive(Debug, Clone)]
struct LinearSolveState {
    matrix: Arc<SparseMatrix>,
    options: SolveOptions,
    columns: usize,
}

impl<I: BurnInner> Backward<I, 1> for LinearSolveBackward {
    type State = LinearSolveState;

    fn backward(
        self,
        ops: Ops<Self::State, 1>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let state = ops.state;
        unary::<I, _>(ops.parents, ops.node, grads, |grad| {
            let shape = grad.shape().to_vec();
            let device = grad.device();
            let values = read(I::float_into_data(grad))
                .try_into_vec_as::<f32>()
                .expect("burn: float data converts to f32");
            // Burn's backward pass cannot return an error: if even the direct fallback of the
            // adjoint solve fails, the gradient is NaN — loud, never a plausible wrong value.
            let adjoint = crate::solve::adjoint_solve_f32(
                &state.matrix,
                &values,
                state.columns,
                &state.options,
            )
            .unwrap_or_else(|_| vec![f32::NAN; values.len()]);
            I::float_from_data(TensorData::new(adjoint, shape), &device)
        });
    }
}

// ------------------------------------------------------------------------------------ Backend

impl<I: BurnInner> Backend for Burn<I> {
    type Float = FloatPrim<I>;
    type Int = IntPrim<I>;
    type Device = I::Device;

    fn name() -> &'static str {
        I::NAME
    }

    fn default_device() -> Self::Device {
        I::Device::default()
    }

    fn float_device(tensor: &Self::Float) -> Self::Device {
        tensor.device()
    }

    fn float_to_device(tensor: Self::Float, device: &Self::Device) -> Self::Float {
        if &tensor.device() == device {
            tensor
        } else {
            Ad::<I>::float_to_device(tensor, device)
        }
    }

    fn int_device(tensor: &Self::Int) -> Self::Device {
        tensor.device()
    }

    fn int_to_device(tensor: Self::Int, device: &Self::Device) -> Self::Int {
        if &tensor.device() == device {
            tensor
        } else {
            I::int_to_device(tensor, device)
        }
    }

    fn float_shape(tensor: &Self::Float) -> Vec<usize> {
        tensor.shape().to_vec()
    }

    fn int_shape(tensor: &Self::Int) -> Vec<usize> {
        tensor.shape().to_vec()
    }

    fn float_to_vec(tensor: &Self::Float) -> Vec<f32> {
        if tensor.shape().num_elements() == 0 {
            return Vec::new();
        }
        read(I::float_into_data(inner::<I>(tensor.clone())))
            .try_into_vec_as::<f32>()
            .expect("burn: float data converts to f32")
    }

    fn int_to_vec(tensor: &Self::Int) -> Vec<i64> {
        if tensor.shape().num_elements() == 0 {
            return Vec::new();
        }
        read(I::int_into_data(tensor.clone()))
            .try_into_vec_as::<i64>()
            .expect("burn: int data converts to i64")
    }

    fn float_from_vec(data: Vec<f32>, shape: &[usize], device: &Self::Device) -> Self::Float {
        Ad::<I>::float_from_data(TensorData::new(data, shape.to_vec()), device)
    }

    fn int_from_vec(data: Vec<i64>, shape: &[usize], device: &Self::Device) -> Self::Int {
        let data = TensorData::new(data, shape.to_vec());
        let data = match int_dtype::<I>(device) {
            IntDType::I64 => data,
            other => data.convert_dtype(other.into()),
        };
        I::int_from_data(data, device)
    }

    fn float_full(shape: &[usize], value: f32, device: &Self::Device) -> Self::Float {
        Ad::<I>::float_full(
            shape_of(shape),
            Scalar::from(value),
            device,
            FloatDType::F32,
        )
    }

    fn float_reshape(tensor: Self::Float, shape: &[usize]) -> Self::Float {
        if tensor.shape().as_slice() == shape {
            tensor
        } else {
            Ad::<I>::float_reshape(tensor, shape_of(shape))
        }
    }

    fn float_permute(tensor: Self::Float, axes: &[usize]) -> Self::Float {
        Ad::<I>::float_permute(tensor, axes)
    }

    fn float_slice(tensor: Self::Float, ranges: &[Range<usize>]) -> Self::Float {
        let dims: Vec<usize> = ranges.iter().map(|r| r.len()).collect();
        if numel(&dims) == 0 {
            // Burn leaves empty slices to its front end; an empty block carries no gradient.
            return Self::float_zeros(&dims, &tensor.device());
        }
        let slices: Vec<Slice> = ranges.iter().map(|r| Slice::from(r.clone())).collect();
        Ad::<I>::float_slice(tensor, &slices)
    }

    fn float_concat(tensors: Vec<Self::Float>, axis: usize) -> Self::Float {
        let mut dims = tensors[0].shape().to_vec();
        dims[axis] = tensors.iter().map(|t| t.shape()[axis]).sum();
        let device = tensors[0].device();
        let mut parts: Vec<Self::Float> = tensors
            .into_iter()
            .filter(|t| t.shape().num_elements() > 0)
            .collect();
        match parts.len() {
            0 => Self::float_zeros(&dims, &device),
            1 => parts.pop().expect("one part"),
            _ => Ad::<I>::float_cat(parts, axis),
        }
    }

    fn float_broadcast_to(tensor: Self::Float, shape: &[usize]) -> Self::Float {
        let tensor = float_align::<I>(tensor, shape.len());
        float_expand_to::<I>(tensor, shape)
    }

    fn float_unary(op: UnaryOp, tensor: Self::Float) -> Self::Float {
        match op {
            UnaryOp::Neg => Ad::<I>::float_neg(tensor),
            UnaryOp::Sqrt => Ad::<I>::float_sqrt(tensor),
            UnaryOp::Exp => Ad::<I>::float_exp(tensor),
            UnaryOp::Log => Ad::<I>::float_log(tensor),
            UnaryOp::Abs => Ad::<I>::float_abs(tensor),
            UnaryOp::Sin => Ad::<I>::float_sin(tensor),
            UnaryOp::Cos => Ad::<I>::float_cos(tensor),
            UnaryOp::Tanh => Ad::<I>::float_tanh(tensor),
            UnaryOp::Floor => Ad::<I>::float_floor(tensor),
            UnaryOp::Sign => Ad::<I>::float_sign(tensor),
            UnaryOp::Relu => Ad::<I>::relu(tensor),
            UnaryOp::Recip => Ad::<I>::float_recip(tensor),
        }
    }

    fn float_binary(op: BinaryOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        let (lhs, rhs) = float_align_pair::<I>(lhs, rhs);
        match op {
            BinaryOp::Add => Ad::<I>::float_add(lhs, rhs),
            BinaryOp::Sub => Ad::<I>::float_sub(lhs, rhs),
            BinaryOp::Mul => Ad::<I>::float_mul(lhs, rhs),
            BinaryOp::Div => Ad::<I>::float_div(lhs, rhs),
            BinaryOp::Pow => Ad::<I>::float_powf(lhs, rhs),
            BinaryOp::Atan2 => Ad::<I>::float_atan2(lhs, rhs),
            BinaryOp::Min | BinaryOp::Max => {
                // Burn has no element-wise min/max of two tensors. Like `f32::min`/`max`, a NaN
                // loses to a number: `lhs` is kept where it wins or where `rhs` is NaN.
                let device = lhs.device();
                let bools = bool_dtype::<I>(&device);
                let (a, b) = (inner::<I>(lhs.clone()), inner::<I>(rhs.clone()));
                let wins = if op == BinaryOp::Max {
                    I::float_greater_equal(a, b.clone(), bools)
                } else {
                    I::float_lower_equal(a, b.clone(), bools)
                };
                let keep_lhs = I::bool_or(wins, I::float_is_nan(b, bools));
                float_select_where::<I>(keep_lhs, lhs, rhs)
            }
        }
    }

    fn float_binary_scalar(op: BinaryOp, lhs: Self::Float, rhs: f32) -> Self::Float {
        let scalar = Scalar::from(rhs);
        match op {
            BinaryOp::Add => Ad::<I>::float_add_scalar(lhs, scalar),
            BinaryOp::Sub => Ad::<I>::float_sub_scalar(lhs, scalar),
            BinaryOp::Mul => Ad::<I>::float_mul_scalar(lhs, scalar),
            BinaryOp::Div => Ad::<I>::float_div_scalar(lhs, scalar),
            BinaryOp::Pow => Ad::<I>::float_powf_scalar(lhs, scalar),
            BinaryOp::Min | BinaryOp::Max | BinaryOp::Atan2 => {
                // Through the tensor path, so that NaN handling matches `float_binary`.
                let device = lhs.device();
                let ones = vec![1; lhs.rank()];
                let rhs = Self::float_full(&ones, rhs, &device);
                Self::float_binary(op, lhs, rhs)
            }
        }
    }

    fn float_clamp(tensor: Self::Float, min: f32, max: f32) -> Self::Float {
        Ad::<I>::float_clamp(tensor, Scalar::from(min), Scalar::from(max))
    }

    fn float_detach(tensor: Self::Float) -> Self::Float {
        wrap::<I>(inner::<I>(tensor))
    }

    fn float_compare(op: CompareOp, lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        let device = lhs.device();
        let bools = bool_dtype::<I>(&device);
        let rank = lhs.rank().max(rhs.rank());
        let lhs = inner_float_align::<I>(inner::<I>(lhs), rank);
        let rhs = inner_float_align::<I>(inner::<I>(rhs), rank);
        let mask = match op {
            CompareOp::Greater => I::float_greater(lhs, rhs, bools),
            CompareOp::GreaterEqual => I::float_greater_equal(lhs, rhs, bools),
            CompareOp::Less => I::float_lower(lhs, rhs, bools),
            CompareOp::LessEqual => I::float_lower_equal(lhs, rhs, bools),
            CompareOp::Equal => I::float_equal(lhs, rhs, bools),
            CompareOp::NotEqual => I::float_not_equal(lhs, rhs, bools),
        };
        wrap::<I>(I::bool_into_float(mask, FloatDType::F32))
    }

    fn float_compare_scalar(op: CompareOp, lhs: Self::Float, rhs: f32) -> Self::Float {
        let device = lhs.device();
        let bools = bool_dtype::<I>(&device);
        let lhs = inner::<I>(lhs);
        let rhs = Scalar::from(rhs);
        let mask = match op {
            CompareOp::Greater => I::float_greater_elem(lhs, rhs, bools),
            CompareOp::GreaterEqual => I::float_greater_equal_elem(lhs, rhs, bools),
            CompareOp::Less => I::float_lower_elem(lhs, rhs, bools),
            CompareOp::LessEqual => I::float_lower_equal_elem(lhs, rhs, bools),
            CompareOp::Equal => I::float_equal_elem(lhs, rhs, bools),
            CompareOp::NotEqual => I::float_not_equal_elem(lhs, rhs, bools),
        };
        wrap::<I>(I::bool_into_float(mask, FloatDType::F32))
    }

    fn float_where(mask: Self::Float, on_true: Self::Float, on_false: Self::Float) -> Self::Float {
        let bools = bool_dtype::<I>(&mask.device());
        let mask = I::float_not_equal_elem(inner::<I>(mask), Scalar::from(0.0f32), bools);
        float_select_where::<I>(mask, on_true, on_false)
    }

    fn float_reduce(op: ReduceOp, tensor: Self::Float) -> Self::Float {
        if tensor.shape().num_elements() == 0 {
            let value = if op == ReduceOp::Mean { f32::NAN } else { 0.0 };
            return Self::float_full(&[1], value, &tensor.device());
        }
        let out = match op {
            ReduceOp::Sum => Ad::<I>::float_sum(tensor),
            ReduceOp::Mean => Ad::<I>::float_mean(tensor),
            ReduceOp::Max => Ad::<I>::float_max(tensor),
            ReduceOp::Min => Ad::<I>::float_min(tensor),
        };
        Self::float_reshape(out, &[1])
    }

    fn float_reduce_axis(op: ReduceOp, tensor: Self::Float, axis: usize) -> Self::Float {
        let dims = tensor.shape().to_vec();
        if numel(&dims) == 0 {
            let mut out = dims.clone();
            out[axis] = 1;
            let value = if op == ReduceOp::Mean && dims[axis] == 0 {
                f32::NAN
            } else {
                0.0
            };
            return Self::float_full(&out, value, &tensor.device());
        }
        match op {
            ReduceOp::Sum => Ad::<I>::float_sum_dim(tensor, axis),
            ReduceOp::Mean => Ad::<I>::float_mean_dim(tensor, axis),
            ReduceOp::Max => Ad::<I>::float_max_dim(tensor, axis),
            ReduceOp::Min => Ad::<I>::float_min_dim(tensor, axis),
        }
    }

    fn float_matmul(lhs: Self::Float, rhs: Self::Float) -> Self::Float {
        let lhs_dims = lhs.shape().to_vec();
        let rhs_dims = rhs.shape().to_vec();
        if numel(&lhs_dims) == 0 || numel(&rhs_dims) == 0 {
            // An empty operand: the product is empty, or all zeros when the inner axis is empty.
            let mut out = lhs_dims.clone();
            let rank = out.len();
            out[rank - 1] = rhs_dims[rank - 1];
            return Self::float_zeros(&out, &lhs.device());
        }
        Ad::<I>::float_matmul(lhs, rhs)
    }

    fn float_gather_rows(tensor: Self::Float, indices: Self::Int) -> Result<Self::Float> {
        let mut dims = tensor.shape().to_vec();
        let m = indices.shape().num_elements();
        if m == 0 {
            dims[0] = 0;
            return Ok(Self::float_zeros(&dims, &tensor.device()));
        }
        check_indices::<I>(&indices, dims[0], "gather_rows")?;
        Ok(Ad::<I>::float_select(tensor, 0, indices))
    }

    fn float_scatter_add_rows(
        tensor: Self::Float,
        indices: Self::Int,
        values: Self::Float,
    ) -> Result<Self::Float> {
        if indices.shape().num_elements() == 0 {
            return Ok(tensor);
        }
        check_indices::<I>(&indices, tensor.shape()[0], "scatter_add_rows")?;
        Ok(Ad::<I>::float_select_assign(
            tensor,
            0,
            indices,
            values,
            IndexingUpdateOp::Add,
        ))
    }

    fn float_to_int(tensor: Self::Float) -> Self::Int {
        let device = tensor.device();
        // Truncated explicitly rather than trusting each backend's cast to round toward zero.
        let truncated = I::float_trunc(inner::<I>(tensor));
        I::float_into_int(truncated, int_dtype::<I>(&device))
    }

    fn int_to_float(tensor: Self::Int) -> Self::Float {
        wrap::<I>(I::int_into_float(tensor, FloatDType::F32))
    }

    fn int_reshape(tensor: Self::Int, shape: &[usize]) -> Self::Int {
        if tensor.shape().as_slice() == shape {
            tensor
        } else {
            I::int_reshape(tensor, shape_of(shape))
        }
    }

    fn int_slice(tensor: Self::Int, ranges: &[Range<usize>]) -> Self::Int {
        let dims: Vec<usize> = ranges.iter().map(|r| r.len()).collect();
        if numel(&dims) == 0 {
            return int_empty::<I>(&dims, &tensor.device());
        }
        let slices: Vec<Slice> = ranges.iter().map(|r| Slice::from(r.clone())).collect();
        I::int_slice(tensor, &slices)
    }

    fn int_concat(tensors: Vec<Self::Int>, axis: usize) -> Self::Int {
        let mut dims = tensors[0].shape().to_vec();
        dims[axis] = tensors.iter().map(|t| t.shape()[axis]).sum();
        let device = tensors[0].device();
        let mut parts: Vec<Self::Int> = tensors
            .into_iter()
            .filter(|t| t.shape().num_elements() > 0)
            .collect();
        match parts.len() {
            0 => int_empty::<I>(&dims, &device),
            1 => parts.pop().expect("one part"),
            _ => I::int_cat(parts, axis),
        }
    }

    fn int_binary(op: IntBinaryOp, lhs: Self::Int, rhs: Self::Int) -> Self::Int {
        match op {
            IntBinaryOp::Add | IntBinaryOp::Sub | IntBinaryOp::Mul => {
                let rank = lhs.rank().max(rhs.rank());
                let (lhs, rhs) = (int_align::<I>(lhs, rank), int_align::<I>(rhs, rank));
                match op {
                    IntBinaryOp::Add => I::int_add(lhs, rhs),
                    IntBinaryOp::Sub => I::int_sub(lhs, rhs),
                    _ => I::int_mul(lhs, rhs),
                }
            }
            IntBinaryOp::FloorDiv => int_floor_div_rem::<I>(lhs, rhs).0,
            IntBinaryOp::Rem => int_floor_div_rem::<I>(lhs, rhs).1,
            IntBinaryOp::Min | IntBinaryOp::Max => {
                let (lhs, rhs, _) = int_broadcast_pair::<I>(lhs, rhs);
                let bools = bool_dtype::<I>(&lhs.device());
                let take_rhs = if op == IntBinaryOp::Max {
                    I::int_lower(lhs.clone(), rhs.clone(), bools)
                } else {
                    I::int_greater(lhs.clone(), rhs.clone(), bools)
                };
                I::int_mask_where(lhs, take_rhs, rhs)
            }
        }
    }

    fn int_binary_scalar(op: IntBinaryOp, lhs: Self::Int, rhs: i64) -> Self::Int {
        match op {
            IntBinaryOp::Add => I::int_add_scalar(lhs, Scalar::from(rhs)),
            IntBinaryOp::Sub => I::int_sub_scalar(lhs, Scalar::from(rhs)),
            IntBinaryOp::Mul => I::int_mul_scalar(lhs, Scalar::from(rhs)),
            IntBinaryOp::Min => I::int_clamp_max(lhs, Scalar::from(rhs)),
            IntBinaryOp::Max => I::int_clamp_min(lhs, Scalar::from(rhs)),
            IntBinaryOp::FloorDiv | IntBinaryOp::Rem => {
                let ones = vec![1; lhs.rank()];
                let rhs = Self::int_from_vec(vec![rhs], &ones, &lhs.device());
                Self::int_binary(op, lhs, rhs)
            }
        }
    }

    fn int_clamp(tensor: Self::Int, min: i64, max: i64) -> Self::Int {
        I::int_clamp(tensor, Scalar::from(min), Scalar::from(max))
    }

    fn int_reduce_axis(op: ReduceOp, tensor: Self::Int, axis: usize) -> Self::Int {
        let dims = tensor.shape().to_vec();
        if numel(&dims) == 0 {
            let mut out = dims;
            out[axis] = 1;
            return int_empty::<I>(&out, &tensor.device());
        }
        match op {
            ReduceOp::Sum => I::int_sum_dim(tensor, axis),
            ReduceOp::Max => I::int_max_dim(tensor, axis),
            ReduceOp::Min => I::int_min_dim(tensor, axis),
            ReduceOp::Mean => {
                // Sum, then divide rounding toward zero whatever rounding `int_div` uses: a
                // flooring division leaves a positive remainder on a negative sum.
                let n = dims[axis] as i64;
                let bools = bool_dtype::<I>(&tensor.device());
                let ints = IntDType::from(tensor.dtype());
                let sum = I::int_sum_dim(tensor, axis);
                let quotient = I::int_div_scalar(sum.clone(), Scalar::from(n));
                let remainder = I::int_sub(
                    sum.clone(),
                    I::int_mul_scalar(quotient.clone(), Scalar::from(n)),
                );
                let fix = I::bool_and(
                    I::int_greater_elem(remainder, Scalar::from(0i64), bools),
                    I::int_lower_elem(sum, Scalar::from(0i64), bools),
                );
                I::int_add(quotient, I::bool_into_int(fix, ints))
            }
        }
    }

    fn int_gather_rows(tensor: Self::Int, indices: Self::Int) -> Result<Self::Int> {
        let mut dims = tensor.shape().to_vec();
        if indices.shape().num_elements() == 0 {
            dims[0] = 0;
            return Ok(int_empty::<I>(&dims, &tensor.device()));
        }
        check_indices::<I>(&indices, dims[0], "int_gather_rows")?;
        Ok(I::int_select(tensor, 0, indices))
    }

    /// Solved on the host; differentiable in `rhs` through [`LinearSolveBackward`], a custom
    /// Burn backward step whose backward is one adjoint solve.
    fn float_linear_solve(
        matrix: Arc<SparseMatrix>,
        rhs: Self::Float,
        options: &SolveOptions,
    ) -> std::result::Result<(Self::Float, SolveStats), SolveError> {
        let shape = rhs.shape().to_vec();
        let columns = shape.get(1).copied().unwrap_or(1);
        let device = rhs.device();
        let values = Self::float_to_vec(&rhs);
        let (x, stats) = crate::solve::solve_f32(&matrix, &values, columns, options)?;
        let out = I::float_from_data(TensorData::new(x, shape), &device);
        let prep = <LinearSolveBackward as Backward<I, 1>>::prepare::<NoCheckpointing>(
            LinearSolveBackward,
            [rhs.node()],
        );
        let out = match prep.compute_bound().stateful() {
            OpsKind::Tracked(prep) => prep.finish(
                LinearSolveState {
                    matrix,
                    options: *options,
                    columns,
                },
                out,
            ),
            OpsKind::UnTracked(prep) => prep.finish(out),
        };
        Ok((out, stats))
    }
}

// ------------------------------------------------------------------------------------ autodiff

impl<I: BurnInner> AutodiffBackend for Burn<I> {
    fn float_require_grad(tensor: Self::Float) -> Self::Float {
        Ad::<I>::float_set_require_grad(Self::float_detach(tensor), true)
    }

    fn float_is_tracked(tensor: &Self::Float) -> bool {
        let prep = <TrackingProbe as Backward<I, 1>>::prepare::<NoCheckpointing>(
            TrackingProbe,
            [tensor.node()],
        );
        matches!(prep.compute_bound().stateful(), OpsKind::Tracked(_))
    }

    fn gradients(loss: &Self::Float, wrt: &[&Self::Float]) -> Result<Vec<Self::Float>> {
        let shape = loss.shape();
        if shape.num_elements() != 1 {
            return Err(TensorError::NotScalar {
                op: "gradients",
                shape: shape.to_vec(),
            });
        }
        // Burn drops the gradients of intermediate results during the backward pass and keeps
        // only those of `float_require_grad` leaves; answering zeros for an intermediate would
        // be silently wrong.
        if let Some(position) = wrt
            .iter()
            .position(|t| !Self::float_is_tracked(t) || !Ad::<I>::float_is_require_grad(t))
        {
            return Err(TensorError::Backend {
                backend: I::NAME,
                message: format!(
                    "gradients: tensor {position} of `wrt` is not a leaf made by require_grad"
                ),
            });
        }
        let zeros = |t: &Self::Float| Self::float_zeros(&t.shape().to_vec(), &t.device());
        if !Self::float_is_tracked(loss) {
            // Nothing behind the loss requires a gradient, so it depends on none of `wrt`.
            return Ok(wrt.iter().map(|t| zeros(t)).collect());
        }
        let grads = Ad::<I>::backward(loss.clone());
        Ok(wrt
            .iter()
            .map(|t| match Ad::<I>::grad(t, &grads) {
                Some(grad) => wrap::<I>(grad),
                None => zeros(t),
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type B = Burn;

    fn device() -> <B as Backend>::Device {
        B::default_device()
    }

    fn t(data: &[f32], shape: &[usize]) -> <B as Backend>::Float {
        B::float_from_vec(data.to_vec(), shape, &device())
    }

    fn ints(data: &[i64], shape: &[usize]) -> <B as Backend>::Int {
        B::int_from_vec(data.to_vec(), shape, &device())
    }

    #[test]
    fn names_and_dtypes() {
        assert_eq!(B::name(), "burn");
        let x = ints(&[1, -2, 3], &[3]);
        assert_eq!(x.dtype(), DType::I64);
        assert_eq!(B::int_to_vec(&x), vec![1, -2, 3]);
        let f = B::float_to_int(t(&[1.7, -1.7, -0.2], &[3]));
        assert_eq!(B::int_to_vec(&f), vec![1, -1, 0]);
    }

    #[test]
    fn broadcasting_across_ranks() {
        let a = t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[2, 3]);
        let b = t(&[10.0, 20.0, 30.0], &[3]);
        let sum = B::float_binary(BinaryOp::Add, a.clone(), b.clone());
        assert_eq!(B::float_shape(&sum), vec![2, 3]);
        assert_eq!(
            B::float_to_vec(&sum),
            vec![11.0, 22.0, 33.0, 14.0, 25.0, 36.0]
        );

        let col = t(&[1.0, 2.0], &[2, 1]);
        let pow = B::float_binary(BinaryOp::Pow, col, t(&[1.0, 2.0, 3.0], &[3]));
        assert_eq!(B::float_to_vec(&pow), vec![1.0, 1.0, 1.0, 2.0, 4.0, 8.0]);

        let max = B::float_binary(BinaryOp::Max, a.clone(), t(&[3.5], &[1]));
        assert_eq!(B::float_to_vec(&max), vec![3.5, 3.5, 3.5, 4.0, 5.0, 6.0]);

        let mask = B::float_compare(CompareOp::Greater, a.clone(), t(&[2.5], &[1]));
        assert_eq!(B::float_to_vec(&mask), vec![0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);

        let picked = B::float_where(t(&[1.0, 0.0], &[2, 1]), a, t(&[-1.0], &[1]));
        assert_eq!(
            B::float_to_vec(&picked),
            vec![1.0, 2.0, 3.0, -1.0, -1.0, -1.0]
        );

        let wide = B::float_broadcast_to(b, &[2, 2, 3]);
        assert_eq!(B::float_shape(&wide), vec![2, 2, 3]);
    }

    #[test]
    fn int_floor_div_and_rem_follow_python() {
        let a = [7, -7, 7, -7, 6, 0];
        let b = [2, 2, -2, -2, 3, -5];
        for op in [IntBinaryOp::FloorDiv, IntBinaryOp::Rem] {
            let out = B::int_binary(op, ints(&a, &[6]), ints(&b, &[6]));
            let expected: Vec<i64> = a.iter().zip(&b).map(|(&x, &y)| op.apply(x, y)).collect();
            assert_eq!(B::int_to_vec(&out), expected, "{op:?}");
        }
        let mean = B::int_reduce_axis(ReduceOp::Mean, ints(&[-3, -4, 3, 4], &[2, 2]), 1);
        assert_eq!(B::int_to_vec(&mean), vec![-3, 3]);
    }

    #[test]
    fn empty_reductions() {
        let empty = t(&[], &[0, 3]);
        assert_eq!(
            B::float_to_vec(&B::float_reduce(ReduceOp::Sum, empty.clone())),
            vec![0.0]
        );
        assert!(B::float_to_vec(&B::float_reduce(ReduceOp::Mean, empty.clone()))[0].is_nan());
        let sum = B::float_reduce_axis(ReduceOp::Sum, empty.clone(), 0);
        assert_eq!(B::float_to_vec(&sum), vec![0.0; 3]);
        let mean = B::float_reduce_axis(ReduceOp::Mean, empty, 0);
        assert!(B::float_to_vec(&mean).iter().all(|v| v.is_nan()));
    }

    #[test]
    fn scatter_add_accumulates_repeated_indices_with_gradients() {
        let base = B::float_require_grad(t(&[0.0; 6], &[3, 2]));
        let values = B::float_require_grad(t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[3, 2]));
        let out = B::float_scatter_add_rows(base.clone(), ints(&[2, 0, 2], &[3]), values.clone())
            .unwrap();
        assert_eq!(B::float_to_vec(&out), vec![3.0, 4.0, 0.0, 0.0, 6.0, 8.0]);

        let weights = t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[3, 2]);
        let loss = B::float_reduce(ReduceOp::Sum, B::float_binary(BinaryOp::Mul, out, weights));
        let grads = B::gradients(&loss, &[&base, &values]).unwrap();
        assert_eq!(
            B::float_to_vec(&grads[0]),
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        );
        assert_eq!(
            B::float_to_vec(&grads[1]),
            vec![5.0, 6.0, 1.0, 2.0, 5.0, 6.0]
        );
    }

    #[test]
    fn bad_indices_are_errors() {
        let x = t(&[1.0, 2.0, 3.0], &[3, 1]);
        let err = B::float_gather_rows(x.clone(), ints(&[0, 3], &[2])).unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "gather_rows",
                index: 3,
                bound: 3
            }
        );
        let err = B::float_scatter_add_rows(x.clone(), ints(&[-1], &[1]), t(&[1.0], &[1, 1]))
            .unwrap_err();
        assert!(matches!(
            err,
            TensorError::IndexOutOfRange { index: -1, .. }
        ));
        let none = B::float_gather_rows(x, ints(&[], &[0])).unwrap();
        assert_eq!(B::float_shape(&none), vec![0, 1]);
    }

    #[test]
    fn gradient_of_sum_of_squares() {
        let x = B::float_require_grad(t(&[1.0, -2.0, 3.0], &[3]));
        assert!(B::float_is_tracked(&x));
        let unrelated = B::float_require_grad(t(&[5.0], &[1]));
        let loss = B::float_reduce(
            ReduceOp::Sum,
            B::float_binary(BinaryOp::Mul, x.clone(), x.clone()),
        );
        assert!(B::float_is_tracked(&loss));
        let grads = B::gradients(&loss, &[&x, &unrelated]).unwrap();
        assert_eq!(B::float_to_vec(&grads[0]), vec![2.0, -4.0, 6.0]);
        assert_eq!(B::float_to_vec(&grads[1]), vec![0.0]);
        assert!(!B::float_is_tracked(&grads[0]));

        let detached = B::float_detach(x.clone());
        assert!(!B::float_is_tracked(&detached));
        assert!(!B::float_is_tracked(&t(&[1.0], &[1])));

        let doubled = B::float_binary_scalar(BinaryOp::Mul, x.clone(), 2.0);
        let loss = B::float_reduce(ReduceOp::Sum, doubled.clone());
        let intermediate = B::gradients(&loss, &[&doubled]).unwrap_err();
        assert!(matches!(intermediate, TensorError::Backend { .. }));

        let not_scalar = B::gradients(&x, &[&x]).unwrap_err();
        assert!(matches!(not_scalar, TensorError::NotScalar { .. }));
    }

    #[test]
    fn gradients_through_where_gather_and_broadcast() {
        let x = B::float_require_grad(t(&[1.0, 2.0, 3.0], &[3]));
        let y = B::float_require_grad(t(&[10.0], &[1]));
        let mask = t(&[1.0, 0.0, 1.0], &[3]);
        let picked = B::float_where(mask, x.clone(), y.clone());
        let rows = B::float_gather_rows(picked, ints(&[0, 0, 1], &[3])).unwrap();
        let loss = B::float_reduce(ReduceOp::Sum, rows);
        let grads = B::gradients(&loss, &[&x, &y]).unwrap();
        assert_eq!(B::float_to_vec(&grads[0]), vec![2.0, 0.0, 0.0]);
        assert_eq!(B::float_to_vec(&grads[1]), vec![1.0]);

        // The gradient of a broadcast operand sums over the axes it was stretched along.
        let row = B::float_require_grad(t(&[1.0, 2.0], &[2]));
        let grid = t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[3, 2]);
        let loss = B::float_reduce(
            ReduceOp::Sum,
            B::float_binary(BinaryOp::Mul, grid, row.clone()),
        );
        let grads = B::gradients(&loss, &[&row]).unwrap();
        assert_eq!(B::float_to_vec(&grads[0]), vec![9.0, 12.0]);
    }
}
