//! Losses between a simulated particle set and a target, as the optimisation through FLIP
//! chooses them ([`Loss`]): the thesis' L2 loss and the Sinkhorn divergence (both from
//! [`phi_core::point_sets`]), and the loss that needs the simulation's grid, an L2 loss on the
//! liquid's density on the grid and on coarser grids, which the thesis proposes with the
//! Sinkhorn divergence as the remedy for its stalled optimisations (section 4.3, chapter 6).
//!
//! Every loss is built from tensor operations and returns a one-element tensor `[1]`, so it is
//! differentiable on the autodiff backends. Point sets are `[N, d]` in domain units.

use phi_core::Tensor;
use phi_core::fields::LatticeKernels;
use phi_core::fields::{Domain, PointCloud, Transfer, particles_to_centered};
use phi_core::point_sets::{SinkhornOptions, check_point_sets, l2_loss, sinkhorn_divergence};

use crate::error::{FlipError, Result};

/// Which loss compares the simulated particles with the target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Loss {
    /// `½ Σᵢ |xᵢ − tᵢ|²`: particle `i` against target point `i` ([`l2_loss`], Φ_Flow's, the
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
            Loss::L2 => Ok(l2_loss(positions, target)?),
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
pub(crate) fn density_grids(domain: &Domain, levels: usize) -> Result<Vec<Domain>> {
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
