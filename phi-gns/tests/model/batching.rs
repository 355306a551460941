//! Batches: examples concatenated by `GraphBatch::from_host_batch` give each example the
//! accelerations it has on its own, on every backend.
//!
//! The two examples occupy the same region of space, so a batch whose graph joined them (node
//! offsets missing, or one radius graph over the concatenated positions) would connect particles
//! of different examples and change the result by O(1). Within one backend a batch runs the same
//! per-row arithmetic as the examples alone; only the blocking of a matrix product over more rows
//! may change its summation order, so the tolerance is `1e-5` of the largest value (measured: 0
//! to 4e-7).

use phi_gns::model::{Gns, GnsKernels, GraphBatch, Parameters};

use crate::common::{self, Rng, assert_close, liquid_over_obstacles, perturbed};

phi_core::backend_tests!(a_batch_equals_its_examples_run_separately);

fn a_batch_equals_its_examples_run_separately<B: GnsKernels>() {
    let device = B::default_device();
    let spec = common::spec(common::config(16, 16, 2, 3), 31);
    let model = Gns::new(
        spec.clone(),
        perturbed(&Parameters::<B>::init(&spec.config, spec.seed, &device), 3),
    )
    .unwrap();
    let first = liquid_over_obstacles(&mut Rng::new(1), 4, 3, 3, [0.11, 0.125], 6);
    let second = liquid_over_obstacles(&mut Rng::new(2), 3, 3, 2, [0.115, 0.13], 6);
    let alone = |scene: &common::Scene| {
        let batch = GraphBatch::from_host(&scene.window, &scene.types, &spec, &device).unwrap();
        (
            batch.graph().edges(),
            model.normalised_acceleration(&batch).unwrap().to_vec(),
        )
    };
    let (edges_first, first_alone) = alone(&first);
    let (edges_second, second_alone) = alone(&second);
    let (n1, n2) = (first.particles(), second.particles());

    for order in [[&first, &second], [&second, &first]] {
        let examples: Vec<(&[f32], &[i64])> = order
            .iter()
            .map(|s| (s.window.as_slice(), s.types.as_slice()))
            .collect();
        let batch = GraphBatch::from_host_batch(&examples, &spec, &device).unwrap();
        let swapped = order[0].particles() != n1;
        let (expected_offsets, expected_edges) = if swapped {
            (vec![0, n2, n1 + n2], vec![edges_second, edges_first])
        } else {
            (vec![0, n1, n1 + n2], vec![edges_first, edges_second])
        };
        assert_eq!(batch.graph().node_offsets(), &expected_offsets[..]);
        assert_eq!(batch.graph().edge_counts(), &expected_edges[..]);
        let got = model.normalised_acceleration(&batch).unwrap().to_vec();
        assert_eq!(got.len(), 2 * (n1 + n2));
        let (a, b) = got.split_at(2 * order[0].particles());
        let (a_alone, b_alone) = if swapped {
            (&second_alone, &first_alone)
        } else {
            (&first_alone, &second_alone)
        };
        let as_f64 = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
        let what = format!("{} batch, swapped {swapped}", B::name());
        assert_close(
            a,
            &as_f64(a_alone),
            1e-5,
            &format!("{what}: its first example"),
        );
        assert_close(
            b,
            &as_f64(b_alone),
            1e-5,
            &format!("{what}: its second example"),
        );
    }

    // The two examples do overlap: one radius graph over both would have joined them.
    let mut latest: Vec<f32> = Vec::new();
    for scene in [&first, &second] {
        for particle in scene.window.chunks_exact(12) {
            latest.extend_from_slice(&particle[10..12]);
        }
    }
    let joined = phi_gns::graph::RadiusGraph::for_positions(&latest, 2, 0.03).unwrap();
    assert!(joined.edges() > edges_first + edges_second);
}
