//! The debiased Sinkhorn divergence: a permutation-invariant loss between point sets of any sizes,
//! and on the host an estimate of the 2-Wasserstein distance.

use super::{PointSetError, Result, check_point_sets};
use crate::backend::{Backend, ReduceOp};
use crate::tensor::Tensor;

/// Options of [`sinkhorn_divergence`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SinkhornOptions {
    /// Entropic regularisation `ε` (domain units², the cost is `½|x − y|²`).
    pub epsilon: f32,
    /// ε-scaling: the potentials are first solved at `ε = diameter²` and `ε` shrinks by this
    /// factor per iteration down to `epsilon` (geomloss' annealing; 0.7 is a safe default).
    pub scaling: f64,
    /// At the final `ε`, iterate until no potential changes by more than this (domain
    /// units²)...
    pub tolerance: f64,
    /// ... or this many iterations.
    pub max_iterations: usize,
}

impl SinkhornOptions {
    /// `epsilon` with ε-scaling factor 0.7, then at most 1000 iterations at the final ε to a
    /// tolerance of `10⁻⁶ ε`.
    pub fn new(epsilon: f32) -> Self {
        Self {
            epsilon,
            scaling: 0.7,
            tolerance: 1e-6 * f64::from(epsilon),
            max_iterations: 1000,
        }
    }
}

/// The debiased Sinkhorn divergence `S(a, b) = OT_ε(a, b) − ½ OT_ε(a, a) − ½ OT_ε(b, b)` between
/// the uniform measures on the point sets `a` `[N, d]` and `b` `[M, d]`, with cost `½|x − y|²`
/// (Feydy et al. 2019). `S ≥ 0`, `S(a, a) = 0`, it is invariant to the order of the points, and
/// for `ε → 0` it tends to `½ W₂²`.
///
/// The dual potentials are found by log-domain Sinkhorn iterations with ε-scaling, on the host in
/// `f64` and detached (they are optimal, so by the envelope theorem their derivative does not
/// enter the gradient). One last update `f = −ε log Σⱼ βⱼ exp((gⱼ − C(aᵢ, bⱼ))/ε)` is taken with
/// tensor operations on the tracked points: its value at convergence is the potential and its
/// gradient is `Σⱼ πᵢⱼ ∇C(aᵢ, bⱼ)`, the gradient of `OT_ε`.
///
/// # Errors
/// [`PointSetError::Invalid`] for empty sets, different dimensions or an `ε` that is not positive
/// and finite.
pub fn sinkhorn_divergence<B: Backend>(
    a: &Tensor<B>,
    b: &Tensor<B>,
    options: &SinkhornOptions,
) -> Result<Tensor<B>> {
    check_point_sets("sinkhorn divergence", a, b)?;
    if !(options.epsilon.is_finite() && options.epsilon > 0.0) {
        return Err(PointSetError::Invalid {
            what: "sinkhorn divergence",
            reason: format!(
                "epsilon must be positive and finite, got {}",
                options.epsilon
            ),
        });
    }
    let (ha, hb) = (a.to_vec(), b.to_vec());
    let d = a.shape()[1];
    let potentials = HostSinkhorn::new(&ha, &hb, d, options);
    let ot_ab = dual_cost(a, b, &potentials.g_ab, options.epsilon)?;
    let ot_aa = dual_cost(a, a, &potentials.f_aa, options.epsilon)?;
    let ot_bb = dual_cost(b, b, &potentials.g_bb, options.epsilon)?;
    Ok(ot_ab - (ot_aa + ot_bb) * 0.5)
}

/// `OT_ε(x, y) = ⟨α, T(g)⟩ + ⟨β, g⟩`, where `T(g)ᵢ = −ε log Σⱼ βⱼ exp((gⱼ − Cᵢⱼ)/ε)` is computed
/// with tensor operations from the tracked points and the detached optimal potential `g` on `y`
/// (so `T(g)` is the potential on `x`), and `⟨β, g⟩` is a constant. Its gradient is
/// `Σᵢⱼ πᵢⱼ dCᵢⱼ`, through both arguments of the cost: taking `T` once is what makes the
/// gradient of the symmetric `OT(a, a)` right too (not twice it).
fn dual_cost<B: Backend>(
    x: &Tensor<B>,
    y: &Tensor<B>,
    g: &[f64],
    epsilon: f32,
) -> Result<Tensor<B>> {
    let (n, m) = (x.shape()[0], y.shape()[0]);
    let device = x.device();
    let cost = (x.unsqueeze(1)? - &y.unsqueeze(0)?).square().sum_axis(2)? * 0.5;
    let log_beta = -(m as f64).ln();
    let g_row: Vec<f32> = g
        .iter()
        .map(|&v| (v / f64::from(epsilon) + log_beta) as f32)
        .collect();
    let g_row = Tensor::from_vec(g_row, &[1, m], &device)?;
    let exponent = g_row - cost * (1.0 / epsilon);
    let max = exponent.detach().reduce_axis(ReduceOp::Max, 1, true)?;
    let log_sum = (exponent - &max)
        .exp()
        .sum_axis(1)?
        .log()
        .reshape(&[n, 1])?
        + max;
    let f = log_sum * (-epsilon);
    let other = g.iter().sum::<f64>() / g.len() as f64;
    Ok(f.mean() + other as f32)
}

/// Log-domain Sinkhorn potentials on the host: `f_ab, g_ab` for `OT(a, b)` and the symmetric
/// `f_aa`, `g_bb`.
struct HostSinkhorn {
    /// Potential on `a` of `OT(a, b)`.
    f_ab: Vec<f64>,
    /// Potential on `b` of `OT(a, b)`.
    g_ab: Vec<f64>,
    /// The symmetric potential of `OT(a, a)`.
    f_aa: Vec<f64>,
    /// The symmetric potential of `OT(b, b)`.
    g_bb: Vec<f64>,
}

/// `½ |x − y|²` for every pair, row-major `[N, M]`.
fn host_cost(a: &[f32], b: &[f32], d: usize) -> Vec<f64> {
    let mut cost = Vec::with_capacity(a.len() / d * (b.len() / d));
    for x in a.chunks(d) {
        for y in b.chunks(d) {
            let s: f64 = x
                .iter()
                .zip(y)
                .map(|(p, q)| (f64::from(*p) - f64::from(*q)).powi(2))
                .sum();
            cost.push(0.5 * s);
        }
    }
    cost
}

/// `T(g)ᵢ = −ε log (1/M) Σⱼ exp((gⱼ − Cᵢⱼ)/ε)` for a row-major cost `[N, M]`; `transpose` reads it
/// as `[M, N]`.
fn softmin(cost: &[f64], n: usize, m: usize, g: &[f64], eps: f64, transpose: bool) -> Vec<f64> {
    let at = |i: usize, j: usize| {
        if transpose {
            cost[j * n + i]
        } else {
            cost[i * m + j]
        }
    };
    let log_m = (m as f64).ln();
    (0..n)
        .map(|i| {
            let mut max = f64::NEG_INFINITY;
            for (j, gj) in g.iter().enumerate() {
                max = max.max((gj - at(i, j)) / eps);
            }
            let sum: f64 = g
                .iter()
                .enumerate()
                .map(|(j, gj)| ((gj - at(i, j)) / eps - max).exp())
                .sum();
            -eps * (max + sum.ln() - log_m)
        })
        .collect()
}

/// The annealing schedule: `diameter²` shrinking by `scaling` down to (excluding) `epsilon`.
fn epsilon_schedule(diameter2: f64, options: &SinkhornOptions) -> Vec<f64> {
    let target = f64::from(options.epsilon);
    let mut schedule = Vec::new();
    let mut eps = diameter2.max(target);
    while eps > target {
        schedule.push(eps);
        eps *= options.scaling.clamp(0.1, 0.95);
    }
    schedule
}

fn largest_change(old: &[f64], new: &[f64]) -> f64 {
    old.iter()
        .zip(new)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

impl HostSinkhorn {
    fn new(a: &[f32], b: &[f32], d: usize, options: &SinkhornOptions) -> Self {
        let (n, m) = (a.len() / d, b.len() / d);
        let diameter2 = {
            let mut lo = vec![f32::INFINITY; d];
            let mut hi = vec![f32::NEG_INFINITY; d];
            for p in a.chunks(d).chain(b.chunks(d)) {
                for k in 0..d {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            (0..d)
                .map(|k| f64::from(hi[k] - lo[k]).powi(2))
                .sum::<f64>()
        };
        let schedule = epsilon_schedule(diameter2, options);
        let eps = f64::from(options.epsilon);
        let c_ab = host_cost(a, b, d);
        let (mut f_ab, mut g_ab) = (vec![0.0; n], vec![0.0; m]);
        for &e in &schedule {
            // Annealing: simultaneous, averaged updates (geomloss' symmetric Sinkhorn).
            let f_new = softmin(&c_ab, n, m, &g_ab, e, false);
            let g_new = softmin(&c_ab, m, n, &f_ab, e, true);
            average(&mut f_ab, &f_new);
            average(&mut g_ab, &g_new);
        }
        // At the final ε, alternating updates converge much faster than averaged ones; the last
        // update is `g = T(f)`, and the loss takes `f = T(g)` once more with tracked points.
        for _ in 0..options.max_iterations.max(1) {
            let f_new = softmin(&c_ab, n, m, &g_ab, eps, false);
            let g_new = softmin(&c_ab, m, n, &f_new, eps, true);
            let change = largest_change(&f_ab, &f_new).max(largest_change(&g_ab, &g_new));
            (f_ab, g_ab) = (f_new, g_new);
            if change <= options.tolerance {
                break;
            }
        }
        let symmetric = |p: &[f32], k: usize| {
            let c = host_cost(p, p, d);
            let mut f = vec![0.0; k];
            for &e in &schedule {
                let f_new = softmin(&c, k, k, &f, e, false);
                average(&mut f, &f_new);
            }
            // The averaged symmetric update converges in a few iterations (Feydy et al.).
            for _ in 0..options.max_iterations.max(1) {
                let mut f_new = softmin(&c, k, k, &f, eps, false);
                average(&mut f_new, &f);
                let change = largest_change(&f, &f_new);
                f = f_new;
                if change <= options.tolerance {
                    break;
                }
            }
            f
        };
        Self {
            f_ab,
            g_ab,
            f_aa: symmetric(a, n),
            g_bb: symmetric(b, m),
        }
    }
}

fn average(into: &mut [f64], new: &[f64]) {
    for (a, b) in into.iter_mut().zip(new) {
        *a = 0.5 * (*a + b);
    }
}

/// [`sinkhorn_divergence`]'s value computed entirely on the host in f64, for reporting (not
/// differentiable): `a` `[N·d]` and `b` `[M·d]` row-major, the result in the units of the cost
/// `½|x − y|²`.
///
/// # Errors
/// [`PointSetError::Invalid`] for empty sets, lengths that are not multiples of `d`, non-finite
/// coordinates or an `ε` that is not positive and finite.
pub fn sinkhorn_divergence_host(
    a: &[f32],
    b: &[f32],
    d: usize,
    options: &SinkhornOptions,
) -> Result<f64> {
    let invalid = |reason: String| {
        Err(PointSetError::Invalid {
            what: "sinkhorn divergence",
            reason,
        })
    };
    if d == 0
        || a.is_empty()
        || b.is_empty()
        || !a.len().is_multiple_of(d)
        || !b.len().is_multiple_of(d)
    {
        return invalid(format!(
            "need non-empty sets of {d}-dimensional points, got {} and {} values",
            a.len(),
            b.len()
        ));
    }
    if let Some(bad) = a.iter().chain(b).position(|x| !x.is_finite()) {
        return invalid(format!("coordinate {bad} of the two sets is not finite"));
    }
    if !(options.epsilon.is_finite() && options.epsilon > 0.0) {
        return invalid(format!(
            "epsilon must be positive and finite, got {}",
            options.epsilon
        ));
    }
    Ok(host_sinkhorn_divergence(a, b, d, options))
}

/// The Sinkhorn divergence computed entirely on the host (for reporting), from host data
/// `[N·d]`, `[M·d]`.
pub(super) fn host_sinkhorn_divergence(
    a: &[f32],
    b: &[f32],
    d: usize,
    options: &SinkhornOptions,
) -> f64 {
    let p = HostSinkhorn::new(a, b, d, options);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let ot_ab = mean(&p.f_ab) + mean(&p.g_ab);
    let ot_aa = 2.0 * mean(&p.f_aa);
    let ot_bb = 2.0 * mean(&p.g_bb);
    ot_ab - 0.5 * (ot_aa + ot_bb)
}
