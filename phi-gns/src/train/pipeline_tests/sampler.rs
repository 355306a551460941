//! The window sampler: its windows, determinism, uniformity and errors.

use std::collections::HashMap;

use crate::data::{DataError, Dataset};
use crate::train::sampler::{WindowRef, WindowSampler, WindowSpec};

use super::common::{chi_square, chi_square_bound, temp_dir, write_dataset};

/// Two frames before, two inputs and two after: `F = 1 + 3 + 2 = 6`.
const SPEC: WindowSpec = WindowSpec {
    input_velocities: 2,
    span_before: 1,
    span_after: 2,
};

/// Every `(trajectory, t)` whose frames `t − C − before ..= t + after` lie in the trajectory,
/// by brute force.
fn all_windows(lengths: &[usize], spec: WindowSpec) -> Vec<WindowRef> {
    let mut windows = Vec::new();
    for (trajectory, &frames) in lengths.iter().enumerate() {
        for frame in 0..frames {
            let first = frame as isize - (spec.input_velocities + spec.span_before) as isize;
            if first >= 0 && frame + spec.span_after < frames {
                windows.push(WindowRef { trajectory, frame });
            }
        }
    }
    windows
}

#[test]
fn the_sampler_enumerates_exactly_the_windows_inside_the_trajectories() {
    assert_eq!(SPEC.frames(), 6);
    assert_eq!(SPEC.first_frame(7), 4);
    assert_eq!([5, 6, 9].map(|frames| SPEC.windows_in(frames)), [0, 1, 4]);
    let lengths = vec![3, 8, 10, 6, 9];
    let sampler = WindowSampler::new("train", lengths.clone(), SPEC).unwrap();
    let expected = all_windows(&lengths, SPEC);
    assert_eq!(sampler.windows(), expected.len());
    let listed: Vec<WindowRef> = (0..sampler.windows())
        .map(|k| sampler.window(k).unwrap())
        .collect();
    assert_eq!(listed, expected);
    assert_eq!(sampler.window(sampler.windows()), None);
    assert_eq!(sampler.lengths(), lengths);
    assert_eq!((sampler.split(), sampler.spec()), ("train", SPEC));
}

#[test]
fn a_step_draws_the_same_windows_every_time_and_other_steps_draw_others() {
    let sampler = WindowSampler::new("train", vec![40, 50, 60], SPEC).unwrap();
    let batch = sampler.sample(11, 5, 8);
    assert_eq!(batch.len(), 8);
    assert_eq!(batch, sampler.sample(11, 5, 8));
    // The same sampler rebuilt (a resumed run) draws the same.
    let rebuilt = WindowSampler::new("train", vec![40, 50, 60], SPEC).unwrap();
    assert_eq!(batch, rebuilt.sample(11, 5, 8));
    assert_ne!(batch, sampler.sample(11, 6, 8));
    assert_ne!(batch, sampler.sample(12, 5, 8));
    // Draws are in batch order: a smaller batch is a prefix.
    assert_eq!(sampler.sample(11, 5, 3), batch[..3]);
    assert!(sampler.sample(11, 5, 0).is_empty());
}

#[test]
fn draws_are_uniform_over_all_windows_and_never_leave_a_trajectory() {
    // 1 + 3 + 5 + 15 = 24 windows: a trajectory-uniform sampler would draw each window of the
    // first trajectory 6 times too often.
    let lengths = vec![6, 8, 10, 20];
    let sampler = WindowSampler::new("train", lengths.clone(), SPEC).unwrap();
    let windows = all_windows(&lengths, SPEC);
    assert_eq!(windows.len(), 24);
    let mut counts: HashMap<WindowRef, u64> = windows.iter().map(|&w| (w, 0)).collect();
    for step in 0..200 {
        for w in sampler.sample(3, step, 120) {
            let count = counts
                .get_mut(&w)
                .unwrap_or_else(|| panic!("{w:?} is not a window inside its trajectory"));
            *count += 1;
        }
    }
    let counts: Vec<u64> = windows.iter().map(|w| counts[w]).collect();
    let chi2 = chi_square(&counts);
    assert!(
        chi2 < chi_square_bound(counts.len()),
        "χ² = {chi2} over {} windows: {counts:?}",
        counts.len()
    );
}

#[test]
fn a_split_without_a_window_is_an_error_naming_split_and_lengths() {
    let message = |lengths: Vec<usize>| match WindowSampler::new("valid", lengths, SPEC) {
        Err(e @ DataError::InvalidInput { .. }) => e.to_string(),
        other => panic!("expected an error, got {other:?}"),
    };
    let text = message(vec![3, 5, 4]);
    assert!(
        text.contains("'valid'") && text.contains("6 frames") && text.contains("3 to 5 frames"),
        "{text}"
    );
    let text = message(vec![5, 5]);
    assert!(text.contains("2 trajectories have 5 frames"), "{text}");
    let text = message(Vec::new());
    assert!(text.contains("no trajectories"), "{text}");
    // One trajectory long enough is enough.
    assert_eq!(
        WindowSampler::new("valid", vec![3, 6, 4], SPEC)
            .unwrap()
            .windows(),
        1
    );
}

#[test]
fn the_sampler_of_a_split_reads_the_frame_count_from_the_metadata() {
    let dir = temp_dir("sampler-split");
    write_dataset(&dir, &[3, 4, 5], 9);
    let dataset = Dataset::open(&dir).unwrap();
    let sampler = WindowSampler::for_split(&dataset, "train", SPEC, None).unwrap();
    assert_eq!(sampler.lengths(), [9, 9, 9]);
    assert_eq!(sampler.windows(), 3 * 4);
    let err = WindowSampler::for_split(&dataset, "test", SPEC, None).unwrap_err();
    assert!(matches!(err, DataError::UnknownSplit { .. }), "{err}");
    // `data.trajectories`: the first ones only, never none or more than there are.
    let first = WindowSampler::for_split(&dataset, "train", SPEC, Some(2)).unwrap();
    assert_eq!(first.lengths(), [9, 9]);
    let drawn: std::collections::BTreeSet<usize> = (0..200)
        .flat_map(|step| first.sample(5, step, 4))
        .map(|w| w.trajectory)
        .collect();
    assert_eq!(drawn, [0, 1].into());
    for bad in [0, 4] {
        let err = WindowSampler::for_split(&dataset, "train", SPEC, Some(bad)).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("data.trajectories") && text.contains("holds 3"),
            "{text}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
