//! The fields layer (`phi_core::fields`) on every backend: differential operators against exact
//! maths and convergence orders, particle ↔ grid transfers, extrapolation, advection, the
//! pressure projection, errors, and gradients on the autodiff backends.

mod gradients;
mod operators;
mod projection;
mod transfer;

use phi_core::fields::{Boundary, Domain};
use phi_core::{Backend, Tensor};

/// Calls `f(multi_index, flat_index)` for every index of `shape` in row-major order.
pub fn for_each_index(shape: &[usize], mut f: impl FnMut(&[usize], usize)) {
    let count: usize = shape.iter().product();
    let mut index = vec![0usize; shape.len()];
    for flat in 0..count {
        f(&index, flat);
        for axis in (0..shape.len()).rev() {
            index[axis] += 1;
            if index[axis] < shape[axis] {
                break;
            }
            index[axis] = 0;
        }
    }
}

/// A domain with the same boundary on every side.
pub fn domain(res: &[usize], lower: &[f32], upper: &[f32], boundary: Boundary) -> Domain {
    Domain::new(res, lower, upper, &vec![[boundary; 2]; res.len()]).expect("a valid test domain")
}

/// A tensor from host values on the default device.
pub fn tensor<B: Backend>(shape: &[usize], values: &[f32]) -> Tensor<B> {
    Tensor::from_slice(values, shape, &B::default_device()).expect("test data fits its shape")
}

/// Largest `|got − want(index)|` over the indices of `shape` (the tensor's shape) that `keep`
/// accepts; `want` gets the multi-index.
pub fn max_error(
    got: &Tensor<impl Backend>,
    keep: impl Fn(&[usize]) -> bool,
    want: impl Fn(&[usize]) -> f32,
) -> f32 {
    let values = got.to_vec();
    let mut worst = 0.0f32;
    let mut checked = 0;
    for_each_index(&got.shape(), |index, flat| {
        if keep(index) {
            worst = worst.max((values[flat] - want(index)).abs());
            checked += 1;
        }
    });
    assert!(checked > 0, "no sample was checked");
    worst
}
