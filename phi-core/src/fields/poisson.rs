//! The Poisson system of a pressure projection on a [`Domain`]: the domain's grid, cell sizes and
//! side conditions handed to the solvers' assembly ([`PoissonSystem::assemble`]).

use crate::solve::{PoissonGrid, PoissonSystem, SolveError, Weight};

use super::domain::{Boundary, Domain};

/// Every face open: `face_open` for [`poisson_matrix`] on a domain without obstacles (the
/// domain's own sides still follow its [`Boundary`] conditions).
pub fn all_faces_open(domain: &Domain) -> Vec<Vec<bool>> {
    (0..domain.dim())
        .map(|axis| vec![true; domain.staggered_shape(axis).iter().product()])
        .collect()
}

/// The masked Poisson system of the pressure projection on `domain` (thesis eq. 2.9): the
/// negative Laplacian over the liquid cells, `p = 0` in air, no flux through
/// [`Boundary::Closed`] sides and blocked faces, air beyond [`Boundary::Open`] sides, one pinned
/// cell in each pure-Neumann region (see [`PoissonSystem::assemble`] for the stencil and the
/// pins).
///
/// - `liquid`: one flag per cell, row-major over `domain.resolution()` (a [`Weight`] above `0.5`
///   is liquid).
/// - `face_open[axis]`: one weight per face of staggered component `axis`, row-major over
///   `domain.staggered_shape(axis)`, in `[0, 1]` (`0`: a wall or an obstacle, `1`: open).
///
/// # Errors
/// [`SolveError::DimensionMismatch`] when `liquid` or a face array has the wrong length or there
/// is not one face array per axis.
pub fn poisson_matrix<L: Weight, W: Weight, F: AsRef<[W]>>(
    domain: &Domain,
    liquid: &[L],
    face_open: &[F],
) -> Result<PoissonSystem, SolveError> {
    // A domain has at most three axes; arrays on the stack, since this runs every step.
    let d = domain.dim();
    let mut cell_size = [0.0f64; 3];
    let mut open_sides = [[false; 2]; 3];
    for (axis, (&h, sides)) in domain
        .cell_size()
        .iter()
        .zip(domain.boundaries())
        .enumerate()
    {
        cell_size[axis] = f64::from(h);
        open_sides[axis] = sides.map(|side| side == Boundary::Open);
    }
    let grid = PoissonGrid {
        resolution: domain.resolution(),
        cell_size: &cell_size[..d],
        open_sides: &open_sides[..d],
    };
    PoissonSystem::assemble(&grid, liquid, face_open)
}

#[cfg(test)]
mod tests {
    //! The Poisson systems of domains: stencil entries at walls, open sides, air and obstacle
    //! faces, pinned pure-Neumann regions, and second-order convergence to manufactured
    //! solutions.

    use super::*;
    use crate::solve::tests::{ALL_METHODS, random_vec};
    use crate::solve::{SolveMethod, SolveOptions, solve};

    #[test]
    fn masked_matrix_properties() {
        // 6×5 domain, open top (upper side of axis 1), closed elsewhere; an air pocket and an
        // obstacle face.
        let domain = Domain::new(
            &[6, 5],
            &[0.0, 0.0],
            &[3.0, 5.0],
            &[[Boundary::Closed; 2], [Boundary::Closed, Boundary::Open]],
        )
        .unwrap();
        let mut liquid = vec![1.0f32; 30];
        liquid[2 * 5 + 3] = 0.0; // air at (2, 3)
        let mut faces = all_faces_open(&domain);
        faces[0][4 * 5 + 1] = false; // the face between (3, 1) and (4, 1)
        let system = poisson_matrix(&domain, &liquid, &faces).unwrap();
        let a = &system.matrix;
        assert_eq!(system.unknowns(), 29);
        assert_eq!(system.cell_to_unknown[2 * 5 + 3], None);
        assert!(system.pinned.is_empty());
        assert!(a.is_symmetric());
        let (hx, hy) = (0.5f64, 1.0f64);
        let (cx, cy) = (1.0 / (hx * hx), 1.0 / (hy * hy));
        for u in 0..a.nrows() {
            assert!(a.get(u, u) > 0.0, "diagonal {u}");
            for (v, value) in a.row(u) {
                if v != u {
                    assert!(value < 0.0);
                }
            }
        }
        let unknown = |i: usize, j: usize| system.cell_to_unknown[i * 5 + j].unwrap();
        // An interior cell whose neighbours are all liquid: row sum 0, diagonal 2/hx² + 2/hy².
        let u = unknown(1, 2);
        assert_eq!(a.row(u).map(|(_, v)| v).sum::<f64>(), 0.0);
        assert_eq!(a.get(u, u), 2.0 * cx + 2.0 * cy);
        assert_eq!(a.get(u, unknown(0, 2)), -cx);
        assert_eq!(a.get(u, unknown(1, 3)), -cy);
        // Next to the air cell: the Dirichlet term adds to the diagonal only.
        let u = unknown(2, 2);
        assert_eq!(a.get(u, u), 2.0 * cx + 2.0 * cy);
        assert_eq!(a.row(u).map(|(_, v)| v).sum::<f64>(), cy);
        // At a closed wall: no flux through it.
        let u = unknown(0, 2);
        assert_eq!(a.get(u, u), cx + 2.0 * cy);
        assert_eq!(a.row(u).map(|(_, v)| v).sum::<f64>(), 0.0);
        // At the open top: the outside counts as air.
        let u = unknown(0, 4);
        assert_eq!(a.get(u, u), cx + 2.0 * cy);
        assert_eq!(a.row(u).map(|(_, v)| v).sum::<f64>(), cy);
        // The closed obstacle face: no coupling, no flux.
        assert_eq!(a.get(unknown(3, 1), unknown(4, 1)), 0.0);
        assert_eq!(a.get(unknown(3, 1), unknown(3, 1)), cx + 2.0 * cy);
        // Positive definite: Cholesky succeeds.
        let b = random_vec(29, 1);
        assert!(solve(a, &b, 1, &SolveOptions::with_method(SolveMethod::Cholesky)).is_ok());
        // Bad sizes.
        assert!(matches!(
            poisson_matrix(&domain, &liquid[..29], &faces),
            Err(SolveError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            poisson_matrix(&domain, &liquid, &faces[..1]),
            Err(SolveError::DimensionMismatch { .. })
        ));
    }

    #[test]
    fn pure_neumann_regions_are_pinned() {
        // A closed box full of liquid, plus a separate pocket sealed by obstacle faces and a second
        // region next to air: the first two are singular and get one pin each.
        let domain = Domain::closed_unit_cells(&[6, 4]).unwrap();
        let mut liquid = vec![true; 24];
        liquid[5 * 4 + 3] = false; // air at (5, 3)
        let mut faces = all_faces_open(&domain);
        // Wall off column x=0 (cells (0, *)) from the rest: faces between x=0 and x=1.
        for j in 0..4 {
            faces[0][4 + j] = false;
        }
        let system = poisson_matrix(&domain, &liquid, &faces).unwrap();
        assert_eq!(system.pinned, vec![0]);
        assert_eq!(system.region_is_singular.len(), 2);
        let a = &system.matrix;
        assert!(a.is_symmetric());
        // Compatible right-hand side: the exact solution with p = 0 at the pinned cell.
        let mut b = random_vec(system.unknowns(), 4);
        system.remove_singular_means(&mut b).unwrap();
        // Exactly, by the direct solve (an iterative one holds the pin only to its tolerance).
        let direct = SolveOptions::with_method(SolveMethod::Cholesky);
        let (x, _) = solve(a, &b, 1, &direct).unwrap();
        assert!(x[0].abs() < 1e-12);
        // Without the pin the same x solves the singular operator: A x = b in region 0.
        let ax = a.mul_vec(&x);
        let pin = a.get(0, 0) - 1.0; // the corner cell (0, 0) has one neighbour, (0, 1)
        assert!((pin - 1.0).abs() < 1e-12);
        for u in 0..4 {
            let unpinned = ax[u] - if u == 0 { pin * x[0] } else { 0.0 };
            assert!((unpinned - b[u]).abs() < 1e-8, "row {u}");
        }
        // Every method handles the pinned system.
        for method in ALL_METHODS {
            assert!(solve(a, &b, 1, &SolveOptions::with_method(method)).is_ok());
        }
        // An isolated liquid cell sealed on every side is pinned too.
        let mut faces = all_faces_open(&domain);
        faces[0][4 * 3 + 1] = false;
        faces[0][4 * 4 + 1] = false;
        faces[1][3 * 5 + 1] = false;
        faces[1][3 * 5 + 2] = false;
        let system = poisson_matrix(&domain, &[true; 24], &faces).unwrap();
        let isolated = system.cell_to_unknown[3 * 4 + 1].unwrap();
        assert!(system.pinned.contains(&isolated));
        assert_eq!(system.pinned.len(), 2);
    }

    /// Max-norm errors of three manufactured solutions on refined grids; each converges at second
    /// order.
    #[test]
    fn manufactured_solutions_converge_at_second_order() {
        use std::f64::consts::PI;
        let sizes = [8usize, 16, 32, 64];
        type Case = (&'static str, fn(usize) -> f64);
        let cases: [Case; 3] = [
            // Open sides: ghost air centres exactly on x, y ∈ {0, 1}; p = sin πx sin πy.
            ("open sides (Dirichlet)", |n| {
                let h = 1.0 / n as f64;
                let m = n - 1;
                let lo = (h / 2.0) as f32;
                let hi = (1.0 - h / 2.0) as f32;
                let domain =
                    Domain::new(&[m, m], &[lo, lo], &[hi, hi], &[[Boundary::Open; 2]; 2]).unwrap();
                let system =
                    poisson_matrix(&domain, &vec![true; m * m], &all_faces_open(&domain)).unwrap();
                let exact = |x: f64, y: f64| (PI * x).sin() * (PI * y).sin();
                max_error(&domain, &system, exact, |x, y| 2.0 * PI * PI * exact(x, y))
            }),
            // Air columns at x = 0 and x = 1 inside the domain, closed walls at y = 0, 1:
            // p = sin πx cos πy.
            ("air mask + closed walls", |n| {
                let h = 1.0 / n as f64;
                let domain = Domain::new(
                    &[n + 1, n],
                    &[(-h / 2.0) as f32, 0.0],
                    &[(1.0 + h / 2.0) as f32, 1.0],
                    &[[Boundary::Closed; 2]; 2],
                )
                .unwrap();
                let liquid: Vec<bool> =
                    (0..(n + 1) * n).map(|c| c / n != 0 && c / n != n).collect();
                let system = poisson_matrix(&domain, &liquid, &all_faces_open(&domain)).unwrap();
                assert!(system.pinned.is_empty());
                let exact = |x: f64, y: f64| (PI * x).sin() * (PI * y).cos();
                max_error(&domain, &system, exact, |x, y| 2.0 * PI * PI * exact(x, y))
            }),
            // Pure Neumann, pinned: p = cos πx cos πy, compared up to the constant.
            ("pure Neumann (pinned)", |n| {
                let domain = Domain::new(
                    &[n, n],
                    &[0.0, 0.0],
                    &[1.0, 1.0],
                    &[[Boundary::Closed; 2]; 2],
                )
                .unwrap();
                let liquid = vec![true; n * n];
                let system = poisson_matrix(&domain, &liquid, &all_faces_open(&domain)).unwrap();
                assert_eq!(system.pinned.len(), 1);
                let exact = |x: f64, y: f64| (PI * x).cos() * (PI * y).cos();
                max_error(&domain, &system, exact, |x, y| 2.0 * PI * PI * exact(x, y))
            }),
        ];
        for (name, run) in cases {
            let errors: Vec<f64> = sizes.iter().map(|&n| run(n)).collect();
            let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
            let shown: Vec<String> = errors.iter().map(|e| format!("{e:.3e}")).collect();
            println!("{name}: max errors {shown:?} at n = {sizes:?}, observed orders {orders:.3?}");
            for &order in &orders {
                assert!(order >= 1.8, "{name}: order {order} (errors {errors:?})");
            }
        }
    }

    /// Solves the manufactured problem (`−∇²p = f`) and returns the max-norm error over the liquid
    /// cells, both sides with their means removed in pinned (pure Neumann) systems.
    fn max_error(
        domain: &Domain,
        system: &PoissonSystem,
        exact: impl Fn(f64, f64) -> f64,
        source: impl Fn(f64, f64) -> f64,
    ) -> f64 {
        let res = domain.resolution();
        let h = domain.cell_size();
        let centre = |cell: usize| {
            let (i, j) = (cell / res[1], cell % res[1]);
            (
                f64::from(domain.lower()[0]) + (i as f64 + 0.5) * f64::from(h[0]),
                f64::from(domain.lower()[1]) + (j as f64 + 0.5) * f64::from(h[1]),
            )
        };
        let mut b: Vec<f64> = system
            .unknown_to_cell
            .iter()
            .map(|&c| {
                let (x, y) = centre(c);
                source(x, y)
            })
            .collect();
        let mut want: Vec<f64> = system
            .unknown_to_cell
            .iter()
            .map(|&c| {
                let (x, y) = centre(c);
                exact(x, y)
            })
            .collect();
        let options = SolveOptions {
            relative_tolerance: 1e-12,
            ..SolveOptions::default()
        };
        let singular = !system.pinned.is_empty();
        if singular {
            system.remove_singular_means(&mut b).unwrap();
        }
        let (mut x, _) = solve(&system.matrix, &b, 1, &options).unwrap();
        if singular {
            for v in [&mut x, &mut want] {
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                v.iter_mut().for_each(|e| *e -= mean);
            }
        }
        x.iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }
}
