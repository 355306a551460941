//! Training batches on the host, in step order, read ahead on another thread so that a step
//! does not wait on disk.
//!
//! [`BatchSource::batch`]`(step)` builds the batch of one step: the windows that
//! [`WindowSampler::sample`] draws for `(seed, step)`, cut from trajectories of a
//! [`TrajectoryCache`]. It depends on `(seed, step)` and the files alone (not on which
//! trajectories happen to be cached), so any step can be rebuilt. [`BatchStream`] hands out the
//! batches of `start_step, start_step + 1, ...`, built either by a background thread up to
//! `read_ahead` steps ahead (through a bounded channel) or, with `read_ahead = 0`, on the
//! caller's thread; both run the same code and give the same batches.
//!
//! Memory: the cache holds at most its capacity; the read-ahead thread holds at most
//! `read_ahead` finished batches in the channel and one it is building.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;

use super::cache::TrajectoryCache;
use super::impacts::{ImpactCriterion, ImpactPool};
use super::sampler::{WindowRef, WindowSampler, WindowSpec};
use crate::data::{DataError, Dataset, IoError};

/// The default capacity of the trajectory cache: 1 GiB (about 250 trajectories of the thesis'
/// datasets).
pub(crate) const DEFAULT_CACHE_BYTES: usize = 1 << 30;

/// One window of a batch on the host: the frames `first_frame .. first_frame + F` of trajectory
/// `trajectory`, latest input frame `frame`.
#[derive(Debug, Clone, PartialEq)]
pub struct HostExample {
    /// The trajectory's index in its split.
    pub trajectory: usize,
    /// The latest input frame `t`.
    pub frame: usize,
    /// The window's first frame, `t − C − span_before`.
    pub first_frame: usize,
    /// The number of particles `N`.
    pub particles: usize,
    /// The number of spatial dimensions.
    pub dim: usize,
    /// The particle types `[N]` ([`crate::data::OBSTACLE`], [`crate::data::LIQUID`]).
    pub particle_type: Vec<i64>,
    /// The stored positions `[F, N, dim]`, frame-major, of frames `first_frame ..`;
    /// `F = span_before + C + 1 + span_after`.
    pub frames: Vec<f32>,
}

impl HostExample {
    /// The number of frames `F` of the window.
    pub fn frame_count(&self) -> usize {
        self.frames.len() / (self.particles * self.dim).max(1)
    }

    /// The positions `[N, dim]` of trajectory frame `t` (an absolute frame number, from
    /// `first_frame` to `first_frame + F − 1`); `None` outside the window.
    pub fn positions_at(&self, t: usize) -> Option<&[f32]> {
        let per_frame = self.particles * self.dim;
        let k = t.checked_sub(self.first_frame)?;
        self.frames.get(k * per_frame..(k + 1) * per_frame)
    }
}

/// The examples of one optimisation step, in the sampler's order.
#[derive(Debug, Clone, PartialEq)]
pub struct HostBatch {
    /// The optimisation step.
    pub step: u64,
    /// The windows, `batch_size` of them.
    pub examples: Vec<HostExample>,
}

/// How batches are drawn: the seed, the number of windows per step and their span.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchConfig {
    /// The seed of the sampling generator (`train::rng::step_rng`).
    pub seed: u64,
    /// Windows per step (DeepMind's default: 2).
    pub batch_size: usize,
    /// The frames of each window.
    pub window: WindowSpec,
    /// The capacity of the trajectory cache in bytes.
    pub cache_bytes: usize,
    /// Draws from the split's first `trajectories` trajectories only (all when `None`).
    pub trajectories: Option<usize>,
}

impl BatchConfig {
    /// A configuration with the default cache capacity (`DEFAULT_CACHE_BYTES`).
    pub fn new(seed: u64, batch_size: usize, window: WindowSpec) -> Self {
        BatchConfig {
            seed,
            batch_size,
            window,
            cache_bytes: DEFAULT_CACHE_BYTES,
            trajectories: None,
        }
    }
}

/// Builds the batch of any step of one split (the synchronous path); see the
/// module documentation of `train::stream`.
#[derive(Debug, Clone)]
pub struct BatchSource {
    sampler: WindowSampler,
    cache: TrajectoryCache,
    seed: u64,
    batch_size: usize,
}

impl BatchSource {
    /// The batches of `split` of `dataset` drawn as `config` says.
    ///
    /// # Errors
    /// [`DataError::UnknownSplit`]; [`DataError::InvalidInput`] when `config.trajectories` is 0
    /// or more than the split holds; as `WindowSampler::new` when no trajectory is as long as
    /// a window.
    pub fn new(dataset: &Dataset, split: &str, config: &BatchConfig) -> Result<Self, DataError> {
        Ok(BatchSource {
            sampler: WindowSampler::for_split(dataset, split, config.window, config.trajectories)?,
            cache: TrajectoryCache::new(dataset, split, config.cache_bytes)?,
            seed: config.seed,
            batch_size: config.batch_size,
        })
    }

    /// The source that draws the fraction `share` of its windows in proportion to their
    /// obstacle impacts under `criterion` (see `train::impacts`), after reading every trajectory
    /// of its split once to count them; returns the pool's windows and impacts too.
    ///
    /// # Errors
    /// A trajectory file that cannot be read (named).
    pub fn with_impacts(
        mut self,
        criterion: &ImpactCriterion,
        share: f64,
    ) -> Result<(Self, usize, u64), DataError> {
        let pool = ImpactPool::scan(self.cache.dataset(), &self.sampler, criterion)?;
        let (windows, impacts) = (pool.windows(), pool.impacts());
        self.sampler = self.sampler.with_impacts(pool, share);
        Ok((self, windows, impacts))
    }

    /// The batch of step `step`.
    ///
    /// # Errors
    /// As `TrajectoryCache::get`: a trajectory file of the batch is missing or damaged (the
    /// error names it).
    pub fn batch(&mut self, step: u64) -> Result<HostBatch, DataError> {
        self.batch_unless(step, &AtomicBool::new(false))
            .expect("an unset flag never cancels")
    }

    /// The batch of step `step`, or `None` as soon as `cancelled` is set (checked before each
    /// file read).
    fn batch_unless(
        &mut self,
        step: u64,
        cancelled: &AtomicBool,
    ) -> Option<Result<HostBatch, DataError>> {
        let windows = self.sampler.sample(self.seed, step, self.batch_size);
        let mut examples = Vec::with_capacity(windows.len());
        for window in windows {
            if cancelled.load(Ordering::Relaxed) {
                return None;
            }
            match self.example(window) {
                Ok(example) => examples.push(example),
                Err(e) => return Some(Err(e)),
            }
        }
        Some(Ok(HostBatch { step, examples }))
    }

    /// The example of `window` (one of the sampler's windows), cut from its trajectory: what
    /// [`BatchSource::batch`] puts in a batch, for a caller that walks the windows itself.
    ///
    /// # Errors
    /// As [`BatchSource::batch`].
    pub fn example(&mut self, window: WindowRef) -> Result<HostExample, DataError> {
        let trajectory = self.cache.get(window.trajectory)?;
        let spec = self.sampler.spec();
        let first_frame = spec.first_frame(window.frame);
        let per_frame = trajectory.particles * trajectory.dim;
        let range = first_frame * per_frame..(first_frame + spec.frames()) * per_frame;
        let Some(frames) = trajectory.position.get(range) else {
            // The sampler's lengths come from the metadata, which the read checked; a file
            // that disagrees anyway is named rather than cut short.
            let path = Dataset::trajectory_path(
                self.cache.dataset().dir(),
                self.sampler.split(),
                window.trajectory,
            );
            return Err(DataError::Invalid {
                path,
                reason: format!(
                    "{} frames cannot hold the window of frames {first_frame}..{}",
                    trajectory.frames,
                    first_frame + spec.frames()
                ),
            });
        };
        Ok(HostExample {
            trajectory: window.trajectory,
            frame: window.frame,
            first_frame,
            particles: trajectory.particles,
            dim: trajectory.dim,
            particle_type: trajectory.particle_type.clone(),
            frames: frames.to_vec(),
        })
    }

    /// The window sampler.
    pub fn sampler(&self) -> &WindowSampler {
        &self.sampler
    }

    /// The trajectory cache.
    pub fn cache(&self) -> &TrajectoryCache {
        &self.cache
    }
}

/// The batches of consecutive steps from a start step; see the [module documentation](self).
///
/// Dropping the stream stops its thread: the thread stops before its next file read (or as
/// soon as the batch it is sending has nowhere to go) and the drop waits for that, so at most
/// one file read.
#[derive(Debug)]
pub(crate) struct BatchStream {
    next_step: u64,
    producer: Producer,
}

#[derive(Debug)]
enum Producer {
    /// `read_ahead = 0`: each batch is built in [`BatchStream::next`].
    Inline(Box<BatchSource>),
    ReadAhead(ReadAhead),
}

/// The background thread and the receiving end of its channel.
#[derive(Debug)]
struct ReadAhead {
    /// `None` once dropped (so that a send blocked on a full channel returns).
    batches: Option<Receiver<Result<HostBatch, DataError>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl BatchStream {
    /// The batches of `source` from step `start_step` on. With `read_ahead > 0` a background
    /// thread builds up to `read_ahead` batches ahead of [`next`](Self::next); with 0 each
    /// batch is built in `next`.
    ///
    /// # Errors
    /// [`DataError::File`] when the thread cannot be started.
    pub fn new(source: BatchSource, start_step: u64, read_ahead: usize) -> Result<Self, DataError> {
        let producer = if read_ahead == 0 {
            Producer::Inline(Box::new(source))
        } else {
            Producer::ReadAhead(ReadAhead::spawn(source, start_step, read_ahead)?)
        };
        Ok(BatchStream {
            next_step: start_step,
            producer,
        })
    }

    /// The step whose batch the next call of [`next`](Self::next) returns.
    #[cfg(test)]
    pub fn next_step(&self) -> u64 {
        self.next_step
    }

    /// The batch of the next step. An error is that step's (a trajectory file of its batch is
    /// missing or damaged, named in the error); the stream goes on with the following step.
    ///
    /// # Errors
    /// As [`BatchSource::batch`]; [`DataError::InvalidInput`] at step `u64::MAX`, where the
    /// stream ends.
    ///
    /// # Panics
    /// Resumes the panic of the read-ahead thread, if it panicked (a bug, not bad data).
    #[allow(clippy::should_implement_trait)] // an endless stream of results, not an iterator
    pub fn next(&mut self) -> Result<HostBatch, DataError> {
        let step = self.next_step;
        if step == u64::MAX {
            return Err(DataError::InvalidInput {
                what: "batch stream",
                reason: "the stream ends before step u64::MAX".into(),
            });
        }
        self.next_step += 1;
        match &mut self.producer {
            Producer::Inline(source) => source.batch(step),
            Producer::ReadAhead(read_ahead) => read_ahead.receive(step),
        }
    }
}

impl ReadAhead {
    fn spawn(source: BatchSource, start_step: u64, depth: usize) -> Result<Self, DataError> {
        let (sender, batches) = sync_channel(depth);
        let stop = Arc::new(AtomicBool::new(false));
        let thread_stop = Arc::clone(&stop);
        let split_dir = source.cache.dataset().dir().join(source.sampler.split());
        let thread = std::thread::Builder::new()
            .name("phi-gns-batches".into())
            .spawn(move || produce(source, start_step, sender, &thread_stop))
            .map_err(|e| {
                DataError::File(IoError::io(
                    &split_dir,
                    "cannot start the read-ahead thread of",
                    e,
                ))
            })?;
        Ok(ReadAhead {
            batches: Some(batches),
            stop,
            thread: Some(thread),
        })
    }

    /// The next batch from the thread, which is the batch of `step`.
    fn receive(&mut self, step: u64) -> Result<HostBatch, DataError> {
        match self.batches.as_ref().map(Receiver::recv) {
            Some(Ok(batch)) => {
                debug_assert!(batch.as_ref().map_or(true, |b| b.step == step));
                batch
            }
            // The thread ended before `u64::MAX`: it panicked.
            Some(Err(mpsc::RecvError)) | None => {
                if let Some(Err(panic)) = self.thread.take().map(JoinHandle::join) {
                    std::panic::resume_unwind(panic);
                }
                Err(DataError::InvalidInput {
                    what: "batch stream",
                    reason: format!("no batch for step {step}: the read-ahead thread ended"),
                })
            }
        }
    }
}

impl Drop for ReadAhead {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        drop(self.batches.take());
        if let Some(thread) = self.thread.take() {
            // A panic of the thread has been reported by `receive` or is dropped with the stream.
            let _ = thread.join();
        }
    }
}

/// The loop of the read-ahead thread: the batches of `start_step, start_step + 1, ...` (up to
/// `u64::MAX`, exclusive) into `sender` until the receiver is dropped or `stop` is set.
fn produce(
    mut source: BatchSource,
    start_step: u64,
    sender: SyncSender<Result<HostBatch, DataError>>,
    stop: &AtomicBool,
) {
    for step in start_step..u64::MAX {
        let Some(batch) = source.batch_unless(step, stop) else {
            return;
        };
        if sender.send(batch).is_err() {
            return;
        }
    }
}
