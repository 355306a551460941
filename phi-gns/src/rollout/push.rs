//! Pushing predicted positions out of obstacle cells ([`Obstacles::Push`]).
//!
//! The solid is the union of the cells around the kinematic particles: squares (cubes in 3D) of
//! side `cell` centred on each of them. A particle is pushed only when it enters a solid cell it
//! was not in at the previous frame, so liquid that the ground truth put inside the outer part
//! of an obstacle cell (the obstacle's surface can lie anywhere within a cell of its particle)
//! stays where it is and gets no velocity it did not have. An entering particle goes back to
//! the face it entered through (along the axis on which its previous position lay furthest
//! outside the cell); when that point is solid too, it leaves along one axis to the nearest
//! face whose far side is free, crossing solid cells up to [`MAX_CELLS`] of them, the shortest
//! of the `2 × dim` ways out that stays inside the domain's bounds. A particle with no way out
//! stays where it is.
//!
//! [`Obstacles::Push`]: crate::model::Obstacles::Push

use std::collections::HashMap;

/// The most solid cells a push crosses along one axis.
pub(crate) const MAX_CELLS: usize = 16;

/// How far beyond a face a pushed particle lands, as a fraction of the cell: enough for the
/// cell of the landing point (`floor`) to be the free one.
const MARGIN: f32 = 1e-3;

/// The solid cells of one frame: the kinematic particles' positions hashed by cell.
pub(crate) struct SolidCells<'a> {
    dim: usize,
    cell: f32,
    /// Half the side of a cell.
    half: f32,
    centres: &'a [f32],
    buckets: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> SolidCells<'a> {
    /// The cells of side `cell` around the particles of `positions` (`[N, dim]` row-major) where
    /// `solid` is true.
    pub(crate) fn new(positions: &'a [f32], solid: &[bool], dim: usize, cell: f32) -> Self {
        let mut buckets: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, _) in solid.iter().enumerate().filter(|(_, s)| **s) {
            let key = bucket(&positions[i * dim..(i + 1) * dim], cell);
            buckets.entry(key).or_default().push(i);
        }
        SolidCells {
            dim,
            cell,
            half: 0.5 * cell,
            centres: positions,
            buckets,
        }
    }

    /// The centre of the solid cell `j`.
    fn centre(&self, j: usize) -> &[f32] {
        &self.centres[j * self.dim..(j + 1) * self.dim]
    }

    /// A solid cell that contains `p` (strictly inside), if any: its particle's index.
    fn containing(&self, p: &[f32]) -> Option<usize> {
        let half = self.half;
        let home = bucket(p, self.cell);
        let mut offset = [0i64; 3];
        // The 3^dim buckets around p's own hold every centre within half a cell of it.
        for code in 0..3usize.pow(self.dim as u32) {
            let mut c = code;
            for o in offset.iter_mut().take(self.dim) {
                *o = (c % 3) as i64 - 1;
                c /= 3;
            }
            let key = [
                home[0] + offset[0],
                home[1] + offset[1],
                home[2] + offset[2],
            ];
            let Some(members) = self.buckets.get(&key) else {
                continue;
            };
            if let Some(&j) = members.iter().find(|&&j| {
                p.iter()
                    .zip(self.centre(j))
                    .all(|(a, b)| (a - b).abs() < half)
            }) {
                return Some(j);
            }
        }
        None
    }

    /// Where a particle that moved from `previous` to `p` goes: `None` when it stays (outside
    /// every solid cell, inside the one it was in before, or with no way out within `bounds`,
    /// `[min, max]` per axis).
    pub(crate) fn pushed(
        &self,
        previous: &[f32],
        p: &[f32],
        bounds: &[[f64; 2]],
    ) -> Option<Vec<f32>> {
        let entered = self.containing(p)?;
        let before = self.containing(previous);
        if before == Some(entered) {
            return None;
        }
        let reach = self.half + MARGIN * self.cell;
        let centre = self.centre(entered);
        // The entry face: the axis on which `previous` lies furthest outside the cell's slab.
        let axis = (0..self.dim)
            .max_by(|&a, &b| {
                let out = |k: usize| (previous[k] - centre[k]).abs();
                out(a).total_cmp(&out(b))
            })
            .unwrap_or(0);
        let mut back = p.to_vec();
        let side = if previous[axis] < centre[axis] {
            -1.0
        } else {
            1.0
        };
        back[axis] = centre[axis] + side * reach;
        let inside = |x: &[f32]| {
            x.iter()
                .zip(bounds)
                .all(|(v, [lo, hi])| (*lo..=*hi).contains(&f64::from(*v)))
        };
        if inside(&back) && self.containing(&back).is_none_or(|j| Some(j) == before) {
            return Some(back);
        }
        self.way_out(entered, p, bounds)
    }

    /// The nearest point outside the solid from `p`, inside solid cell `first`, along one axis.
    fn way_out(&self, first: usize, p: &[f32], bounds: &[[f64; 2]]) -> Option<Vec<f32>> {
        let reach = self.half + MARGIN * self.cell;
        let mut best: Option<(f32, Vec<f32>)> = None;
        for axis in 0..self.dim {
            for sign in [-1.0f32, 1.0] {
                let mut x = p.to_vec();
                let mut centre = first;
                for _ in 0..MAX_CELLS {
                    x[axis] = self.centre(centre)[axis] + sign * reach;
                    let [lo, hi] = bounds[axis];
                    if !(lo..=hi).contains(&f64::from(x[axis])) {
                        break;
                    }
                    match self.containing(&x) {
                        Some(next) => centre = next,
                        None => {
                            let distance = (x[axis] - p[axis]).abs();
                            if best.as_ref().is_none_or(|(d, _)| distance < *d) {
                                best = Some((distance, x));
                            }
                            break;
                        }
                    }
                }
            }
        }
        best.map(|(_, x)| x)
    }
}

/// The bucket (cell of side `cell` from the origin) of a point, padded to three axes.
fn bucket(p: &[f32], cell: f32) -> [i64; 3] {
    let mut key = [0i64; 3];
    for (k, x) in key.iter_mut().zip(p) {
        *k = (x / cell).floor() as i64;
    }
    key
}

/// Pushes the particles of `positions` (`[N, dim]` row-major) where `moves` is true out of the
/// cells around those where `solid` is true that they entered since `previous` (the frame
/// before, `[N, dim]`; [`SolidCells::pushed`]); returns which moved.
pub(crate) fn push_out(
    positions: &mut [f32],
    previous: &[f32],
    moves: &[bool],
    solid: &[bool],
    dim: usize,
    cell: f32,
    bounds: &[[f64; 2]],
) -> Vec<bool> {
    let pushed: Vec<(usize, Vec<f32>)> = {
        let cells = SolidCells::new(positions, solid, dim, cell);
        moves
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .filter_map(|(i, _)| {
                let row = i * dim..(i + 1) * dim;
                cells
                    .pushed(&previous[row.clone()], &positions[row], bounds)
                    .map(|x| (i, x))
            })
            .collect()
    };
    let mut moved = vec![false; moves.len()];
    for (i, x) in pushed {
        positions[i * dim..(i + 1) * dim].copy_from_slice(&x);
        moved[i] = true;
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;

    const CELL: f32 = 0.1;
    const BOUNDS: [[f64; 2]; 2] = [[0.0, 1.0], [0.0, 1.0]];

    /// Where a liquid particle that moved from `previous` to `p` ends, among obstacle particles
    /// at the centres of the cells `(i, j)`; `None` when it is not moved.
    fn push(cells: &[(i32, i32)], previous: [f32; 2], p: [f32; 2]) -> Option<[f32; 2]> {
        let centres = cells
            .iter()
            .flat_map(|&(i, j)| [(i as f32 + 0.5) * CELL, (j as f32 + 0.5) * CELL]);
        let mut positions: Vec<f32> = centres.clone().chain(p).collect();
        let before: Vec<f32> = centres.chain(previous).collect();
        let mut solid = vec![true; cells.len()];
        solid.push(false);
        let moves: Vec<bool> = solid.iter().map(|s| !s).collect();
        let moved = push_out(&mut positions, &before, &moves, &solid, 2, CELL, &BOUNDS);
        assert!(
            moved[..cells.len()].iter().all(|m| !m),
            "obstacles never move"
        );
        let n = cells.len();
        moved[n].then(|| [positions[2 * n], positions[2 * n + 1]])
    }

    fn cell_of(x: f32) -> i32 {
        (x / CELL).floor() as i32
    }

    #[test]
    fn a_particle_entering_a_cell_goes_back_to_the_face_it_came_through() {
        // From the left into cell (4, 4) (x 0.4 to 0.5): back just left of x = 0.4.
        let out = push(&[(4, 4)], [0.38, 0.43], [0.42, 0.43]).expect("entered, so pushed");
        assert!(out[0] < 0.4 && out[0] > 0.399, "{out:?}");
        assert_eq!(out[1], 0.43);
        // From above, nearer its right face than its top: still back out of the top.
        let out = push(&[(4, 4)], [0.47, 0.52], [0.49, 0.46]).expect("entered");
        assert_eq!(out[0], 0.49);
        assert_eq!((cell_of(out[0]), cell_of(out[1])), (4, 5));
    }

    #[test]
    fn a_thin_wall_is_not_crossed_by_a_particle_that_lands_past_its_middle() {
        // A wall one cell thick (x 0.4 to 0.5) the whole height of the domain; the particle
        // lands 0.02 from its far face: back to the near side, where it came from.
        let wall: Vec<(i32, i32)> = (0..=9).map(|j| (4, j)).collect();
        let out = push(&wall, [0.37, 0.55], [0.48, 0.55]).expect("entered");
        assert_eq!((cell_of(out[0]), cell_of(out[1])), (3, 5));
        assert!((out[0] - 0.4).abs() < 1e-3);
    }

    #[test]
    fn a_particle_that_was_inside_or_stays_outside_is_left_alone() {
        // Inside the cell at both frames: liquid the truth put there keeps its motion.
        assert_eq!(push(&[(4, 4)], [0.41, 0.43], [0.42, 0.44]), None);
        // Outside at the second frame.
        assert_eq!(push(&[(4, 4)], [0.48, 0.45], [0.52, 0.45]), None);
        assert_eq!(push(&[(4, 4), (5, 4)], [0.55, 0.41], [0.55, 0.39]), None);
    }

    #[test]
    fn moving_deeper_from_one_solid_cell_into_the_next_goes_back_to_the_first() {
        // Resting inside cell (3, 4), it moves into cell (4, 4): it goes back across their
        // shared face, into the cell it was in.
        let out = push(&[(3, 4), (4, 4)], [0.38, 0.45], [0.42, 0.45]).expect("entered");
        assert_eq!((cell_of(out[0]), cell_of(out[1])), (3, 4));
    }

    #[test]
    fn when_the_way_back_is_solid_it_leaves_by_the_nearest_free_face() {
        // From x = 0.28 it jumped over cell (3, 4) into (4, 4): the face it came through leads
        // into (3, 4), so it leaves through the nearest face with a free side: the top (0.04).
        let out = push(&[(3, 4), (4, 4)], [0.28, 0.45], [0.42, 0.46]).expect("entered");
        assert_eq!(out[0], 0.42);
        assert_eq!(cell_of(out[1]), 5);
        assert!((out[1] - 0.5).abs() < 1e-3);
    }

    #[test]
    fn the_bounds_close_a_way_out() {
        // A column of three cells against the left bound; the particle comes from above into
        // the middle one, whose top face leads into the top cell: of the ways left, x < 0 is
        // outside the domain, so it leaves to the right (0.09) rather than up or down (0.15).
        let out = push(&[(0, 3), (0, 4), (0, 5)], [0.01, 0.62], [0.01, 0.45]).expect("entered");
        assert_eq!((cell_of(out[0]), cell_of(out[1])), (1, 4));
        assert!(out[0] >= 0.0);
    }

    #[test]
    fn moving_obstacle_particles_carry_their_cells() {
        // An obstacle particle off the grid, at (0.43, 0.47): its cell spans 0.38–0.48 in x.
        let (mut positions, solid) = (vec![0.43, 0.47, 0.475, 0.47], vec![true, false]);
        let before = [0.43, 0.47, 0.49, 0.47];
        let moved = push_out(
            &mut positions,
            &before,
            &[false, true],
            &solid,
            2,
            CELL,
            &BOUNDS,
        );
        assert_eq!(moved, [false, true]);
        assert!(positions[2] > 0.48 && positions[2] < 0.481, "{positions:?}");
    }

    #[test]
    fn it_works_in_three_dimensions() {
        let bounds = [[0.0, 1.0]; 3];
        // Into the cube around (0.45, 0.45, 0.45) through its z = 0.4 face.
        let mut positions = vec![0.45, 0.45, 0.45, 0.46, 0.44, 0.405];
        let before = [0.45, 0.45, 0.45, 0.46, 0.44, 0.39];
        let moved = push_out(
            &mut positions,
            &before,
            &[false, true],
            &[true, false],
            3,
            CELL,
            &bounds,
        );
        assert_eq!(moved, [false, true]);
        assert_eq!(&positions[3..5], &[0.46, 0.44]);
        assert!(positions[5] < 0.4 && positions[5] > 0.399, "{positions:?}");
    }
}
