//! A training run's configuration: the TOML presets of `configs/gns/` (thesis section 5.3).
//!
//! Every hyperparameter is a key and every key is required, so that a preset states the whole
//! run; unknown keys are errors naming the key. Sections:
//!
//! - `[model]`: the sizes of the GNS ([`GnsConfig`]; the dimension and the particle types come
//!   from the dataset), the training noise σ and the seed of the initial weights;
//! - `[training]`: total steps, batch size, the seed of the data and noise draws, the extra
//!   steps `n` of the multi-step loss (eq. 5.2; 0 is the one-step loss of eq. 5.1), the
//!   pushforward schedule (optional) and how often the loss is logged;
//! - `[optimizer]`: Adam's constants and the learning-rate schedule ([`AdamConfig`]);
//! - `[checkpoints]`: how often, and how many to keep;
//! - `[screening]`: how often the validation split is screened, on how many trajectories, with
//!   rollouts of how many steps, and which metric picks the best checkpoint;
//! - `[data]`: the training split, the cache bound and the read-ahead depth.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{
    AdamConfig, BatchConfig, ErrorNorm, ImpactSampling, Pushforward, TrainError, WindowSpec,
};
use crate::data::{Metadata, Variant};
use crate::model::{GnsConfig, ModelSpec, Walls};

/// The content of a training preset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// One line on what the preset trains.
    #[serde(default)]
    pub description: String,
    /// The network and its initial weights.
    pub model: ModelSection,
    /// The optimisation loop.
    pub training: TrainingSection,
    /// Adam and its learning-rate schedule.
    pub optimizer: AdamConfig,
    /// Checkpoints.
    pub checkpoints: CheckpointSection,
    /// Screening on the validation split.
    pub screening: ScreeningSection,
    /// Reading the training split.
    pub data: DataSection,
}

/// `[model]`: the sizes of [`GnsConfig`] that a preset chooses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    /// `C`, past velocities in the node features (5).
    pub input_velocities: usize,
    /// `R` in stored units; absent: the dataset's `default_connectivity_radius`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connectivity_radius: Option<f64>,
    /// Width of the node and edge latents (128).
    pub latent_size: usize,
    /// Width of the hidden layers (128).
    pub hidden_size: usize,
    /// Hidden layers per MLP (2).
    pub hidden_layers: usize,
    /// `M`, interaction-network steps (10).
    pub message_passing_steps: usize,
    /// Width of the particle-type embedding (16).
    pub embedding_size: usize,
    /// Distances to the domain bounds in the node features. They must agree with the dataset:
    /// on for obstacles-only datasets, off for datasets whose walls are particles (`1snb`).
    pub boundary_features: bool,
    /// Where the boundary features saturate, in multiples of `R` (absent: 1, DeepMind's; see
    /// [`GnsConfig::boundary_horizon`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary_horizon: Option<f64>,
    /// `σ` of the random-walk input noise (6.7e-4 for `1sn`, 0 for none).
    pub noise_std: f64,
    /// What the model's rollouts (screening among them) do at the domain's walls: `"open"`
    /// (the default) or `"clamp"` ([`Walls`]).
    #[serde(default, skip_serializing_if = "Walls::is_open")]
    pub walls: Walls,
    /// The seed of the initial weights.
    pub seed: u64,
}

/// `[training]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingSection {
    /// The total number of optimisation steps (a resumed run ends at the same step).
    pub steps: u64,
    /// Graphs per batch (2).
    pub batch_size: usize,
    /// The seed of the window draws, the noise and the pushforward unrolls.
    pub seed: u64,
    /// `n` of equation 5.2: steps on the model's own predictions after the first (0: the
    /// one-step loss; the thesis's 2ss and 2si use 1).
    pub extra_steps: usize,
    /// LagrangeBench's pushforward: unrolls without gradient before the loss (absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pushforward: Option<Pushforward>,
    /// A row of `train.csv` (the mean loss since the last row) every this many steps.
    pub log_every: u64,
    /// How a particle's error in normalised acceleration is scored: `"mse"` (the thesis's
    /// squared error, the default), `"huber"` (squared within `huber_delta`, linear beyond) or
    /// `"relative"` (squared, over the size of the particle's target acceleration floored at
    /// `relative_scale`: [`ErrorNorm::Relative`]).
    #[serde(default, skip_serializing_if = "LossKind::is_mse")]
    pub loss: LossKind,
    /// `δ` of the Huber loss in normalised units (only with `loss = "huber"`; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub huber_delta: Option<f64>,
    /// `s` of the relative loss in normalised units (only with `loss = "relative"`; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_scale: Option<f64>,
    /// The weight in the loss of a counted particle that has a kinematic particle (an obstacle)
    /// within the connectivity radius in the latest input frame, against 1 for the others; the
    /// loss is then the weighted mean ([`obstacle_weights`](super::obstacle_weights)). Obstacle
    /// contacts are ~3 % of the training data's liquid particle-frames (absent: 1, no weighting).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacle_weight: Option<f64>,
    /// Draws the fraction `share` of the windows in proportion to their obstacle impacts, the
    /// rest uniformly (`[training.impact_sampling]`; absent: every draw uniform). See
    /// `train::impacts`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impact_sampling: Option<ImpactSampling>,
    /// Mirror augmentation: each example of a batch is reflected across the vertical mid-plane
    /// of the model's bounds (`x ↦ lower + upper − x` on the first axis; gravity is along
    /// the last) with probability ½, which maps a scene to a scene (default off).
    #[serde(default, skip_serializing_if = "is_false")]
    pub mirror: bool,
    /// `d` of a moving average of the weights (`WeightAverage`, e.g. 0.999): when
    /// set, screening, `best/` and each checkpoint's `average/` hold the averaged weights,
    /// while training goes on from the weights of the last step (absent: no average). The
    /// one key besides `steps` that `--resume` lets change: an average switched on then
    /// starts from the checkpoint's weights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ema_decay: Option<f64>,
    /// Each graph of a batch differentiated on its own, the graphs in parallel when the run
    /// has threads for them, their gradients summed in batch order (default off: one graph of
    /// the whole batch). The loss and its gradients are the same sums in another order, so
    /// the bits differ from a run without it, but not between thread counts.
    #[serde(default, skip_serializing_if = "is_false")]
    pub parallel_graphs: bool,
}

fn is_false(value: &bool) -> bool {
    !*value
}

/// `training.loss`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LossKind {
    /// The squared error (thesis equation 5.1).
    #[default]
    Mse,
    /// Huber's loss (times two), quadratic within `huber_delta`.
    Huber,
    /// The squared error relative to the target's size, floored at `relative_scale`.
    Relative,
}

impl LossKind {
    fn is_mse(&self) -> bool {
        *self == LossKind::Mse
    }
}

impl TrainingSection {
    /// The error norm of the loss this section chooses.
    pub(crate) fn error_norm(&self) -> ErrorNorm {
        match self.loss {
            LossKind::Mse => ErrorNorm::Squared,
            LossKind::Huber => ErrorNorm::Huber {
                delta: self.huber_delta.unwrap_or(1.0) as f32,
            },
            LossKind::Relative => ErrorNorm::Relative {
                scale: self.relative_scale.unwrap_or(1.0) as f32,
            },
        }
    }
}

/// `[checkpoints]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointSection {
    /// A checkpoint every this many steps (and at the end, and on SIGINT / SIGTERM).
    pub every: u64,
    /// The newest checkpoints kept (the best one is kept apart, in `best/`).
    pub keep: usize,
}

/// The screening metric that picks the best checkpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SelectBy {
    /// The one-step acceleration error (MSE-acc 1).
    MseAcc1,
    /// The position error of the screening rollouts (the thesis picks by MSE 400: set
    /// `rollout_steps` to the trajectory length for that).
    RolloutMse,
    /// The EMD of the screening rollouts' liquid (needs `emd_every ≥ 1`): where the liquid is,
    /// the thesis's other headline metric.
    Emd,
}

impl SelectBy {
    /// Every metric.
    pub const ALL: [SelectBy; 3] = [SelectBy::MseAcc1, SelectBy::RolloutMse, SelectBy::Emd];

    /// Its name in a preset (`select_by = "…"`).
    pub fn name(self) -> &'static str {
        match self {
            SelectBy::MseAcc1 => "mse_acc1",
            SelectBy::RolloutMse => "rollout_mse",
            SelectBy::Emd => "emd",
        }
    }

    /// The metric's name in `train.csv` and `best/best.json`.
    pub fn column(self) -> &'static str {
        match self {
            SelectBy::MseAcc1 => "valid_mse_acc1",
            SelectBy::RolloutMse => "valid_rollout_mse",
            SelectBy::Emd => "valid_emd",
        }
    }
}

impl std::str::FromStr for SelectBy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SelectBy::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = SelectBy::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "'{s}' is not a screening metric (one of {})",
                    names.join(", ")
                )
            })
    }
}

/// `[screening]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreeningSection {
    /// Screen every this many steps (a multiple of `training.log_every`; 0: never).
    pub every: u64,
    /// The split screened ("valid").
    pub split: String,
    /// Its first this many trajectories (0: all).
    pub trajectories: usize,
    /// One-step windows every this many frames of each trajectory for MSE-acc 1.
    pub window_stride: usize,
    /// Steps of the rollout from the first full input window of each trajectory (at most
    /// the trajectory's length minus `C`).
    pub rollout_steps: usize,
    /// The EMD of every this many predicted frames of the screening rollouts (and of the
    /// last); 0, the default: no EMD.
    #[serde(default)]
    pub emd_every: usize,
    /// The metric that picks the best checkpoint.
    pub select_by: SelectBy,
}

/// `[data]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataSection {
    /// The split trained on ("train").
    pub split: String,
    /// Decoded trajectories kept in memory, in MiB (peak memory does not grow with the split).
    pub cache_mib: usize,
    /// Batches prepared ahead on another thread.
    pub read_ahead: usize,
    /// Trains on the split's first `trajectories` trajectories only (all when absent): the
    /// lever of how much data a run sees. The normalisation statistics stay the dataset's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectories: Option<usize>,
}

impl TrainConfig {
    /// Reads and validates a preset; errors name the file and the key.
    ///
    /// # Errors
    /// [`TrainError::Config`] for an unreadable file, a syntax error, an unknown key, a value
    /// of the wrong type or out of range.
    pub fn from_file(path: &Path) -> Result<Self, TrainError> {
        let (text, name) = phi_io::read_toml_text(path)?;
        Self::from_toml(&text, &name)
    }

    /// Parses and validates a preset from TOML text; `origin` names it in errors.
    ///
    /// # Errors
    /// As [`TrainConfig::from_file`].
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, TrainError> {
        let config: TrainConfig = phi_io::parse_toml(text, origin)?;
        config.validate(origin)?;
        Ok(config)
    }

    /// The preset as TOML text (what `phi train` stores beside its outputs).
    ///
    /// # Panics
    /// Never: every value is representable in TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a training config is plain data")
    }

    /// Checks every value; `origin` names the file in errors.
    ///
    /// # Errors
    /// [`TrainError::Config`] naming the key and the value.
    pub fn validate(&self, origin: &str) -> Result<(), TrainError> {
        let fail = |key: &str, reason: String| {
            Err(TrainError::Config {
                path: origin.to_string(),
                key: key.to_string(),
                reason,
            })
        };
        let m = &self.model;
        if !(m.noise_std.is_finite() && m.noise_std >= 0.0) {
            return fail("model.noise_std", format!("{} is not ≥ 0", m.noise_std));
        }
        if let Some(r) = m.connectivity_radius
            && !(r.is_finite() && r > 0.0)
        {
            return fail("model.connectivity_radius", format!("{r} is not > 0"));
        }
        let t = &self.training;
        if t.steps == 0 {
            return fail("training.steps", "0 steps train nothing".into());
        }
        if t.batch_size == 0 {
            return fail(
                "training.batch_size",
                "a batch needs at least one graph".into(),
            );
        }
        if t.log_every == 0 {
            return fail("training.log_every", "must be ≥ 1".into());
        }
        if let Some(delta) = t.huber_delta {
            if t.loss != LossKind::Huber {
                return fail(
                    "training.huber_delta",
                    "is only used with training.loss = \"huber\"".into(),
                );
            }
            if !(delta.is_finite() && delta > 0.0) {
                return fail("training.huber_delta", format!("{delta} is not > 0"));
            }
        }
        if let Some(scale) = t.relative_scale {
            if t.loss != LossKind::Relative {
                return fail(
                    "training.relative_scale",
                    "is only used with training.loss = \"relative\"".into(),
                );
            }
            if !(scale.is_finite() && scale > 0.0) {
                return fail("training.relative_scale", format!("{scale} is not > 0"));
            }
        }
        if let Some(w) = t.obstacle_weight
            && !(w.is_finite() && w > 0.0)
        {
            return fail("training.obstacle_weight", format!("{w} is not > 0"));
        }
        if let Some(Err((key, reason))) = t.impact_sampling.as_ref().map(ImpactSampling::check) {
            return fail(key, reason);
        }
        if let Some(d) = t.ema_decay
            && !(d > 0.0 && d < 1.0)
        {
            return fail("training.ema_decay", format!("{d} is not in (0, 1)"));
        }
        if let Some(p) = &t.pushforward {
            p.validate(Path::new(origin), "training.pushforward")
                .map_err(|e| match e {
                    crate::model::ModelError::Config { key, reason, .. } => TrainError::Config {
                        path: origin.to_string(),
                        key,
                        reason,
                    },
                    other => TrainError::Model(other),
                })?;
            if t.extra_steps > 0 {
                return fail(
                    "training.pushforward",
                    "pushforward and the multi-step loss (training.extra_steps > 0) do not \
                     combine: choose one"
                        .into(),
                );
            }
        }
        let o = &self.optimizer;
        for (key, beta) in [("optimizer.beta1", o.beta1), ("optimizer.beta2", o.beta2)] {
            if !(0.0..1.0).contains(&beta) {
                return fail(key, format!("{beta} is not in [0, 1)"));
            }
        }
        if !(o.eps.is_finite() && o.eps > 0.0) {
            return fail("optimizer.eps", format!("{} is not > 0", o.eps));
        }
        let lr = &o.learning_rate;
        for (key, value) in [
            ("optimizer.learning_rate.initial", lr.initial),
            ("optimizer.learning_rate.final_rate", lr.final_rate),
            ("optimizer.learning_rate.decay_steps", lr.decay_steps),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return fail(key, format!("{value} is not > 0"));
            }
        }
        if !(lr.warmup_steps.is_finite() && lr.warmup_steps >= 0.0) {
            return fail(
                "optimizer.learning_rate.warmup_steps",
                format!("{} is not ≥ 0", lr.warmup_steps),
            );
        }
        if let Some(clip) = o.clip_norm
            && !(clip.is_finite() && clip > 0.0)
        {
            return fail("optimizer.clip_norm", format!("{clip} is not > 0"));
        }
        if self.checkpoints.every == 0 {
            return fail("checkpoints.every", "must be ≥ 1".into());
        }
        if self.checkpoints.keep == 0 {
            return fail(
                "checkpoints.keep",
                "at least the newest checkpoint is kept (resume needs it)".into(),
            );
        }
        let s = &self.screening;
        if s.every > 0 && !s.every.is_multiple_of(t.log_every) {
            return fail(
                "screening.every",
                format!(
                    "{} is not a multiple of training.log_every = {}",
                    s.every, t.log_every
                ),
            );
        }
        if s.every > 0 && s.window_stride == 0 {
            return fail("screening.window_stride", "must be ≥ 1".into());
        }
        if s.every > 0 && s.rollout_steps == 0 {
            return fail("screening.rollout_steps", "must be ≥ 1".into());
        }
        if s.select_by == SelectBy::Emd && s.emd_every == 0 {
            return fail(
                "screening.emd_every",
                "select_by = \"emd\" needs the EMD: set emd_every ≥ 1".into(),
            );
        }
        if self.data.trajectories == Some(0) {
            return fail("data.trajectories", "must be ≥ 1 (or absent: all)".into());
        }
        if self.data.read_ahead == 0 {
            return fail("data.read_ahead", "must be ≥ 1".into());
        }
        Ok(())
    }

    /// The model this preset trains on a dataset: its sizes on top of the dataset's dimension,
    /// bounds, statistics and particle types.
    ///
    /// # Errors
    /// [`TrainError::Config`] when `model.boundary_features` does not fit the dataset's variant
    /// (`origin` names the preset), or the sizes make no valid model (naming the key).
    pub(crate) fn model_spec(
        &self,
        metadata: &Metadata,
        metadata_path: &Path,
        origin: &str,
    ) -> Result<ModelSpec, TrainError> {
        let m = &self.model;
        let walls = metadata.variant == Variant::WallsAsParticles;
        if m.boundary_features == walls {
            return Err(TrainError::Config {
                path: origin.to_string(),
                key: "model.boundary_features".into(),
                reason: format!(
                    "{} does not fit the dataset '{}', whose variant is '{}': {}",
                    m.boundary_features,
                    metadata_path.display(),
                    if walls { "walls" } else { "obstacles" },
                    if walls {
                        "its walls are particles, so the model needs no distances to them \
                         (false, model 1snb)"
                    } else {
                        "its walls are not particles, so the model must be given the \
                         distances to them (true)"
                    }
                ),
            });
        }
        let config = GnsConfig {
            dim: metadata.dim,
            input_velocities: m.input_velocities,
            connectivity_radius: m
                .connectivity_radius
                .unwrap_or(metadata.default_connectivity_radius),
            latent_size: m.latent_size,
            hidden_size: m.hidden_size,
            hidden_layers: m.hidden_layers,
            message_passing_steps: m.message_passing_steps,
            particle_types: metadata.particle_types.len().max(1),
            embedding_size: m.embedding_size,
            boundary_features: m.boundary_features,
            boundary_horizon: m
                .boundary_horizon
                .unwrap_or(crate::model::config::DEFAULT_BOUNDARY_HORIZON),
            noise_std: m.noise_std,
            walls: m.walls,
            obstacles: crate::model::Obstacles::Open,
        };
        let spec = ModelSpec::for_dataset(metadata, config, m.seed);
        spec.validate(metadata_path).map_err(|e| match e {
            crate::model::ModelError::Config { key, reason, .. } => {
                match key.strip_prefix("config.") {
                    Some(k) => TrainError::Config {
                        path: origin.to_string(),
                        key: format!("model.{k}"),
                        reason,
                    },
                    None => TrainError::Model(crate::model::ModelError::Config {
                        path: metadata_path.to_path_buf(),
                        key,
                        reason,
                    }),
                }
            }
            other => TrainError::Model(other),
        })?;
        Ok(spec)
    }

    /// Frames a training window needs after its latest input frame: the target of each of the
    /// `1 + n` loss steps.
    pub(crate) fn frames_after(&self) -> usize {
        1 + self.training.extra_steps
    }

    /// Frames a training window needs before its first input frame: the longest pushforward
    /// unroll.
    pub(crate) fn frames_before(&self) -> usize {
        self.training
            .pushforward
            .as_ref()
            .map_or(0, Pushforward::max_unroll)
    }

    /// How the run's batches are drawn: `[training]`'s seed and batch size, the windows its loss
    /// needs, and `[data]`'s cache and trajectories.
    pub(crate) fn batches(&self) -> BatchConfig {
        let window = WindowSpec {
            input_velocities: self.model.input_velocities,
            span_before: self.frames_before(),
            span_after: self.frames_after(),
        };
        BatchConfig {
            cache_bytes: self.data.cache_mib << 20,
            trajectories: self.data.trajectories,
            ..BatchConfig::new(self.training.seed, self.training.batch_size, window)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CPU 1s preset of the repository.
    fn preset() -> String {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/gns/cpu/1s.toml");
        std::fs::read_to_string(path).expect("the CPU 1s preset")
    }

    fn refusal(text: &str) -> String {
        TrainConfig::from_toml(text, "preset.toml")
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn the_loss_defaults_to_the_squared_error_and_huber_and_relative_take_a_size() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(plain.training.error_norm(), ErrorNorm::Squared);
        assert!(
            !plain.to_toml().contains("loss ="),
            "the default is left unsaid"
        );
        let huber = text.replace("log_every = 100", "log_every = 100\nloss = \"huber\"");
        let c = TrainConfig::from_toml(&huber, "preset.toml").unwrap();
        assert_eq!(c.training.error_norm(), ErrorNorm::Huber { delta: 1.0 });
        let delta = huber.replace("loss = \"huber\"", "loss = \"huber\"\nhuber_delta = 2.5");
        let c = TrainConfig::from_toml(&delta, "preset.toml").unwrap();
        assert_eq!(c.training.error_norm(), ErrorNorm::Huber { delta: 2.5 });
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&text.replace("log_every = 100", "log_every = 100\nhuber_delta = 2.0"));
        assert!(
            e.contains("training.huber_delta") && e.contains("huber"),
            "{e}"
        );
        let e = refusal(&delta.replace("huber_delta = 2.5", "huber_delta = -1.0"));
        assert!(
            e.contains("training.huber_delta") && e.contains("-1"),
            "{e}"
        );
        let e = refusal(&text.replace("log_every = 100", "log_every = 100\nloss = \"l1\""));
        assert!(e.contains("l1"), "{e}");
        let relative = text.replace("log_every = 100", "log_every = 100\nloss = \"relative\"");
        let c = TrainConfig::from_toml(&relative, "preset.toml").unwrap();
        assert_eq!(c.training.error_norm(), ErrorNorm::Relative { scale: 1.0 });
        let scale = relative.replace(
            "loss = \"relative\"",
            "loss = \"relative\"\nrelative_scale = 0.1",
        );
        let c = TrainConfig::from_toml(&scale, "preset.toml").unwrap();
        assert_eq!(c.training.error_norm(), ErrorNorm::Relative { scale: 0.1 });
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&delta.replace("huber_delta = 2.5", "relative_scale = 0.1"));
        assert!(
            e.contains("training.relative_scale") && e.contains("relative"),
            "{e}"
        );
        let e = refusal(&scale.replace("relative_scale = 0.1", "relative_scale = 0.0"));
        assert!(
            e.contains("training.relative_scale") && e.contains("is not > 0"),
            "{e}"
        );
    }

    #[test]
    fn impact_sampling_is_absent_unless_asked_and_checked() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(plain.training.impact_sampling, None);
        assert!(!plain.to_toml().contains("impact_sampling"));
        let asked = format!("{text}\n[training.impact_sampling]\nshare = 0.5\n");
        let c = TrainConfig::from_toml(&asked, "preset.toml").unwrap();
        assert_eq!(
            c.training.impact_sampling,
            Some(ImpactSampling {
                share: 0.5,
                threshold: 3.0
            })
        );
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&asked.replace("share = 0.5", "share = 1.5"));
        assert!(
            e.contains("training.impact_sampling.share") && e.contains("not in (0, 1]"),
            "{e}"
        );
        let e = refusal(&asked.replace("share = 0.5", "share = 0.5\nthreshold = -1.0"));
        assert!(e.contains("training.impact_sampling.threshold"), "{e}");
        assert!(
            TrainConfig::from_toml(&asked.replace("share = 0.5", "shares = 0.5"), "p").is_err()
        );
    }

    #[test]
    fn obstacle_weight_is_absent_unless_asked_and_positive() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(plain.training.obstacle_weight, None);
        assert!(!plain.to_toml().contains("obstacle_weight"));
        let asked = text.replace("log_every = 100", "log_every = 100\nobstacle_weight = 4.0");
        let c = TrainConfig::from_toml(&asked, "preset.toml").unwrap();
        assert_eq!(c.training.obstacle_weight, Some(4.0));
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        for bad in ["0.0", "-2.0", "nan"] {
            let e = refusal(
                &asked.replace("obstacle_weight = 4.0", &format!("obstacle_weight = {bad}")),
            );
            assert!(
                e.contains("training.obstacle_weight") && e.contains("is not > 0"),
                "{e}"
            );
        }
    }

    #[test]
    fn mirror_augmentation_is_off_unless_asked_and_stored() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert!(!plain.training.mirror);
        assert!(
            !plain.to_toml().contains("mirror"),
            "the default is left unsaid"
        );
        let on = text.replace("log_every = 100", "log_every = 100\nmirror = true");
        let c = TrainConfig::from_toml(&on, "preset.toml").unwrap();
        assert!(c.training.mirror);
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&text.replace("log_every = 100", "log_every = 100\nmirror = 1"));
        assert!(e.contains("mirror"), "{e}");
    }

    #[test]
    fn graphs_run_apart_when_a_preset_asks_and_stored_runs_without_the_key_stay_whole() {
        let text = preset();
        let on = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert!(on.training.parallel_graphs, "the CPU presets ask for it");
        assert_eq!(TrainConfig::from_toml(&on.to_toml(), "stored").unwrap(), on);
        let before = text.replace("parallel_graphs = true\n", "");
        let off = TrainConfig::from_toml(&before, "preset.toml").unwrap();
        assert!(!off.training.parallel_graphs);
        assert!(
            !off.to_toml().contains("parallel_graphs"),
            "the default is left unsaid, so stored runs read as they were written"
        );
        let e = refusal(&text.replace("parallel_graphs = true", "parallel_graphs = 2"));
        assert!(e.contains("parallel_graphs"), "{e}");
    }

    #[test]
    fn the_trajectories_trained_on_are_all_unless_limited_and_stored() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(plain.data.trajectories, None);
        let stored = plain.to_toml();
        let data = stored
            .split("[data]")
            .nth(1)
            .unwrap()
            .split("\n[")
            .next()
            .unwrap();
        assert!(
            !data.contains("trajectories"),
            "absent is left unsaid: {data}"
        );
        assert_eq!(plain.batches().trajectories, None);
        let limited = text.replace("read_ahead = ", "trajectories = 200\nread_ahead = ");
        let c = TrainConfig::from_toml(&limited, "preset.toml").unwrap();
        assert_eq!(c.data.trajectories, Some(200));
        // ... and the run's batches are drawn from them.
        let batches = c.batches();
        assert_eq!(batches.trajectories, Some(200));
        assert_eq!(batches.cache_bytes, c.data.cache_mib << 20);
        assert_eq!(
            (batches.seed, batches.batch_size),
            (c.training.seed, c.training.batch_size)
        );
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&text.replace("read_ahead = ", "trajectories = 0\nread_ahead = "));
        assert!(e.contains("data.trajectories") && e.contains("≥ 1"), "{e}");
    }

    #[test]
    fn the_weight_average_is_off_unless_asked_and_its_decay_is_checked() {
        let text = preset();
        let plain = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(plain.training.ema_decay, None);
        assert!(!plain.to_toml().contains("ema_decay"));
        let on = text.replace("log_every = 100", "log_every = 100\nema_decay = 0.999");
        let c = TrainConfig::from_toml(&on, "preset.toml").unwrap();
        assert_eq!(c.training.ema_decay, Some(0.999));
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        for bad in ["1.0", "0.0", "-0.5", "1.5"] {
            let e = refusal(&text.replace(
                "log_every = 100",
                &format!("log_every = 100\nema_decay = {bad}"),
            ));
            assert!(
                e.contains("training.ema_decay") && e.contains("(0, 1)"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn warm_up_and_clipping_are_checked_and_stored() {
        let text = preset()
            .replace("eps = 1e-8", "eps = 1e-8\nclip_norm = 0.5")
            .replace("decay_steps = 1e4", "decay_steps = 1e4\nwarmup_steps = 100");
        let c = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(c.optimizer.clip_norm, Some(0.5));
        assert_eq!(c.optimizer.learning_rate.warmup_steps, 100.0);
        assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        let e = refusal(&text.replace("clip_norm = 0.5", "clip_norm = 0.0"));
        assert!(e.contains("optimizer.clip_norm"), "{e}");
        let e = refusal(&text.replace("warmup_steps = 100", "warmup_steps = -3"));
        assert!(e.contains("optimizer.learning_rate.warmup_steps"), "{e}");
    }

    #[test]
    fn the_emd_metric_needs_the_emd_and_names_agree_with_the_preset_keys() {
        let text = preset();
        assert!(text.contains("select_by = \"rollout_mse\""));
        let e = refusal(&text.replace("\"rollout_mse\"", "\"emd\""));
        assert!(e.contains("screening.emd_every"), "{e}");
        for metric in SelectBy::ALL {
            let with = text.replace(
                "select_by = \"rollout_mse\"",
                &format!("emd_every = 5\nselect_by = \"{}\"", metric.name()),
            );
            let c = TrainConfig::from_toml(&with, "preset.toml").unwrap();
            assert_eq!(c.screening.select_by, metric);
            assert_eq!(c.screening.emd_every, 5);
            assert_eq!(metric.name().parse::<SelectBy>(), Ok(metric));
            assert_eq!(TrainConfig::from_toml(&c.to_toml(), "stored").unwrap(), c);
        }
        let e = "emd2".parse::<SelectBy>().unwrap_err();
        assert!(e.contains("mse_acc1, rollout_mse, emd"), "{e}");
        // A preset from before the key reads as "no EMD".
        let c = TrainConfig::from_toml(&text, "preset.toml").unwrap();
        assert_eq!(c.screening.emd_every, 0);
    }

    #[test]
    fn every_lever_preset_parses() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/gns/levers");
        let mut count = 0;
        for entry in std::fs::read_dir(dir).expect("configs/gns/levers") {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                TrainConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
                count += 1;
            }
        }
        assert!(count >= 2, "{count} presets");
    }
}
