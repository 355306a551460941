//! Training the GNS (thesis section 5.3): the pieces that do not depend on the optimiser.
//!
//! - [`noise`]: DeepMind's random-walk noise on the input positions, and the matching target;
//! - [`loss`]: the one-step loss of equation 5.1 on normalised accelerations.

pub mod loss;
pub mod noise;

pub use loss::{non_kinematic_mask, one_step_loss};
pub use noise::{RandomWalkNoise, random_walk_noise};
