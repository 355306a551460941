//! The configuration of a GNS and the dataset facts it was built for: the content of
//! `model.json`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::ModelError;
use crate::data::{Metadata, OBSTACLE, Variant};

/// The value of [`ModelSpec::format`].
pub(crate) const MODEL_FORMAT: &str = "phi-gns-model";
/// The value of [`ModelSpec::format_version`] this code reads and writes.
pub(crate) const MODEL_FORMAT_VERSION: u32 = 1;

/// The sizes and options of a GNS (Sanchez-Gonzalez et al. 2020; thesis section 5.1). Every key
/// but `walls` and `obstacles` is required in `model.json`; unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnsConfig {
    /// Spatial dimensions of the positions (2 or 3).
    pub dim: usize,
    /// `C`, the number of past velocities in a node's features (5); the model reads the last
    /// `C + 1` positions.
    pub input_velocities: usize,
    /// `R`, the connectivity radius of the radius graph, in stored position units (0.03).
    pub connectivity_radius: f64,
    /// Width of the node and edge latents (128).
    pub latent_size: usize,
    /// Width of the hidden layers of every MLP (128).
    pub hidden_size: usize,
    /// Hidden layers per MLP (2): an MLP has `hidden_layers + 1` dense layers.
    pub hidden_layers: usize,
    /// `M`, the number of unshared interaction-network steps of the processor (10).
    pub message_passing_steps: usize,
    /// Rows of the particle-type embedding: the number of particle types (2: obstacle, liquid).
    pub particle_types: usize,
    /// Width of the particle-type embedding (16); used only when `particle_types > 1`.
    pub embedding_size: usize,
    /// Whether nodes carry their clipped distances to the domain bounds (off for the model that
    /// sees the walls as particles, `1snb`).
    pub boundary_features: bool,
    /// The distance, in multiples of `R`, at which a boundary feature saturates: a node's
    /// distance to a wall is divided by `boundary_horizon · R` and clipped to `[−1, 1]`
    /// (absent: 1, DeepMind's). A longer horizon lets a particle see a wall several frames
    /// before it reaches it.
    #[serde(default = "unit_horizon", skip_serializing_if = "is_unit_horizon")]
    pub boundary_horizon: f64,
    /// `σ`, the standard deviation of the training noise (0 without noise); it widens the
    /// normalisation of velocities and accelerations as in DeepMind's code.
    pub noise_std: f64,
    /// What a rollout does at the domain's walls (absent: [`Walls::Open`]).
    #[serde(default, skip_serializing_if = "Walls::is_open")]
    pub walls: Walls,
    /// What a rollout does with liquid predicted inside an obstacle (absent: [`Obstacles::Open`]).
    #[serde(default, skip_serializing_if = "Obstacles::is_open")]
    pub obstacles: Obstacles,
}

/// DeepMind's boundary horizon, the default: the distance to a wall is clipped at `R`.
pub(crate) const DEFAULT_BOUNDARY_HORIZON: f64 = 1.0;

fn unit_horizon() -> f64 {
    DEFAULT_BOUNDARY_HORIZON
}

/// Whether a horizon is the default one, left out of `model.json` so that the files of models
/// made before the key existed stay as they were.
#[allow(clippy::trivially_copy_pass_by_ref)] // serde's `skip_serializing_if` passes a reference
fn is_unit_horizon(horizon: &f64) -> bool {
    *horizon == DEFAULT_BOUNDARY_HORIZON
}

/// What a rollout does with a predicted position beyond the domain's walls (the model's
/// `bounds`).
///
/// The network itself never sees this: training and the one-step prediction are the same
/// either way. It is a property of the simulator the model is part of, as the FLIP solver that
/// made the data ends each of its steps by clamping every particle into the domain's closed box.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Walls {
    /// The predicted positions are taken as they are, wherever they lie (DeepMind's GNS).
    #[default]
    Open,
    /// Each predicted position is clamped into the closed box of the model's `bounds` before it
    /// joins the window, as FLIP clamps its particles: a particle that reaches a wall stops
    /// there, and its next velocity, read from the window, loses the part into the wall.
    Clamp,
}

impl Walls {
    /// Whether this is [`Walls::Open`] (the default, left out of `model.json`).
    pub fn is_open(&self) -> bool {
        *self == Walls::Open
    }
}

/// What a rollout does with a liquid particle predicted inside an obstacle.
///
/// As with [`Walls`], the network never sees this. A model knows a dataset's obstacles only as
/// kinematic particles, one at the centre of each grid cell whose centre lies inside an obstacle;
/// [`Obstacles::Push`] takes the cell around each of them as solid and moves a particle predicted
/// inside one to the nearest point outside, as the FLIP solver that made the data ends each of
/// its steps by pushing its particles out of the obstacles. In `model.json`:
/// `"obstacles": {"kind": "push", "cell_size": 0.03125}`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind", deny_unknown_fields)]
pub enum Obstacles {
    /// The predicted positions are taken as they are (DeepMind's GNS).
    #[default]
    Open,
    /// A predicted position inside the cell of a kinematic particle (the square or cube of side
    /// `cell_size` centred on it, moving with it) is moved out of the union of those cells along
    /// the axis that moves it least, and no gradient flows through it; the next velocity, read
    /// from the window, loses the part into the obstacle.
    Push {
        /// The side of a grid cell in stored units: the dataset's `position_scale`, the spacing
        /// of its obstacle particles.
        cell_size: f64,
    },
}

impl Obstacles {
    /// Whether this is [`Obstacles::Open`] (the default, left out of `model.json`).
    pub fn is_open(&self) -> bool {
        *self == Obstacles::Open
    }
}

/// The sizes and options of [`GnsConfig::for_dataset`] that a caller chooses; `None` keeps the
/// default. Validation happens on the [`ModelSpec`] made from the result
/// ([`ModelSpec::validate`]), which names the `model.json` key of a bad value.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConfigOverrides {
    /// `latent_size`.
    pub latent_size: Option<usize>,
    /// `hidden_size`.
    pub hidden_size: Option<usize>,
    /// `hidden_layers`.
    pub hidden_layers: Option<usize>,
    /// `message_passing_steps`.
    pub message_passing_steps: Option<usize>,
    /// `input_velocities` (`C`).
    pub input_velocities: Option<usize>,
    /// `embedding_size`.
    pub embedding_size: Option<usize>,
    /// `connectivity_radius`, stored units.
    pub connectivity_radius: Option<f64>,
    /// `boundary_features`.
    pub boundary_features: Option<bool>,
    /// `boundary_horizon`, multiples of `R`.
    pub boundary_horizon: Option<f64>,
    /// `noise_std` (σ).
    pub noise_std: Option<f64>,
}

impl GnsConfig {
    /// The sizes of the thesis and of DeepMind's model for a `dim`-dimensional dataset with two
    /// particle types: `C = 5`, `R = 0.03`, latent and hidden width 128, 2 hidden layers, 10
    /// message-passing steps, an embedding of 16, boundary features, no noise.
    pub fn thesis(dim: usize) -> Self {
        GnsConfig {
            dim,
            input_velocities: 5,
            connectivity_radius: 0.03,
            latent_size: 128,
            hidden_size: 128,
            hidden_layers: 2,
            message_passing_steps: 10,
            particle_types: 2,
            embedding_size: 16,
            boundary_features: true,
            boundary_horizon: DEFAULT_BOUNDARY_HORIZON,
            noise_std: 0.0,
            walls: Walls::Open,
            obstacles: Obstacles::Open,
        }
    }

    /// The configuration `phi model init` (and `phi_rs.Model.init`) makes for a dataset: the
    /// thesis's sizes ([`GnsConfig::thesis`]), the dataset's `default_connectivity_radius`,
    /// boundary features unless its walls are particles; then each size or option `overrides`
    /// sets.
    ///
    /// ```
    /// # use phi_gns::model::{ConfigOverrides, GnsConfig};
    /// # fn demo(metadata: &phi_gns::data::Metadata) {
    /// let small = ConfigOverrides { latent_size: Some(64), message_passing_steps: Some(5),
    ///                               ..Default::default() };
    /// let config = GnsConfig::for_dataset(metadata, &small);
    /// assert_eq!((config.latent_size, config.hidden_size), (64, 128));
    /// # }
    /// ```
    pub fn for_dataset(metadata: &Metadata, overrides: &ConfigOverrides) -> Self {
        let mut config = GnsConfig::thesis(metadata.dim);
        config.connectivity_radius = metadata.default_connectivity_radius;
        config.boundary_features = metadata.variant != Variant::WallsAsParticles;
        let o = overrides;
        for (size, value) in [
            (&mut config.latent_size, o.latent_size),
            (&mut config.hidden_size, o.hidden_size),
            (&mut config.hidden_layers, o.hidden_layers),
            (&mut config.message_passing_steps, o.message_passing_steps),
            (&mut config.input_velocities, o.input_velocities),
            (&mut config.embedding_size, o.embedding_size),
        ] {
            if let Some(v) = value {
                *size = v;
            }
        }
        config.connectivity_radius = o.connectivity_radius.unwrap_or(config.connectivity_radius);
        config.boundary_features = o.boundary_features.unwrap_or(config.boundary_features);
        config.boundary_horizon = o.boundary_horizon.unwrap_or(config.boundary_horizon);
        config.noise_std = o.noise_std.unwrap_or(config.noise_std);
        config
    }

    /// Whether nodes carry a particle-type embedding (more than one type).
    pub fn uses_embedding(&self) -> bool {
        self.particle_types > 1 && self.embedding_size > 0
    }

    /// Width of the node features: `C · dim` velocities, `2 · dim` boundary distances when
    /// enabled, and the embedding when used (30 in 2D with the defaults).
    pub fn node_features(&self) -> usize {
        let boundary = if self.boundary_features {
            2 * self.dim
        } else {
            0
        };
        let embedding = if self.uses_embedding() {
            self.embedding_size
        } else {
            0
        };
        self.input_velocities * self.dim + boundary + embedding
    }

    /// Width of the edge features: the displacement over `R` per axis and its norm.
    pub fn edge_features(&self) -> usize {
        self.dim + 1
    }

    /// Checks that every size is usable; `path` names the file in the error.
    ///
    /// # Errors
    /// [`ModelError::Config`] naming the key and the value.
    pub fn validate(&self, path: &Path) -> Result<(), ModelError> {
        let fail = |key: &str, reason: String| {
            Err(ModelError::Config {
                path: path.to_path_buf(),
                key: format!("config.{key}"),
                reason,
            })
        };
        if self.dim != 2 && self.dim != 3 {
            return fail("dim", format!("{} is not 2 or 3", self.dim));
        }
        if self.input_velocities == 0 {
            return fail("input_velocities", "0 must be at least 1".into());
        }
        if !(self.connectivity_radius.is_finite() && self.connectivity_radius > 0.0) {
            return fail(
                "connectivity_radius",
                format!("{} is not a positive number", self.connectivity_radius),
            );
        }
        for (key, value) in [
            ("latent_size", self.latent_size),
            ("hidden_size", self.hidden_size),
            ("particle_types", self.particle_types),
        ] {
            if value == 0 {
                return fail(key, format!("{value} must be at least 1"));
            }
        }
        // A generous ceiling that still keeps a mistyped size from allocating terabytes.
        for (key, value) in [
            ("latent_size", self.latent_size),
            ("hidden_size", self.hidden_size),
            ("hidden_layers", self.hidden_layers),
            ("message_passing_steps", self.message_passing_steps),
            ("embedding_size", self.embedding_size),
            ("input_velocities", self.input_velocities),
            ("particle_types", self.particle_types),
        ] {
            if value > 4096 {
                return fail(key, format!("{value} is larger than 4096"));
            }
        }
        if !(self.boundary_horizon.is_finite() && self.boundary_horizon > 0.0) {
            return fail(
                "boundary_horizon",
                format!(
                    "{} is not a positive number (multiples of the connectivity radius)",
                    self.boundary_horizon
                ),
            );
        }
        if !(self.noise_std.is_finite() && self.noise_std >= 0.0) {
            return fail(
                "noise_std",
                format!("{} is not a number ≥ 0", self.noise_std),
            );
        }
        if let Obstacles::Push { cell_size } = self.obstacles
            && !(cell_size.is_finite() && cell_size > 0.0)
        {
            return fail(
                "obstacles.cell_size",
                format!("{cell_size} is not a positive number"),
            );
        }
        Ok(())
    }
}

/// The statistics that normalise velocities and accelerations (in stored units per frame),
/// copied from the training split's `metadata.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Normalisation {
    /// Mean velocity per component.
    pub vel_mean: Vec<f64>,
    /// Standard deviation of the velocity per component.
    pub vel_std: Vec<f64>,
    /// Mean acceleration per component.
    pub acc_mean: Vec<f64>,
    /// Standard deviation of the acceleration per component.
    pub acc_std: Vec<f64>,
}

impl Normalisation {
    /// The statistics of a dataset's metadata.
    pub fn of(metadata: &Metadata) -> Self {
        Normalisation {
            vel_mean: metadata.vel_mean.clone(),
            vel_std: metadata.vel_std.clone(),
            acc_mean: metadata.acc_mean.clone(),
            acc_std: metadata.acc_std.clone(),
        }
    }

    /// `sqrt(std² + σ²)` per component: DeepMind's widened scale.
    pub fn scale(std: &[f64], noise_std: f64) -> Vec<f64> {
        std.iter()
            .map(|s| (s * s + noise_std * noise_std).sqrt())
            .collect()
    }
}

/// `model.json`: the configuration, the normalisation and the dataset facts a model depends on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// Always `MODEL_FORMAT`.
    pub format: String,
    /// Always `MODEL_FORMAT_VERSION`.
    pub format_version: u32,
    /// Sizes and options.
    pub config: GnsConfig,
    /// Velocity and acceleration statistics of the training data.
    pub normalisation: Normalisation,
    /// The domain bounds the boundary features measure from, `[min, max]` per axis.
    pub bounds: Vec<[f64; 2]>,
    /// The legend of particle types, as in the dataset's metadata.
    pub particle_types: BTreeMap<String, String>,
    /// The particle types whose positions come from the ground truth (obstacles, walls).
    pub kinematic_types: Vec<i64>,
    /// The seed of the initial weights.
    pub seed: u64,
    /// What made the weights (free-form: the training command fills it).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

impl ModelSpec {
    /// Which of the particles of types `types` are kinematic (their positions come from the
    /// ground truth, and no loss or metric counts them).
    pub fn kinematic(&self, types: &[i64]) -> Vec<bool> {
        types
            .iter()
            .map(|t| self.kinematic_types.contains(t))
            .collect()
    }

    /// A model for a dataset: its dimension, bounds, statistics and particle types, with the
    /// sizes of `config` (whose `dim` and `particle_types` are taken from the dataset).
    pub fn for_dataset(metadata: &Metadata, mut config: GnsConfig, seed: u64) -> Self {
        config.dim = metadata.dim;
        config.particle_types = metadata.particle_types.len().max(1);
        ModelSpec {
            format: MODEL_FORMAT.to_string(),
            format_version: MODEL_FORMAT_VERSION,
            config,
            normalisation: Normalisation::of(metadata),
            bounds: metadata.bounds.clone(),
            particle_types: metadata.particle_types.clone(),
            kinematic_types: vec![OBSTACLE],
            seed,
            provenance: serde_json::Value::Null,
        }
    }

    /// Checks the spec on its own: format, sizes, and that every per-component list has `dim`
    /// finite entries; `path` names the file in the error.
    ///
    /// # Errors
    /// [`ModelError::Config`] naming the key.
    pub fn validate(&self, path: &Path) -> Result<(), ModelError> {
        let fail = |key: &str, reason: String| {
            Err(ModelError::Config {
                path: path.to_path_buf(),
                key: key.to_string(),
                reason,
            })
        };
        if self.format != MODEL_FORMAT {
            return fail(
                "format",
                format!("'{}' is not '{MODEL_FORMAT}'", self.format),
            );
        }
        if self.format_version != MODEL_FORMAT_VERSION {
            return fail(
                "format_version",
                format!(
                    "version {} is not the supported {MODEL_FORMAT_VERSION}",
                    self.format_version
                ),
            );
        }
        self.config.validate(path)?;
        let dim = self.config.dim;
        let n = &self.normalisation;
        for (key, values, positive) in [
            ("normalisation.vel_mean", &n.vel_mean, false),
            ("normalisation.vel_std", &n.vel_std, true),
            ("normalisation.acc_mean", &n.acc_mean, false),
            ("normalisation.acc_std", &n.acc_std, true),
        ] {
            if values.len() != dim {
                return fail(key, format!("{} entries for a {dim}D model", values.len()));
            }
            if let Some(v) = values
                .iter()
                .find(|v| !v.is_finite() || (positive && **v < 0.0))
            {
                return fail(
                    key,
                    format!(
                        "{v} is not a finite number{}",
                        if positive { " ≥ 0" } else { "" }
                    ),
                );
            }
        }
        // A zero scale would divide by zero in the features.
        for (key, std) in [
            ("normalisation.vel_std", &n.vel_std),
            ("normalisation.acc_std", &n.acc_std),
        ] {
            if Normalisation::scale(std, self.config.noise_std)
                .iter()
                .any(|s| *s <= 0.0)
            {
                return fail(
                    key,
                    "a zero standard deviation (with zero noise) cannot normalise".into(),
                );
            }
        }
        if self.bounds.len() != dim {
            return fail(
                "bounds",
                format!("{} axes for a {dim}D model", self.bounds.len()),
            );
        }
        if let Some([lo, hi]) = self
            .bounds
            .iter()
            .find(|[lo, hi]| !(lo.is_finite() && hi.is_finite() && lo < hi))
        {
            return fail(
                "bounds",
                format!("[{lo}, {hi}] is not a finite interval with min < max"),
            );
        }
        if self.particle_types.len() != self.config.particle_types {
            return fail(
                "particle_types",
                format!(
                    "{} types named but config.particle_types is {}",
                    self.particle_types.len(),
                    self.config.particle_types
                ),
            );
        }
        for key in self.particle_types.keys() {
            match key.parse::<usize>() {
                Ok(t) if t < self.config.particle_types => {}
                _ => {
                    return fail(
                        "particle_types",
                        format!(
                            "type '{key}' is not one of 0..{}",
                            self.config.particle_types
                        ),
                    );
                }
            }
        }
        Ok(())
    }

    /// Checks that a dataset fits the model: the same dimension, bounds and particle types
    /// (the statistics may differ: a model is applied to test data with its training
    /// statistics). `path` names the dataset's metadata in the error.
    ///
    /// # Errors
    /// [`ModelError::DatasetMismatch`] naming the key and both values.
    pub fn check_dataset(&self, metadata: &Metadata, path: &Path) -> Result<(), ModelError> {
        let mismatch = |key: &str, model: String, dataset: String| {
            Err(ModelError::DatasetMismatch {
                path: path.to_path_buf(),
                key: key.to_string(),
                model,
                dataset,
            })
        };
        if metadata.dim != self.config.dim {
            return mismatch("dim", self.config.dim.to_string(), metadata.dim.to_string());
        }
        if self.config.boundary_features && metadata.bounds != self.bounds {
            return mismatch(
                "bounds",
                format!("{:?}", self.bounds),
                format!("{:?}", metadata.bounds),
            );
        }
        if metadata.particle_types != self.particle_types {
            return mismatch(
                "particle_types",
                format!("{:?}", self.particle_types),
                format!("{:?}", metadata.particle_types),
            );
        }
        Ok(())
    }
}
