//! The Graph Network-based Simulator (Sanchez-Gonzalez et al. 2020; thesis section 5.1),
//! written once against [`Backend`](phi_core::Backend) through [`GnsKernels`].
//!
//! - [`config`]: sizes and options ([`GnsConfig`]) and `model.json` ([`ModelSpec`]);
//! - [`params`]: the named parameters, their PyTorch-style layout and seeded initial values;
//! - `features`: node and edge features from a window of positions, and the integration of
//!   the predicted acceleration;
//! - `network`: encode-process-decode with unshared interaction networks;
//! - [`kernels`]: the fused kernels the network calls ([`GnsKernels`]);
//! - [`files`]: model directories (`model.safetensors` and `model.json`).
//!
//! ```
//! use phi_core::backend::ndarray::NdArray;
//! use phi_gns::data::Metadata;
//! use phi_gns::model::{Gns, GnsConfig, GraphBatch, ModelSpec};
//!
//! let mut metadata = Metadata::new(2);
//! metadata.vel_std = vec![1e-3; 2];
//! metadata.acc_std = vec![1e-4; 2];
//! let mut config = GnsConfig::thesis(2);
//! config.latent_size = 16;
//! config.hidden_size = 16;
//! config.message_passing_steps = 2;
//! let spec = ModelSpec::for_dataset(&metadata, config, 7);
//! let device = Default::default();
//! let model = Gns::<NdArray>::init(spec, &device)?;
//! // Two particles, six frames each ([N, C + 1, dim]), at rest.
//! let window: Vec<f32> = [[0.50, 0.50], [0.51, 0.50]]
//!     .iter()
//!     .flat_map(|p| std::iter::repeat_n(*p, 6).flatten())
//!     .collect();
//! let batch = GraphBatch::from_host(&window, &[1, 1], model.spec(), &device)?;
//! let next = model.next_positions(&batch)?;
//! assert_eq!(next.shape(), vec![2, 2]);
//! # Ok::<(), phi_gns::model::ModelError>(())
//! ```

pub mod average;
mod batch;
pub mod config;
pub(crate) mod features;
pub mod files;
pub mod floor;
pub mod kernels;
pub(crate) mod network;
pub mod params;

use std::path::{Path, PathBuf};

use phi_core::error::TensorError;
use phi_core::tensor::Tensor;

use crate::graph::GraphError;
pub use average::average_models;
pub use batch::GraphBatch;
pub use config::{ConfigOverrides, GnsConfig, ModelSpec, Normalisation, Obstacles, Walls};
use features::Normalisers;
pub use files::{MODEL_FILE, WEIGHTS_FILE, load_model, read_spec, save_model};
pub use floor::Floor;
pub use kernels::GnsKernels;
pub use params::{Init, ParameterSpec, Parameters, parameter_layout};

/// Errors of the GNS model: each names the file, the key or the tensor, and both values where
/// two disagree.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A tensor operation failed (a shape misfit the checks before it did not catch).
    #[error(transparent)]
    Tensor(#[from] TensorError),
    /// The radius graph could not be built (non-finite positions, ...).
    #[error(transparent)]
    Graph(#[from] GraphError),
    /// A value of `model.json` is out of range or inconsistent.
    #[error("'{path}': key '{key}': {reason}", path = path.display())]
    Config {
        /// The file.
        path: PathBuf,
        /// The key, e.g. `config.latent_size`.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A dataset the model does not fit: another dimension, other bounds, other particle types.
    #[error(
        "'{path}': key '{key}': the model was made for {model}, the dataset has {dataset}",
        path = path.display()
    )]
    DatasetMismatch {
        /// The dataset's metadata file.
        path: PathBuf,
        /// The metadata key.
        key: String,
        /// The model's value.
        model: String,
        /// The dataset's value.
        dataset: String,
    },
    /// The weights file lacks a tensor of the layout.
    #[error("'{path}': missing tensor '{name}' (shape {shape:?})", path = path.display())]
    MissingWeight {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        name: String,
        /// The shape the layout asks for.
        shape: Vec<usize>,
    },
    /// The weights file has a tensor the layout does not know.
    #[error("'{path}': tensor '{name}' is not a parameter of this model's configuration", path = path.display())]
    UnexpectedWeight {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        name: String,
    },
    /// A tensor of the weights file has another shape than the layout's.
    #[error(
        "'{path}': tensor '{name}' has shape {found:?}, the configuration needs {expected:?}",
        path = path.display()
    )]
    WeightShape {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        name: String,
        /// The shape the configuration needs.
        expected: Vec<usize>,
        /// The shape in the file.
        found: Vec<usize>,
    },
    /// Writing a file failed (the error names it).
    #[error(transparent)]
    Io(#[from] phi_io::IoError),
    /// A file cannot be read, or is not valid safetensors / JSON.
    #[error("'{path}': {reason}", path = path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// Inputs of a forward pass that do not fit the model (a window of the wrong length or
    /// dimension, a particle type outside the embedding).
    #[error("{what}: {reason}")]
    Input {
        /// The input.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A NaN or infinite training loss or gradient: the update is not made.
    #[error("{what}: {reason}")]
    NonFinite {
        /// `loss` or `gradients`.
        what: &'static str,
        /// The value, or the parameter whose gradient is not finite.
        reason: String,
    },
    /// A prediction with NaN or infinite positions: the rollout stops there.
    #[error(
        "rollout step {step} (frame {frame}): particle {particle} has a non-finite predicted position"
    )]
    NonFinitePrediction {
        /// The rollout step, counted from 1.
        step: usize,
        /// The trajectory frame it predicts.
        frame: usize,
        /// The first particle with a non-finite component.
        particle: usize,
    },
}

/// A GNS: its `model.json` and its parameters on backend `B`.
#[derive(Debug, Clone)]
pub struct Gns<B: phi_core::Backend> {
    spec: ModelSpec,
    params: Parameters<B>,
    normalisers: Normalisers<B>,
}

impl<B: GnsKernels> Gns<B> {
    /// A model with seeded initial weights (the seed is `spec.seed`).
    ///
    /// # Errors
    /// [`ModelError::Config`] when `spec` is invalid.
    pub fn init(spec: ModelSpec, device: &B::Device) -> Result<Self, ModelError> {
        spec.validate(&PathBuf::from(MODEL_FILE))?;
        let params = Parameters::init(&spec.config, spec.seed, device);
        Self::new(spec, params)
    }

    /// A model from a spec and parameters of its layout.
    ///
    /// # Errors
    /// [`ModelError::Config`] when `spec` is invalid; [`ModelError::MissingWeight`] /
    /// [`ModelError::WeightShape`] when `params` do not fit it.
    pub fn new(spec: ModelSpec, params: Parameters<B>) -> Result<Self, ModelError> {
        spec.validate(&PathBuf::from(MODEL_FILE))?;
        let source = PathBuf::from(WEIGHTS_FILE);
        let named = params
            .iter()
            .map(|(n, t)| (n.to_string(), t.clone()))
            .collect();
        let params = Parameters::from_tensors(&spec.config, named, &source)?;
        let device = params
            .iter()
            .next()
            .map(|(_, t)| t.device())
            .unwrap_or_else(B::default_device);
        let normalisers = Normalisers::new(&spec, &device)?;
        Ok(Gns {
            spec,
            params,
            normalisers,
        })
    }

    /// The configuration and dataset facts.
    pub fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    /// The parameters.
    pub fn params(&self) -> &Parameters<B> {
        &self.params
    }

    /// The same model with other parameters of the same layout (trainable leaves, an
    /// optimiser's update). The spec was validated and the normalisers made when `self` was:
    /// only the parameters' names and shapes are checked (on the host), and the normalisers are
    /// made again only when the parameters live on another device. A training step calls this
    /// twice or more, so it must not re-upload what has not changed.
    ///
    /// # Errors
    /// [`ModelError::MissingWeight`], [`ModelError::UnexpectedWeight`] or
    /// [`ModelError::WeightShape`] when `params` do not fit the spec.
    pub fn with_params(&self, params: Parameters<B>) -> Result<Self, ModelError> {
        let named = params
            .iter()
            .map(|(n, t)| (n.to_string(), t.clone()))
            .collect();
        let params =
            Parameters::from_tensors(&self.spec.config, named, &PathBuf::from(WEIGHTS_FILE))?;
        let device = params.iter().next().map(|(_, t)| t.device());
        let normalisers = match device {
            Some(device) if device != self.normalisers.vel_mean.device() => {
                Normalisers::new(&self.spec, &device)?
            }
            _ => self.normalisers.clone(),
        };
        Ok(Gns {
            spec: self.spec.clone(),
            params,
            normalisers,
        })
    }

    /// The same model measuring its boundary features against other walls: `bounds` `[lower,
    /// upper]` per dimension in stored units (a model trained on one domain rolled out on a
    /// larger one). Without boundary features nothing changes but the recorded bounds.
    ///
    /// # Errors
    /// [`ModelError::Config`] for bounds of another dimension, reversed or non-finite ones.
    pub fn with_bounds(&self, bounds: Vec<[f64; 2]>) -> Result<Self, ModelError> {
        let mut spec = self.spec.clone();
        spec.bounds = bounds;
        Self::new(spec, self.params.clone())
    }

    /// The same model with other walls for its rollouts ([`Walls`]); the network and its
    /// predictions of one step are unchanged.
    pub fn with_walls(&self, walls: Walls) -> Self {
        let mut model = self.clone();
        model.spec.config.walls = walls;
        model
    }

    /// The same model with another treatment of liquid predicted inside obstacles for its
    /// rollouts ([`Obstacles`]); the network and its predictions of one step are unchanged.
    ///
    /// # Errors
    /// [`ModelError::Config`] for a cell size that is not a positive number.
    pub fn with_obstacles(&self, obstacles: Obstacles) -> Result<Self, ModelError> {
        let mut model = self.clone();
        model.spec.config.obstacles = obstacles;
        model.spec.config.validate(Path::new("obstacles"))?;
        Ok(model)
    }

    /// The network's output: the normalised acceleration `[N, dim]` of every particle.
    ///
    /// # Errors
    /// Only tensor errors, which [`GraphBatch::new`]'s checks rule out.
    pub fn normalised_acceleration(&self, batch: &GraphBatch<B>) -> Result<Tensor<B>, ModelError> {
        let config = &self.spec.config;
        let radius = config.connectivity_radius as f32;
        let nodes = features::node_features(
            batch,
            &self.params,
            &self.normalisers,
            config
                .boundary_features
                .then_some(radius * config.boundary_horizon as f32),
            config.uses_embedding(),
        )?;
        let latest = features::latest_positions(batch.positions())?;
        let (senders, receivers) = batch.edge_index();
        let edges = features::edge_features(&latest, senders, receivers, radius)?;
        network::encode_process_decode(
            &self.params,
            config.hidden_layers,
            config.message_passing_steps,
            &nodes,
            &edges,
            senders,
            receivers,
        )
    }

    /// The predicted acceleration in stored units `[N, dim]`.
    ///
    /// # Errors
    /// As [`Gns::normalised_acceleration`].
    pub fn acceleration(&self, batch: &GraphBatch<B>) -> Result<Tensor<B>, ModelError> {
        features::denormalise_acceleration(&self.normalised_acceleration(batch)?, &self.normalisers)
    }

    /// The next positions `[N, dim]` of every particle, kinematic ones included (a rollout
    /// replaces those by the ground truth).
    ///
    /// # Errors
    /// As [`Gns::normalised_acceleration`].
    pub fn next_positions(&self, batch: &GraphBatch<B>) -> Result<Tensor<B>, ModelError> {
        self.integrate(batch, &self.normalised_acceleration(batch)?)
    }

    /// The next positions `[N, dim]` from the window of `batch` and the network's output
    /// `normalised` on it (what [`Gns::next_positions`] computes, for a caller that needs the
    /// output too).
    pub(crate) fn integrate(
        &self,
        batch: &GraphBatch<B>,
        normalised: &Tensor<B>,
    ) -> Result<Tensor<B>, ModelError> {
        let acceleration = features::denormalise_acceleration(normalised, &self.normalisers)?;
        features::integrate(batch.positions(), &acceleration)
    }

    /// The normalised acceleration that takes the window's latest positions to `next`
    /// (`[N, dim]`): the one-step training target, `p_{t+1} − 2p_t + p_{t−1}` normalised.
    ///
    /// # Errors
    /// Shape errors when `next` is not `[N, dim]`.
    pub fn target_acceleration(
        &self,
        batch: &GraphBatch<B>,
        next: &Tensor<B>,
    ) -> Result<Tensor<B>, ModelError> {
        let positions = batch.positions();
        let latest = features::latest_positions(positions)?;
        let previous = features::previous_positions(positions)?;
        let acceleration =
            next.binary(phi_core::backend::BinaryOp::Sub, &(&latest * 2.0))? + previous;
        self.normalise_acceleration(&acceleration)
    }

    /// An acceleration in stored units (`[N, dim]`) in the units of the network's output:
    /// `(a − acc_mean) / acc_scale`.
    ///
    /// # Errors
    /// Shape errors when `acceleration` is not `[N, dim]`.
    pub(crate) fn normalise_acceleration(
        &self,
        acceleration: &Tensor<B>,
    ) -> Result<Tensor<B>, ModelError> {
        features::normalise_acceleration(acceleration, &self.normalisers)
    }
}
