//! Cross-backend conformance: every operation of the `Backend` trait, written once and run on
//! every enabled backend.
//!
//! Each test is a generic function `fn name<B: Backend>()`; [`phi_core::backend_tests!`] writes
//! one `#[test]` per enabled backend for it (`conformance::forward::burn::unary_ops`, ...), so the
//! test output lists how many ran on each. Values are checked three ways: against exact answers
//! worked by hand, against the same computation on the ndarray backend (the reference, relative
//! tolerance 1e-5), and, for autodiff backends, gradients against central finite differences and
//! against each other (`gradients`).

mod cases;
mod edge_cases;
mod forward;
mod gradients;

use phi_core::backend::ndarray::NdArray;
use phi_core::{Backend, Tensor};

/// The backend every other one is compared with.
pub type Reference = NdArray;

/// Whether `got` is within `rtol · |want| + atol` of `want`; NaNs match NaNs and infinities
/// match equal infinities.
pub fn close(got: f32, want: f32, rtol: f32, atol: f32) -> bool {
    if want.is_nan() {
        return got.is_nan();
    }
    if want.is_infinite() {
        return got == want;
    }
    (got - want).abs() <= rtol * want.abs() + atol
}

/// Asserts that `got` has shape `shape` and values within tolerance of `want`.
#[track_caller]
pub fn assert_values(
    what: &str,
    got_shape: &[usize],
    got: &[f32],
    shape: &[usize],
    want: &[f32],
    rtol: f32,
    atol: f32,
) {
    assert_eq!(got_shape, shape, "{what}: shape");
    assert_eq!(got.len(), want.len(), "{what}: number of values");
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        assert!(
            close(g, w, rtol, atol),
            "{what}: element {i} is {g}, expected {w} (rtol {rtol}, atol {atol})\n got: {got:?}\nwant: {want:?}"
        );
    }
}

/// Asserts that a tensor has exactly `shape` and values within 1e-5 relative (1e-6 absolute)
/// of `want`.
#[track_caller]
pub fn assert_tensor<B: Backend>(what: &str, got: &Tensor<B>, shape: &[usize], want: &[f32]) {
    assert_values(what, &got.shape(), &got.to_vec(), shape, want, 1e-5, 1e-6);
}

/// Asserts that a tensor on `B` equals the reference backend's result within 1e-5 relative.
#[track_caller]
pub fn assert_matches_reference<B: Backend>(what: &str, got: &Tensor<B>, want: &Tensor<Reference>) {
    assert_values(
        what,
        &got.shape(),
        &got.to_vec(),
        &want.shape(),
        &want.to_vec(),
        1e-5,
        1e-6,
    );
}

/// A tensor from host values on the default device.
pub fn tensor<B: Backend>(shape: &[usize], values: &[f32]) -> Tensor<B> {
    Tensor::from_slice(values, shape, &B::default_device()).expect("test data fits its shape")
}

/// Deterministic, well-spread test values in `[low, high)`.
pub fn values(n: usize, low: f32, high: f32, seed: u64) -> Vec<f32> {
    Tensor::<Reference>::random_uniform(&[n], low, high, seed, &Default::default()).to_vec()
}
