//! Losses between a simulated particle set and a target: the thesis' L2 loss (particle `i`
//! against target point `i`), and two permutation-invariant losses the thesis proposes as the
//! remedy for its stalled optimisations (section 4.3, chapter 6): the debiased Sinkhorn
//! divergence between the point sets and an L2 loss on the liquid's density on the grid and
//! on coarser grids.
//!
//! Every loss is built from tensor operations and returns a one-element tensor `[1]`, so it is
//! differentiable on the autodiff backends. Point sets are `[N, d]` in domain units.

use phi_core::Tensor;
use phi_core::backend::{Backend, ReduceOp};
use phi_core::fields::LatticeKernels;
use phi_core::fields::{Domain, PointCloud, Transfer, particles_to_centered};

use crate::error::{FlipError, Result};

/// Which loss compares the simulated particles with the target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Loss {
    /// `½ Σᵢ |xᵢ − tᵢ|²`: particle `i` against target point `i` (Φ_Flow's `l2_loss`, the
    /// thesis). Needs as many target points as particles.
    L2,
    /// The debiased Sinkhorn divergence ([`sinkhorn_divergence`]) with entropic blur
    /// `epsilon` (domain units², the scale below which the loss stops resolving structure),
    /// scaled by the number of particles so that its gradient has the size of the L2 loss'.
    Sinkhorn {
        /// Entropic regularisation `ε` of the cost `½|x − y|²`.
        epsilon: f32,
    },
    /// The squared difference of the densities on the grid and on `levels − 1` coarsenings of
    /// it, normalised by the target's mean density ([`density_loss`]).
    Density {
        /// Grids compared: the domain's, then each coarser by 2 per axis (at least 1; fewer
        /// when the resolution cannot be halved).
        levels: usize,
    },
}

impl Loss {
    /// The loss of `positions` `[N, d]` against `target` `[M, d]` on `domain`.
    ///
    /// # Errors
    /// [`FlipError::InvalidParameter`] (name `target`) for empty sets, a dimension mismatch, or
    /// (L2) different counts.
    pub fn evaluate<B: LatticeKernels>(
        &self,
        positions: &Tensor<B>,
        target: &Tensor<B>,
        domain: &Domain,
    ) -> Result<Tensor<B>> {
        match *self {
            Loss::L2 => l2_loss(positions, target),
            Loss::Sinkhorn { epsilon } => {
                let n = positions.shape()[0] as f32;
                Ok(sinkhorn_divergence(positions, target, &SinkhornOptions::new(epsilon))? * n)
            }
            Loss::Density { levels } => density_loss(positions, target, domain, levels),
        }
    }

    /// The name used in configuration files (`"l2"`, `"sinkhorn"`, `"density"`).
    pub fn name(&self) -> &'static str {
        match self {
            Loss::L2 => "l2",
            Loss::Sinkhorn { .. } => "sinkhorn",
            Loss::Density { .. } => "density",
        }
    }
}

fn invalid(reason: String) -> FlipError {
    FlipError::InvalidParameter {
        name: "target",
        reason,
    }
}

/// Checks that `a` and `b` are non-empty `[·, d]` point sets of the same `d`; returns `(N, M, d)`.
fn check_point_sets<B: Backend>(
    what: &str,
    a: &Tensor<B>,
    b: &Tensor<B>,
) -> Result<(usize, usize, usize)> {
    let (sa, sb) = (a.shape(), b.shape());
    if sa.len() != 2 || sb.len() != 2 {
        return Err(invalid(format!(
            "{what}: point sets are [N, d] tensors, got shapes {sa:?} and {sb:?}"
        )));
    }
    if sa[1] != sb[1] {
        return Err(invalid(format!(
            "{what}: the particles are {}-dimensional but the target points are {}-dimensional",
            sa[1], sb[1]
        )));
    }
    if sa[0] == 0 || sb[0] == 0 {
        return Err(invalid(format!(
            "{what}: empty point set ({} particles, {} target points)",
            sa[0], sb[0]
        )));
    }
    Ok((sa[0], sb[0], sa[1]))
}

/// `½ Σᵢ |xᵢ − tᵢ|²` over particles `i` (Φ_Flow's `l2_loss`, as in the thesis: with learning
/// rate 1, a gradient step moves a particle by its whole residual when the map is the identity).
///
/// # Errors
/// [`FlipError::InvalidParameter`] for empty sets, different dimensions or counts.
pub fn l2_loss<B: Backend>(positions: &Tensor<B>, target: &Tensor<B>) -> Result<Tensor<B>> {
    let (n, m, _) = check_point_sets("l2 loss", positions, target)?;
    if n != m {
        return Err(invalid(format!(
            "l2 loss: compares particle i with target point i, but there are {n} particles and \
             {m} target points (use loss = \"sinkhorn\" or \"density\" for sets of different size)"
        )));
    }
    Ok((positions - target).square().sum() * 0.5)
}

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
/// [`FlipError::InvalidParameter`] for empty sets, different dimensions or a `ε ≤ 0`.
pub fn sinkhorn_divergence<B: Backend>(
    a: &Tensor<B>,
    b: &Tensor<B>,
    options: &SinkhornOptions,
) -> Result<Tensor<B>> {
    check_point_sets("sinkhorn divergence", a, b)?;
    if !(options.epsilon.is_finite() && options.epsilon > 0.0) {
        return Err(invalid(format!(
            "sinkhorn divergence: epsilon must be positive and finite, got {}",
            options.epsilon
        )));
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

/// A multi-scale density loss:
///
/// `L = 1/(K ρ̄) Σ_{k<K} ½ Σ_cells (ρₖ(x) − ρₖ(t))²`,
///
/// where `ρₖ` is the particle count per cell, spread with tent weights (particle → centred grid,
/// unit mass), on the domain's grid coarsened `2ᵏ` times per axis (`k = 0` is the domain's own
/// grid), and `ρ̄ = Σ ρ₀(t)² / Σ ρ₀(t)` is the target's mean density per cell (density-weighted,
/// so empty cells do not count). `K = levels`, lowered to the number of grids the resolution
/// allows (halving stops at an odd count or below 2 cells on an axis).
///
/// Why the coarse grids: on the finest grid a particle only sees the target within one cell,
/// so a liquid that does not overlap its target gets no pull towards it (the gradient of a
/// translation is exactly zero); a grid of cell size `s` cells reaches `s` cells far. Why
/// `1/ρ̄`: the counts grow with the particles per cell, so the gradient per particle would too;
/// divided by `ρ̄` it does not depend on them (the loss grows with `N`, like the L2 loss). For
/// a liquid shifted by a small `δ` against its target the level of cell size `s` adds
/// `≈ ½ ρ̄² P s δ²` (`P` the length of the liquid's outline, in cells), so the coarse grids
/// dominate the curvature: with 5 grids (mean cell size 6.2) a step of learning rate `η`
/// moves each particle of a shifted liquid by `≈ 6.2 η (P / A) δ` (`A` its area in cells), the
/// full (Gauss–Newton) step at `η ≈ A / (6.2 P)`, 0.4 for a 10×10-cell liquid. Through a
/// chaotic simulation smaller steps are needed (0.05 on `scenes/optimize/far_sphere_density.toml`).
///
/// The gradient reaches the positions through the tent weights; which cells a particle touches
/// is held constant, so each level is piecewise quadratic with kinks where particles cross cell
/// centres.
///
/// # Errors
/// [`FlipError::InvalidParameter`] for empty sets, a dimension mismatch with the domain or
/// `levels = 0`.
pub fn density_loss<B: LatticeKernels>(
    positions: &Tensor<B>,
    target: &Tensor<B>,
    domain: &Domain,
    levels: usize,
) -> Result<Tensor<B>> {
    let (_, _, d) = check_point_sets("density loss", positions, target)?;
    if d != domain.dim() {
        return Err(invalid(format!(
            "density loss: {d}-dimensional points in a {}-dimensional domain",
            domain.dim()
        )));
    }
    if levels == 0 {
        return Err(invalid("density loss: levels must be at least 1".into()));
    }
    let target = target.detach();
    let grids = density_grids(domain, levels)?;
    let targets = grids
        .iter()
        .map(|grid| density(&target, grid))
        .collect::<Result<Vec<_>>>()?;
    let fine = targets[0].to_vec();
    let mass: f64 = fine.iter().map(|&r| f64::from(r)).sum();
    let squares: f64 = fine.iter().map(|&r| f64::from(r).powi(2)).sum();
    let mean_density = if mass > 0.0 { squares / mass } else { 1.0 };
    let weight = (0.5 / (grids.len() as f64 * mean_density)) as f32;
    let mut total: Option<Tensor<B>> = None;
    for (grid, target_density) in grids.iter().zip(&targets) {
        let difference = density(positions, grid)? - target_density;
        let term = difference.square().sum() * weight;
        total = Some(match total {
            Some(t) => t + term,
            None => term,
        });
    }
    Ok(total.expect("at least one level"))
}

/// The domain's grid and up to `levels − 1` coarsenings by 2 per axis, as domains over the same
/// box; halving stops at an odd count or below 2 cells on an axis.
///
/// # Errors
/// Domain construction errors only (none for a valid `domain`).
pub fn density_grids(domain: &Domain, levels: usize) -> Result<Vec<Domain>> {
    let mut grids = vec![domain.clone()];
    let mut resolution = domain.resolution().to_vec();
    while grids.len() < levels && resolution.iter().all(|&n| n % 2 == 0 && n >= 4) {
        resolution.iter_mut().for_each(|n| *n /= 2);
        grids.push(Domain::new(
            &resolution,
            domain.lower(),
            domain.upper(),
            domain.boundaries(),
        )?);
    }
    Ok(grids)
}

/// Tent-weighted particle count per cell, `[res..., 1]`.
///
/// # Errors
/// Tensor errors only.
pub fn density<B: LatticeKernels>(positions: &Tensor<B>, domain: &Domain) -> Result<Tensor<B>> {
    let n = positions.shape()[0];
    let ones = Tensor::ones(&[n, 1], &positions.device());
    let cloud = PointCloud::new(positions.clone(), ones)?;
    let (_, weights) = particles_to_centered(&cloud, domain, Transfer::Linear)?;
    Ok(weights.values().clone())
}

/// Distances between point sets on the host, for reporting (not differentiable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetDistances {
    /// Symmetric Chamfer distance: the mean over both sets of the distance to the nearest point
    /// of the other set (domain units).
    pub chamfer: f32,
    /// An earth mover's estimate: `√(2 S_ε)` with a small `ε` (`0.01` domain units²), close to
    /// the 2-Wasserstein distance between the uniform measures (domain units).
    pub wasserstein: f32,
}

/// [`SetDistances`] between `a` and `b` (host data `[N·d]`, `[M·d]`).
///
/// # Errors
/// [`FlipError::InvalidParameter`] for empty sets or lengths that are not multiples of `d`.
pub fn set_distances(a: &[f32], b: &[f32], d: usize) -> Result<SetDistances> {
    if d == 0
        || a.is_empty()
        || b.is_empty()
        || !a.len().is_multiple_of(d)
        || !b.len().is_multiple_of(d)
    {
        return Err(invalid(format!(
            "set distances: need non-empty sets of {d}-dimensional points, got {} and {} values",
            a.len(),
            b.len()
        )));
    }
    let chamfer = chamfer_distance(a, b, d);
    let options = SinkhornOptions {
        max_iterations: 300,
        ..SinkhornOptions::new(0.01)
    };
    let s = host_sinkhorn_divergence(a, b, d, &options);
    Ok(SetDistances {
        chamfer,
        wasserstein: (2.0 * s.max(0.0)).sqrt() as f32,
    })
}

/// Symmetric Chamfer distance between host point sets `[N·d]`, `[M·d]`: the mean over both sets
/// of the distance to the nearest point of the other (domain units); `NaN` for an empty set.
pub fn chamfer_distance(a: &[f32], b: &[f32], d: usize) -> f32 {
    if d == 0 || a.is_empty() || b.is_empty() {
        return f32::NAN;
    }
    let nearest = |from: &[f32], to: &[f32]| -> f64 {
        let count = from.len() / d;
        from.chunks(d)
            .map(|x| {
                to.chunks(d)
                    .map(|y| {
                        x.iter()
                            .zip(y)
                            .map(|(p, q)| f64::from(p - q).powi(2))
                            .sum::<f64>()
                    })
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
            })
            .sum::<f64>()
            / count as f64
    };
    (0.5 * (nearest(a, b) + nearest(b, a))) as f32
}

/// The Sinkhorn divergence computed entirely on the host (for reporting).
fn host_sinkhorn_divergence(a: &[f32], b: &[f32], d: usize, options: &SinkhornOptions) -> f64 {
    let p = HostSinkhorn::new(a, b, d, options);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let ot_ab = mean(&p.f_ab) + mean(&p.g_ab);
    let ot_aa = 2.0 * mean(&p.f_aa);
    let ot_bb = 2.0 * mean(&p.g_bb);
    ot_ab - 0.5 * (ot_aa + ot_bb)
}
