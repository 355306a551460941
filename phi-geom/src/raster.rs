//! Rasterising a geometry onto the grid of a [`Domain`]: inside masks and volume fractions of
//! cells and of staggered faces, which become obstacle masks and face accessibility of the
//! pressure solve.
//!
//! Sample positions follow the layout of [`Domain`]: cell `(i, j)` is centred at
//! `lower + (i + ½, j + ½) dx`, face `k` of staggered component `a` at `lower_a + k dx_a` along
//! axis `a` and centred on the other axes. The *control volume* of a sample is the cell-sized
//! box centred on it (for a face: the box reaching half a cell into each of the two cells it
//! separates, as Φ_Flow's soft masks sample a staggered grid).

use phi_core::fields::Domain;
use phi_core::{Backend, Tensor};

use crate::error::{GeomError, Result};
use crate::geometry::Geometry;

impl Geometry {
    /// `1.0` for each cell whose centre lies inside (open interior), else `0.0`; shape
    /// `domain.resolution()`.
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] when the domain has another dimension.
    pub fn cell_inside_mask<B: Backend>(
        &self,
        domain: &Domain,
        device: &B::Device,
    ) -> Result<Tensor<B>> {
        self.check_domain("cell_inside_mask", domain)?;
        self.sampled_fraction(domain, None, 1, device)
    }

    /// The fraction of each cell's volume inside, estimated from `samples_per_axis^d` samples
    /// on a regular sub-grid of the cell (their centres, the midpoint rule); shape
    /// `domain.resolution()`. The error of the total volume shrinks as the sampling refines;
    /// `samples_per_axis = 1` is [`Geometry::cell_inside_mask`].
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] for a domain of another dimension,
    /// [`GeomError::InvalidArgument`] for `samples_per_axis = 0`.
    pub fn cell_volume_fraction<B: Backend>(
        &self,
        domain: &Domain,
        samples_per_axis: usize,
        device: &B::Device,
    ) -> Result<Tensor<B>> {
        self.check_domain("cell_volume_fraction", domain)?;
        self.sampled_fraction(domain, None, samples_per_axis, device)
    }

    /// `1.0` for each face of staggered component `axis` whose centre lies inside; shape
    /// `domain.staggered_shape(axis)`.
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] for a domain of another dimension,
    /// [`GeomError::InvalidArgument`] for an axis the domain does not have.
    pub fn face_inside_mask<B: Backend>(
        &self,
        domain: &Domain,
        axis: usize,
        device: &B::Device,
    ) -> Result<Tensor<B>> {
        self.check_domain("face_inside_mask", domain)?;
        check_axis("face_inside_mask", domain, axis)?;
        self.sampled_fraction(domain, Some(axis), 1, device)
    }

    /// The fraction of the control volume of each face of staggered component `axis` that lies
    /// inside, from `samples_per_axis^d` samples; shape `domain.staggered_shape(axis)`.
    ///
    /// # Errors
    /// As [`Geometry::face_inside_mask`], and [`GeomError::InvalidArgument`] for
    /// `samples_per_axis = 0`.
    pub fn face_volume_fraction<B: Backend>(
        &self,
        domain: &Domain,
        axis: usize,
        samples_per_axis: usize,
        device: &B::Device,
    ) -> Result<Tensor<B>> {
        self.check_domain("face_volume_fraction", domain)?;
        check_axis("face_volume_fraction", domain, axis)?;
        self.sampled_fraction(domain, Some(axis), samples_per_axis, device)
    }

    /// [`Geometry::face_volume_fraction`] for every axis, in axis order.
    ///
    /// # Errors
    /// As [`Geometry::face_volume_fraction`].
    pub fn face_volume_fractions<B: Backend>(
        &self,
        domain: &Domain,
        samples_per_axis: usize,
        device: &B::Device,
    ) -> Result<Vec<Tensor<B>>> {
        (0..domain.dim())
            .map(|axis| self.face_volume_fraction(domain, axis, samples_per_axis, device))
            .collect()
    }

    fn check_domain(&self, op: &'static str, domain: &Domain) -> Result<()> {
        self.validate()?;
        if domain.dim() != self.dim() {
            return Err(GeomError::dims(op, self.dim(), "the domain", domain.dim()));
        }
        Ok(())
    }

    /// The mean inside mask over `k^d` sub-samples of the control volume of every cell
    /// (`stagger = None`) or face of component `stagger`. One pass per sub-sample keeps memory at
    /// one point per sample position.
    fn sampled_fraction<B: Backend>(
        &self,
        domain: &Domain,
        stagger: Option<usize>,
        k: usize,
        device: &B::Device,
    ) -> Result<Tensor<B>> {
        if k == 0 {
            return Err(GeomError::InvalidArgument {
                op: "volume fraction",
                reason: "samples_per_axis must be at least 1".into(),
            });
        }
        let d = domain.dim();
        let shape = match stagger {
            Some(axis) => domain.staggered_shape(axis),
            None => domain.resolution().to_vec(),
        };
        let count: usize = shape.iter().product();
        let passes = k.pow(d as u32);
        let mut total: Option<Tensor<B>> = None;
        for pass in 0..passes {
            // Sub-sample offset from the sample position, in cells: the centres of a k^d grid.
            let mut digits = pass;
            let sub: Vec<f64> = (0..d)
                .map(|_| {
                    let s = digits % k;
                    digits /= k;
                    (s as f64 + 0.5) / k as f64 - 0.5
                })
                .collect();
            let points = sample_positions(domain, &shape, stagger, &sub);
            let points = Tensor::from_vec(points, &[count, d], device)?;
            let mask = self.inside_col(&points, false)?;
            total = Some(match total {
                None => mask,
                Some(t) => t + mask,
            });
        }
        let total = total.expect("at least one pass");
        let mean = if passes == 1 {
            total
        } else {
            total / passes as f32
        };
        Ok(mean.reshape(&shape)?)
    }
}

/// Row-major `[count, d]` coordinates of the samples of `shape`, each moved by `sub` cells.
fn sample_positions(
    domain: &Domain,
    shape: &[usize],
    stagger: Option<usize>,
    sub: &[f64],
) -> Vec<f32> {
    let d = shape.len();
    let lower: Vec<f64> = domain.lower().iter().map(|&v| f64::from(v)).collect();
    let dx: Vec<f64> = (0..d)
        .map(|i| (f64::from(domain.upper()[i]) - lower[i]) / domain.resolution()[i] as f64)
        .collect();
    let base: Vec<f64> = (0..d)
        .map(|i| if stagger == Some(i) { 0.0 } else { 0.5 })
        .collect();
    let count: usize = shape.iter().product();
    let mut out = Vec::with_capacity(count * d);
    let mut index = vec![0usize; d];
    for _ in 0..count {
        for i in 0..d {
            out.push((lower[i] + (index[i] as f64 + base[i] + sub[i]) * dx[i]) as f32);
        }
        // Row-major increment: the last axis runs fastest.
        for i in (0..d).rev() {
            index[i] += 1;
            if index[i] < shape[i] {
                break;
            }
            index[i] = 0;
        }
    }
    out
}

fn check_axis(op: &'static str, domain: &Domain, axis: usize) -> Result<()> {
    if axis < domain.dim() {
        Ok(())
    } else {
        Err(GeomError::InvalidArgument {
            op,
            reason: format!("the domain has {} axes, no axis {axis}", domain.dim()),
        })
    }
}
