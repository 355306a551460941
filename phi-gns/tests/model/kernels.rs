//! The kernels of `GnsKernels` on every backend against host f64 arithmetic, the split first
//! layer of the edge MLP against the dense layer on the concatenation `[e, v_s, v_r]`, and on
//! the autodiff backends every kernel's gradients against those of its composite: the tests
//! that a backend's fused overrides must pass.
//!
//! # Tolerances
//! The inputs are f32 values and the references are computed from those same values in f64, so
//! the only error is the kernel's own f32 rounding. A sum of `n` products in any order is within
//! `γ_n · Σ|terms|` of its exact value, `γ_n ≈ n · 2⁻²⁴` (Higham, *Accuracy and Stability of
//! Numerical Algorithms*, §3.1); the dense-layer and sum assertions hold every element to twice
//! that bound. LayerNorm has no such simple bound: it is held to `1e-5` of the largest output,
//! ten times the rounding of a mean, a variance and a square root of O(1) rows.

use phi_core::error::Result;
use phi_core::{AutodiffBackend, Backend, IntTensor, Tensor};
use phi_gns::graph::RadiusGraph;
use phi_gns::model::GnsKernels;
use phi_gns::model::kernels::{
    composite_edge_input_layer, composite_layer_norm, composite_linear, composite_sum_by_receiver,
};

use crate::common::{Rng, assert_close_f64};
use crate::reference::{EPS, layer_norm};

phi_core::backend_tests!(
    linear_is_x_times_w_transposed_plus_b,
    layer_norm_matches_the_host,
    edge_input_layer_is_the_dense_layer_on_the_concatenation,
    sum_by_receiver_matches_the_host,
    kernels_take_zero_edges,
);

mod gradient {
    use super::kernel_gradients_match_the_composites;
    phi_core::autodiff_backend_tests!(kernel_gradients_match_the_composites);
}

/// The unit roundoff of f32.
const U: f64 = 1.0 / (1u64 << 24) as f64;

/// `n` values uniform in `[low, high)`, rounded to f32 (and returned as the f64 of those f32).
fn uniform(rng: &mut Rng, n: usize, low: f64, high: f64) -> Vec<f64> {
    (0..n)
        .map(|_| f64::from((low + (high - low) * rng.uniform()) as f32))
        .collect()
}

fn tensor<B: Backend>(values: &[f64], shape: &[usize]) -> Tensor<B> {
    let values = values.iter().map(|&v| v as f32).collect();
    Tensor::from_vec(values, shape, &B::default_device()).unwrap()
}

fn indices<B: Backend>(values: &[i64]) -> B::Int {
    IntTensor::<B>::from_vec(values.to_vec(), &[values.len()], &B::default_device())
        .unwrap()
        .primitive()
        .clone()
}

/// Asserts `|got_i − expected_i| ≤ bound_i` for every element, naming the worst.
fn assert_within(got: &Tensor<impl Backend>, expected: &[f64], bound: &[f64], what: &str) {
    let got = got.to_vec();
    assert_eq!(got.len(), expected.len(), "{what}: length");
    for (i, ((g, e), b)) in got.iter().zip(expected).zip(bound).enumerate() {
        let error = (f64::from(*g) - e).abs();
        assert!(
            error <= *b,
            "{what}: element {i} is {g}, the host's {e} (error {error:.3e} > bound {b:.3e})"
        );
    }
}

/// `x Wᵀ + b` in f64 with its rounding bound `2 γ_{n+1} (|b| + Σ |x_k w_k|)` per element.
fn host_linear(x: &[f64], w: &[f64], b: &[f64], inputs: usize, relu: bool) -> (Vec<f64>, Vec<f64>) {
    let mut y = Vec::new();
    let mut bound = Vec::new();
    let gamma = 2.0 * (inputs + 1) as f64 * U;
    for xi in x.chunks_exact(inputs) {
        for (wo, bo) in w.chunks_exact(inputs).zip(b) {
            let s: f64 = bo + xi.iter().zip(wo).map(|(x, w)| x * w).sum::<f64>();
            let size: f64 = bo.abs() + xi.iter().zip(wo).map(|(x, w)| (x * w).abs()).sum::<f64>();
            y.push(if relu { s.max(0.0) } else { s });
            bound.push(gamma * size);
        }
    }
    (y, bound)
}

fn linear_is_x_times_w_transposed_plus_b<B: GnsKernels>() {
    check_linear::<B>(7, 9, 5);
    // The size of an edge MLP's layer on a few thousand edges (a fused kernel's blocked and
    // parallel paths).
    check_linear::<B>(3000, 32, 24);
}

fn check_linear<B: GnsKernels>(n: usize, inputs: usize, out: usize) {
    let mut rng = Rng::new(1);
    let x = uniform(&mut rng, n * inputs, -2.0, 2.0);
    let w = uniform(&mut rng, out * inputs, -0.5, 0.5);
    let b = uniform(&mut rng, out, -0.5, 0.5);
    for relu in [false, true] {
        let got = Tensor::<B>::from_primitive(
            B::gns_linear(
                tensor::<B>(&x, &[n, inputs]).into_primitive(),
                tensor::<B>(&w, &[out, inputs]).into_primitive(),
                tensor::<B>(&b, &[out]).into_primitive(),
                relu,
            )
            .unwrap(),
        );
        assert_eq!(got.shape(), vec![n, out]);
        let (expected, bound) = host_linear(&x, &w, &b, inputs, relu);
        if relu {
            // The ReLU is exercised: some outputs are clipped, others are not.
            assert!(expected.contains(&0.0) && expected.iter().any(|&v| v > 0.0));
        }
        let what = format!("{} linear [{n}, {inputs}] → {out}, relu {relu}", B::name());
        assert_within(&got, &expected, &bound, &what);
    }
}

fn layer_norm_matches_the_host<B: GnsKernels>() {
    check_layer_norm::<B>(9, 4);
    check_layer_norm::<B>(32, 3000);
}

fn check_layer_norm<B: GnsKernels>(k: usize, spread_rows: usize) {
    let mut rng = Rng::new(2);
    // Rows of mean ~3 and spread ~1, a constant row (variance 0: the output is beta, and
    // without eps it would be 0/0) and a row of variance ~3e-7, below eps, which tells
    // √(var + eps) from √var + eps.
    let mut x = uniform(&mut rng, spread_rows * k, 2.0, 4.0);
    x.extend(std::iter::repeat_n(1.5, k));
    x.extend(uniform(&mut rng, k, -1e-3, 1e-3));
    let rows = x.len() / k;
    let gamma = uniform(&mut rng, k, 0.5, 1.5);
    let beta = uniform(&mut rng, k, -0.5, 0.5);
    let got = Tensor::<B>::from_primitive(
        B::gns_layer_norm(
            tensor::<B>(&x, &[rows, k]).into_primitive(),
            tensor::<B>(&gamma, &[k]).into_primitive(),
            tensor::<B>(&beta, &[k]).into_primitive(),
            EPS as f32,
        )
        .unwrap(),
    );
    assert_eq!(got.shape(), vec![rows, k]);
    let expected = layer_norm(&x, &gamma, &beta);
    assert_close_f64(
        &got.to_vec().into_iter().map(f64::from).collect::<Vec<_>>(),
        &expected,
        1e-5,
        &format!("{} layer norm [{rows}, {k}]", B::name()),
    );
    // The reference itself: each row of (y − β) / γ has mean 0 and, away from eps, variance 1.
    for row in expected.chunks_exact(k).take(spread_rows) {
        let z: Vec<f64> = row
            .iter()
            .zip(&gamma)
            .zip(&beta)
            .map(|((y, g), b)| (y - b) / g)
            .collect();
        let mean = z.iter().sum::<f64>() / k as f64;
        let var = z.iter().map(|z| z * z).sum::<f64>() / k as f64;
        assert!(
            mean.abs() < 1e-12 && (var - 1.0).abs() < 1e-4,
            "{mean} {var}"
        );
    }
    assert_eq!(&expected[spread_rows * k..(spread_rows + 1) * k], &beta[..]);
}

/// Seven nodes; receivers ascending (the radius graph's order); nodes 0, 3 and 6 receive
/// nothing, node 4 receives four edges, node 1 three, a self-edge on 2; senders repeat.
const SENDERS: [i64; 10] = [1, 2, 4, 2, 0, 4, 5, 6, 1, 5];
const RECEIVERS: [i64; 10] = [1, 1, 1, 2, 4, 4, 4, 4, 5, 5];
const NODES: usize = 7;

fn edge_input_layer_is_the_dense_layer_on_the_concatenation<B: GnsKernels>() {
    check_edge_input_layer::<B>(&SENDERS, &RECEIVERS, NODES, 5, 4, 6);
    let (senders, receivers, nodes) = large_graph();
    check_edge_input_layer::<B>(&senders, &receivers, nodes, 16, 16, 16);
}

/// The radius graph of 300 particles at spacing 0.01 with R = 0.03 (~8000 edges), the
/// neighbourhood size of the thesis' data.
fn large_graph() -> (Vec<i64>, Vec<i64>, usize) {
    let mut rng = Rng::new(9);
    let positions: Vec<f32> = (0..300)
        .flat_map(|i| {
            let (x, y) = ((i % 20) as f64, (i / 20) as f64);
            [
                (0.2 + 0.01 * x + 0.002 * (rng.uniform() - 0.5)) as f32,
                (0.2 + 0.01 * y + 0.002 * (rng.uniform() - 0.5)) as f32,
            ]
        })
        .collect();
    let graph = RadiusGraph::for_positions(&positions, 2, 0.03).unwrap();
    assert!(graph.edges() > 6000, "{} edges", graph.edges());
    (graph.senders().to_vec(), graph.receivers().to_vec(), 300)
}

fn check_edge_input_layer<B: GnsKernels>(
    senders: &[i64],
    receivers: &[i64],
    nodes: usize,
    width: usize,
    latent: usize,
    out: usize,
) {
    let mut rng = Rng::new(3);
    let edges = senders.len();
    let e = uniform(&mut rng, edges * width, -1.0, 1.0);
    let v = uniform(&mut rng, nodes * latent, -1.0, 1.0);
    let inputs = width + 2 * latent;
    let w = uniform(&mut rng, out * inputs, -0.5, 0.5);
    let b = uniform(&mut rng, out, -0.5, 0.5);
    // The blocks W_e, W_s, W_r of W [out, width + 2 latent].
    let block = |from: usize, to: usize| -> Vec<f64> {
        w.chunks_exact(inputs)
            .flat_map(|row| row[from..to].to_vec())
            .collect()
    };
    let (w_e, w_s, w_r) = (
        block(0, width),
        block(width, width + latent),
        block(width + latent, inputs),
    );
    // The node projections v W_sᵀ, v W_rᵀ, rounded to f32 as the network hands them over.
    let zeros = vec![0.0; out];
    let project = |wb: &[f64]| -> Vec<f64> {
        host_linear(&v, wb, &zeros, latent, false)
            .0
            .into_iter()
            .map(|x| f64::from(x as f32))
            .collect()
    };
    let (p_s, p_r) = (project(&w_s), project(&w_r));
    // The concatenation [e, v_s, v_r] per edge.
    let concatenated: Vec<f64> = (0..edges)
        .flat_map(|j| {
            let (s, r) = (senders[j] as usize, receivers[j] as usize);
            let mut row = e[j * width..(j + 1) * width].to_vec();
            row.extend_from_slice(&v[s * latent..(s + 1) * latent]);
            row.extend_from_slice(&v[r * latent..(r + 1) * latent]);
            row
        })
        .collect();
    for relu in [false, true] {
        let got = Tensor::<B>::from_primitive(
            B::gns_edge_input_layer(
                tensor::<B>(&e, &[edges, width]).into_primitive(),
                tensor::<B>(&w_e, &[out, width]).into_primitive(),
                tensor::<B>(&b, &[out]).into_primitive(),
                tensor::<B>(&p_s, &[nodes, out]).into_primitive(),
                tensor::<B>(&p_r, &[nodes, out]).into_primitive(),
                indices::<B>(senders),
                indices::<B>(receivers),
                relu,
            )
            .unwrap(),
        );
        assert_eq!(got.shape(), vec![edges, out]);
        let what = format!("{} edge input layer, {edges} edges, relu {relu}", B::name());

        // Against the host: e W_eᵀ + b + P_s[s] + P_r[r] of the values handed over.
        let (own, own_bound) = host_linear(&e, &w_e, &b, width, false);
        let mut expected = Vec::new();
        let mut bound = Vec::new();
        for j in 0..edges {
            let (s, r) = (senders[j] as usize, receivers[j] as usize);
            for o in 0..out {
                let x = own[j * out + o] + p_s[s * out + o] + p_r[r * out + o];
                expected.push(if relu { x.max(0.0) } else { x });
                let size = own_bound[j * out + o] / (2.0 * (width + 1) as f64 * U)
                    + p_s[s * out + o].abs()
                    + p_r[r * out + o].abs();
                bound.push(2.0 * (width + 3) as f64 * U * size);
            }
        }
        assert_within(
            &got,
            &expected,
            &bound,
            &format!("{what}, against the host"),
        );

        // Against the dense layer on the concatenation (on the same backend), within the
        // rounding of both and of the projections.
        let dense = Tensor::<B>::from_primitive(
            B::gns_linear(
                tensor::<B>(&concatenated, &[edges, inputs]).into_primitive(),
                tensor::<B>(&w, &[out, inputs]).into_primitive(),
                tensor::<B>(&b, &[out]).into_primitive(),
                relu,
            )
            .unwrap(),
        );
        let (exact, exact_bound) = host_linear(&concatenated, &w, &b, inputs, relu);
        let dense_values: Vec<f64> = dense.to_vec().into_iter().map(f64::from).collect();
        let both: Vec<f64> = exact_bound.iter().map(|b| 2.0 * b).collect();
        assert_within(
            &got,
            &dense_values,
            &both,
            &format!("{what}, against the dense layer"),
        );
        assert_within(
            &dense,
            &exact,
            &exact_bound,
            &format!("{what}, the dense layer"),
        );
        if relu {
            assert!(expected.contains(&0.0) && expected.iter().any(|&x| x > 0.0));
        }
    }
}

fn sum_by_receiver_matches_the_host<B: GnsKernels>() {
    let got = check_sum_by_receiver::<B>(&RECEIVERS, NODES, 3);
    // Nodes without incoming edges get exact zeros.
    for node in [0, 3, 6] {
        assert_eq!(&got[node * 3..(node + 1) * 3], &[0.0; 3], "node {node}");
    }
    let (_, receivers, nodes) = large_graph();
    check_sum_by_receiver::<B>(&receivers, nodes, 32);
}

/// Checks the sums against the host and returns them.
fn check_sum_by_receiver<B: GnsKernels>(receivers: &[i64], nodes: usize, k: usize) -> Vec<f32> {
    let mut rng = Rng::new(4);
    let edges = receivers.len();
    let values = uniform(&mut rng, edges * k, -1.0, 1.0);
    let got = Tensor::<B>::from_primitive(
        B::gns_sum_by_receiver(
            tensor::<B>(&values, &[edges, k]).into_primitive(),
            indices::<B>(receivers),
            nodes,
        )
        .unwrap(),
    );
    assert_eq!(got.shape(), vec![nodes, k]);
    let mut expected = vec![0.0; nodes * k];
    let mut size = vec![0.0; nodes * k];
    let mut count = vec![0usize; nodes];
    for (j, &r) in receivers.iter().enumerate() {
        count[r as usize] += 1;
        for c in 0..k {
            expected[r as usize * k + c] += values[j * k + c];
            size[r as usize * k + c] += values[j * k + c].abs();
        }
    }
    let bound: Vec<f64> = size
        .iter()
        .enumerate()
        .map(|(i, s)| 2.0 * count[i / k] as f64 * U * s)
        .collect();
    let what = format!("{} sum by receiver, {edges} edges", B::name());
    assert_within(&got, &expected, &bound, &what);
    got.to_vec()
}

fn kernels_take_zero_edges<B: GnsKernels>() {
    let (width, latent, out) = (3, 4, 5);
    let empty = |columns: usize| tensor::<B>(&[], &[0, columns]).into_primitive();
    let none = || indices::<B>(&[]);
    let w = vec![0.25; out * width];
    let b = vec![0.5; out];

    let sums =
        Tensor::<B>::from_primitive(B::gns_sum_by_receiver(empty(width), none(), 4).unwrap());
    assert_eq!(sums.shape(), vec![4, width]);
    assert_eq!(sums.to_vec(), vec![0.0; 4 * width]);

    let projections = tensor::<B>(&vec![1.0; 4 * out], &[4, out]);
    let first = Tensor::<B>::from_primitive(
        B::gns_edge_input_layer(
            empty(width),
            tensor::<B>(&w, &[out, width]).into_primitive(),
            tensor::<B>(&b, &[out]).into_primitive(),
            projections.primitive().clone(),
            projections.into_primitive(),
            none(),
            none(),
            true,
        )
        .unwrap(),
    );
    assert_eq!(first.shape(), vec![0, out]);

    let dense = Tensor::<B>::from_primitive(
        B::gns_linear(
            empty(width),
            tensor::<B>(&w, &[out, width]).into_primitive(),
            tensor::<B>(&b, &[out]).into_primitive(),
            true,
        )
        .unwrap(),
    );
    assert_eq!(dense.shape(), vec![0, out]);
    let normed = Tensor::<B>::from_primitive(
        B::gns_layer_norm(
            empty(latent),
            tensor::<B>(&[1.0; 4], &[latent]).into_primitive(),
            tensor::<B>(&[0.0; 4], &[latent]).into_primitive(),
            EPS as f32,
        )
        .unwrap(),
    );
    assert_eq!(normed.shape(), vec![0, latent]);
}

/// A kernel as a function of its float inputs.
type Kernel<'a, B> = &'a dyn Fn(&[<B as Backend>::Float]) -> Result<<B as Backend>::Float>;

/// The values of `fused` and `composite` on `inputs`, and the gradients in every input of
/// `L = Σ c ⊙ output` for a seeded random `c`, agree to `1e-4` of their largest entry: the
/// fused kernel's backward pass is its composite's (f32 sums in other orders: measured ~1e-6).
fn assert_same_gradients<B: AutodiffBackend + GnsKernels>(
    inputs: &[Tensor<B>],
    fused: impl Fn(&[B::Float]) -> Result<B::Float>,
    composite: impl Fn(&[B::Float]) -> Result<B::Float>,
    what: &str,
) {
    let run = |f: Kernel<'_, B>, c: Option<&Tensor<B>>| {
        let leaves: Vec<Tensor<B>> = inputs.iter().map(|t| t.require_grad()).collect();
        let primitives: Vec<B::Float> = leaves.iter().map(|t| t.primitive().clone()).collect();
        let y = Tensor::<B>::from_primitive(f(&primitives).unwrap());
        let c = match c {
            Some(c) => c.clone(),
            None => {
                let mut rng = Rng::new(17);
                let values = uniform(&mut rng, y.numel(), -1.0, 1.0);
                tensor::<B>(&values, &y.shape())
            }
        };
        let loss = y
            .binary(phi_core::backend::BinaryOp::Mul, &c)
            .unwrap()
            .sum();
        let wrt: Vec<&Tensor<B>> = leaves.iter().collect();
        (y.detach(), loss.gradients(&wrt).unwrap(), c)
    };
    let (y, grads, c) = run(&fused, None);
    let (y0, grads0, _) = run(&composite, Some(&c));
    let as_f64 = |t: &Tensor<B>| t.to_vec().into_iter().map(f64::from).collect::<Vec<_>>();
    let name = B::name();
    assert_close_f64(
        &as_f64(&y),
        &as_f64(&y0),
        1e-4,
        &format!("{name} {what}: value"),
    );
    for (i, (g, g0)) in grads.iter().zip(&grads0).enumerate() {
        assert_eq!(g.shape(), g0.shape(), "{name} {what}: gradient {i} shape");
        let what = format!("{name} {what}: gradient in input {i}");
        assert_close_f64(&as_f64(g), &as_f64(g0), 1e-4, &what);
    }
}

fn kernel_gradients_match_the_composites<B: AutodiffBackend + GnsKernels>() {
    let mut rng = Rng::new(5);
    let mut input = |shape: &[usize], low: f64, high: f64| {
        let n = shape.iter().product();
        tensor::<B>(&uniform(&mut rng, n, low, high), shape)
    };
    // More rows than one task of a kernel's backward pass (its partial sums are added).
    let (rows, k, out) = (2500, 12, 10);
    let x = input(&[rows, k], -2.0, 2.0);
    let w = input(&[out, k], -0.5, 0.5);
    let b = input(&[out], -0.5, 0.5);
    for relu in [false, true] {
        assert_same_gradients(
            &[x.clone(), w.clone(), b.clone()],
            |t| B::gns_linear(t[0].clone(), t[1].clone(), t[2].clone(), relu),
            |t| composite_linear::<B>(t[0].clone(), t[1].clone(), t[2].clone(), relu),
            &format!("linear, relu {relu}"),
        );
    }
    let gamma = input(&[k], 0.5, 1.5);
    let beta = input(&[k], -0.5, 0.5);
    assert_same_gradients(
        &[x.clone(), gamma, beta],
        |t| B::gns_layer_norm(t[0].clone(), t[1].clone(), t[2].clone(), EPS as f32),
        |t| composite_layer_norm::<B>(t[0].clone(), t[1].clone(), t[2].clone(), EPS as f32),
        "layer norm",
    );
    let (senders, receivers, nodes) = large_graph();
    let edges = senders.len();
    let e = input(&[edges, k], -1.0, 1.0);
    let p_s = input(&[nodes, out], -1.0, 1.0);
    let p_r = input(&[nodes, out], -1.0, 1.0);
    let (s, r) = (indices::<B>(&senders), indices::<B>(&receivers));
    for relu in [false, true] {
        let layer = |t: &[B::Float], composite: bool| {
            let f = if composite {
                composite_edge_input_layer::<B>
            } else {
                B::gns_edge_input_layer
            };
            f(
                t[0].clone(),
                t[1].clone(),
                t[2].clone(),
                t[3].clone(),
                t[4].clone(),
                s.clone(),
                r.clone(),
                relu,
            )
        };
        assert_same_gradients(
            &[e.clone(), w.clone(), b.clone(), p_s.clone(), p_r.clone()],
            |t| layer(t, false),
            |t| layer(t, true),
            &format!("edge input layer, relu {relu}"),
        );
    }
    assert_same_gradients(
        &[e],
        |t| B::gns_sum_by_receiver(t[0].clone(), r.clone(), nodes),
        |t| composite_sum_by_receiver::<B>(t[0].clone(), r.clone(), nodes),
        "sum by receiver",
    );
}
