//! Which windows a training step sees: a deterministic sampler, uniform over every valid
//! `(trajectory, frame)` pair of a split (with `[training.impact_sampling]`, a share of the
//! draws goes to the windows with obstacle impacts instead: `train::impacts`).
//!
//! A window of latest input frame `t` holds the frames `t − C − span_before ..= t + span_after`
//! ([`WindowSpec`]): the `C + 1` input positions, `span_before` earlier frames from which
//! pushforward training unrolls the model up to `t`, and `span_after` later frames for the
//! targets (1 for one-step training, `n + 1` for `n` extra unrolled steps). A trajectory of `L`
//! frames has `L − F + 1` valid windows, `F` the window's frame count.
//!
//! Each draw is uniform over all valid windows of the split, so trajectories are weighted by
//! their number of valid windows. DeepMind's `learning_to_simulate` does the same in effect: it
//! cuts every trajectory into all its windows and shuffles them (with a buffer); the
//! `geoelements/gns` loader indexes all windows of all trajectories and shuffles that index each
//! epoch. Ours draws independently with replacement, from the generator of
//! [`step_rng`]`(seed, step, `[`RngStream::Sampling`]`)`, so that the windows of step `s` depend
//! on `(seed, s)` alone and a resumed run sees the batches of an uninterrupted one.

use rand::RngCore;

use super::impacts::ImpactPool;
use super::rng::{RngStream, step_rng, uniform_index};
use crate::data::{DataError, Dataset};

/// The frames a training window spans around its latest input frame `t`:
/// `t − input_velocities − span_before ..= t + span_after`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowSpec {
    /// `C`, the number of input velocities: the model sees the `C + 1` positions `t − C ..= t`.
    pub input_velocities: usize,
    /// Extra frames before the input positions (from which pushforward unrolls start).
    pub span_before: usize,
    /// Frames after `t`: 1 for one-step training (the target `t + 1`), `n + 1` for `n` extra
    /// unrolled steps.
    pub span_after: usize,
}

impl WindowSpec {
    /// The window of one-step training: `C + 1` inputs and the next frame.
    pub fn one_step(input_velocities: usize) -> Self {
        WindowSpec {
            input_velocities,
            span_before: 0,
            span_after: 1,
        }
    }

    /// The number of frames of a window, `F = span_before + C + 1 + span_after`.
    pub fn frames(&self) -> usize {
        self.span_before + self.input_velocities + 1 + self.span_after
    }

    /// The earliest latest-input frame `t` of a window, `C + span_before`.
    pub(crate) fn first_latest_frame(&self) -> usize {
        self.input_velocities + self.span_before
    }

    /// The first frame of the window whose latest input frame is `t`: `t − C − span_before`.
    ///
    /// # Panics
    /// If `t < C + span_before` (no such window; the sampler never draws one).
    pub fn first_frame(&self, t: usize) -> usize {
        t - self.first_latest_frame()
    }

    /// The number of valid windows in a trajectory of `frames` frames: `frames − F + 1`, or 0
    /// when it is shorter than a window.
    pub fn windows_in(&self, frames: usize) -> usize {
        (frames + 1).saturating_sub(self.frames())
    }
}

/// One window of a batch: trajectory `trajectory` of the split, latest input frame `frame`
/// (`t`); the window spans the frames given by its [`WindowSpec`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WindowRef {
    /// The trajectory's index in its split.
    pub trajectory: usize,
    /// The latest input frame `t`.
    pub frame: usize,
}

/// Draws windows uniformly over all valid `(trajectory, t)` pairs of a split; see the
/// [module documentation](self).
#[derive(Debug, Clone)]
pub struct WindowSampler {
    split: String,
    spec: WindowSpec,
    lengths: Vec<usize>,
    /// `ends[i]`: the number of valid windows in trajectories `0..=i`.
    ends: Vec<usize>,
    /// With `[training.impact_sampling]`: the windows with obstacle impacts and the share of
    /// the draws taken from them (see `train::impacts`).
    impacts: Option<(ImpactPool, f64)>,
}

impl WindowSampler {
    /// A sampler over trajectories of `lengths[i]` frames (index `i` in `split`).
    /// Trajectories shorter than a window are never drawn.
    ///
    /// # Errors
    /// [`DataError::InvalidInput`] naming the split and the lengths when no trajectory is as
    /// long as a window.
    pub fn new(
        split: impl Into<String>,
        lengths: Vec<usize>,
        spec: WindowSpec,
    ) -> Result<Self, DataError> {
        let split = split.into();
        let ends: Vec<usize> = lengths
            .iter()
            .scan(0usize, |total, &frames| {
                *total += spec.windows_in(frames);
                Some(*total)
            })
            .collect();
        if ends.last().copied().unwrap_or(0) == 0 {
            let lengths = match (lengths.iter().min(), lengths.iter().max()) {
                (Some(min), Some(max)) if min == max => {
                    format!("its {} trajectories have {min} frames", lengths.len())
                }
                (Some(min), Some(max)) => format!(
                    "its {} trajectories have {min} to {max} frames",
                    lengths.len()
                ),
                _ => "it has no trajectories".to_string(),
            };
            return Err(DataError::InvalidInput {
                what: "window sampler",
                reason: format!(
                    "split '{split}' has no window of {} frames ({} before, {} inputs, {} \
                     after): {lengths}",
                    spec.frames(),
                    spec.span_before,
                    spec.input_velocities + 1,
                    spec.span_after,
                ),
            });
        }
        Ok(WindowSampler {
            split,
            spec,
            lengths,
            ends,
            impacts: None,
        })
    }

    /// The sampler of `split` of `dataset`, whose trajectories all have
    /// [`Metadata::frames`](crate::data::Metadata::frames) frames ([`Dataset::open`] checked
    /// them).
    ///
    /// # Errors
    /// [`DataError::UnknownSplit`]; as [`WindowSampler::new`].
    pub(crate) fn for_split(
        dataset: &Dataset,
        split: &str,
        spec: WindowSpec,
        first: Option<usize>,
    ) -> Result<Self, DataError> {
        let count = dataset.split_len(split)?;
        let used = match first {
            None => count,
            Some(first) if (1..=count).contains(&first) => first,
            Some(first) => {
                return Err(DataError::InvalidInput {
                    what: "data.trajectories",
                    reason: format!(
                        "{first} trajectories asked of split '{split}' of {}, which holds {count}",
                        dataset.dir().display()
                    ),
                });
            }
        };
        Self::new(split, vec![dataset.metadata().frames(); used], spec)
    }

    /// The split's name.
    pub fn split(&self) -> &str {
        &self.split
    }

    /// The frames each window spans.
    pub fn spec(&self) -> WindowSpec {
        self.spec
    }

    /// The number of frames of each trajectory, by index.
    pub fn lengths(&self) -> &[usize] {
        &self.lengths
    }

    /// The number of valid windows of the split (at least 1).
    pub fn windows(&self) -> usize {
        self.ends.last().copied().unwrap_or(0)
    }

    /// The `k`-th valid window in (trajectory, frame) order, `k < windows()`; `None` beyond.
    pub fn window(&self, k: usize) -> Option<WindowRef> {
        let trajectory = self.ends.partition_point(|&end| end <= k);
        let start = trajectory
            .checked_sub(1)
            .map_or(0, |previous| self.ends[previous]);
        self.ends.get(trajectory).map(|_| WindowRef {
            trajectory,
            frame: self.spec.first_latest_frame() + (k - start),
        })
    }

    /// The sampler that takes the fraction `share` (in `(0, 1]`) of its draws from `pool`, in
    /// proportion to each window's impacts, and the others uniformly (a `pool` without windows
    /// leaves every draw uniform).
    pub(crate) fn with_impacts(mut self, pool: ImpactPool, share: f64) -> Self {
        self.impacts = Some((pool, share));
        self
    }

    /// The `batch_size` windows of step `step`: independent uniform draws over all valid
    /// windows, from [`step_rng`]`(seed, step, `[`RngStream::Sampling`]`)` in batch order. With
    /// impact sampling each draw first decides, from the same generator, whether it comes from
    /// the impact pool.
    pub fn sample(&self, seed: u64, step: u64, batch_size: usize) -> Vec<WindowRef> {
        let mut rng = step_rng(seed, step, RngStream::Sampling);
        (0..batch_size)
            .map(|_| {
                let k = self
                    .impact_draw(&mut rng)
                    .unwrap_or_else(|| uniform_index(&mut rng, self.windows()));
                self.window(k)
                    .expect("a uniform index below the window count names a window")
            })
            .collect()
    }

    /// With impact sampling, a window of the pool for the fraction `share` of the calls (a
    /// 53-bit uniform below `share`), `None` otherwise; draws nothing without it.
    fn impact_draw(&self, rng: &mut impl RngCore) -> Option<usize> {
        let (pool, share) = self.impacts.as_ref()?;
        let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        if u < *share { pool.draw(rng) } else { None }
    }
}
