//! Optimisation of initial positions through the simulation (thesis section 4.3): a tiny case
//! converges with each loss, configuration errors name file and key, a diverging run stops
//! with its last good state, and the shipped configurations load.

use phi_core::backend::burn::Burn;
use phi_flip::optimize::LossSpec;
use phi_flip::{FlipError, OptimizeConfig, OptimizeError};

/// A 12×12 block of 4×4 cells is to end like a sphere simulated 5 steps.
const TINY: &str = r#"
[scene.domain]
resolution = [12, 12]

[scene.simulation]
dt = 0.05
steps = 5
particles_per_cell = 2
placement = "centered"

[[scene.liquid]]
geometry = { type = "box", lower = [2, 2], upper = [6, 6] }

[target]
liquid = [{ type = "sphere", center = [6.5, 6.5], radius = 2.6 }]
particles_per_cell = 4

[optimize]
iterations = 8
"#;

fn tiny(loss: LossSpec) -> OptimizeConfig {
    let mut config = OptimizeConfig::from_toml(TINY, "tiny.toml").unwrap();
    config.optimize.loss = loss;
    config
}

#[test]
fn tiny_optimisation_reaches_the_target() {
    // Learning rate 1 on ½ Σ |x − t|²: for a map close to a translation, one step removes most of
    // the residual, so 8 iterations must cut the loss by 100× (measured: to 0). The Sinkhorn
    // divergence (×N) behaves alike until its blur ε = 1 cell² (measured: 248 → 0.09). The
    // density loss (grids of 1, 2 and 4 cells here) is coarse at this particle count
    // (measured: 61.8 → 7.4).
    for (loss, factor) in [
        (LossSpec::L2, 100.0),
        (LossSpec::Sinkhorn, 100.0),
        (LossSpec::Density, 5.0),
    ] {
        let problem = tiny(loss)
            .build::<Burn>("tiny.toml", &Default::default())
            .unwrap();
        let outcome = problem.run(|_| {});
        assert!(outcome.stopped.is_none(), "{loss:?}: {:?}", outcome.stopped);
        let losses: Vec<f32> = outcome.records.iter().map(|r| r.loss).collect();
        let chamfer: Vec<f32> = outcome.records.iter().map(|r| r.chamfer).collect();
        println!("{loss:?}: losses {losses:?}, chamfer {chamfer:?}");
        assert_eq!(losses.len(), 9);
        let (first, last) = (losses[0], *losses.last().unwrap());
        assert!(
            last * factor <= first,
            "{loss:?}: loss {first} -> {last}, not {factor}x lower"
        );
        assert!(chamfer.last().unwrap() < &chamfer[0]);
    }
}

fn error_of(text: &str) -> String {
    match OptimizeConfig::from_toml(text, "bad.toml")
        .and_then(|c| c.build::<Burn>("bad.toml", &Default::default()).map(|_| ()))
    {
        Err(e @ FlipError::Scene { .. }) => e.to_string(),
        other => panic!("expected a configuration error, got {other:?}"),
    }
}

#[test]
fn configuration_errors_name_file_and_key() {
    let cases = [
        (
            TINY.replace("iterations = 8", "iterations = 8\nstep_size = 2"),
            "optimize",
            "unknown field `step_size`",
        ),
        (
            TINY.replace("center = [6.5, 6.5]", "center = [6.5, 6.5, 1.0]"),
            "target.liquid[0]",
            "3-dimensional",
        ),
        (
            TINY.replace("center = [6.5, 6.5]", "center = [60, 60]"),
            "target.liquid",
            "empty",
        ),
        (
            TINY.replace("particles_per_cell = 4", "particles_per_cell = 1"),
            "target.liquid",
            "points for",
        ),
        (
            TINY.replace("iterations = 8", "loss = \"l1\""),
            "optimize.loss",
            "unknown variant",
        ),
        (
            TINY.replace("resolution = [12, 12]", "resolution = [12, 0]"),
            "scene.domain.resolution[1]",
            "at least 1",
        ),
        (
            TINY.replace("iterations = 8", "learning_rate = -1"),
            "optimize.learning_rate",
            "positive",
        ),
        (
            TINY.replace("iterations = 8", "density_levels = 0"),
            "optimize.density_levels",
            "at least 1",
        ),
        (
            TINY.replace("liquid = [{ type", "liquid = []\n#[{ type"),
            "target.liquid",
            "empty",
        ),
    ];
    for (text, key, reason) in cases {
        let message = error_of(&text);
        assert!(
            message.starts_with("bad.toml: ") && message.contains(key) && message.contains(reason),
            "want bad.toml, {key}, {reason}; got {message}"
        );
    }
}

#[test]
fn sinkhorn_and_density_accept_a_target_of_another_size() {
    let text = TINY.replace("particles_per_cell = 4", "particles_per_cell = 1");
    let mut config = OptimizeConfig::from_toml(&text, "t.toml").unwrap();
    config.optimize.loss = LossSpec::Sinkhorn;
    let problem = config.build::<Burn>("t.toml", &Default::default()).unwrap();
    assert!(problem.target.shape()[0] < problem.initial.len());
    config.optimize.iterations = 1;
    let problem = config.build::<Burn>("t.toml", &Default::default()).unwrap();
    assert!(problem.run(|_| {}).stopped.is_none());
}

#[test]
fn a_diverging_optimisation_stops_with_its_last_good_state() {
    let mut config = tiny(LossSpec::L2);
    config.optimize.learning_rate = 40.0;
    config.optimize.divergence_factor = 1.01;
    let problem = config
        .build::<Burn>("tiny.toml", &Default::default())
        .unwrap();
    let outcome = problem.run(|_| {});
    match &outcome.stopped {
        Some(OptimizeError::Diverged { iteration, .. }) => {
            assert_eq!(*iteration, outcome.records.len());
        }
        other => panic!("expected a divergence, got {other:?}"),
    }
    let last = outcome.last().unwrap();
    assert!(last.loss.is_finite());
    assert!(last.initial_positions.iter().all(|v| v.is_finite()));
}

#[test]
fn shipped_optimisations_load() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/optimize");
    let mut count = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let config = OptimizeConfig::from_file(&path).unwrap();
            let problem = config
                .build::<Burn>(&path.display().to_string(), &Default::default())
                .unwrap();
            assert_eq!(problem.steps, 20, "{}", path.display());
            count += 1;
        }
    }
    assert!(count >= 3);
}

/// `√(mean |aᵢ − bᵢ|²)` and the mean of `aᵢ − bᵢ` per axis, host `[N·2]`.
fn rms_and_mean(a: &[f32], b: &[f32]) -> (f32, [f32; 2]) {
    let n = a.len() / 2;
    let mut mean = [0.0f64; 2];
    let mut sq = 0.0f64;
    for i in 0..n {
        for k in 0..2 {
            let e = f64::from(a[2 * i + k] - b[2 * i + k]);
            mean[k] += e / n as f64;
            sq += e * e;
        }
    }
    (
        (sq / n as f64).sqrt() as f32,
        [mean[0] as f32, mean[1] as f32],
    )
}

/// `½ Σ_{i ∈ ids} |aᵢ − bᵢ|²`, host `[N·2]`.
fn half_sum(ids: &[usize], a: &[f32], b: &[f32]) -> f32 {
    ids.iter()
        .map(|&i| 0.5 * ((a[2 * i] - b[2 * i]).powi(2) + (a[2 * i + 1] - b[2 * i + 1]).powi(2)))
        .sum()
}

#[test]
fn two_spheres_rises_first_then_converges() {
    // The shipped fig. 4.5 case: the loss must first rise (the thesis: 14,129 → 18,141), then
    // fall below 1% of its first value within 15 iterations (measured on Burn: 13,810 →
    // 17,058 → 7,151 → … → 0.83 at iteration 11 → 3·10⁻¹¹). Prints the numbers that explain
    // the rise in docs/optimize.md.
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/optimize/two_spheres.toml"
    );
    let mut config = OptimizeConfig::from_file(std::path::Path::new(path)).unwrap();
    config.optimize.iterations = 15;
    let problem = config.build::<Burn>(path, &Default::default()).unwrap();
    let outcome = problem.run(|_| {});
    assert!(outcome.stopped.is_none(), "{:?}", outcome.stopped);
    let losses: Vec<f32> = outcome.records.iter().map(|r| r.loss).collect();
    println!("losses {losses:?}");

    let (t0, tt) = (problem.target_initial.to_vec(), problem.target.to_vec());
    let r = &outcome.records;
    let (x0, x1) = (&r[0].initial_positions, &r[1].initial_positions);
    let n = t0.len() / 2;
    let all: Vec<usize> = (0..n).collect();
    let show = |what: &str, a: &[f32], b: &[f32]| {
        let (rms, mean) = rms_and_mean(a, b);
        println!(
            "{what}: rms {rms:.2}, mean ({:.2}, {:.2}) cells",
            mean[0], mean[1]
        );
    };
    show("target: end − start", &tt, &t0);
    show("block: end − start", &r[0].final_positions, x0);
    show("iteration 0: end − target", &r[0].final_positions, &tt);
    show("x1 − target end", x1, &tt);
    show("x1 − target start", x1, &t0);
    show("iteration 1: end − x1", &r[1].final_positions, x1);
    show("iteration 1: end − target", &r[1].final_positions, &tt);
    show("x2 − target start", &r[2].initial_positions, &t0);
    show("x3 − target start", &r[3].initial_positions, &t0);

    // The first gradient, per particle: the tenth with the largest gradients.
    let (_, g0, _) = problem
        .loss_and_gradient(&problem.initial.positions)
        .unwrap();
    let g0 = g0.to_vec();
    let norm = |i: usize| g0[2 * i].hypot(g0[2 * i + 1]);
    let mut order = all.clone();
    order.sort_by(|&a, &b| norm(b).total_cmp(&norm(a)));
    let (top, rest) = order.split_at(n / 10);
    let near_ends = top
        .iter()
        .filter(|&&i| x0[2 * i] < 9.0 || x0[2 * i] > 23.0)
        .count();
    println!(
        "|g0| median {:.2}, max {:.2}; of the {} largest, {near_ends} start within 4 cells of \
         the block's ends",
        norm(order[n / 2]),
        norm(order[0]),
        top.len()
    );
    for (what, ids) in [("largest tenth", top), ("the others", rest)] {
        println!(
            "{what}: loss at iteration 0 {:.0}, at iteration 1 {:.0}",
            half_sum(ids, &r[0].final_positions, &tt),
            half_sum(ids, &r[1].final_positions, &tt)
        );
    }
    let mut d1: Vec<f32> = all
        .iter()
        .map(|&i| (x1[2 * i] - tt[2 * i]).hypot(x1[2 * i + 1] - tt[2 * i + 1]))
        .collect();
    d1.sort_by(f32::total_cmp);
    println!("|x1 − target end| median {:.2}", d1[n / 2]);

    // Two references: the step of an identity Jacobian (x0 − r0), and the target's end state
    // simulated again from rest.
    let resimulated_loss = |x: Vec<f32>| {
        let p = phi_flip::Particles::<Burn>::from_host(x, vec![0.0; 2 * n], 2, &Default::default())
            .unwrap();
        let end = phi_flip::optimize::simulate(&problem.simulation, &p, problem.steps, None)
            .unwrap()
            .positions
            .to_vec();
        half_sum(&all, &end, &tt)
    };
    let identity_step: Vec<f32> = (0..2 * n)
        .map(|k| (x0[k] - (r[0].final_positions[k] - tt[k])).clamp(0.0, 31.999))
        .collect();
    println!(
        "loss after the identity-Jacobian step x0 − r0: {:.0}; of the target's end state \
         simulated again: {:.0}",
        resimulated_loss(identity_step),
        resimulated_loss(tt.clone())
    );

    assert!(losses[1] > losses[0], "no initial rise: {losses:?}");
    let first = losses[0];
    assert!(
        losses.iter().skip(2).any(|&l| l < 0.01 * first),
        "not below 1% of {first} within 15 iterations: {losses:?}"
    );
}

#[test]
fn the_density_loss_pulls_a_distant_liquid_through_its_coarse_grids() {
    // A 4×4-cell blob 12 cells left of an equal target blob on a 32² grid: on the domain's grid
    // alone the blobs do not overlap and a translation has no gradient; with the coarser grids
    // the mean gradient points from the target to the liquid (descent moves the liquid right).
    // Normalised by the target's density, the gradient per particle does not depend on the
    // particles per cell (4 or 16 here, placed symmetrically in their cells; measured: −0.106
    // with 5 grids, both).
    use phi_core::Tensor;
    use phi_flip::loss::Loss;
    let domain = phi_core::fields::Domain::closed_unit_cells(&[32, 32]).unwrap();
    let blob = |x0: f32, per_axis: usize| -> Vec<f32> {
        let h = 1.0 / per_axis as f32;
        let mut p = Vec::new();
        for i in 0..4 * per_axis {
            for j in 0..4 * per_axis {
                p.extend([x0 + (i as f32 + 0.5) * h, 14.0 + (j as f32 + 0.5) * h]);
            }
        }
        p
    };
    let mean_gradient_x = |levels: usize, per_axis: usize| -> f32 {
        let (x, t) = (blob(6.0, per_axis), blob(18.0, per_axis));
        let n = x.len() / 2;
        let device = Default::default();
        let x = Tensor::<Burn>::from_vec(x, &[n, 2], &device)
            .unwrap()
            .require_grad();
        let t = Tensor::<Burn>::from_vec(t, &[n, 2], &device).unwrap();
        let loss = Loss::Density { levels }.evaluate(&x, &t, &domain).unwrap();
        let g = loss.gradients(&[&x]).unwrap().remove(0).to_vec();
        g.iter().step_by(2).sum::<f32>() / n as f32
    };
    let one_grid = mean_gradient_x(1, 2);
    assert!(one_grid.abs() < 1e-6, "one grid: {one_grid}");
    let (ppc4, ppc16) = (mean_gradient_x(5, 2), mean_gradient_x(5, 4));
    println!("mean x-gradient with 5 grids: {ppc4} (4 per cell), {ppc16} (16 per cell)");
    assert!(ppc4 < -0.01, "{ppc4}");
    assert!((ppc4 / ppc16 - 1.0).abs() < 1e-3, "{ppc4} vs {ppc16}");
}
