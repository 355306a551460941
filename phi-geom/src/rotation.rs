//! [`Rotation`]: a planar angle in 2D, an axis–angle pair in 3D.

use crate::error::{GeomError, Result};

/// A rotation about the origin; [`crate::Rotated`] moves it to a pivot.
///
/// Angles are in **degrees**, positive angles turn counter-clockwise:
/// - [`Rotation::Planar`] (2D) turns the x axis toward the y axis;
/// - [`Rotation::AxisAngle`] (3D) turns by the right-hand rule about `axis` (which need not have
///   unit length; it is normalised, and must not be zero). A planar rotation by `θ` is the 3D
///   rotation about `[0, 0, 1]` by `θ`.
#[derive(Debug, Clone, PartialEq)]
pub enum Rotation {
    /// A 2D rotation by `degrees`, counter-clockwise.
    Planar {
        /// The angle in degrees.
        degrees: f32,
    },
    /// A 3D rotation by `degrees` about `axis`, right-handed.
    AxisAngle {
        /// The axis of rotation (any non-zero length).
        axis: [f32; 3],
        /// The angle in degrees.
        degrees: f32,
    },
}

impl Rotation {
    /// A 2D rotation by `degrees`, counter-clockwise.
    pub fn degrees(degrees: f32) -> Self {
        Rotation::Planar { degrees }
    }

    /// A 3D rotation by `degrees` about `axis` (right-hand rule).
    pub fn axis_angle(axis: [f32; 3], degrees: f32) -> Self {
        Rotation::AxisAngle { axis, degrees }
    }

    /// The dimension of the space the rotation acts on: 2 or 3.
    pub fn dim(&self) -> usize {
        match self {
            Rotation::Planar { .. } => 2,
            Rotation::AxisAngle { .. } => 3,
        }
    }

    /// The angle in degrees.
    pub fn angle_degrees(&self) -> f32 {
        match self {
            Rotation::Planar { degrees } | Rotation::AxisAngle { degrees, .. } => *degrees,
        }
    }

    /// Checks that the numbers are finite and the axis is not zero.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] naming the field.
    pub fn validate(&self) -> Result<()> {
        match self {
            Rotation::Planar { degrees } => {
                if !degrees.is_finite() {
                    return Err(GeomError::invalid(
                        "rotated.angle",
                        degrees,
                        "must be finite",
                    ));
                }
            }
            Rotation::AxisAngle { axis, degrees } => {
                if !degrees.is_finite() {
                    return Err(GeomError::invalid(
                        "rotated.angle",
                        degrees,
                        "must be finite",
                    ));
                }
                if axis.iter().any(|a| !a.is_finite()) {
                    return Err(GeomError::invalid("rotated.axis", axis, "must be finite"));
                }
                if axis.iter().all(|&a| a == 0.0) {
                    return Err(GeomError::invalid("rotated.axis", axis, "must not be zero"));
                }
            }
        }
        Ok(())
    }

    /// The rotation matrix `R`, row-major `d × d`, computed in `f64`: a vector `v` turns into
    /// `R v`.
    pub fn matrix(&self) -> Vec<f64> {
        match self {
            Rotation::Planar { degrees } => {
                let (s, c) = f64::from(*degrees).to_radians().sin_cos();
                vec![c, -s, s, c]
            }
            Rotation::AxisAngle { axis, degrees } => {
                let norm = axis
                    .iter()
                    .map(|&a| f64::from(a).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let [x, y, z] = axis.map(|a| f64::from(a) / norm);
                let (s, c) = f64::from(*degrees).to_radians().sin_cos();
                let t = 1.0 - c;
                // Rodrigues: R = c I + s [n]ₓ + (1 - c) n nᵀ
                vec![
                    c + t * x * x,
                    t * x * y - s * z,
                    t * x * z + s * y,
                    t * y * x + s * z,
                    c + t * y * y,
                    t * y * z - s * x,
                    t * z * x - s * y,
                    t * z * y + s * x,
                    c + t * z * z,
                ]
            }
        }
    }

    /// `R v` for a host vector of the rotation's dimension.
    pub fn apply(&self, v: &[f32]) -> Vec<f32> {
        let d = self.dim();
        let m = self.matrix();
        (0..d)
            .map(|i| (0..d).map(|j| m[i * d + j] * f64::from(v[j])).sum::<f64>() as f32)
            .collect()
    }

    /// The inverse rotation.
    pub fn inverse(&self) -> Rotation {
        match self {
            Rotation::Planar { degrees } => Rotation::Planar { degrees: -degrees },
            Rotation::AxisAngle { axis, degrees } => Rotation::AxisAngle {
                axis: *axis,
                degrees: -degrees,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn planar_quarter_turn_maps_x_to_y() {
        let r = Rotation::degrees(90.0);
        let v = r.apply(&[1.0, 0.0]);
        assert_abs_diff_eq!(v[0], 0.0, epsilon = 1e-7);
        assert_abs_diff_eq!(v[1], 1.0, epsilon = 1e-7);
    }

    #[test]
    fn axis_angle_about_z_matches_planar_and_is_orthonormal() {
        let planar = Rotation::degrees(37.0).matrix();
        let spatial = Rotation::axis_angle([0.0, 0.0, 2.0], 37.0).matrix();
        for i in 0..2 {
            for j in 0..2 {
                assert_abs_diff_eq!(planar[i * 2 + j], spatial[i * 3 + j], epsilon = 1e-12);
            }
        }
        assert_abs_diff_eq!(spatial[8], 1.0, epsilon = 1e-12);
        let m = Rotation::axis_angle([1.0, -2.0, 0.5], 123.0).matrix();
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| m[i * 3 + k] * m[j * 3 + k]).sum();
                assert_abs_diff_eq!(dot, if i == j { 1.0 } else { 0.0 }, epsilon = 1e-12);
            }
        }
        // The axis is fixed, and the inverse undoes the rotation.
        let axis = [1.0, -2.0, 0.5];
        let r = Rotation::axis_angle(axis, 123.0);
        let fixed = r.apply(&axis);
        for k in 0..3 {
            assert_abs_diff_eq!(fixed[k], axis[k], epsilon = 1e-6);
        }
        let back = r.inverse().apply(&r.apply(&[0.3, 0.4, -1.2]));
        for (b, e) in back.iter().zip([0.3, 0.4, -1.2]) {
            assert_abs_diff_eq!(*b, e, epsilon = 1e-6);
        }
    }

    #[test]
    fn invalid_rotations_are_errors() {
        assert!(Rotation::degrees(f32::NAN).validate().is_err());
        let message = Rotation::axis_angle([0.0; 3], 10.0)
            .validate()
            .unwrap_err()
            .to_string();
        assert!(message.contains("rotated.axis"), "{message}");
        assert!(
            Rotation::axis_angle([0.0, 0.0, 1.0], 10.0)
                .validate()
                .is_ok()
        );
    }
}
