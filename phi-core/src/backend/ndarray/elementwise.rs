//! Element-wise kernels: maps and broadcasting zips, serial below `PAR_THRESHOLD`.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- element-wise kernels

/// `1.0` for true, `0.0` for false.
pub(super) fn mask(condition: bool) -> f32 {
    if condition { 1.0 } else { 0.0 }
}

/// `⌊a / b⌋` as Python's `//`, without the panics of `i64` division (zero divisor, overflow).
pub(super) fn floor_div(a: i64, b: i64) -> i64 {
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
pub(super) fn floor_rem(a: i64, b: i64) -> i64 {
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
pub(super) fn map<T, U, F>(tensor: &Tensor<T>, f: F) -> Tensor<U>
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
pub(super) fn zip2<T, U, F>(a: &Tensor<T>, b: &Tensor<T>, f: F) -> Tensor<U>
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
