//! The losses' properties and gradients (against central finite differences) on the autodiff
//! backends, and the host metrics on sets with known distances.

use super::*;
use crate::backend::AutodiffBackend;

macro_rules! for_each_autodiff_backend {
    ($($test:ident),* $(,)?) => {
        #[cfg(feature = "burn")]
        mod burn {
            $(#[test] fn $test() { super::$test::<crate::backend::burn::Burn>(); })*
        }
        #[cfg(feature = "tch")]
        mod tch {
            $(#[test] fn $test() { super::$test::<crate::backend::tch::Tch>(); })*
        }
    };
}

for_each_autodiff_backend!(
    sinkhorn_divergence_is_a_divergence,
    sinkhorn_and_l2_gradients_match_finite_differences,
    sets_that_cannot_be_compared_are_errors,
);

/// The finite-difference step (domain units).
const H: f32 = 1e-2;

fn points<B: Backend>(values: &[f32]) -> Tensor<B> {
    Tensor::from_vec(
        values.to_vec(),
        &[values.len() / 2, 2],
        &B::default_device(),
    )
    .unwrap()
}

fn cloud(n: usize, seed: f32, shift: f32) -> Vec<f32> {
    (0..2 * n)
        .map(|k| 2.0 * (seed + 0.77 * k as f32).sin() + 3.0 + if k % 2 == 0 { shift } else { 0.0 })
        .collect()
}

fn sinkhorn_divergence_is_a_divergence<B: AutodiffBackend>() {
    let options = SinkhornOptions::new(0.1);
    let a = cloud(12, 0.3, 0.0);
    let b = cloud(9, 1.7, 1.5);
    let s = |x: &[f32], y: &[f32]| {
        sinkhorn_divergence(&points::<B>(x), &points::<B>(y), &options)
            .unwrap()
            .to_scalar()
            .unwrap()
    };
    // S(a, a) = 0 and S ≥ 0.
    let aa = s(&a, &a);
    assert!(aa.abs() < 1e-4, "S(a, a) = {aa}");
    let ab = s(&a, &b);
    assert!(ab > 0.1, "S(a, b) = {ab}");
    assert!((s(&b, &a) - ab).abs() < 1e-4 * ab.max(1.0));
    // Invariant to the order of the points of either set.
    let mut permuted = Vec::new();
    for i in (0..12)
        .rev()
        .step_by(2)
        .chain((0..12).rev().skip(1).step_by(2))
    {
        permuted.extend_from_slice(&a[2 * i..2 * i + 2]);
    }
    assert_ne!(permuted, a);
    let ab_permuted = s(&permuted, &b);
    assert!(
        (ab_permuted - ab).abs() < 1e-4 * ab,
        "{ab_permuted} vs {ab}"
    );
    // A translated copy: with a small ε, S ≈ ½ |shift|² (the optimal plan is the translation).
    let shifted: Vec<f32> = a
        .iter()
        .enumerate()
        .map(|(k, v)| if k % 2 == 0 { v + 0.5 } else { *v })
        .collect();
    let t = s(&a, &shifted);
    assert!(
        (t - 0.125).abs() < 0.02,
        "S(a, a + 0.5 e₀) = {t}, want ≈ 0.125"
    );
}

fn sinkhorn_and_l2_gradients_match_finite_differences<B: AutodiffBackend>() {
    let a = cloud(10, 0.3, 0.0);
    let b = cloud(10, 1.7, 1.0);
    let target = points::<B>(&b);
    for (name, options) in [
        ("sinkhorn ε=0.5", Some(SinkhornOptions::new(0.5))),
        ("sinkhorn ε=0.05", Some(SinkhornOptions::new(0.05))),
        ("l2", None),
    ] {
        let eval = |x: &Tensor<B>| match &options {
            Some(o) => sinkhorn_divergence(x, &target, o).unwrap(),
            None => l2_loss(x, &target).unwrap(),
        };
        let x = points::<B>(&a).require_grad();
        let g = eval(&x).gradients(&[&x]).unwrap()[0].to_vec();
        for e in 0..a.len() {
            let (mut plus, mut minus) = (a.clone(), a.clone());
            plus[e] += H;
            minus[e] -= H;
            let fd = (eval(&points::<B>(&plus)).to_scalar().unwrap()
                - eval(&points::<B>(&minus)).to_scalar().unwrap())
                / (2.0 * H);
            // The potentials are re-solved at every evaluation (to the Sinkhorn iterations'
            // accuracy, ~1e-5 relative), and the loss is O(1): the FD error is ~1e-3.
            assert!(
                (g[e] - fd).abs() <= 3e-3 + 1e-2 * fd.abs(),
                "{name}: ∂S/∂a[{e}] backprop {} vs finite differences {fd}",
                g[e]
            );
        }
    }
}

fn sets_that_cannot_be_compared_are_errors<B: AutodiffBackend>() {
    let a = points::<B>(&cloud(4, 0.3, 0.0));
    let b = points::<B>(&cloud(3, 1.7, 0.0));
    let flat = Tensor::<B>::from_vec(cloud(4, 0.3, 0.0), &[8], &B::default_device()).unwrap();
    let three_d = Tensor::<B>::from_vec(cloud(3, 0.3, 0.0), &[2, 3], &B::default_device()).unwrap();
    let empty = Tensor::<B>::zeros(&[0, 2], &B::default_device());
    let message = |r: Result<Tensor<B>>| match r {
        Err(e @ PointSetError::Invalid { .. }) => e.to_string(),
        other => panic!("expected an invalid-input error, got {other:?}"),
    };
    let sinkhorn = |x: &Tensor<B>, y: &Tensor<B>, epsilon: f32| {
        sinkhorn_divergence(x, y, &SinkhornOptions::new(epsilon))
    };
    assert!(message(l2_loss(&a, &b)).contains("4 particles and 3 target points"));
    assert!(message(l2_loss(&a, &flat)).contains("[N, d] tensors"));
    assert!(message(l2_loss(&a, &three_d)).contains("2-dimensional but"));
    assert!(message(l2_loss(&empty, &empty)).contains("empty point set"));
    assert!(message(sinkhorn(&a, &empty, 0.1)).starts_with("sinkhorn divergence: empty"));
    assert!(message(sinkhorn(&a, &b, 0.0)).contains("epsilon must be positive"));
    assert!(message(sinkhorn(&a, &b, f32::NAN)).contains("epsilon must be positive"));
    // Sets of different sizes are fine for the Sinkhorn divergence.
    assert!(sinkhorn(&a, &b, 0.1).is_ok());
}

/// Chamfer: from `(0, 0)` the nearest of `(3, 4)` and `(0, 1)` is 1 away; from those, `(0, 0)`
/// is 5 and 1 away (mean 3); the symmetric mean is 2.
#[test]
fn the_chamfer_distance_averages_nearest_distances_both_ways() {
    let a = [0.0, 0.0];
    let b = [3.0, 4.0, 0.0, 1.0];
    assert_eq!(chamfer_distance(&a, &b, 2), 2.0);
    assert_eq!(chamfer_distance(&b, &a, 2), 2.0);
    assert_eq!(chamfer_distance(&b, &b, 2), 0.0);
    assert!(chamfer_distance(&a, &[], 2).is_nan());
    assert!(chamfer_distance(&a, &b, 0).is_nan());
}

/// A translated copy is `|shift|` away in the Wasserstein estimate (the optimal plan is the
/// translation); a set is 0 away from itself in both distances.
#[test]
fn set_distances_measure_a_translation() {
    let a = cloud(12, 0.3, 0.0);
    let shifted = cloud(12, 0.3, 0.5);
    let apart = set_distances(&a, &shifted, 2).unwrap();
    assert!(
        (apart.wasserstein - 0.5).abs() < 0.05,
        "Wasserstein estimate {} for a shift of 0.5",
        apart.wasserstein
    );
    assert!(apart.chamfer > 0.0 && apart.chamfer < 0.51);
    let same = set_distances(&a, &a, 2).unwrap();
    assert_eq!(same.chamfer, 0.0);
    assert!(same.wasserstein < 0.02, "{}", same.wasserstein);
    for (x, y, d) in [
        (&a[..], &[][..], 2),
        (&a[..], &a[..3], 2),
        (&a[..], &a[..], 0),
    ] {
        assert!(matches!(
            set_distances(x, y, d),
            Err(PointSetError::Invalid {
                what: "set distances",
                ..
            })
        ));
    }
}

#[test]
fn the_host_sinkhorn_divergence_vanishes_on_equal_sets_and_checks_its_inputs() {
    let options = SinkhornOptions::new(0.01);
    let a = cloud(40, 0.3, 0.0);
    let same = sinkhorn_divergence_host(&a, &a, 2, &options).unwrap();
    assert!(same.abs() < 1e-9, "S(a, a) = {same}");
    // A rigid shift by s: S tends to ½|s|² as ε → 0 and stays below it (entropic blur).
    let s = 0.05f32;
    let b: Vec<f32> = a.iter().map(|x| x + s).collect();
    let shifted = sinkhorn_divergence_host(&a, &b, 2, &options).unwrap();
    let half_w2 = 0.5 * 2.0 * f64::from(s) * f64::from(s);
    assert!(
        shifted > 0.5 * half_w2 && shifted <= half_w2 * (1.0 + 1e-6),
        "{shifted} vs {half_w2}"
    );
    for (x, y, d) in [
        (&a[..0], &a[..], 2),
        (&a[..3], &a[..], 2),
        (&a[..], &a[..], 0),
    ] {
        assert!(sinkhorn_divergence_host(x, y, d, &options).is_err());
    }
    let mut bad = a.clone();
    bad[5] = f32::NAN;
    assert!(sinkhorn_divergence_host(&bad, &a, 2, &options).is_err());
    assert!(sinkhorn_divergence_host(&a, &a, 2, &SinkhornOptions::new(0.0)).is_err());
}
