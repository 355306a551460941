//! Per-step generators: their definition as a ChaCha8 keystream and the unbiased index draw.

use crate::train::rng::{RngStream, step_rng, uniform_index};
use rand::RngCore;

use super::common::{chi_square, chi_square_bound};

/// Block `counter` of the ChaCha keystream with `rounds` rounds (RFC 8439's block function with
/// a 64-bit counter and a 64-bit nonce, as in the original ChaCha), written out here.
fn chacha_block(key: &[u8; 32], nonce: u64, counter: u64, rounds: usize) -> [u32; 16] {
    let mut state = [0u32; 16];
    state[..4].copy_from_slice(&[0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574]);
    for (i, word) in key.chunks_exact(4).enumerate() {
        state[4 + i] = u32::from_le_bytes(word.try_into().unwrap());
    }
    state[12] = counter as u32;
    state[13] = (counter >> 32) as u32;
    state[14] = nonce as u32;
    state[15] = (nonce >> 32) as u32;
    let quarter = |x: &mut [u32; 16], a: usize, b: usize, c: usize, d: usize| {
        x[a] = x[a].wrapping_add(x[b]);
        x[d] = (x[d] ^ x[a]).rotate_left(16);
        x[c] = x[c].wrapping_add(x[d]);
        x[b] = (x[b] ^ x[c]).rotate_left(12);
        x[a] = x[a].wrapping_add(x[b]);
        x[d] = (x[d] ^ x[a]).rotate_left(8);
        x[c] = x[c].wrapping_add(x[d]);
        x[b] = (x[b] ^ x[c]).rotate_left(7);
    };
    let mut x = state;
    for _ in 0..rounds / 2 {
        quarter(&mut x, 0, 4, 8, 12);
        quarter(&mut x, 1, 5, 9, 13);
        quarter(&mut x, 2, 6, 10, 14);
        quarter(&mut x, 3, 7, 11, 15);
        quarter(&mut x, 0, 5, 10, 15);
        quarter(&mut x, 1, 6, 11, 12);
        quarter(&mut x, 2, 7, 8, 13);
        quarter(&mut x, 3, 4, 9, 14);
    }
    for (out, input) in x.iter_mut().zip(state) {
        *out = out.wrapping_add(input);
    }
    x
}

#[test]
fn chacha_block_matches_the_rfc_8439_test_vector() {
    // RFC 8439 section 2.3.2 uses a 96-bit nonce 00:00:00:09:00:00:00:4a:00:00:00:00 and
    // counter 1; with a 64-bit counter that is counter word 1, word 13 = 0x09000000, and
    // nonce words 0x4a000000, 0.
    let key: [u8; 32] = std::array::from_fn(|i| i as u8);
    let counter = 1 | (0x0900_0000u64 << 32);
    let block = chacha_block(&key, 0x4a00_0000, counter, 20);
    assert_eq!(
        block[..4],
        [0xe4e7_f110, 0x1559_3bd1, 0x1fdd_0f50, 0xc471_20a3]
    );
    assert_eq!(block[15], 0x4e3c_50a2);
}

#[test]
fn a_step_generator_is_the_chacha8_keystream_of_seed_purpose_and_step() {
    for (seed, step, stream) in [
        (0, 0, RngStream::Sampling),
        (42, 7, RngStream::Noise),
        (u64::MAX, 123_456_789, RngStream::Pushforward),
    ] {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        key[8..16].copy_from_slice(&stream.id().to_le_bytes());
        // Three blocks, so that the comparison crosses block boundaries.
        let expected: Vec<u32> = (0..3)
            .flat_map(|block| chacha_block(&key, step, block, 8))
            .collect();
        let mut rng = step_rng(seed, step, stream);
        let drawn: Vec<u32> = (0..expected.len()).map(|_| rng.next_u32()).collect();
        assert_eq!(drawn, expected, "seed {seed}, step {step}, {stream:?}");
    }
}

#[test]
fn step_generators_differ_by_seed_step_and_purpose_only() {
    let first = |seed, step, stream| step_rng(seed, step, stream).next_u64();
    let base = first(5, 10, RngStream::Sampling);
    assert_eq!(base, first(5, 10, RngStream::Sampling));
    assert_ne!(base, first(6, 10, RngStream::Sampling));
    assert_ne!(base, first(5, 11, RngStream::Sampling));
    assert_ne!(base, first(5, 10, RngStream::Noise));
    assert_ne!(
        first(5, 10, RngStream::Noise),
        first(5, 10, RngStream::Pushforward)
    );
    let ids = [
        RngStream::Sampling,
        RngStream::Noise,
        RngStream::Pushforward,
    ]
    .map(RngStream::id);
    assert_eq!(
        ids,
        [1, 2, 3],
        "the identifiers are part of the reproducibility contract"
    );
}

/// A generator that returns given 64-bit values, counting them.
struct Fixed(Vec<u64>, usize);

impl RngCore for Fixed {
    fn next_u32(&mut self) -> u32 {
        self.next_u64() as u32
    }
    fn next_u64(&mut self) -> u64 {
        self.1 += 1;
        self.0[self.1 - 1]
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for chunk in dst.chunks_mut(8) {
            let bytes = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
    }
}

#[test]
fn uniform_index_is_the_high_word_of_the_product_and_rejects_the_biased_low_words() {
    // n = 3: 2⁶⁴ mod 3 = 1, so x = 0 (low word 0 < 1) is redrawn; x = 2⁶⁴ − 1 gives
    // ⌊3 (2⁶⁴ − 1) / 2⁶⁴⌋ = 2.
    let mut rng = Fixed(vec![0, u64::MAX], 0);
    assert_eq!(uniform_index(&mut rng, 3), 2);
    assert_eq!(rng.1, 2);
    let mut rng = Fixed(vec![1 << 63], 0);
    assert_eq!(uniform_index(&mut rng, 3), 1);
    // n = 2⁶³ + 1: 2⁶⁴ mod n = 2⁶³ − 1; x = 1 has low word 2⁶³ + 1 ≥ that and gives 0.
    let mut rng = Fixed(vec![1], 0);
    assert_eq!(uniform_index(&mut rng, (1usize << 63) + 1), 0);
    // x = 2 has low word 2 < 2⁶³ − 1: redrawn.
    let mut rng = Fixed(vec![2, u64::MAX], 0);
    assert_eq!(uniform_index(&mut rng, (1usize << 63) + 1), 1 << 63);
    assert_eq!(rng.1, 2);
    let mut rng = Fixed(vec![u64::MAX], 0);
    assert_eq!(uniform_index(&mut rng, 1), 0);
}

#[test]
fn uniform_index_is_uniform() {
    let n = 7;
    let mut counts = vec![0u64; n];
    for step in 0..70 {
        let mut rng = step_rng(3, step, RngStream::Sampling);
        for _ in 0..1000 {
            counts[uniform_index(&mut rng, n)] += 1;
        }
    }
    let chi2 = chi_square(&counts);
    assert!(chi2 < chi_square_bound(n), "χ² = {chi2}: {counts:?}");
}
