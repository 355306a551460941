//! The exact EMD against hand-computed cases, brute force over all permutations, its invariances,
//! and POT's `ot.emd2` on the committed fixture `phi-core/tests/fixtures/emd_pot.txt` (made by
//! `emd_pot.py` beside it).

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::*;

const COSTS: [GroundCost; 2] = [GroundCost::SquaredEuclidean, GroundCost::Euclidean];

fn uniform(n: usize, d: usize, rng: &mut StdRng) -> Vec<f64> {
    (0..n * d).map(|_| rng.random::<f64>()).collect()
}

fn relative(x: f64, y: f64) -> f64 {
    (x - y).abs() / y.abs().max(f64::MIN_POSITIVE)
}

/// `(1/N) Σᵢ C(aᵢ, b_π(i))` for the permutation `π`.
fn cost_of(a: &[f64], b: &[f64], d: usize, cost: GroundCost, pi: &[usize]) -> f64 {
    let total: f64 = pi
        .iter()
        .enumerate()
        .map(|(i, &j)| {
            let s = neighbours::squared_distance(&a[i * d..][..d], &b[j * d..][..d]);
            match cost {
                GroundCost::SquaredEuclidean => s,
                GroundCost::Euclidean => s.sqrt(),
            }
        })
        .sum();
    total / pi.len() as f64
}

/// The minimum over all `N!` permutations (Heap's algorithm).
fn brute_force(a: &[f64], b: &[f64], d: usize, cost: GroundCost) -> f64 {
    let n = a.len() / d;
    let mut pi: Vec<usize> = (0..n).collect();
    let mut counters = vec![0; n];
    let mut best = cost_of(a, b, d, cost, &pi);
    let mut k = 0;
    while k < n {
        if counters[k] < k {
            let swap = if k % 2 == 0 { 0 } else { counters[k] };
            pi.swap(swap, k);
            best = best.min(cost_of(a, b, d, cost, &pi));
            counters[k] += 1;
            k = 0;
        } else {
            counters[k] = 0;
            k += 1;
        }
    }
    best
}

fn permuted(points: &[f64], d: usize, order: &[usize]) -> Vec<f64> {
    order
        .iter()
        .flat_map(|&i| points[i * d..(i + 1) * d].iter().copied())
        .collect()
}

#[test]
fn two_swapped_particles_are_zero_apart_though_their_pairs_are_not() {
    let truth = [0.0f32, 0.0, 1.0, 0.5];
    let predicted = [1.0f32, 0.5, 0.0, 0.0];
    let paired: f32 = truth
        .iter()
        .zip(&predicted)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f32>()
        / 2.0;
    assert_eq!(paired, 1.25);
    for cost in COSTS {
        assert_eq!(
            earth_movers_distance(&predicted, &truth, 2, cost).unwrap(),
            0.0
        );
    }
}

/// For any set and shift `s`, `(1/N) Σ |aᵢ + s − a_σ(i)|² = (1/N) Σ |aᵢ − a_σ(i)|² + |s|²` (the
/// cross term vanishes after summing over the permutation), so the squared EMD is `|s|²`; the
/// Euclidean one is `|s|`, attained by the identity and a lower bound by testing the 1-Lipschitz
/// function `x · s/|s|` (Kantorovich–Rubinstein).
#[test]
fn a_rigid_shift_costs_its_length_or_its_square() {
    let mut rng = StdRng::seed_from_u64(1);
    for (d, shift) in [
        (1, &[0.37][..]),
        (2, &[0.13, -0.07]),
        (3, &[0.02, 0.3, -0.11]),
    ] {
        let a = uniform(60, d, &mut rng);
        let b: Vec<f64> = a
            .iter()
            .enumerate()
            .map(|(e, x)| x + shift[e % d])
            .collect();
        let s2: f64 = shift.iter().map(|x| x * x).sum();
        let squared = earth_movers_distance(&b, &a, d, GroundCost::SquaredEuclidean).unwrap();
        let euclidean = earth_movers_distance(&b, &a, d, GroundCost::Euclidean).unwrap();
        assert!(relative(squared, s2) < 1e-12, "d = {d}: {squared} vs {s2}");
        assert!(
            relative(euclidean, s2.sqrt()) < 1e-12,
            "d = {d}: {euclidean} vs {}",
            s2.sqrt()
        );
    }
}

#[test]
fn the_distance_is_the_minimum_over_all_permutations() {
    for seed in 0..16 {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = 1 + seed as usize % 7;
        // Four dimensions take the brute-force neighbours.
        let d = 1 + seed as usize % 4;
        let a = uniform(n, d, &mut rng);
        let b = uniform(n, d, &mut rng);
        for cost in COSTS {
            let want = brute_force(&a, &b, d, cost);
            for k in [1, 2, 8] {
                let mut solver = EmdSolver::new().with_neighbours(k);
                let got = solver.solve(&a, &b, d, cost).unwrap();
                assert!(
                    relative(got, want) < 1e-12,
                    "seed {seed}, N = {n}, d = {d}, {cost:?}, k = {k}: {got} vs {want}"
                );
                let assignment = solver.assignment();
                assert!(relative(cost_of(&a, &b, d, cost, &assignment), want) < 1e-12);
                let mut sorted = assignment.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..n).collect::<Vec<_>>(), "not a permutation");
            }
        }
    }
}

#[test]
fn the_order_of_the_points_does_not_matter() {
    let mut rng = StdRng::seed_from_u64(5);
    let (n, d) = (200, 2);
    let a = uniform(n, d, &mut rng);
    let b: Vec<f64> = uniform(n, d, &mut rng)
        .iter()
        .map(|x| 0.2 + 0.8 * x)
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    let reversed: Vec<usize> = (0..n).rev().collect();
    for cost in COSTS {
        let emd = earth_movers_distance(&a, &b, d, cost).unwrap();
        for (x, y) in [
            (permuted(&a, d, &order), b.clone()),
            (a.clone(), permuted(&b, d, &order)),
            (permuted(&a, d, &reversed), permuted(&b, d, &order)),
        ] {
            let other = earth_movers_distance(&x, &y, d, cost).unwrap();
            assert!(relative(other, emd) < 1e-12, "{cost:?}: {other} vs {emd}");
        }
        // Symmetric: the transposed assignment is optimal the other way.
        let back = earth_movers_distance(&b, &a, d, cost).unwrap();
        assert!(relative(back, emd) < 1e-12, "{cost:?}: {back} vs {emd}");
    }
}

/// The certification leaves nothing to chance: with one or two neighbours per point, and 30
/// points of `a` in a far cluster, the graph misses most optimal pairs and the sweeps add them;
/// the result is the one of the complete graph, which the first sweep certifies.
#[test]
fn the_result_does_not_depend_on_the_candidate_graph() {
    let mut rng = StdRng::seed_from_u64(9);
    let d = 2;
    let mut a = uniform(90, d, &mut rng);
    a.extend(uniform(30, d, &mut rng).iter().map(|x| 5.0 + 0.01 * x));
    let b = uniform(120, d, &mut rng);
    for cost in COSTS {
        let mut complete = EmdSolver::new().with_neighbours(120);
        let want = complete.solve(&a, &b, d, cost).unwrap();
        assert_eq!(complete.stats().certifications, 1);
        assert_eq!(complete.stats().initial_edges, 120 * 120);
        for k in [1, 2, 4, 16] {
            let mut solver = EmdSolver::new().with_neighbours(k);
            let got = solver.solve(&a, &b, d, cost).unwrap();
            assert!(
                relative(got, want) < 1e-12,
                "{cost:?}, k = {k}: {got} vs {want}"
            );
            assert!(solver.optimality_gap() <= 1e-10 * want, "{cost:?}, k = {k}");
            let stats = solver.stats();
            if k <= 2 {
                assert!(stats.certifications > 1, "{cost:?}, k = {k}: {stats:?}");
                assert!(stats.final_edges > stats.initial_edges);
            }
        }
    }
}

/// Frames of a moving set solved in order by one warm-starting solver equal cold solves.
#[test]
fn a_warm_start_gives_the_cold_result() {
    let mut rng = StdRng::seed_from_u64(3);
    let (n, d) = (300, 2);
    let truth = uniform(n, d, &mut rng);
    let mut warm = EmdSolver::new();
    for frame in 0..6 {
        let t = 0.02 * frame as f64;
        let moved = |x: &[f64], phase: f64| -> Vec<f64> {
            x.chunks(d)
                .flat_map(|p| [p[0] + t * (3.0 * p[1] + phase).sin(), p[1] - t * p[0]])
                .collect()
        };
        let a = moved(&truth, 0.5);
        let b = moved(&truth, 0.0);
        for cost in COSTS {
            let cold = earth_movers_distance(&a, &b, d, cost).unwrap();
            let got = warm.solve(&a, &b, d, cost).unwrap();
            assert!(relative(got, cold) < 1e-12, "frame {frame}, {cost:?}");
        }
    }
}

/// One solver across sizes, dimensions and costs: a warm start applies only to the same shape
/// and cost, and the results are those of fresh solvers. Coincident points cost nothing.
#[test]
fn a_solver_can_be_reused_for_any_sets() {
    let mut rng = StdRng::seed_from_u64(12);
    let mut solver = EmdSolver::new();
    for (n, d) in [(5, 2), (7, 2), (7, 3), (40, 2), (40, 2), (1, 1)] {
        let a = uniform(n, d, &mut rng);
        let b = uniform(n, d, &mut rng);
        for cost in COSTS {
            let fresh = earth_movers_distance(&a, &b, d, cost).unwrap();
            let got = solver.solve(&a, &b, d, cost).unwrap();
            assert!(relative(got, fresh) < 1e-12, "N = {n}, d = {d}, {cost:?}");
        }
    }
    let same = vec![0.25f32; 2 * 30];
    for cost in COSTS {
        assert_eq!(solver.solve(&same, &same, 2, cost).unwrap(), 0.0);
    }
}

/// One case of the fixture: two sets and POT's `ot.emd2` for both costs.
struct PotCase {
    name: String,
    d: usize,
    emd: [f64; 2],
    a: Vec<f32>,
    b: Vec<f32>,
}

fn pot_cases() -> Vec<PotCase> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/emd_pot.txt");
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    lines
        .chunks(3)
        .map(|case| {
            let head: Vec<&str> = case[0].split_whitespace().collect();
            assert_eq!(head[0], "case");
            let values = |line: &str, tag: &str| -> Vec<f32> {
                let mut words = line.split_whitespace();
                assert_eq!(words.next(), Some(tag));
                words.map(|w| w.parse().unwrap()).collect()
            };
            let (n, d): (usize, usize) = (head[2].parse().unwrap(), head[3].parse().unwrap());
            let (a, b) = (values(case[1], "a"), values(case[2], "b"));
            assert_eq!((a.len(), b.len()), (n * d, n * d));
            PotCase {
                name: head[1].to_string(),
                d,
                emd: [head[4].parse().unwrap(), head[5].parse().unwrap()],
                a,
                b,
            }
        })
        .collect()
}

#[test]
fn the_distance_is_pots_emd2() {
    let cases = pot_cases();
    assert_eq!(cases.len(), 6);
    for case in &cases {
        for (cost, want) in COSTS.into_iter().zip(case.emd) {
            let mut solver = EmdSolver::new();
            let got = solver.solve(&case.a, &case.b, case.d, cost).unwrap();
            assert!(
                relative(got, want) < 1e-9,
                "{} {cost:?}: {got} vs POT {want}",
                case.name
            );
            assert!(solver.optimality_gap() <= 1e-10 * want, "{}", case.name);
        }
    }
}

#[test]
fn sets_that_cannot_be_compared_are_errors() {
    let message = |a: &[f32], b: &[f32], d: usize| match earth_movers_distance(
        a,
        b,
        d,
        GroundCost::SquaredEuclidean,
    ) {
        Err(e @ PointSetError::Invalid { .. }) => e.to_string(),
        other => panic!("expected an invalid-input error, got {other:?}"),
    };
    let four = [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    let three = &four[..6];
    let unequal = message(&four, three, 2);
    assert!(unequal.starts_with("earth mover's distance:"), "{unequal}");
    assert!(unequal.contains("equal counts are required"), "{unequal}");
    assert!(unequal.contains("4 points and the second 3"), "{unequal}");
    assert!(message(&[], &[], 2).contains("empty point set"));
    assert!(message(&four, &four, 0).contains("d = 0"));
    assert!(message(&four, &four[..7], 2).contains("second set has 7 values"));
    assert!(
        message(&four, &four, 3)
            .contains("first set has 8 values, not a whole number of 3-dimensional")
    );
    let mut bad = four;
    bad[5] = f32::NAN;
    assert!(message(&four, &bad, 2).contains("coordinate 1 of point 2 of the second set is NaN"));
    bad[5] = f32::INFINITY;
    assert!(message(&bad, &four, 2).contains("of the first set is inf"));
    let huge = [0.0, 1e101];
    let reason = earth_movers_distance(&huge, &[0.0, 0.0], 2, GroundCost::Euclidean);
    assert!(
        matches!(reason, Err(PointSetError::Invalid { reason, .. }) if reason.contains("up to 1e100"))
    );
    // A single point, and f64 input.
    let one = earth_movers_distance(&[1.0f64, 2.0], &[4.0, 6.0], 2, GroundCost::Euclidean);
    assert_eq!(one, Ok(5.0));
}
