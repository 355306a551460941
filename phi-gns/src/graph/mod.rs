//! The radius graph of the Graph Network-based Simulator (thesis section 5.1; Sanchez-Gonzalez et
//! al. 2020; `connectivity_utils.py` of DeepMind's `learning_to_simulate`): every particle
//! receives an edge from each particle within the connectivity radius `R`, itself included.
//!
//! # Edges
//!
//! For each example of a batch, the edges are all ordered pairs (sender `s`, receiver `r`) of its
//! particles with `|p_s − p_r| ≤ R` (inclusive), the distance computed in f64 from the f32
//! positions: `Σ_a (f64(p_s,a) − f64(p_r,a))² ≤ R²`. Self-edges are included, as in DeepMind's
//! code, whose KD-tree query returns each particle's own index; the relation is symmetric, so
//! `(s, r)` is an edge exactly when `(r, s)` is.
//!
//! **Order.** Edges are sorted by receiver, then by sender, both ascending; the examples follow
//! each other in batch order with node indices offset by the particles of the examples before.
//! The incoming edges of a particle are therefore one contiguous run, so message passing, which
//! sums edge messages per receiver (a scatter-add by receiver), can also do it as a segment sum,
//! with the same summation order on every run, and the runs' starts are the row pointers of the
//! receivers' CSR adjacency. The order does not depend on the number of threads: each receiver's
//! senders are found and sorted independently and the pieces are concatenated in receiver order.
//!
//! # Algorithm
//!
//! A cell list on the host (`cell_list`): cells somewhat wider than `R`, only the occupied ones
//! stored (a hash map from cell coordinates to dense ids, then a counting sort of the particles
//! by cell), so building is O(N) expected time and memory whatever the spread of the positions;
//! each particle then tests the particles of the 3^d cells around its own. Examples and chunks
//! of receivers run in parallel on rayon's current thread pool.
//!
//! # Example
//!
//! ```
//! use phi_gns::graph::{ExamplePositions, RadiusGraph};
//! // Example 0: three particles on a line 0.5 apart; example 1: one particle. 2D, R = 0.5.
//! let first = [0.0, 0.0, 0.5, 0.0, 1.0, 0.0];
//! let second = [0.3, 0.3];
//! let graph = RadiusGraph::for_batch(
//!     &[ExamplePositions::new(&first, 3), ExamplePositions::new(&second, 1)],
//!     2,
//!     0.5,
//! )?;
//! // Sorted by receiver, then sender; example 1's particle is node 3.
//! assert_eq!(graph.receivers(), &[0, 0, 1, 1, 1, 2, 2, 3]);
//! assert_eq!(graph.senders(), &[0, 1, 0, 1, 2, 1, 2, 3]);
//! assert_eq!(graph.edge_counts(), &[7, 1]);
//! assert_eq!(graph.node_offsets(), &[0, 3, 4]);
//! # Ok::<(), phi_gns::graph::GraphError>(())
//! ```

mod cell_list;

use std::ops::Range;

use phi_core::{Backend, IntTensor, TensorError};
use rayon::prelude::*;

use cell_list::CellList;

/// Receivers handled by one parallel task: enough work per task to amortise its scheduling.
const RECEIVERS_PER_TASK: usize = 256;

/// Errors of [`crate::graph`]: each names the example (its index in the batch) and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// The connectivity radius is not a finite number above zero.
    #[error("radius graph: the connectivity radius must be finite and > 0, got {radius}")]
    InvalidRadius {
        /// The radius given.
        radius: f64,
    },
    /// The spatial dimension is not 2 or 3.
    #[error("radius graph: positions must be 2D or 3D, got dim = {dim}")]
    UnsupportedDimension {
        /// The dimension given.
        dim: usize,
    },
    /// An example's positions do not hold `particles × dim` values.
    #[error(
        "radius graph, example {example}: {len} position values for {particles} particles in \
         {dim}D (expected {particles} × {dim})"
    )]
    PositionLength {
        /// The example's index in the batch.
        example: usize,
        /// The length of its position slice.
        len: usize,
        /// The particle count given.
        particles: usize,
        /// The spatial dimension.
        dim: usize,
    },
    /// A position component is NaN or infinite.
    #[error(
        "radius graph, example {example}: particle {particle} has a non-finite position \
         component {value} on axis {axis}"
    )]
    NonFinitePosition {
        /// The example's index in the batch.
        example: usize,
        /// The particle's index within the example.
        particle: usize,
        /// The axis of the component.
        axis: usize,
        /// The component.
        value: f32,
    },
    /// Making the index tensors failed on the backend.
    #[error("radius graph: {0}")]
    Tensor(#[from] TensorError),
}

/// The positions of one example of a batch: `positions` is `[particles, dim]`, row-major, in the
/// units of the connectivity radius.
#[derive(Debug, Clone, Copy)]
pub struct ExamplePositions<'a> {
    /// `[particles, dim]`, row-major.
    pub positions: &'a [f32],
    /// The number of particles.
    pub particles: usize,
}

impl<'a> ExamplePositions<'a> {
    /// An example of `particles` particles at `positions` (`[particles, dim]`, row-major).
    pub fn new(positions: &'a [f32], particles: usize) -> Self {
        ExamplePositions {
            positions,
            particles,
        }
    }
}

/// The radius graph of a batch: edges of all examples, concatenated in batch order with node
/// indices offset per example (see the [module docs](self) for the edges and their order).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RadiusGraph {
    senders: Vec<i64>,
    receivers: Vec<i64>,
    node_offsets: Vec<usize>,
    edge_counts: Vec<usize>,
}

impl RadiusGraph {
    /// The radius graph of one example: `positions` is `[N, dim]`, row-major.
    ///
    /// # Errors
    /// As [`RadiusGraph::for_batch`]; a `positions` length that is not a multiple of `dim` is a
    /// [`GraphError::PositionLength`].
    pub fn for_positions(positions: &[f32], dim: usize, radius: f64) -> Result<Self, GraphError> {
        let particles = positions.len().checked_div(dim).unwrap_or(0);
        Self::for_batch(&[ExamplePositions::new(positions, particles)], dim, radius)
    }

    /// The radius graph of a batch of examples in `dim` dimensions (2 or 3) for the connectivity
    /// radius `radius` (in position units, inclusive).
    ///
    /// # Errors
    /// [`GraphError::InvalidRadius`] unless `radius` is finite and > 0,
    /// [`GraphError::UnsupportedDimension`] unless `dim` is 2 or 3,
    /// [`GraphError::PositionLength`] where an example's slice does not hold `particles × dim`
    /// values, [`GraphError::NonFinitePosition`] at the first NaN or infinite component.
    pub fn for_batch(
        examples: &[ExamplePositions<'_>],
        dim: usize,
        radius: f64,
    ) -> Result<Self, GraphError> {
        check_batch(examples, dim, radius)?;
        let mut node_offsets = Vec::with_capacity(examples.len() + 1);
        node_offsets.push(0);
        for e in examples {
            node_offsets.push(node_offsets[node_offsets.len() - 1] + e.particles);
        }
        let pieces: Vec<(Vec<i64>, Vec<i64>)> = examples
            .par_iter()
            .zip(&node_offsets[..examples.len()])
            .map(|(e, &offset)| match dim {
                2 => example_edges::<2>(e.positions, radius, offset),
                _ => example_edges::<3>(e.positions, radius, offset),
            })
            .collect();
        let edges = pieces.iter().map(|(s, _)| s.len()).sum();
        let mut graph = RadiusGraph {
            senders: Vec::with_capacity(edges),
            receivers: Vec::with_capacity(edges),
            node_offsets,
            edge_counts: Vec::with_capacity(examples.len()),
        };
        for (senders, receivers) in pieces {
            graph.edge_counts.push(senders.len());
            graph.senders.extend(senders);
            graph.receivers.extend(receivers);
        }
        Ok(graph)
    }

    /// The sender (source) node of each edge, `[E]`.
    pub fn senders(&self) -> &[i64] {
        &self.senders
    }

    /// The receiver (target) node of each edge, `[E]`; ascending.
    pub fn receivers(&self) -> &[i64] {
        &self.receivers
    }

    /// `[examples + 1]`: example `i`'s particles are nodes `node_offsets[i]..node_offsets[i + 1]`.
    pub fn node_offsets(&self) -> &[usize] {
        &self.node_offsets
    }

    /// The number of edges of each example, `[examples]` (DeepMind's `n_edge`).
    pub fn edge_counts(&self) -> &[usize] {
        &self.edge_counts
    }

    /// The edges of example `example`: a range into [`Self::senders`] and [`Self::receivers`].
    ///
    /// # Panics
    /// If `example` is not below [`Self::examples`] (an index, like a slice's).
    pub fn example_edges(&self, example: usize) -> Range<usize> {
        let start: usize = self.edge_counts[..example].iter().sum();
        start..start + self.edge_counts[example]
    }

    /// The number of examples in the batch.
    pub fn examples(&self) -> usize {
        self.edge_counts.len()
    }

    /// The number of nodes (particles) of all examples.
    pub fn nodes(&self) -> usize {
        self.node_offsets[self.node_offsets.len() - 1]
    }

    /// The number of edges of all examples.
    pub fn edges(&self) -> usize {
        self.senders.len()
    }

    /// The senders and receivers as index tensors, each `[E]`, on `device`: the indices that
    /// gather node features onto edges and scatter-add messages back to receivers.
    ///
    /// # Errors
    /// [`GraphError::Tensor`] if the backend refuses the data.
    pub fn to_tensors<B: Backend>(
        &self,
        device: &B::Device,
    ) -> Result<(IntTensor<B>, IntTensor<B>), GraphError> {
        let shape = [self.edges()];
        Ok((
            IntTensor::from_vec(self.senders.clone(), &shape, device)?,
            IntTensor::from_vec(self.receivers.clone(), &shape, device)?,
        ))
    }
}

/// How many other particles lie within `radius` of each particle (inclusive, as the edges of
/// [`RadiusGraph`], whose self-edge is left out): `positions` is `[N, dim]`, row-major. The
/// counts of [`RadiusGraph::for_positions`]'s receivers less one, found without storing the
/// edges, so memory stays O(N) whatever the radius.
///
/// # Errors
/// As [`RadiusGraph::for_positions`].
///
/// # Example
///
/// ```
/// // Three particles on a line 0.5 apart: the middle one has both others within R = 0.5.
/// let counts = phi_gns::graph::neighbour_counts(&[0.0, 0.0, 0.5, 0.0, 1.0, 0.0], 2, 0.5)?;
/// assert_eq!(counts, [1, 2, 1]);
/// # Ok::<(), phi_gns::graph::GraphError>(())
/// ```
pub fn neighbour_counts(
    positions: &[f32],
    dim: usize,
    radius: f64,
) -> Result<Vec<usize>, GraphError> {
    let particles = positions.len().checked_div(dim).unwrap_or(0);
    check_batch(&[ExamplePositions::new(positions, particles)], dim, radius)?;
    Ok(match dim {
        2 => example_neighbour_counts::<2>(positions, radius),
        _ => example_neighbour_counts::<3>(positions, radius),
    })
}

fn example_neighbour_counts<const D: usize>(positions: &[f32], radius: f64) -> Vec<usize> {
    let (positions, cells) = points_and_cells::<D>(positions, radius);
    let test = within::<D>(radius * radius);
    let mut counts = vec![0; positions.len()];
    counts
        .par_chunks_mut(RECEIVERS_PER_TASK)
        .enumerate()
        .for_each(|(task, counts)| {
            let first = task * RECEIVERS_PER_TASK;
            let mut found = Vec::new();
            for (i, count) in counts.iter_mut().enumerate() {
                found.clear();
                let r = first + i;
                cells.neighbours_of(r, &positions[r], &test, &mut found);
                // The particle itself is always within.
                *count = found.len() - 1;
            }
        });
    counts
}

/// The positions (`[N, D]`, row-major) as points, and their cell list for `radius`.
fn points_and_cells<const D: usize>(
    positions: &[f32],
    radius: f64,
) -> (Vec<[f32; D]>, CellList<D>) {
    let points: Vec<[f32; D]> = positions
        .chunks_exact(D)
        .map(|p| std::array::from_fn(|a| p[a]))
        .collect();
    let cells = CellList::new(&points, radius);
    (points, cells)
}

/// The distance test of the edges: `Σ_a (f64(a_a) − f64(b_a))² ≤ R²`.
fn within<const D: usize>(radius_squared: f64) -> impl Fn(&[f32; D], &[f32; D]) -> bool {
    move |a, b| {
        let mut d2 = 0.0;
        for k in 0..D {
            let d = f64::from(a[k]) - f64::from(b[k]);
            d2 += d * d;
        }
        d2 <= radius_squared
    }
}

/// Checks the radius (finite, > 0), the dimension (2 or 3) and every example.
fn check_batch(
    examples: &[ExamplePositions<'_>],
    dim: usize,
    radius: f64,
) -> Result<(), GraphError> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(GraphError::InvalidRadius { radius });
    }
    if dim != 2 && dim != 3 {
        return Err(GraphError::UnsupportedDimension { dim });
    }
    for (example, e) in examples.iter().enumerate() {
        check_example(example, e, dim)?;
    }
    Ok(())
}

/// Checks one example's length and that every component is finite.
fn check_example(example: usize, e: &ExamplePositions<'_>, dim: usize) -> Result<(), GraphError> {
    if e.particles.checked_mul(dim) != Some(e.positions.len()) {
        return Err(GraphError::PositionLength {
            example,
            len: e.positions.len(),
            particles: e.particles,
            dim,
        });
    }
    match e.positions.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(GraphError::NonFinitePosition {
            example,
            particle: i / dim,
            axis: i % dim,
            value: e.positions[i],
        }),
        None => Ok(()),
    }
}

/// The edges of one example (checked), node indices offset by `offset`, sorted by receiver then
/// sender: `(senders, receivers)`.
fn example_edges<const D: usize>(
    positions: &[f32],
    radius: f64,
    offset: usize,
) -> (Vec<i64>, Vec<i64>) {
    let (positions, cells) = points_and_cells::<D>(positions, radius);
    let within = within::<D>(radius * radius);
    // Node indices fit in i64: they count elements of slices, which never exceed isize::MAX.
    let node = |i: usize| (offset + i) as i64;
    let n = positions.len();
    let pieces: Vec<(Vec<i64>, Vec<i64>)> = (0..n.div_ceil(RECEIVERS_PER_TASK))
        .into_par_iter()
        .map(|task| {
            let first = task * RECEIVERS_PER_TASK;
            let mut senders = Vec::new();
            let mut receivers = Vec::new();
            let mut found = Vec::new();
            let last = (first + RECEIVERS_PER_TASK).min(n);
            for (r, position) in (first..last).zip(&positions[first..last]) {
                found.clear();
                cells.neighbours_of(r, position, &within, &mut found);
                found.sort_unstable();
                senders.extend(found.iter().map(|&s| node(s)));
                receivers.extend(std::iter::repeat_n(node(r), found.len()));
            }
            (senders, receivers)
        })
        .collect();
    let edges = pieces.iter().map(|(s, _)| s.len()).sum();
    let mut senders = Vec::with_capacity(edges);
    let mut receivers = Vec::with_capacity(edges);
    for (s, r) in pieces {
        senders.extend(s);
        receivers.extend(r);
    }
    (senders, receivers)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` points of `dim` components in `[-1, 2)` from a fixed linear congruential stream, with
    /// every fifth point a copy of the one before moved by exactly `radius` along axis 0.
    fn points(n: usize, dim: usize, radius: f32, seed: u64) -> Vec<f32> {
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 * 3.0 - 1.0
        };
        let mut p: Vec<f32> = (0..n * dim).map(|_| next()).collect();
        for i in (5..n).step_by(5) {
            let (before, this) = p.split_at_mut(i * dim);
            this[..dim].copy_from_slice(&before[(i - 1) * dim..]);
            this[0] += radius;
        }
        p
    }

    #[test]
    fn neighbour_counts_are_the_graphs_receiver_counts_less_the_self_edge() {
        for (dim, n, radius) in [(2, 700, 0.11), (3, 500, 0.3)] {
            let p = points(n, dim, radius as f32, 7 + dim as u64);
            let counts = neighbour_counts(&p, dim, radius).unwrap();
            let graph = RadiusGraph::for_positions(&p, dim, radius).unwrap();
            let mut expected = vec![0usize; n];
            for (&s, &r) in graph.senders().iter().zip(graph.receivers()) {
                expected[r as usize] += usize::from(s != r);
            }
            assert_eq!(counts, expected, "{dim}D");
            // Brute force, the same f64 test.
            for i in 0..n {
                let brute = (0..n)
                    .filter(|&j| {
                        let d2: f64 = (0..dim)
                            .map(|a| f64::from(p[i * dim + a]) - f64::from(p[j * dim + a]))
                            .map(|d| d * d)
                            .sum();
                        j != i && d2 <= radius * radius
                    })
                    .count();
                assert_eq!(counts[i], brute, "{dim}D particle {i}");
            }
            assert!(
                counts.iter().any(|&c| c > 1),
                "{dim}D: the test needs neighbours"
            );
        }
    }

    #[test]
    fn neighbour_counts_check_their_input() {
        assert!(matches!(
            neighbour_counts(&[0.0, 0.0], 2, 0.0),
            Err(GraphError::InvalidRadius { .. })
        ));
        assert!(matches!(
            neighbour_counts(&[0.0; 4], 4, 1.0),
            Err(GraphError::UnsupportedDimension { dim: 4 })
        ));
        assert!(matches!(
            neighbour_counts(&[0.0, 0.0, 1.0], 2, 1.0),
            Err(GraphError::PositionLength { .. })
        ));
        assert!(matches!(
            neighbour_counts(&[0.0, f32::NAN], 2, 1.0),
            Err(GraphError::NonFinitePosition {
                particle: 0,
                axis: 1,
                ..
            })
        ));
        assert_eq!(neighbour_counts(&[], 3, 1.0).unwrap(), Vec::<usize>::new());
    }
}
