//! Welford moments, their merge, and the velocity / acceleration definitions.

use phi_gns::data::{LIQUID, Moments, OBSTACLE, Trajectory, TrajectoryStats};

use crate::common::{Rng, assert_rel_close, sample_trajectory};

/// Mean and M2 per component by the textbook two-pass method.
fn two_pass(samples: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let dim = samples[0].len();
    let n = samples.len() as f64;
    let mean: Vec<f64> = (0..dim)
        .map(|k| samples.iter().map(|x| x[k]).sum::<f64>() / n)
        .collect();
    let m2 = (0..dim)
        .map(|k| samples.iter().map(|x| (x[k] - mean[k]).powi(2)).sum())
        .collect();
    (mean, m2)
}

/// Samples with a large mean and a small spread, where a one-pass sum of squares would lose
/// most digits.
fn samples(seed: u64, n: usize, dim: usize) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            (0..dim)
                .map(|k| 1e4 * (k as f64 + 1.0) + rng.uniform() - 0.5)
                .collect()
        })
        .collect()
}

fn pushed(samples: &[Vec<f64>], dim: usize) -> Moments {
    let mut m = Moments::new(dim);
    for x in samples {
        m.push(x);
    }
    m
}

#[test]
fn welford_agrees_with_two_passes() {
    let xs = samples(1, 10_000, 3);
    let m = pushed(&xs, 3);
    let (mean, m2) = two_pass(&xs);
    assert_eq!(m.count(), 10_000);
    for k in 0..3 {
        assert_rel_close(m.mean()[k], mean[k], 1e-12, "mean");
        assert_rel_close(m.m2()[k], m2[k], 1e-9, "M2");
        assert_rel_close(m.std()[k], (m2[k] / 10_000.0).sqrt(), 1e-9, "std");
    }
    // The spread is uniform on [-0.5, 0.5): variance 1/12.
    assert!((m.variance()[0] - 1.0 / 12.0).abs() < 0.01);
}

#[test]
fn merged_shards_equal_a_single_pass() {
    let xs = samples(2, 5_000, 2);
    let single = pushed(&xs, 2);
    // Uneven shards, including empty ones, merged in order and in reverse.
    let cuts = [0, 0, 1, 17, 1_000, 1_001, 3_333, 5_000, 5_000];
    let shards: Vec<Moments> = cuts
        .windows(2)
        .map(|w| pushed(&xs[w[0]..w[1]], 2))
        .collect();
    for order in [false, true] {
        let mut merged = Moments::new(2);
        let mut list: Vec<&Moments> = shards.iter().collect();
        if order {
            list.reverse();
        }
        for shard in list {
            merged.merge(shard).unwrap();
        }
        assert_eq!(merged.count(), single.count());
        for k in 0..2 {
            assert_rel_close(merged.mean()[k], single.mean()[k], 1e-12, "merged mean");
            assert_rel_close(merged.m2()[k], single.m2()[k], 1e-12, "merged M2");
        }
    }
}

#[test]
fn empty_moments_are_zero_and_merge_as_identity() {
    let mut m = Moments::new(2);
    assert_eq!(
        (m.count(), m.mean(), m.std()),
        (0, &[0.0, 0.0][..], vec![0.0, 0.0])
    );
    let other = pushed(&[vec![1.0, 2.0], vec![3.0, 6.0]], 2);
    m.merge(&other).unwrap();
    assert_eq!(m, other);
    m.merge(&Moments::new(2)).unwrap();
    assert_eq!(m, other);
    assert!(m.merge(&Moments::new(3)).is_err());
    assert!(Moments::from_parts(0, vec![1.0], vec![0.0]).is_err());
    assert!(Moments::from_parts(2, vec![1.0], vec![-1.0]).is_err());
    assert!(Moments::from_parts(2, vec![1.0, 2.0], vec![1.0]).is_err());
    assert!(Moments::from_parts(2, vec![f64::NAN], vec![1.0]).is_err());
}

#[test]
fn velocity_and_acceleration_follow_deepmind_definitions() {
    // One liquid particle at x = 0, 1, 3, 7 (y fixed) and one obstacle that jumps around: the
    // obstacle must not count. Velocities 1, 2, 4; accelerations 1, 2.
    let xs = [0.0f32, 1.0, 3.0, 7.0];
    let obstacle = [0.0f32, 100.0, -50.0, 9.0];
    let position: Vec<f32> = xs
        .iter()
        .zip(&obstacle)
        .flat_map(|(&x, &o)| [x, 0.5, o, o])
        .collect();
    let traj = Trajectory::new(2, position, vec![LIQUID, OBSTACLE], 0, 0).unwrap();
    let stats = TrajectoryStats::of(&traj);
    assert_eq!(stats.velocity.count(), 3);
    assert_eq!(stats.velocity.mean(), [7.0 / 3.0, 0.0]);
    let var = ((1.0f64 - 7.0 / 3.0).powi(2)
        + (2.0f64 - 7.0 / 3.0).powi(2)
        + (4.0f64 - 7.0 / 3.0).powi(2))
        / 3.0;
    assert_rel_close(
        stats.velocity.variance()[0],
        var,
        1e-15,
        "velocity variance",
    );
    assert_eq!(stats.acceleration.count(), 2);
    assert_eq!(stats.acceleration.mean(), [1.5, 0.0]);
    assert_eq!(stats.acceleration.std(), [0.5, 0.0]);

    // A single frame has no velocity; two frames have no acceleration.
    let one = Trajectory::new(1, vec![0.3], vec![LIQUID], 0, 0).unwrap();
    assert_eq!(TrajectoryStats::of(&one), TrajectoryStats::new(1));
    let two = Trajectory::new(1, vec![0.3, 0.5], vec![LIQUID], 0, 0).unwrap();
    let two = TrajectoryStats::of(&two);
    assert_eq!((two.velocity.count(), two.acceleration.count()), (1, 0));
}

#[test]
fn per_trajectory_stats_merge_to_the_two_pass_stats_of_all_trajectories() {
    let trajectories: Vec<Trajectory> = (0..6)
        .map(|i| {
            sample_trajectory(
                40 + i,
                i as usize,
                30 + 7 * i as usize,
                10 + i as usize,
                3,
                3,
            )
        })
        .collect();
    let mut merged = TrajectoryStats::new(3);
    for traj in &trajectories {
        merged.merge(&TrajectoryStats::of(traj)).unwrap();
    }
    // Independent computation: collect every liquid velocity and acceleration, then two passes.
    let (mut vs, mut accs) = (Vec::new(), Vec::new());
    for traj in &trajectories {
        let p = |t: usize, i: usize, k: usize| f64::from(traj.frame(t)[i * 3 + k]);
        for i in (0..traj.particles).filter(|&i| traj.particle_type[i] == LIQUID) {
            for t in 1..traj.frames {
                vs.push(
                    (0..3)
                        .map(|k| p(t, i, k) - p(t - 1, i, k))
                        .collect::<Vec<_>>(),
                );
                if t >= 2 {
                    accs.push(
                        (0..3)
                            .map(|k| p(t, i, k) - 2.0 * p(t - 1, i, k) + p(t - 2, i, k))
                            .collect::<Vec<_>>(),
                    );
                }
            }
        }
    }
    let single_v = pushed(&vs, 3);
    let (mean_v, m2_v) = two_pass(&vs);
    let (mean_a, m2_a) = two_pass(&accs);
    assert_eq!(merged.velocity.count() as usize, vs.len());
    assert_eq!(merged.acceleration.count() as usize, accs.len());
    for k in 0..3 {
        assert_rel_close(
            merged.velocity.mean()[k],
            single_v.mean()[k],
            1e-12,
            "v mean",
        );
        assert_rel_close(merged.velocity.m2()[k], single_v.m2()[k], 1e-12, "v M2");
        assert_rel_close(
            merged.velocity.mean()[k],
            mean_v[k],
            1e-9,
            "v mean vs two-pass",
        );
        assert_rel_close(merged.velocity.m2()[k], m2_v[k], 1e-9, "v M2 vs two-pass");
        assert_rel_close(
            merged.acceleration.mean()[k],
            mean_a[k],
            1e-6,
            "a mean vs two-pass",
        );
        assert_rel_close(
            merged.acceleration.m2()[k],
            m2_a[k],
            1e-9,
            "a M2 vs two-pass",
        );
    }
}
