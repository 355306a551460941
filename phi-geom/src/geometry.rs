//! The geometry types, their validation, builders and serde forms.

use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::error::{GeomError, Result};
use crate::rotation::Rotation;

/// An axis-aligned box `lower ≤ x ≤ upper` (Φ_Flow's `Box`).
///
/// Its interior is the open box `lower < x < upper`; a degenerate box (`lower_i = upper_i` on some
/// axis) is allowed and has no interior. Scene files write it as
/// `{ type = "box", lower = [0, 0], upper = [32, 8] }` inside a [`Geometry`], or as the table
/// `{ lower = [..], upper = [..] }` on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "AxisBoxSpec")]
pub struct AxisBox {
    lower: Vec<f32>,
    upper: Vec<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisBoxSpec {
    lower: Vec<f32>,
    upper: Vec<f32>,
}

impl TryFrom<AxisBoxSpec> for AxisBox {
    type Error = GeomError;
    fn try_from(spec: AxisBoxSpec) -> Result<Self> {
        AxisBox::new(spec.lower, spec.upper)
    }
}

impl AxisBox {
    /// The box `lower..upper`.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] for a dimension other than 1 to 3, corners of different
    /// lengths, non-finite corners or `lower > upper` on some axis.
    pub fn new(lower: impl Into<Vec<f32>>, upper: impl Into<Vec<f32>>) -> Result<Self> {
        let b = AxisBox {
            lower: lower.into(),
            upper: upper.into(),
        };
        b.validate()?;
        Ok(b)
    }

    /// The box with one range per axis, like Φ_Flow's `Box[0:32, 0:8]`:
    /// `AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0])`.
    ///
    /// # Errors
    /// As [`AxisBox::new`].
    pub fn from_ranges(ranges: &[Range<f32>]) -> Result<Self> {
        Self::new(
            ranges.iter().map(|r| r.start).collect::<Vec<_>>(),
            ranges.iter().map(|r| r.end).collect::<Vec<_>>(),
        )
    }

    /// A box with unchecked (possibly infinite) corners, for bounding boxes.
    pub(crate) fn unchecked(lower: Vec<f32>, upper: Vec<f32>) -> Self {
        AxisBox { lower, upper }
    }

    fn validate(&self) -> Result<()> {
        check_dim("box.lower", &self.lower)?;
        if self.upper.len() != self.lower.len() {
            return Err(GeomError::invalid(
                "box.upper",
                &self.upper,
                format!(
                    "has {} entries but box.lower {:?} has {}",
                    self.upper.len(),
                    self.lower,
                    self.lower.len()
                ),
            ));
        }
        check_finite("box.lower", &self.lower)?;
        check_finite("box.upper", &self.upper)?;
        if let Some(axis) = (0..self.lower.len()).find(|&i| self.lower[i] > self.upper[i]) {
            return Err(GeomError::invalid(
                "box.upper",
                &self.upper,
                format!(
                    "is below box.lower {:?} along axis {axis}; lower ≤ upper is required",
                    self.lower
                ),
            ));
        }
        Ok(())
    }

    /// The number of axes.
    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// The lower corner.
    pub fn lower(&self) -> &[f32] {
        &self.lower
    }

    /// The upper corner.
    pub fn upper(&self) -> &[f32] {
        &self.upper
    }

    /// The midpoint of the corners.
    pub fn center(&self) -> Vec<f32> {
        self.lower
            .iter()
            .zip(&self.upper)
            .map(|(l, u)| 0.5 * (l + u))
            .collect()
    }

    /// Half the edge lengths.
    pub(crate) fn half_size(&self) -> Vec<f32> {
        self.lower
            .iter()
            .zip(&self.upper)
            .map(|(l, u)| 0.5 * (u - l))
            .collect()
    }

    /// The edge lengths.
    pub fn size(&self) -> Vec<f32> {
        self.lower
            .iter()
            .zip(&self.upper)
            .map(|(l, u)| u - l)
            .collect()
    }

    /// The area (2D) or volume (3D).
    pub fn volume(&self) -> f32 {
        self.size().iter().product()
    }

    /// Whether all corners are finite (bounding boxes of inverted geometries are not).
    pub fn is_finite(&self) -> bool {
        self.lower.iter().chain(&self.upper).all(|v| v.is_finite())
    }

    /// The smallest box containing `self` and `other` (of one dimension).
    pub(crate) fn hull(&self, other: &AxisBox) -> AxisBox {
        AxisBox {
            lower: self
                .lower
                .iter()
                .zip(&other.lower)
                .map(|(a, b)| a.min(*b))
                .collect(),
            upper: self
                .upper
                .iter()
                .zip(&other.upper)
                .map(|(a, b)| a.max(*b))
                .collect(),
        }
    }

    /// The `2^d` corners.
    pub(crate) fn corners(&self) -> Vec<Vec<f32>> {
        let d = self.dim();
        (0..1usize << d)
            .map(|bits| {
                (0..d)
                    .map(|i| {
                        if (bits >> i) & 1 == 1 {
                            self.upper[i]
                        } else {
                            self.lower[i]
                        }
                    })
                    .collect()
            })
            .collect()
    }
}

/// A ball `|x - center| ≤ radius` (a disc in 2D), interior `|x - center| < radius`.
/// Scene files write `{ type = "sphere", center = [16, 16], radius = 4 }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "SphereSpec")]
pub struct Sphere {
    center: Vec<f32>,
    radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereSpec {
    center: Vec<f32>,
    radius: f32,
}

impl TryFrom<SphereSpec> for Sphere {
    type Error = GeomError;
    fn try_from(spec: SphereSpec) -> Result<Self> {
        Sphere::new(spec.center, spec.radius)
    }
}

impl Sphere {
    /// The ball of `radius` around `center`.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] for a dimension other than 1 to 3, non-finite numbers or a
    /// negative radius.
    pub fn new(center: impl Into<Vec<f32>>, radius: f32) -> Result<Self> {
        let s = Sphere {
            center: center.into(),
            radius,
        };
        s.validate()?;
        Ok(s)
    }

    fn validate(&self) -> Result<()> {
        check_dim("sphere.center", &self.center)?;
        check_finite("sphere.center", &self.center)?;
        if !self.radius.is_finite() || self.radius < 0.0 {
            return Err(GeomError::invalid(
                "sphere.radius",
                self.radius,
                "must be finite and not negative",
            ));
        }
        Ok(())
    }

    /// The number of axes.
    pub fn dim(&self) -> usize {
        self.center.len()
    }

    /// The centre.
    pub fn center(&self) -> &[f32] {
        &self.center
    }

    /// The radius.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// The length (1D), area (2D) or volume (3D).
    pub fn volume(&self) -> f32 {
        let r = self.radius;
        match self.dim() {
            1 => 2.0 * r,
            2 => std::f32::consts::PI * r * r,
            _ => 4.0 / 3.0 * std::f32::consts::PI * r * r * r,
        }
    }
}

/// A geometry turned by a [`Rotation`] about a pivot (by default the geometry's
/// [centre](Geometry::center)).
///
/// A point `x` lies in the rotated geometry when `pivot + R⁻¹ (x - pivot)` lies in the original.
#[derive(Debug, Clone, PartialEq)]
pub struct Rotated {
    geometry: Box<Geometry>,
    rotation: Rotation,
    pivot: Option<Vec<f32>>,
}

impl Rotated {
    /// `geometry` turned by `rotation` about `pivot` (`None`: about the geometry's centre).
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] when the rotation or pivot does not have the geometry's
    /// dimension; [`GeomError::InvalidGeometry`] for non-finite numbers or a zero axis.
    pub fn new(geometry: Geometry, rotation: Rotation, pivot: Option<Vec<f32>>) -> Result<Self> {
        let r = Rotated {
            geometry: Box::new(geometry),
            rotation,
            pivot,
        };
        r.validate()?;
        Ok(r)
    }

    fn validate(&self) -> Result<()> {
        self.geometry.validate()?;
        let depth = self.geometry.depth() + 1;
        if depth > MAX_DEPTH {
            return Err(too_deep(depth));
        }
        self.rotation.validate()?;
        let d = self.geometry.dim();
        if self.rotation.dim() != d {
            return Err(GeomError::dims(
                "rotated",
                d,
                match self.rotation {
                    Rotation::Planar { .. } => "a planar rotation (an angle without an axis)",
                    Rotation::AxisAngle { .. } => "an axis–angle rotation",
                },
                self.rotation.dim(),
            ));
        }
        if let Some(pivot) = &self.pivot {
            if pivot.len() != d {
                return Err(GeomError::dims("rotated", d, "the pivot", pivot.len()));
            }
            check_finite("rotated.pivot", pivot)?;
        }
        Ok(())
    }

    /// The geometry before rotation.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The rotation.
    pub fn rotation(&self) -> &Rotation {
        &self.rotation
    }

    /// The point the rotation turns about: the given pivot, or the geometry's centre.
    pub fn pivot(&self) -> Vec<f32> {
        match &self.pivot {
            Some(p) => p.clone(),
            None => self.geometry.center(),
        }
    }

    /// The pivot as given (`None`: the geometry's centre).
    pub fn explicit_pivot(&self) -> Option<&[f32]> {
        self.pivot.as_deref()
    }
}

/// A geometry in 1 to 3 dimensions, for obstacles, liquid initial states and domain walls.
///
/// Build one from [`AxisBox`] and [`Sphere`] (`Geometry::from(b)`), then combine with
/// [`Geometry::rotated`], [`Geometry::shifted`], [`Geometry::union`] and [`Geometry::inverted`].
/// Every constructor validates; deserialisation validates too, so a `Geometry` read from a scene
/// file is consistent.
///
/// # Scene-file form
/// A table with a `type` key (unknown keys are errors):
/// ```toml
/// obstacle = { type = "box", lower = [0, 0], upper = [32, 8] }
/// ball     = { type = "sphere", center = [16, 20], radius = 4 }
/// # 2D: `angle` in degrees, counter-clockwise; 3D: `angle` about `axis` (right-hand rule).
/// # `pivot` is optional and defaults to the centre of the rotated geometry.
/// ramp     = { type = "rotated", angle = 30, geometry = { type = "box", lower = [4, 4], upper = [20, 6] } }
/// cube     = { type = "rotated", angle = 45, axis = [0, 0, 1], pivot = [0, 0, 0], geometry = { type = "box", lower = [-1, -1, -1], upper = [1, 1, 1] } }
/// both     = { type = "union", members = [{ type = "sphere", center = [8, 8], radius = 2 }, { type = "box", lower = [0, 0], upper = [4, 4] }] }
/// hollow   = { type = "inverted", geometry = { type = "box", lower = [0, 0], upper = [64, 64] } }
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "GeometrySpec", into = "GeometrySpec")]
pub enum Geometry {
    /// An axis-aligned box.
    Box(AxisBox),
    /// A ball.
    Sphere(Sphere),
    /// A rotated geometry.
    Rotated(Rotated),
    /// The union of one or more geometries of one dimension.
    Union(Vec<Geometry>),
    /// The complement of a geometry: inside where it is outside (including its surface).
    Inverted(Box<Geometry>),
}

/// The serde form of [`Geometry`]: an internally tagged enum (`type = "box"`).
#[derive(Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
enum GeometrySpec {
    Box {
        lower: Vec<f32>,
        upper: Vec<f32>,
    },
    Sphere {
        center: Vec<f32>,
        radius: f32,
    },
    Rotated {
        geometry: Box<Geometry>,
        angle: f32,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        axis: Option<Vec<f32>>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pivot: Option<Vec<f32>>,
    },
    Union {
        members: Vec<Geometry>,
    },
    Inverted {
        geometry: Box<Geometry>,
    },
}

impl TryFrom<GeometrySpec> for Geometry {
    type Error = GeomError;
    fn try_from(spec: GeometrySpec) -> Result<Self> {
        Ok(match spec {
            GeometrySpec::Box { lower, upper } => Geometry::Box(AxisBox::new(lower, upper)?),
            GeometrySpec::Sphere { center, radius } => {
                Geometry::Sphere(Sphere::new(center, radius)?)
            }
            GeometrySpec::Rotated {
                geometry,
                angle,
                axis,
                pivot,
            } => {
                let rotation = match axis {
                    None => Rotation::degrees(angle),
                    Some(axis) => {
                        let axis: [f32; 3] = axis.as_slice().try_into().map_err(|_| {
                            GeomError::invalid(
                                "rotated.axis",
                                &axis,
                                "a rotation axis has 3 entries (2D rotations have no axis)",
                            )
                        })?;
                        Rotation::axis_angle(axis, angle)
                    }
                };
                Geometry::Rotated(Rotated::new(*geometry, rotation, pivot)?)
            }
            GeometrySpec::Union { members } => Geometry::union(members)?,
            GeometrySpec::Inverted { geometry } => {
                geometry.validate()?;
                Geometry::Inverted(geometry)
            }
        })
    }
}

impl From<Geometry> for GeometrySpec {
    fn from(geometry: Geometry) -> Self {
        match geometry {
            Geometry::Box(b) => GeometrySpec::Box {
                lower: b.lower,
                upper: b.upper,
            },
            Geometry::Sphere(s) => GeometrySpec::Sphere {
                center: s.center,
                radius: s.radius,
            },
            Geometry::Rotated(r) => {
                let (angle, axis) = match r.rotation {
                    Rotation::Planar { degrees } => (degrees, None),
                    Rotation::AxisAngle { axis, degrees } => (degrees, Some(axis.to_vec())),
                };
                GeometrySpec::Rotated {
                    geometry: r.geometry,
                    angle,
                    axis,
                    pivot: r.pivot,
                }
            }
            Geometry::Union(members) => GeometrySpec::Union { members },
            Geometry::Inverted(inner) => GeometrySpec::Inverted { geometry: inner },
        }
    }
}

impl From<AxisBox> for Geometry {
    fn from(b: AxisBox) -> Self {
        Geometry::Box(b)
    }
}

impl From<Sphere> for Geometry {
    fn from(s: Sphere) -> Self {
        Geometry::Sphere(s)
    }
}

impl From<Rotated> for Geometry {
    fn from(r: Rotated) -> Self {
        Geometry::Rotated(r)
    }
}

impl Geometry {
    /// An axis-aligned box; see [`AxisBox::new`].
    ///
    /// # Errors
    /// As [`AxisBox::new`].
    pub fn boxed(lower: impl Into<Vec<f32>>, upper: impl Into<Vec<f32>>) -> Result<Self> {
        AxisBox::new(lower, upper).map(Geometry::Box)
    }

    /// A ball; see [`Sphere::new`].
    ///
    /// # Errors
    /// As [`Sphere::new`].
    pub fn sphere(center: impl Into<Vec<f32>>, radius: f32) -> Result<Self> {
        Sphere::new(center, radius).map(Geometry::Sphere)
    }

    /// The union of `members`.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] for no members or an invalid member;
    /// [`GeomError::DimensionMismatch`] naming the first member whose dimension differs from the
    /// first's.
    pub fn union(members: Vec<Geometry>) -> Result<Self> {
        let u = Geometry::Union(members);
        u.validate()?;
        Ok(u)
    }

    /// `self` turned by `rotation` about its [centre](Geometry::center).
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] when the rotation is not of the geometry's dimension
    /// (planar for 2D, axis–angle for 3D); [`GeomError::InvalidGeometry`] for non-finite numbers.
    pub fn rotated(self, rotation: Rotation) -> Result<Self> {
        Rotated::new(self, rotation, None).map(Geometry::Rotated)
    }

    /// `self` turned by `rotation` about `pivot`.
    ///
    /// # Errors
    /// As [`Geometry::rotated`], and for a pivot of the wrong dimension.
    pub fn rotated_about(self, rotation: Rotation, pivot: impl Into<Vec<f32>>) -> Result<Self> {
        Rotated::new(self, rotation, Some(pivot.into())).map(Geometry::Rotated)
    }

    /// The complement of `self`.
    pub fn inverted(self) -> Self {
        Geometry::Inverted(Box::new(self))
    }

    /// `self` moved by `delta`.
    ///
    /// # Errors
    /// [`GeomError::DimensionMismatch`] for a `delta` of another dimension,
    /// [`GeomError::InvalidGeometry`] for a non-finite one.
    pub fn shifted(&self, delta: &[f32]) -> Result<Self> {
        if delta.len() != self.dim() {
            return Err(GeomError::dims(
                "shifted",
                self.dim(),
                "the shift",
                delta.len(),
            ));
        }
        check_finite("shift", delta)?;
        let shifted = self.shifted_unchecked(delta);
        shifted.validate()?;
        Ok(shifted)
    }

    fn shifted_unchecked(&self, delta: &[f32]) -> Self {
        let add = |v: &[f32]| -> Vec<f32> { v.iter().zip(delta).map(|(a, b)| a + b).collect() };
        match self {
            Geometry::Box(b) => Geometry::Box(AxisBox::unchecked(add(&b.lower), add(&b.upper))),
            Geometry::Sphere(s) => Geometry::Sphere(Sphere {
                center: add(&s.center),
                radius: s.radius,
            }),
            Geometry::Rotated(r) => Geometry::Rotated(Rotated {
                geometry: Box::new(r.geometry.shifted_unchecked(delta)),
                rotation: r.rotation.clone(),
                pivot: r.pivot.as_deref().map(add),
            }),
            Geometry::Union(members) => {
                Geometry::Union(members.iter().map(|m| m.shifted_unchecked(delta)).collect())
            }
            Geometry::Inverted(inner) => {
                Geometry::Inverted(Box::new(inner.shifted_unchecked(delta)))
            }
        }
    }

    /// Checks every number and dimension, recursively. Constructors and deserialisation call it;
    /// call it yourself after building a geometry from its variants directly.
    ///
    /// # Errors
    /// [`GeomError::InvalidGeometry`] naming the field and value, or
    /// [`GeomError::DimensionMismatch`] for mixed dimensions.
    pub fn validate(&self) -> Result<()> {
        let depth = self.depth();
        if depth > MAX_DEPTH {
            return Err(too_deep(depth));
        }
        // Dimensions first: the cost estimate compares the members' bounding boxes.
        self.validate_tree()?;
        if !matches!(self, Geometry::Box(_) | Geometry::Sphere(_)) {
            let cost = self.push_cost();
            if cost > MAX_PUSH_COST {
                return Err(GeomError::invalid(
                    "geometry",
                    format!("{cost:.3e} box and ball pushes per push"),
                    format!(
                        "more than {MAX_PUSH_COST:e}: overlapping unions inside rotations or \
                         inversions inside unions multiply the rounds of their pushes; list the \
                         members of nested unions in one union"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// [`validate`](Self::validate) without the checks of the whole tree's size.
    fn validate_tree(&self) -> Result<()> {
        match self {
            Geometry::Box(b) => b.validate(),
            Geometry::Sphere(s) => s.validate(),
            Geometry::Rotated(r) => r.validate(),
            Geometry::Union(members) => {
                let first = members.first().ok_or_else(|| {
                    GeomError::invalid(
                        "union.members",
                        Vec::<()>::new(),
                        "a union needs at least one member",
                    )
                })?;
                for m in members {
                    m.validate_tree()?;
                }
                let d = first.dim();
                if let Some((i, m)) = members.iter().enumerate().find(|(_, m)| m.dim() != d) {
                    return Err(GeomError::dims(
                        "union",
                        d,
                        format!("member {i} of the union"),
                        m.dim(),
                    ));
                }
                Ok(())
            }
            Geometry::Inverted(inner) => inner.validate_tree(),
        }
    }

    /// The number of spatial dimensions (0 for an empty union, which validation rejects).
    pub fn dim(&self) -> usize {
        match self {
            Geometry::Box(b) => b.dim(),
            Geometry::Sphere(s) => s.dim(),
            Geometry::Rotated(r) => r.geometry.dim(),
            Geometry::Union(members) => members.first().map_or(0, Geometry::dim),
            Geometry::Inverted(inner) => inner.dim(),
        }
    }

    /// A representative centre: the centre of a box or ball, the rotated centre of a rotated
    /// geometry, the centre of a union's bounding box (the mean of its members' centres when that
    /// box is infinite), the centre of the inverted geometry.
    pub fn center(&self) -> Vec<f32> {
        self.summary().center
    }

    /// An axis-aligned box containing the geometry: exact for boxes, balls and unions of them,
    /// the box around the rotated corners of the inner bounding box for rotated geometries (the
    /// rotated ball's box for a rotated ball), and the infinite box for inverted geometries.
    pub fn bounding_box(&self) -> AxisBox {
        self.summary().bounds
    }

    /// The largest absolute finite coordinate the geometry's numbers reach (bounding box and
    /// pivots): the scale of its rounding errors.
    pub(crate) fn coordinate_scale(&self) -> f32 {
        self.summary().scale
    }

    /// Centre, bounding box and coordinate scale together, in one pass over the tree (each of
    /// them needs the others' values of the children, so computing them apart would visit a
    /// nested geometry's children again and again).
    fn summary(&self) -> Summary {
        let finite_max = |v: &[f32]| {
            v.iter()
                .filter(|x| x.is_finite())
                .fold(0.0f32, |m, x| m.max(x.abs()))
        };
        let own_scale = |b: &AxisBox| finite_max(&b.lower).max(finite_max(&b.upper));
        match self {
            Geometry::Box(b) => Summary {
                center: b.center(),
                scale: own_scale(b),
                bounds: b.clone(),
            },
            Geometry::Sphere(s) => {
                let bounds = AxisBox::unchecked(
                    s.center.iter().map(|c| c - s.radius).collect(),
                    s.center.iter().map(|c| c + s.radius).collect(),
                );
                Summary {
                    center: s.center.clone(),
                    scale: own_scale(&bounds),
                    bounds,
                }
            }
            Geometry::Rotated(r) => {
                let inner = r.geometry.summary();
                let pivot = r.pivot.clone().unwrap_or_else(|| inner.center.clone());
                let turn = |point: &[f32]| -> Vec<f32> {
                    let rel: Vec<f32> = point.iter().zip(&pivot).map(|(c, p)| c - p).collect();
                    r.rotation
                        .apply(&rel)
                        .iter()
                        .zip(&pivot)
                        .map(|(v, p)| v + p)
                        .collect()
                };
                let center = turn(&inner.center);
                let bounds = if !inner.bounds.is_finite() {
                    inner.bounds.clone()
                } else if let Geometry::Sphere(s) = r.geometry.as_ref() {
                    AxisBox::unchecked(
                        center.iter().map(|c| c - s.radius).collect(),
                        center.iter().map(|c| c + s.radius).collect(),
                    )
                } else {
                    let d = pivot.len();
                    let mut lower = vec![f32::INFINITY; d];
                    let mut upper = vec![f32::NEG_INFINITY; d];
                    for corner in inner.bounds.corners() {
                        for (i, v) in turn(&corner).into_iter().enumerate() {
                            lower[i] = lower[i].min(v);
                            upper[i] = upper[i].max(v);
                        }
                    }
                    AxisBox::unchecked(lower, upper)
                };
                Summary {
                    scale: own_scale(&bounds).max(finite_max(&pivot)).max(inner.scale),
                    center,
                    bounds,
                }
            }
            Geometry::Union(members) => {
                let parts: Vec<Summary> = members.iter().map(Geometry::summary).collect();
                let bounds = parts
                    .iter()
                    .map(|p| p.bounds.clone())
                    .reduce(|a, b| a.hull(&b))
                    .unwrap_or_else(|| AxisBox::unchecked(vec![], vec![]));
                let center = if bounds.is_finite() {
                    bounds.center()
                } else {
                    let mut mean = vec![0.0; self.dim()];
                    for p in &parts {
                        for (acc, c) in mean.iter_mut().zip(&p.center) {
                            *acc += c / parts.len() as f32;
                        }
                    }
                    mean
                };
                Summary {
                    scale: parts.iter().fold(own_scale(&bounds), |m, p| m.max(p.scale)),
                    center,
                    bounds,
                }
            }
            Geometry::Inverted(inner) => {
                let inner = inner.summary();
                let d = inner.center.len();
                Summary {
                    center: inner.center,
                    scale: inner.scale,
                    bounds: AxisBox::unchecked(vec![f32::NEG_INFINITY; d], vec![f32::INFINITY; d]),
                }
            }
        }
    }

    /// The members of a union with nested unions expanded (a union of unions is the union of
    /// all their members); any other geometry is its own only member.
    pub(crate) fn flat_members(&self) -> Vec<&Geometry> {
        let mut out = Vec::new();
        let mut stack = vec![self];
        while let Some(g) = stack.pop() {
            match g {
                Geometry::Union(members) => stack.extend(members.iter().rev()),
                other => out.push(other),
            }
        }
        out
    }

    /// How deep the tree is: 1 for a box or ball, one more per rotation, union or inversion
    /// around it. Iterative, so that it can check trees too deep to recurse into.
    pub fn depth(&self) -> usize {
        let mut deepest = 0;
        let mut stack = vec![(self, 1usize)];
        while let Some((g, depth)) = stack.pop() {
            deepest = deepest.max(depth);
            match g {
                Geometry::Box(_) | Geometry::Sphere(_) => {}
                Geometry::Rotated(r) => stack.push((&r.geometry, depth + 1)),
                Geometry::Union(members) => stack.extend(members.iter().map(|m| (m, depth + 1))),
                Geometry::Inverted(inner) => stack.push((inner, depth + 1)),
            }
        }
        deepest
    }

    /// How many pushes of boxes and balls one [`push`](Geometry::push) may evaluate: one per
    /// primitive, times the rounds of each union's outward push (one when its members'
    /// bounding boxes are apart, [`UNION_PUSH_ROUNDS`](crate::UNION_PUSH_ROUNDS) otherwise).
    /// Linear in the size of the tree except where unions sit inside rotations or inversions
    /// inside unions, whose rounds multiply.
    pub fn push_cost(&self) -> f64 {
        match self {
            Geometry::Box(_) | Geometry::Sphere(_) => 1.0,
            Geometry::Rotated(r) => r.geometry.push_cost(),
            Geometry::Inverted(inner) => inner.push_cost(),
            Geometry::Union(_) => {
                let members = self.flat_members();
                let rounds = if members_apart(&members, 0.0) {
                    1.0
                } else {
                    UNION_PUSH_ROUNDS as f64
                };
                rounds * members.iter().map(|m| m.push_cost()).sum::<f64>()
            }
        }
    }
}

/// How often an outward push of a [`Geometry::Union`] cycles through its members before the
/// fallback (see [`Geometry::push`]).
pub const UNION_PUSH_ROUNDS: usize = 4;

/// Whether the bounding boxes of `members`, grown by `grow` on every side, are pairwise
/// disjoint (touching counts as overlapping): then a point pushed out of one member cannot land
/// in another. Sorted by their lower corner along axis 0, so that boxes apart along it are not
/// compared.
pub(crate) fn members_apart(members: &[&Geometry], grow: f32) -> bool {
    let mut boxes: Vec<AxisBox> = members.iter().map(|m| m.bounding_box()).collect();
    if boxes.iter().any(|b| !b.is_finite()) {
        return members.len() <= 1;
    }
    boxes.sort_by(|a, b| a.lower[0].total_cmp(&b.lower[0]));
    for (i, a) in boxes.iter().enumerate() {
        for b in &boxes[i + 1..] {
            if b.lower[0] - grow > a.upper[0] + grow {
                break;
            }
            let overlap = (0..a.dim()).all(|k| {
                a.lower[k] - grow <= b.upper[k] + grow && b.lower[k] - grow <= a.upper[k] + grow
            });
            if overlap {
                return false;
            }
        }
    }
    true
}

/// The error of a tree `depth` levels deep, beyond [`MAX_DEPTH`].
fn too_deep(depth: usize) -> GeomError {
    GeomError::invalid(
        "geometry",
        format!("a tree {depth} levels deep"),
        format!(
            "rotations, unions and inversions nest at most {MAX_DEPTH} deep; combine rotations \
             into one and list union members side by side"
        ),
    )
}

/// [`Geometry::summary`]: what a node's parent needs of it.
struct Summary {
    center: Vec<f32>,
    bounds: AxisBox,
    scale: f32,
}

/// The deepest geometry tree accepted (see [`Geometry::depth`]): deeper ones are refused
/// rather than recursed into.
pub const MAX_DEPTH: usize = 128;

/// The most box and ball pushes one push may evaluate (see [`Geometry::push_cost`]).
pub const MAX_PUSH_COST: f64 = 1e5;

fn check_dim(field: &str, v: &[f32]) -> Result<()> {
    if (1..=3).contains(&v.len()) {
        Ok(())
    } else {
        Err(GeomError::invalid(
            field,
            v,
            format!("a geometry has 1 to 3 dimensions, not {}", v.len()),
        ))
    }
}

fn check_finite(field: &str, v: &[f32]) -> Result<()> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(GeomError::invalid(field, v, "every entry must be finite"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_geometries_name_the_field() {
        let e = AxisBox::new(vec![0.0, 1.0], vec![1.0, 0.5])
            .unwrap_err()
            .to_string();
        assert!(e.contains("box.upper") && e.contains("axis 1"), "{e}");
        let e = Sphere::new(vec![0.0, 0.0], -1.0).unwrap_err().to_string();
        assert!(e.contains("sphere.radius") && e.contains("-1"), "{e}");
        let e = Sphere::new(vec![0.0, f32::INFINITY], 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sphere.center") && e.contains("inf"), "{e}");
        let e = AxisBox::new(vec![0.0, 0.0], vec![1.0, 1.0, 1.0])
            .unwrap_err()
            .to_string();
        assert!(e.contains("box.upper") && e.contains("3 entries"), "{e}");
        let e = AxisBox::new(vec![0.0; 4], vec![1.0; 4])
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 to 3 dimensions"), "{e}");
    }

    #[test]
    fn union_of_mixed_dimensions_is_an_error() {
        let square = Geometry::boxed([0.0, 0.0], [1.0, 1.0]).unwrap();
        let ball = Geometry::sphere([0.0, 0.0, 0.0], 1.0).unwrap();
        let e = Geometry::union(vec![square.clone(), ball]).unwrap_err();
        assert_eq!(
            e,
            GeomError::DimensionMismatch {
                context: "union".into(),
                geometry: 2,
                other_name: "member 1 of the union".into(),
                other: 3
            }
        );
        assert!(Geometry::union(vec![]).is_err());
        assert_eq!(Geometry::union(vec![square]).unwrap().dim(), 2);
    }

    #[test]
    fn rotation_must_match_dimension() {
        let cube = Geometry::boxed([0.0; 3], [1.0; 3]).unwrap();
        let e = cube
            .clone()
            .rotated(Rotation::degrees(30.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("3-dimensional") && e.contains("2-dimensional"),
            "{e}"
        );
        assert!(
            cube.clone()
                .rotated(Rotation::axis_angle([1.0, 0.0, 0.0], 30.0))
                .is_ok()
        );
        assert!(
            cube.rotated_about(Rotation::axis_angle([1.0, 0.0, 0.0], 30.0), [0.0, 0.0])
                .is_err()
        );
    }

    #[test]
    fn shift_center_and_bounds() {
        let b = AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap();
        assert_eq!(b.center(), vec![16.0, 4.0]);
        assert_eq!(b.volume(), 256.0);
        let g = Geometry::from(b).rotated(Rotation::degrees(90.0)).unwrap();
        let bounds = g.bounding_box();
        for (got, want) in bounds.lower().iter().zip([12.0, -12.0]) {
            assert!((got - want).abs() < 1e-4, "{bounds:?}");
        }
        for (got, want) in bounds.upper().iter().zip([20.0, 20.0]) {
            assert!((got - want).abs() < 1e-4, "{bounds:?}");
        }
        let moved = g.shifted(&[1.0, 2.0]).unwrap();
        let c = moved.center();
        assert!(
            (c[0] - 17.0).abs() < 1e-5 && (c[1] - 6.0).abs() < 1e-5,
            "{c:?}"
        );
        assert!(g.shifted(&[1.0]).is_err());
        let inv = Geometry::sphere([1.0, 1.0], 1.0).unwrap().inverted();
        assert!(!inv.bounding_box().is_finite());
        assert_eq!(inv.center(), vec![1.0, 1.0]);
    }
}
