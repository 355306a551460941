//! Unit tests of the fields layer on the ndarray backend (the cross-backend suite is in
//! `tests/fields`).

use super::*;
use crate::backend::ndarray::NdArray;
use crate::tensor::Tensor;

type T = Tensor<NdArray>;

fn device() -> <NdArray as crate::Backend>::Device {
    Default::default()
}

fn unit(res: &[usize]) -> Domain {
    Domain::closed_unit_cells(res).unwrap()
}

#[test]
fn constructors_check_shapes() {
    let domain = unit(&[3, 2]);
    assert!(CenteredGrid::new(T::zeros(&[3, 2, 1], &device()), domain.clone()).is_ok());
    let message = CenteredGrid::new(T::zeros(&[2, 3, 1], &device()), domain.clone())
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("[2, 3, 1]") && message.contains("[3, 2]"),
        "{message}"
    );
    let good = vec![T::zeros(&[4, 2], &device()), T::zeros(&[3, 3], &device())];
    assert!(StaggeredGrid::new(good, domain.clone()).is_ok());
    let bad = vec![T::zeros(&[3, 2], &device()), T::zeros(&[3, 3], &device())];
    let message = StaggeredGrid::new(bad, domain.clone())
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("[4, 2]") && message.contains("[3, 2]"),
        "{message}"
    );
    let one = vec![T::zeros(&[4, 2], &device())];
    assert!(StaggeredGrid::new(one, domain).is_err());
    let message = PointCloud::new(T::zeros(&[5, 2], &device()), T::zeros(&[4, 2], &device()))
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("[5, 2]") && message.contains("[4, 2]"),
        "{message}"
    );
    assert!(PointCloud::new(T::zeros(&[5, 4], &device()), T::zeros(&[5, 1], &device())).is_err());
}

#[test]
fn sample_points_follow_the_layout() {
    let domain = Domain::new(
        &[2, 3],
        &[1.0, -1.0],
        &[2.0, 2.0],
        &[[Boundary::Open; 2]; 2],
    )
    .unwrap();
    let centres = cell_centers::<NdArray>(&domain, &device());
    assert_eq!(centres.shape(), vec![2, 3, 2]);
    // cell (1, 2): x = 1 + 1.5 · 0.5, y = −1 + 2.5 · 1
    assert_eq!(centres.to_vec()[(3 + 2) * 2..(3 + 2) * 2 + 2], [1.75, 1.5]);
    let faces = face_centers::<NdArray>(&domain, 0, &device());
    assert_eq!(faces.shape(), vec![3, 3, 2]);
    // face (2, 0) of component x: x = 1 + 2 · 0.5, y = −1 + 0.5
    assert_eq!(faces.to_vec()[6 * 2..6 * 2 + 2], [2.0, -0.5]);
    let faces = face_centers::<NdArray>(&domain, 1, &device());
    assert_eq!(faces.shape(), vec![2, 4, 2]);
    assert_eq!(faces.to_vec()[3 * 2..3 * 2 + 2], [1.25, 2.0]);
}

#[test]
fn gradient_and_divergence_small() {
    let domain = unit(&[3]);
    let p = CenteredGrid::<NdArray>::new(
        T::from_vec(vec![1.0, 4.0, 9.0], &[3, 1], &device()).unwrap(),
        domain,
    )
    .unwrap();
    let g = gradient(&p).unwrap();
    assert_eq!(g.component(0).to_vec(), vec![0.0, 3.0, 5.0, 0.0]);
    let div = divergence(&g).unwrap();
    assert_eq!(div.values().to_vec(), vec![3.0, 2.0, -5.0]);
    let open = Domain::new(&[3], &[0.0], &[3.0], &[[Boundary::Open; 2]]).unwrap();
    let p = p.values().clone();
    let g = gradient(&CenteredGrid::new(p, open).unwrap()).unwrap();
    assert_eq!(g.component(0).to_vec(), vec![1.0, 3.0, 5.0, -9.0]);
}

#[test]
fn nearest_transfer_averages_and_counts() {
    let domain = unit(&[3, 2]);
    let positions = T::from_vec(vec![0.2, 0.4, 0.4, 0.6, 2.9, 1.9], &[3, 2], &device()).unwrap();
    let values = T::from_vec(vec![1.0, 10.0, 3.0, 20.0, 5.0, 30.0], &[3, 2], &device()).unwrap();
    let cloud = PointCloud::new(positions.clone(), values).unwrap();
    let (v, w) = particles_to_staggered(&cloud, &domain, Transfer::NearestFace).unwrap();
    // x faces: shape [4, 2]; particles 0 and 1 → face (0, 0); particle 2 → face (3, 1).
    assert_eq!(
        w.component(0).to_vec(),
        vec![2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    );
    assert_eq!(
        v.component(0).to_vec(),
        vec![2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0]
    );
    // y faces: shape [3, 3]; particle 0 → (0, 0), particle 1 → (0, 1), particle 2 → (2, 2).
    assert_eq!(
        v.component(1).to_vec(),
        vec![10.0, 20.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 30.0]
    );
    let occupied = occupied_cells(&positions, &domain).unwrap();
    assert_eq!(
        occupied.values().to_vec(),
        vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    );
    let counts = count_particles(&positions, &domain).unwrap();
    assert_eq!(counts.values().to_vec(), vec![2.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn extrapolation_grows_one_layer_per_iteration() {
    let values = T::from_vec(vec![0.0, 0.0, 4.0, 0.0, 0.0, 0.0], &[6], &device()).unwrap();
    let valid = T::from_vec(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0], &[6], &device()).unwrap();
    let (v, m) = extrapolate_valid_tensor(&values, &valid, 1, 2).unwrap();
    assert_eq!(v.to_vec(), vec![4.0, 4.0, 4.0, 4.0, 4.0, 0.0]);
    assert_eq!(m.to_vec(), vec![1.0, 1.0, 1.0, 1.0, 1.0, 0.0]);
    // two valid neighbours are averaged
    let values = T::from_vec(vec![2.0, 0.0, 6.0], &[3], &device()).unwrap();
    let valid = T::from_vec(vec![1.0, 0.0, 1.0], &[3], &device()).unwrap();
    let (v, _) = extrapolate_valid_tensor(&values, &valid, 1, 1).unwrap();
    assert_eq!(v.to_vec(), vec![2.0, 4.0, 6.0]);
}

#[test]
fn grids_on_different_domains_do_not_mix() {
    let a = CenteredGrid::<NdArray>::zeros(&unit(&[4, 4]), 1, &device());
    let b = CenteredGrid::<NdArray>::zeros(&unit(&[4, 8]), 1, &device());
    let message = a.add(&b).unwrap_err().to_string();
    assert!(
        message.contains("[4, 4]") && message.contains("[4, 8]"),
        "{message}"
    );
    let u = StaggeredGrid::<NdArray>::zeros(&unit(&[4, 8]), &device());
    assert!(advect_semi_lagrangian(&a, &u, 0.1).is_err());
}

#[test]
fn fused_extrapolation_matches_the_composite_bit_for_bit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    // (values shape, mask shape, spatial axes): one mask per site, per value, a broadcast the
    // fused kernel leaves to the composite, 1D to 3D.
    let cases: [(&[usize], &[usize], usize); 5] = [
        (&[17], &[17], 1),
        (&[9, 12, 2], &[9, 12, 1], 2),
        (&[9, 12, 2], &[9, 12, 2], 2),
        (&[5, 6, 7], &[5, 6, 7], 3),
        (&[4, 5, 2, 3], &[4, 5, 1, 3], 2),
    ];
    for (shape, mask_shape, spatial) in cases {
        let n: usize = shape.iter().product();
        let m: usize = mask_shape.iter().product();
        let values: Vec<f32> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
        // A sparse valid set, so that several layers are needed and some samples stay invalid.
        let mask: Vec<f32> = (0..m)
            .map(|_| if rng.random_bool(0.08) { 1.0 } else { 0.0 })
            .collect();
        for cells in [0, 1, 3] {
            let v = T::from_vec(values.clone(), shape, &device()).unwrap();
            let k = T::from_vec(mask.clone(), mask_shape, &device()).unwrap();
            let (fused_v, fused_k) = NdArray::float_extrapolate_valid(
                v.primitive().clone(),
                k.primitive().clone(),
                spatial,
                cells,
            )
            .unwrap();
            let (plain_v, plain_k) = kernels::composite_extrapolate_valid::<NdArray>(
                v.into_primitive(),
                k.into_primitive(),
                spatial,
                cells,
            )
            .unwrap();
            let as_bits = |t: &ndarray::ArcArray<f32, ndarray::IxDyn>| {
                t.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(fused_v.shape(), plain_v.shape(), "{shape:?}");
            assert_eq!(fused_k.shape(), plain_k.shape(), "{shape:?}");
            assert_eq!(
                as_bits(&fused_v),
                as_bits(&plain_v),
                "{shape:?}, {cells} cells"
            );
            assert_eq!(
                as_bits(&fused_k),
                as_bits(&plain_k),
                "{shape:?}, {cells} cells"
            );
            if cells == 3 {
                let grown = fused_k.iter().filter(|&&x| x == 1.0).count();
                let before = mask.iter().filter(|&&x| x == 1.0).count();
                assert!(grown > before, "{shape:?}: the valid region did not grow");
            }
        }
    }
}

#[test]
fn fused_point_advection_matches_the_composite_bit_for_bit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    for res in [vec![9], vec![7, 5], vec![4, 6, 5]] {
        let domain = unit(&res);
        let d = res.len();
        let lattices = lattice::staggered_lattices(&domain);
        let components: Vec<_> = lattices
            .iter()
            .map(|lattice| {
                let count: usize = lattice.shape.iter().product();
                let values: Vec<f32> = (0..count).map(|_| rng.random_range(-3.0..3.0)).collect();
                T::from_vec(values, &[count, 1], &device())
                    .unwrap()
                    .into_primitive()
            })
            .collect();
        // Points inside, on the edges and beyond the domain (clamped).
        let points: Vec<f32> = (0..40 * d)
            .map(|k| rng.random_range(-1.0..res[k % d] as f32 + 1.0))
            .collect();
        let points = T::from_vec(points, &[40, d], &device()).unwrap();
        for integrator in [Integrator::Euler, Integrator::Rk4] {
            let fused = NdArray::float_advect_points(
                &lattices,
                &components,
                points.primitive().clone(),
                0.7,
                integrator,
            )
            .unwrap();
            let plain = kernels::composite_advect_points::<NdArray>(
                &lattices,
                &components,
                points.primitive().clone(),
                0.7,
                integrator,
            )
            .unwrap();
            let bits = |t: &ndarray::ArcArray<f32, ndarray::IxDyn>| {
                t.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(fused.shape(), plain.shape());
            assert_eq!(bits(&fused), bits(&plain), "{res:?} {integrator:?}");
        }
    }
}

#[test]
fn fused_lattice_transfers_match_the_composite_bit_for_bit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    let bits = |t: &ndarray::ArcArray<f32, ndarray::IxDyn>| {
        t.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    for res in [vec![9], vec![7, 5], vec![4, 6, 5]] {
        let domain = unit(&res);
        let d = res.len();
        // Not a whole number of the kernels' blocks; inside, on the edges and beyond the domain.
        let n = 37;
        let points: Vec<f32> = (0..n * d)
            .map(|k| rng.random_range(-1.0..res[k % d] as f32 + 1.0))
            .collect();
        let points = T::from_vec(points, &[n, d], &device()).unwrap();
        for lattice in lattice::staggered_lattices(&domain) {
            let samples: usize = lattice.shape.iter().product();
            for c in [1, 3] {
                let grid: Vec<f32> = (0..samples * c)
                    .map(|_| rng.random_range(-3.0..3.0))
                    .collect();
                let grid = T::from_vec(grid, &[samples, c], &device()).unwrap();
                let fused = NdArray::float_lattice_sample(
                    &lattice,
                    grid.primitive().clone(),
                    points.primitive().clone(),
                )
                .unwrap();
                let plain = lattice::composite_lattice_sample::<NdArray>(
                    &lattice,
                    grid.primitive().clone(),
                    points.primitive().clone(),
                )
                .unwrap();
                assert_eq!(bits(&fused), bits(&plain), "sample {res:?} c = {c}");
                let values: Vec<f32> = (0..n * c).map(|_| rng.random_range(-3.0..3.0)).collect();
                let values = T::from_vec(values, &[n, c], &device()).unwrap();
                for transfer in [Transfer::Linear, Transfer::NearestFace] {
                    let (fused_sums, fused_weights) = NdArray::float_lattice_splat(
                        &lattice,
                        points.primitive().clone(),
                        values.primitive().clone(),
                        transfer,
                    )
                    .unwrap();
                    let (plain_sums, plain_weights) = lattice::composite_lattice_splat::<NdArray>(
                        &lattice,
                        points.primitive().clone(),
                        values.primitive().clone(),
                        transfer,
                    )
                    .unwrap();
                    let case = format!("splat {res:?} c = {c} {transfer:?}");
                    assert_eq!(bits(&fused_sums), bits(&plain_sums), "{case}");
                    assert_eq!(bits(&fused_weights), bits(&plain_weights), "{case}");
                }
            }
        }
        // All components in one call (interleaved on ndarray): each column lands as the
        // composite splats it alone.
        let lattices = lattice::staggered_lattices(&domain);
        let values: Vec<f32> = (0..n * d).map(|_| rng.random_range(-3.0..3.0)).collect();
        let values = T::from_vec(values, &[n, d], &device()).unwrap();
        for transfer in [Transfer::Linear, Transfer::NearestFace] {
            let fused = NdArray::float_lattice_splat_columns(
                &lattices,
                points.primitive().clone(),
                values.primitive().clone(),
                transfer,
            )
            .unwrap();
            assert_eq!(fused.len(), d);
            for (j, (lattice, (sums, weights))) in lattices.iter().zip(&fused).enumerate() {
                let column = values.narrow(1, j..j + 1).unwrap();
                let (plain_sums, plain_weights) = lattice::composite_lattice_splat::<NdArray>(
                    lattice,
                    points.primitive().clone(),
                    column.primitive().clone(),
                    transfer,
                )
                .unwrap();
                let case = format!("column splat {res:?} component {j} {transfer:?}");
                assert_eq!(bits(sums), bits(&plain_sums), "{case}");
                assert_eq!(bits(weights), bits(&plain_weights), "{case}");
            }
        }
        // All components sampled in one call: each column as the composite samples it alone.
        let components: Vec<_> = lattices
            .iter()
            .map(|lattice| {
                let samples: usize = lattice.shape.iter().product();
                let grid: Vec<f32> = (0..samples).map(|_| rng.random_range(-3.0..3.0)).collect();
                T::from_vec(grid, &[samples, 1], &device())
                    .unwrap()
                    .into_primitive()
            })
            .collect();
        let fused = T::from_primitive(
            NdArray::float_lattice_sample_columns(
                &lattices,
                &components,
                points.primitive().clone(),
            )
            .unwrap(),
        );
        assert_eq!(fused.shape(), [n, d]);
        for (j, (lattice, grid)) in lattices.iter().zip(&components).enumerate() {
            let plain = lattice::composite_lattice_sample::<NdArray>(
                lattice,
                grid.clone(),
                points.primitive().clone(),
            )
            .unwrap();
            let column = fused.narrow(1, j..j + 1).unwrap().into_primitive();
            assert_eq!(
                bits(&column),
                bits(&plain),
                "column sample {res:?} component {j}"
            );
        }
    }
}
