//! Obstacles rasterised onto the grid: which cells are solid, which faces they block and, when
//! obstacles move, their velocity on those faces.

use phi_core::Tensor;
use phi_core::backend::{Backend, PadMode};
use phi_core::fields::{CenteredGrid, StaggeredGrid};
use phi_geom::Obstacle;

use super::FlipSimulation;
use crate::error::Result;

/// Obstacles rasterised onto the grid: solid cells and the faces they block.
#[derive(Debug, Clone)]
pub(super) struct ObstacleMasks<B: Backend> {
    /// `[res..., 1]`: 1 in cells whose centre lies inside an obstacle.
    pub(super) solid: CenteredGrid<B>,
    /// Per face, 1 where both neighbouring cells are free, 0 where one is solid.
    pub(super) face_open: StaggeredGrid<B>,
    /// The obstacles' velocity on the faces they block, when any obstacle moves.
    pub(super) velocity: Option<StaggeredGrid<B>>,
}

impl<B: Backend> FlipSimulation<B> {
    /// The obstacles at `time`, obstacle `i` translated by `offsets[i]` (missing or all-zero
    /// offsets: not translated).
    pub(super) fn shifted_obstacles_at(
        &self,
        time: f32,
        offsets: &[Vec<f32>],
    ) -> Result<Vec<Obstacle>> {
        self.obstacles
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let o = o.advanced(time)?;
                match offsets.get(i) {
                    Some(c) if c.iter().any(|&v| v != 0.0) => Ok(Obstacle::new(
                        o.geometry().shifted(c)?,
                        o.velocity().to_vec(),
                    )?),
                    _ => Ok(o),
                }
            })
            .collect()
    }

    /// The obstacle masks at `time` with obstacle `i` translated by `offsets[i]`: the ones built
    /// once when no obstacle moves and no offset is set, else rasterised afresh.
    pub(super) fn masks_at(&self, time: f32, offsets: &[Vec<f32>]) -> Result<ObstacleMasks<B>> {
        let shifted = offsets.iter().flatten().any(|&v| v != 0.0);
        match &self.static_masks {
            Some(m) if !shifted => Ok(m.clone()),
            _ => self.obstacle_masks(time, offsets),
        }
    }

    /// Rasterises the obstacles at `time`: a face is blocked when a cell on either side is solid
    /// (Φ_Flow's staggered accessibility), so the pressure solve never couples liquid with the
    /// inside of an obstacle.
    pub(super) fn obstacle_masks(
        &self,
        time: f32,
        offsets: &[Vec<f32>],
    ) -> Result<ObstacleMasks<B>> {
        let domain = &self.domain;
        let d = domain.dim();
        let device = &self.device;
        let mut cell_shape = domain.resolution().to_vec();
        cell_shape.push(1);
        let mut solid = Tensor::<B>::zeros(domain.resolution(), device);
        let mut velocity: Option<Vec<Tensor<B>>> = None;
        let moving = self.obstacles.iter().any(Obstacle::is_moving);
        let mut blocked_total: Vec<Tensor<B>> = (0..d)
            .map(|a| Tensor::zeros(&domain.staggered_shape(a), device))
            .collect();
        for obstacle in self.shifted_obstacles_at(time, offsets)? {
            let inside = obstacle.geometry().cell_inside_mask::<B>(domain, device)?;
            solid = solid.maximum(&inside)?;
            let blocked = blocked_faces(&inside)?;
            if moving {
                let v = velocity.get_or_insert_with(|| {
                    (0..d)
                        .map(|a| Tensor::zeros(&domain.staggered_shape(a), device))
                        .collect()
                });
                for axis in 0..d {
                    let own = &blocked[axis] * obstacle.velocity()[axis];
                    v[axis] = Tensor::select(&blocked[axis], &own, &v[axis])?;
                }
            }
            for axis in 0..d {
                blocked_total[axis] = blocked_total[axis].maximum(&blocked[axis])?;
            }
        }
        let face_open = blocked_total.iter().map(|b| 1.0 - b).collect();
        Ok(ObstacleMasks {
            solid: CenteredGrid::new(solid.reshape(&cell_shape)?, domain.clone())?,
            face_open: StaggeredGrid::new(face_open, domain.clone())?,
            velocity: match velocity {
                Some(v) => Some(StaggeredGrid::new(v, domain.clone())?),
                None => None,
            },
        })
    }
}

/// Faces of each axis with a solid cell (`inside [res...]`, 0/1) on either side. Faces on the
/// domain's sides see only their one cell.
fn blocked_faces<B: Backend>(inside: &Tensor<B>) -> Result<Vec<Tensor<B>>> {
    let d = inside.rank();
    (0..d)
        .map(|axis| {
            let mut widths = vec![(0, 0); d];
            widths[axis] = (1, 1);
            let padded = inside.pad(&widths, PadMode::Constant(0.0))?;
            let n = inside.shape()[axis];
            Ok(padded
                .narrow(axis, 0..n + 1)?
                .maximum(&padded.narrow(axis, 1..n + 2)?)?)
        })
        .collect()
}
