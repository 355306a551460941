//! The differentiable operations of the trait as data: each [`Case`] knows its inputs and how to
//! apply itself on any backend, so forward comparisons and gradient checks share one list.
//!
//! Inputs stay away from the places where an operation is not smooth (kinks of `abs`, `relu`,
//! `clamp`; ties of `min`, `max`; integers for `floor`) by more than the finite-difference step,
//! so that central differences are a valid reference.

use phi_core::backend::{BinaryOp, PadMode, ReduceOp, UnaryOp};
use phi_core::{Backend, IntTensor, Tensor};

use super::values;

/// One operation applied to fixed inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Case {
    Unary(UnaryOp),
    /// Broadcasting `[3, 1, 4]` against `[2, 4]`.
    Binary(BinaryOp),
    BinaryScalar(BinaryOp, f32),
    Clamp,
    Where,
    Reduce(ReduceOp),
    ReduceAxis(ReduceOp, usize),
    /// Batched `[2, 3, 4] × [2, 4, 5]`.
    Matmul,
    /// `[2, 3, 4] × [4, 5]`, the right operand broadcast over the batch.
    MatmulBroadcast,
    Reshape,
    Permute,
    Slice,
    Concat,
    Stack,
    BroadcastTo,
    Pad(PadMode),
    GatherRows,
    ScatterAddRows,
    GatherNd,
    ScatterAddNd,
    ToDevice,
}

impl Case {
    /// Every case, covering every differentiable operation of the trait.
    pub fn all() -> Vec<Case> {
        let mut cases: Vec<Case> = UnaryOp::ALL.iter().map(|&op| Case::Unary(op)).collect();
        cases.extend(BinaryOp::ALL.iter().map(|&op| Case::Binary(op)));
        cases.extend(
            BinaryOp::ALL
                .iter()
                .map(|&op| Case::BinaryScalar(op, scalar_operand(op))),
        );
        cases.extend([Case::Clamp, Case::Where]);
        cases.extend(ReduceOp::ALL.iter().map(|&op| Case::Reduce(op)));
        for axis in 0..3 {
            cases.extend(ReduceOp::ALL.iter().map(|&op| Case::ReduceAxis(op, axis)));
        }
        cases.extend([
            Case::Matmul,
            Case::MatmulBroadcast,
            Case::Reshape,
            Case::Permute,
            Case::Slice,
            Case::Concat,
            Case::Stack,
            Case::BroadcastTo,
            Case::Pad(PadMode::Constant(0.5)),
            Case::Pad(PadMode::Edge),
            Case::Pad(PadMode::Periodic),
            Case::Pad(PadMode::Symmetric),
            Case::GatherRows,
            Case::ScatterAddRows,
            Case::GatherNd,
            Case::ScatterAddNd,
            Case::ToDevice,
        ]);
        cases
    }

    /// The shapes and values of the inputs.
    pub fn inputs(&self) -> Vec<(Vec<usize>, Vec<f32>)> {
        match *self {
            Case::Unary(op) => vec![(vec![2, 5], unary_input(op))],
            Case::Binary(op) => {
                let (a, b) = binary_inputs(op, 12, 8);
                vec![(vec![3, 1, 4], a), (vec![2, 4], b)]
            }
            Case::BinaryScalar(op, _) => vec![(vec![2, 3], binary_inputs(op, 6, 1).0)],
            // On a 0.13 grid offset so that no value is within 0.03 of the bounds ±0.5.
            Case::Clamp => vec![(
                vec![3, 3],
                (0..9).map(|i| -0.98 + 0.23 * i as f32).collect(),
            )],
            Case::Where => vec![
                (vec![2, 3], values(6, -1.0, 1.0, 11)),
                (vec![3], values(3, -1.0, 1.0, 12)),
            ],
            Case::Reduce(_) | Case::ReduceAxis(..) => vec![(vec![2, 3, 4], distinct(24))],
            Case::Matmul => vec![
                (vec![2, 3, 4], values(24, -1.0, 1.0, 21)),
                (vec![2, 4, 5], values(40, -1.0, 1.0, 22)),
            ],
            Case::MatmulBroadcast => {
                vec![
                    (vec![2, 3, 4], values(24, -1.0, 1.0, 23)),
                    (vec![4, 5], values(20, -1.0, 1.0, 24)),
                ]
            }
            Case::Reshape | Case::Permute | Case::Slice | Case::Pad(_) => {
                vec![(vec![2, 3, 4], values(24, -1.0, 1.0, 31))]
            }
            // A one-wide column too: the ndarray kernel copies those element by element.
            Case::Concat => vec![
                (vec![2, 3], values(6, -1.0, 1.0, 32)),
                (vec![2, 1], values(2, -1.0, 1.0, 34)),
                (vec![2, 2], values(4, -1.0, 1.0, 33)),
            ],
            Case::Stack => vec![
                (vec![2, 3], values(6, -1.0, 1.0, 34)),
                (vec![2, 3], values(6, -1.0, 1.0, 35)),
            ],
            Case::BroadcastTo => vec![(vec![3, 1], values(3, -1.0, 1.0, 36))],
            Case::GatherRows | Case::GatherNd => vec![(vec![4, 3], values(12, -1.0, 1.0, 41))],
            Case::ScatterAddRows | Case::ScatterAddNd => {
                vec![
                    (vec![4, 3], values(12, -1.0, 1.0, 42)),
                    (vec![5, 3], values(15, -1.0, 1.0, 43)),
                ]
            }
            Case::ToDevice => vec![(vec![4], values(4, -1.0, 1.0, 44))],
        }
    }

    /// The operation applied to `inputs` (shaped as [`Case::inputs`] says).
    pub fn apply<B: Backend>(&self, inputs: &[Tensor<B>]) -> Tensor<B> {
        let device = inputs[0].device();
        let ints = |values: Vec<i64>, shape: &[usize]| {
            IntTensor::<B>::from_vec(values, shape, &device).unwrap()
        };
        let x = &inputs[0];
        match *self {
            Case::Unary(op) => x.unary(op),
            Case::Binary(op) => x.binary(op, &inputs[1]).unwrap(),
            Case::BinaryScalar(op, scalar) => x.binary_scalar(op, scalar),
            Case::Clamp => x.clamp(-0.5, 0.5),
            Case::Where => {
                let mask =
                    Tensor::from_vec(vec![1.0, 0.0, 1.0, 0.0, 0.0, 1.0], &[2, 3], &device).unwrap();
                Tensor::select(&mask, x, &inputs[1]).unwrap()
            }
            Case::Reduce(op) => x.reduce(op).unwrap(),
            Case::ReduceAxis(op, axis) => x.reduce_axis(op, axis, true).unwrap(),
            Case::Matmul | Case::MatmulBroadcast => x.matmul(&inputs[1]).unwrap(),
            Case::Reshape => x.reshape(&[4, 6]).unwrap(),
            Case::Permute => x.permute(&[2, 0, 1]).unwrap(),
            Case::Slice => x.slice(&[1..2, 0..3, 1..3]).unwrap(),
            Case::Concat => Tensor::concat(inputs, 1).unwrap(),
            Case::Stack => Tensor::stack(inputs, 1).unwrap(),
            Case::BroadcastTo => x.broadcast_to(&[2, 3, 4]).unwrap(),
            Case::Pad(mode) => x.pad(&[(1, 0), (0, 2), (2, 1)], mode).unwrap(),
            Case::GatherRows => x.gather_rows(&ints(vec![3, 0, 3, 1, 3], &[5])).unwrap(),
            Case::ScatterAddRows => x
                .scatter_add_rows(&ints(vec![2, 0, 2, 3, 2], &[5]), &inputs[1])
                .unwrap(),
            Case::GatherNd => x
                .gather_nd(&ints(vec![3, 2, 0, 0, 3, 2, 1, 1], &[4, 2]))
                .unwrap(),
            Case::ScatterAddNd => {
                let flat_values = inputs[1].reshape(&[15]).unwrap();
                let indices = vec![
                    0, 1, 3, 2, 0, 1, 1, 0, 2, 2, 3, 2, 0, 1, 1, 1, 2, 0, 3, 0, 0, 0, 1, 2, 3, 1,
                    2, 2, 0, 2,
                ];
                x.scatter_add_nd(&ints(indices, &[15, 2]), &flat_values)
                    .unwrap()
            }
            Case::ToDevice => x.to_device(&B::default_device()),
        }
    }
}

/// The scalar operand of a `BinaryScalar` case.
fn scalar_operand(op: BinaryOp) -> f32 {
    match op {
        BinaryOp::Pow => 1.7,
        BinaryOp::Min | BinaryOp::Max => 0.11,
        _ => -0.7,
    }
}

/// Input of a unary case, inside its domain and away from its kinks.
fn unary_input(op: UnaryOp) -> Vec<f32> {
    match op {
        UnaryOp::Sqrt | UnaryOp::Log | UnaryOp::Recip => values(10, 0.5, 2.0, 1),
        // Half-way between integers, so a small step never crosses one.
        UnaryOp::Floor => (0..10).map(|i| i as f32 - 4.5).collect(),
        // Alternating signs, at least 0.2 away from zero.
        UnaryOp::Abs | UnaryOp::Sign | UnaryOp::Relu => values(10, 0.2, 1.5, 2)
            .into_iter()
            .enumerate()
            .map(|(i, v)| if i % 2 == 0 { v } else { -v })
            .collect(),
        _ => values(10, -1.5, 1.5, 3),
    }
}

/// Inputs of a binary case with `n` and `m` elements, inside the domain and away from ties.
fn binary_inputs(op: BinaryOp, n: usize, m: usize) -> (Vec<f32>, Vec<f32>) {
    match op {
        BinaryOp::Pow => (values(n, 0.5, 2.0, 4), values(m, -1.5, 1.5, 5)),
        BinaryOp::Div | BinaryOp::Atan2 => (
            values(n, -1.5, 1.5, 6),
            values(m, 0.5, 1.5, 7)
                .into_iter()
                .enumerate()
                .map(|(i, v)| if i % 3 == 1 { -v } else { v })
                .collect(),
        ),
        // Two interleaved grids 0.12 apart at least, so no pair is a near tie.
        BinaryOp::Min | BinaryOp::Max => (
            (0..n).map(|i| 0.05 + 0.25 * ((i * 3) % 7) as f32).collect(),
            (0..m).map(|j| 0.17 + 0.25 * ((j * 2) % 5) as f32).collect(),
        ),
        _ => (values(n, -1.5, 1.5, 8), values(m, -1.5, 1.5, 9)),
    }
}

/// `n` distinct values at least 0.1 apart, in a scrambled order: no ties for max and min.
fn distinct(n: usize) -> Vec<f32> {
    (0..n).map(|i| 0.1 * ((i * 7) % n) as f32 - 1.0).collect()
}
