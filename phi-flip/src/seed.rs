//! Seeding particles in the cells of a geometry.

use phi_core::backend::Host;
use phi_core::fields::Domain;
use phi_geom::Geometry;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::Result;

/// Where in its cell a seeded particle goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Placement {
    /// Uniformly at random inside the cell (the default; thesis and Φ_Flow).
    #[default]
    Jittered,
    /// At the cell centre, every particle of the cell (Φ_Flow's `center=True`, used for the
    /// symmetry test of thesis fig. 4.4: a mirror-symmetric seeding).
    Centered,
}

/// `particles_per_cell` particles in every cell of `domain` whose centre lies inside `geometry`
/// and outside `excluded` (the obstacles), as host positions `[N * d]` (row-major `[N, d]`).
/// Cells are visited in row-major order; jitter comes from `seed`, so the same arguments give the
/// same particles.
///
/// # Errors
/// A dimension mismatch between the geometries and the domain.
pub fn seed_particles(
    geometry: &Geometry,
    excluded: Option<&Geometry>,
    domain: &Domain,
    particles_per_cell: usize,
    placement: Placement,
    seed: u64,
) -> Result<Vec<f32>> {
    let device = Default::default();
    let inside = geometry.cell_inside_mask::<Host>(domain, &device)?.to_vec();
    let blocked = match excluded {
        Some(g) => Some(g.cell_inside_mask::<Host>(domain, &device)?.to_vec()),
        None => None,
    };
    let d = domain.dim();
    let resolution = domain.resolution();
    let dx = domain.cell_size();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut positions = Vec::new();
    let mut index = vec![0usize; d];
    for cell in 0..domain.cell_count() {
        let mut rest = cell;
        for axis in (0..d).rev() {
            index[axis] = rest % resolution[axis];
            rest /= resolution[axis];
        }
        let free = blocked.as_ref().is_none_or(|b| b[cell] < 0.5);
        if inside[cell] < 0.5 || !free {
            continue;
        }
        for _ in 0..particles_per_cell {
            for axis in 0..d {
                let offset: f32 = match placement {
                    Placement::Jittered => rng.random_range(0.0..1.0),
                    Placement::Centered => 0.5,
                };
                positions.push(domain.lower()[axis] + (index[axis] as f32 + offset) * dx[axis]);
            }
        }
    }
    Ok(positions)
}
