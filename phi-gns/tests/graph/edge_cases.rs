//! Distances exactly at the radius, tiny examples, self-edges.

use phi_gns::graph::RadiusGraph;

use crate::common::{assert_matches_brute_force, pairs};

/// The smallest f32 above `x`.
fn next_up(x: f32) -> f32 {
    f32::from_bits(x.to_bits() + 1)
}

#[test]
fn a_pair_exactly_r_apart_is_an_edge_and_the_next_float_is_not() {
    let at_radius = RadiusGraph::for_positions(&[0.0, 0.0, 0.5, 0.0], 2, 0.5).unwrap();
    assert_eq!(pairs(&at_radius), [(0, 0), (0, 1), (1, 0), (1, 1)]);
    let beyond = RadiusGraph::for_positions(&[0.0, 0.0, next_up(0.5), 0.0], 2, 0.5).unwrap();
    assert_eq!(pairs(&beyond), [(0, 0), (1, 1)]);

    // 3D, along the last axis, on negative coordinates straddling zero.
    let at_radius = RadiusGraph::for_positions(&[1.0, -2.0, -0.25, 1.0, -2.0, 0.25], 3, 0.5);
    assert_eq!(at_radius.unwrap().edges(), 4);
    let beyond = [1.0, -2.0, -0.25, 1.0, -2.0, next_up(0.25)];
    assert_eq!(
        RadiusGraph::for_positions(&beyond, 3, 0.5).unwrap().edges(),
        2
    );
}

#[test]
fn particles_on_the_bounds_and_at_negative_coordinates_match_brute_force() {
    // DeepMind's bounds [0.1, 0.9]² with particles on the walls and corners, and the same set
    // shifted to negative coordinates.
    let mut positions = Vec::new();
    for &x in &[0.1f32, 0.13, 0.5, 0.87, 0.9] {
        for &y in &[0.1f32, 0.12, 0.9] {
            positions.extend([x, y]);
        }
    }
    for radius in [0.03, 0.015, 0.8] {
        assert_matches_brute_force(&positions, 2, radius);
        let shifted: Vec<f32> = positions.iter().map(|x| x - 1.0).collect();
        assert_matches_brute_force(&shifted, 2, radius);
    }
}

#[test]
fn coincident_particles_are_all_connected() {
    let positions = [0.3f32, -0.7, 0.1].repeat(4);
    let graph = assert_matches_brute_force(&positions, 3, 0.01);
    assert_eq!(graph.edges(), 16);
}

#[test]
fn one_particle_has_one_self_edge() {
    for (positions, dim) in [(vec![0.4f32, 0.6], 2), (vec![-1.0, 0.0, 3.0], 3)] {
        let graph = RadiusGraph::for_positions(&positions, dim, 0.03).unwrap();
        assert_eq!(pairs(&graph), [(0, 0)]);
        assert_eq!(graph.nodes(), 1);
    }
}

#[test]
fn no_particles_have_no_edges() {
    for dim in [2, 3] {
        let graph = RadiusGraph::for_positions(&[], dim, 0.03).unwrap();
        assert_eq!(graph.edges(), 0);
        assert_eq!(graph.nodes(), 0);
        assert_eq!(graph.edge_counts(), &[0]);
        assert_eq!(graph.node_offsets(), &[0, 0]);
    }
    let empty_batch = RadiusGraph::for_batch(&[], 2, 0.03).unwrap();
    assert_eq!(empty_batch.examples(), 0);
    assert_eq!(empty_batch.nodes(), 0);
    assert_eq!(empty_batch.edges(), 0);
}

#[test]
fn every_edge_has_its_reverse_and_each_particle_its_self_edge() {
    let mut rng = crate::common::Rng::new(3);
    let positions = crate::common::points(&mut rng, 500, 3, 0.0, 1.0);
    let graph = RadiusGraph::for_positions(&positions, 3, 0.12).unwrap();
    let edges: std::collections::HashSet<(i64, i64)> = pairs(&graph).into_iter().collect();
    assert!(edges.iter().all(|&(r, s)| edges.contains(&(s, r))));
    assert!((0..500).all(|i| edges.contains(&(i, i))));
}
