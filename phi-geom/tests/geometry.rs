//! Integration tests of phi-geom: exact signed distances and masks, `push`, gradients through
//! `push` (Burn) against finite differences, rasterisation, and the scene-file (TOML) form.

use phi_core::Tensor;
use phi_core::backend::burn::Burn;
use phi_core::backend::ndarray::NdArray;
use phi_core::fields::Domain;
use phi_geom::{AxisBox, GeomError, Geometry, Obstacle, PushDirection, Rotation, Sphere};

type Nd = NdArray;

/// `[N, d]` points on the ndarray backend from row-major values.
fn points(values: &[f32], d: usize) -> Tensor<Nd> {
    Tensor::from_slice(values, &[values.len() / d, d], &Default::default()).unwrap()
}

/// `n` uniform random points in `[low, high)^d`.
fn random_points(n: usize, d: usize, low: f32, high: f32, seed: u64) -> Tensor<Nd> {
    Tensor::random_uniform(&[n, d], low, high, seed, &Default::default())
}

fn assert_close(got: &[f32], want: &[f32], tol: f32) {
    assert_eq!(got.len(), want.len(), "lengths differ: {got:?} vs {want:?}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tol,
            "element {i}: got {g}, want {w} (tolerance {tol})\n{got:?}"
        );
    }
}

/// The rows of a host `[N, d]` buffer.
fn rows(values: &[f32], d: usize) -> Vec<&[f32]> {
    values.chunks(d).collect()
}

fn distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f32>()
        .sqrt()
}

mod signed_distance {
    use super::*;

    #[test]
    fn box_distances_are_exact() {
        let b = Geometry::boxed([0.0, 0.0], [2.0, 1.0]).unwrap();
        let p = points(
            &[
                1.0, 0.5, 1.0, 0.8, 0.1, 0.5, 3.0, 0.5, 3.0, 2.0, 0.0, 0.0, -1.0, -1.0, 1.0, -0.25,
            ],
            2,
        );
        let sdf = b.approximate_signed_distance(&p).unwrap();
        assert_eq!(sdf.shape(), vec![8]);
        let s2 = 2f32.sqrt();
        assert_close(
            &sdf.to_vec(),
            &[-0.5, -0.2, -0.1, 1.0, s2, 0.0, s2, 0.25],
            1e-6,
        );
    }

    #[test]
    fn sphere_distances_are_exact() {
        let s = Geometry::sphere([1.0, 1.0], 2.0).unwrap();
        let p = points(&[1.0, 1.0, 4.0, 1.0, 4.0, 5.0, 1.0, 2.5, 1.0, -1.0], 2);
        let sdf = s.approximate_signed_distance(&p).unwrap().to_vec();
        assert_close(&sdf, &[-2.0, 1.0, 3.0, -0.5, 0.0], 1e-6);
        let ball = Geometry::sphere([0.0, 0.0, 1.0], 1.5).unwrap();
        let p = points(&[0.0, 0.0, 1.0, 2.0, 3.0, 7.0, 0.0, 0.5, 1.0], 3);
        assert_close(
            &ball.approximate_signed_distance(&p).unwrap().to_vec(),
            &[-1.5, 5.5, -1.0],
            1e-6,
        );
    }

    #[test]
    fn box_distances_in_3d() {
        let b = Geometry::boxed([0.0, 0.0, 0.0], [4.0, 2.0, 6.0]).unwrap();
        let p = points(
            &[2.0, 1.0, 3.0, 2.0, 1.9, 3.0, 5.0, 4.0, 8.0, 2.0, 1.0, 7.0],
            3,
        );
        let sdf = b.approximate_signed_distance(&p).unwrap().to_vec();
        assert_close(&sdf, &[-1.0, -0.1, 3.0, 1.0], 1e-6);
    }

    #[test]
    fn rotation_preserves_distances() {
        // A box rotated by 30° about its centre, against the unrotated box at points turned back.
        let square = Geometry::boxed([1.0, 2.0], [5.0, 3.0]).unwrap();
        let rotation = Rotation::degrees(30.0);
        let rotated = square.clone().rotated(rotation.clone()).unwrap();
        let p = random_points(500, 2, -2.0, 8.0, 1);
        let pivot = [3.0f32, 2.5];
        let back: Vec<f32> = rows(&p.to_vec(), 2)
            .into_iter()
            .flat_map(|x| {
                let rel = [x[0] - pivot[0], x[1] - pivot[1]];
                let local = rotation.inverse().apply(&rel);
                vec![local[0] + pivot[0], local[1] + pivot[1]]
            })
            .collect();
        let want = square
            .approximate_signed_distance(&points(&back, 2))
            .unwrap()
            .to_vec();
        let got = rotated.approximate_signed_distance(&p).unwrap().to_vec();
        assert_close(&got, &want, 1e-5);
    }

    #[test]
    fn union_is_the_minimum_and_inversion_flips_the_sign() {
        let a = Geometry::boxed([0.0, 0.0], [2.0, 2.0]).unwrap();
        let b = Geometry::sphere([5.0, 1.0], 1.0).unwrap();
        let u = Geometry::union(vec![a.clone(), b.clone()]).unwrap();
        let p = random_points(300, 2, -3.0, 9.0, 2);
        let (da, db) = (
            a.approximate_signed_distance(&p).unwrap().to_vec(),
            b.approximate_signed_distance(&p).unwrap().to_vec(),
        );
        let want: Vec<f32> = da.iter().zip(&db).map(|(x, y)| x.min(*y)).collect();
        assert_close(
            &u.approximate_signed_distance(&p).unwrap().to_vec(),
            &want,
            0.0,
        );
        let inv: Vec<f32> = u
            .clone()
            .inverted()
            .approximate_signed_distance(&p)
            .unwrap()
            .to_vec();
        let neg: Vec<f32> = want.iter().map(|v| -v).collect();
        assert_close(&inv, &neg, 0.0);
        // Outside the union it is the exact distance: (3.5, 1) is 1.5 from the box, 0.5 from the ball.
        assert_close(
            &u.approximate_signed_distance(&points(&[3.5, 1.0], 2))
                .unwrap()
                .to_vec(),
            &[0.5],
            1e-6,
        );
    }

    #[test]
    fn sign_agrees_with_the_inside_mask() {
        let shapes = vec![
            Geometry::boxed([1.0, 1.0], [4.0, 3.0])
                .unwrap()
                .rotated(Rotation::degrees(20.0))
                .unwrap(),
            Geometry::union(vec![
                Geometry::sphere([2.0, 2.0], 1.5).unwrap(),
                Geometry::boxed([2.0, 0.0], [6.0, 1.0]).unwrap(),
            ])
            .unwrap(),
            Geometry::sphere([3.0, 3.0], 2.0).unwrap().inverted(),
        ];
        let p = random_points(2000, 2, -1.0, 7.0, 3);
        for g in shapes {
            let inside = g.lies_inside(&p).unwrap().to_vec();
            let sdf = g.approximate_signed_distance(&p).unwrap().to_vec();
            for (m, s) in inside.iter().zip(&sdf) {
                assert_eq!(*m == 1.0, *s < 0.0, "mask {m}, sdf {s} for {g:?}");
            }
        }
    }
}

mod inside {
    use super::*;

    #[test]
    fn box_and_sphere_masks_by_hand() {
        let b = Geometry::from(AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap());
        // inside, outside above, on the top face (not inside), outside left, a corner
        let p = points(
            &[
                16.0, 4.0, 16.0, 9.0, 16.0, 8.0, -0.5, 4.0, 0.0, 0.0, 31.9, 7.9,
            ],
            2,
        );
        assert_eq!(
            b.lies_inside(&p).unwrap().to_vec(),
            vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        );
        let s = Geometry::sphere([0.0, 0.0], 5.0).unwrap();
        let p = points(&[3.0, 3.9, 3.0, 4.0, 3.0, 4.1, -4.9, 0.0], 2);
        assert_eq!(
            s.lies_inside(&p).unwrap().to_vec(),
            vec![1.0, 0.0, 0.0, 1.0]
        );
    }

    #[test]
    fn rotated_square_is_a_diamond() {
        // [-1, 1]² turned by 45°: |x| + |y| < √2.
        let diamond = Geometry::boxed([-1.0, -1.0], [1.0, 1.0])
            .unwrap()
            .rotated(Rotation::degrees(45.0))
            .unwrap();
        let p = points(
            &[
                0.0, 1.3, 1.0, 0.5, 0.7, 0.7, 0.72, 0.72, -1.35, 0.0, 0.0, -1.45,
            ],
            2,
        );
        assert_eq!(
            diamond.lies_inside(&p).unwrap().to_vec(),
            vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0]
        );
    }

    #[test]
    fn rotated_cube_in_3d() {
        // The unit cube [-1, 1]³ turned 45° about z: |x| + |y| < √2, |z| < 1.
        let cube = Geometry::boxed([-1.0; 3], [1.0; 3])
            .unwrap()
            .rotated(Rotation::axis_angle([0.0, 0.0, 1.0], 45.0))
            .unwrap();
        let p = points(
            &[
                0.0, 1.3, 0.5, 0.0, 1.3, 1.1, 0.72, 0.72, 0.0, 0.7, 0.7, -0.9,
            ],
            3,
        );
        assert_eq!(
            cube.lies_inside(&p).unwrap().to_vec(),
            vec![1.0, 0.0, 0.0, 1.0]
        );
        // Turning about x by 90° maps the y extent onto z.
        let slab = Geometry::boxed([-1.0, -3.0, -0.5], [1.0, 3.0, 0.5])
            .unwrap()
            .rotated(Rotation::axis_angle([1.0, 0.0, 0.0], 90.0))
            .unwrap();
        let p = points(&[0.0, 0.0, 2.5, 0.0, 2.5, 0.0, 0.0, 0.4, 0.0], 3);
        assert_eq!(slab.lies_inside(&p).unwrap().to_vec(), vec![1.0, 0.0, 1.0]);
    }

    #[test]
    fn union_and_inverted_masks() {
        let u = Geometry::union(vec![
            Geometry::boxed([0.0, 0.0], [1.0, 1.0]).unwrap(),
            Geometry::sphere([3.0, 0.5], 0.5).unwrap(),
        ])
        .unwrap();
        let p = points(&[0.5, 0.5, 3.0, 0.5, 2.0, 0.5, 1.0, 0.5], 2);
        assert_eq!(
            u.lies_inside(&p).unwrap().to_vec(),
            vec![1.0, 1.0, 0.0, 0.0]
        );
        // The inverse contains what is outside the closed union; surface points are in neither.
        assert_eq!(
            u.inverted().lies_inside(&p).unwrap().to_vec(),
            vec![0.0, 0.0, 1.0, 0.0]
        );
    }

    #[test]
    fn rotated_box_by_90_degrees_equals_the_swapped_box() {
        let long = Geometry::boxed([10.0, 13.8], [22.6, 18.2]).unwrap();
        let turned = long.rotated(Rotation::degrees(90.0)).unwrap();
        let swapped = Geometry::boxed([14.1, 9.7], [18.5, 22.3]).unwrap();
        let p = random_points(4000, 2, 5.0, 27.0, 4);
        assert_eq!(
            turned.lies_inside(&p).unwrap().to_vec(),
            swapped.lies_inside(&p).unwrap().to_vec()
        );
        assert_close(
            &turned.approximate_signed_distance(&p).unwrap().to_vec(),
            &swapped.approximate_signed_distance(&p).unwrap().to_vec(),
            1e-5,
        );
        let b = turned.bounding_box();
        assert_close(b.lower(), &[14.1, 9.7], 1e-5);
        assert_close(b.upper(), &[18.5, 22.3], 1e-5);
        // 3D: a quarter turn about z swaps the x and y extents.
        let brick = Geometry::boxed([-3.0, -1.0, -2.0], [3.0, 1.0, 2.0]).unwrap();
        let turned = brick
            .rotated(Rotation::axis_angle([0.0, 0.0, 1.0], 90.0))
            .unwrap();
        let swapped = Geometry::boxed([-1.0, -3.0, -2.0], [1.0, 3.0, 2.0]).unwrap();
        let p = random_points(4000, 3, -4.0, 4.0, 5);
        assert_eq!(
            turned.lies_inside(&p).unwrap().to_vec(),
            swapped.lies_inside(&p).unwrap().to_vec()
        );
        assert_close(
            &turned.approximate_signed_distance(&p).unwrap().to_vec(),
            &swapped.approximate_signed_distance(&p).unwrap().to_vec(),
            1e-5,
        );
    }

    #[test]
    fn wrong_points_are_errors_naming_both_dimensions() {
        let square = Geometry::boxed([0.0, 0.0], [1.0, 1.0]).unwrap();
        let e = square
            .lies_inside(&points(&[0.5, 0.5, 0.5], 3))
            .unwrap_err();
        assert_eq!(
            e,
            GeomError::DimensionMismatch {
                context: "lies_inside".into(),
                geometry: 2,
                other_name: "the points".into(),
                other: 3
            }
        );
        let message = e.to_string();
        assert!(
            message.contains("2-dimensional") && message.contains("3-dimensional"),
            "{message}"
        );
        let flat = Tensor::<Nd>::from_slice(&[0.5, 0.5], &[2], &Default::default()).unwrap();
        assert!(matches!(
            square.push(&flat, PushDirection::Outward, 0.0),
            Err(GeomError::NotPoints { .. })
        ));
        let e = square
            .push(&points(&[0.5, 0.5], 2), PushDirection::Outward, -1.0)
            .unwrap_err();
        assert!(e.to_string().contains("offset"), "{e}");
        // Tensor errors are wrapped with their message.
        let inner = phi_core::TensorError::NotScalar {
            op: "x",
            shape: vec![2],
        };
        assert_eq!(
            GeomError::from(inner.clone()).to_string(),
            inner.to_string()
        );
        // Empty batches work.
        let none = Tensor::<Nd>::zeros(&[0, 2], &Default::default());
        assert_eq!(square.lies_inside(&none).unwrap().shape(), vec![0]);
    }
}

mod push {
    use super::*;

    fn count_inside(g: &Geometry, p: &Tensor<Nd>) -> usize {
        g.lies_inside(p)
            .unwrap()
            .to_vec()
            .iter()
            .filter(|&&m| m == 1.0)
            .count()
    }

    /// Checks that an outward push leaves no point inside and leaves outside points untouched.
    fn check_outward(g: &Geometry, p: &Tensor<Nd>, offset: f32) -> Tensor<Nd> {
        let before = g.lies_inside(p).unwrap().to_vec();
        assert!(before.contains(&1.0), "the test needs points inside {g:?}");
        let pushed = g.push(p, PushDirection::Outward, offset).unwrap();
        assert_eq!(pushed.shape(), p.shape());
        assert_eq!(
            count_inside(g, &pushed),
            0,
            "points left inside {g:?} (offset {offset})"
        );
        let d = p.shape()[1];
        let (old, new) = (p.to_vec(), pushed.to_vec());
        for ((a, b), m) in rows(&old, d).iter().zip(rows(&new, d)).zip(&before) {
            if *m == 0.0 {
                assert_eq!(*a, b, "an outside point moved");
            }
        }
        pushed
    }

    #[test]
    fn outward_push_empties_rotated_boxes_spheres_and_unions() {
        let rotated = Geometry::boxed([2.0, 3.0], [7.0, 5.0])
            .unwrap()
            .rotated(Rotation::degrees(33.0))
            .unwrap();
        let ball = Geometry::sphere([4.0, 4.0], 2.5).unwrap();
        let union = Geometry::union(vec![
            Geometry::boxed([0.0, 0.0], [4.0, 2.0]).unwrap(),
            Geometry::boxed([3.0, 1.0], [5.0, 6.0]).unwrap(),
            Geometry::sphere([5.0, 5.0], 1.5).unwrap(),
            Geometry::boxed([1.0, 4.0], [7.0, 5.0])
                .unwrap()
                .rotated(Rotation::degrees(-20.0))
                .unwrap(),
        ])
        .unwrap();
        let p = random_points(5000, 2, -1.0, 8.0, 10);
        for g in [&rotated, &ball, &union] {
            for offset in [0.0, 0.05] {
                let pushed = check_outward(g, &p, offset);
                // (For a union the point may end closer than `offset` to another member.)
                if offset > 0.0 && !matches!(g, Geometry::Union(_)) {
                    let sdf = g.approximate_signed_distance(&pushed).unwrap().to_vec();
                    let inside_before = g.lies_inside(&p).unwrap().to_vec();
                    for (s, m) in sdf.iter().zip(&inside_before) {
                        if *m == 1.0 {
                            assert!(*s >= offset - 1e-4, "pushed point only {s} from {g:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn outward_push_of_a_dense_union_converges_or_falls_back() {
        // A staircase of overlapping boxes, where leaving one box often lands in the next.
        let steps: Vec<Geometry> = (0..6)
            .map(|i| {
                let x = i as f32 * 0.7;
                Geometry::boxed([x, 0.0], [x + 1.0, 1.0 + x]).unwrap()
            })
            .collect();
        let union = Geometry::union(steps).unwrap();
        let p = random_points(4000, 2, -0.5, 5.5, 11);
        check_outward(&union, &p, 0.0);
        check_outward(&union, &p, 0.1);
    }

    #[test]
    fn outward_push_in_3d() {
        let union = Geometry::union(vec![
            Geometry::sphere([0.0, 0.0, 0.0], 1.0).unwrap(),
            Geometry::boxed([0.5, -0.5, -0.5], [2.0, 0.5, 0.5])
                .unwrap()
                .rotated(Rotation::axis_angle([1.0, 1.0, 0.0], 40.0))
                .unwrap(),
        ])
        .unwrap();
        let p = random_points(5000, 3, -1.5, 2.5, 12);
        check_outward(&union, &p, 0.0);
        check_outward(&union, &p, 0.02);
        let cube = Geometry::boxed([-1.0; 3], [1.0; 3])
            .unwrap()
            .rotated(Rotation::axis_angle([0.3, -1.0, 2.0], 75.0))
            .unwrap();
        check_outward(&cube, &p, 0.0);
    }

    #[test]
    fn outward_push_is_minimal_for_box_sphere_and_rotated_box() {
        let shapes = [
            Geometry::boxed([1.0, 1.0], [6.0, 3.0]).unwrap(),
            Geometry::sphere([3.0, 3.0], 2.0).unwrap(),
            Geometry::boxed([1.0, 1.0], [6.0, 3.0])
                .unwrap()
                .rotated(Rotation::degrees(25.0))
                .unwrap(),
            Geometry::boxed([-1.0, 0.0, 0.0], [1.0, 2.0, 3.0]).unwrap(),
            Geometry::sphere([0.0, 1.0, 1.0], 1.5).unwrap(),
        ];
        for g in &shapes {
            let d = g.dim();
            let p = random_points(3000, d, -1.0, 7.0, 13 + d as u64);
            for offset in [0.0, 0.3] {
                let depth = g.approximate_signed_distance(&p).unwrap().to_vec();
                let pushed = g.push(&p, PushDirection::Outward, offset).unwrap().to_vec();
                let old = p.to_vec();
                let after = g
                    .approximate_signed_distance(&points(&pushed, d))
                    .unwrap()
                    .to_vec();
                for i in 0..depth.len() {
                    let moved = distance(&old[i * d..(i + 1) * d], &pushed[i * d..(i + 1) * d]);
                    if depth[i] < 0.0 {
                        assert!(
                            (moved - (offset - depth[i])).abs() < 5e-5,
                            "{g:?}: moved {moved} for depth {}",
                            depth[i]
                        );
                        assert!(
                            (after[i] - offset).abs() < 5e-5,
                            "{g:?}: ends at sdf {}",
                            after[i]
                        );
                    } else {
                        assert_eq!(moved, 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn box_push_snaps_to_the_nearest_face_by_hand() {
        let b = Geometry::boxed([0.0, 0.0], [4.0, 2.0]).unwrap();
        let p = points(&[1.0, 0.5, 3.5, 1.0, 2.0, 1.9, 5.0, 5.0], 2);
        let pushed = b.push(&p, PushDirection::Outward, 0.25).unwrap().to_vec();
        assert_eq!(pushed, vec![1.0, -0.25, 4.25, 1.0, 2.0, 2.25, 5.0, 5.0]);
        let inward = b
            .push(
                &points(&[5.0, 5.0, -1.0, 1.0, 1.0, 1.0], 2),
                PushDirection::Inward,
                0.5,
            )
            .unwrap();
        assert_eq!(inward.to_vec(), vec![3.5, 1.5, 0.5, 1.0, 1.0, 1.0]);
        // The centre of a ball goes along +x.
        let s = Geometry::sphere([1.0, 1.0], 2.0).unwrap();
        let centre = s
            .push(&points(&[1.0, 1.0], 2), PushDirection::Outward, 0.0)
            .unwrap()
            .to_vec();
        assert!(
            (centre[0] - 3.0).abs() < 1e-5 && centre[1] == 1.0,
            "{centre:?}"
        );
    }

    #[test]
    fn inward_push_keeps_particles_in_the_domain_box() {
        let domain = Geometry::from(AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap());
        let p = random_points(5000, 2, -10.0, 40.0, 14);
        let before = domain.approximate_signed_distance(&p).unwrap().to_vec();
        for offset in [0.0, 0.5] {
            let pushed = domain.push(&p, PushDirection::Inward, offset).unwrap();
            let sdf = domain
                .approximate_signed_distance(&pushed)
                .unwrap()
                .to_vec();
            let (old, new) = (p.to_vec(), pushed.to_vec());
            for i in 0..sdf.len() {
                // Moved points end `offset` inside; the others stay inside.
                let bound = if before[i] > 0.0 { -offset } else { 0.0 };
                assert!(sdf[i] <= bound + 1e-6, "point {i} ended at sdf {}", sdf[i]);
                let moved = distance(&old[2 * i..2 * i + 2], &new[2 * i..2 * i + 2]);
                if before[i] <= 0.0 {
                    assert_eq!(moved, 0.0, "an inside point moved");
                } else if offset == 0.0 {
                    // Clamping is the nearest point of the box.
                    assert!(
                        (moved - before[i]).abs() < 1e-4,
                        "moved {moved}, distance {}",
                        before[i]
                    );
                }
            }
            if offset > 0.0 {
                // Points that were outside end `offset` inside: strictly inside.
                assert!(
                    domain
                        .lies_inside(&pushed)
                        .unwrap()
                        .to_vec()
                        .iter()
                        .all(|&m| m == 1.0)
                );
            }
            // Pushing outward from the inverted box is the same thing.
            let walls = domain.clone().inverted();
            assert_eq!(
                walls
                    .push(&p, PushDirection::Outward, offset)
                    .unwrap()
                    .to_vec(),
                pushed.to_vec()
            );
        }
        // 3D
        let room = Geometry::boxed([0.0; 3], [4.0, 2.0, 3.0]).unwrap();
        let p = random_points(3000, 3, -3.0, 6.0, 15);
        let pushed = room.push(&p, PushDirection::Inward, 0.1).unwrap();
        assert!(
            room.lies_inside(&pushed)
                .unwrap()
                .to_vec()
                .iter()
                .all(|&m| m == 1.0)
        );
    }

    #[test]
    fn inward_push_into_spheres_rotations_and_unions() {
        let ball = Geometry::sphere([1.0, 2.0], 1.5).unwrap();
        let p = random_points(2000, 2, -4.0, 6.0, 16);
        let before = ball.approximate_signed_distance(&p).unwrap().to_vec();
        let pushed = ball.push(&p, PushDirection::Inward, 0.2).unwrap();
        let (old, new) = (p.to_vec(), pushed.to_vec());
        let after = ball.approximate_signed_distance(&pushed).unwrap().to_vec();
        for i in 0..before.len() {
            let moved = distance(&old[2 * i..2 * i + 2], &new[2 * i..2 * i + 2]);
            if before[i] > 0.0 {
                assert!((moved - (before[i] + 0.2)).abs() < 1e-4);
                assert!((after[i] + 0.2).abs() < 1e-4);
            } else {
                assert_eq!(moved, 0.0);
            }
        }
        let union = Geometry::union(vec![
            Geometry::sphere([0.0, 0.0], 1.0).unwrap(),
            Geometry::boxed([2.0, -1.0], [5.0, 0.0])
                .unwrap()
                .rotated(Rotation::degrees(15.0))
                .unwrap(),
        ])
        .unwrap();
        let pushed = union.push(&p, PushDirection::Inward, 0.05).unwrap();
        assert!(
            union
                .lies_inside(&pushed)
                .unwrap()
                .to_vec()
                .iter()
                .all(|&m| m == 1.0)
        );
        // Points go into the nearer member: the distance to the union, plus at most the offset
        // (times √2 where a box clamps a corner).
        let dist = union.approximate_signed_distance(&p).unwrap().to_vec();
        let new = pushed.to_vec();
        for i in 0..dist.len() {
            let moved = distance(&old[2 * i..2 * i + 2], &new[2 * i..2 * i + 2]);
            if dist[i] > 0.0 {
                let most = dist[i] + 0.05 * 2f32.sqrt() + 1e-4;
                assert!(
                    moved <= most && moved >= dist[i] - 1e-4,
                    "moved {moved} for distance {}",
                    dist[i]
                );
            }
        }
    }
}

mod gradients {
    use super::*;

    type Ad = Burn;

    fn burn_points(values: &[f32], d: usize) -> Tensor<Ad> {
        Tensor::from_slice(values, &[values.len() / d, d], &Default::default()).unwrap()
    }

    /// The autodiff gradient of `Σ w ⊙ f(x)` (fixed random weights `w`) against central finite
    /// differences, on Burn. The differences are taken element by element on the host, so that
    /// only the perturbed point's outputs contribute rounding error.
    fn check_gradient(f: &dyn Fn(&Tensor<Ad>) -> Tensor<Ad>, values: &[f32], d: usize) {
        let x = burn_points(values, d).require_grad();
        let out_shape = f(&x).shape();
        let w = Tensor::<Ad>::random_uniform(&out_shape, 0.5, 1.5, 99, &Default::default());
        let weights = w.to_vec();
        let grad = (f(&x) * &w)
            .sum()
            .gradients(&[&x])
            .unwrap()
            .remove(0)
            .to_vec();
        assert_eq!(grad.len(), values.len());
        let eps = 1e-2f32;
        for i in 0..values.len() {
            let mut plus = values.to_vec();
            plus[i] += eps;
            let mut minus = values.to_vec();
            minus[i] -= eps;
            let (fp, fm) = (
                f(&burn_points(&plus, d)).to_vec(),
                f(&burn_points(&minus, d)).to_vec(),
            );
            let fd: f64 = fp
                .iter()
                .zip(&fm)
                .zip(&weights)
                .map(|((a, b), w)| f64::from(a - b) * f64::from(*w))
                .sum::<f64>()
                / f64::from(2.0 * eps);
            let fd = fd as f32;
            let tol = 2e-3 * (1.0 + fd.abs());
            assert!(grad[i].is_finite(), "gradient {i} is {}", grad[i]);
            assert!(
                (grad[i] - fd).abs() <= tol,
                "coordinate {i}: autodiff {} vs finite differences {fd}",
                grad[i]
            );
        }
    }

    /// `n_in` points inside and `n_out` outside `g`, each at least 0.05 from the surface and with
    /// `kink_distance > 0.05` (away from where the map is not smooth).
    fn sample(
        g: &Geometry,
        kink_distance: &dyn Fn(&[f32]) -> f32,
        d: usize,
        seed: u64,
        n_in: usize,
        n_out: usize,
    ) -> Vec<f32> {
        let p = random_points(3000, d, -1.0, 7.0, seed).to_vec();
        let sdf = g
            .approximate_signed_distance(&points(&p, d))
            .unwrap()
            .to_vec();
        let (mut inside, mut outside) = (Vec::new(), Vec::new());
        for (i, x) in rows(&p, d).into_iter().enumerate() {
            if sdf[i].abs() <= 0.05 || kink_distance(x) <= 0.05 {
                continue;
            }
            if sdf[i] < 0.0 && inside.len() < n_in * d {
                inside.extend_from_slice(x);
            } else if sdf[i] > 0.0 && outside.len() < n_out * d {
                outside.extend_from_slice(x);
            }
        }
        assert_eq!(inside.len(), n_in * d, "too few usable points inside");
        assert_eq!(outside.len(), n_out * d, "too few usable points outside");
        inside.extend(outside);
        inside
    }

    #[test]
    fn push_out_of_a_sphere_matches_finite_differences() {
        let ball = Geometry::sphere([3.0, 3.0], 2.5).unwrap();
        // Keep away from the centre, where the push's curvature is large.
        let kink = |x: &[f32]| ((x[0] - 3.0).powi(2) + (x[1] - 3.0).powi(2)).sqrt() - 0.95;
        let values = sample(&ball, &kink, 2, 20, 12, 4);
        for offset in [0.0, 0.1] {
            let g = ball.clone();
            check_gradient(
                &move |x| g.push(x, PushDirection::Outward, offset).unwrap(),
                &values,
                2,
            );
            let g = ball.clone();
            check_gradient(
                &move |x| g.push(x, PushDirection::Inward, offset).unwrap(),
                &values,
                2,
            );
        }
        let g = ball.clone();
        check_gradient(
            &move |x| g.approximate_signed_distance(x).unwrap(),
            &values,
            2,
        );
    }

    #[test]
    fn push_out_of_a_rotated_box_matches_finite_differences() {
        let rotation = Rotation::degrees(25.0);
        let g = Geometry::boxed([1.0, 2.0], [6.0, 4.0])
            .unwrap()
            .rotated(rotation.clone())
            .unwrap();
        let (pivot, half, offset) = ([3.5f32, 3.0], [2.5f32, 1.0], 0.2f32);
        // In the box frame: ties between faces, the centre lines, and where clamping starts.
        let kink = move |x: &[f32]| {
            let local = rotation
                .inverse()
                .apply(&[x[0] - pivot[0], x[1] - pivot[1]]);
            let q: Vec<f32> = (0..2).map(|k| half[k] - local[k].abs()).collect();
            let clamp = (0..2)
                .map(|k| (local[k].abs() - (half[k] - offset)).abs())
                .fold(f32::INFINITY, f32::min);
            (q[1] - q[0])
                .abs()
                .min(local[0].abs())
                .min(local[1].abs())
                .min(clamp)
        };
        let values = sample(&g, &kink, 2, 21, 10, 10);
        let h = g.clone();
        check_gradient(
            &move |x| h.push(x, PushDirection::Outward, offset).unwrap(),
            &values,
            2,
        );
        let h = g.clone();
        check_gradient(
            &move |x| h.push(x, PushDirection::Inward, offset).unwrap(),
            &values,
            2,
        );
        let h = g;
        check_gradient(
            &move |x| h.approximate_signed_distance(x).unwrap(),
            &values,
            2,
        );
    }

    #[test]
    fn push_out_of_a_3d_union_matches_finite_differences() {
        let g = Geometry::union(vec![
            Geometry::sphere([2.0, 2.0, 2.0], 1.5).unwrap(),
            Geometry::sphere([5.0, 4.0, 3.0], 1.0).unwrap(),
        ])
        .unwrap();
        let kink =
            |x: &[f32]| distance(x, &[2.0, 2.0, 2.0]).min(distance(x, &[5.0, 4.0, 3.0])) - 0.5;
        let values = sample(&g, &kink, 3, 22, 12, 4);
        let h = g.clone();
        check_gradient(
            &move |x| h.push(x, PushDirection::Outward, 0.05).unwrap(),
            &values,
            3,
        );
    }

    #[test]
    fn gradient_is_finite_at_the_centre_of_a_ball() {
        let ball = Geometry::sphere([0.0, 0.0], 1.0).unwrap();
        let x = burn_points(&[0.0, 0.0, 2.0, 0.0], 2).require_grad();
        let sdf = ball.approximate_signed_distance(&x).unwrap();
        let grad = sdf.sum().gradients(&[&x]).unwrap().remove(0).to_vec();
        assert_close(&grad, &[0.0, 0.0, 1.0, 0.0], 1e-6);
        let pushed = ball.push(&x, PushDirection::Outward, 0.0).unwrap();
        let grad = pushed.sum().gradients(&[&x]).unwrap().remove(0).to_vec();
        assert!(grad.iter().all(|g| g.is_finite()), "{grad:?}");
        // The untouched outside point passes its gradient through unchanged.
        assert_eq!(&grad[2..], &[1.0, 1.0]);
    }
}

mod rasterise {
    use super::*;

    fn sum(t: &Tensor<Nd>) -> f32 {
        t.to_vec().iter().sum()
    }

    #[test]
    fn volume_fraction_of_a_disc_converges_to_its_area() {
        let domain = Domain::closed_unit_cells(&[32, 32]).unwrap();
        let disc = Sphere::new(vec![16.3, 15.7], 9.5).unwrap();
        let area = disc.volume();
        let g = Geometry::from(disc);
        let device = Default::default();
        for k in [1usize, 2, 4, 8] {
            let f = g.cell_volume_fraction::<Nd>(&domain, k, &device).unwrap();
            assert_eq!(f.shape(), vec![32, 32]);
            let error = (sum(&f) - area).abs() / area;
            assert!(error <= 0.02 / k as f32, "k = {k}: relative error {error}");
            assert!(f.to_vec().iter().all(|&v| (0.0..=1.0).contains(&v)));
        }
    }

    #[test]
    fn volume_fraction_of_a_ball_converges_to_its_volume() {
        let domain = Domain::new(
            &[16, 16, 16],
            &[0.0; 3],
            &[8.0; 3],
            &[[phi_core::fields::Boundary::Closed; 2]; 3],
        )
        .unwrap();
        let ball = Sphere::new(vec![4.1, 3.9, 4.2], 2.7).unwrap();
        let volume = ball.volume();
        let g = Geometry::from(ball);
        let cell = 0.5f32.powi(3);
        for k in [1usize, 2, 4] {
            let f = g
                .cell_volume_fraction::<Nd>(&domain, k, &Default::default())
                .unwrap();
            assert_eq!(f.shape(), vec![16, 16, 16]);
            let error = (sum(&f) * cell - volume).abs() / volume;
            assert!(error <= 0.03 / k as f32, "k = {k}: relative error {error}");
        }
    }

    #[test]
    fn cell_mask_of_a_floor() {
        let domain = Domain::closed_unit_cells(&[32, 16]).unwrap();
        let floor = Geometry::from(AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap());
        let mask = floor
            .cell_inside_mask::<Nd>(&domain, &Default::default())
            .unwrap();
        assert_eq!(mask.shape(), vec![32, 16]);
        let values = mask.to_vec();
        for i in 0..32 {
            for j in 0..16 {
                assert_eq!(
                    values[i * 16 + j],
                    if j < 8 { 1.0 } else { 0.0 },
                    "cell ({i}, {j})"
                );
            }
        }
    }

    #[test]
    fn face_fractions_by_hand() {
        // An 8 × 4 grid of unit cells and the slab 2 ≤ x ≤ 5 over the full height.
        let domain = Domain::closed_unit_cells(&[8, 4]).unwrap();
        let slab = Geometry::boxed([2.0, 0.0], [5.0, 4.0]).unwrap();
        let device = Default::default();
        let cells = slab
            .cell_volume_fraction::<Nd>(&domain, 4, &device)
            .unwrap()
            .to_vec();
        for i in 0..8 {
            let want = if (2..5).contains(&i) { 1.0 } else { 0.0 };
            assert!(
                cells[i * 4..i * 4 + 4].iter().all(|&v| v == want),
                "cell column {i}"
            );
        }
        let faces = slab
            .face_volume_fractions::<Nd>(&domain, 4, &device)
            .unwrap();
        assert_eq!(faces[0].shape(), vec![9, 4]);
        assert_eq!(faces[1].shape(), vec![8, 5]);
        // x faces: face k at x = k; its control volume k - ½ .. k + ½.
        let x_faces = faces[0].to_vec();
        let want_x = [0.0, 0.0, 0.5, 1.0, 1.0, 0.5, 0.0, 0.0, 0.0];
        for k in 0..9 {
            assert!(
                x_faces[k * 4..k * 4 + 4].iter().all(|&v| v == want_x[k]),
                "x face {k}: {x_faces:?}"
            );
        }
        // y faces: centred on cells along x; the bottom and top faces are half covered.
        let y_faces = faces[1].to_vec();
        for i in 0..8 {
            for k in 0..5 {
                let inside = if (2..5).contains(&i) { 1.0 } else { 0.0 };
                let want = if k == 0 || k == 4 {
                    0.5 * inside
                } else {
                    inside
                };
                assert_eq!(y_faces[i * 5 + k], want, "y face ({i}, {k})");
            }
        }
        let x_mask = slab
            .face_inside_mask::<Nd>(&domain, 0, &device)
            .unwrap()
            .to_vec();
        // Face centres on x = 2 and x = 5 are on the surface, not inside.
        let want_mask = [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
        for k in 0..9 {
            assert!(
                x_mask[k * 4..k * 4 + 4].iter().all(|&v| v == want_mask[k]),
                "x face mask {k}"
            );
        }
    }

    #[test]
    fn rotated_box_rasterises_like_the_swapped_box() {
        let domain = Domain::closed_unit_cells(&[24, 24]).unwrap();
        let turned = Geometry::boxed([5.7, 9.8], [18.3, 14.2])
            .unwrap()
            .rotated(Rotation::degrees(90.0))
            .unwrap();
        let swapped = Geometry::boxed([9.8, 5.7], [14.2, 18.3]).unwrap();
        let device = Default::default();
        let a = turned
            .cell_volume_fraction::<Nd>(&domain, 4, &device)
            .unwrap()
            .to_vec();
        let b = swapped
            .cell_volume_fraction::<Nd>(&domain, 4, &device)
            .unwrap()
            .to_vec();
        assert_eq!(a, b);
        let a = turned
            .face_volume_fraction::<Nd>(&domain, 1, 3, &device)
            .unwrap()
            .to_vec();
        let b = swapped
            .face_volume_fraction::<Nd>(&domain, 1, 3, &device)
            .unwrap()
            .to_vec();
        assert_eq!(a, b);
        // And its area is 12.6 × 4.4.
        let total: f32 = turned
            .cell_volume_fraction::<Nd>(&domain, 8, &device)
            .unwrap()
            .to_vec()
            .iter()
            .sum();
        // (up to the sub-sample spacing, 1/8, times half the perimeter)
        assert!((total - 12.6 * 4.4).abs() < 34.0 / 16.0, "{total}");
    }

    #[test]
    fn rasterising_on_a_mismatched_domain_is_an_error() {
        let domain = Domain::closed_unit_cells(&[8, 8, 8]).unwrap();
        let square = Geometry::boxed([0.0, 0.0], [1.0, 1.0]).unwrap();
        let e = square
            .cell_inside_mask::<Nd>(&domain, &Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("the domain is 3-dimensional") && e.contains("2-dimensional"),
            "{e}"
        );
        let plane = Domain::closed_unit_cells(&[8, 8]).unwrap();
        assert!(
            square
                .cell_volume_fraction::<Nd>(&plane, 0, &Default::default())
                .is_err()
        );
        assert!(
            square
                .face_inside_mask::<Nd>(&plane, 2, &Default::default())
                .is_err()
        );
    }
}

mod scene_files {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Scene {
        walls: Geometry,
        obstacles: Vec<Obstacle>,
        shapes: Vec<Geometry>,
    }

    const SCENE: &str = r#"
walls = { type = "inverted", geometry = { type = "box", lower = [0, 0], upper = [64, 32] } }
shapes = [
    { type = "sphere", center = [1, 2, 3], radius = 0.5 },
    { type = "rotated", angle = 45, axis = [0, 0, 1], pivot = [0, 0, 0], geometry = { type = "box", lower = [-1, -1, -1], upper = [1, 1, 1] } },
]

[[obstacles]]
geometry = { type = "rotated", angle = 30, geometry = { type = "box", lower = [4, 4], upper = [20, 6] } }

[[obstacles]]
geometry = { type = "union", members = [{ type = "sphere", center = [8, 8], radius = 2 }, { type = "box", lower = [0, 0], upper = [4, 4] }] }
velocity = [1.5, 0]
"#;

    #[test]
    fn scene_reads_as_written_and_round_trips() {
        let scene: Scene = toml::from_str(SCENE).unwrap();
        let want = Scene {
            walls: Geometry::boxed([0.0, 0.0], [64.0, 32.0])
                .unwrap()
                .inverted(),
            obstacles: vec![
                Obstacle::at_rest(
                    Geometry::boxed([4.0, 4.0], [20.0, 6.0])
                        .unwrap()
                        .rotated(Rotation::degrees(30.0))
                        .unwrap(),
                )
                .unwrap(),
                Obstacle::new(
                    Geometry::union(vec![
                        Geometry::sphere([8.0, 8.0], 2.0).unwrap(),
                        Geometry::boxed([0.0, 0.0], [4.0, 4.0]).unwrap(),
                    ])
                    .unwrap(),
                    [1.5, 0.0],
                )
                .unwrap(),
            ],
            shapes: vec![
                Geometry::sphere([1.0, 2.0, 3.0], 0.5).unwrap(),
                Geometry::boxed([-1.0; 3], [1.0; 3])
                    .unwrap()
                    .rotated_about(Rotation::axis_angle([0.0, 0.0, 1.0], 45.0), [0.0, 0.0, 0.0])
                    .unwrap(),
            ],
        };
        assert_eq!(scene, want);
        // The default pivot is the centre of the rotated box.
        if let Geometry::Rotated(r) = scene.obstacles[0].geometry() {
            assert_eq!(r.pivot(), vec![12.0, 5.0]);
            assert_eq!(r.explicit_pivot(), None);
        } else {
            panic!("expected a rotated geometry");
        }
        let text = toml::to_string(&scene).unwrap();
        let again: Scene = toml::from_str(&text).unwrap();
        assert_eq!(again, scene, "round trip through\n{text}");
    }

    fn parse_error(text: &str) -> String {
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct One {
            g: Geometry,
        }
        toml::from_str::<One>(text).unwrap_err().to_string()
    }

    #[test]
    fn unknown_keys_and_types_are_errors() {
        let e =
            parse_error(r#"g = { type = "box", lower = [0, 0], upper = [1, 1], colour = "red" }"#);
        assert!(e.contains("colour"), "{e}");
        let e = parse_error(r#"g = { type = "cone", lower = [0, 0] }"#);
        assert!(e.contains("cone"), "{e}");
        let e = parse_error(
            r#"g = { type = "rotated", angel = 30, geometry = { type = "sphere", center = [0, 0], radius = 1 } }"#,
        );
        assert!(e.contains("angel"), "{e}");
        let e = toml::from_str::<Obstacle>(
            "geometry = { type = \"sphere\", center = [0, 0], radius = 1 }\nspeed = [1, 0]",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("speed"), "{e}");
    }

    #[test]
    fn wrong_dimensions_and_values_are_errors() {
        let e = parse_error(r#"g = { type = "box", lower = [0, 0], upper = [1, 1, 1] }"#);
        assert!(e.contains("box.upper") && e.contains("3 entries"), "{e}");
        let e = parse_error(
            r#"g = { type = "union", members = [{ type = "sphere", center = [0, 0], radius = 1 }, { type = "sphere", center = [0, 0, 0], radius = 1 }] }"#,
        );
        assert!(e.contains("member 1 of the union is 3-dimensional"), "{e}");
        let e = parse_error(
            r#"g = { type = "rotated", angle = 30, geometry = { type = "sphere", center = [0, 0, 0], radius = 1 } }"#,
        );
        assert!(
            e.contains("dimension mismatch") && e.contains("planar rotation"),
            "{e}"
        );
        let e = parse_error(
            r#"g = { type = "rotated", angle = 30, axis = [0, 1], geometry = { type = "sphere", center = [0, 0], radius = 1 } }"#,
        );
        assert!(e.contains("rotated.axis"), "{e}");
        let e = parse_error(r#"g = { type = "sphere", center = [0, 0], radius = -2 }"#);
        assert!(e.contains("sphere.radius") && e.contains("-2"), "{e}");
        let e = toml::from_str::<Obstacle>(
            "geometry = { type = \"sphere\", center = [0, 0], radius = 1 }\nvelocity = [1, 0, 0]",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("velocity") && e.contains("3-dimensional"), "{e}");
        // A box on its own reads as a table of corners.
        let b: AxisBox = toml::from_str("lower = [0, 0]\nupper = [32, 8]").unwrap();
        assert_eq!(b, AxisBox::from_ranges(&[0.0..32.0, 0.0..8.0]).unwrap());
        assert!(toml::from_str::<AxisBox>("lower = [1, 0]\nupper = [0, 8]").is_err());
    }
}

/// Deeply nested geometries evaluate in time linear in their size (no timing asserted: the
/// depths below took minutes or never finished when children were evaluated repeatedly), and
/// agree with the shape they nest.
mod nesting {
    use super::*;

    /// A box wrapped in `depth` unions of itself with a small ball inside it (which changes
    /// nothing). (Scene files cannot nest this deep: the TOML parser refuses first.)
    fn nested_unions(depth: usize) -> Geometry {
        let ball = Geometry::sphere([5.0, 5.0], 1.0).unwrap();
        let mut g = Geometry::boxed([2.0, 3.0], [10.0, 7.0]).unwrap();
        for _ in 0..depth {
            g = Geometry::union(vec![g, ball.clone()]).unwrap();
        }
        g
    }

    /// The box rotated `depth` times by 360°/`depth` (a full turn in all) about its centre.
    fn nested_rotations(depth: usize) -> Geometry {
        let mut g = Geometry::boxed([2.0, 3.0], [10.0, 7.0]).unwrap();
        for _ in 0..depth {
            g = g.rotated(Rotation::degrees(360.0 / depth as f32)).unwrap();
        }
        g
    }

    /// `tol` bounds the distances; pushes may overshoot by `push_tol` (the rounding margins of
    /// the rotations, which grow with the nesting as each rotation's bounding box encloses the
    /// one inside).
    fn check_against_the_box(g: &Geometry, tol: f32, push_tol: f32) {
        let plain = Geometry::boxed([2.0, 3.0], [10.0, 7.0]).unwrap();
        // Points away from the surface, where rounding of the turns cannot flip the answers.
        let p = random_points(400, 2, 0.0, 12.0, 3);
        let sdf = plain.approximate_signed_distance(&p).unwrap().to_vec();
        let far: Vec<f32> = p
            .to_vec()
            .chunks(2)
            .zip(&sdf)
            .filter(|(_, d)| d.abs() > 0.05)
            .flat_map(|(q, _)| q.to_vec())
            .collect();
        let p = points(&far, 2);
        assert_eq!(
            g.lies_inside(&p).unwrap().to_vec(),
            plain.lies_inside(&p).unwrap().to_vec()
        );
        assert_close(
            &g.approximate_signed_distance(&p).unwrap().to_vec(),
            &plain.approximate_signed_distance(&p).unwrap().to_vec(),
            tol,
        );
        let pushed = g.push(&p, PushDirection::Outward, 0.0).unwrap().to_vec();
        let want = plain
            .push(&p, PushDirection::Outward, 0.0)
            .unwrap()
            .to_vec();
        assert_close(&pushed, &want, push_tol);
        let pushed = g.push(&p, PushDirection::Inward, 0.0).unwrap().to_vec();
        let want = plain.push(&p, PushDirection::Inward, 0.0).unwrap().to_vec();
        assert_close(&pushed, &want, push_tol);
    }

    #[test]
    fn unions_nested_forty_deep_are_the_box() {
        let g = nested_unions(40);
        assert_eq!(g.depth(), 41);
        let b = g.bounding_box();
        assert_eq!((b.lower(), b.upper()), (&[2.0, 3.0][..], &[10.0, 7.0][..]));
        assert_eq!(g.center(), vec![6.0, 5.0]);
        check_against_the_box(&g, 0.0, 0.0);
    }

    #[test]
    fn rotations_nested_fifty_deep_are_the_box() {
        let g = nested_rotations(50);
        assert_eq!(g.depth(), 51);
        assert_close(&g.center(), &[6.0, 5.0], 1e-4);
        check_against_the_box(&g, 3e-3, 0.03);
    }

    /// Too deep a tree, or unions whose rounds multiply past the bound, are refused with a clear
    /// error instead of being recursed into.
    #[test]
    fn trees_beyond_the_bounds_are_refused() {
        let mut g = Geometry::boxed([2.0, 3.0], [10.0, 7.0]).unwrap();
        let mut error = None;
        for _ in 0..phi_geom::MAX_DEPTH + 5 {
            match g.clone().rotated(Rotation::degrees(1.0)) {
                Ok(next) => g = next,
                Err(e) => {
                    error = Some(e.to_string());
                    break;
                }
            }
        }
        let e = error.expect("a tree deeper than MAX_DEPTH must be refused");
        assert!(e.contains("nest at most"), "{e}");
        // Overlapping unions inside rotations inside unions: 4 rounds per level.
        let ball = Geometry::sphere([5.0, 5.0], 2.0).unwrap();
        let mut g = ball.clone();
        let mut error = None;
        for _ in 0..20 {
            let u = Geometry::union(vec![g.clone(), ball.clone()])
                .and_then(|u| u.rotated(Rotation::degrees(10.0)));
            match u {
                Ok(next) => g = next,
                Err(e) => {
                    error = Some(e.to_string());
                    break;
                }
            }
        }
        let e = error.expect("multiplying rounds must be refused");
        assert!(e.contains("pushes per push"), "{e}");
    }
}
