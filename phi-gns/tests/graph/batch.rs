//! Batches with node offsets, the independence of the thread count, index tensors.

use phi_core::backend::Backend;
use phi_gns::graph::{ExamplePositions, RadiusGraph};

use crate::common::{Rng, pairs, points};

#[test]
fn a_batch_is_its_examples_side_by_side_with_node_offsets() {
    let mut rng = Rng::new(5);
    for dim in [2, 3] {
        let first = points(&mut rng, 120, dim, 0.0, 1.0);
        let second = points(&mut rng, 80, dim, -0.5, 0.5);
        let radius = 0.2;
        let batch = RadiusGraph::for_batch(
            &[
                ExamplePositions::new(&first, 120),
                ExamplePositions::new(&[], 0),
                ExamplePositions::new(&second, 80),
            ],
            dim,
            radius,
        )
        .unwrap();
        let a = RadiusGraph::for_positions(&first, dim, radius).unwrap();
        let b = RadiusGraph::for_positions(&second, dim, radius).unwrap();

        assert_eq!(batch.node_offsets(), &[0, 120, 120, 200]);
        assert_eq!(batch.edge_counts(), &[a.edges(), 0, b.edges()]);
        assert_eq!(batch.examples(), 3);
        assert_eq!(batch.nodes(), 200);
        let mut expected = pairs(&a);
        expected.extend(pairs(&b).into_iter().map(|(r, s)| (r + 120, s + 120)));
        assert_eq!(pairs(&batch), expected);
        assert_eq!(batch.example_edges(0), 0..a.edges());
        assert_eq!(batch.example_edges(1), a.edges()..a.edges());
        assert_eq!(batch.example_edges(2), a.edges()..a.edges() + b.edges());
    }
}

#[test]
fn the_edges_do_not_depend_on_the_thread_count() {
    let mut rng = Rng::new(17);
    let big = points(&mut rng, 6000, 3, 0.0, 1.0);
    let small = points(&mut rng, 700, 2, 0.0, 1.0);
    let small_too = points(&mut rng, 300, 2, 0.0, 1.0);
    let build = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let one = RadiusGraph::for_positions(&big, 3, 0.06).unwrap();
            let batch = RadiusGraph::for_batch(
                &[
                    ExamplePositions::new(&small, 700),
                    ExamplePositions::new(&small_too, 300),
                ],
                2,
                0.05,
            )
            .unwrap();
            (one, batch)
        })
    };
    let serial = build(1);
    assert!(
        serial.0.edges() > 6000 * 2,
        "a graph with many edges per node"
    );
    for threads in [2, 3, 8] {
        assert_eq!(build(threads), serial, "{threads} threads");
    }
}

fn assert_tensors_hold_the_edges<B: Backend>() {
    let mut rng = Rng::new(19);
    let positions = points(&mut rng, 60, 2, 0.0, 1.0);
    let graph = RadiusGraph::for_positions(&positions, 2, 0.2).unwrap();
    let (senders, receivers) = graph.to_tensors::<B>(&B::default_device()).unwrap();
    assert_eq!(senders.shape(), [graph.edges()]);
    assert_eq!(receivers.shape(), [graph.edges()]);
    assert_eq!(senders.to_vec(), graph.senders());
    assert_eq!(receivers.to_vec(), graph.receivers());

    let empty = RadiusGraph::for_positions(&[], 2, 0.2).unwrap();
    let (senders, receivers) = empty.to_tensors::<B>(&B::default_device()).unwrap();
    assert_eq!(senders.shape(), [0]);
    assert_eq!(receivers.shape(), [0]);
}

#[test]
fn index_tensors_hold_the_edges_on_ndarray() {
    assert_tensors_hold_the_edges::<phi_core::backend::ndarray::NdArray>();
}

#[test]
fn index_tensors_hold_the_edges_on_burn() {
    assert_tensors_hold_the_edges::<phi_core::backend::burn::Burn>();
}

#[cfg(feature = "tch")]
#[test]
fn index_tensors_hold_the_edges_on_tch() {
    assert_tensors_hold_the_edges::<phi_core::backend::tch::Tch>();
}
