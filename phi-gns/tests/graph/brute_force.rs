//! The cell list against the O(N²) definition on random and lattice point sets.

use crate::common::{Rng, assert_matches_brute_force, points};

#[test]
fn random_points_in_2d_and_3d_match_brute_force() {
    let mut rng = Rng::new(7);
    for dim in [2, 3] {
        for n in [2, 17, 300, 1500] {
            for radius in [0.03, 0.1, 0.35, 2.0] {
                let positions = points(&mut rng, n, dim, 0.0, 1.0);
                assert_matches_brute_force(&positions, dim, radius);
            }
        }
    }
}

#[test]
fn clustered_points_spanning_negative_coordinates_match_brute_force() {
    let mut rng = Rng::new(11);
    for dim in [2, 3] {
        // A dense blob, a sparse halo and a few far-away particles.
        let mut positions = points(&mut rng, 400, dim, -0.1, 0.1);
        positions.extend(points(&mut rng, 200, dim, -3.0, 2.0));
        positions.extend(points(&mut rng, 5, dim, -50.0, 80.0));
        assert_matches_brute_force(&positions, dim, 0.05);
    }
}

#[test]
fn lattices_with_spacing_equal_to_the_radius_keep_their_axis_neighbours() {
    // Points exactly R apart sit on cell boundaries, the case rounding would break first.
    for (dim, radius) in [(2, 0.25), (3, 0.125), (2, 0.03), (3, 0.03)] {
        let side: usize = 7;
        let n = side.pow(dim as u32);
        let mut positions = Vec::with_capacity(n * dim);
        for i in 0..n {
            let mut rest = i;
            for _ in 0..dim {
                let k = (rest % side) as f64 - 3.0;
                rest /= side;
                positions.push((0.5 + k * radius) as f32);
            }
        }
        let graph = assert_matches_brute_force(&positions, dim, radius);
        if radius == 0.25 || radius == 0.125 {
            // Exact spacing: self + 2·dim neighbours inside, fewer on the faces; diagonals are
            // R·√2 away. Each axis has side − 1 neighbour pairs per line, two edges each.
            let lines = side.pow(dim as u32 - 1);
            let expected = n + dim * lines * (side - 1) * 2;
            assert_eq!(graph.edges(), expected, "{dim}D lattice, R = {radius}");
        }
    }
}

#[test]
fn positions_spread_over_1e9_with_a_tiny_radius_match_brute_force() {
    let mut rng = Rng::new(13);
    for dim in [2, 3] {
        let mut positions = points(&mut rng, 300, dim, -1.0e9, 1.0e9);
        // A pair 1e-6 apart far from the origin, and a small cluster near it.
        positions.extend(vec![5.0e8; dim]);
        let mut near = vec![5.0e8f32; dim];
        near[0] = 5.0e8 + 32.0; // the next f32 values near 5e8 are 32 apart
        positions.extend(near);
        positions.extend(points(&mut rng, 50, dim, 0.0, 1.0e-3));
        let graph = assert_matches_brute_force(&positions, dim, 1.0e-4);
        assert!(graph.edges() > 352, "the cluster and the pair have edges");
        assert_matches_brute_force(&positions, dim, 32.0);
    }
}
