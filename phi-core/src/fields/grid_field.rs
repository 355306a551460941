//! [`GridField`]: what centred and staggered grids share, growing a valid region and
//! semi-Lagrangian advection, with the generic free functions over it.

use super::kernels::LatticeKernels;
use crate::error::Result;

use super::advect::{advect_centered, advect_staggered};
use super::extrapolate::extrapolate_valid_tensor;
use super::grid::{CenteredGrid, StaggeredGrid};

/// A grid whose valid region can be grown ([`extrapolate_valid`]) and that can be advected
/// ([`advect_semi_lagrangian`]).
pub trait GridField<B: LatticeKernels>: Sized {
    /// See [`extrapolate_valid`].
    ///
    /// # Errors
    /// See [`extrapolate_valid`].
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)>;

    /// See [`advect_semi_lagrangian`].
    ///
    /// # Errors
    /// See [`advect_semi_lagrangian`].
    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self>;
}

impl<B: LatticeKernels> GridField<B> for CenteredGrid<B> {
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)> {
        self.domain()
            .check_same(valid.domain(), "extrapolate_valid")?;
        let d = self.domain().dim();
        let (values, mask) = extrapolate_valid_tensor(self.values(), valid.values(), d, cells)?;
        Ok((self.with_values(values)?, valid.with_values(mask)?))
    }

    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self> {
        advect_centered(self, velocity, dt)
    }
}

impl<B: LatticeKernels> GridField<B> for StaggeredGrid<B> {
    fn extrapolate_valid(&self, valid: &Self, cells: usize) -> Result<(Self, Self)> {
        self.domain()
            .check_same(valid.domain(), "extrapolate_valid")?;
        let d = self.domain().dim();
        let mut values = Vec::with_capacity(d);
        let mut masks = Vec::with_capacity(d);
        for (component, mask) in self.components().iter().zip(valid.components()) {
            let (v, m) = extrapolate_valid_tensor(component, mask, d, cells)?;
            values.push(v);
            masks.push(m);
        }
        Ok((self.with_components(values)?, valid.with_components(masks)?))
    }

    fn advect_semi_lagrangian(&self, velocity: &StaggeredGrid<B>, dt: f32) -> Result<Self> {
        advect_staggered(self, velocity, dt)
    }
}

/// Grows the valid region of a grid by `cells` layers, each newly valid sample taking the mean
/// of its valid neighbours (`3^d` box, diagonals included), like Φ_Flow's
/// `extrapolate_valid_values`. For a [`StaggeredGrid`] each component is extrapolated on its own
/// faces with its own mask (thesis fig. 4.1); for a [`CenteredGrid`] the mask is `[res..., 1]`
/// (all channels) or `[res..., c]`. Returns `(values, valid)`; valid samples are untouched.
///
/// # Errors
/// [`TensorError::InvalidArgument`] for grids on different domains,
/// [`TensorError::ShapeMismatch`] for a mask with other channels.
pub fn extrapolate_valid<B: LatticeKernels, G: GridField<B>>(
    field: &G,
    valid: &G,
    cells: usize,
) -> Result<(G, G)> {
    field.extrapolate_valid(valid, cells)
}

/// Semi-Lagrangian advection of a grid through `velocity` over `dt`:
/// `f_new(x) = f(x − Δt · u(x))`, each sample traced back from its own position (cell centres,
/// or the faces of each staggered component) with the velocity interpolated there
/// ([`sample_staggered`]), and the old field interpolated multilinearly at the traced-back point
/// ([`sample_centered`] / [`sample_face_component`]; points leaving the grid are clamped to its
/// outermost samples). Exact for fields linear in space moved by a constant velocity, as long as
/// the traced-back points stay inside the sampled region. Differentiable in the field and the
/// velocity.
///
/// # Errors
/// [`TensorError::InvalidArgument`] when the field and the velocity live on different grids.
pub fn advect_semi_lagrangian<B: LatticeKernels, G: GridField<B>>(
    field: &G,
    velocity: &StaggeredGrid<B>,
    dt: f32,
) -> Result<G> {
    field.advect_semi_lagrangian(velocity, dt)
}
