//! Helpers shared by the graph tests: random points and the O(N²) reference graph.

use phi_gns::graph::RadiusGraph;

/// A small deterministic generator (SplitMix64), so the tests need no dependency.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// `n × dim` values uniform in `[low, high)`, as f32.
    pub fn points(&mut self, n: usize, dim: usize, low: f64, high: f64) -> Vec<f32> {
        (0..n * dim)
            .map(|_| (low + (high - low) * self.uniform()) as f32)
            .collect()
    }
}

/// Every `(receiver, sender)` pair within `radius` (inclusive, distance in f64 as documented),
/// self-pairs included, sorted by receiver then sender: the graph by definition, in O(N²).
pub fn brute_force(positions: &[f32], dim: usize, radius: f64) -> Vec<(i64, i64)> {
    let n = positions.len() / dim;
    let mut pairs = Vec::new();
    for r in 0..n {
        for s in 0..n {
            let d2: f64 = (0..dim)
                .map(|a| {
                    let d = f64::from(positions[s * dim + a]) - f64::from(positions[r * dim + a]);
                    d * d
                })
                .sum();
            if d2 <= radius * radius {
                pairs.push((r as i64, s as i64));
            }
        }
    }
    pairs
}

/// The graph's edges as `(receiver, sender)` pairs, in the graph's order.
pub fn pairs(graph: &RadiusGraph) -> Vec<(i64, i64)> {
    graph
        .receivers()
        .iter()
        .copied()
        .zip(graph.senders().iter().copied())
        .collect()
}

/// Builds the graph of one example and checks it against [`brute_force`], order included.
pub fn assert_matches_brute_force(positions: &[f32], dim: usize, radius: f64) -> RadiusGraph {
    let graph = RadiusGraph::for_positions(positions, dim, radius).expect("radius graph");
    let expected = brute_force(positions, dim, radius);
    assert_eq!(
        pairs(&graph),
        expected,
        "{} particles in {dim}D, R = {radius}",
        positions.len() / dim
    );
    assert_eq!(graph.edge_counts(), &[expected.len()]);
    assert_eq!(graph.node_offsets(), &[0, positions.len() / dim]);
    graph
}
