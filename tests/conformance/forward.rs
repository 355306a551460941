//! Forward values of every operation: against exact answers, the host's `f32` maths and the
//! reference backend.

use phi_core::backend::{BinaryOp, CompareOp, IntBinaryOp, PadMode, ReduceOp, UnaryOp};
use phi_core::{Backend, IntTensor, Tensor};

use super::cases::Case;
use super::{Reference, assert_matches_reference, assert_tensor, assert_values, tensor, values};

phi_core::backend_tests!(
    unary_ops,
    binary_ops,
    scalar_ops,
    clamp_and_where,
    comparisons,
    reductions,
    matmul,
    shape_ops,
    padding,
    gather_and_scatter,
    casts,
    int_ops,
    creation_and_random,
    device_transfer,
);

/// Runs the cases that `keep` selects on `B` and on the reference backend and compares them.
fn check_cases_against_reference<B: Backend>(keep: impl Fn(&Case) -> bool) {
    let cases: Vec<Case> = Case::all().into_iter().filter(|c| keep(c)).collect();
    assert!(!cases.is_empty());
    for case in cases {
        let inputs = case.inputs();
        let on_b: Vec<Tensor<B>> = inputs.iter().map(|(s, v)| tensor(s, v)).collect();
        let on_reference: Vec<Tensor<Reference>> =
            inputs.iter().map(|(s, v)| tensor(s, v)).collect();
        assert_matches_reference(
            &format!("{case:?}"),
            &case.apply(&on_b),
            &case.apply(&on_reference),
        );
    }
}

fn unary_ops<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Unary(_)));
    // And against the host's f32 maths, over a range that includes zero and negative values.
    let x = values(16, -3.0, 3.0, 101);
    for op in UnaryOp::ALL {
        let input: Vec<f32> = match op {
            UnaryOp::Sqrt | UnaryOp::Log => x.iter().map(|v| v.abs() + 0.01).collect(),
            _ => x.clone(),
        };
        let want: Vec<f32> = input.iter().map(|&v| op.apply(v)).collect();
        assert_tensor(
            &format!("{op:?}"),
            &tensor::<B>(&[4, 4], &input).unary(op),
            &[4, 4],
            &want,
        );
    }
    // Exact values at the special points.
    let special = tensor::<B>(&[4], &[-2.0, -0.5, 0.0, 2.5]);
    assert_tensor("floor", &special.floor(), &[4], &[-2.0, -1.0, 0.0, 2.0]);
    assert_tensor("sign", &special.sign(), &[4], &[-1.0, -1.0, 0.0, 1.0]);
    assert_tensor("relu", &special.relu(), &[4], &[0.0, 0.0, 0.0, 2.5]);
    assert_tensor("abs", &special.abs(), &[4], &[2.0, 0.5, 0.0, 2.5]);
}

fn binary_ops<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Binary(_)));
    // Broadcasting [2, 1] against [3]: out[i][j] = op(a[i], b[j]).
    let a = [0.5f32, 2.0];
    let b = [1.5f32, -0.25, 3.0];
    for op in BinaryOp::ALL {
        let want: Vec<f32> = a
            .iter()
            .flat_map(|&x| b.iter().map(move |&y| op.apply(x, y)))
            .collect();
        let got = tensor::<B>(&[2, 1], &a)
            .binary(op, &tensor(&[3], &b))
            .unwrap();
        assert_tensor(&format!("{op:?}"), &got, &[2, 3], &want);
    }
    // The operators.
    let x = tensor::<B>(&[3], &[1.0, 2.0, 3.0]);
    let y = tensor::<B>(&[3], &[4.0, 5.0, 6.0]);
    assert_tensor("x + y", &(&x + &y), &[3], &[5.0, 7.0, 9.0]);
    assert_tensor("x - y", &(&x - &y), &[3], &[-3.0, -3.0, -3.0]);
    assert_tensor("x * y", &(&x * &y), &[3], &[4.0, 10.0, 18.0]);
    assert_tensor("y / x", &(&y / &x), &[3], &[4.0, 2.5, 2.0]);
    assert_tensor("-x", &(-&x), &[3], &[-1.0, -2.0, -3.0]);
    assert_tensor("1 - x", &(1.0 - &x), &[3], &[0.0, -1.0, -2.0]);
    assert_tensor("6 / x", &(6.0 / &x), &[3], &[6.0, 3.0, 2.0]);
    assert_tensor("2 * x + 1", &(2.0 * &x + 1.0), &[3], &[3.0, 5.0, 7.0]);
}

fn scalar_ops<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::BinaryScalar(..)));
    let x = [0.5f32, 2.0, 3.0];
    for op in BinaryOp::ALL {
        let want: Vec<f32> = x.iter().map(|&v| op.apply(v, 1.5)).collect();
        assert_tensor(
            &format!("{op:?}"),
            &tensor::<B>(&[3], &x).binary_scalar(op, 1.5),
            &[3],
            &want,
        );
    }
}

fn clamp_and_where<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Clamp | Case::Where));
    let x = tensor::<B>(&[5], &[-2.0, -0.5, 0.0, 0.7, 3.0]);
    assert_tensor(
        "clamp",
        &x.clamp(-1.0, 0.5),
        &[5],
        &[-1.0, -0.5, 0.0, 0.5, 0.5],
    );
    // The mask broadcasts along rows, the values along columns.
    let mask = tensor::<B>(&[2, 1], &[1.0, 0.0]);
    let on_true = tensor::<B>(&[3], &[1.0, 2.0, 3.0]);
    let on_false = tensor::<B>(&[2, 3], &[-1.0, -2.0, -3.0, -4.0, -5.0, -6.0]);
    let selected = Tensor::select(&mask, &on_true, &on_false).unwrap();
    assert_tensor(
        "select",
        &selected,
        &[2, 3],
        &[1.0, 2.0, 3.0, -4.0, -5.0, -6.0],
    );
}

fn comparisons<B: Backend>() {
    let a = [1.0f32, 2.0, 3.0, f32::NEG_INFINITY];
    let b = [2.0f32, 2.0, 1.0, 0.0];
    for op in CompareOp::ALL {
        let want: Vec<f32> = a
            .iter()
            .zip(&b)
            .map(|(&x, &y)| f32::from(u8::from(op.apply(x, y))))
            .collect();
        let got = tensor::<B>(&[4], &a)
            .compare(op, &tensor(&[4], &b))
            .unwrap();
        assert_tensor(&format!("{op:?}"), &got, &[4], &want);
        let want: Vec<f32> = a
            .iter()
            .map(|&x| f32::from(u8::from(op.apply(x, 2.0))))
            .collect();
        assert_tensor(
            &format!("{op:?} scalar"),
            &tensor::<B>(&[4], &a).compare_scalar(op, 2.0),
            &[4],
            &want,
        );
    }
    // Broadcasting [2, 1] against [2].
    let got = tensor::<B>(&[2, 1], &[1.0, 3.0])
        .compare(CompareOp::Less, &tensor(&[2], &[2.0, 4.0]))
        .unwrap();
    assert_tensor("less broadcast", &got, &[2, 2], &[1.0, 1.0, 0.0, 1.0]);
}

fn reductions<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Reduce(_) | Case::ReduceAxis(..)));
    let x = tensor::<B>(&[2, 3], &[1.0, 5.0, 3.0, 4.0, 2.0, 6.0]);
    assert_tensor("sum", &x.sum(), &[1], &[21.0]);
    assert_tensor("mean", &x.mean(), &[1], &[3.5]);
    assert_tensor("max", &x.reduce(ReduceOp::Max).unwrap(), &[1], &[6.0]);
    assert_tensor("min", &x.reduce(ReduceOp::Min).unwrap(), &[1], &[1.0]);
    let axis = |op, axis, keep| x.reduce_axis(op, axis, keep).unwrap();
    assert_tensor(
        "sum axis 0",
        &axis(ReduceOp::Sum, 0, true),
        &[1, 3],
        &[5.0, 7.0, 9.0],
    );
    assert_tensor(
        "mean axis 1",
        &axis(ReduceOp::Mean, 1, true),
        &[2, 1],
        &[3.0, 4.0],
    );
    assert_tensor(
        "max axis 1",
        &axis(ReduceOp::Max, 1, false),
        &[2],
        &[5.0, 6.0],
    );
    assert_tensor(
        "min axis 0",
        &axis(ReduceOp::Min, 0, false),
        &[3],
        &[1.0, 2.0, 3.0],
    );
    assert_tensor("sum_axis", &x.sum_axis(1).unwrap(), &[2], &[9.0, 12.0]);
    assert_tensor(
        "mean_axis",
        &x.mean_axis(0).unwrap(),
        &[3],
        &[2.5, 3.5, 4.5],
    );
}

fn matmul<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Matmul | Case::MatmulBroadcast));
    let a = tensor::<B>(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let b = tensor::<B>(&[3, 2], &[7.0, 8.0, 9.0, 10.0, 11.0, 12.0]);
    assert_tensor(
        "matmul",
        &a.matmul(&b).unwrap(),
        &[2, 2],
        &[58.0, 64.0, 139.0, 154.0],
    );
    // A batch of two: the identity and twice the identity, against one shared matrix.
    let batch = tensor::<B>(&[2, 2, 2], &[1.0, 0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 2.0]);
    let m = tensor::<B>(&[2, 2], &[1.0, 2.0, 3.0, 4.0]);
    assert_tensor(
        "batched matmul",
        &batch.matmul(&m).unwrap(),
        &[2, 2, 2],
        &[1.0, 2.0, 3.0, 4.0, 2.0, 4.0, 6.0, 8.0],
    );
    // A larger product against the reference (summation order differs: relative 1e-5 holds).
    let (x, w) = (values(64 * 48, -1.0, 1.0, 7), values(48 * 32, -1.0, 1.0, 8));
    let got = tensor::<B>(&[64, 48], &x)
        .matmul(&tensor(&[48, 32], &w))
        .unwrap();
    let want = tensor::<Reference>(&[64, 48], &x)
        .matmul(&tensor(&[48, 32], &w))
        .unwrap();
    assert_values(
        "large matmul",
        &got.shape(),
        &got.to_vec(),
        &want.shape(),
        &want.to_vec(),
        1e-5,
        1e-5,
    );
}

fn shape_ops<B: Backend>() {
    check_cases_against_reference::<B>(|c| {
        matches!(
            c,
            Case::Reshape
                | Case::Permute
                | Case::Slice
                | Case::Concat
                | Case::Stack
                | Case::BroadcastTo
        )
    });
    let x = Tensor::<B>::arange(24, &B::default_device())
        .reshape(&[2, 3, 4])
        .unwrap();
    // out[k][i][j] = x[i][j][k] = 12 i + 4 j + k
    let want: Vec<f32> = (0..4)
        .flat_map(|k| (0..2).flat_map(move |i| (0..3).map(move |j| (12 * i + 4 * j + k) as f32)))
        .collect();
    assert_tensor(
        "permute",
        &x.permute(&[2, 0, 1]).unwrap(),
        &[4, 2, 3],
        &want,
    );
    assert_tensor(
        "slice",
        &x.slice(&[1..2, 1..3, 2..4]).unwrap(),
        &[1, 2, 2],
        &[18.0, 19.0, 22.0, 23.0],
    );
    assert_tensor(
        "narrow",
        &x.narrow(2, 3..4).unwrap().flatten(),
        &[6],
        &[3.0, 7.0, 11.0, 15.0, 19.0, 23.0],
    );
    // Reshape after a permutation must follow the permuted (row-major) order.
    let t = tensor::<B>(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        .transpose()
        .unwrap();
    assert_tensor(
        "transpose",
        &t.reshape(&[6]).unwrap(),
        &[6],
        &[1.0, 4.0, 2.0, 5.0, 3.0, 6.0],
    );
    let a = tensor::<B>(&[2, 1], &[1.0, 2.0]);
    let b = tensor::<B>(&[2, 2], &[3.0, 4.0, 5.0, 6.0]);
    assert_tensor(
        "concat",
        &Tensor::concat(&[a.clone(), b], 1).unwrap(),
        &[2, 3],
        &[1.0, 3.0, 4.0, 2.0, 5.0, 6.0],
    );
    let c = tensor::<B>(&[2, 1], &[7.0, 8.0]);
    assert_tensor(
        "stack",
        &Tensor::stack(&[a.clone(), c], 0).unwrap(),
        &[2, 2, 1],
        &[1.0, 2.0, 7.0, 8.0],
    );
    assert_tensor(
        "broadcast_to",
        &a.broadcast_to(&[2, 2, 3]).unwrap(),
        &[2, 2, 3],
        &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0],
    );
    assert_tensor(
        "unsqueeze/squeeze",
        &a.squeeze(1).unwrap().unsqueeze(0).unwrap(),
        &[1, 2],
        &[1.0, 2.0],
    );
}

fn padding<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::Pad(_)));
    let x = tensor::<B>(&[3], &[1.0, 2.0, 3.0]);
    let pad = |mode| x.pad(&[(2, 2)], mode).unwrap();
    assert_tensor(
        "constant",
        &pad(PadMode::Constant(0.0)),
        &[7],
        &[0.0, 0.0, 1.0, 2.0, 3.0, 0.0, 0.0],
    );
    assert_tensor(
        "edge",
        &pad(PadMode::Edge),
        &[7],
        &[1.0, 1.0, 1.0, 2.0, 3.0, 3.0, 3.0],
    );
    assert_tensor(
        "periodic",
        &pad(PadMode::Periodic),
        &[7],
        &[2.0, 3.0, 1.0, 2.0, 3.0, 1.0, 2.0],
    );
    assert_tensor(
        "symmetric",
        &pad(PadMode::Symmetric),
        &[7],
        &[2.0, 1.0, 1.0, 2.0, 3.0, 3.0, 2.0],
    );
    // Two axes, unequal widths: the corners combine both axes' rules.
    let m = tensor::<B>(&[2, 2], &[1.0, 2.0, 3.0, 4.0]);
    let padded = m.pad(&[(1, 0), (0, 1)], PadMode::Edge).unwrap();
    assert_tensor(
        "edge 2d",
        &padded,
        &[3, 3],
        &[1.0, 2.0, 2.0, 1.0, 2.0, 2.0, 3.0, 4.0, 4.0],
    );
    let padded = m.pad(&[(0, 1)], PadMode::Constant(-1.0)).unwrap();
    assert_tensor(
        "constant rows only",
        &padded,
        &[3, 2],
        &[1.0, 2.0, 3.0, 4.0, -1.0, -1.0],
    );
}

fn gather_and_scatter<B: Backend>() {
    check_cases_against_reference::<B>(|c| {
        matches!(
            c,
            Case::GatherRows | Case::ScatterAddRows | Case::GatherNd | Case::ScatterAddNd
        )
    });
    let device = B::default_device();
    let ints = |v: Vec<i64>, shape: &[usize]| IntTensor::<B>::from_vec(v, shape, &device).unwrap();
    let table = tensor::<B>(&[3, 2], &[0.0, 1.0, 10.0, 11.0, 20.0, 21.0]);
    let rows = table.gather_rows(&ints(vec![2, 0, 2], &[3])).unwrap();
    assert_tensor(
        "gather_rows",
        &rows,
        &[3, 2],
        &[20.0, 21.0, 0.0, 1.0, 20.0, 21.0],
    );
    // Repeated indices accumulate.
    let updates = tensor::<B>(&[4, 2], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
    let scattered = table
        .scatter_add_rows(&ints(vec![1, 1, 0, 1], &[4]), &updates)
        .unwrap();
    assert_tensor(
        "scatter_add_rows",
        &scattered,
        &[3, 2],
        &[5.0, 7.0, 21.0, 25.0, 20.0, 21.0],
    );
    // n-d: pick elements of a [2, 3] grid, and sub-rows of a [2, 2, 2] tensor.
    let grid = tensor::<B>(&[2, 3], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    let picked = grid
        .gather_nd(&ints(vec![1, 2, 0, 1, 1, 0], &[3, 2]))
        .unwrap();
    assert_tensor("gather_nd", &picked, &[3], &[5.0, 1.0, 3.0]);
    let cube = Tensor::<B>::arange(8, &device).reshape(&[2, 2, 2]).unwrap();
    let sub = cube.gather_nd(&ints(vec![1, 0, 0, 1], &[2, 2])).unwrap();
    assert_tensor("gather_nd rows", &sub, &[2, 2], &[4.0, 5.0, 2.0, 3.0]);
    let added = grid
        .scatter_add_nd(
            &ints(vec![0, 0, 1, 2, 0, 0], &[3, 2]),
            &tensor(&[3], &[1.0, 2.0, 3.0]),
        )
        .unwrap();
    assert_tensor(
        "scatter_add_nd",
        &added,
        &[2, 3],
        &[4.0, 1.0, 2.0, 3.0, 4.0, 7.0],
    );
    // Many repeats of one index: a particle-to-grid pattern.
    let ones = Tensor::<B>::ones(&[1000, 1], &device);
    let counts = Tensor::<B>::zeros(&[4, 1], &device)
        .scatter_add_rows(
            &ints((0..1000).map(|i| [0, 3, 3, 1][i % 4]).collect(), &[1000]),
            &ones,
        )
        .unwrap();
    assert_tensor("counts", &counts, &[4, 1], &[250.0, 250.0, 0.0, 500.0]);
}

fn casts<B: Backend>() {
    let x = tensor::<B>(&[6], &[-1.7, -0.2, 0.2, 1.7, 2.0, 1e6]);
    assert_eq!(x.to_int().to_vec(), vec![-1, 0, 0, 1, 2, 1_000_000]);
    assert_eq!(
        x.floor().to_int().to_vec(),
        vec![-2, -1, 0, 1, 2, 1_000_000]
    );
    let i = IntTensor::<B>::from_vec(vec![-3, 0, 7, 16_777_216], &[2, 2], &B::default_device())
        .unwrap();
    assert_tensor(
        "int to float",
        &i.to_float(),
        &[2, 2],
        &[-3.0, 0.0, 7.0, 16_777_216.0],
    );
}

fn int_ops<B: Backend>() {
    let device = B::default_device();
    let ints = |v: Vec<i64>, shape: &[usize]| IntTensor::<B>::from_vec(v, shape, &device).unwrap();
    let a = vec![-7i64, -1, 0, 5, 9, 12];
    let b = vec![3i64, -2, 4];
    for op in IntBinaryOp::ALL {
        // [2, 3] against [3].
        let want: Vec<i64> = a
            .chunks(3)
            .flat_map(|row| row.iter().zip(&b).map(|(&x, &y)| op.apply(x, y)))
            .collect();
        let got = ints(a.clone(), &[2, 3])
            .binary(op, &ints(b.clone(), &[3]))
            .unwrap();
        assert_eq!(got.to_vec(), want, "{op:?}");
        assert_eq!(got.shape(), vec![2, 3], "{op:?}");
        let want: Vec<i64> = a.iter().map(|&x| op.apply(x, -4)).collect();
        assert_eq!(
            ints(a.clone(), &[6]).binary_scalar(op, -4).to_vec(),
            want,
            "{op:?} scalar"
        );
    }
    // Python semantics of floor division and remainder, spelled out.
    assert_eq!(IntBinaryOp::FloorDiv.apply(-7, 3), -3);
    assert_eq!(IntBinaryOp::Rem.apply(-7, 3), 2);
    assert_eq!(IntBinaryOp::Rem.apply(7, -3), -2);
    let x = ints(a.clone(), &[2, 3]);
    assert_eq!((&x + &x).to_vec(), vec![-14, -2, 0, 10, 18, 24]);
    assert_eq!((&x * 2).to_vec(), vec![-14, -2, 0, 10, 18, 24]);
    assert_eq!((&x - 1).to_vec(), vec![-8, -2, -1, 4, 8, 11]);
    assert_eq!(x.clamp(0, 9).to_vec(), vec![0, 0, 0, 5, 9, 9]);
    assert_eq!(
        x.reduce_axis(ReduceOp::Sum, 1).unwrap().to_vec(),
        vec![-8, 26]
    );
    assert_eq!(
        x.reduce_axis(ReduceOp::Max, 0).unwrap().to_vec(),
        vec![5, 9, 12]
    );
    assert_eq!(
        x.reduce_axis(ReduceOp::Min, 1).unwrap().to_vec(),
        vec![-7, 5]
    );
    assert_eq!(
        x.reduce_axis(ReduceOp::Mean, 1).unwrap().to_vec(),
        vec![-2, 8]
    );
    assert_eq!(x.slice(&[1..2, 0..2]).unwrap().to_vec(), vec![5, 9]);
    assert_eq!(x.reshape(&[3, 2]).unwrap().shape(), vec![3, 2]);
    assert_eq!(
        IntTensor::concat(&[x.clone(), x.clone()], 0)
            .unwrap()
            .shape(),
        vec![4, 3]
    );
    assert_eq!(
        x.gather_rows(&ints(vec![1, 1, 0], &[3])).unwrap().to_vec(),
        vec![5, 9, 12, 5, 9, 12, -7, -1, 0]
    );
    assert_eq!(
        IntTensor::<B>::arange(5, &device).to_vec(),
        vec![0, 1, 2, 3, 4]
    );
}

fn creation_and_random<B: Backend>() {
    let device = B::default_device();
    assert_tensor(
        "zeros",
        &Tensor::<B>::zeros(&[2, 2], &device),
        &[2, 2],
        &[0.0; 4],
    );
    assert_tensor("ones", &Tensor::<B>::ones(&[3], &device), &[3], &[1.0; 3]);
    assert_tensor(
        "full",
        &Tensor::<B>::full(&[1, 2], -2.5, &device),
        &[1, 2],
        &[-2.5, -2.5],
    );
    assert_tensor("scalar", &Tensor::<B>::scalar(4.0, &device), &[1], &[4.0]);
    assert_eq!(Tensor::<B>::scalar(4.0, &device).to_scalar().unwrap(), 4.0);
    assert_tensor(
        "arange",
        &Tensor::<B>::arange(4, &device),
        &[4],
        &[0.0, 1.0, 2.0, 3.0],
    );
    // Seeded random values are identical on every backend: they are drawn on the host.
    let uniform = Tensor::<B>::random_uniform(&[1000], -2.0, 3.0, 7, &device);
    let reference = Tensor::<Reference>::random_uniform(&[1000], -2.0, 3.0, 7, &Default::default());
    assert_eq!(uniform.to_vec(), reference.to_vec());
    assert!(uniform.to_vec().iter().all(|&v| (-2.0..3.0).contains(&v)));
    let mean = uniform.mean().to_scalar().unwrap();
    assert!((mean - 0.5).abs() < 0.15, "uniform mean {mean}");
    let normal = Tensor::<B>::random_normal(&[20_000], 1.0, 2.0, 9, &device);
    let sample_mean = normal.mean().to_scalar().unwrap();
    let sample_std = (&normal - sample_mean)
        .square()
        .mean()
        .to_scalar()
        .unwrap()
        .sqrt();
    // Standard errors: 2/√20000 ≈ 0.014 for the mean, about 0.01 for the std.
    assert!(
        (sample_mean - 1.0).abs() < 0.06,
        "normal mean {sample_mean}"
    );
    assert!((sample_std - 2.0).abs() < 0.05, "normal std {sample_std}");
    assert_ne!(
        Tensor::<B>::random_normal(&[4], 0.0, 1.0, 1, &device).to_vec(),
        Tensor::<B>::random_normal(&[4], 0.0, 1.0, 2, &device).to_vec()
    );
}

fn device_transfer<B: Backend>() {
    check_cases_against_reference::<B>(|c| matches!(c, Case::ToDevice));
    let device = B::default_device();
    let x = tensor::<B>(&[2], &[1.0, 2.0]);
    assert_eq!(x.device(), device);
    let moved = x.to_device(&device);
    assert_eq!(moved.device(), device);
    assert_eq!(moved.to_vec(), vec![1.0, 2.0]);
    let i = IntTensor::<B>::arange(3, &device).to_device(&device);
    assert_eq!(i.device(), device);
    assert_tensor("detach", &x.detach(), &[2], &[1.0, 2.0]);
    // The command line's device names: `cpu` is the default device everywhere; a GPU that is
    // not there, or a name no backend knows, is None rather than a panic.
    assert_eq!(B::device_by_name("cpu"), Some(device));
    for name in ["cuda:4096", "gpu", "cuda:x", ""] {
        assert_eq!(B::device_by_name(name), None, "{name}");
    }
}
