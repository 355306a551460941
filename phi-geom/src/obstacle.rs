//! [`Obstacle`]: a solid geometry moving at a constant velocity.

use serde::{Deserialize, Serialize};

use crate::error::{GeomError, Result};
use crate::geometry::Geometry;

/// A solid obstacle: a geometry and the velocity its surface moves with (zero for a resting
/// obstacle). Scene files write
/// `{ geometry = { type = "box", lower = [8, 0], upper = [12, 20] }, velocity = [0, 0] }`;
/// `velocity` may be left out (at rest). Unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ObstacleSpec")]
pub struct Obstacle {
    geometry: Geometry,
    velocity: Vec<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleSpec {
    geometry: Geometry,
    #[serde(default)]
    velocity: Option<Vec<f32>>,
}

impl TryFrom<ObstacleSpec> for Obstacle {
    type Error = GeomError;
    fn try_from(spec: ObstacleSpec) -> Result<Self> {
        match spec.velocity {
            Some(v) => Obstacle::new(spec.geometry, v),
            None => Obstacle::at_rest(spec.geometry),
        }
    }
}

impl Obstacle {
    /// An obstacle moving with `velocity`.
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] when the velocity's length is not the geometry's
    /// dimension; [`GeomError::InvalidGeometry`] for a non-finite velocity or an invalid geometry.
    pub fn new(geometry: Geometry, velocity: impl Into<Vec<f32>>) -> Result<Self> {
        let velocity = velocity.into();
        geometry.validate()?;
        if velocity.len() != geometry.dim() {
            return Err(GeomError::dims(
                "obstacle",
                geometry.dim(),
                "the velocity",
                velocity.len(),
            ));
        }
        if velocity.iter().any(|v| !v.is_finite()) {
            return Err(GeomError::invalid(
                "obstacle.velocity",
                &velocity,
                "every entry must be finite",
            ));
        }
        Ok(Obstacle { geometry, velocity })
    }

    /// A resting obstacle.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] for an invalid geometry.
    pub fn at_rest(geometry: Geometry) -> Result<Self> {
        let d = geometry.dim();
        Obstacle::new(geometry, vec![0.0; d])
    }

    /// The shape.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The velocity, one entry per axis.
    pub fn velocity(&self) -> &[f32] {
        &self.velocity
    }

    /// Whether the velocity is not zero.
    pub fn is_moving(&self) -> bool {
        self.velocity.iter().any(|&v| v != 0.0)
    }

    /// The obstacle after moving for `dt` at its velocity.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] when `dt` is not finite.
    pub fn advanced(&self, dt: f32) -> Result<Self> {
        let delta: Vec<f32> = self.velocity.iter().map(|v| v * dt).collect();
        Ok(Obstacle {
            geometry: self.geometry.shifted(&delta)?,
            velocity: self.velocity.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocity_must_match_and_advancing_moves_the_geometry() {
        let ball = Geometry::sphere([1.0, 2.0], 0.5).unwrap();
        let e = Obstacle::new(ball.clone(), [1.0, 0.0, 0.0])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("2-dimensional") && e.contains("velocity") && e.contains("3-dimensional"),
            "{e}"
        );
        assert!(Obstacle::new(ball.clone(), [f32::NAN, 0.0]).is_err());
        let rest = Obstacle::at_rest(ball.clone()).unwrap();
        assert!(!rest.is_moving());
        assert_eq!(rest.velocity(), &[0.0, 0.0]);
        let moving = Obstacle::new(ball, [2.0, -1.0]).unwrap();
        let later = moving.advanced(0.5).unwrap();
        assert_eq!(later.geometry().center(), vec![2.0, 1.5]);
        assert!(later.is_moving());
    }
}
