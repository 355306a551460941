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
mod extrapolate;
mod grid;
mod grid_field;
pub mod kernels;
mod lattice;
pub mod ops;
mod point_cloud;
mod poisson;
mod projection;
mod sample;

pub use advect::advect_points;
pub use domain::{Boundary, Domain};
pub use extrapolate::extrapolate_valid_tensor;
pub use grid::{CenteredGrid, StaggeredGrid, cell_centers, face_centers};
pub use grid_field::{GridField, advect_semi_lagrangian, extrapolate_valid};
pub use kernels::{Integrator, LatticeKernels};
pub use lattice::{SampleLattice, Transfer};
pub use ops::{
    apply_wall_boundaries, centered_to_staggered, curl, divergence, gradient, laplace,
    staggered_to_centered,
};
pub use point_cloud::PointCloud;
pub use poisson::{all_faces_open, poisson_matrix};
pub use projection::{Projection, ProjectionMasks, pressure_projection};
pub use sample::{
    count_particles, occupied_cells, occupied_cells_from_host, particles_to_centered,
    particles_to_staggered, particles_to_staggered_affine, sample_centered, sample_face_component,
    sample_face_component_gradient, sample_staggered, sample_staggered_gradient, valid_faces,
};

#[cfg(all(test, feature = "ndarray"))]
mod tests;
