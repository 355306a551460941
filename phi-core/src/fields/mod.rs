//! Fields on a [`Domain`]: the Φ_Flow layer that physics is written in.
//!
//! - Values: [`CenteredGrid`] (`[res..., c]` at the cell centres), [`StaggeredGrid`] (one tensor
//!   per axis on the faces, a MAC grid) and [`PointCloud`] (`positions [N, d]`, `values [N, c]`).
//!   All are immutable; operations return new values.
//! - Differential operators ([`divergence`], [`gradient`], [`laplace`], [`curl`]) and conversions
//!   ([`staggered_to_centered`], [`centered_to_staggered`]), boundary conditions from the
//!   [`Domain`] (see [`ops`]).
//! - Sampling and particle ↔ grid transfer ([`sample_staggered`], [`sample_centered`],
//!   [`particles_to_staggered`], [`particles_to_centered`]; APIC's affine transfer
//!   [`particles_to_staggered_affine`] and [`sample_staggered_gradient`]), masks ([`occupied_cells`],
//!   [`valid_faces`]), [`extrapolate_valid`] and advection ([`advect_semi_lagrangian`],
//!   [`advect_points`]).
//! - The pressure projection ([`pressure_projection`]) and the Poisson system it solves on a
//!   domain ([`poisson_matrix`]).
//!
//! Everything is written once over `B: Backend` and works in 2D and 3D (most also in 1D). What
//! samples, splats, advects points or extrapolates needs `B: LatticeKernels` (the fused kernels of
//! this layer, an extension of `Backend`: see [`kernels`]).

mod advect;
mod domain;
pub(crate) mod extrapolate;
mod grid;
pub mod kernels;
pub mod ops;
mod point_cloud;
mod poisson;
mod projection;
pub(crate) mod sample;

pub use advect::{Integrator, advect_points, advect_semi_lagrangian};
pub use domain::{Boundary, Domain};
pub use extrapolate::{GridField, extrapolate_valid, extrapolate_valid_tensor};
pub use grid::{CenteredGrid, StaggeredGrid, cell_centers, face_centers};
pub use kernels::LatticeKernels;
pub use ops::{
    apply_wall_boundaries, centered_to_staggered, curl, divergence, gradient, laplace,
    staggered_to_centered,
};
pub use point_cloud::PointCloud;
pub use poisson::{all_faces_open, poisson_matrix};
pub use projection::{Projection, ProjectionMasks, pressure_projection};
pub use sample::{
    SampleLattice, Transfer, count_particles, occupied_cells, occupied_cells_from_host,
    particles_to_centered, particles_to_staggered, particles_to_staggered_affine, sample_centered,
    sample_face_component, sample_face_component_gradient, sample_staggered,
    sample_staggered_gradient, valid_faces,
};

#[cfg(all(test, feature = "ndarray"))]
mod tests;
