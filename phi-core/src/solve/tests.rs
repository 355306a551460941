//! Tests of the host-side solvers and the Poisson assembly on plain grids.

use rand::{Rng, SeedableRng};

use super::*;

pub(crate) const ALL_METHODS: [SolveMethod; 7] = [
    SolveMethod::Auto,
    SolveMethod::Cholesky,
    SolveMethod::Lu,
    SolveMethod::ConjugateGradient(Preconditioner::None),
    SolveMethod::ConjugateGradient(Preconditioner::Jacobi),
    SolveMethod::ConjugateGradient(Preconditioner::IncompleteCholesky),
    SolveMethod::ConjugateGradient(Preconditioner::ModifiedIncompleteCholesky),
];

/// A random sparse symmetric positive definite matrix: a random symmetric pattern with a
/// dominant diagonal.
fn random_spd(n: usize, per_row: usize, seed: u64) -> SparseMatrix {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut triplets = Vec::new();
    let mut row_sums = vec![0.0f64; n];
    for i in 0..n {
        for _ in 0..per_row {
            let j = rng.random_range(0..n);
            if j == i {
                continue;
            }
            let v: f64 = rng.random_range(-1.0..1.0);
            triplets.push((i, j, v));
            triplets.push((j, i, v));
            row_sums[i] += v.abs();
            row_sums[j] += v.abs();
        }
    }
    for (i, s) in row_sums.iter().enumerate() {
        triplets.push((i, i, s + rng.random_range(0.1..1.0)));
    }
    SparseMatrix::from_triplets(n, n, &triplets).unwrap()
}

pub(crate) fn random_vec(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn residual(a: &SparseMatrix, x: &[f64], b: &[f64]) -> f64 {
    let ax = a.mul_vec(x);
    norm(&ax.iter().zip(b).map(|(p, q)| p - q).collect::<Vec<_>>())
}

/// Every face of `grid` open.
fn all_faces_open(grid: &PoissonGrid<'_>) -> Vec<Vec<bool>> {
    (0..grid.dim())
        .map(|axis| vec![true; grid.face_count(axis)])
        .collect()
}

/// The sides of a closed tank with an open top (the upper side of the last axis).
fn open_top(d: usize) -> Vec<[bool; 2]> {
    let mut open_sides = vec![[false; 2]; d];
    open_sides[d - 1][1] = true;
    open_sides
}

/// The 2-d or 3-d Poisson matrix on a closed box of unit cells with an open top, every cell
/// liquid.
fn box_poisson(resolution: &[usize]) -> PoissonSystem {
    let d = resolution.len();
    let grid = PoissonGrid {
        resolution,
        cell_size: &vec![1.0; d],
        open_sides: &open_top(d),
    };
    let liquid = vec![true; grid.cell_count()];
    PoissonSystem::assemble(&grid, &liquid, &all_faces_open(&grid)).unwrap()
}

#[test]
fn every_method_reaches_the_tolerance_on_random_spd_systems() {
    for (seed, n) in [(1u64, 50usize), (2, 300), (3, 1000)] {
        let a = random_spd(n, 4, seed);
        assert!(a.is_symmetric());
        let b = random_vec(n, seed + 100);
        for method in ALL_METHODS {
            let options = SolveOptions {
                relative_tolerance: 1e-8,
                ..SolveOptions::with_method(method)
            };
            let (x, stats) = solve(&a, &b, 1, &options).unwrap();
            let r = residual(&a, &x, &b);
            assert!(r <= 1e-8 * norm(&b), "{method:?} n={n}: residual {r}");
            assert!(
                (stats.residual - r).abs() <= 1e-12 + 1e-6 * r,
                "{method:?}: reported residual {} against {r}",
                stats.residual
            );
            if matches!(method, SolveMethod::ConjugateGradient(_)) {
                assert!(stats.iterations > 0 && stats.iterations <= options.max_iterations);
            }
        }
    }
}

#[test]
fn several_right_hand_sides_and_transposed_solves() {
    let n = 40;
    let a = random_spd(n, 3, 7);
    let b1 = random_vec(n, 8);
    let b2 = random_vec(n, 9);
    let both: Vec<f64> = (0..n).flat_map(|i| [b1[i], b2[i]]).collect();
    let (x, _) = solve(&a, &both, 2, &SolveOptions::default()).unwrap();
    let (x1, _) = solve(&a, &b1, 1, &SolveOptions::default()).unwrap();
    let (x2, _) = solve(&a, &b2, 1, &SolveOptions::default()).unwrap();
    for i in 0..n {
        assert!((x[2 * i] - x1[i]).abs() < 1e-9 && (x[2 * i + 1] - x2[i]).abs() < 1e-9);
    }

    // A non-symmetric matrix: LU, and the transposed solve solves Aᵀ y = b.
    let mut dense = vec![0.0; 9];
    dense.copy_from_slice(&[4.0, 1.0, 0.0, 2.0, 5.0, 1.0, 0.0, 3.0, 6.0]);
    let m = SparseMatrix::from_dense(3, 3, &dense).unwrap();
    assert!(!m.is_symmetric());
    let b = [1.0, 2.0, 3.0];
    let (x, _) = solve(&m, &b, 1, &SolveOptions::default()).unwrap();
    assert!(residual(&m, &x, &b) < 1e-12);
    let (y, _) = solve_transpose(&m, &b, 1, &SolveOptions::default()).unwrap();
    assert!(residual(&m.transpose(), &y, &b) < 1e-12);
    let cg = SolveOptions::with_method(SolveMethod::ConjugateGradient(Preconditioner::Jacobi));
    assert!(matches!(
        solve(&m, &b, 1, &cg),
        Err(SolveError::Invalid { .. })
    ));
}

#[test]
fn poisson_systems_reach_the_tolerance() {
    for resolution in [vec![16, 16], vec![8, 8, 8]] {
        let system = box_poisson(&resolution);
        let a = &system.matrix;
        let b = random_vec(a.nrows(), 11);
        for method in ALL_METHODS {
            let options = SolveOptions::with_method(method);
            let (x, stats) = solve(a, &b, 1, &options).unwrap();
            let r = residual(a, &x, &b);
            assert!(r <= 1e-5 * norm(&b), "{method:?}: residual {r}");
            assert!(stats.residual <= 1e-5 * norm(&b));
        }
    }
}

#[test]
fn non_convergence_is_an_error() {
    let system = box_poisson(&[32, 32]);
    let b = random_vec(system.matrix.nrows(), 3);
    for pre in [
        Preconditioner::None,
        Preconditioner::Jacobi,
        Preconditioner::IncompleteCholesky,
        Preconditioner::ModifiedIncompleteCholesky,
    ] {
        let options = SolveOptions {
            max_iterations: 2,
            ..SolveOptions::with_method(SolveMethod::ConjugateGradient(pre))
        };
        match solve(&system.matrix, &b, 1, &options) {
            Err(SolveError::NotConverged {
                iterations,
                residual,
                tolerance,
            }) => {
                assert_eq!(iterations, 2);
                assert!(residual > tolerance && tolerance > 0.0);
            }
            other => panic!("{pre:?}: expected NotConverged, got {other:?}"),
        }
    }
}

#[test]
fn nan_and_bad_sizes_are_errors() {
    let system = box_poisson(&[8, 8]);
    let mut b = random_vec(64, 5);
    b[17] = f64::NAN;
    for method in ALL_METHODS {
        assert!(matches!(
            solve(&system.matrix, &b, 1, &SolveOptions::with_method(method)),
            Err(SolveError::NonFinite { .. })
        ));
    }
    let b32 = vec![f32::INFINITY; 64];
    assert!(matches!(
        solve_f32(&system.matrix, &b32, 1, &SolveOptions::default()),
        Err(SolveError::NonFinite { .. })
    ));
    assert!(matches!(
        solve(&system.matrix, &[1.0; 63], 1, &SolveOptions::default()),
        Err(SolveError::DimensionMismatch {
            expected: 64,
            got: 63,
            ..
        })
    ));
    let rectangular = SparseMatrix::from_triplets(2, 3, &[(0, 0, 1.0)]).unwrap();
    assert!(matches!(
        solve(&rectangular, &[1.0, 1.0], 1, &SolveOptions::default()),
        Err(SolveError::DimensionMismatch { .. })
    ));
    // Indefinite: Cholesky and CG refuse instead of answering.
    let indefinite = SparseMatrix::from_dense(2, 2, &[1.0, 2.0, 2.0, 1.0]).unwrap();
    assert!(matches!(
        solve(
            &indefinite,
            &[1.0, 0.0],
            1,
            &SolveOptions::with_method(SolveMethod::Cholesky)
        ),
        Err(SolveError::Factorization { .. })
    ));
}

/// Face counts follow the MAC layout, and a grid that cannot carry a Poisson matrix is an error
/// saying what is wrong, not a panic.
#[test]
fn poisson_grids_are_checked() {
    let open_sides = [[false; 2], [false, true]];
    let grid = PoissonGrid {
        resolution: &[3, 2],
        cell_size: &[1.0, 0.5],
        open_sides: &open_sides,
    };
    assert_eq!((grid.dim(), grid.cell_count()), (2, 6));
    assert_eq!((grid.face_count(0), grid.face_count(1)), (8, 9));
    let liquid = [true; 6];
    let faces = all_faces_open(&grid);
    let system = PoissonSystem::assemble(&grid, &liquid, &faces).unwrap();
    assert_eq!(system.unknowns(), 6);
    assert!(system.pinned.is_empty(), "the open top anchors the region");

    let assemble = |grid: PoissonGrid<'_>| PoissonSystem::assemble(&grid, &liquid, &faces);
    let invalid = |result: Result<PoissonSystem, SolveError>, needle: &str| match result {
        Err(SolveError::Invalid { reason }) => {
            assert!(reason.contains(needle), "{reason:?} should name {needle:?}")
        }
        other => panic!("expected Invalid naming {needle:?}, got {other:?}"),
    };
    invalid(
        assemble(PoissonGrid {
            resolution: &[1, 1, 2, 3],
            cell_size: &[1.0; 4],
            open_sides: &[[false; 2]; 4],
        }),
        "not 4",
    );
    invalid(
        assemble(PoissonGrid {
            resolution: &[],
            cell_size: &[],
            open_sides: &[],
        }),
        "not 0",
    );
    invalid(
        assemble(PoissonGrid {
            resolution: &[6, 0],
            ..grid
        }),
        "axis 1",
    );
    for h in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        invalid(
            assemble(PoissonGrid {
                cell_size: &[1.0, h],
                ..grid
            }),
            "axis 1",
        );
    }
    assert!(matches!(
        assemble(PoissonGrid {
            cell_size: &[1.0],
            ..grid
        }),
        Err(SolveError::DimensionMismatch {
            expected: 2,
            got: 1,
            ..
        })
    ));
    assert!(matches!(
        assemble(PoissonGrid {
            open_sides: &open_sides[..1],
            ..grid
        }),
        Err(SolveError::DimensionMismatch {
            expected: 2,
            got: 1,
            ..
        })
    ));
    let short_faces = [vec![true; 8], vec![true; 8]];
    assert!(matches!(
        PoissonSystem::assemble(&grid, &liquid, &short_faces),
        Err(SolveError::DimensionMismatch {
            expected: 9,
            got: 8,
            ..
        })
    ));
}

#[test]
fn grid_elimination_orders_are_permutations() {
    for resolution in [
        vec![1, 7],
        vec![33, 17],
        vec![64, 64],
        vec![5, 3, 2],
        vec![9, 16, 11],
    ] {
        let order = grid_elimination_order(&resolution);
        let cells: usize = resolution.iter().product();
        let mut seen = vec![false; cells];
        for &cell in order.iter() {
            assert!(!seen[cell as usize], "{resolution:?}: cell {cell} twice");
            seen[cell as usize] = true;
        }
        assert!(seen.iter().all(|&s| s), "{resolution:?}: a cell is missing");
    }
}

/// A closed tank of unit cells (open top) holding a pool of a third of its height and a ball of
/// liquid above, like a FLIP step's liquid cells.
fn pool_and_ball(resolution: &[usize]) -> PoissonSystem {
    let d = resolution.len();
    let grid = PoissonGrid {
        resolution,
        cell_size: &vec![1.0; d],
        open_sides: &open_top(d),
    };
    let mut liquid = Vec::with_capacity(grid.cell_count());
    let mut index = vec![0usize; d];
    for cell in 0..grid.cell_count() {
        let mut rest = cell;
        for axis in (0..d).rev() {
            index[axis] = rest % resolution[axis];
            rest /= resolution[axis];
        }
        let height = index[d - 1] as f64 / resolution[d - 1] as f64;
        let ball: f64 = (0..d)
            .map(|a| {
                let centre = if a == d - 1 { 0.7 } else { 0.4 };
                (index[a] as f64 / resolution[a] as f64 - centre).powi(2)
            })
            .sum();
        liquid.push(height < 0.33 || ball < 0.04);
    }
    PoissonSystem::assemble(&grid, &liquid, &all_faces_open(&grid)).unwrap()
}

/// The same matrix without an elimination order (faer's AMD then orders it).
fn without_ordering(a: &SparseMatrix) -> SparseMatrix {
    SparseMatrix::from_csr(
        a.nrows(),
        a.ncols(),
        a.row_ptr().to_vec(),
        a.col_indices().to_vec(),
        a.values().to_vec(),
    )
    .unwrap()
}

#[test]
fn grid_ordered_cholesky_matches_amd_and_keeps_the_fill_small() {
    for (resolution, system) in [
        (vec![64, 64], box_poisson(&[64, 64])),
        (vec![64, 64], pool_and_ball(&[64, 64])),
        (vec![33, 20], pool_and_ball(&[33, 20])),
    ] {
        let ordered = &system.matrix;
        assert!(ordered.ordering().is_some());
        let amd = without_ordering(ordered);
        let b = random_vec(ordered.nrows(), 5);
        let options = SolveOptions::with_method(SolveMethod::Cholesky);
        let (x_ordered, _) = solve(ordered, &b, 1, &options).unwrap();
        let (x_amd, _) = solve(&amd, &b, 1, &options).unwrap();
        let scale = norm(&x_amd);
        let difference = norm(
            &x_ordered
                .iter()
                .zip(&x_amd)
                .map(|(p, q)| p - q)
                .collect::<Vec<_>>(),
        );
        assert!(
            difference <= 1e-10 * scale,
            "{resolution:?}: {difference} vs {scale}"
        );
        assert!(residual(ordered, &x_ordered, &b) <= 1e-9 * norm(&b));

        // Fill: the grid's AMD order restricted to the liquid stays within 1.25× of an AMD
        // analysis of the matrix itself, and the full tank's is far below the natural
        // (banded) order.
        let natural = without_ordering(ordered)
            .with_ordering((0..ordered.nrows()).collect())
            .unwrap();
        let fill = |m: &SparseMatrix| m.cholesky().unwrap().factor_entries().unwrap();
        let (restricted, amd, banded) = (
            fill(ordered),
            factor::amd_factor_entries(ordered.csr()),
            fill(&natural),
        );
        println!(
            "{resolution:?}: factor entries: grid order {restricted}, AMD {amd}, natural {banded}"
        );
        assert!(
            restricted as f64 <= 1.25 * amd as f64,
            "{resolution:?}: {restricted} vs AMD {amd}"
        );
        if system.unknowns() == system.cell_to_unknown.len() {
            assert!(
                2 * restricted < banded,
                "{resolution:?}: {restricted} vs {banded}"
            );
        }
    }
}

#[test]
fn elimination_orders_must_be_permutations() {
    let a = random_spd(5, 2, 1);
    for order in [vec![0, 1, 2, 3], vec![0, 1, 2, 3, 3], vec![0, 1, 2, 3, 5]] {
        assert!(matches!(
            a.clone().with_ordering(order),
            Err(SolveError::Invalid { .. })
        ));
    }
    let reversed = a.clone().with_ordering(vec![4, 3, 2, 1, 0]).unwrap();
    let b = random_vec(5, 2);
    let (x, _) = solve(
        &reversed,
        &b,
        1,
        &SolveOptions::with_method(SolveMethod::Cholesky),
    )
    .unwrap();
    assert!(residual(&a, &x, &b) <= 1e-12 * norm(&b));
}

/// Matrices of one pattern share a symbolic analysis (cached per thread): the factorization of
/// each must still be its own. Three systems of the same pattern with different values, factorised
/// in turn and twice, each solved to the tolerance; a different pattern in between does not
/// disturb them.
#[test]
fn ordered_factorizations_of_one_pattern_are_each_their_own() {
    let base = pool_and_ball(&[24, 20]);
    let scaled = |factor: f64, shift: f64| {
        let m = &base.matrix;
        let mut values = m.values().to_vec();
        for row in 0..m.nrows() {
            let entries = m.row_ptr()[row]..m.row_ptr()[row + 1];
            for (value, &col) in values[entries.clone()]
                .iter_mut()
                .zip(&m.col_indices()[entries])
            {
                *value *= factor;
                if col == row {
                    *value += shift;
                }
            }
        }
        SparseMatrix::from_csr(
            m.nrows(),
            m.ncols(),
            m.row_ptr().to_vec(),
            m.col_indices().to_vec(),
            values,
        )
        .unwrap()
        .with_ordering(m.ordering().unwrap().to_vec())
        .unwrap()
    };
    let options = SolveOptions::with_method(SolveMethod::Cholesky);
    let b = random_vec(base.matrix.nrows(), 9);
    let other = box_poisson(&[17, 9]);
    for round in 0..2 {
        for (factor, shift) in [(1.0, 0.0), (2.5, 0.0), (0.7, 3.0)] {
            let a = scaled(factor, shift);
            let (x, _) = solve(&a, &b, 1, &options).unwrap();
            assert!(
                residual(&a, &x, &b) <= 1e-9 * norm(&b),
                "round {round}, ×{factor} + {shift}: residual {}",
                residual(&a, &x, &b)
            );
            let c = random_vec(other.matrix.nrows(), 3);
            let (y, _) = solve(&other.matrix, &c, 1, &options).unwrap();
            assert!(residual(&other.matrix, &y, &c) <= 1e-9 * norm(&c));
        }
    }
}

/// A random 2-d pressure system on cells of size 0.5: random liquid blobs (often several disjoint
/// regions, some sealed), random obstacle faces (blocked or partly open), random open or closed
/// sides.
fn random_grid_poisson(seed: u64) -> PoissonSystem {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let resolution = [rng.random_range(3..40usize), rng.random_range(3..40usize)];
    let open_sides: Vec<[bool; 2]> = (0..2)
        .map(|_| [0, 1].map(|_| rng.random_bool(0.3)))
        .collect();
    let grid = PoissonGrid {
        resolution: &resolution,
        cell_size: &[0.5, 0.5],
        open_sides: &open_sides,
    };
    // Blobs: discs of random centres and radii; a few cells of air scattered inside.
    let blobs: Vec<(f64, f64, f64)> = (0..rng.random_range(1..5))
        .map(|_| {
            (
                rng.random_range(0.0..resolution[0] as f64),
                rng.random_range(0.0..resolution[1] as f64),
                rng.random_range(1.0..12.0),
            )
        })
        .collect();
    let liquid: Vec<bool> = (0..grid.cell_count())
        .map(|cell| {
            let (i, j) = ((cell / resolution[1]) as f64, (cell % resolution[1]) as f64);
            let inside = blobs
                .iter()
                .any(|&(x, y, r)| (i - x).powi(2) + (j - y).powi(2) < r * r);
            inside && !rng.random_bool(0.05)
        })
        .collect();
    let faces: Vec<Vec<f64>> = (0..2)
        .map(|axis| {
            (0..grid.face_count(axis))
                .map(|_| match rng.random_range(0..10) {
                    0 => 0.0,
                    1 => rng.random_range(0.05..1.0),
                    _ => 1.0,
                })
                .collect()
        })
        .collect();
    PoissonSystem::assemble(&grid, &liquid, &faces).unwrap()
}

/// The up-looking factorization against faer's (AMD ordering, and the same grid order): the
/// same solution to rounding and the same fill on random grid systems with obstacles, several
/// regions and a new pattern each time.
#[test]
fn up_looking_cholesky_matches_faer_on_random_grid_systems() {
    use super::up_looking::UpLookingCholesky;
    let mut tested = 0;
    for seed in 0..60 {
        let system = random_grid_poisson(seed);
        let a = &system.matrix;
        if a.nrows() == 0 {
            continue;
        }
        tested += 1;
        let order = a.ordering().expect("2-d systems carry the grid order");
        let factor = UpLookingCholesky::factorize(a.csr(), order).unwrap();
        let b = random_vec(a.nrows(), seed + 100);
        let x = factor.solve(&b);
        let amd = without_ordering(a);
        let (x_amd, _) = solve(
            &amd,
            &b,
            1,
            &SolveOptions::with_method(SolveMethod::Cholesky),
        )
        .expect("faer factorises the same matrix");
        let difference = norm(&x.iter().zip(&x_amd).map(|(p, q)| p - q).collect::<Vec<_>>());
        assert!(
            difference <= 1e-10 * norm(&x_amd),
            "seed {seed}: {difference} vs {}",
            norm(&x_amd)
        );
        assert!(residual(a, &x, &b) <= 1e-10 * norm(&b), "seed {seed}");
        // The same elimination order gives the same factor structure as faer's analysis.
        let faer_ordered = factor::ordered_cholesky(a.csr(), order.to_vec().into()).unwrap();
        assert_eq!(
            Some(factor.entries()),
            faer_ordered.factor_entries(),
            "seed {seed}: fill"
        );
    }
    assert!(tested > 50);
}

/// General sparse SPD matrices (not grids) in random elimination orders, and several
/// right-hand sides through the cached factor.
#[test]
fn up_looking_cholesky_solves_random_spd_matrices_in_any_order() {
    use super::up_looking::UpLookingCholesky;
    use rand::seq::SliceRandom;
    for (n, per_row, seed) in [(1, 0, 1), (2, 1, 2), (40, 2, 3), (300, 3, 4), (800, 5, 5)] {
        let a = random_spd(n, per_row, seed);
        let mut order: Vec<usize> = (0..n).collect();
        order.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
        let factor = UpLookingCholesky::factorize(a.csr(), &order).unwrap();
        for column in 0..3 {
            let b = random_vec(n, seed * 10 + column);
            let x = factor.solve(&b);
            assert!(residual(&a, &x, &b) <= 1e-12 * norm(&b), "n {n}");
        }
        // Through the solver: the ordered matrix takes the up-looking path.
        let ordered = a.clone().with_ordering(order).unwrap();
        let b = random_vec(n, seed);
        let options = SolveOptions::with_method(SolveMethod::Cholesky);
        let (x, stats) = solve(&ordered, &b, 1, &options).unwrap();
        assert_eq!(stats.iterations, 0);
        assert!(residual(&a, &x, &b) <= 1e-12 * norm(&b));
    }
}

/// A symmetric matrix that is not positive definite is a factorization error, not a wrong
/// solution; so is a matrix with a missing diagonal entry.
#[test]
fn up_looking_cholesky_rejects_indefinite_matrices() {
    let options = SolveOptions::with_method(SolveMethod::Cholesky);
    let indefinite =
        SparseMatrix::from_dense(3, 3, &[2.0, 1.0, 0.0, 1.0, -1.0, 1.0, 0.0, 1.0, 2.0])
            .unwrap()
            .with_ordering(vec![2, 0, 1])
            .unwrap();
    assert!(matches!(
        solve(&indefinite, &[1.0, 2.0, 3.0], 1, &options),
        Err(SolveError::Factorization { .. })
    ));
    let no_diagonal = SparseMatrix::from_dense(2, 2, &[0.0, 1.0, 1.0, 0.0])
        .unwrap()
        .with_ordering(vec![0, 1])
        .unwrap();
    assert!(matches!(
        solve(&no_diagonal, &[1.0, 2.0], 1, &options),
        Err(SolveError::Factorization { .. })
    ));
}

/// The regions of random grid systems: the connected components of the matrix's graph (checked
/// against a union-find), numbered in order of their first unknown, a pin in exactly the ones
/// that touch neither air nor an open side (their rows sum to zero but for the pin).
#[test]
fn regions_are_the_connected_components() {
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            x = parent[x];
        }
        x
    }
    for seed in 0..40 {
        let system = random_grid_poisson(seed);
        let a = &system.matrix;
        let n = a.nrows();
        let mut parent: Vec<usize> = (0..n).collect();
        for u in 0..n {
            for (v, _) in a.row(u) {
                let (ru, rv) = (find(&mut parent, u), find(&mut parent, v));
                parent[ru.max(rv)] = ru.min(rv);
            }
        }
        let mut next_region = 0;
        for u in 0..n {
            let root = find(&mut parent, u);
            if root == u {
                assert_eq!(system.region_of[u], next_region, "seed {seed}: numbering");
                next_region += 1;
            } else {
                assert_eq!(system.region_of[u], system.region_of[root], "seed {seed}");
            }
        }
        assert_eq!(system.region_is_singular.len(), next_region);
        // A region is singular exactly when every row sums to zero (no Dirichlet term), the
        // pinned row aside.
        let mut unanchored = vec![true; next_region];
        for u in 0..n {
            let sum: f64 = a.row(u).map(|(_, v)| v).sum();
            if sum.abs() > 1e-9 && !system.pinned.contains(&u) {
                unanchored[system.region_of[u]] = false;
            }
        }
        assert_eq!(unanchored, system.region_is_singular, "seed {seed}");
        assert_eq!(
            system.pinned.len(),
            unanchored.iter().filter(|&&s| s).count()
        );
    }
}

/// The split product (diagonal, neighbouring rows, padded far entries) equals the CSR product,
/// for narrow and wide rows (the fixed-width kernels and the general one), odd and even sizes.
#[test]
fn split_product_equals_the_csr_product() {
    use super::mic::SplitMatrix;
    let far_entries =
        |a: &SparseMatrix, i: usize| a.row(i).filter(|&(j, _)| j + 1 < i || j > i + 1).count();
    let mut widths = Vec::new();
    for (n, per_row, seed) in [
        (1, 0, 1),
        (2, 1, 2),
        (7, 1, 3),
        (64, 2, 4),
        (301, 2, 5),
        (300, 3, 6),
        (300, 3, 7),
    ] {
        let a = random_spd(n, per_row, seed);
        let width = (0..n).map(|i| far_entries(&a, i)).max().unwrap();
        let Some(split) = SplitMatrix::new(a.csr()) else {
            assert!(width > 8, "n {n}: refused a layout of width {width}");
            continue;
        };
        widths.push(width);
        let x = random_vec(n, seed + 50);
        let mut y = vec![0.0; n];
        split.mul_vec_into(&x, &mut y);
        let want = a.mul_vec(&x);
        for i in 0..n {
            assert!(
                (y[i] - want[i]).abs() <= 1e-12 * (1.0 + want[i].abs()),
                "n {n} row {i}"
            );
        }
    }
    // Both the fixed-width kernels and the general one ran.
    assert!(
        widths.iter().any(|&w| w <= 4) && widths.iter().any(|&w| w > 4),
        "{widths:?}"
    );
    // A row with more far entries than the layout takes: no split.
    let wide = random_spd(40, 12, 6);
    assert!((0..40).any(|i| far_entries(&wide, i) > 8));
    assert!(SplitMatrix::new(wide.csr()).is_none());
}

/// A matrix whose elimination drops no fill (a tree, children numbered before their parents)
/// has MIC(0) equal to its exact Cholesky factorization: applying the preconditioner inverts
/// the matrix. Parents at distance one use the register coupling, the others the far entries;
/// odd and even sizes exercise both ends of the paired substitutions.
#[test]
fn mic0_is_exact_where_no_fill_is_dropped() {
    use super::mic::{ModifiedIncompleteCholesky, SplitMatrix};
    let mut rng = rand::rngs::StdRng::seed_from_u64(21);
    for n in [1usize, 2, 3, 8, 9, 100, 101] {
        let mut triplets = Vec::new();
        let mut degree = vec![0.0f64; n];
        for child in 0..n.saturating_sub(1) {
            // The parent: the next row half of the time, else any later row.
            let parent = if rng.random_bool(0.5) {
                child + 1
            } else {
                rng.random_range(child + 1..n)
            };
            let w: f64 = rng.random_range(0.5..2.0);
            triplets.push((child, parent, -w));
            triplets.push((parent, child, -w));
            degree[child] += w;
            degree[parent] += w;
        }
        for (i, d) in degree.iter().enumerate() {
            triplets.push((i, i, d + rng.random_range(0.1..1.0)));
        }
        let a = SparseMatrix::from_triplets(n, n, &triplets).unwrap();
        let split = SplitMatrix::new(a.csr()).expect("short rows");
        let mic = ModifiedIncompleteCholesky::new(&split).expect("an M-matrix");
        let x = random_vec(n, n as u64);
        let ax = a.mul_vec(&x);
        let mut back = vec![0.0; n];
        let dot = mic.apply(&ax, &mut back);
        let want: f64 = ax.iter().zip(&back).map(|(a, b)| a * b).sum();
        assert!(
            (dot - want).abs() <= 1e-10 * (1.0 + want.abs()),
            "n {n}: rᵀz {dot} against {want}"
        );
        for i in 0..n {
            assert!(
                (back[i] - x[i]).abs() <= 1e-10,
                "n {n} row {i}: {} against {}",
                back[i],
                x[i]
            );
        }
    }
}

/// On Poisson matrices MIC(0) keeps the matrix's row sums up to the dropped share `1 − τ`, which
/// removes the smooth error modes: it needs clearly fewer iterations than IC(0), and the gap
/// grows with the grid (IC(0)'s count grows like the side, MIC(0)'s like its square root).
#[test]
fn mic0_needs_fewer_iterations_than_ic0_on_poisson_matrices() {
    let iterations = |system: &PoissonSystem, pre: Preconditioner| {
        let b = random_vec(system.matrix.nrows(), 5);
        let options = SolveOptions::with_method(SolveMethod::ConjugateGradient(pre));
        let (x, stats) = solve(&system.matrix, &b, 1, &options).unwrap();
        assert!(residual(&system.matrix, &x, &b) <= 1e-5 * norm(&b));
        stats.iterations
    };
    let mut ratios = Vec::new();
    for resolution in [vec![32, 32], vec![128, 128], vec![16, 16, 16]] {
        let system = box_poisson(&resolution);
        assert!(system.matrix.is_stencil_m_matrix());
        let ic = iterations(&system, Preconditioner::IncompleteCholesky);
        let mic = iterations(&system, Preconditioner::ModifiedIncompleteCholesky);
        assert!(
            (mic as f64) < 0.8 * ic as f64,
            "{resolution:?}: MIC(0) {mic} iterations, IC(0) {ic}"
        );
        ratios.push(mic as f64 / ic as f64);
    }
    assert!(
        ratios[1] < ratios[0],
        "the gap grows with the grid: {ratios:?}"
    );
}

/// Auto takes MIC(0) conjugate gradients for stencil M-matrices and the previous choices for
/// other symmetric matrices.
#[test]
fn auto_picks_mic0_for_stencil_m_matrices() {
    let poisson = box_poisson(&[24, 24]);
    assert!(poisson.matrix.is_stencil_m_matrix());
    let b = random_vec(poisson.matrix.nrows(), 3);
    let (_, stats) = solve(&poisson.matrix, &b, 1, &SolveOptions::default()).unwrap();
    assert!(stats.iterations > 0, "an iterative solve");
    // Mixed signs off the diagonal: not an M-matrix, factorised.
    let spd = random_spd(200, 2, 9);
    assert!(!spd.is_stencil_m_matrix());
    let b = random_vec(200, 4);
    let (_, stats) = solve(&spd, &b, 1, &SolveOptions::default()).unwrap();
    assert_eq!(stats.iterations, 0);
}
