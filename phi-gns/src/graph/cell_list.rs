//! A cell list of one example's particles: the spatial index behind [`super::RadiusGraph`].
//!
//! Space is cut into axis-aligned cells a little wider than the connectivity radius `R`, so two
//! particles within `R` of each other lie in the same or in adjacent cells (3^d cells around each
//! particle, itself included). Only occupied cells exist: a hash map from the packed integer
//! coordinates of a cell to a dense cell id, then a counting sort of the particles by cell id.
//! Building is O(N) expected time and O(N) memory whatever the spread of the positions; a grid
//! stored densely would need `(extent / R)^d` cells, which positions 1e9 apart with `R = 1e-6`
//! make impossible.
//!
//! # Why the cells are wider than `R`
//!
//! A cell coordinate is `floor((x − min) / c)`, computed in f64. Were `c` exactly `R`, rounding
//! could put two particles exactly `R` apart two cells apart and lose their edge. With
//! `c ≥ R (1 + 2⁻²⁰)` the exact coordinates of such particles differ by at most `1 − 2⁻²¹`, and the
//! rounding error of a coordinate below `2²¹` is about `2⁻³¹`, far below that margin. Coordinates
//! are kept below 2²⁰ by widening the cells of an axis whose extent spans more than 2²⁰ radii:
//! correctness is kept, only the cells of such sparse inputs hold more particles than needed.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Relative widening of a cell beyond the radius (see the module docs).
const CELL_MARGIN: f64 = 1.0 / (1u64 << 20) as f64;
/// Most cells along one axis; coordinates are `0..=MAX_CELLS_PER_AXIS`.
const MAX_CELLS_PER_AXIS: u64 = 1 << 20;
/// Bits per axis in a packed cell key: room for a coordinate and its `+1` neighbour.
const KEY_BITS: u32 = 21;

/// The particles of one example sorted by cell, with each cell's neighbouring cells.
pub(super) struct CellList<const D: usize> {
    /// Particle indices ordered by cell id, ascending within each cell.
    order: Vec<usize>,
    /// The positions in the order of `order`, so that a cell's particles are contiguous in memory.
    sorted_positions: Vec<[f32; D]>,
    /// Cell `c` holds `order[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<usize>,
    /// The cell id of each particle, by particle index.
    particle_cell: Vec<usize>,
    /// Cell `c`'s neighbours (itself included) are
    /// `neighbours[neighbour_start[c]..neighbour_start[c + 1]]`.
    neighbour_start: Vec<usize>,
    neighbours: Vec<usize>,
}

impl<const D: usize> CellList<D> {
    /// The cell list of `positions` (finite, checked by the caller) for cells of at least
    /// `radius` (finite, > 0).
    pub(super) fn new(positions: &[[f32; D]], radius: f64) -> Self {
        let (low, cell_size) = cell_geometry(positions, radius);
        let coordinates = |p: &[f32; D]| -> [u64; D] {
            std::array::from_fn(|a| {
                let q = ((f64::from(p[a]) - low[a]) / cell_size[a]).floor();
                // `q` is finite and ≥ 0 (x ≥ low); the bound only absorbs rounding at the top.
                (q as u64).min(MAX_CELLS_PER_AXIS)
            })
        };

        // Dense ids of occupied cells, numbered by first appearance in particle order.
        let mut cell_ids: HashMap<u64, usize, CellKeyHash> = HashMap::default();
        let mut cell_coordinates: Vec<[u64; D]> = Vec::new();
        let mut counts: Vec<usize> = Vec::new();
        let particle_cell: Vec<usize> = positions
            .iter()
            .map(|p| {
                let q = coordinates(p);
                let id = *cell_ids.entry(pack(&q)).or_insert_with(|| {
                    cell_coordinates.push(q);
                    counts.push(0);
                    counts.len() - 1
                });
                counts[id] += 1;
                id
            })
            .collect();

        // Counting sort by cell id; scanning particles in index order keeps each cell ascending.
        let mut cell_start = Vec::with_capacity(counts.len() + 1);
        cell_start.push(0);
        for &count in &counts {
            cell_start.push(cell_start[cell_start.len() - 1] + count);
        }
        let mut next = cell_start[..counts.len()].to_vec();
        let mut order = vec![0; positions.len()];
        for (particle, &cell) in particle_cell.iter().enumerate() {
            order[next[cell]] = particle;
            next[cell] += 1;
        }
        let sorted_positions = order.iter().map(|&i| positions[i]).collect();

        let mut neighbour_start = Vec::with_capacity(cell_coordinates.len() + 1);
        neighbour_start.push(0);
        let mut neighbours = Vec::new();
        for q in &cell_coordinates {
            for offset in 0..3usize.pow(D as u32) {
                if let Some(key) = neighbour_key(q, offset)
                    && let Some(&id) = cell_ids.get(&key)
                {
                    neighbours.push(id);
                }
            }
            neighbour_start.push(neighbours.len());
        }

        CellList {
            order,
            sorted_positions,
            cell_start,
            particle_cell,
            neighbour_start,
            neighbours,
        }
    }

    /// Appends to `senders` every particle within `radius` of particle `receiver` (itself
    /// included), in no particular order. `within(a, b)` is the distance test.
    pub(super) fn neighbours_of(
        &self,
        receiver: usize,
        position: &[f32; D],
        within: impl Fn(&[f32; D], &[f32; D]) -> bool,
        senders: &mut Vec<usize>,
    ) {
        let cell = self.particle_cell[receiver];
        for &other in &self.neighbours[self.neighbour_start[cell]..self.neighbour_start[cell + 1]] {
            let range = self.cell_start[other]..self.cell_start[other + 1];
            for (&sender, candidate) in self.order[range.clone()]
                .iter()
                .zip(&self.sorted_positions[range])
            {
                if within(candidate, position) {
                    senders.push(sender);
                }
            }
        }
    }
}

/// The lower corner of the positions and the cell size along each axis: `radius` widened by
/// [`CELL_MARGIN`], or more where the axis spans more than [`MAX_CELLS_PER_AXIS`] cells.
fn cell_geometry<const D: usize>(positions: &[[f32; D]], radius: f64) -> ([f64; D], [f64; D]) {
    let mut low = [f64::INFINITY; D];
    let mut high = [f64::NEG_INFINITY; D];
    for p in positions {
        for a in 0..D {
            low[a] = low[a].min(f64::from(p[a]));
            high[a] = high[a].max(f64::from(p[a]));
        }
    }
    let cell_size = std::array::from_fn(|a| {
        let extent = (high[a] - low[a]).max(0.0);
        (radius * (1.0 + CELL_MARGIN)).max(extent / (MAX_CELLS_PER_AXIS - 1) as f64)
    });
    (low, cell_size)
}

/// One integer key per cell: the coordinates side by side, [`KEY_BITS`] bits each.
fn pack<const D: usize>(q: &[u64; D]) -> u64 {
    q.iter()
        .enumerate()
        .fold(0, |key, (a, &c)| key | (c << (KEY_BITS * a as u32)))
}

/// The key of the neighbour of cell `q` at `offset` (in `0..3^D`, base-3 digits meaning −1, 0, +1
/// per axis), or `None` below coordinate 0.
fn neighbour_key<const D: usize>(q: &[u64; D], offset: usize) -> Option<u64> {
    let mut digits = offset;
    let mut neighbour = [0u64; D];
    for a in 0..D {
        let step = (digits % 3) as u64;
        digits /= 3;
        neighbour[a] = (q[a] + step).checked_sub(1)?;
    }
    Some(pack(&neighbour))
}

/// A fast hash of packed cell keys (a multiply and a shift); the keys are not adversarial and the
/// map's iteration order is never used, so the graph does not depend on the hash.
type CellKeyHash = BuildHasherDefault<CellKeyHasher>;

#[derive(Default)]
struct CellKeyHasher(u64);

impl Hasher for CellKeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, key: u64) {
        let x = (self.0 ^ key).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = x ^ (x >> 29);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbour_keys_cover_the_3_by_3_block_and_stop_at_zero() {
        let keys: Vec<u64> = (0..9).filter_map(|o| neighbour_key(&[0, 5], o)).collect();
        // x = 0 has no x − 1 neighbour: 2 × 3 cells remain.
        assert_eq!(keys.len(), 6);
        assert!(keys.contains(&pack(&[0, 5])));
        assert!(keys.contains(&pack(&[1, 6])));
        assert!(keys.contains(&pack(&[0, 4])));
    }

    #[test]
    fn wide_spreads_get_wider_cells_not_more_of_them() {
        let positions = [[-1.0e9f32, 0.0, 0.0], [1.0e9, 0.0, 1.0e-6]];
        let (_, cell_size) = cell_geometry(&positions, 1.0e-6);
        assert!(cell_size[0] >= 2.0e9 / (MAX_CELLS_PER_AXIS - 1) as f64);
        assert!(cell_size[1] > 1.0e-6 && cell_size[1] < 1.1e-6);
        let cells = CellList::new(&positions, 1.0e-6);
        assert_eq!(cells.cell_start.len(), 3);
    }
}
