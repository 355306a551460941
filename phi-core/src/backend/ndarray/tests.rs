//! Unit tests of the ndarray kernels: broadcasting, views, scatters, padding, reductions.
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
        .flat_map(|k| (0..2).flat_map(move |a| (0..3).map(move |b| (a * 12 + b * 4 + k) as f32)))
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
    let out = B::float_scatter_add_rows(t, i(&[2, 0, 2, 2], &[4]), f(&seq(8), &[4, 2])).unwrap();
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
    let err =
        B::float_scatter_add_rows(t.clone(), i(&[-1], &[1]), f(&[0.0, 0.0], &[1, 2])).unwrap_err();
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
