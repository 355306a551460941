//! Edge cases on every backend: broadcasting corners, empty tensors, out-of-range indices and
//! shape errors that must be errors, never aborts or silent wrong answers.

use std::panic::{AssertUnwindSafe, catch_unwind};

use phi_core::backend::{PadMode, ReduceOp};
use phi_core::{Backend, IntTensor, Tensor, TensorError};

use super::{assert_tensor, tensor};

phi_core::backend_tests!(
    broadcasting_corners,
    empty_tensors,
    out_of_range_indices,
    shape_errors_name_both_shapes,
    operator_panics_name_the_shapes,
    relu_keeps_nan,
);

/// A NaN through a ReLU stays NaN on every backend (as in PyTorch), so that a blown-up network
/// output is seen by the checks after it instead of turning into a finite zero.
fn relu_keeps_nan<B: Backend>() {
    let x = tensor::<B>(&[4], &[f32::NAN, -1.0, 0.0, 2.0]);
    let y = x.relu().to_vec();
    assert!(y[0].is_nan(), "{}: relu(NaN) = {}", B::name(), y[0]);
    assert_eq!(&y[1..], &[0.0, 0.0, 2.0], "{}", B::name());
    assert!(phi_core::backend::relu(f32::NAN).is_nan());
}

fn broadcasting_corners<B: Backend>() {
    // Rank 1 against rank 3, and length-1 axes on both sides.
    let a = tensor::<B>(&[2, 1, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let b = tensor::<B>(&[3], &[10.0, 20.0, 30.0]);
    assert_tensor(
        "rank 3 + rank 1",
        &(&a + &b),
        &[2, 1, 3],
        &[11.0, 22.0, 33.0, 14.0, 25.0, 36.0],
    );
    let c = tensor::<B>(&[4, 1], &[1.0, 2.0, 3.0, 4.0]);
    let outer = &tensor::<B>(&[1, 2], &[1.0, 10.0]) * &c;
    assert_tensor(
        "[1,2] * [4,1]",
        &outer,
        &[4, 2],
        &[1.0, 10.0, 2.0, 20.0, 3.0, 30.0, 4.0, 40.0],
    );
    // A one-element tensor broadcasts against anything, including an empty axis.
    let one = tensor::<B>(&[1], &[2.0]);
    let empty = Tensor::<B>::zeros(&[0, 3], &B::default_device());
    assert_eq!((&one + &empty).shape(), vec![0, 3]);
}

fn empty_tensors<B: Backend>() {
    let device = B::default_device();
    let empty = Tensor::<B>::zeros(&[0, 3], &device);
    assert_eq!(empty.numel(), 0);
    assert!(empty.to_vec().is_empty());
    assert_tensor("sum of nothing", &empty.sum(), &[1], &[0.0]);
    assert!(
        empty.mean().to_scalar().unwrap().is_nan(),
        "mean of nothing is NaN"
    );
    assert_tensor(
        "sum over the empty axis",
        &empty.reduce_axis(ReduceOp::Sum, 0, true).unwrap(),
        &[1, 3],
        &[0.0; 3],
    );
    assert_eq!(
        empty.reduce_axis(ReduceOp::Max, 1, true).unwrap().shape(),
        vec![0, 1]
    );
    assert!(
        empty.reduce(ReduceOp::Max).is_err(),
        "max of nothing is an error"
    );
    assert!(empty.reduce_axis(ReduceOp::Min, 0, true).is_err());
    assert_eq!(empty.exp().shape(), vec![0, 3]);
    assert_eq!(empty.permute(&[1, 0]).unwrap().shape(), vec![3, 0]);
    let full = tensor::<B>(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let joined = Tensor::concat(&[empty.clone(), full.clone()], 0).unwrap();
    assert_tensor("concat with empty", &joined, &[2, 3], &full.to_vec());
    assert_eq!(full.narrow(0, 1..1).unwrap().shape(), vec![0, 3]);
    assert_eq!(
        empty
            .matmul(&Tensor::zeros(&[3, 2], &device))
            .unwrap()
            .shape(),
        vec![0, 2]
    );
    assert_tensor(
        "matmul over an empty inner axis",
        &Tensor::<B>::zeros(&[2, 0], &device)
            .matmul(&Tensor::zeros(&[0, 2], &device))
            .unwrap(),
        &[2, 2],
        &[0.0; 4],
    );
    assert_eq!(
        empty
            .pad(&[(1, 1)], PadMode::Constant(7.0))
            .unwrap()
            .to_vec(),
        vec![7.0; 6]
    );
    // Gathers and scatters with no indices.
    let none = IntTensor::<B>::from_vec(vec![], &[0], &device).unwrap();
    assert_eq!(full.gather_rows(&none).unwrap().shape(), vec![0, 3]);
    let unchanged = full
        .scatter_add_rows(&none, &Tensor::zeros(&[0, 3], &device))
        .unwrap();
    assert_tensor("scatter nothing", &unchanged, &[2, 3], &full.to_vec());
    let no_pairs = IntTensor::<B>::from_vec(vec![], &[0, 2], &device).unwrap();
    assert_eq!(full.gather_nd(&no_pairs).unwrap().shape(), vec![0]);
}

fn out_of_range_indices<B: Backend>() {
    let device = B::default_device();
    let ints = |v: Vec<i64>, shape: &[usize]| IntTensor::<B>::from_vec(v, shape, &device).unwrap();
    let table = tensor::<B>(&[4, 2], &[0.0; 8]);
    let expect_out_of_range =
        |result: phi_core::Result<Tensor<B>>, index: i64, bound: usize| match result {
            Err(TensorError::IndexOutOfRange {
                index: i, bound: b, ..
            }) => {
                assert_eq!(
                    (i, b),
                    (index, bound),
                    "the error names the offending index and the bound"
                );
            }
            other => panic!("expected an index error for {index} in 0..{bound}, got {other:?}"),
        };
    expect_out_of_range(table.gather_rows(&ints(vec![0, 4], &[2])), 4, 4);
    expect_out_of_range(table.gather_rows(&ints(vec![-1, 2], &[2])), -1, 4);
    let values = tensor::<B>(&[2, 2], &[1.0; 4]);
    expect_out_of_range(
        table.scatter_add_rows(&ints(vec![1, 9], &[2]), &values),
        9,
        4,
    );
    // [4, 2] viewed as a grid: (0, 2) would alias the valid flat index 2 = (1, 0).
    expect_out_of_range(table.gather_nd(&ints(vec![0, 2], &[1, 2])), 2, 2);
    expect_out_of_range(
        table.scatter_add_nd(&ints(vec![5, 0], &[1, 2]), &tensor(&[1], &[1.0])),
        5,
        4,
    );
    let int_table = ints(vec![1, 2, 3], &[3]);
    assert!(matches!(
        int_table.gather_rows(&ints(vec![3], &[1])),
        Err(TensorError::IndexOutOfRange {
            index: 3,
            bound: 3,
            ..
        })
    ));
    // The table is unharmed and still usable after the errors.
    assert_tensor("after errors", &table.sum(), &[1], &[0.0]);
}

fn shape_errors_name_both_shapes<B: Backend>() {
    let device = B::default_device();
    let a = Tensor::<B>::zeros(&[3, 2], &device);
    let b = Tensor::<B>::zeros(&[3], &device);
    let message = a
        .binary(phi_core::backend::BinaryOp::Add, &b)
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("add") && message.contains("[3, 2]") && message.contains("[3]"),
        "{message}"
    );
    let message = a
        .matmul(&b.reshape(&[1, 3]).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("matmul") && message.contains("[3, 2]") && message.contains("[1, 3]"),
        "{message}"
    );
    assert!(matches!(
        Tensor::<B>::from_vec(vec![1.0; 5], &[2, 3], &device),
        Err(TensorError::DataLength {
            expected: 6,
            got: 5,
            ..
        })
    ));
    assert!(a.reshape(&[4]).is_err());
    assert!(a.permute(&[0, 0]).is_err());
    assert!(a.narrow(0, 0..4).is_err());
    assert!(a.sum_axis(2).is_err());
    assert!(Tensor::concat(&[a.clone(), b.clone()], 0).is_err());
    assert!(Tensor::<B>::concat(&[], 0).is_err());
    assert!(a.pad(&[(4, 0)], PadMode::Periodic).is_err());
    assert!(a.broadcast_to(&[3, 3]).is_err());
    assert!(matches!(a.to_scalar(), Err(TensorError::NotScalar { .. })));
    let idx = IntTensor::<B>::from_vec(vec![0, 1], &[2], &device).unwrap();
    assert!(
        a.scatter_add_rows(&idx, &Tensor::zeros(&[2, 3], &device))
            .is_err()
    );
}

fn operator_panics_name_the_shapes<B: Backend>() {
    let device = B::default_device();
    let a = Tensor::<B>::zeros(&[2, 5], &device);
    let b = Tensor::<B>::zeros(&[4], &device);
    let panic = catch_unwind(AssertUnwindSafe(|| &a * &b))
        .expect_err("mismatched shapes must not multiply");
    let message = panic.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(
        message.contains("mul") && message.contains("[2, 5]") && message.contains("[4]"),
        "{message}"
    );
}
