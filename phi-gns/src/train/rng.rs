//! Counter-based randomness of training: every random draw of optimisation step `s` comes from a
//! generator that depends only on `(seed, s, purpose)`, so that the state a checkpoint needs to
//! reproduce the rest of a run is the seed and the step, and resuming at step `s` draws exactly
//! what an uninterrupted run would have drawn.
//!
//! The generator is ChaCha8 ([`ChaCha8Rng`]), whose output `rand_chacha` documents as portable
//! and fixed by reference vectors; `rand`'s `StdRng` is documented as *not* reproducible across
//! versions or platforms, so it is not used here. [`step_rng`] keys ChaCha8 with the seed and the
//! purpose and takes the step as the 64-bit stream (nonce): distinct `(seed, purpose, step)`
//! give distinct keystreams, and no step's draws overlap another's however many are taken.

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{RngCore, SeedableRng};

/// What the draws of a step's generator are for: each purpose has its own generator, so adding
/// draws for one purpose never shifts the draws of another.
///
/// The identifiers ([`RngStream::id`]) are part of the reproducibility contract: new purposes
/// get new identifiers, existing ones never change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum RngStream {
    /// The windows of the batch ([`crate::train::sampler::WindowSampler::sample`]).
    Sampling,
    /// The random-walk noise on the input positions ([`crate::train::random_walk_noise`]).
    Noise,
    /// The draws of pushforward training (how many steps to unroll, which examples).
    Pushforward,
    /// Which examples of a batch are mirrored (`training.mirror`).
    Mirror,
}

impl RngStream {
    /// The purpose's identifier in the generator's key: 1, 2, 3, 4.
    pub fn id(self) -> u64 {
        match self {
            RngStream::Sampling => 1,
            RngStream::Noise => 2,
            RngStream::Pushforward => 3,
            RngStream::Mirror => 4,
        }
    }
}

/// The generator of step `step`'s draws for `stream`: ChaCha8 with the 256-bit key
/// `seed ‖ stream.id() ‖ 0 ‖ 0` (four little-endian `u64`), stream (nonce) `step`, from block 0.
///
/// The result depends on nothing but the three arguments; it is a [`rand::Rng`], so
/// distributions such as `rand_distr::Normal` draw from it.
pub(crate) fn step_rng(seed: u64, step: u64, stream: RngStream) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    key[8..16].copy_from_slice(&stream.id().to_le_bytes());
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(step);
    rng
}

/// A uniform integer in `0..n`, without bias: Lemire's multiply-and-reject method on
/// [`RngCore::next_u64`] (the high word of `x · n` for a uniform 64-bit `x`, redrawn in the rare
/// case that the low word falls below `2⁶⁴ mod n`).
///
/// Written here rather than taken from `rand`'s `random_range`, whose algorithm `rand` may
/// change between versions: this one is fixed, so sampled batches stay bit-exact across builds.
///
/// # Panics
/// If `n` is 0 (there is no integer to draw; callers check first).
pub(crate) fn uniform_index(rng: &mut impl RngCore, n: usize) -> usize {
    assert!(n > 0, "uniform_index: empty range");
    let n = n as u64;
    let mut product = u128::from(rng.next_u64()) * u128::from(n);
    if (product as u64) < n {
        // The `2⁶⁴ mod n` lowest values of the low word would make some results more likely.
        let threshold = n.wrapping_neg() % n;
        while (product as u64) < threshold {
            product = u128::from(rng.next_u64()) * u128::from(n);
        }
    }
    (product >> 64) as usize
}
