//! Helpers shared by the graph tests: random points and the O(N²) reference graph.

use phi_gns::graph::RadiusGraph;

#[path = "../shared/rng.rs"]
mod rng;
pub use rng::Rng;

/// `n × dim` values uniform in `[low, high)` drawn from `rng`, as f32.
pub fn points(rng: &mut Rng, n: usize, dim: usize, low: f64, high: f64) -> Vec<f32> {
    (0..n * dim)
        .map(|_| (low + (high - low) * rng.uniform()) as f32)
        .collect()
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
