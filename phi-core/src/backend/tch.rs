//! [`Tch`]: the [`Backend`] over libtorch through the `tch` crate, on the CPU or a CUDA device,
//! with libtorch's own autograd as its [`AutodiffBackend`].
//!
//! Every call into libtorch goes through tch's fallible `f_*` functions, so a C++ exception comes
//! back as a Rust error instead of aborting the process. Where the trait returns a `Result` the
//! error becomes [`TensorError::Backend`]; elsewhere the front end has already checked the shapes,
//! so an error there is a bug (or the device running out of memory) and panics with libtorch's
//! message.
//!
//! Floats are always `Kind::Float` and integers `Kind::Int64`: operations whose libtorch result
//! has another kind (comparisons give `Bool`) are cast back.

use std::ffi::{c_char, c_void};
use std::fmt;
use std::ops::Range;
use std::sync::{Arc, Mutex};

use tch::{Device, Kind, TchError, Tensor};

use super::{
    AutodiffBackend, Backend, BinaryOp, CompareOp, IntBinaryOp, PadMode, ReduceOp, UnaryOp,
};
use crate::error::{Result, TensorError};
use crate::solve::{SolveError, SolveOptions, SolveStats, SparseMatrix};

/// The libtorch backend. Tensors live on a [`tch::Device`]; the default is the CPU.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tch;

/// A float (`f32`, `Kind::Float`) libtorch tensor.
///
/// Cloning is shallow: the clone shares storage and autograd history with the original, which is
/// safe because no backend operation modifies a tensor in place.
pub struct TchTensor(pub Tensor);

/// An integer (`i64`, `Kind::Int64`) libtorch tensor; cloning is shallow as for [`TchTensor`].
pub struct TchIntTensor(pub Tensor);

impl Clone for TchTensor {
    fn clone(&self) -> Self {
        Self(self.0.shallow_clone())
    }
}

impl Clone for TchIntTensor {
    fn clone(&self) -> Self {
        Self(self.0.shallow_clone())
    }
}

/// Shape, kind and device only: printing the data would copy it from the device.
fn describe(name: &str, tensor: &Tensor, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    if !tensor.defined() {
        return write!(f, "{name}(undefined)");
    }
    f.debug_struct(name)
        .field("shape", &tensor.size())
        .field("kind", &tensor.f_kind().ok())
        .field("device", &tensor.device())
        .field("requires_grad", &tensor.requires_grad())
        .finish()
}

impl fmt::Debug for TchTensor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        describe("TchTensor", &self.0, f)
    }
}

impl fmt::Debug for TchIntTensor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        describe("TchIntTensor", &self.0, f)
    }
}

// ------------------------------------------------------------------------------------ helpers

/// The value of a libtorch call whose arguments the front end has validated; an error here is a
/// bug or an exhausted device, which the infallible trait method can only report by panicking.
#[track_caller]
fn ok<T>(result: std::result::Result<T, TchError>, op: &str) -> T {
    match result {
        Ok(value) => value,
        Err(err) => panic!("tch backend: {op} failed: {err}"),
    }
}

fn backend_error(err: TchError) -> TensorError {
    TensorError::Backend {
        backend: "tch",
        message: err.to_string(),
    }
}

fn dims(shape: &[usize]) -> Vec<i64> {
    shape.iter().map(|&d| d as i64).collect()
}

fn shape_of(tensor: &Tensor) -> Vec<usize> {
    tensor.size().into_iter().map(|d| d as usize).collect()
}

fn float(tensor: Tensor) -> TchTensor {
    TchTensor(tensor)
}

fn int(tensor: Tensor) -> TchIntTensor {
    TchIntTensor(tensor)
}

/// A comparison's `Bool` result as the trait's float mask.
fn mask(result: std::result::Result<Tensor, TchError>, op: &str) -> TchTensor {
    float(ok(result.and_then(|m| m.f_to_kind(Kind::Float)), op))
}

fn reshape(tensor: &Tensor, shape: &[usize], op: &str) -> Tensor {
    ok(tensor.f_reshape(dims(shape)), op)
}

fn slice(tensor: &Tensor, ranges: &[Range<usize>], op: &str) -> Tensor {
    let mut out = tensor.shallow_clone();
    for (axis, range) in ranges.iter().enumerate() {
        if range.start == 0 && range.end as i64 == out.size()[axis] {
            continue;
        }
        let length = range.end.saturating_sub(range.start);
        out = ok(
            out.f_narrow(axis as i64, range.start as i64, length as i64),
            op,
        );
    }
    out
}

fn concat(tensors: &[Tensor], axis: usize, op: &str) -> Tensor {
    if tensors.len() == 1 {
        return tensors[0].shallow_clone();
    }
    ok(Tensor::f_cat(tensors, axis as i64), op)
}

/// Checks that every index in `indices` lies in `0..bound`, before libtorch sees them: on CUDA an
/// out-of-range index is a device-side assert that poisons the whole context. Returns the
/// offending index (the lowest if it is negative, else the highest) in the error.
fn check_indices(indices: &Tensor, bound: usize, op: &'static str) -> Result<()> {
    if indices.numel() == 0 {
        return Ok(());
    }
    let extremes = indices
        .f_min()
        .and_then(|lowest| Tensor::f_stack(&[lowest, indices.f_max()?], 0))
        .map_err(backend_error)?;
    let mut host = [0i64; 2];
    extremes.f_copy_data(&mut host, 2).map_err(backend_error)?;
    let [lowest, highest] = host;
    let offending = if lowest < 0 {
        Some(lowest)
    } else if highest >= bound as i64 {
        Some(highest)
    } else {
        None
    };
    match offending {
        Some(index) => Err(TensorError::IndexOutOfRange { op, index, bound }),
        None => Ok(()),
    }
}

/// `tensor` padded along one axis, the sides built from views of `tensor` so that autograd sees
/// only narrow, flip, expand and cat.
fn pad_axis(tensor: &Tensor, axis: usize, before: usize, after: usize, mode: PadMode) -> Tensor {
    const OP: &str = "pad";
    let shape = shape_of(tensor);
    let n = shape[axis] as i64;
    let dim = axis as i64;
    let side = |width: usize, at_start: bool| -> Tensor {
        let width = width as i64;
        match mode {
            PadMode::Constant(_) => unreachable!("constant padding is done in one call"),
            PadMode::Edge => {
                let edge = ok(
                    tensor.f_narrow(dim, if at_start { 0 } else { n - 1 }, 1),
                    OP,
                );
                let mut side_shape = dims(&shape);
                side_shape[axis] = width;
                ok(edge.f_expand(side_shape, false), OP)
            }
            PadMode::Periodic => {
                let start = if at_start { n - width } else { 0 };
                ok(tensor.f_narrow(dim, start, width), OP)
            }
            PadMode::Symmetric => {
                // Mirrored including the edge cell: the first `width` cells reversed.
                let start = if at_start { 0 } else { n - width };
                ok(
                    tensor
                        .f_narrow(dim, start, width)
                        .and_then(|t| t.f_flip([dim])),
                    OP,
                )
            }
        }
    };
    let mut parts = Vec::with_capacity(3);
    if before > 0 {
        parts.push(side(before, true));
    }
    parts.push(tensor.shallow_clone());
    if after > 0 {
        parts.push(side(after, false));
    }
    concat(&parts, axis, OP)
}

/// `divisor` with zeros replaced by ones: integer division by zero throws on the CPU, and the
/// trait leaves that result unspecified, so it must not take the process down.
fn nonzero_divisor(divisor: &Tensor) -> Tensor {
    ok(
        divisor
            .f_eq(0)
            .and_then(|zero| zero.f_to_kind(Kind::Int64))
            .and_then(|zero| divisor.f_add(&zero)),
        "int_binary",
    )
}

impl Backend for Tch {
    type Float = TchTensor;
    type Int = TchIntTensor;
    type Device = Device;

    // ---------------------------------------------------------------- devices and host transfer

    fn name() -> &'static str {
        "tch"
    }

    fn default_device() -> Device {
        Device::Cpu
    }

    fn device_by_name(name: &str) -> Option<Device> {
        let ordinal = match name {
            "cpu" => return Some(Device::Cpu),
            "cuda" => 0,
            _ => name.strip_prefix("cuda:")?.parse::<usize>().ok()?,
        };
        let devices = usize::try_from(tch::Cuda::device_count()).unwrap_or(0);
        (ordinal < devices).then_some(Device::Cuda(ordinal))
    }

    fn float_device(tensor: &TchTensor) -> Device {
        tensor.0.device()
    }

    fn float_to_device(tensor: TchTensor, device: &Device) -> TchTensor {
        if tensor.0.device() == *device {
            return tensor;
        }
        float(ok(tensor.0.f_to_device(*device), "float_to_device"))
    }

    fn int_device(tensor: &TchIntTensor) -> Device {
        tensor.0.device()
    }

    fn int_to_device(tensor: TchIntTensor, device: &Device) -> TchIntTensor {
        if tensor.0.device() == *device {
            return tensor;
        }
        int(ok(tensor.0.f_to_device(*device), "int_to_device"))
    }

    fn float_shape(tensor: &TchTensor) -> Vec<usize> {
        shape_of(&tensor.0)
    }

    fn int_shape(tensor: &TchIntTensor) -> Vec<usize> {
        shape_of(&tensor.0)
    }

    fn float_to_vec(tensor: &TchTensor) -> Vec<f32> {
        let n = tensor.0.numel();
        let mut data = vec![0.0f32; n];
        if n > 0 {
            // copy_data makes a contiguous host copy first, whatever the strides and device.
            ok(tensor.0.f_copy_data(&mut data, n), "float_to_vec");
        }
        data
    }

    fn int_to_vec(tensor: &TchIntTensor) -> Vec<i64> {
        let n = tensor.0.numel();
        let mut data = vec![0i64; n];
        if n > 0 {
            ok(tensor.0.f_copy_data(&mut data, n), "int_to_vec");
        }
        data
    }

    // ---------------------------------------------------------------- creation

    fn float_from_vec(data: Vec<f32>, shape: &[usize], device: &Device) -> TchTensor {
        let flat = ok(Tensor::f_from_slice(&data), "float_from_vec");
        let shaped = reshape(&flat, shape, "float_from_vec");
        Self::float_to_device(float(shaped), device)
    }

    fn int_from_vec(data: Vec<i64>, shape: &[usize], device: &Device) -> TchIntTensor {
        let flat = ok(Tensor::f_from_slice(&data), "int_from_vec");
        let shaped = reshape(&flat, shape, "int_from_vec");
        Self::int_to_device(int(shaped), device)
    }

    fn float_full(shape: &[usize], value: f32, device: &Device) -> TchTensor {
        let options = (Kind::Float, *device);
        float(ok(
            Tensor::f_full(dims(shape), f64::from(value), options),
            "float_full",
        ))
    }

    fn float_zeros(shape: &[usize], device: &Device) -> TchTensor {
        float(ok(
            Tensor::f_zeros(dims(shape), (Kind::Float, *device)),
            "float_zeros",
        ))
    }

    fn int_arange(n: usize, device: &Device) -> TchIntTensor {
        int(ok(
            Tensor::f_arange(n as i64, (Kind::Int64, *device)),
            "int_arange",
        ))
    }

    // ---------------------------------------------------------------- shape

    fn float_reshape(tensor: TchTensor, shape: &[usize]) -> TchTensor {
        float(reshape(&tensor.0, shape, "float_reshape"))
    }

    fn float_permute(tensor: TchTensor, axes: &[usize]) -> TchTensor {
        float(ok(tensor.0.f_permute(dims(axes)), "float_permute"))
    }

    fn float_slice(tensor: TchTensor, ranges: &[Range<usize>]) -> TchTensor {
        float(slice(&tensor.0, ranges, "float_slice"))
    }

    fn float_concat(tensors: Vec<TchTensor>, axis: usize) -> TchTensor {
        let tensors: Vec<Tensor> = tensors.into_iter().map(|t| t.0).collect();
        float(concat(&tensors, axis, "float_concat"))
    }

    fn float_broadcast_to(tensor: TchTensor, shape: &[usize]) -> TchTensor {
        // A strided view, not a copy: nothing writes into tensors in place, and every later
        // operation (reshape included) copies where the layout needs it.
        float(ok(
            tensor.0.f_expand(dims(shape), false),
            "float_broadcast_to",
        ))
    }

    fn float_stack(tensors: Vec<TchTensor>, axis: usize) -> TchTensor {
        let tensors: Vec<Tensor> = tensors.into_iter().map(|t| t.0).collect();
        float(ok(Tensor::f_stack(&tensors, axis as i64), "float_stack"))
    }

    fn float_pad(tensor: TchTensor, widths: &[(usize, usize)], mode: PadMode) -> TchTensor {
        if widths
            .iter()
            .all(|&(before, after)| before == 0 && after == 0)
        {
            return tensor;
        }
        if let PadMode::Constant(value) = mode {
            // torch's pad list runs from the last axis backwards, (before, after) per axis.
            let pad: Vec<i64> = widths
                .iter()
                .rev()
                .flat_map(|&(before, after)| [before as i64, after as i64])
                .collect();
            return float(ok(tensor.0.f_pad(pad, "constant", f64::from(value)), "pad"));
        }
        // torch's own modes differ from the trait's (its "reflect" leaves out the edge cell) and
        // only cover the last few axes, so the sides are built per axis.
        let mut result = tensor.0;
        for (axis, &(before, after)) in widths.iter().enumerate() {
            if before > 0 || after > 0 {
                result = pad_axis(&result, axis, before, after, mode);
            }
        }
        float(result)
    }

    // ---------------------------------------------------------------- element-wise maths

    fn float_unary(op: UnaryOp, tensor: TchTensor) -> TchTensor {
        let t = &tensor.0;
        let result = match op {
            UnaryOp::Neg => t.f_neg(),
            UnaryOp::Sqrt => t.f_sqrt(),
            UnaryOp::Exp => t.f_exp(),
            UnaryOp::Log => t.f_log(),
            UnaryOp::Abs => t.f_abs(),
            UnaryOp::Sin => t.f_sin(),
            UnaryOp::Cos => t.f_cos(),
            UnaryOp::Tanh => t.f_tanh(),
            UnaryOp::Floor => t.f_floor(),
            UnaryOp::Sign => t.f_sign(),
            UnaryOp::Relu => t.f_relu(),
            UnaryOp::Recip => t.f_reciprocal(),
        };
        float(ok(result, "float_unary"))
    }

    fn float_binary(op: BinaryOp, lhs: TchTensor, rhs: TchTensor) -> TchTensor {
        let (a, b) = (&lhs.0, &rhs.0);
        let result = match op {
            BinaryOp::Add => a.f_add(b),
            BinaryOp::Sub => a.f_sub(b),
            BinaryOp::Mul => a.f_mul(b),
            BinaryOp::Div => a.f_div(b),
            BinaryOp::Pow => a.f_pow(b),
            // fmin/fmax rather than minimum/maximum: they skip a NaN operand like f32::min/max.
            BinaryOp::Min => a.f_fmin(b),
            BinaryOp::Max => a.f_fmax(b),
            BinaryOp::Atan2 => a.f_atan2(b),
        };
        float(ok(result, "float_binary"))
    }

    fn float_binary_scalar(op: BinaryOp, lhs: TchTensor, rhs: f32) -> TchTensor {
        let (a, b) = (&lhs.0, f64::from(rhs));
        let as_tensor = || Tensor::f_scalar_tensor(b, (Kind::Float, a.device()));
        let result = match op {
            BinaryOp::Add => a.f_add_scalar(b),
            BinaryOp::Sub => a.f_sub_scalar(b),
            BinaryOp::Mul => a.f_mul_scalar(b),
            BinaryOp::Div => a.f_div_scalar(b),
            BinaryOp::Pow => a.f_pow_tensor_scalar(b),
            BinaryOp::Min => as_tensor().and_then(|s| a.f_fmin(&s)),
            BinaryOp::Max => as_tensor().and_then(|s| a.f_fmax(&s)),
            BinaryOp::Atan2 => as_tensor().and_then(|s| a.f_atan2(&s)),
        };
        float(ok(result, "float_binary_scalar"))
    }

    fn float_clamp(tensor: TchTensor, min: f32, max: f32) -> TchTensor {
        float(ok(
            tensor.0.f_clamp(f64::from(min), f64::from(max)),
            "float_clamp",
        ))
    }

    fn float_detach(tensor: TchTensor) -> TchTensor {
        float(ok(tensor.0.f_detach(), "float_detach"))
    }

    // ---------------------------------------------------------------- comparisons and selection

    fn float_compare(op: CompareOp, lhs: TchTensor, rhs: TchTensor) -> TchTensor {
        let (a, b) = (&lhs.0, &rhs.0);
        let result = match op {
            CompareOp::Greater => a.f_gt_tensor(b),
            CompareOp::GreaterEqual => a.f_ge_tensor(b),
            CompareOp::Less => a.f_lt_tensor(b),
            CompareOp::LessEqual => a.f_le_tensor(b),
            CompareOp::Equal => a.f_eq_tensor(b),
            CompareOp::NotEqual => a.f_ne_tensor(b),
        };
        mask(result, "float_compare")
    }

    fn float_compare_scalar(op: CompareOp, lhs: TchTensor, rhs: f32) -> TchTensor {
        let (a, b) = (&lhs.0, f64::from(rhs));
        let result = match op {
            CompareOp::Greater => a.f_gt(b),
            CompareOp::GreaterEqual => a.f_ge(b),
            CompareOp::Less => a.f_lt(b),
            CompareOp::LessEqual => a.f_le(b),
            CompareOp::Equal => a.f_eq(b),
            CompareOp::NotEqual => a.f_ne(b),
        };
        mask(result, "float_compare_scalar")
    }

    fn float_where(mask: TchTensor, on_true: TchTensor, on_false: TchTensor) -> TchTensor {
        let condition = ok(mask.0.f_ne(0.0), "float_where");
        float(ok(
            on_true.0.f_where_self(&condition, &on_false.0),
            "float_where",
        ))
    }

    // ---------------------------------------------------------------- reductions

    fn float_reduce(op: ReduceOp, tensor: TchTensor) -> TchTensor {
        let t = &tensor.0;
        let result = match op {
            ReduceOp::Sum => t.f_sum(Kind::Float),
            ReduceOp::Mean => t.f_mean(Kind::Float),
            // max_dim/min_dim send the gradient to one extreme element, where the full
            // max()/min() would share it among ties.
            ReduceOp::Max => t.f_flatten(0, -1).and_then(|f| Ok(f.f_max_dim(0, true)?.0)),
            ReduceOp::Min => t.f_flatten(0, -1).and_then(|f| Ok(f.f_min_dim(0, true)?.0)),
        };
        // libtorch's full reductions are rank 0, which the trait does not have.
        float(ok(result.and_then(|r| r.f_reshape([1])), "float_reduce"))
    }

    fn float_reduce_axis(op: ReduceOp, tensor: TchTensor, axis: usize) -> TchTensor {
        let (t, dim) = (&tensor.0, axis as i64);
        let result = match op {
            ReduceOp::Sum => t.f_sum_dim_intlist(dim, true, Kind::Float),
            ReduceOp::Mean => t.f_mean_dim(dim, true, Kind::Float),
            ReduceOp::Max => t.f_max_dim(dim, true).map(|(values, _)| values),
            ReduceOp::Min => t.f_min_dim(dim, true).map(|(values, _)| values),
        };
        float(ok(result, "float_reduce_axis"))
    }

    // ---------------------------------------------------------------- matmul

    fn float_matmul(lhs: TchTensor, rhs: TchTensor) -> TchTensor {
        float(ok(lhs.0.f_matmul(&rhs.0), "float_matmul"))
    }

    // ---------------------------------------------------------------- gather and scatter

    fn float_gather_rows(tensor: TchTensor, indices: TchIntTensor) -> Result<TchTensor> {
        check_indices(&indices.0, tensor.0.size()[0] as usize, "gather_rows")?;
        let rows = tensor
            .0
            .f_index_select(0, &indices.0)
            .map_err(backend_error)?;
        Ok(float(rows))
    }

    fn float_scatter_add_rows(
        tensor: TchTensor,
        indices: TchIntTensor,
        values: TchTensor,
    ) -> Result<TchTensor> {
        check_indices(&indices.0, tensor.0.size()[0] as usize, "scatter_add_rows")?;
        // The out-of-place index_add accumulates repeated indices and is differentiable in both
        // the base tensor and the values.
        let sum = tensor
            .0
            .f_index_add(0, &indices.0, &values.0)
            .map_err(backend_error)?;
        Ok(float(sum))
    }

    // ---------------------------------------------------------------- casts

    fn float_to_int(tensor: TchTensor) -> TchIntTensor {
        // The cast truncates toward zero, as the trait asks.
        int(ok(tensor.0.f_to_kind(Kind::Int64), "float_to_int"))
    }

    fn int_to_float(tensor: TchIntTensor) -> TchTensor {
        float(ok(tensor.0.f_to_kind(Kind::Float), "int_to_float"))
    }

    // ---------------------------------------------------------------- integer tensors

    fn int_reshape(tensor: TchIntTensor, shape: &[usize]) -> TchIntTensor {
        int(reshape(&tensor.0, shape, "int_reshape"))
    }

    fn int_slice(tensor: TchIntTensor, ranges: &[Range<usize>]) -> TchIntTensor {
        int(slice(&tensor.0, ranges, "int_slice"))
    }

    fn int_concat(tensors: Vec<TchIntTensor>, axis: usize) -> TchIntTensor {
        let tensors: Vec<Tensor> = tensors.into_iter().map(|t| t.0).collect();
        int(concat(&tensors, axis, "int_concat"))
    }

    fn int_binary(op: IntBinaryOp, lhs: TchIntTensor, rhs: TchIntTensor) -> TchIntTensor {
        let (a, b) = (&lhs.0, &rhs.0);
        let result = match op {
            IntBinaryOp::Add => a.f_add(b),
            IntBinaryOp::Sub => a.f_sub(b),
            IntBinaryOp::Mul => a.f_mul(b),
            IntBinaryOp::FloorDiv => a.f_div_tensor_mode(&nonzero_divisor(b), "floor"),
            // remainder is Python's %, with the sign of the divisor.
            IntBinaryOp::Rem => a.f_remainder_tensor(&nonzero_divisor(b)),
            IntBinaryOp::Min => a.f_minimum(b),
            IntBinaryOp::Max => a.f_maximum(b),
        };
        int(ok(result, "int_binary"))
    }

    fn int_binary_scalar(op: IntBinaryOp, lhs: TchIntTensor, rhs: i64) -> TchIntTensor {
        let a = &lhs.0;
        // See `nonzero_divisor`: a zero divisor gives an unspecified result, not an exception.
        let divisor = if rhs == 0 { 1 } else { rhs };
        let result = match op {
            IntBinaryOp::Add => a.f_add_scalar(rhs),
            IntBinaryOp::Sub => a.f_sub_scalar(rhs),
            IntBinaryOp::Mul => a.f_mul_scalar(rhs),
            IntBinaryOp::FloorDiv => a.f_div_scalar_mode(divisor, "floor"),
            IntBinaryOp::Rem => a.f_remainder(divisor),
            IntBinaryOp::Min => a.f_clamp_max(rhs),
            IntBinaryOp::Max => a.f_clamp_min(rhs),
        };
        int(ok(result, "int_binary_scalar"))
    }

    fn int_clamp(tensor: TchIntTensor, min: i64, max: i64) -> TchIntTensor {
        int(ok(tensor.0.f_clamp(min, max), "int_clamp"))
    }

    fn int_reduce_axis(op: ReduceOp, tensor: TchIntTensor, axis: usize) -> TchIntTensor {
        let (t, dim) = (&tensor.0, axis as i64);
        let sum = || t.f_sum_dim_intlist(dim, true, Kind::Int64);
        let result = match op {
            ReduceOp::Sum => sum(),
            ReduceOp::Mean => {
                let n = t.size()[axis];
                // libtorch has no integer mean; an empty axis keeps its sum, 0, rather than
                // dividing by zero (which throws).
                if n == 0 {
                    sum()
                } else {
                    sum().and_then(|s| s.f_div_scalar_mode(n, "trunc"))
                }
            }
            ReduceOp::Max => t.f_amax(dim, true),
            ReduceOp::Min => t.f_amin(dim, true),
        };
        int(ok(result, "int_reduce_axis"))
    }

    fn int_gather_rows(tensor: TchIntTensor, indices: TchIntTensor) -> Result<TchIntTensor> {
        check_indices(&indices.0, tensor.0.size()[0] as usize, "gather_rows")?;
        let rows = tensor
            .0
            .f_index_select(0, &indices.0)
            .map_err(backend_error)?;
        Ok(int(rows))
    }

    /// Solved on the host. A right-hand side that requires a gradient goes through the C++
    /// autograd `Function` of `src/solve/tch_shim.cpp`, whose backward is one adjoint solve;
    /// others skip the shim.
    fn float_linear_solve(
        matrix: Arc<SparseMatrix>,
        rhs: TchTensor,
        options: &SolveOptions,
    ) -> std::result::Result<(TchTensor, SolveStats), SolveError> {
        let shape = shape_of(&rhs.0);
        let columns = shape.get(1).copied().unwrap_or(1);
        if rhs.0.requires_grad() && rhs.0.numel() > 0 {
            return tracked_linear_solve(matrix, &rhs, options, columns);
        }
        let values = Self::float_to_vec(&rhs);
        let (x, stats) = crate::solve::solve_f32(&matrix, &values, columns, options)?;
        Ok((Self::float_from_vec(x, &shape, &rhs.0.device()), stats))
    }
}

// ------------------------------------------------------------------------------------ linear solve

/// The C++ shim (`src/solve/tch_shim.cpp`, compiled by the build script): a libtorch autograd
/// `Function` whose forward and backward call [`shim_solve`] for the host-side solves.
mod shim {
    use std::ffi::{c_char, c_void};

    /// Solves `(transpose ? Aᵀ : A) X = B` for `len` values; `0` on success.
    pub(super) type SolveCallback = extern "C" fn(
        context: *mut c_void,
        rhs: *const f32,
        out: *mut f32,
        len: i64,
        transpose: i32,
        error: *mut c_char,
        error_len: usize,
    ) -> i32;
    /// Releases a context.
    pub(super) type DropCallback = extern "C" fn(context: *mut c_void);

    unsafe extern "C" {
        /// `x = LinearSolve::apply(rhs, context)`: on success returns `0` and stores a new
        /// tensor handle (owned by the caller) in `out`; otherwise a message in `error`. Takes
        /// ownership of `context` in every case (`drop` runs exactly once, possibly later, when
        /// the autograd graph holding it is freed).
        pub(super) fn phi_tch_linear_solve(
            rhs: *const torch_sys::C_tensor,
            context: *mut c_void,
            solve: SolveCallback,
            drop: DropCallback,
            out: *mut *mut torch_sys::C_tensor,
            error: *mut c_char,
            error_len: usize,
        ) -> i32;
    }
}

/// What the shim's callbacks need: the matrix, the options, and where the forward solve leaves
/// its outcome for [`Tch::float_linear_solve`] to pick up.
struct ShimContext {
    matrix: Arc<SparseMatrix>,
    options: SolveOptions,
    columns: usize,
    forward: Mutex<Option<std::result::Result<SolveStats, SolveError>>>,
}

fn write_message(error: *mut c_char, error_len: usize, message: &str) {
    if error.is_null() || error_len == 0 {
        return;
    }
    let bytes = message.as_bytes();
    let n = bytes.len().min(error_len - 1);
    // SAFETY: the shim passes a writable buffer of `error_len` bytes.
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), error.cast::<u8>(), n);
        *error.add(n) = 0;
    }
}

extern "C" fn shim_solve(
    context: *mut c_void,
    rhs: *const f32,
    out: *mut f32,
    len: i64,
    transpose: i32,
    error: *mut c_char,
    error_len: usize,
) -> i32 {
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        // SAFETY: `context` comes from `Arc::into_raw` in `float_linear_solve` and stays alive
        // until the shim calls `shim_drop`, which it does only after its last solve.
        let context = unsafe { &*context.cast::<ShimContext>() };
        let len = usize::try_from(len).unwrap_or(0);
        let rhs: &[f32] = if len == 0 {
            &[]
        } else {
            // SAFETY: the shim passes contiguous CPU buffers of `len` floats.
            unsafe { std::slice::from_raw_parts(rhs, len) }
        };
        let solution = if transpose == 0 {
            let result =
                crate::solve::solve_f32(&context.matrix, rhs, context.columns, &context.options);
            let (x, reply) = match result {
                Ok((x, stats)) => (Ok(x), Ok(stats)),
                Err(err) => (Err(err.clone()), Err(err)),
            };
            *context.forward.lock().unwrap_or_else(|e| e.into_inner()) = Some(reply);
            x
        } else {
            crate::solve::adjoint_solve_f32(&context.matrix, rhs, context.columns, &context.options)
        };
        solution.map(|x| {
            if len > 0 {
                // SAFETY: `out` holds `len` floats, as many as the solution.
                unsafe { std::ptr::copy_nonoverlapping(x.as_ptr(), out, len) };
            }
        })
    }));
    match outcome {
        Ok(Ok(())) => 0,
        Ok(Err(err)) => {
            write_message(error, error_len, &err.to_string());
            1
        }
        Err(_) => {
            write_message(error, error_len, "the solve panicked");
            1
        }
    }
}

extern "C" fn shim_drop(context: *mut c_void) {
    // SAFETY: `context` is the pointer from `Arc::into_raw`, released exactly once by the shim.
    drop(unsafe { Arc::from_raw(context.cast::<ShimContext>().cast_const()) });
}

/// The forward solve through the shim: a tensor whose `grad_fn` is the C++ `LinearSolve` node.
fn tracked_linear_solve(
    matrix: Arc<SparseMatrix>,
    rhs: &TchTensor,
    options: &SolveOptions,
    columns: usize,
) -> std::result::Result<(TchTensor, SolveStats), SolveError> {
    let context = Arc::new(ShimContext {
        matrix,
        options: *options,
        columns,
        forward: Mutex::new(None),
    });
    let raw = Arc::into_raw(context.clone()).cast_mut().cast::<c_void>();
    let mut out: *mut torch_sys::C_tensor = std::ptr::null_mut();
    let mut error = vec![0u8; 1024];
    // SAFETY: `rhs` is a live tensor handle; the shim takes over `raw` (see `phi_tch_linear_solve`).
    let status = unsafe {
        shim::phi_tch_linear_solve(
            rhs.0.as_ptr(),
            raw,
            shim_solve,
            shim_drop,
            &mut out,
            error.as_mut_ptr().cast::<c_char>(),
            error.len(),
        )
    };
    let forward = context
        .forward
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take();
    if status != 0 || out.is_null() {
        // The solve's own error is the precise one; otherwise libtorch's message.
        if let Some(Err(err)) = forward {
            return Err(err);
        }
        let end = error.iter().position(|&b| b == 0).unwrap_or(error.len());
        return Err(SolveError::Tensor(TensorError::Backend {
            backend: "tch",
            message: String::from_utf8_lossy(&error[..end]).into_owned(),
        }));
    }
    // SAFETY: on success `out` is a fresh heap tensor handle that we now own.
    let x = unsafe { Tensor::from_ptr(out) };
    match forward {
        Some(Ok(stats)) => Ok((float(x), stats)),
        Some(Err(err)) => Err(err),
        None => Err(SolveError::Tensor(TensorError::Backend {
            backend: "tch",
            message: "linear_solve: the shim returned without solving".into(),
        })),
    }
}

impl AutodiffBackend for Tch {
    fn float_require_grad(tensor: TchTensor) -> TchTensor {
        // detach gives a fresh leaf sharing the storage (no copy); nothing writes into it, so
        // sharing is safe.
        let leaf = ok(
            tensor
                .0
                .f_detach()
                .and_then(|t| t.f_set_requires_grad(true)),
            "float_require_grad",
        );
        float(leaf)
    }

    fn float_is_tracked(tensor: &TchTensor) -> bool {
        tensor.0.requires_grad()
    }

    fn gradients(loss: &TchTensor, wrt: &[&TchTensor]) -> Result<Vec<TchTensor>> {
        let shape = shape_of(&loss.0);
        if shape.iter().product::<usize>() != 1 {
            return Err(TensorError::NotScalar {
                op: "gradients",
                shape,
            });
        }
        // Only leaves, as on every backend: Burn keeps no gradients for intermediate results.
        if let Some(position) = wrt
            .iter()
            .position(|t| !t.0.requires_grad() || !t.0.is_leaf())
        {
            return Err(TensorError::Backend {
                backend: "tch",
                message: format!(
                    "gradients: tensor {position} of `wrt` is not a leaf made by require_grad"
                ),
            });
        }
        let zeros =
            |t: &TchTensor| Tensor::f_zeros(t.0.size(), (Kind::Float, t.0.device())).map(float);
        // A loss computed from untracked tensors only has no graph to run backward through; it
        // depends on none of `wrt`.
        if wrt.is_empty() || !loss.0.requires_grad() {
            return wrt
                .iter()
                .map(|t| zeros(t).map_err(backend_error))
                .collect();
        }
        let inputs: Vec<&Tensor> = wrt.iter().map(|t| &t.0).collect();
        let grads =
            Tensor::f_run_backward(&[&loss.0], &inputs, false, false).map_err(backend_error)?;
        grads
            .into_iter()
            .zip(wrt)
            .map(|(grad, t)| {
                // An input the loss does not reach comes back undefined.
                let grad = if grad.defined() {
                    grad.f_detach().map(float)
                } else {
                    zeros(t)
                };
                grad.map_err(backend_error)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn floats(data: &[f32], shape: &[usize]) -> TchTensor {
        Tch::float_from_vec(data.to_vec(), shape, &Device::Cpu)
    }

    fn ints(data: &[i64], shape: &[usize]) -> TchIntTensor {
        Tch::int_from_vec(data.to_vec(), shape, &Device::Cpu)
    }

    fn values(t: &TchTensor) -> Vec<f32> {
        Tch::float_to_vec(t)
    }

    #[test]
    fn broadcasting_across_ranks() {
        let a = floats(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[2, 3]);
        let b = floats(&[10.0, 20.0, 30.0], &[3]);
        let sum = Tch::float_binary(BinaryOp::Add, a, b);
        assert_eq!(Tch::float_shape(&sum), vec![2, 3]);
        assert_eq!(values(&sum), vec![11.0, 22.0, 33.0, 14.0, 25.0, 36.0]);

        let column = floats(&[1.0, 2.0], &[2, 1]);
        let row = floats(&[1.0, 2.0, 3.0], &[1, 1, 3]);
        let product = Tch::float_binary(BinaryOp::Mul, column, row.clone());
        assert_eq!(Tch::float_shape(&product), vec![1, 2, 3]);
        assert_eq!(values(&product), vec![1.0, 2.0, 3.0, 2.0, 4.0, 6.0]);

        let mask = Tch::float_compare_scalar(CompareOp::Greater, row.clone(), 1.5);
        let picked = Tch::float_where(mask, row, floats(&[-1.0], &[1]));
        assert_eq!(values(&picked), vec![-1.0, 2.0, 3.0]);

        let wide = Tch::float_broadcast_to(floats(&[1.0, 2.0], &[2, 1]), &[3, 2, 2]);
        assert_eq!(Tch::float_shape(&wide), vec![3, 2, 2]);
        assert_eq!(values(&wide), [1.0, 1.0, 2.0, 2.0].repeat(3));
    }

    #[test]
    fn kinds_and_reductions() {
        let x = floats(&[3.0, -1.0, 2.0, 5.0], &[2, 2]);
        let total = Tch::float_reduce(ReduceOp::Sum, x.clone());
        assert_eq!(Tch::float_shape(&total), vec![1]);
        assert_eq!(values(&total), vec![9.0]);
        assert_eq!(
            values(&Tch::float_reduce(ReduceOp::Max, x.clone())),
            vec![5.0]
        );
        let rows = Tch::float_reduce_axis(ReduceOp::Min, x.clone(), 1);
        assert_eq!(Tch::float_shape(&rows), vec![2, 1]);
        assert_eq!(values(&rows), vec![-1.0, 2.0]);
        let mask = Tch::float_compare_scalar(CompareOp::Less, x.clone(), 2.5);
        assert_eq!(mask.0.kind(), Kind::Float);
        assert_eq!(values(&mask), vec![0.0, 1.0, 1.0, 0.0]);
        let empty_mean = Tch::float_reduce(ReduceOp::Mean, floats(&[], &[0, 3]));
        assert!(values(&empty_mean)[0].is_nan());

        let truncated = Tch::float_to_int(floats(&[-1.7, 1.7], &[2]));
        assert_eq!(Tch::int_to_vec(&truncated), vec![-1, 1]);
        let i = ints(&[-7, 7, -8, 2], &[2, 2]);
        let mean = Tch::int_reduce_axis(ReduceOp::Mean, i.clone(), 1);
        assert_eq!(mean.0.kind(), Kind::Int64);
        assert_eq!(Tch::int_to_vec(&mean), vec![0, -3]);
        let sum = Tch::int_reduce_axis(ReduceOp::Sum, i, 0);
        assert_eq!(sum.0.kind(), Kind::Int64);
        assert_eq!(Tch::int_to_vec(&sum), vec![-15, 9]);
    }

    #[test]
    fn integer_division_follows_python() {
        let a = ints(&[7, -7, 7, -7], &[4]);
        let b = ints(&[2, 2, -2, -2], &[4]);
        for op in [IntBinaryOp::FloorDiv, IntBinaryOp::Rem] {
            let got = Tch::int_to_vec(&Tch::int_binary(op, a.clone(), b.clone()));
            let want: Vec<i64> = [(7, 2), (-7, 2), (7, -2), (-7, -2)]
                .iter()
                .map(|&(x, y)| op.apply(x, y))
                .collect();
            assert_eq!(got, want, "{op:?}");
            let scalar = Tch::int_to_vec(&Tch::int_binary_scalar(op, a.clone(), -2));
            let want: Vec<i64> = [7, -7, 7, -7].iter().map(|&x| op.apply(x, -2)).collect();
            assert_eq!(scalar, want, "{op:?} scalar");
        }
        // Unspecified, but it must not throw.
        let _ = Tch::int_binary(IntBinaryOp::Rem, a.clone(), ints(&[0], &[1]));
        let _ = Tch::int_binary_scalar(IntBinaryOp::FloorDiv, a, 0);
    }

    #[test]
    fn symmetric_and_edge_padding() {
        let x = floats(&[1.0, 2.0, 3.0], &[1, 3]);
        let symmetric = Tch::float_pad(x.clone(), &[(0, 0), (2, 2)], PadMode::Symmetric);
        assert_eq!(values(&symmetric), vec![2.0, 1.0, 1.0, 2.0, 3.0, 3.0, 2.0]);
        let periodic = Tch::float_pad(x.clone(), &[(0, 0), (1, 2)], PadMode::Periodic);
        assert_eq!(values(&periodic), vec![3.0, 1.0, 2.0, 3.0, 1.0, 2.0]);
        let edge = Tch::float_pad(x.clone(), &[(1, 0), (0, 1)], PadMode::Edge);
        assert_eq!(Tch::float_shape(&edge), vec![2, 4]);
        assert_eq!(values(&edge), vec![1.0, 2.0, 3.0, 3.0, 1.0, 2.0, 3.0, 3.0]);
        let constant = Tch::float_pad(x, &[(1, 0), (0, 1)], PadMode::Constant(7.0));
        assert_eq!(
            values(&constant),
            vec![7.0, 7.0, 7.0, 7.0, 1.0, 2.0, 3.0, 7.0]
        );
    }

    #[test]
    fn scatter_add_accumulates_and_differentiates() {
        let base = Tch::float_require_grad(floats(&[0.0; 6], &[3, 2]));
        let updates = Tch::float_require_grad(floats(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[3, 2]));
        let indices = ints(&[2, 0, 2], &[3]);
        let out = Tch::float_scatter_add_rows(base.clone(), indices, updates.clone()).unwrap();
        assert_eq!(values(&out), vec![3.0, 4.0, 0.0, 0.0, 6.0, 8.0]);

        // loss = Σ w ⊙ out, so ∂loss/∂base = w and ∂loss/∂values[i] = w[indices[i]].
        let weights = floats(&[1.0, 10.0, 100.0, 1000.0, 2.0, 20.0], &[3, 2]);
        let loss = Tch::float_reduce(
            ReduceOp::Sum,
            Tch::float_binary(BinaryOp::Mul, out, weights),
        );
        let grads = Tch::gradients(&loss, &[&base, &updates]).unwrap();
        assert_eq!(values(&grads[0]), vec![1.0, 10.0, 100.0, 1000.0, 2.0, 20.0]);
        assert_eq!(values(&grads[1]), vec![2.0, 20.0, 1.0, 10.0, 2.0, 20.0]);
        assert!(grads.iter().all(|g| !Tch::float_is_tracked(g)));
    }

    #[test]
    fn empty_indices_work() {
        let x = floats(&[1.0, 2.0, 3.0, 4.0], &[2, 2]);
        let none = ints(&[], &[0]);
        let rows = Tch::float_gather_rows(x.clone(), none.clone()).unwrap();
        assert_eq!(Tch::float_shape(&rows), vec![0, 2]);
        let same = Tch::float_scatter_add_rows(x, none, floats(&[], &[0, 2])).unwrap();
        assert_eq!(values(&same), vec![1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn out_of_range_indices_are_errors() {
        let x = floats(&[1.0, 2.0, 3.0, 4.0], &[2, 2]);
        let err = Tch::float_gather_rows(x.clone(), ints(&[0, 2, 1], &[3])).unwrap_err();
        assert_eq!(
            err,
            TensorError::IndexOutOfRange {
                op: "gather_rows",
                index: 2,
                bound: 2
            }
        );
        let err =
            Tch::float_scatter_add_rows(x.clone(), ints(&[-1], &[1]), floats(&[0.0, 0.0], &[1, 2]))
                .unwrap_err();
        assert!(matches!(
            err,
            TensorError::IndexOutOfRange { index: -1, .. }
        ));
        let err = Tch::int_gather_rows(ints(&[1, 2], &[2]), ints(&[5], &[1])).unwrap_err();
        assert!(matches!(
            err,
            TensorError::IndexOutOfRange {
                index: 5,
                bound: 2,
                ..
            }
        ));
        let err = Tch::float_gather_nd(x, ints(&[0, 2], &[1, 2])).unwrap_err();
        assert!(matches!(
            err,
            TensorError::IndexOutOfRange {
                index: 2,
                bound: 2,
                ..
            }
        ));
    }

    #[test]
    fn gradient_of_sum_of_squares() {
        let x = Tch::float_require_grad(floats(&[1.0, -2.0, 3.0], &[3]));
        assert!(Tch::float_is_tracked(&x));
        let unused = Tch::float_require_grad(floats(&[5.0, 6.0], &[1, 2]));
        let loss = Tch::float_reduce(
            ReduceOp::Sum,
            Tch::float_binary(BinaryOp::Mul, x.clone(), x.clone()),
        );
        let grads = Tch::gradients(&loss, &[&x, &unused]).unwrap();
        assert_eq!(values(&grads[0]), vec![2.0, -4.0, 6.0]);
        assert_eq!(Tch::float_shape(&grads[1]), vec![1, 2]);
        assert_eq!(values(&grads[1]), vec![0.0, 0.0]);

        // The graph is consumed: a second backward pass is the engine's refusal, not a crash.
        assert!(matches!(
            Tch::gradients(&loss, &[&x]),
            Err(TensorError::Backend { .. })
        ));

        let constant = floats(&[1.0], &[1]);
        assert!(matches!(
            Tch::gradients(&loss, &[&constant]),
            Err(TensorError::Backend { .. })
        ));
        let detached = Tch::float_detach(x.clone());
        assert!(!Tch::float_is_tracked(&detached));
        let untracked_loss = Tch::float_reduce(ReduceOp::Sum, detached);
        let grads = Tch::gradients(&untracked_loss, &[&x]).unwrap();
        assert_eq!(values(&grads[0]), vec![0.0, 0.0, 0.0]);
    }
}
