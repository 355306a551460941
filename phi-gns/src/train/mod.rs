//! Training the GNS (thesis section 5.3): its pieces.
//!
//! - [`noise`]: DeepMind's random-walk noise on the input positions, and the matching target;
//! - [`adam`]: Adam over the named parameters, with DeepMind's learning-rate schedule;
//! - [`loss`]: the one-step loss of equation 5.1 on normalised accelerations;
//! - the data pipeline: `rng` (per-step generators), `sampler` (windows), `cache`
//!   (trajectories) and `stream` (batches read ahead on another thread), crate-private but
//!   for [`BatchSource`] (the batches of any step) and [`WindowSpec`].
//! - [`multistep`]: the multi-step loss of equation 5.2, the model run on its own predictions;
//! - [`pushforward`]: LagrangeBench's pushforward training, a one-step loss after unrolled
//!   steps without gradient, and its schedule.
//!
//! - `average`: a moving average of the weights over the steps, screened and kept instead
//!   of the weights of one step.
//!
//! [`step`] is one training step read top to bottom (`take_step`: windows, mirroring, noise,
//! targets, graph, the variant's loss, gradients, Adam); [`train_step`] and
//! [`train_step_with`] take one Adam step on a loss of the caller's. A whole run, with its
//! presets ([`config`]), checkpoints (`checkpoint`), screening on the validation split
//! ([`screening`]) and files, is [`run::TrainingRun`]; `phi train` drives it.

pub mod adam;
pub(crate) mod average;
pub(crate) mod cache;
pub(crate) mod checkpoint;
pub mod config;
mod error;
pub(crate) mod impacts;
pub mod loss;
pub mod multistep;
pub mod noise;
pub mod options;
pub mod pushforward;
pub(crate) mod rng;
pub mod run;
pub(crate) mod sampler;
pub mod screening;
pub mod step;
pub(crate) mod stream;

pub use adam::{Adam, AdamConfig, LearningRate};
pub use checkpoint::BEST_DIR;
pub use config::TrainConfig;
pub use error::TrainError;
pub use impacts::ImpactSampling;
pub use loss::{ErrorNorm, acceleration_loss, non_kinematic_mask, obstacle_weights, one_step_loss};
pub use multistep::multi_step_loss;
pub use noise::{RandomWalkNoise, random_walk_noise};
pub use pushforward::{Pushforward, push_forward, pushforward_loss};
pub use sampler::WindowSpec;
pub use step::{train_step, train_step_with};
pub use stream::{BatchConfig, BatchSource, HostExample};

#[cfg(test)]
mod pipeline_tests;
