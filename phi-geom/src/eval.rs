//! Evaluating geometries on batches of points: inside masks, signed distances and `push`.
//!
//! Everything here is built from [`Tensor`] operations (no values are read back to the host), so
//! it runs on any backend and is differentiable in the points on an autodiff backend. Internally
//! per-point results are `[N, 1]` columns, which broadcast against `[N, d]` points.

use phi_core::backend::{CompareOp, ReduceOp};
use phi_core::{Backend, Tensor, TensorError};

use crate::error::{GeomError, Result};
use crate::geometry::{AxisBox, Geometry, Rotated, UNION_PUSH_ROUNDS, members_apart};

type TResult<T> = std::result::Result<T, TensorError>;

/// Which way [`Geometry::push`] moves points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PushDirection {
    /// Points inside the geometry move to its nearest surface and `offset` beyond it; points
    /// outside (or on the surface) stay where they are. Used to keep particles out of obstacles.
    Outward,
    /// Points outside the geometry move onto its nearest surface and `offset` into it; points
    /// inside (or on the surface) stay where they are. Used to keep particles inside the domain.
    Inward,
}

impl PushDirection {
    fn flipped(self) -> Self {
        match self {
            PushDirection::Outward => PushDirection::Inward,
            PushDirection::Inward => PushDirection::Outward,
        }
    }
}

/// Rounding margin, in units of the coordinates' magnitude, added to pushes whose landing point
/// is computed rather than copied (balls, rotations), so that rounding cannot leave a pushed
/// point inside.
const ROUNDING_MARGIN: f32 = 16.0 * f32::EPSILON;

impl Geometry {
    /// Whether each point lies strictly inside (in the open interior; points on the surface are
    /// outside), as a `[N]` mask of `0.0` and `1.0`. An inverted geometry's interior is everything
    /// outside the closed original, so a point on the surface is inside neither.
    ///
    /// # Errors
    /// [`GeomError::NotPoints`] unless `points` is `[N, d]`; [`GeomError::DimensionMismatch`] when
    /// `d` is not the geometry's dimension; [`GeomError::InvalidGeometry`] for a geometry that
    /// fails [`Geometry::validate`].
    pub fn lies_inside<B: Backend>(&self, points: &Tensor<B>) -> Result<Tensor<B>> {
        let n = self.check_points("lies_inside", points)?;
        Ok(self.inside_col(points, false)?.reshape(&[n])?)
    }

    /// Signed distance of each point to the surface, `[N]`: negative inside, positive outside,
    /// zero on the surface. Differentiable in the points.
    ///
    /// Exact for boxes and balls, and exact for a rotated or inverted geometry whose original is
    /// exact (rotations preserve distances; inversion flips the sign). For a union it is the
    /// minimum over the members, which is the exact distance outside the union and, inside,
    /// bounds the depth from below (`|sdf|` ≤ the true distance to the union's surface, because
    /// overlapping members hide surfaces); hence it is approximate for compositions with unions
    /// (a union inside an inversion, a rotation of a union inherits the union's bound). The
    /// sign is always right.
    ///
    /// # Errors
    /// As [`Geometry::lies_inside`].
    pub fn approximate_signed_distance<B: Backend>(&self, points: &Tensor<B>) -> Result<Tensor<B>> {
        let n = self.check_points("approximate_signed_distance", points)?;
        Ok(self.sdf_col(points)?.reshape(&[n])?)
    }

    /// The points moved out of (`Outward`) or into (`Inward`) the geometry, `[N, d]`.
    ///
    /// - **Outward**: each point strictly inside moves to the nearest point of the surface and
    ///   then `offset` further along the outward direction; every other point is returned
    ///   unchanged (bit for bit).
    /// - **Inward**: each point outside the closed geometry moves to the nearest point of it and
    ///   `offset` further in (for a box, every coordinate is clamped into the box shrunk by
    ///   `offset`, collapsing to the centre on axes shorter than `2 offset`; for a ball, the
    ///   landing point is `offset` inside the sphere along the ray from the centre); every other
    ///   point is unchanged.
    ///
    /// The move is the minimal one for boxes and balls (ties between faces of a box go to the
    /// lowest axis; the centre of a ball is pushed along +x) and for rotations and inversions of
    /// them. Landing points that are computed rather than copied (balls, rotations) overshoot by
    /// a few units in the last place of the coordinates, so that rounding never leaves a pushed
    /// point inside when `offset = 0`.
    ///
    /// **Unions.** `Inward`: each outside point goes into the member with the smallest signed
    /// distance (exactly the nearest member for exact members). `Outward`: the members push in
    /// turn, [`UNION_PUSH_ROUNDS`] times round, since leaving one member may land a point in
    /// another; points still inside after that are pushed out of the union's bounding box
    /// (not minimal, but outside every member). So no point ends inside any member, unless the
    /// union's bounding box is infinite (a member is inverted) and the rounds did not suffice.
    ///
    /// Built from tensor operations only: differentiable in the points (the gradient is the
    /// Jacobian of the piecewise-smooth map: identity on untouched points, zero along a box axis
    /// a point was snapped on).
    ///
    /// # Errors
    /// As [`Geometry::lies_inside`], and [`GeomError::InvalidArgument`] for a negative or
    /// non-finite `offset`.
    pub fn push<B: Backend>(
        &self,
        points: &Tensor<B>,
        direction: PushDirection,
        offset: f32,
    ) -> Result<Tensor<B>> {
        self.check_points("push", points)?;
        if !offset.is_finite() || offset < 0.0 {
            return Err(GeomError::InvalidArgument {
                op: "push",
                reason: format!("the offset must be finite and not negative, got {offset}"),
            });
        }
        Ok(self.push_col(points, direction, offset)?)
    }

    /// Checks `points` against the geometry and returns `N`.
    pub(crate) fn check_points<B: Backend>(
        &self,
        op: &'static str,
        points: &Tensor<B>,
    ) -> Result<usize> {
        self.validate()?;
        let shape = points.shape();
        if shape.len() != 2 {
            return Err(GeomError::NotPoints { op, shape });
        }
        if shape[1] != self.dim() {
            return Err(GeomError::dims(op, self.dim(), "the points", shape[1]));
        }
        Ok(shape[0])
    }

    /// Inside mask `[N, 1]`: the closed geometry when `closed`, else the open interior.
    pub(crate) fn inside_col<B: Backend>(&self, p: &Tensor<B>, closed: bool) -> TResult<Tensor<B>> {
        let device = p.device();
        match self {
            Geometry::Box(b) => {
                let lower = row(b.lower(), &device)?;
                let upper = row(b.upper(), &device)?;
                // Signs of differences are exact in IEEE arithmetic: `x - l > 0 ⇔ x > l`.
                let margin = (p - &lower).minimum(&(&upper - p))?;
                let margin = margin.reduce_axis(ReduceOp::Min, 1, true)?;
                Ok(margin.compare_scalar(
                    if closed {
                        CompareOp::GreaterEqual
                    } else {
                        CompareOp::Greater
                    },
                    0.0,
                ))
            }
            Geometry::Sphere(s) => {
                let rel = p - row(s.center(), &device)?;
                let d2 = sum_cols(&(&rel * &rel))?;
                let r2 = s.radius() * s.radius();
                Ok(d2.compare_scalar(
                    if closed {
                        CompareOp::LessEqual
                    } else {
                        CompareOp::Less
                    },
                    r2,
                ))
            }
            Geometry::Rotated(r) => {
                let frame = Frame::new(r, &device)?;
                r.geometry().inside_col(&frame.to_local(p)?, closed)
            }
            Geometry::Union(members) => {
                let mut acc: Option<Tensor<B>> = None;
                for m in members {
                    let mask = m.inside_col(p, closed)?;
                    acc = Some(match acc {
                        None => mask,
                        Some(a) => a.maximum(&mask)?,
                    });
                }
                acc.ok_or_else(|| empty_union("inside"))
            }
            Geometry::Inverted(inner) => Ok(1.0 - inner.inside_col(p, !closed)?),
        }
    }

    /// Signed distance `[N, 1]`.
    pub(crate) fn sdf_col<B: Backend>(&self, p: &Tensor<B>) -> TResult<Tensor<B>> {
        let device = p.device();
        match self {
            Geometry::Box(b) => {
                let rel = p - row(&b.center(), &device)?;
                let q = rel.abs() - row(&b.half_size(), &device)?;
                let outside = safe_sqrt(&sum_cols(&q.relu().square())?)?;
                let deepest = q.reduce_axis(ReduceOp::Max, 1, true)?;
                // min(deepest, 0) = -relu(-deepest)
                Ok(outside - (-deepest).relu())
            }
            Geometry::Sphere(s) => {
                let rel = p - row(s.center(), &device)?;
                Ok(safe_sqrt(&sum_cols(&rel.square())?)? - s.radius())
            }
            Geometry::Rotated(r) => {
                let frame = Frame::new(r, &device)?;
                r.geometry().sdf_col(&frame.to_local(p)?)
            }
            Geometry::Union(members) => {
                let mut acc: Option<Tensor<B>> = None;
                for m in members {
                    let d = m.sdf_col(p)?;
                    acc = Some(match acc {
                        None => d,
                        Some(a) => a.minimum(&d)?,
                    });
                }
                acc.ok_or_else(|| empty_union("signed distance"))
            }
            Geometry::Inverted(inner) => Ok(-inner.sdf_col(p)?),
        }
    }

    /// `push` without the argument checks.
    pub(crate) fn push_col<B: Backend>(
        &self,
        p: &Tensor<B>,
        direction: PushDirection,
        offset: f32,
    ) -> TResult<Tensor<B>> {
        match self {
            Geometry::Box(b) => match direction {
                PushDirection::Outward => push_box_outward(self, b, p, offset),
                PushDirection::Inward => push_box_inward(self, b, p, offset),
            },
            Geometry::Sphere(s) => {
                let device = p.device();
                let center = row(s.center(), &device)?;
                let rel = p - &center;
                let d2 = sum_cols(&rel.square())?;
                let r = s.radius();
                let scale = s.center().iter().fold(0.0f32, |m, c| m.max(c.abs())) + r + offset;
                let margin = ROUNDING_MARGIN * scale;
                let (moved, landing_radius) = match direction {
                    PushDirection::Outward => (d2.less_scalar(r * r), r + offset + margin),
                    PushDirection::Inward => {
                        (d2.greater_scalar(r * r), (r - offset - margin).max(0.0))
                    }
                };
                let nonzero = d2.greater_scalar(0.0);
                let dist =
                    Tensor::select(&nonzero, &d2, &Tensor::full(&[1, 1], 1.0, &device))?.sqrt();
                let mut e0 = vec![0.0; s.dim()];
                e0[0] = 1.0;
                let unit = Tensor::select(&nonzero, &(&rel / &dist), &row(&e0, &device)?)?;
                let target = center + unit * landing_radius;
                Tensor::select(&moved, &target, p)
            }
            Geometry::Rotated(r) => {
                let frame = Frame::new(r, &p.device())?;
                let local = frame.to_local(p)?;
                let margin = ROUNDING_MARGIN * (self.coordinate_scale() + offset);
                let pushed = r.geometry().push_col(&local, direction, offset + margin)?;
                // The inner push returns the points it does not move bit for bit, so the moved
                // ones are those that changed: no second pass over the inner tree (which made
                // nested rotations quadratic), and the unmoved points skip the round trip.
                let moved = pushed.compare(CompareOp::NotEqual, &local)?.reduce_axis(
                    ReduceOp::Max,
                    1,
                    true,
                )?;
                Tensor::select(&moved, &frame.to_world(&pushed)?, p)
            }
            Geometry::Union(_) => match direction {
                PushDirection::Outward => {
                    // Nested unions are one union of all their members, pushed in one set of
                    // rounds (rounds of rounds would grow exponentially with the nesting); one
                    // round suffices when no landing point can lie in another member.
                    let members = self.flat_members();
                    let margin = ROUNDING_MARGIN * (self.coordinate_scale() + offset);
                    let rounds = if members_apart(&members, offset + margin) {
                        1
                    } else {
                        UNION_PUSH_ROUNDS
                    };
                    let mut q = p.clone();
                    for _ in 0..rounds {
                        for m in &members {
                            q = m.push_col(&q, PushDirection::Outward, offset)?;
                        }
                    }
                    if rounds == 1 {
                        return Ok(q);
                    }
                    let bounds = self.bounding_box();
                    if bounds.is_finite() {
                        let still_inside = self.inside_col(&q, false)?;
                        let out = Geometry::Box(bounds).push_col(
                            &q,
                            PushDirection::Outward,
                            offset + margin,
                        )?;
                        q = Tensor::select(&still_inside, &out, &q)?;
                    }
                    Ok(q)
                }
                PushDirection::Inward => {
                    let members = self.flat_members();
                    let distances = members
                        .iter()
                        .map(|m| m.sdf_col(p))
                        .collect::<TResult<Vec<_>>>()?;
                    let mut nearest = distances
                        .first()
                        .cloned()
                        .ok_or_else(|| empty_union("push"))?;
                    for d in &distances[1..] {
                        nearest = nearest.minimum(d)?;
                    }
                    let mut taken = Tensor::zeros(&[1, 1], &p.device());
                    let mut out = p.clone();
                    for (m, d) in members.iter().zip(&distances) {
                        let is_nearest = d.compare(CompareOp::LessEqual, &nearest)?;
                        let choose = &is_nearest * &(1.0 - &taken);
                        taken = taken.maximum(&is_nearest)?;
                        out = Tensor::select(
                            &choose,
                            &m.push_col(p, PushDirection::Inward, offset)?,
                            &out,
                        )?;
                    }
                    Ok(out)
                }
            },
            Geometry::Inverted(inner) => inner.push_col(p, direction.flipped(), offset),
        }
    }
}

/// Outward push of a box: snap the coordinate of the nearest face to that face plus `offset`.
fn push_box_outward<B: Backend>(
    g: &Geometry,
    b: &AxisBox,
    p: &Tensor<B>,
    offset: f32,
) -> TResult<Tensor<B>> {
    let device = p.device();
    let inside = g.inside_col(p, false)?;
    let rel = p - row(&b.center(), &device)?;
    let q = rel.abs() - row(&b.half_size(), &device)?;
    let deepest = q.reduce_axis(ReduceOp::Max, 1, true)?;
    let mut taken = Tensor::zeros(&[1, 1], &device);
    let mut columns = Vec::with_capacity(b.dim());
    for k in 0..b.dim() {
        let is_nearest = column(&q, k)?.compare(CompareOp::GreaterEqual, &deepest)?;
        let choose = &(&is_nearest * &(1.0 - &taken)) * &inside;
        taken = taken.maximum(&is_nearest)?;
        let upper_side = column(&rel, k)?.compare_scalar(CompareOp::GreaterEqual, 0.0);
        // The face coordinates themselves (not centre ± half size), so that `offset = 0` lands
        // exactly on the surface.
        let target = Tensor::select(
            &upper_side,
            &Tensor::full(&[1, 1], b.upper()[k] + offset, &device),
            &Tensor::full(&[1, 1], b.lower()[k] - offset, &device),
        )?;
        columns.push(Tensor::select(&choose, &target, &column(p, k)?)?);
    }
    Tensor::concat(&columns, 1)
}

/// Inward push of a box: clamp every coordinate into the box shrunk by `offset`.
fn push_box_inward<B: Backend>(
    g: &Geometry,
    b: &AxisBox,
    p: &Tensor<B>,
    offset: f32,
) -> TResult<Tensor<B>> {
    let device = p.device();
    let center = b.center();
    let (mut low, mut high) = (Vec::with_capacity(b.dim()), Vec::with_capacity(b.dim()));
    for ((&lower, &upper), &middle) in b.lower().iter().zip(b.upper()).zip(&center) {
        let (l, h) = (lower + offset, upper - offset);
        // A box thinner than twice the offset shrinks to its centre line.
        if l <= h {
            low.push(l);
            high.push(h);
        } else {
            low.push(middle);
            high.push(middle);
        }
    }
    let clamped = p
        .maximum(&row(&low, &device)?)?
        .minimum(&row(&high, &device)?)?;
    let outside = 1.0 - g.inside_col(p, true)?;
    Tensor::select(&outside, &clamped, p)
}

/// The rotation of a [`Rotated`] as tensors: `local = (x - pivot) R + pivot` (rows times `R`
/// apply `R⁻¹ = Rᵀ`), `world = (x - pivot) Rᵀ + pivot`.
struct Frame<B: Backend> {
    pivot: Tensor<B>,
    to_local: Tensor<B>,
    to_world: Tensor<B>,
}

impl<B: Backend> Frame<B> {
    fn new(r: &Rotated, device: &B::Device) -> TResult<Self> {
        let d = r.rotation().dim();
        let m: Vec<f32> = r
            .rotation()
            .matrix()
            .into_iter()
            .map(|v| v as f32)
            .collect();
        let mt: Vec<f32> = (0..d * d).map(|i| m[(i % d) * d + i / d]).collect();
        Ok(Frame {
            pivot: row(&r.pivot(), device)?,
            to_local: Tensor::from_vec(m, &[d, d], device)?,
            to_world: Tensor::from_vec(mt, &[d, d], device)?,
        })
    }

    fn to_local(&self, p: &Tensor<B>) -> TResult<Tensor<B>> {
        Ok((p - &self.pivot).matmul(&self.to_local)? + &self.pivot)
    }

    fn to_world(&self, p: &Tensor<B>) -> TResult<Tensor<B>> {
        Ok((p - &self.pivot).matmul(&self.to_world)? + &self.pivot)
    }
}

/// `values` as a `[1, d]` row.
fn row<B: Backend>(values: &[f32], device: &B::Device) -> TResult<Tensor<B>> {
    Tensor::from_slice(values, &[1, values.len()], device)
}

/// Column `k` of `[N, d]`, as `[N, 1]`.
fn column<B: Backend>(t: &Tensor<B>, k: usize) -> TResult<Tensor<B>> {
    t.narrow(1, k..k + 1)
}

/// The sum over the columns, `[N, d] → [N, 1]`.
fn sum_cols<B: Backend>(t: &Tensor<B>) -> TResult<Tensor<B>> {
    t.reduce_axis(ReduceOp::Sum, 1, true)
}

/// `√s` for `s ≥ 0` whose gradient is finite (zero) at `s = 0`.
fn safe_sqrt<B: Backend>(s: &Tensor<B>) -> TResult<Tensor<B>> {
    let device = s.device();
    let positive = s.greater_scalar(0.0);
    let safe = Tensor::select(&positive, s, &Tensor::full(&[1, 1], 1.0, &device))?;
    Tensor::select(&positive, &safe.sqrt(), &Tensor::zeros(&[1, 1], &device))
}

fn empty_union(what: &str) -> TensorError {
    TensorError::InvalidArgument {
        op: "geometry",
        shape: vec![],
        reason: format!("the {what} of a union without members"),
    }
}
