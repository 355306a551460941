//! [`CenteredGrid`] and [`StaggeredGrid`]: immutable sampled fields on a [`Domain`], like
//! Φ_Flow's `CenteredGrid` and `StaggeredGrid`, plus the coordinates of their sample points.
//!
//! Layouts (see [`Domain`]): a centred grid of resolution `[nx, ny]` with `c` channels is a tensor
//! `[nx, ny, c]`; staggered component `i` is a tensor of shape [`Domain::staggered_shape`]`(i)`
//! (no channel axis).

use crate::backend::Backend;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

use super::domain::Domain;

/// A field sampled at the cell centres of a [`Domain`]: `values` has shape `[res..., channels]`.
#[derive(Debug, Clone)]
pub struct CenteredGrid<B: Backend> {
    values: Tensor<B>,
    domain: Domain,
}

impl<B: Backend> CenteredGrid<B> {
    /// A grid holding `values [res..., channels]` on `domain`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] naming the expected and the actual shape when `values` is
    /// not `[res..., c]` for the domain's resolution and some `c ≥ 1`.
    pub fn new(values: Tensor<B>, domain: Domain) -> Result<Self> {
        let shape = values.shape();
        let res = domain.resolution();
        let fits =
            shape.len() == res.len() + 1 && shape[..res.len()] == *res && shape[res.len()] > 0;
        if !fits {
            return Err(TensorError::InvalidArgument {
                op: "CenteredGrid::new",
                shape,
                reason: format!(
                    "a centred grid on resolution {res:?} needs values of shape {res:?} + [channels]"
                ),
            });
        }
        Ok(Self { values, domain })
    }

    /// A grid of zeros with `channels` channels.
    pub fn zeros(domain: &Domain, channels: usize, device: &B::Device) -> Self {
        let mut shape = domain.resolution().to_vec();
        shape.push(channels.max(1));
        Self {
            values: Tensor::zeros(&shape, device),
            domain: domain.clone(),
        }
    }

    /// A grid with the value `f(cell centre)` (a vector of `channels` values) in each cell,
    /// evaluated on the host.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when `f` returns another number of values than
    /// `channels`, or `channels` is zero.
    pub fn from_fn(
        domain: &Domain,
        channels: usize,
        device: &B::Device,
        f: impl Fn(&[f32]) -> Vec<f32>,
    ) -> Result<Self> {
        let d = domain.dim();
        let centres = host_sample_points(domain, None);
        let mut data = Vec::with_capacity(domain.cell_count() * channels);
        for point in centres.chunks(d) {
            let value = f(point);
            if value.len() != channels || channels == 0 {
                return Err(TensorError::InvalidArgument {
                    op: "CenteredGrid::from_fn",
                    shape: domain.resolution().to_vec(),
                    reason: format!(
                        "the function returned {} values for {channels} channels",
                        value.len()
                    ),
                });
            }
            data.extend(value);
        }
        let mut shape = domain.resolution().to_vec();
        shape.push(channels);
        Self::new(Tensor::from_vec(data, &shape, device)?, domain.clone())
    }

    /// The values, `[res..., channels]`.
    pub fn values(&self) -> &Tensor<B> {
        &self.values
    }

    /// The domain.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// Number of channels (1 for a scalar field, `d` for a vector field).
    pub fn channels(&self) -> usize {
        *self.values.shape().last().expect("a grid has axes")
    }

    /// The same grid with other values.
    ///
    /// # Errors
    /// As [`CenteredGrid::new`].
    pub fn with_values(&self, values: Tensor<B>) -> Result<Self> {
        Self::new(values, self.domain.clone())
    }

    /// The values without the channel axis, `[res...]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] when the grid has more than one channel.
    pub(crate) fn scalar_values(&self, op: &'static str) -> Result<Tensor<B>> {
        if self.channels() != 1 {
            return Err(TensorError::InvalidArgument {
                op,
                shape: self.values.shape(),
                reason: format!(
                    "needs a scalar grid (1 channel), got {} channels",
                    self.channels()
                ),
            });
        }
        self.values.reshape(self.domain.resolution())
    }

    /// `self + other` (same domain; channel counts broadcast).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains, [`TensorError::ShapeMismatch`] for
    /// channel counts that do not broadcast.
    pub fn add(&self, other: &Self) -> Result<Self> {
        self.zip(other, "CenteredGrid::add", |a, b| {
            a.binary(crate::backend::BinaryOp::Add, b)
        })
    }

    /// `self - other` (same domain; channel counts broadcast).
    ///
    /// # Errors
    /// As [`CenteredGrid::add`].
    pub fn sub(&self, other: &Self) -> Result<Self> {
        self.zip(other, "CenteredGrid::sub", |a, b| {
            a.binary(crate::backend::BinaryOp::Sub, b)
        })
    }

    /// `self · other` element by element (same domain; e.g. a vector field times a 1-channel mask).
    ///
    /// # Errors
    /// As [`CenteredGrid::add`].
    pub fn mul(&self, other: &Self) -> Result<Self> {
        self.zip(other, "CenteredGrid::mul", |a, b| {
            a.binary(crate::backend::BinaryOp::Mul, b)
        })
    }

    /// `factor · self`.
    pub fn scale(&self, factor: f32) -> Self {
        Self {
            values: &self.values * factor,
            domain: self.domain.clone(),
        }
    }

    fn zip(
        &self,
        other: &Self,
        op: &'static str,
        f: impl Fn(&Tensor<B>, &Tensor<B>) -> Result<Tensor<B>>,
    ) -> Result<Self> {
        self.domain.check_same(&other.domain, op)?;
        Self::new(f(&self.values, &other.values)?, self.domain.clone())
    }
}

/// A vector field on the faces of a [`Domain`] (a MAC grid): component `i` is a tensor of shape
/// [`Domain::staggered_shape`]`(i)`, face `k` along axis `i` at `lower_i + k dx_i`, centred on the
/// other axes.
#[derive(Debug, Clone)]
pub struct StaggeredGrid<B: Backend> {
    components: Vec<Tensor<B>>,
    domain: Domain,
}

impl<B: Backend> StaggeredGrid<B> {
    /// A grid holding one tensor per axis.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] naming the expected and the actual shape when there is
    /// not one component per axis or component `i` is not of shape `domain.staggered_shape(i)`.
    pub fn new(components: Vec<Tensor<B>>, domain: Domain) -> Result<Self> {
        if components.len() != domain.dim() {
            return Err(TensorError::InvalidArgument {
                op: "StaggeredGrid::new",
                shape: domain.resolution().to_vec(),
                reason: format!(
                    "a staggered grid in {} dimensions needs {} components, got {}",
                    domain.dim(),
                    domain.dim(),
                    components.len()
                ),
            });
        }
        for (axis, component) in components.iter().enumerate() {
            let expected = domain.staggered_shape(axis);
            let shape = component.shape();
            if shape != expected {
                return Err(TensorError::InvalidArgument {
                    op: "StaggeredGrid::new",
                    shape,
                    reason: format!(
                        "component {axis} on resolution {:?} must have shape {expected:?}",
                        domain.resolution()
                    ),
                });
            }
        }
        Ok(Self { components, domain })
    }

    /// A grid of zeros.
    pub fn zeros(domain: &Domain, device: &B::Device) -> Self {
        Self {
            components: (0..domain.dim())
                .map(|axis| Tensor::zeros(&domain.staggered_shape(axis), device))
                .collect(),
            domain: domain.clone(),
        }
    }

    /// A grid whose component `i` at each face is `f(i, face centre)`, evaluated on the host.
    ///
    /// # Errors
    /// Only as [`StaggeredGrid::new`], which cannot fail here.
    pub fn from_fn(
        domain: &Domain,
        device: &B::Device,
        f: impl Fn(usize, &[f32]) -> f32,
    ) -> Result<Self> {
        let d = domain.dim();
        let components = (0..d)
            .map(|axis| {
                let points = host_sample_points(domain, Some(axis));
                let data: Vec<f32> = points.chunks(d).map(|p| f(axis, p)).collect();
                Tensor::from_vec(data, &domain.staggered_shape(axis), device)
            })
            .collect::<Result<Vec<_>>>()?;
        Self::new(components, domain.clone())
    }

    /// The components, one per axis.
    pub fn components(&self) -> &[Tensor<B>] {
        &self.components
    }

    /// Component `axis`.
    pub fn component(&self, axis: usize) -> &Tensor<B> {
        &self.components[axis]
    }

    /// The domain.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// The same domain with other components.
    ///
    /// # Errors
    /// As [`StaggeredGrid::new`].
    pub(crate) fn with_components(&self, components: Vec<Tensor<B>>) -> Result<Self> {
        Self::new(components, self.domain.clone())
    }

    /// `f(axis, component)` applied to each component.
    ///
    /// # Errors
    /// Whatever `f` returns, or [`TensorError::InvalidArgument`] when it changes a shape.
    pub fn map(&self, f: impl Fn(usize, &Tensor<B>) -> Result<Tensor<B>>) -> Result<Self> {
        let components = self
            .components
            .iter()
            .enumerate()
            .map(|(axis, c)| f(axis, c))
            .collect::<Result<Vec<_>>>()?;
        self.with_components(components)
    }

    /// `f(axis, a_i, b_i)` applied to the components of two grids on the same domain.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains; whatever `f` returns.
    pub fn zip(
        &self,
        other: &Self,
        op: &'static str,
        f: impl Fn(usize, &Tensor<B>, &Tensor<B>) -> Result<Tensor<B>>,
    ) -> Result<Self> {
        self.domain.check_same(&other.domain, op)?;
        let components = self
            .components
            .iter()
            .zip(&other.components)
            .enumerate()
            .map(|(axis, (a, b))| f(axis, a, b))
            .collect::<Result<Vec<_>>>()?;
        self.with_components(components)
    }

    /// `self + other`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains.
    pub fn add(&self, other: &Self) -> Result<Self> {
        self.zip(other, "StaggeredGrid::add", |_, a, b| {
            a.binary(crate::backend::BinaryOp::Add, b)
        })
    }

    /// `self - other`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains.
    pub fn sub(&self, other: &Self) -> Result<Self> {
        self.zip(other, "StaggeredGrid::sub", |_, a, b| {
            a.binary(crate::backend::BinaryOp::Sub, b)
        })
    }

    /// `self · other` component by component (e.g. velocities times face masks).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains.
    pub fn mul(&self, other: &Self) -> Result<Self> {
        self.zip(other, "StaggeredGrid::mul", |_, a, b| {
            a.binary(crate::backend::BinaryOp::Mul, b)
        })
    }

    /// `factor · self`.
    pub fn scale(&self, factor: f32) -> Self {
        Self {
            components: self.components.iter().map(|c| c * factor).collect(),
            domain: self.domain.clone(),
        }
    }

    /// `v + factor · g` per component, a common update (`v - dt ∇p`, `v + dt g`).
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for different domains.
    pub fn add_scaled(&self, other: &Self, factor: f32) -> Result<Self> {
        self.zip(other, "StaggeredGrid::add_scaled", |_, a, b| {
            a.binary(crate::backend::BinaryOp::Add, &(b * factor))
        })
    }
}

/// Physical coordinates of the sample points of a grid on `domain`, row-major, `d` values per
/// point: the cell centres for `face_axis = None`, the faces of staggered component `axis` for
/// `Some(axis)`.
pub(crate) fn host_sample_points(domain: &Domain, face_axis: Option<usize>) -> Vec<f32> {
    let d = domain.dim();
    let shape = match face_axis {
        None => domain.resolution().to_vec(),
        Some(axis) => domain.staggered_shape(axis),
    };
    let dx = domain.cell_size();
    let lower = domain.lower();
    let count: usize = shape.iter().product();
    let mut out = Vec::with_capacity(count * d);
    let mut index = vec![0usize; d];
    for _ in 0..count {
        for axis in 0..d {
            let offset = if face_axis == Some(axis) { 0.0 } else { 0.5 };
            out.push(lower[axis] + (index[axis] as f32 + offset) * dx[axis]);
        }
        for axis in (0..d).rev() {
            index[axis] += 1;
            if index[axis] < shape[axis] {
                break;
            }
            index[axis] = 0;
        }
    }
    out
}

/// The cell centres of `domain` as a tensor `[res..., d]`: entry `(i, j, :)` is
/// `lower + ((i + ½) dx, (j + ½) dy)`.
pub fn cell_centers<B: Backend>(domain: &Domain, device: &B::Device) -> Tensor<B> {
    let mut shape = domain.resolution().to_vec();
    shape.push(domain.dim());
    Tensor::from_vec(host_sample_points(domain, None), &shape, device).expect("one point per cell")
}

/// The face centres of staggered component `axis` as a tensor `[staggered_shape(axis)..., d]`:
/// face `k` along `axis` at `lower_axis + k dx_axis`, centred on the other axes.
///
/// # Panics
/// When `axis ≥ domain.dim()`.
pub fn face_centers<B: Backend>(domain: &Domain, axis: usize, device: &B::Device) -> Tensor<B> {
    assert!(
        axis < domain.dim(),
        "face_centers: axis {axis} of a {}-d domain",
        domain.dim()
    );
    let mut shape = domain.staggered_shape(axis);
    shape.push(domain.dim());
    Tensor::from_vec(host_sample_points(domain, Some(axis)), &shape, device)
        .expect("one point per face")
}
