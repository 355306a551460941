//! [`GraphBatch`]: the inputs of one forward pass, a batch of examples concatenated over
//! particles: their windows `[N, C + 1, dim]`, their types, and the radius graph of their
//! latest positions.

use std::sync::Arc;

use phi_core::tensor::{IntTensor, Tensor};

use super::{ModelError, ModelSpec, features};
use crate::graph::{ExamplePositions, RadiusGraph};

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
    pub(crate) fn edge_index(&self) -> (&IntTensor<B>, &IntTensor<B>) {
        (&self.senders, &self.receivers)
    }

    /// The same graph and types with other positions of the same shape (a noisy or predicted
    /// window: the graph is not rebuilt).
    ///
    /// # Errors
    /// [`ModelError::Input`] for another shape.
    pub fn with_positions(&self, positions: Tensor<B>) -> Result<Self, ModelError> {
        self.check_same_shape(&positions)?;
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
        self.check_same_shape(&positions)?;
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
        self.advance_from(next, &next.to_vec(), spec)
    }

    /// [`ModelError::Input`] unless `positions` has the shape of this batch's window.
    fn check_same_shape(&self, positions: &Tensor<B>) -> Result<(), ModelError> {
        if positions.shape() == self.positions.shape() {
            return Ok(());
        }
        Err(ModelError::Input {
            what: "positions",
            reason: format!(
                "shape {:?} replaces {:?}",
                positions.shape(),
                self.positions.shape()
            ),
        })
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
