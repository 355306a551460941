//! The exact earth mover's distance on the POT fixture's 1,300-point cases
//! (`tests/fixtures/emd_pot.txt`): a rollout-like pair (a jittered block of liquid and its
//! perturbed, compressed prediction) and two independent uniform sets, both ground costs; and ten
//! consecutive frames of a moving rollout-like pair, cold and warm-started. Compare with POT on
//! the same points: `benches/emd_pot.py` (docs/benchmarks.md, "Exact EMD against POT").
//!
//! `cargo bench -p phi-core --bench emd -- --noplot`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use phi_core::point_sets::{EmdSolver, GroundCost, earth_movers_distance};

/// The fixture's case `name`: `(a, b, d)`.
fn case(name: &str) -> (Vec<f32>, Vec<f32>, usize) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/emd_pot.txt");
    let text = std::fs::read_to_string(path).expect("the EMD fixture");
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.split_whitespace().nth(1) == Some(name))
        .expect("a case of that name");
    let d = lines[at]
        .split_whitespace()
        .nth(3)
        .unwrap()
        .parse()
        .unwrap();
    let values = |line: &str| -> Vec<f32> {
        line.split_whitespace()
            .skip(1)
            .map(|w| w.parse().unwrap())
            .collect()
    };
    (values(lines[at + 1]), values(lines[at + 2]), d)
}

const COSTS: [(GroundCost, &str); 2] = [
    (GroundCost::SquaredEuclidean, "sqeuclidean"),
    (GroundCost::Euclidean, "euclidean"),
];

fn single(c: &mut Criterion) {
    let mut group = c.benchmark_group("emd");
    for name in ["rollout_1300", "uniform_1300"] {
        let (a, b, d) = case(name);
        for (cost, label) in COSTS {
            let mut solver = EmdSolver::new();
            let emd = solver.solve(&a, &b, d, cost).unwrap();
            eprintln!("{name} {label}: EMD {emd:.9e}, {:?}", solver.stats());
            group.bench_function(BenchmarkId::new(name, label), |bench| {
                bench.iter(|| earth_movers_distance(black_box(&a), black_box(&b), d, cost).unwrap())
            });
        }
    }
    group.finish();
}

/// Ten frames of the rollout-like pair carried by a smooth swirl, the prediction's error growing
/// by 2 % a frame: consecutive frames move by ~0.2 % of the domain.
fn frames() -> Vec<(Vec<f32>, Vec<f32>)> {
    let (a, b, d) = case("rollout_1300");
    let carry = |p: &[f32], t: f32| -> [f32; 2] {
        let (x, y) = (p[0], p[1]);
        let s = std::f32::consts::PI;
        [x + t * (s * y).sin(), y - t * (s * x).sin() * 0.5]
    };
    (0..10)
        .map(|f| {
            let t = 0.002 * f as f32;
            let grow = 1.0 + 0.02 * f as f32;
            let mut predicted = Vec::with_capacity(a.len());
            let mut truth = Vec::with_capacity(b.len());
            for (p, q) in a.chunks(d).zip(b.chunks(d)) {
                let wrong = [q[0] + grow * (p[0] - q[0]), q[1] + grow * (p[1] - q[1])];
                predicted.extend(carry(&wrong, t));
                truth.extend(carry(q, t));
            }
            (predicted, truth)
        })
        .collect()
}

fn rollout(c: &mut Criterion) {
    let frames = frames();
    let mut group = c.benchmark_group("emd rollout_1300 10 frames");
    for (cost, label) in COSTS {
        for warm in [false, true] {
            let mut solver = EmdSolver::new().with_warm_start(warm);
            let kind = if warm { "warm" } else { "cold" };
            let mut stats = Vec::new();
            for (a, b) in &frames {
                solver.solve(a, b, 2, cost).unwrap();
                stats.push(solver.stats());
            }
            eprintln!("{label} {kind}, last frame: {:?}", stats.last().unwrap());
            group.bench_function(BenchmarkId::new(label, kind), |bench| {
                bench.iter(|| {
                    frames
                        .iter()
                        .map(|(a, b)| solver.solve(black_box(a), black_box(b), 2, cost).unwrap())
                        .sum::<f64>()
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, single, rollout);
criterion_main!(benches);
