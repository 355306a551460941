//! A run's states kept on the host, frame by frame, and their arrays `[T+1, N, d]`: what `phi
//! simulate` writes as `trajectory.npz` and what [`run_scene`] returns to a library caller;
//! and [`SceneRun`], a scene's simulation stepped on demand, which `run_scene` steps.
//!
//! With inflows the particle count grows; the arrays are as wide as the last frame and the rows
//! of particles that do not exist yet are NaN, with `particle_count` saying how many exist.
//!
//! ```
//! use phi_core::Backend;
//! use phi_core::backend::ndarray::NdArray;
//! use phi_flip::{Scene, run_scene};
//!
//! let scene = Scene::from_toml(
//!     r#"
//!     [domain]
//!     resolution = [8, 8]
//!     [simulation]
//!     dt = 0.05
//!     steps = 3
//!     [[liquid]]
//!     geometry = { type = "box", lower = [1, 1], upper = [4, 4] }
//!     "#,
//!     "<string>",
//! )?;
//! let recording = run_scene::<NdArray>(&scene, "<string>", None, &NdArray::default_device())?;
//! let arrays = recording.arrays();
//! assert_eq!(arrays.frames, 4);
//! assert_eq!(arrays.positions.len(), 4 * arrays.particles * 2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use phi_core::Backend;
use phi_core::fields::LatticeKernels;

use crate::scene::Scene;
use crate::sim::{FlipSimulation, Particles, StepStats};
use crate::{Result, Scheme};

/// One recorded state on the host: positions and velocities `[N * d]`, with APIC the affine
/// matrices `[N * d * d]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// Positions `[N, d]` row-major, domain units.
    pub positions: Vec<f32>,
    /// Velocities `[N, d]` row-major, domain units per second.
    pub velocities: Vec<f32>,
    /// APIC's affine matrices `[N, d, d]` (zero in frame 0); `None` for the other schemes.
    pub affine: Option<Vec<f32>>,
}

/// The states of a run so far, frame 0 (the initial state) first.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    dim: usize,
    dt: f32,
    apic: bool,
    frames: Vec<RecordedFrame>,
}

/// A [`Recording`] as dense arrays (see the [module documentation](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryArrays {
    /// Recorded frames `T + 1`.
    pub frames: usize,
    /// Particles `N`: the most any frame holds.
    pub particles: usize,
    /// Dimension `d`.
    pub dim: usize,
    /// Positions `[T+1, N, d]`, NaN for particles that do not exist yet.
    pub positions: Vec<f32>,
    /// Velocities `[T+1, N, d]`, NaN for particles that do not exist yet.
    pub velocities: Vec<f32>,
    /// With APIC, the affine matrices `[T+1, N, d, d]`, NaN for particles that do not exist yet.
    pub affine: Option<Vec<f32>>,
    /// Particles that exist in each frame, `[T+1]`.
    pub particle_count: Vec<usize>,
    /// Each frame's time `t · dt`, seconds, `[T+1]`.
    pub time: Vec<f32>,
}

impl RecordedFrame {
    /// The state `particles` read back to the host; `apic` keeps the affine matrices (zero
    /// where the state has none).
    pub fn of<B: Backend>(particles: &Particles<B>, apic: bool) -> Self {
        RecordedFrame {
            positions: particles.positions.to_vec(),
            velocities: particles.velocities.to_vec(),
            affine: apic.then(|| particles.affine_or_zeros().to_vec()),
        }
    }
}

impl Recording {
    /// An empty recording of a `dim`-dimensional run with step `dt`; `apic` keeps the affine
    /// matrices too.
    pub fn new(dim: usize, dt: f32, apic: bool) -> Self {
        Recording {
            dim,
            dt,
            apic,
            frames: Vec::new(),
        }
    }

    /// Makes room for `frames` more frames.
    pub fn reserve(&mut self, frames: usize) {
        self.frames.reserve(frames);
    }

    /// Appends the state `particles` (read back to the host).
    pub fn push<B: Backend>(&mut self, particles: &Particles<B>) {
        self.frames.push(RecordedFrame::of(particles, self.apic));
    }

    /// Appends a state already on the host (a frame of another recording, or one a caller
    /// read back itself).
    pub fn push_frame(&mut self, frame: RecordedFrame) {
        self.frames.push(frame);
    }

    /// The recorded frames, frame 0 first.
    pub fn frames(&self) -> &[RecordedFrame] {
        &self.frames
    }

    /// The number of recorded frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether nothing has been recorded.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The dimension of the run.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The step length, seconds.
    pub fn dt(&self) -> f32 {
        self.dt
    }

    /// The frames as dense arrays, NaN-padded to the widest frame.
    pub fn arrays(&self) -> TrajectoryArrays {
        let (frames, d) = (self.frames.len(), self.dim);
        let n = self
            .frames
            .iter()
            .map(|f| f.positions.len() / d)
            .max()
            .unwrap_or(0);
        let mut positions = vec![f32::NAN; frames * n * d];
        let mut velocities = vec![f32::NAN; frames * n * d];
        let mut affine = self
            .frames
            .iter()
            .any(|f| f.affine.is_some())
            .then(|| vec![f32::NAN; frames * n * d * d]);
        let mut particle_count = Vec::with_capacity(frames);
        for (t, frame) in self.frames.iter().enumerate() {
            let (p, v) = (&frame.positions, &frame.velocities);
            positions[t * n * d..t * n * d + p.len()].copy_from_slice(p);
            velocities[t * n * d..t * n * d + v.len()].copy_from_slice(v);
            if let (Some(all), Some(c)) = (affine.as_mut(), &frame.affine) {
                let start = t * n * d * d;
                all[start..start + c.len()].copy_from_slice(c);
            }
            particle_count.push(p.len() / d);
        }
        TrajectoryArrays {
            frames,
            particles: n,
            dim: d,
            positions,
            velocities,
            affine,
            particle_count,
            time: (0..frames).map(|t| t as f32 * self.dt).collect(),
        }
    }
}

/// A scene's simulation stepped on demand: the state after [`steps_done`](Self::steps_done)
/// steps, advanced one step at a time by [`step`](Self::step). [`run_scene`] is this run
/// stepped `steps` times, so the states are the same bit for bit.
///
/// ```
/// use phi_core::backend::ndarray::NdArray;
/// use phi_core::Backend;
/// use phi_flip::{Scene, SceneRun, run_scene};
///
/// let scene = Scene::from_toml(
///     r#"
///     [domain]
///     resolution = [8, 8]
///     [simulation]
///     dt = 0.05
///     steps = 3
///     [[liquid]]
///     geometry = { type = "box", lower = [1, 1], upper = [4, 4] }
///     "#,
///     "<string>",
/// )?;
/// let device = NdArray::default_device();
/// let mut run = SceneRun::<NdArray>::new(&scene, "<string>", &device)?;
/// run.step()?;
/// run.step()?;
/// assert_eq!(run.steps_done(), 2);
/// assert_eq!(run.time(), 2.0 * 0.05);
/// let recording = run_scene::<NdArray>(&scene, "<string>", Some(2), &device)?;
/// assert_eq!(run.frame(), recording.frames()[2]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct SceneRun<B: Backend> {
    simulation: FlipSimulation<B>,
    particles: Particles<B>,
    steps_done: usize,
    scene_steps: usize,
    apic: bool,
}

impl<B: LatticeKernels> SceneRun<B> {
    /// Builds `scene` on `device` at step 0 (its initial state). `origin` names the scene in
    /// errors.
    ///
    /// # Errors
    /// [`crate::FlipError::Scene`] for a scene that cannot be built.
    pub fn new(scene: &Scene, origin: &str, device: &B::Device) -> Result<Self> {
        let setup = scene.build::<B>(origin, device)?;
        Ok(SceneRun {
            simulation: setup.simulation,
            particles: setup.particles,
            steps_done: 0,
            scene_steps: scene.simulation.steps,
            apic: scene.simulation.scheme == Scheme::Apic,
        })
    }

    /// Advances the state one step. On an error the state stays at the last completed step.
    ///
    /// # Errors
    /// The step's errors: an unstable or non-finite state, a failed pressure solve.
    pub fn step(&mut self) -> Result<StepStats> {
        let (particles, stats) = self.simulation.step(&self.particles, self.steps_done)?;
        self.particles = particles;
        self.steps_done += 1;
        Ok(stats)
    }

    /// The current state.
    pub fn particles(&self) -> &Particles<B> {
        &self.particles
    }

    /// The current state on the host, as a [`Recording`] keeps it.
    pub fn frame(&self) -> RecordedFrame {
        RecordedFrame::of(&self.particles, self.apic)
    }

    /// The simulation the run steps.
    pub fn simulation(&self) -> &FlipSimulation<B> {
        &self.simulation
    }

    /// The steps done so far.
    pub fn steps_done(&self) -> usize {
        self.steps_done
    }

    /// The scene's `simulation.steps`.
    pub(crate) fn scene_steps(&self) -> usize {
        self.scene_steps
    }

    /// The simulated time of the current state, `steps_done · dt` seconds (as a [`Recording`]
    /// writes it).
    pub fn time(&self) -> f32 {
        self.steps_done as f32 * self.simulation.params().dt
    }

    /// Whether the scene uses APIC (its states carry affine matrices).
    pub fn apic(&self) -> bool {
        self.apic
    }

    /// An empty [`Recording`] for this run's states.
    pub fn recording(&self) -> Recording {
        Recording::new(
            self.simulation.domain().dim(),
            self.simulation.params().dt,
            self.apic,
        )
    }
}

/// Runs `scene` for `steps` steps (`None`: the scene's `simulation.steps`) on `device` and
/// returns every state, frame 0 first: the simulation `phi simulate` runs, without its files.
/// `origin` names the scene in errors. A [`SceneRun`] stepped `steps` times.
///
/// # Errors
/// [`crate::FlipError::Scene`] for a scene that cannot be built; the step's errors (an
/// unstable or non-finite state, a failed pressure solve).
pub fn run_scene<B: LatticeKernels>(
    scene: &Scene,
    origin: &str,
    steps: Option<usize>,
    device: &B::Device,
) -> Result<Recording> {
    run_scene_checked::<B, crate::FlipError>(scene, origin, steps, device, |_| Ok(()))
}

/// [`run_scene`], calling `check(step)` after each step (counted from 1): an error from it
/// stops the run and is returned (a front end's check for Ctrl-C). The states are those of
/// [`run_scene`], bit for bit.
///
/// # Errors
/// As [`run_scene`], and `check`'s.
pub fn run_scene_checked<B: LatticeKernels, E: From<crate::FlipError>>(
    scene: &Scene,
    origin: &str,
    steps: Option<usize>,
    device: &B::Device,
    mut check: impl FnMut(usize) -> std::result::Result<(), E>,
) -> std::result::Result<Recording, E> {
    let mut run = SceneRun::<B>::new(scene, origin, device)?;
    let steps = steps.unwrap_or(run.scene_steps());
    let mut recording = run.recording();
    recording.reserve(steps.saturating_add(1));
    recording.push(run.particles());
    for step in 1..=steps {
        run.step()?;
        recording.push(run.particles());
        check(step)?;
    }
    Ok(recording)
}
