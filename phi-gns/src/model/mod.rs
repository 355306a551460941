//! The Graph Network-based Simulator (Sanchez-Gonzalez et al. 2020; thesis section 5.1),
//! written once against [`Backend`](phi_core::Backend) through [`GnsKernels`].
//!
//! - [`config`]: sizes and options ([`GnsConfig`]) and `model.json` ([`ModelSpec`]);
//! - [`params`]: the named parameters, their PyTorch-style layout and seeded initial values;
//! - [`features`]: node and edge features from a window of positions, and the integration of
//!   the predicted acceleration;
//! - [`network`]: encode-process-decode with unshared interaction networks;
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

pub mod config;
pub mod features;
pub mod files;
pub mod floor;
pub mod kernels;
pub mod network;
pub mod params;

use std::path::PathBuf;
use std::sync::Arc;

use phi_core::error::TensorError;
use phi_core::tensor::{IntTensor, Tensor};

use crate::graph::{ExamplePositions, GraphError, RadiusGraph};
pub use config::{GnsConfig, MODEL_FORMAT, MODEL_FORMAT_VERSION, ModelSpec, Normalisation};
pub use features::Normalisers;
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

/// The inputs of one forward pass: a batch of examples concatenated over particles.
#[derive(Debug, Clone)]
pub struct GraphBatch<B: phi_core::Backend> {
    positions: Tensor<B>,
    particle_type: IntTensor<B>,
    /// The same types on the host, checked against the model once, when the batch was made.
    types: Arc<[i64]>,
    senders: IntTensor<B>,
    receivers: IntTensor<B>,
    graph: RadiusGraph,
}

impl<B: phi_core::Backend> GraphBatch<B> {
    /// A batch from positions `[N, C + 1, dim]` (each particle's last `C + 1` positions, oldest
    /// first: DeepMind's layout), particle types `[N]` and the radius graph of the latest
    /// positions (with its node offsets per example).
    ///
    /// # Errors
    /// [`ModelError::Input`] when the shapes do not fit `spec` or each other, or a type is not
    /// one of the model's.
    pub fn new(
        positions: Tensor<B>,
        particle_type: IntTensor<B>,
        graph: RadiusGraph,
        spec: &ModelSpec,
    ) -> Result<Self, ModelError> {
        let types: Arc<[i64]> = particle_type.to_vec().into();
        Self::checked(positions, particle_type, types, graph, spec)
    }

    /// [`GraphBatch::new`] with the types also on the host (`types` must be `particle_type`'s
    /// values): everything is checked, nothing is read back from the device.
    fn checked(
        positions: Tensor<B>,
        particle_type: IntTensor<B>,
        types: Arc<[i64]>,
        graph: RadiusGraph,
        spec: &ModelSpec,
    ) -> Result<Self, ModelError> {
        let config = &spec.config;
        let window = config.input_velocities + 1;
        let shape = positions.shape();
        if shape.len() != 3 || shape[1] != window || shape[2] != config.dim {
            return Err(ModelError::Input {
                what: "positions",
                reason: format!(
                    "shape {shape:?}; the model needs [particles, {window}, {}]",
                    config.dim
                ),
            });
        }
        if particle_type.shape() != [shape[0]] || graph.nodes() != shape[0] {
            return Err(ModelError::Input {
                what: "particle types",
                reason: format!(
                    "{:?} types and a graph of {} nodes for {} particles",
                    particle_type.shape(),
                    graph.nodes(),
                    shape[0]
                ),
            });
        }
        if let Some(t) = types
            .iter()
            .find(|&&t| t < 0 || t as usize >= config.particle_types)
        {
            return Err(ModelError::Input {
                what: "particle types",
                reason: format!(
                    "type {t} is not one of the model's 0..{}",
                    config.particle_types
                ),
            });
        }
        Self::assemble(positions, particle_type, types, graph)
    }

    /// A batch of parts that are known to fit each other and the model (the particles and types
    /// of a batch that was checked, the graph of its new positions): no check, no read-back.
    fn assemble(
        positions: Tensor<B>,
        particle_type: IntTensor<B>,
        types: Arc<[i64]>,
        graph: RadiusGraph,
    ) -> Result<Self, ModelError> {
        let device = positions.device();
        let (senders, receivers) = graph.to_tensors::<B>(&device)?;
        Ok(GraphBatch {
            positions,
            particle_type,
            types,
            senders,
            receivers,
            graph,
        })
    }

    /// One example from host data: `window` is `[N, C + 1, dim]` row-major, `particle_type`
    /// `[N]`; the radius graph is built from the latest positions.
    ///
    /// # Errors
    /// As [`GraphBatch::new`], and [`ModelError::Graph`] for non-finite positions.
    pub fn from_host(
        window: &[f32],
        particle_type: &[i64],
        spec: &ModelSpec,
        device: &B::Device,
    ) -> Result<Self, ModelError> {
        Self::from_host_batch(&[(window, particle_type)], spec, device)
    }

    /// Several examples from host data, each `(window [N_i, C + 1, dim], types [N_i])`,
    /// concatenated in order.
    ///
    /// # Errors
    /// As [`GraphBatch::from_host`].
    pub fn from_host_batch(
        examples: &[(&[f32], &[i64])],
        spec: &ModelSpec,
        device: &B::Device,
    ) -> Result<Self, ModelError> {
        let config = &spec.config;
        let (dim, window) = (config.dim, config.input_velocities + 1);
        let mut latest = Vec::with_capacity(examples.len());
        for (i, (positions, types)) in examples.iter().enumerate() {
            if positions.len() != types.len() * window * dim {
                return Err(ModelError::Input {
                    what: "positions",
                    reason: format!(
                        "example {i}: {} values for {} particles × {window} frames × {dim}",
                        positions.len(),
                        types.len()
                    ),
                });
            }
            let last: Vec<f32> = positions
                .chunks_exact(window * dim)
                .flat_map(|p| p[(window - 1) * dim..].iter().copied())
                .collect();
            latest.push(last);
        }
        let views: Vec<ExamplePositions<'_>> = latest
            .iter()
            .zip(examples)
            .map(|(p, (_, t))| ExamplePositions::new(p, t.len()))
            .collect();
        let graph = RadiusGraph::for_batch(&views, dim, config.connectivity_radius)?;
        let n: usize = examples.iter().map(|(_, t)| t.len()).sum();
        let data: Vec<f32> = examples
            .iter()
            .flat_map(|(p, _)| p.iter().copied())
            .collect();
        let types: Vec<i64> = examples
            .iter()
            .flat_map(|(_, t)| t.iter().copied())
            .collect();
        let positions = Tensor::from_vec(data, &[n, window, dim], device)?;
        let particle_type = IntTensor::from_vec(types.clone(), &[n], device)?;
        Self::checked(positions, particle_type, types.into(), graph, spec)
    }

    /// The positions `[N, C + 1, dim]`.
    pub fn positions(&self) -> &Tensor<B> {
        &self.positions
    }

    /// The particle types `[N]`.
    pub fn particle_type(&self) -> &IntTensor<B> {
        &self.particle_type
    }

    /// The particle types `[N]` on the host.
    pub fn types(&self) -> &[i64] {
        &self.types
    }

    /// The radius graph.
    pub fn graph(&self) -> &RadiusGraph {
        &self.graph
    }

    /// The sender and receiver index tensors `[E]`.
    pub fn edge_index(&self) -> (&IntTensor<B>, &IntTensor<B>) {
        (&self.senders, &self.receivers)
    }

    /// The same graph and types with other positions of the same shape (a noisy or predicted
    /// window: the graph is not rebuilt).
    ///
    /// # Errors
    /// [`ModelError::Input`] for another shape.
    pub fn with_positions(&self, positions: Tensor<B>) -> Result<Self, ModelError> {
        if positions.shape() != self.positions.shape() {
            return Err(ModelError::Input {
                what: "positions",
                reason: format!(
                    "shape {:?} replaces {:?}",
                    positions.shape(),
                    self.positions.shape()
                ),
            });
        }
        Ok(GraphBatch {
            positions,
            ..self.clone()
        })
    }

    /// The same particles, types and examples with the window `positions` (`[N, C + 1, dim]`),
    /// the radius graph rebuilt per example from its latest positions. The graph is built on
    /// the host from the positions' values, so it carries no gradient; the positions keep
    /// theirs.
    ///
    /// # Errors
    /// [`ModelError::Input`] for another shape; [`ModelError::Graph`] for non-finite latest
    /// positions.
    pub fn regraph(&self, positions: Tensor<B>, spec: &ModelSpec) -> Result<Self, ModelError> {
        if positions.shape() != self.positions.shape() {
            return Err(ModelError::Input {
                what: "positions",
                reason: format!(
                    "shape {:?} replaces {:?}",
                    positions.shape(),
                    self.positions.shape()
                ),
            });
        }
        let latest = features::latest_positions(&positions)?.to_vec();
        self.regraph_from(positions, &latest, spec)
    }

    /// [`GraphBatch::regraph`] with the latest positions already on the host (`latest`,
    /// `[N, dim]`, the values of the window's last frame).
    fn regraph_from(
        &self,
        positions: Tensor<B>,
        latest: &[f32],
        spec: &ModelSpec,
    ) -> Result<Self, ModelError> {
        let dim = spec.config.dim;
        let examples: Vec<ExamplePositions<'_>> = self
            .graph
            .node_offsets()
            .windows(2)
            .map(|range| {
                ExamplePositions::new(&latest[range[0] * dim..range[1] * dim], range[1] - range[0])
            })
            .collect();
        let graph = RadiusGraph::for_batch(&examples, dim, spec.config.connectivity_radius)?;
        Self::assemble(
            positions,
            self.particle_type.clone(),
            self.types.clone(),
            graph,
        )
    }

    /// The window one frame on: the oldest position of every particle dropped, `next`
    /// (`[N, dim]`) appended as the latest, and the graph rebuilt from it
    /// ([`GraphBatch::regraph`]). Gradients flow through `next` into the new window.
    ///
    /// # Errors
    /// [`ModelError::Input`] when `next` is not `[N, dim]`; as [`GraphBatch::regraph`].
    pub fn advance(&self, next: &Tensor<B>, spec: &ModelSpec) -> Result<Self, ModelError> {
        let [n, window, dim] = self.positions.shape()[..] else {
            unreachable!("GraphBatch keeps a rank-3 window")
        };
        if next.shape() != [n, dim] {
            return Err(ModelError::Input {
                what: "next positions",
                reason: format!(
                    "shape {:?} for a window of [{n}, {window}, {dim}]",
                    next.shape()
                ),
            });
        }
        let kept = self.positions.narrow(1, 1..window)?;
        let positions = Tensor::concat(&[kept, next.unsqueeze(1)?], 1)?;
        self.regraph_from(positions, &next.to_vec(), spec)
    }

    /// [`GraphBatch::advance`] with `next`'s values already on the host (`host`, `[N, dim]`
    /// row-major): the step of a rollout, whose caller reads each frame anyway.
    pub(crate) fn advance_from(
        &self,
        next: &Tensor<B>,
        host: &[f32],
        spec: &ModelSpec,
    ) -> Result<Self, ModelError> {
        let window = self.positions.shape()[1];
        let kept = self.positions.narrow(1, 1..window)?;
        let positions = Tensor::concat(&[kept, next.unsqueeze(1)?], 1)?;
        self.regraph_from(positions, host, spec)
    }
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

    /// The normalisation constants and bounds as `[dim]` tensors.
    pub fn normalisers(&self) -> &Normalisers<B> {
        &self.normalisers
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
            radius,
            config.boundary_features,
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
    pub fn normalise_acceleration(
        &self,
        acceleration: &Tensor<B>,
    ) -> Result<Tensor<B>, ModelError> {
        features::normalise_acceleration(acceleration, &self.normalisers)
    }
}
