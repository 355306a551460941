//! [`Domain`]: the box a simulation lives in, its grid resolution and its boundary conditions.
//!
//! # Layout conventions (used by every field and operator)
//! - Spatial axis `i` of a grid tensor is physical dimension `i` (x, y, z): a centred grid of
//!   resolution `[nx, ny]` is a tensor of shape `[nx, ny, channels]`, and cell `(i, j)` has its
//!   centre at `lower + ((i + ½) dx, (j + ½) dy)`.
//! - Staggered (MAC) component `i` has one more sample along axis `i`: face `k` along axis `i`
//!   lies at `lower_i + k dx_i`, centred on the other axes.
//! - Points are `[N, d]` tensors in physical units, column `i` the coordinate along axis `i`.

use crate::error::{Result, TensorError};

/// What happens at one side of the domain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Boundary {
    /// A solid free-slip wall: no flow through it (`u · n = 0`), tangential flow unhindered.
    Closed,
    /// An open side: liquid may leave, pressure is zero outside.
    Open,
}

/// A box-shaped simulation domain: physical bounds, grid resolution and the boundary condition of
/// each of its `2 d` sides.
#[derive(Debug, Clone, PartialEq)]
pub struct Domain {
    resolution: Vec<usize>,
    lower: Vec<f32>,
    upper: Vec<f32>,
    boundaries: Vec<[Boundary; 2]>,
}

impl Domain {
    /// A domain spanning `lower..upper` with `resolution` cells per axis and `boundaries[axis] =
    /// [lower side, upper side]`.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] for a dimension other than 1, 2 or 3, lists of different
    /// lengths, a zero resolution, non-finite bounds or `upper ≤ lower`.
    pub fn new(
        resolution: &[usize],
        lower: &[f32],
        upper: &[f32],
        boundaries: &[[Boundary; 2]],
    ) -> Result<Self> {
        let invalid = |reason: String| TensorError::InvalidArgument {
            op: "Domain::new",
            shape: resolution.to_vec(),
            reason,
        };
        let d = resolution.len();
        if !(1..=3).contains(&d) {
            return Err(invalid(format!("a domain has 1 to 3 dimensions, not {d}")));
        }
        if lower.len() != d || upper.len() != d || boundaries.len() != d {
            return Err(invalid(format!(
                "resolution, lower, upper and boundaries must all have {d} entries \
                 (got {}, {}, {})",
                lower.len(),
                upper.len(),
                boundaries.len()
            )));
        }
        for axis in 0..d {
            if resolution[axis] == 0 {
                return Err(invalid(format!("the resolution along axis {axis} is zero")));
            }
            let (lo, hi) = (lower[axis], upper[axis]);
            if !lo.is_finite() || !hi.is_finite() || hi <= lo {
                return Err(invalid(format!(
                    "the bounds along axis {axis} are {lo}..{hi}; they must be finite with lower < upper"
                )));
            }
        }
        Ok(Self {
            resolution: resolution.to_vec(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            boundaries: boundaries.to_vec(),
        })
    }

    /// A closed box `[0, n_i]` per axis with unit cells, like Φ_Flow's `Domain(x=64, y=64)`
    /// with closed walls.
    ///
    /// # Errors
    /// As [`Domain::new`].
    pub fn closed_unit_cells(resolution: &[usize]) -> Result<Self> {
        let lower = vec![0.0; resolution.len()];
        let upper: Vec<f32> = resolution.iter().map(|&n| n as f32).collect();
        let boundaries = vec![[Boundary::Closed; 2]; resolution.len()];
        Self::new(resolution, &lower, &upper, &boundaries)
    }

    /// Number of spatial dimensions.
    pub fn dim(&self) -> usize {
        self.resolution.len()
    }

    /// Cells per axis.
    pub fn resolution(&self) -> &[usize] {
        &self.resolution
    }

    /// Total number of cells.
    pub fn cell_count(&self) -> usize {
        self.resolution.iter().product()
    }

    /// Lower corner.
    pub fn lower(&self) -> &[f32] {
        &self.lower
    }

    /// Upper corner.
    pub fn upper(&self) -> &[f32] {
        &self.upper
    }

    /// Edge length of a cell along each axis.
    pub fn cell_size(&self) -> Vec<f32> {
        (0..self.dim())
            .map(|i| (self.upper[i] - self.lower[i]) / self.resolution[i] as f32)
            .collect()
    }

    /// Boundary conditions, `[lower side, upper side]` per axis.
    pub fn boundaries(&self) -> &[[Boundary; 2]] {
        &self.boundaries
    }

    /// The shape of staggered component `axis`: the resolution with one more sample along `axis`.
    pub fn staggered_shape(&self, axis: usize) -> Vec<usize> {
        let mut shape = self.resolution.clone();
        shape[axis] += 1;
        shape
    }

    /// Checks that `other` describes the same grid, for operations that combine two fields.
    ///
    /// # Errors
    /// [`TensorError::InvalidArgument`] naming both resolutions and bounds when they differ.
    pub(crate) fn check_same(&self, other: &Domain, op: &'static str) -> Result<()> {
        if self.resolution == other.resolution
            && self.lower == other.lower
            && self.upper == other.upper
        {
            Ok(())
        } else {
            Err(TensorError::InvalidArgument {
                op,
                shape: self.resolution.clone(),
                reason: format!(
                    "the fields live on different grids: resolution {:?} over {:?}..{:?} against \
                     resolution {:?} over {:?}..{:?}",
                    self.resolution,
                    self.lower,
                    self.upper,
                    other.resolution,
                    other.lower,
                    other.upper
                ),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_faces() {
        let domain = Domain::new(
            &[4, 2],
            &[0.0, -1.0],
            &[2.0, 1.0],
            &[[Boundary::Closed; 2]; 2],
        )
        .unwrap();
        assert_eq!(domain.cell_size(), vec![0.5, 1.0]);
        assert_eq!(domain.cell_count(), 8);
        assert_eq!(domain.staggered_shape(0), vec![5, 2]);
        assert_eq!(domain.staggered_shape(1), vec![4, 3]);
    }

    #[test]
    fn invalid_domains_are_errors() {
        let closed = [[Boundary::Closed; 2]; 2];
        assert!(Domain::new(&[0, 4], &[0.0, 0.0], &[1.0, 1.0], &closed).is_err());
        assert!(Domain::new(&[4, 4], &[0.0, 1.0], &[1.0, 1.0], &closed).is_err());
        assert!(Domain::new(&[4, 4], &[0.0, f32::NAN], &[1.0, 1.0], &closed).is_err());
        assert!(Domain::new(&[4], &[0.0, 0.0], &[1.0, 1.0], &closed).is_err());
        assert!(
            Domain::new(
                &[2, 2, 2, 2],
                &[0.0; 4],
                &[1.0; 4],
                &[[Boundary::Open; 2]; 4]
            )
            .is_err()
        );
        let a = Domain::closed_unit_cells(&[4, 4]).unwrap();
        let b = Domain::closed_unit_cells(&[4, 8]).unwrap();
        let message = a.check_same(&b, "add").unwrap_err().to_string();
        assert!(
            message.contains("[4, 4]") && message.contains("[4, 8]"),
            "{message}"
        );
    }
}
