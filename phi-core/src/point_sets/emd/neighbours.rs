//! Candidate partners for the assignment: for every point of one set, the points of the other in
//! the cells around it (a uniform grid, a cell list) for `d ≤ 3`, its `k` nearest by brute force
//! above; and both sets in the order of a space-filling curve.

/// A uniform grid over a point set `[N·d]` (row-major, `d ≤ 3`): the points of each cell are
/// contiguous in `order`, cell `c` holding `order[start[c]..start[c + 1]]`. Dimensions past `d`
/// have one cell. Points outside the box (none here, the box is the set's) would be clamped into
/// its border cells, which keeps [`CellGrid::nearby`]'s guarantee.
struct CellGrid {
    d: usize,
    lo: [f64; 3],
    /// Cell side (domain units).
    h: f64,
    cells: [usize; 3],
    start: Vec<usize>,
    order: Vec<u32>,
}

impl CellGrid {
    /// A grid of about `n / per_cell` cells over the bounding box of `points`.
    fn new(points: &[f64], d: usize, per_cell: f64) -> Self {
        let n = points.len() / d;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..d {
            let column = points.iter().skip(k).step_by(d);
            lo[k] = column.clone().copied().fold(f64::INFINITY, f64::min);
            hi[k] = column.copied().fold(f64::NEG_INFINITY, f64::max);
        }
        let extent: Vec<f64> = (0..d).map(|k| hi[k] - lo[k]).collect();
        let widest = extent.iter().copied().fold(0.0, f64::max);
        // The cell side that gives ~`n / per_cell` cells over the extents that are not flat (a
        // flat direction gets one cell).
        let flat = |e: f64| e <= 1e-9 * widest;
        let spread: Vec<f64> = extent.iter().copied().filter(|&e| !flat(e)).collect();
        let h: f64 = if spread.is_empty() {
            1.0
        } else {
            let volume: f64 = spread.iter().product();
            let target = (n as f64 / per_cell).max(1.0);
            (volume / target).powf(1.0 / spread.len() as f64)
        };
        let mut h = h;
        let mut cells = [1; 3];
        loop {
            for k in 0..d {
                if !flat(extent[k]) {
                    cells[k] = (extent[k] / h).floor() as usize + 1;
                }
            }
            // Nearly flat directions can multiply the count: keep it proportional to `n`.
            if cells.iter().product::<usize>() <= 8 * n + 64 {
                break;
            }
            h *= 2.0;
        }
        let mut grid = Self {
            d,
            lo,
            h,
            cells,
            start: Vec::new(),
            order: Vec::new(),
        };
        // Counting sort of the points by cell.
        let count = cells.iter().product::<usize>();
        let keys: Vec<usize> = (0..n)
            .map(|i| grid.flat_index(grid.cell_of(&points[i * d..(i + 1) * d])))
            .collect();
        let mut start = vec![0; count + 1];
        for &key in &keys {
            start[key + 1] += 1;
        }
        for c in 0..count {
            start[c + 1] += start[c];
        }
        let mut next = start.clone();
        let mut order = vec![0; n];
        for (i, &key) in keys.iter().enumerate() {
            order[next[key]] = i as u32;
            next[key] += 1;
        }
        grid.start = start;
        grid.order = order;
        grid
    }

    fn cell_of(&self, q: &[f64]) -> [usize; 3] {
        let mut c = [0; 3];
        for k in 0..self.d {
            let x = ((q[k] - self.lo[k]) / self.h).floor();
            c[k] = if x.is_nan() || x < 0.0 {
                0
            } else {
                (x as usize).min(self.cells[k] - 1)
            };
        }
        c
    }

    fn flat_index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.cells[1] + c[1]) * self.cells[0] + c[0]
    }

    /// Into `found`, the points of the cells within Chebyshev distance `r` of `q`'s cell, for the
    /// smallest `r ≥ 1` at which there are at least `k` (or all cells). Returns the distance from
    /// `q` to the nearest face of that block of cells with cells beyond it (infinite if none):
    /// every point closer to `q` than that is in `found`.
    fn nearby(&self, q: &[f64], k: usize, found: &mut Vec<u32>) -> f64 {
        found.clear();
        let c = self.cell_of(q);
        for r in 0.. {
            let mut bound = f64::INFINITY;
            let mut range = [(0, 0); 3];
            for dim in 0..3 {
                let first = c[dim].saturating_sub(r);
                let last = (c[dim] + r).min(self.cells[dim] - 1);
                range[dim] = (first, last);
                if dim < self.d {
                    let cell_lo = |index: usize| self.lo[dim] + index as f64 * self.h;
                    if first > 0 {
                        bound = bound.min(q[dim] - cell_lo(first));
                    }
                    if last + 1 < self.cells[dim] {
                        bound = bound.min(cell_lo(last + 1) - q[dim]);
                    }
                }
            }
            for z in range[2].0..=range[2].1 {
                for y in range[1].0..=range[1].1 {
                    for x in range[0].0..=range[0].1 {
                        let ring = x.abs_diff(c[0]).max(y.abs_diff(c[1])).max(z.abs_diff(c[2]));
                        if ring == r {
                            let cell = self.flat_index([x, y, z]);
                            found.extend_from_slice(
                                &self.order[self.start[cell]..self.start[cell + 1]],
                            );
                        }
                    }
                }
            }
            if (r >= 1 && found.len() >= k) || bound == f64::INFINITY {
                return bound.max(0.0);
            }
        }
        unreachable!("the rings cover the grid")
    }
}

/// `|x − y|²`, summed in the order of the coordinates (the same order wherever a cost is taken,
/// so that equal pairs give bitwise equal costs).
#[inline]
pub(super) fn squared_distance(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(p, q)| (p - q) * (p - q)).sum()
}

/// For every point of `queries` `[M·d]`, candidate partners among `points` `[N·d]` (row-major),
/// pushed to `out[query]`: for `d ≤ 3` the points in the smallest block of `3ᵈ`, `5ᵈ`, ... grid
/// cells around it that holds at least `k` (cells of ~`k/3ᵈ` points), for `d > 3` its `min(k, N)`
/// nearest.
pub(super) fn candidates(
    queries: &[f64],
    points: &[f64],
    d: usize,
    k: usize,
    out: &mut [Vec<u32>],
) {
    let n = points.len() / d;
    let k = k.clamp(1, n);
    if d <= 3 {
        let per_cell = (k as f64 / 3f64.powi(d as i32)).max(0.5);
        let grid = CellGrid::new(points, d, per_cell);
        let mut found = Vec::new();
        for (q, row) in queries.chunks_exact(d).zip(out) {
            grid.nearby(q, k, &mut found);
            row.extend_from_slice(&found);
        }
    } else {
        let mut found: Vec<(f64, u32)> = Vec::with_capacity(n);
        for (q, row) in queries.chunks_exact(d).zip(out) {
            found.clear();
            let all = points.chunks_exact(d).enumerate();
            found.extend(all.map(|(p, x)| (squared_distance(q, x), p as u32)));
            found.select_nth_unstable_by(k - 1, |x, y| x.0.total_cmp(&y.0));
            row.extend(found[..k].iter().map(|&(_, p)| p));
        }
    }
}

/// The indices of `a` `[N·d]` and of `b` `[M·d]` sorted along the Z-order (Morton) curve of a
/// `2^21`-per-axis lattice over their common bounding box (`⌊64 / d⌋` bits per axis above
/// three dimensions). Consecutive points of either order are close; pairing the two orders rank
/// by rank gives a perfect matching of nearby points.
pub(super) fn curve_orders(a: &[f64], b: &[f64], d: usize) -> (Vec<u32>, Vec<u32>) {
    let bits = (64 / d).min(21) as u32;
    let mut lo = vec![f64::INFINITY; d];
    let mut hi = vec![f64::NEG_INFINITY; d];
    for p in a.chunks_exact(d).chain(b.chunks_exact(d)) {
        for k in 0..d {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let top = ((1u64 << bits) - 1) as f64;
    let key = |p: &[f64]| -> u64 {
        let mut key = 0u64;
        for k in 0..d {
            let extent = hi[k] - lo[k];
            let x = if extent > 0.0 {
                (p[k] - lo[k]) / extent * top
            } else {
                0.0
            };
            key |= spread(x.clamp(0.0, top) as u64, bits, d) << k;
        }
        key
    };
    let sorted = |points: &[f64]| -> Vec<u32> {
        let mut keyed: Vec<(u64, u32)> = points
            .chunks_exact(d)
            .enumerate()
            .map(|(i, p)| (key(p), i as u32))
            .collect();
        keyed.sort_unstable();
        keyed.into_iter().map(|(_, i)| i).collect()
    };
    (sorted(a), sorted(b))
}

/// The low `bits` bits of `x` moved to every `d`-th bit (bit `t` to bit `t·d`).
fn spread(x: u64, bits: u32, d: usize) -> u64 {
    match d {
        1 => x,
        2 => {
            let mut x = x & 0xffff_ffff;
            x = (x | x << 16) & 0x0000_ffff_0000_ffff;
            x = (x | x << 8) & 0x00ff_00ff_00ff_00ff;
            x = (x | x << 4) & 0x0f0f_0f0f_0f0f_0f0f;
            x = (x | x << 2) & 0x3333_3333_3333_3333;
            (x | x << 1) & 0x5555_5555_5555_5555
        }
        3 => {
            let mut x = x & 0x1f_ffff;
            x = (x | x << 32) & 0x1f_0000_0000_ffff;
            x = (x | x << 16) & 0x1f_0000_ff00_00ff;
            x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
            x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
            (x | x << 2) & 0x1249_2492_4924_9249
        }
        _ => (0..bits).fold(0, |key, t| key | ((x >> t) & 1) << (t as usize * d)),
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    use super::*;

    /// A block of cells holds at least `min(k, N)` points, and every point closer to the query
    /// than the block's faces; above three dimensions the candidates are the `k` nearest. For
    /// clustered and spread sets in 1 to 4 dimensions and queries inside and outside the grid.
    #[test]
    fn candidates_hold_the_points_near_the_query() {
        let mut rng = StdRng::seed_from_u64(4);
        for d in 1..=4 {
            for (n, k) in [(1, 4), (5, 8), (200, 8), (300, 1), (257, 32)] {
                // Half the points in a tight cluster, half spread out: cells of very different
                // occupancy.
                let points: Vec<f64> = (0..n * d)
                    .map(|e| {
                        if e / d % 2 == 0 {
                            0.3 + 0.01 * rng.random::<f64>()
                        } else {
                            rng.random::<f64>()
                        }
                    })
                    .collect();
                let queries: Vec<f64> = (0..40 * d)
                    .map(|_| 3.0 * rng.random::<f64>() - 1.0)
                    .collect();
                let grid = (d <= 3)
                    .then(|| CellGrid::new(&points, d, (k as f64 / 3f64.powi(d as i32)).max(0.5)));
                let mut out = vec![Vec::new(); 40];
                candidates(&queries, &points, d, k, &mut out);
                for (q, row) in queries.chunks(d).zip(&out) {
                    let mut distances: Vec<f64> =
                        points.chunks(d).map(|x| squared_distance(q, x)).collect();
                    let within = match &grid {
                        Some(grid) => grid.nearby(q, k, &mut Vec::new()).powi(2),
                        None => {
                            let mut sorted = distances.clone();
                            sorted.sort_by(f64::total_cmp);
                            sorted[k.min(n) - 1]
                        }
                    };
                    assert!(row.len() >= k.min(n), "d = {d}, N = {n}, k = {k}");
                    let mut listed = vec![false; n];
                    for &p in row {
                        assert!(!listed[p as usize], "{p} listed twice");
                        listed[p as usize] = true;
                    }
                    for (p, s) in distances.iter_mut().enumerate() {
                        if *s < within {
                            assert!(listed[p], "d = {d}, N = {n}, k = {k}: point {p} missing");
                        }
                    }
                }
            }
        }
    }

    /// The bit spreading of the Z-order keys is the bit-by-bit definition, and the curve orders
    /// are permutations.
    #[test]
    fn curve_orders_are_permutations_along_the_z_order() {
        let mut rng = StdRng::seed_from_u64(8);
        for d in 1..=4 {
            let bits = (64 / d).min(21) as u32;
            for _ in 0..100 {
                let x = rng.random::<u64>() & ((1 << bits) - 1);
                let slow = (0..bits).fold(0, |key, t| key | ((x >> t) & 1) << (t as usize * d));
                assert_eq!(spread(x, bits, d), slow, "d = {d}, x = {x:#x}");
            }
            let a: Vec<f64> = (0..100 * d).map(|_| rng.random::<f64>()).collect();
            let b: Vec<f64> = (0..90 * d).map(|_| 5.0 * rng.random::<f64>()).collect();
            let (mut first, mut second) = curve_orders(&a, &b, d);
            first.sort_unstable();
            second.sort_unstable();
            assert_eq!(first, (0..100).collect::<Vec<_>>());
            assert_eq!(second, (0..90).collect::<Vec<_>>());
        }
    }
}
