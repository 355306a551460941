//! The particle ↔ grid kernels: multilinear sampling, splatting and RK4 advection of points,
//! with the composite's index arithmetic and summation order.

use crate::fields::kernels::Integrator;
use crate::fields::lattice::{SampleLattice, Transfer};

/// The index arithmetic of the multilinear stencil, operation for operation as the composite
/// default in `fields::sample` does it (so the fused kernels give the same values).
pub(super) struct LatticeIndexer {
    origin: Vec<f32>,
    inverse_spacing: Vec<f32>,
    /// `shape − 1`: the clamp of continuous indices.
    upper: Vec<f32>,
    /// `max(shape − 2, 0)`: the highest lower corner.
    highest_base: Vec<usize>,
    strides: Vec<usize>,
    shape: Vec<usize>,
}

impl LatticeIndexer {
    pub(super) fn new(lattice: &SampleLattice) -> Self {
        let d = lattice.shape.len();
        let mut strides = vec![1usize; d];
        for axis in (0..d.saturating_sub(1)).rev() {
            strides[axis] = strides[axis + 1] * lattice.shape[axis + 1];
        }
        Self {
            origin: lattice.origin.clone(),
            inverse_spacing: lattice.spacing.iter().map(|s| 1.0 / s).collect(),
            upper: lattice.shape.iter().map(|&s| (s - 1) as f32).collect(),
            highest_base: lattice.shape.iter().map(|&s| s.saturating_sub(2)).collect(),
            strides,
            shape: lattice.shape.clone(),
        }
    }
}

/// The flat offset of each corner from the lower corner (independent of the point).
fn corner_offsets<const D: usize>(indexer: &LatticeIndexer) -> [usize; 8] {
    let mut offsets = [0usize; 8];
    for (corner, offset) in offsets.iter_mut().enumerate().take(1 << D) {
        for axis in 0..D {
            if (corner >> (D - 1 - axis)) & 1 == 1 && indexer.shape[axis] > 1 {
                *offset += indexer.strides[axis];
            }
        }
    }
    offsets
}

/// [`LatticeIndexer`] in fixed-size arrays for a `D`-dimensional lattice, so the per-point loops
/// keep everything in registers (no bounds checks, unrolled axes).
struct FixedIndexer<const D: usize> {
    origin: [f32; D],
    inverse_spacing: [f32; D],
    upper: [f32; D],
    /// `max(shape − 2, 0)` as an integer: the highest lower corner.
    highest_base: [i32; D],
    strides: [usize; D],
    /// `strides` in `i32`, for the vectorised lower corners: a lattice has at most `i32::MAX`
    /// samples (checked in `new`), so every flat index fits.
    strides_i32: [i32; D],
    /// `highest_base` and `strides` in `f32`, for lattices whose flat indices are all exact in
    /// `f32` (`exact_in_f32`): there the lower corners need no integer multiplications or
    /// minima, which x86-64's baseline SSE2 lacks for 32-bit lanes.
    highest_base_f32: [f32; D],
    strides_f32: [f32; D],
    exact_in_f32: bool,
}

impl<const D: usize> FixedIndexer<D> {
    fn new(indexer: &LatticeIndexer) -> Self {
        let pick = |v: &[f32]| std::array::from_fn(|axis| v[axis]);
        // The lower corners are computed in `i32` (below): the lattice must index within it.
        assert!(
            indexer.shape.iter().product::<usize>() <= i32::MAX as usize,
            "lattice too large"
        );
        Self {
            origin: pick(&indexer.origin),
            inverse_spacing: pick(&indexer.inverse_spacing),
            upper: pick(&indexer.upper),
            highest_base: std::array::from_fn(|axis| indexer.highest_base[axis] as i32),
            strides: std::array::from_fn(|axis| indexer.strides[axis]),
            strides_i32: std::array::from_fn(|axis| indexer.strides[axis] as i32),
            highest_base_f32: std::array::from_fn(|axis| indexer.highest_base[axis] as f32),
            strides_f32: std::array::from_fn(|axis| indexer.strides[axis] as f32),
            // Every flat index and every partial sum of one is below the sample count.
            exact_in_f32: indexer.shape.iter().product::<usize>() <= 1 << f32::MANTISSA_DIGITS,
        }
    }

    /// The continuous sample index of coordinate `x` along `axis`, `(x − origin) / spacing`
    /// clamped to `[0, shape − 1]`, as the composite computes it.
    #[inline(always)]
    fn continuous(&self, x: f32, axis: usize) -> f32 {
        ((x - self.origin[axis]) * self.inverse_spacing[axis])
            .max(0.0)
            .min(self.upper[axis])
    }

    /// The lower corner along `axis` of a continuous index `t` (from
    /// [`continuous`](Self::continuous)) and the fraction beyond it: `min(trunc(t), shape − 2)`
    /// in integers. `t` is clamped to `[0, shape − 1]`, so truncation is the floor, and these
    /// integers convert to `f32` exactly, which makes it the composite's
    /// `min(floor(t), shape − 2)` bit for bit.
    #[inline(always)]
    fn base(&self, t: f32, axis: usize) -> (i32, f32) {
        // SAFETY: `t` comes from `continuous`, which clamps it into `[0, shape − 1]` (a NaN
        // coordinate becomes 0 there, as `f32::max` returns the other operand), so it is finite
        // and, with `new`'s check on the lattice size, representable in `i32`. The unchecked
        // conversion then equals `t as i32`, without the saturation fix-ups that keep the lane
        // loops from vectorising.
        let whole: i32 = unsafe { t.to_int_unchecked() };
        let b = whole.min(self.highest_base[axis]);
        (b, t - b as f32)
    }

    /// The flat lower corner and the fractions of `point`: the continuous index
    /// `(x − origin) / spacing` clamped to `[0, shape − 1]`, its integer part capped at
    /// `shape − 2`, as the composite computes it.
    #[inline(always)]
    fn lower_corner(&self, point: &[f32]) -> (usize, [f32; D]) {
        let mut flat = 0;
        let mut fraction = [0.0f32; D];
        for axis in 0..D {
            let (b, f) = self.base(self.continuous(point[axis], axis), axis);
            flat += b as usize * self.strides[axis];
            fraction[axis] = f;
        }
        (flat, fraction)
    }

    /// [`lower_corner`](Self::lower_corner) of a block of points `x` (coordinate-major:
    /// `x[axis][point]`): the flat lower corners and the fractions (`fraction[axis][point]`).
    /// The arithmetic runs lane by lane over the block, which the compiler vectorises; the flat
    /// indices are summed in 32-bit lanes (a lattice has at most `i32::MAX` samples, checked in
    /// `new`), as 64-bit multiplications would not vectorise.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
    fn lower_corners(&self, x: &[Lane; D]) -> ([u32; LANES], [Lane; D]) {
        let mut fraction = [[0.0f32; LANES]; D];
        if self.exact_in_f32 {
            // The same corners in `f32`: `trunc(min(t, highest))` is `min(trunc(t), highest)`
            // for `t ≥ 0` and an integer `highest`, and the flat index and its partial sums are
            // integers below `2^24`, so every product and sum is exact.
            let mut flat = [0.0f32; LANES];
            for axis in 0..D {
                for i in 0..LANES {
                    let t = self.continuous(x[axis][i], axis);
                    let capped = t.min(self.highest_base_f32[axis]);
                    // SAFETY: `t` is clamped into `[0, shape − 1]` by `continuous` (a NaN
                    // coordinate becomes 0 there), so `capped` is finite and fits `i32`.
                    let b = unsafe { capped.to_int_unchecked::<i32>() } as f32;
                    flat[i] += b * self.strides_f32[axis];
                    fraction[axis][i] = t - b;
                }
            }
            // SAFETY: every entry is an exact non-negative integer below `2^24`.
            return (
                flat.map(|f| unsafe { f.to_int_unchecked::<i32>() } as u32),
                fraction,
            );
        }
        let mut flat = [0i32; LANES];
        for axis in 0..D {
            for i in 0..LANES {
                let (b, f) = self.base(self.continuous(x[axis][i], axis), axis);
                flat[i] += b * self.strides_i32[axis];
                fraction[axis][i] = f;
            }
        }
        // Non-negative: every lower corner and stride is.
        (flat.map(|f| f as u32), fraction)
    }
}

/// The tent weight of `corner`, multiplied in axis order as the composite does.
#[inline(always)]
fn corner_weight<const D: usize>(corner: usize, fraction: &[f32; D]) -> f32 {
    let mut weight = 1.0f32;
    for (axis, &f) in fraction.iter().enumerate() {
        let factor = if (corner >> (D - 1 - axis)) & 1 == 1 {
            f
        } else {
            1.0 - f
        };
        weight = if axis == 0 { factor } else { weight * factor };
    }
    weight
}

/// [`LatticeKernels::float_lattice_sample`] on a `D`-dimensional lattice: `out [N, c]` from values
/// `v [samples, c]` at points `p [N, D]`, corners summed in the composite's order.
pub(super) fn sample_kernel<const D: usize>(
    indexer: &LatticeIndexer,
    v: &[f32],
    p: &[f32],
    c: usize,
    out: &mut [f32],
) {
    let offsets = corner_offsets::<D>(indexer);
    let fixed = FixedIndexer::<D>::new(indexer);
    if c == 1 {
        // One channel (a staggered component): blocks of points, corners in the same order.
        let sampler = ComponentSampler::<D>::new(indexer, v);
        for_each_block::<D>(p, |first, x, count| {
            let values = sampler.sample_block(x);
            out[first..first + count].copy_from_slice(&values[..count]);
        });
        return;
    }
    for (point, row) in p.chunks_exact(D).zip(out.chunks_exact_mut(c)) {
        let (flat, fraction) = fixed.lower_corner(point);
        for (corner, &offset) in offsets.iter().enumerate().take(1 << D) {
            let weight = corner_weight::<D>(corner, &fraction);
            let at = (flat + offset) * c;
            for (o, &x) in row.iter_mut().zip(&v[at..at + c]) {
                *o += x * weight;
            }
        }
    }
}

/// Points per block of the vectorised point loops ([`ComponentSampler::sample_block`] and the
/// kernels built on it). Each step of the interpolation runs over a whole block before the next,
/// in structure-of-arrays layout, so that the compiler turns the arithmetic into SIMD
/// instructions and the independent points keep the pipeline full.
const LANES: usize = 16;

/// One coordinate (or velocity component) of a block of [`LANES`] points.
type Lane = [f32; LANES];

/// One staggered component (or one channel of a lattice) ready for point queries: the lattice's
/// index arithmetic, its corner offsets and its values `[samples]`.
struct ComponentSampler<'a, const D: usize> {
    indexer: FixedIndexer<D>,
    offsets: [usize; 8],
    values: &'a [f32],
}

impl<'a, const D: usize> ComponentSampler<'a, D> {
    fn new(indexer: &LatticeIndexer, values: &'a [f32]) -> Self {
        let samples: usize = indexer.shape.iter().product();
        assert_eq!(values.len(), samples, "one value per lattice sample");
        Self {
            indexer: FixedIndexer::new(indexer),
            offsets: corner_offsets::<D>(indexer),
            values,
        }
    }

    /// The values at a block of points `x` (coordinate-major: `x[axis][point]`), each as
    /// [`sample_kernel`] computes it with one channel: first the lower corners and fractions of
    /// the whole block ([`FixedIndexer::lower_corners`], vectorised), then corner by corner the
    /// scalar loads, the tent weights and the running sums, in the composite's corner order.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
    fn sample_block(&self, x: &[Lane; D]) -> Lane {
        let (flat, fraction) = self.indexer.lower_corners(x);
        let mut out = [0.0f32; LANES];
        for corner in 0..(1 << D) {
            let offset = self.offsets[corner];
            for i in 0..LANES {
                let f: [f32; D] = std::array::from_fn(|axis| fraction[axis][i]);
                let at = flat[i] as usize + offset;
                debug_assert!(at < self.values.len());
                // SAFETY: along each axis the lower corner is at most `max(shape − 2, 0)`
                // (`FixedIndexer::base`), and a corner's offset steps one sample further only
                // along axes with more than one sample, so `at ≤ Σ (shape − 1) · stride =
                // samples − 1`; `new` checked that `values` holds `samples` values.
                let value = unsafe { *self.values.get_unchecked(at) };
                out[i] += value * corner_weight::<D>(corner, &f);
            }
        }
        out
    }
}

/// The points `p [N, D]` (row-major) in blocks of [`LANES`], coordinate-major: `f` gets each
/// block and the number of real points in it. The last block is padded with zeros (a valid
/// position: queries are clamped to the lattice), whose results `f` ignores.
#[allow(clippy::needless_range_loop)] // the axes of a point, unrolled
fn for_each_block<const D: usize>(p: &[f32], mut f: impl FnMut(usize, &[Lane; D], usize)) {
    for (block, points) in p.chunks(D * LANES).enumerate() {
        let mut x = [[0.0f32; LANES]; D];
        for (i, point) in points.chunks_exact(D).enumerate() {
            for axis in 0..D {
                x[axis][i] = point[axis];
            }
        }
        f(block * LANES, &x, points.len() / D);
    }
}

/// [`LatticeKernels::float_lattice_sample_columns`] for `D` one-channel lattices of dimension `D` (a
/// staggered grid's components) at points `p [N, D]`: `[N, D]`, each column as [`sample_kernel`]
/// computes it, written in place of the composite's joined columns.
pub(super) fn sample_columns_kernel<const D: usize>(
    lattices: &[SampleLattice],
    values: &[&[f32]],
    p: &[f32],
) -> Vec<f32> {
    let components: Vec<ComponentSampler<'_, D>> = lattices
        .iter()
        .zip(values)
        .map(|(lattice, values)| ComponentSampler::new(&LatticeIndexer::new(lattice), values))
        .collect();
    let mut out = vec![0.0f32; p.len()];
    for_each_block::<D>(p, |first, x, count| {
        let columns: [Lane; D] = std::array::from_fn(|axis| components[axis].sample_block(x));
        for (i, o) in out[first * D..(first + count) * D]
            .chunks_exact_mut(D)
            .enumerate()
        {
            for (axis, o) in o.iter_mut().enumerate() {
                *o = columns[axis][i];
            }
        }
    });
    out
}

/// Points moved through a staggered velocity as
/// [`composite_advect_points`](crate::fields::sample::composite_advect_points) moves them: the
/// same operations in the same order, so the same values, on blocks of [`LANES`] points stage by
/// stage (each stage depends on the one before, so the independent points of a block are what
/// keeps the pipeline full, and the element-wise steps vectorise).
#[allow(clippy::needless_range_loop)] // index loops over lanes vectorise
pub(super) fn advect_kernel<const D: usize>(
    lattices: &[SampleLattice],
    values: &[&[f32]],
    p: &[f32],
    dt: f32,
    integrator: Integrator,
) -> Vec<f32> {
    let components: Vec<ComponentSampler<'_, D>> = lattices
        .iter()
        .zip(values)
        .map(|(lattice, values)| ComponentSampler::new(&LatticeIndexer::new(lattice), values))
        .collect();
    let components = &components[..D];
    #[inline(always)]
    fn velocity<const D: usize>(
        components: &[ComponentSampler<'_, D>],
        x: &[Lane; D],
    ) -> [Lane; D] {
        std::array::from_fn(|axis| components[axis].sample_block(x))
    }
    /// `x + k h`, lane by lane.
    #[inline(always)]
    fn step<const D: usize>(x: &[Lane; D], k: &[Lane; D], h: f32) -> [Lane; D] {
        let mut y = [[0.0f32; LANES]; D];
        for axis in 0..D {
            for i in 0..LANES {
                y[axis][i] = x[axis][i] + k[axis][i] * h;
            }
        }
        y
    }
    let (half, sixth) = (0.5 * dt, dt / 6.0);
    let mut out = vec![0.0f32; p.len()];
    for_each_block::<D>(p, |first, x, count| {
        let moved = match integrator {
            Integrator::Euler => step(x, &velocity(components, x), dt),
            Integrator::Rk4 => {
                let k1 = velocity(components, x);
                let k2 = velocity(components, &step(x, &k1, half));
                let k3 = velocity(components, &step(x, &k2, half));
                let k4 = velocity(components, &step(x, &k3, dt));
                let mut moved = [[0.0f32; LANES]; D];
                for axis in 0..D {
                    let [k1, k2, k3, k4] = [&k1[axis], &k2[axis], &k3[axis], &k4[axis]];
                    for i in 0..LANES {
                        moved[axis][i] =
                            x[axis][i] + (k1[i] + k4[i] + (k2[i] + k3[i]) * 2.0) * sixth;
                    }
                }
                moved
            }
        };
        for (i, o) in out[first * D..(first + count) * D]
            .chunks_exact_mut(D)
            .enumerate()
        {
            for axis in 0..D {
                o[axis] = moved[axis][i];
            }
        }
    });
    out
}

/// The tent stencils of `p [N, D]` on a lattice, block by block (vectorised): each point's lower
/// corner (flat index) and its weight per corner (`corner_weights[corner][point]`).
fn linear_stencils<const D: usize>(
    fixed: &FixedIndexer<D>,
    p: &[f32],
) -> (Vec<u32>, Vec<Vec<f32>>) {
    let n = p.len() / D;
    // Whole blocks are appended (a fixed-size copy, inlined, where the `count` real points of the
    // last block would call `memcpy` for every block), and the padding of the last block is cut
    // off afterwards.
    let padded = n.div_ceil(LANES) * LANES;
    let mut flats = Vec::with_capacity(padded);
    let mut corner_weights: Vec<Vec<f32>> =
        (0..1 << D).map(|_| Vec::with_capacity(padded)).collect();
    for_each_block::<D>(p, |_, x, _| {
        let (flat, fraction) = fixed.lower_corners(x);
        flats.extend_from_slice(&flat);
        for (corner, out) in corner_weights.iter_mut().enumerate() {
            let w: Lane = std::array::from_fn(|i| {
                corner_weight::<D>(corner, &std::array::from_fn(|axis| fraction[axis][i]))
            });
            out.extend_from_slice(&w);
        }
    });
    flats.truncate(n);
    for out in &mut corner_weights {
        out.truncate(n);
    }
    (flats, corner_weights)
}

/// [`LatticeKernels::float_lattice_splat_columns`] with tent weights for `D` columns onto `D` lattices
/// of dimension `D` (a staggered grid's components): `(sums, weights)` per lattice. The stencils
/// are those of [`splat_kernel`]; the adds of the `D` lattices are interleaved point by point.
/// Each lattice still receives its adds corner-major in point order, so its sums round exactly
/// as [`splat_kernel`]'s; but where consecutive points add to the same sample, each add waits
/// for the one before (through memory), and the other lattices' adds fill that wait.
#[allow(clippy::needless_range_loop)] // corners and lattices index several arrays
pub(super) fn splat_columns_kernel<const D: usize>(
    lattices: &[SampleLattice],
    v: &[f32],
    p: &[f32],
) -> Vec<(Vec<f32>, Vec<f32>)> {
    let n = p.len() / D;
    assert!(lattices.len() == D && v.len() == n * D);
    let indexers: Vec<LatticeIndexer> = lattices.iter().map(LatticeIndexer::new).collect();
    let stencils: Vec<(Vec<u32>, Vec<Vec<f32>>)> = indexers
        .iter()
        .map(|indexer| linear_stencils(&FixedIndexer::<D>::new(indexer), p))
        .collect();
    let offsets: Vec<[usize; 8]> = indexers.iter().map(corner_offsets::<D>).collect();
    let mut out: Vec<(Vec<f32>, Vec<f32>)> = indexers
        .iter()
        .map(|indexer| {
            let samples: usize = indexer.shape.iter().product();
            (vec![0.0; samples], vec![0.0; samples])
        })
        .collect();
    let flats: [&[u32]; D] = std::array::from_fn(|j| &stencils[j].0[..n]);
    for corner in 0..1 << D {
        let weights: [&[f32]; D] = std::array::from_fn(|j| &stencils[j].1[corner][..n]);
        let offset: [usize; D] = std::array::from_fn(|j| offsets[j][corner]);
        let mut sinks: [(&mut [f32], &mut [f32]); D] = {
            let mut rest = &mut out[..];
            std::array::from_fn(|_| {
                let (first, tail) = std::mem::take(&mut rest)
                    .split_first_mut()
                    .expect("one output per lattice");
                rest = tail;
                (&mut first.0[..], &mut first.1[..])
            })
        };
        for (k, point) in v.chunks_exact(D).enumerate() {
            for j in 0..D {
                let at = flats[j][k] as usize + offset[j];
                let weight = weights[j][k];
                let (sums, sample_weights) = &mut sinks[j];
                debug_assert!(at < sums.len() && at < sample_weights.len());
                // SAFETY: `at` is a corner of a lower corner from `lower_corners`, at most
                // `samples − 1` of lattice `j` (see `ComponentSampler::sample_block`), and both
                // arrays hold that lattice's `samples` values.
                unsafe {
                    *sums.get_unchecked_mut(at) += point[j] * weight;
                    *sample_weights.get_unchecked_mut(at) += weight;
                }
            }
        }
    }
    out
}

/// [`LatticeKernels::float_lattice_splat`] on a `D`-dimensional lattice into `(sums [samples, c],
/// weights [samples])`. Tent weights are added corner-major, as the composite scatter adds, so
/// that the sums round the same.
pub(super) fn splat_kernel<const D: usize>(
    indexer: &LatticeIndexer,
    v: &[f32],
    p: &[f32],
    c: usize,
    transfer: Transfer,
    (sums, weights): (&mut [f32], &mut [f32]),
) {
    let fixed = FixedIndexer::<D>::new(indexer);
    /// Adds `weight · value` to the sums of sample `at` and `weight` to its weight.
    #[inline(always)]
    fn add(sums: &mut [f32], weights: &mut [f32], at: usize, value: &[f32], weight: f32) {
        let c = value.len();
        for (s, &x) in sums[at * c..(at + 1) * c].iter_mut().zip(value) {
            *s += x * weight;
        }
        weights[at] += weight;
    }
    match transfer {
        Transfer::NearestFace => {
            for (point, value) in p.chunks_exact(D).zip(v.chunks_exact(c)) {
                add(sums, weights, nearest_sample(&fixed, point), value, 1.0);
            }
        }
        Transfer::Linear => {
            let offsets = corner_offsets::<D>(indexer);
            let (flats, corner_weights) = linear_stencils(&fixed, p);
            let samples: usize = indexer.shape.iter().product();
            assert!(sums.len() == samples * c && weights.len() == samples);
            for (&offset, corner_weights) in offsets.iter().zip(&corner_weights) {
                let stencils = flats.iter().zip(corner_weights);
                if c == 1 {
                    // One channel (a staggered component): no row slices.
                    for ((&flat, &weight), &x) in stencils.zip(v) {
                        let at = flat as usize + offset;
                        debug_assert!(at < samples);
                        // SAFETY: `at` is a corner of a lower corner from `lower_corners`, at
                        // most `samples − 1` (see `ComponentSampler::sample_block`), and both
                        // arrays hold `samples` values (checked above).
                        unsafe {
                            *sums.get_unchecked_mut(at) += x * weight;
                            *weights.get_unchecked_mut(at) += weight;
                        }
                    }
                } else {
                    for ((&flat, &weight), value) in stencils.zip(v.chunks_exact(c)) {
                        add(sums, weights, flat as usize + offset, value, weight);
                    }
                }
            }
        }
    }
}

/// The flat index of the sample nearest to `point`.
#[inline(always)]
fn nearest_sample<const D: usize>(indexer: &FixedIndexer<D>, point: &[f32]) -> usize {
    (0..D)
        .map(|axis| {
            let t = indexer.continuous(point[axis], axis) + 0.5;
            (t as u32 as f32).min(indexer.upper[axis]) as usize * indexer.strides[axis]
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lower corners in `f32` (lattices whose flat indices are exact there) equal the
    /// integer ones, which larger lattices take: points inside, on the upper edges (where the
    /// corner is capped) and beyond, including NaN, in 1D to 3D.
    #[test]
    fn lower_corners_in_f32_equal_the_integer_ones() {
        fn check<const D: usize>(shape: &[usize]) {
            let lattice = SampleLattice {
                origin: vec![0.25; D],
                spacing: (0..D).map(|axis| 0.5 + 0.25 * axis as f32).collect(),
                shape: shape.to_vec(),
            };
            let fast = FixedIndexer::<D>::new(&LatticeIndexer::new(&lattice));
            assert!(fast.exact_in_f32);
            let integer = FixedIndexer::<D> {
                exact_in_f32: false,
                ..FixedIndexer::<D>::new(&LatticeIndexer::new(&lattice))
            };
            let mut x = [[0.0f32; LANES]; D];
            for (axis, lane) in x.iter_mut().enumerate() {
                let (step, upper) = (lattice.spacing[axis], shape[axis] as f32 - 1.0);
                for (i, v) in lane.iter_mut().enumerate() {
                    // Sample positions, halfway points, the upper edge and beyond.
                    *v = lattice.origin[axis] + step * (i as f32 * 0.5 - 1.0).min(upper + 1.0);
                }
                lane[LANES - 2] = lattice.origin[axis] + step * upper;
            }
            x[0][LANES - 1] = f32::NAN;
            let (flat, fraction) = fast.lower_corners(&x);
            let (flat_integer, fraction_integer) = integer.lower_corners(&x);
            assert_eq!(flat, flat_integer, "{shape:?}");
            let bits = |f: &[Lane; D]| f.map(|lane| lane.map(f32::to_bits));
            assert_eq!(bits(&fraction), bits(&fraction_integer), "{shape:?}");
        }
        check::<1>(&[9]);
        check::<1>(&[1]);
        check::<2>(&[7, 5]);
        check::<2>(&[6, 1]);
        check::<3>(&[4, 6, 5]);
    }
}
