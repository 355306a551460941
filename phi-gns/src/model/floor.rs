//! The floors a learned simulator is read against: trivial predictors of a constant
//! acceleration, written as GNS models so that every metric and rollout treats them exactly as
//! it treats a trained one.
//!
//! A floor is a GNS whose decoder's last layer has zero weights: its output is that layer's
//! bias whatever the input, and the bias is set to the normalised acceleration the floor
//! predicts. The network in front of it is the smallest one (width 8, one message-passing
//! step), since its values are multiplied by zero.

use phi_core::Tensor;

use super::{Gns, GnsConfig, GnsKernels, ModelError, ModelSpec};
use crate::data::{Metadata, Variant};

/// A trivial predictor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Floor {
    /// Zero acceleration: every particle keeps its last velocity.
    ConstantVelocity,
    /// The dataset's mean acceleration (`acc_mean`, mostly gravity) for every particle.
    MeanAcceleration,
}

impl Floor {
    /// Both floors, in the order tables list them.
    pub const ALL: [Floor; 2] = [Floor::ConstantVelocity, Floor::MeanAcceleration];

    /// Its name in tables, file names and `model.json` (`constant-velocity`,
    /// `mean-acceleration`).
    pub fn name(self) -> &'static str {
        match self {
            Floor::ConstantVelocity => "constant-velocity",
            Floor::MeanAcceleration => "mean-acceleration",
        }
    }

    /// The floor of `name` ([`Floor::name`]), if any.
    pub fn from_name(name: &str) -> Option<Floor> {
        Floor::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The acceleration it predicts for every particle, per component in stored units.
    pub fn acceleration(self, metadata: &Metadata) -> Vec<f64> {
        match self {
            Floor::ConstantVelocity => vec![0.0; metadata.dim],
            Floor::MeanAcceleration => metadata.acc_mean.clone(),
        }
    }

    /// The floor as a model for `metadata`'s dataset with `input_velocities` past velocities
    /// (those of the models it is compared with, so that rollouts start at the same frame).
    ///
    /// # Errors
    /// [`ModelError::Config`] when the dataset's statistics make no valid model (a zero
    /// `acc_std`, say).
    pub fn model<B: GnsKernels>(
        self,
        metadata: &Metadata,
        input_velocities: usize,
        device: &B::Device,
    ) -> Result<Gns<B>, ModelError> {
        let mut config = GnsConfig::thesis(metadata.dim);
        config.input_velocities = input_velocities;
        config.connectivity_radius = metadata.default_connectivity_radius;
        config.boundary_features = metadata.variant != Variant::WallsAsParticles;
        config.latent_size = 8;
        config.hidden_size = 8;
        config.hidden_layers = 1;
        config.message_passing_steps = 1;
        config.embedding_size = 0;
        let mut spec = ModelSpec::for_dataset(metadata, config, 0);
        spec.provenance = serde_json::json!({ "floor": self.name() });
        spec.validate(std::path::Path::new("model.json"))?;
        let scale = super::Normalisation::scale(&spec.normalisation.acc_std, spec.config.noise_std);
        let bias: Vec<f32> = self
            .acceleration(metadata)
            .iter()
            .zip(&spec.normalisation.acc_mean)
            .zip(&scale)
            .map(|((a, mean), s)| ((a - mean) / s) as f32)
            .collect();
        let last = format!("decoder.{}", spec.config.hidden_layers);
        let dim = spec.config.dim;
        let model = Gns::<B>::init(spec, device)?;
        let params = model.params().map(|name, t| {
            if name == format!("{last}.weight") {
                t.zeros_like()
            } else if name == format!("{last}.bias") {
                Tensor::from_vec(bias.clone(), &[dim], device).expect("the bias is [dim]")
            } else {
                t.clone()
            }
        });
        model.with_params(params)
    }
}
