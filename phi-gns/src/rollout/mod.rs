//! Rollouts: a trained GNS run forward from ground-truth frames, feeding its predictions back.
//!
//! A rollout starts from the `C + 1` frames of a trajectory ending at frame `start` and predicts
//! frames `start + 1 ..= start + steps`. Kinematic particles (obstacles, walls) take their next
//! positions from the ground truth at every step, as in DeepMind's evaluation, so a rollout
//! cannot run past the trajectory's last frame.
//!
//! [`Rollout`] is the one stepper every rollout goes through (`phi rollout`, screening, `phi
//! eval`, the pushforward loss, the inverse problems): the window stays on the device, each step
//! predicts, puts the kinematic particles where they must be by a tensor select and slides the
//! window. The radius graph of the new positions is built on the host, so their values are read
//! back once per step; a caller that reads the frame ([`Rollout::read`]) shares that read.
//! [`TrajectoryRollout`] drives it over a trajectory as an iterator of frames.
//!
//! ```no_run
//! # use phi_gns::{data::Trajectory, model::Gns, rollout::{RolloutRange, TrajectoryRollout}};
//! # fn demo(model: &Gns<phi_core::backend::ndarray::NdArray>, trajectory: &Trajectory)
//! #     -> Result<(), phi_gns::model::ModelError> {
//! let c = model.spec().config.input_velocities;
//! let range = RolloutRange::full(c, trajectory.frames);
//! for frame in TrajectoryRollout::new(model, trajectory, range, &Default::default())? {
//!     let frame = frame?;
//!     println!("frame {}: first particle at {:?}", frame.frame, &frame.positions[..2]);
//! }
//! # Ok(()) }
//! ```

mod push;

use phi_core::tensor::Tensor;

use crate::data::Trajectory;
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError, Obstacles, Walls};

/// A model stepping a window forward on the device, its predictions fed back.
///
/// Each [`Rollout::step`] predicts every particle's next positions, replaces those of the
/// kinematic particles (the model's `kinematic_types`) by the positions the caller gives, and
/// slides the window one frame on (the oldest frame dropped, the radius graph rebuilt per
/// example). With [`Walls::Clamp`] in the model's configuration the predicted positions are
/// first clamped into the closed box of the model's bounds (no gradient flows through a clamped
/// coordinate). With [`Obstacles::Push`] the particles that follow the model are then pushed
/// out of the cells of the kinematic particles, on the host values the next graph is built from
/// (no gradient flows through a pushed particle). Gradients flow through the steps when the
/// window or the parameters carry them.
#[derive(Debug)]
pub struct Rollout<'m, B: GnsKernels> {
    model: &'m Gns<B>,
    window: GraphBatch<B>,
    /// `[N, 1]`: 1 where a particle follows the model, 0 where it is kinematic.
    follows_model: Tensor<B>,
    /// `[1, dim]` lower and upper bounds the predictions are clamped into ([`Walls::Clamp`]).
    clamp: Option<(Tensor<B>, Tensor<B>)>,
    /// With [`Obstacles::Push`]: what pushing needs.
    push: Option<Push>,
    /// The positions of the last step, not yet slid into the window, and their host values
    /// once read.
    pending: Option<(Tensor<B>, Option<Vec<f32>>)>,
}

impl<'m, B: GnsKernels> Rollout<'m, B> {
    /// A rollout of `model` from the window and graph of `window`.
    ///
    /// # Errors
    /// [`ModelError::Input`] when `window` does not fit the model.
    pub fn new(model: &'m Gns<B>, window: GraphBatch<B>) -> Result<Self, ModelError> {
        let spec = model.spec();
        let shape = window.positions().shape();
        if shape[1] != spec.config.input_velocities + 1 || shape[2] != spec.config.dim {
            return Err(ModelError::Input {
                what: "rollout window",
                reason: format!(
                    "shape {shape:?}; the model reads [particles, {}, {}]",
                    spec.config.input_velocities + 1,
                    spec.config.dim
                ),
            });
        }
        let follows: Vec<f32> = spec
            .kinematic(window.types())
            .into_iter()
            .map(|k| f32::from(u8::from(!k)))
            .collect();
        let device = window.positions().device();
        let follows_model = Tensor::from_vec(follows, &[shape[0], 1], &device)?;
        Self::with_mask(model, window, &follows_model)
    }

    /// A rollout in which the particles where `mask` (`[N]` or `[N, 1]`) is 0 are kinematic,
    /// whatever their types: a loss's mask of the particles it counts.
    ///
    /// # Errors
    /// [`ModelError::Input`] when `window` does not fit the model or `mask` the window.
    pub(crate) fn with_mask(
        model: &'m Gns<B>,
        window: GraphBatch<B>,
        mask: &Tensor<B>,
    ) -> Result<Self, ModelError> {
        let n = window.positions().shape()[0];
        if mask.numel() != n || mask.shape().len() > 2 {
            return Err(ModelError::Input {
                what: "rollout mask",
                reason: format!("shape {:?} for {n} particles", mask.shape()),
            });
        }
        let spec = model.spec();
        let clamp = match spec.config.walls {
            Walls::Open => None,
            Walls::Clamp => {
                let device = window.positions().device();
                let d = spec.config.dim;
                let side =
                    |i: usize| -> Vec<f32> { spec.bounds.iter().map(|b| b[i] as f32).collect() };
                Some((
                    Tensor::from_vec(side(0), &[1, d], &device)?,
                    Tensor::from_vec(side(1), &[1, d], &device)?,
                ))
            }
        };
        let push = match spec.config.obstacles {
            Obstacles::Open => None,
            Obstacles::Push { cell_size } => {
                let [_, frames, dim] = window.positions().shape()[..] else {
                    unreachable!("GraphBatch keeps a rank-3 window")
                };
                let previous = window
                    .positions()
                    .to_vec()
                    .chunks(frames * dim)
                    .flat_map(|particle| particle[(frames - 1) * dim..].to_vec())
                    .collect();
                Some(Push {
                    cell: cell_size as f32,
                    solid: spec.kinematic(window.types()),
                    moves: mask.to_vec().iter().map(|m| *m != 0.0).collect(),
                    previous,
                })
            }
        };
        Ok(Rollout {
            model,
            window,
            follows_model: mask.reshape(&[n, 1])?,
            clamp,
            push,
            pending: None,
        })
    }

    /// The window the next step reads: `[N, C + 1, dim]`, its graph and types.
    ///
    /// # Errors
    /// As [`Rollout::step`], for sliding the last step's positions in.
    pub fn window(&mut self) -> Result<&GraphBatch<B>, ModelError> {
        self.slide()?;
        Ok(&self.window)
    }

    /// One step: the next positions `[N, dim]` of every particle, the kinematic ones taken from
    /// `kinematic` (`[N, dim]`; only their rows are read).
    ///
    /// # Errors
    /// [`ModelError::Input`] when `kinematic` is not `[N, dim]`; [`ModelError::Graph`] when the
    /// previous step's positions were not finite (a caller that reads them can name the
    /// particle first); shape errors from the network.
    pub fn step(&mut self, kinematic: &Tensor<B>) -> Result<&Tensor<B>, ModelError> {
        self.slide()?;
        let normalised = self.model.normalised_acceleration(&self.window)?;
        self.step_with(&normalised, kinematic)
    }

    /// [`Rollout::step`] from the network's output on the current window (`[N, dim]`
    /// normalised accelerations, from [`Gns::normalised_acceleration`] of
    /// [`Rollout::window`]), for a caller that needs that output too (a multi-step loss).
    ///
    /// # Errors
    /// As [`Rollout::step`].
    pub fn step_with(
        &mut self,
        normalised: &Tensor<B>,
        kinematic: &Tensor<B>,
    ) -> Result<&Tensor<B>, ModelError> {
        self.slide()?;
        let mut predicted = self.model.integrate(&self.window, normalised)?;
        if let Some((lower, upper)) = &self.clamp {
            predicted = predicted.maximum(lower)?.minimum(upper)?;
        }
        if kinematic.shape() != predicted.shape() {
            return Err(ModelError::Input {
                what: "kinematic positions",
                reason: format!(
                    "shape {:?} for next positions {:?}",
                    kinematic.shape(),
                    predicted.shape()
                ),
            });
        }
        let mut next = Tensor::select(&self.follows_model, &predicted, kinematic)?;
        let mut host = None;
        if let Some(push) = &mut self.push {
            let mut values = next.to_vec();
            let spec = self.model.spec();
            let moved = push::push_out(
                &mut values,
                &push.previous,
                &push.moves,
                &push.solid,
                spec.config.dim,
                push.cell,
                &spec.bounds,
            );
            if moved.iter().any(|m| *m) {
                let shape = next.shape();
                let device = next.device();
                let keep: Vec<f32> = moved.iter().map(|m| f32::from(u8::from(!m))).collect();
                let keep = Tensor::from_vec(keep, &[shape[0], 1], &device)?;
                let pushed = Tensor::from_slice(&values, &shape, &device)?;
                next = Tensor::select(&keep, &next, &pushed)?;
            }
            push.previous.clone_from(&values);
            host = Some(values);
        }
        Ok(&self.pending.insert((next, host)).0)
    }

    /// The host values of the last step's positions (`[N, dim]` row-major), read once: the
    /// next step builds its graph from the same values. Empty before the first step.
    pub fn read(&mut self) -> &[f32] {
        match &mut self.pending {
            Some((next, host)) => host.get_or_insert_with(|| next.to_vec()),
            None => &[],
        }
    }

    /// Slides the last step's positions into the window.
    fn slide(&mut self) -> Result<(), ModelError> {
        if let Some((next, host)) = self.pending.take() {
            let spec = self.model.spec();
            self.window = match host {
                Some(host) => self.window.advance_from(&next, &host, spec)?,
                None => self.window.advance(&next, spec)?,
            };
        }
        Ok(())
    }
}

/// What [`Obstacles::Push`] needs from step to step.
#[derive(Debug)]
struct Push {
    /// The side of an obstacle particle's cell.
    cell: f32,
    /// Which particles are solid (the kinematic types).
    solid: Vec<bool>,
    /// Which particles are pushed (those that follow the model).
    moves: Vec<bool>,
    /// The positions of the frame before the next prediction, `[N, dim]`, as pushed.
    previous: Vec<f32>,
}

/// One predicted frame of a [`TrajectoryRollout`].
#[derive(Debug, Clone)]
pub struct RolloutFrame<B: phi_core::Backend> {
    /// The rollout step, counted from 1.
    pub step: usize,
    /// The trajectory frame it predicts (`start + step`).
    pub frame: usize,
    /// The positions `[N, dim]` row-major, in stored units (kinematic particles at the truth).
    pub positions: Vec<f32>,
    /// The same positions on the device.
    pub tensor: Tensor<B>,
}

/// A [`Rollout`] over a trajectory: an iterator of the predicted frames
/// `start + 1 ..= start + steps`, kinematic particles following the ground truth. It stops after
/// the first error: a non-finite position is [`ModelError::NonFinitePrediction`], naming the
/// step, the frame and the particle, and every frame before it has been yielded.
#[derive(Debug)]
pub struct TrajectoryRollout<'a, B: GnsKernels> {
    stepper: Rollout<'a, B>,
    trajectory: &'a Trajectory,
    range: RolloutRange,
    device: B::Device,
    dim: usize,
    step: usize,
    stopped: bool,
}

impl<'a, B: GnsKernels> TrajectoryRollout<'a, B> {
    /// The rollout of `model` on `trajectory` over `range`.
    ///
    /// # Errors
    /// [`ModelError::Input`] for a range or trajectory that does not fit the model; graph
    /// errors for a non-finite input window.
    pub fn new(
        model: &'a Gns<B>,
        trajectory: &'a Trajectory,
        range: RolloutRange,
        device: &B::Device,
    ) -> Result<Self, ModelError> {
        let config = &model.spec().config;
        let (dim, c) = (config.dim, config.input_velocities);
        if trajectory.dim != dim {
            return Err(ModelError::Input {
                what: "trajectory",
                reason: format!("{}D positions for a {dim}D model", trajectory.dim),
            });
        }
        range.check(c, trajectory.frames)?;
        let window = input_window(trajectory, range.start, c);
        let batch =
            GraphBatch::from_host(&window, &trajectory.particle_type, model.spec(), device)?;
        Ok(TrajectoryRollout {
            stepper: Rollout::new(model, batch)?,
            trajectory,
            range,
            device: device.clone(),
            dim,
            step: 0,
            stopped: false,
        })
    }

    /// The next frame, or `None` after the last one or an error.
    fn advance(&mut self) -> Result<RolloutFrame<B>, ModelError> {
        let step = self.step + 1;
        let frame = self.range.start + step;
        let n = self.trajectory.particles;
        let truth = Tensor::from_slice(self.trajectory.frame(frame), &[n, self.dim], &self.device)?;
        let tensor = self.stepper.step(&truth)?.clone();
        let positions = self.stepper.read().to_vec();
        if let Some(bad) = positions.iter().position(|x| !x.is_finite()) {
            return Err(ModelError::NonFinitePrediction {
                step,
                frame,
                particle: bad / self.dim,
            });
        }
        self.step = step;
        Ok(RolloutFrame {
            step,
            frame,
            positions,
            tensor,
        })
    }
}

impl<B: GnsKernels> Iterator for TrajectoryRollout<'_, B> {
    type Item = Result<RolloutFrame<B>, ModelError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.stopped || self.step >= self.range.steps {
            return None;
        }
        let frame = self.advance();
        self.stopped = frame.is_err();
        Some(frame)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = if self.stopped {
            0
        } else {
            self.range.steps - self.step
        };
        (0, Some(left))
    }
}

/// Where a rollout starts and how far it runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RolloutRange {
    /// The last ground-truth frame of the input window (at least `C`).
    pub start: usize,
    /// The number of predicted frames.
    pub steps: usize,
}

impl RolloutRange {
    /// From the first possible frame (`C`) to the end of a trajectory of `frames` frames.
    pub fn full(input_velocities: usize, frames: usize) -> Self {
        RolloutRange {
            start: input_velocities,
            steps: frames.saturating_sub(input_velocities + 1),
        }
    }

    /// Checks the range against a model's window and a trajectory's length.
    ///
    /// # Errors
    /// [`ModelError::Input`] when the window would begin before frame 0 or the rollout would
    /// end after the last frame.
    pub fn check(&self, input_velocities: usize, frames: usize) -> Result<(), ModelError> {
        if self.start < input_velocities {
            return Err(ModelError::Input {
                what: "rollout start",
                reason: format!(
                    "frame {} leaves no room for the {} frames before it that the model reads",
                    self.start, input_velocities
                ),
            });
        }
        // Checked: a step count near usize::MAX must be refused, not wrap around.
        if self
            .start
            .checked_add(self.steps)
            .is_none_or(|end| end >= frames)
        {
            return Err(ModelError::Input {
                what: "rollout steps",
                reason: format!(
                    "{} steps from frame {} end after the trajectory's last frame {} (kinematic \
                     particles follow the ground truth)",
                    self.steps,
                    self.start,
                    frames.saturating_sub(1)
                ),
            });
        }
        Ok(())
    }
}

/// Rolls `model` out on `trajectory` over `range`, calling `on_frame(step, positions)` with each
/// predicted frame (`step` counts from 1, `positions` is `[N, dim]` row-major in stored units)
/// as soon as it exists, so that a caller can stream frames to a file.
///
/// # Errors
/// [`ModelError::Input`] for a range or trajectory that does not fit the model;
/// [`ModelError::NonFinitePrediction`] at the first step with a NaN or infinite position (every
/// earlier frame has been handed to `on_frame`); whatever `on_frame` returns.
pub fn rollout<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
    device: &B::Device,
    mut on_frame: impl FnMut(usize, &[f32]) -> Result<(), ModelError>,
) -> Result<(), ModelError> {
    for frame in TrajectoryRollout::new(model, trajectory, range, device)? {
        let frame = frame?;
        on_frame(frame.step, &frame.positions)?;
    }
    Ok(())
}

/// The predicted frames of [`rollout`] collected: `[steps, N, dim]` row-major.
///
/// # Errors
/// As [`rollout`] (the frames before a non-finite prediction are lost; use [`rollout`] to keep
/// them).
pub fn rollout_positions<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
    device: &B::Device,
) -> Result<Vec<f32>, ModelError> {
    let mut frames = Vec::with_capacity(range.steps * trajectory.particles * trajectory.dim);
    rollout(model, trajectory, range, device, |_, positions| {
        frames.extend_from_slice(positions);
        Ok(())
    })?;
    Ok(frames)
}

/// The position MSE of one frame: the mean of `(predicted − truth)²` over the particles that
/// are not `kinematic` and the `dim` components (0 when every particle is kinematic), in f64.
pub fn position_mse(predicted: &[f32], truth: &[f32], kinematic: &[bool], dim: usize) -> f64 {
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (i, _) in kinematic.iter().enumerate().filter(|(_, k)| !**k) {
        for a in i * dim..(i + 1) * dim {
            let d = f64::from(predicted[a]) - f64::from(truth[a]);
            sum += d * d;
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The model's input window `[N, C + 1, dim]` (row-major) of frames `frame − C ..= frame` of
/// `trajectory`, for `C = input_velocities`.
///
/// # Panics
/// If `frame < C` or `frame` is not a frame of the trajectory (check with
/// [`RolloutRange::check`]).
pub fn input_window(trajectory: &Trajectory, frame: usize, input_velocities: usize) -> Vec<f32> {
    let frames: Vec<&[f32]> = (frame - input_velocities..=frame)
        .map(|t| trajectory.frame(t))
        .collect();
    let mut window = vec![0.0; trajectory.particles * frames.len() * trajectory.dim];
    fill_window(&frames, trajectory.particles, trajectory.dim, &mut window);
    window
}

/// `window [N, C + 1, dim]` from `C + 1` frames `[N, dim]`, oldest first.
pub(crate) fn fill_window<F: AsRef<[f32]>>(
    history: &[F],
    n: usize,
    dim: usize,
    window: &mut [f32],
) {
    let frames = history.len();
    for i in 0..n {
        for (t, frame) in history.iter().enumerate() {
            let dst = (i * frames + t) * dim;
            window[dst..dst + dim].copy_from_slice(&frame.as_ref()[i * dim..(i + 1) * dim]);
        }
    }
}
