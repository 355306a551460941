//! Bad input is an error naming the example and what is wrong, never a panic.

use phi_gns::graph::{ExamplePositions, GraphError, RadiusGraph};

#[test]
fn a_radius_that_is_not_finite_and_positive_is_an_error() {
    for radius in [0.0, -0.03, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let err = RadiusGraph::for_positions(&[0.0, 0.0], 2, radius).unwrap_err();
        assert!(
            matches!(err, GraphError::InvalidRadius { .. }),
            "{radius}: {err}"
        );
        assert!(err.to_string().contains("connectivity radius"), "{err}");
    }
}

#[test]
fn a_dimension_other_than_2_or_3_is_an_error() {
    for dim in [0, 1, 4] {
        let err = RadiusGraph::for_positions(&[0.0; 12], dim, 0.1).unwrap_err();
        assert!(
            matches!(err, GraphError::UnsupportedDimension { dim: d } if d == dim),
            "{err}"
        );
    }
}

#[test]
fn a_position_length_that_does_not_match_the_particle_count_is_an_error() {
    let positions = [0.0f32; 7];
    let err = RadiusGraph::for_batch(
        &[
            ExamplePositions::new(&positions[..6], 3),
            ExamplePositions::new(&positions, 3),
        ],
        2,
        0.1,
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            GraphError::PositionLength {
                example: 1,
                len: 7,
                particles: 3,
                dim: 2
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("example 1"), "{err}");

    let err = RadiusGraph::for_positions(&positions, 3, 0.1).unwrap_err();
    assert!(
        matches!(err, GraphError::PositionLength { len: 7, .. }),
        "{err}"
    );

    let err = RadiusGraph::for_batch(&[ExamplePositions::new(&[], usize::MAX)], 3, 0.1);
    assert!(matches!(err, Err(GraphError::PositionLength { .. })));
}

#[test]
fn a_non_finite_position_is_an_error_naming_particle_and_axis() {
    for value in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut positions = vec![0.5f32; 3 * 4];
        positions[2 * 3 + 1] = value;
        let err = RadiusGraph::for_batch(
            &[
                ExamplePositions::new(&[0.1, 0.2, 0.3], 1),
                ExamplePositions::new(&positions, 4),
            ],
            3,
            0.1,
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                GraphError::NonFinitePosition {
                    example: 1,
                    particle: 2,
                    axis: 1,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("particle 2"), "{err}");
    }
}
