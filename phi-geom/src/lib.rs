//! Geometries (boxes, spheres, rotated and united shapes) and obstacles, generic over the backend.
//!
//! The model is Φ_Flow's `phi.geom`: a [`Geometry`] answers, for a batch of points (an `[N, d]`
//! [`phi_core::Tensor`] on any backend), whether they [lie inside](Geometry::lies_inside), their
//! [signed distance](Geometry::approximate_signed_distance) to the surface, and where they go when
//! [pushed](Geometry::push) out of it or into it (how FLIP keeps particles out of obstacles and
//! inside the domain). It also [rasterises](Geometry::cell_volume_fraction) onto the cells and
//! faces of a [`phi_core::fields::Domain`], giving obstacle masks and face accessibility.
//!
//! Geometries are host-side descriptions (a few numbers); evaluation builds tensor operations
//! from them, so it runs on the device of the points and is differentiable in the points.
//!
//! ```
//! use phi_core::backend::ndarray::NdArray;
//! use phi_core::Tensor;
//! use phi_geom::{AxisBox, Geometry, PushDirection, Rotation};
//!
//! let device = Default::default();
//! let floor = Geometry::from(AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap());
//! let ramp = Geometry::boxed([8.0, 10.0], [24.0, 12.0]).unwrap().rotated(Rotation::degrees(30.0)).unwrap();
//! let obstacles = Geometry::union(vec![floor, ramp]).unwrap();
//!
//! let points = Tensor::<NdArray>::from_vec(vec![16.0, 7.0, 16.0, 30.0], &[2, 2], &device).unwrap();
//! assert_eq!(obstacles.lies_inside(&points).unwrap().to_vec(), vec![1.0, 0.0]);
//! let pushed = obstacles.push(&points, PushDirection::Outward, 0.0).unwrap();
//! assert_eq!(pushed.to_vec(), vec![16.0, 8.0, 16.0, 30.0]);
//! ```

mod error;
mod eval;
mod geometry;
mod obstacle;
mod raster;
mod rotation;

pub use error::{GeomError, Result};
pub use eval::PushDirection;
pub use geometry::{
    AxisBox, Geometry, MAX_DEPTH, MAX_PUSH_COST, Rotated, Sphere, UNION_PUSH_ROUNDS,
};
pub use obstacle::Obstacle;
pub use rotation::Rotation;
