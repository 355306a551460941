//! Helpers shared by the model tests: model specs, particle scenes, parameters moved off their
//! initial values, comparisons with a stated tolerance and temporary directories.

use std::collections::BTreeMap;
use std::path::PathBuf;

use phi_core::{Backend, Tensor};
use phi_gns::data::{LIQUID, Metadata, OBSTACLE};
use phi_gns::model::{GnsConfig, ModelSpec, Parameters};

#[path = "../shared/rng.rs"]
mod rng;
pub use rng::Rng;

/// A fresh, empty directory for one test.
pub fn temp_dir(test: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("phi-gns-model-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test directory");
    dir
}

/// The metadata of a 2D dataset with the thesis' bounds `[0.1, 0.9]`, two particle types and
/// statistics of the size FLIP data has (velocities ~1e-3 and accelerations ~1e-4 per frame),
/// with non-zero means and different values per axis so that a swapped axis shows.
pub fn metadata() -> Metadata {
    let mut metadata = Metadata::new(2);
    metadata.vel_mean = vec![2e-4, -3e-4];
    metadata.vel_std = vec![1.2e-3, 0.9e-3];
    metadata.acc_mean = vec![1e-5, -4e-5];
    metadata.acc_std = vec![1.1e-4, 0.8e-4];
    metadata
}

/// The thesis' configuration (C = 5, R = 0.03, boundary features, two types) with other sizes.
pub fn config(latent: usize, hidden: usize, hidden_layers: usize, steps: usize) -> GnsConfig {
    let mut config = GnsConfig::thesis(2);
    config.latent_size = latent;
    config.hidden_size = hidden;
    config.hidden_layers = hidden_layers;
    config.message_passing_steps = steps;
    config
}

/// A model spec for [`metadata`] with `config` and `seed`.
pub fn spec(config: GnsConfig, seed: u64) -> ModelSpec {
    ModelSpec::for_dataset(&metadata(), config, seed)
}

/// One example: `window` is `[N, C + 1, 2]` (oldest frame first), `types` `[N]`.
#[derive(Debug, Clone)]
pub struct Scene {
    pub window: Vec<f32>,
    pub types: Vec<i64>,
}

impl Scene {
    /// The window in f64 (the host reference's input).
    pub fn window_f64(&self) -> Vec<f64> {
        self.window.iter().map(|&x| f64::from(x)).collect()
    }

    /// The number of particles.
    pub fn particles(&self) -> usize {
        self.types.len()
    }

    /// The number of frames of the window.
    pub fn frames(&self) -> usize {
        self.window.len() / (self.particles() * 2)
    }

    /// The scene's true frames from its window's latest on: `[N, frames, 2]` row-major, frame 0
    /// the window's latest. Each particle starts with its latest velocity; liquid falls by
    /// 1e-4 per frame² and is slowed by a drag of 5% of its velocity per frame (so that the
    /// accelerations differ between particles and follow from what the model sees), obstacles
    /// move on uniformly.
    pub fn future(&self, frames: usize) -> Vec<f32> {
        let w = self.frames();
        let mut future = Vec::with_capacity(self.particles() * frames * 2);
        for (i, &t) in self.types.iter().enumerate() {
            let at = |f: usize, a: usize| f64::from(self.window[(i * w + f) * 2 + a]);
            let mut position = [at(w - 1, 0), at(w - 1, 1)];
            let mut velocity = [position[0] - at(w - 2, 0), position[1] - at(w - 2, 1)];
            for _ in 0..frames {
                future.extend(position.iter().map(|&x| x as f32));
                if t == LIQUID {
                    velocity = [0.95 * velocity[0], 0.95 * velocity[1] - 1e-4];
                }
                for a in 0..2 {
                    position[a] += velocity[a];
                }
            }
        }
        future
    }
}

/// Frame `f` `[N, 2]` of frames `[N, F, 2]` (row-major).
pub fn frame_of(frames: &[f32], particles: usize, f: usize) -> Vec<f32> {
    let count = frames.len() / (particles * 2);
    (0..particles)
        .flat_map(|i| frames[(i * count + f) * 2..(i * count + f + 1) * 2].to_vec())
        .collect()
}

/// The window `[N, C + 1, 2]` one frame on: each particle's oldest position dropped and its
/// `next` (`[N, 2]`) appended.
pub fn shifted_window(window: &[f32], next: &[f32]) -> Vec<f32> {
    let particles = next.len() / 2;
    let w = window.len() / (particles * 2);
    (0..particles)
        .flat_map(|i| {
            let own = &window[i * w * 2..(i + 1) * w * 2];
            own[2..].iter().chain(&next[i * 2..i * 2 + 2]).copied()
        })
        .collect()
}

/// A block of `nx × ny` liquid particles at spacing 0.01 (jittered by up to ±0.002) with its
/// lower-left particle near `origin`, and below it a row of `obstacles` obstacle particles at
/// spacing 0.01, 0.015 under the block: `window` frames ending at these positions. The liquid
/// moves with a swirl of ~1e-3 per frame, falls with 1e-4 per frame², and jitters by ±5e-5 per
/// frame; the obstacles slide along x by 2e-4 per frame. Liquid comes first.
pub fn liquid_over_obstacles(
    rng: &mut Rng,
    nx: usize,
    ny: usize,
    obstacles: usize,
    origin: [f64; 2],
    window: usize,
) -> Scene {
    let mut base: Vec<([f64; 2], i64)> = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let jitter = [rng.uniform() - 0.5, rng.uniform() - 0.5];
            base.push((
                [
                    origin[0] + 0.01 * i as f64 + 0.004 * jitter[0],
                    origin[1] + 0.01 * j as f64 + 0.004 * jitter[1],
                ],
                LIQUID,
            ));
        }
    }
    for k in 0..obstacles {
        base.push(([origin[0] + 0.01 * k as f64, origin[1] - 0.015], OBSTACLE));
    }
    let last = (window - 1) as f64;
    let mut positions = Vec::with_capacity(base.len() * window * 2);
    for (p, t) in &base {
        let velocity = if *t == LIQUID {
            [1e-3 * (40.0 * p[1]).sin(), 1e-3 * (50.0 * p[0]).cos()]
        } else {
            [2e-4, 0.0]
        };
        for frame in 0..window {
            // Frames before the last one, counted back: the window ends at `base`.
            let s = frame as f64 - last;
            for a in 0..2 {
                let fall = if a == 1 && *t == LIQUID {
                    -0.5e-4 * s * s
                } else {
                    0.0
                };
                let noise = if *t == LIQUID && frame + 1 < window {
                    1e-4 * (rng.uniform() - 0.5)
                } else {
                    0.0
                };
                positions.push((p[a] + velocity[a] * s + fall + noise) as f32);
            }
        }
    }
    Scene {
        window: positions,
        types: base.iter().map(|(_, t)| *t).collect(),
    }
}

/// `params` with every LayerNorm scale drawn from `[0.6, 1.4)` and every LayerNorm shift from
/// `[-0.3, 0.3)` (their initial values, ones and zeros, would hide a LayerNorm whose parameters
/// are ignored or swapped), the other parameters unchanged.
pub fn perturbed<B: Backend>(params: &Parameters<B>, seed: u64) -> Parameters<B> {
    let mut rng = Rng::new(seed);
    params.map(|name, t| {
        let (low, high) = if name.ends_with(".ln.weight") {
            (0.6, 1.4)
        } else if name.ends_with(".ln.bias") {
            (-0.3, 0.3)
        } else {
            return t.clone();
        };
        let values = (0..t.numel())
            .map(|_| (low + (high - low) * rng.uniform()) as f32)
            .collect();
        Tensor::from_vec(values, &t.shape(), &t.device()).expect("same shape")
    })
}

/// The parameters' values in f64 by name.
pub fn host_params<B: Backend>(params: &Parameters<B>) -> BTreeMap<String, Vec<f64>> {
    params
        .iter()
        .map(|(name, t)| {
            (
                name.to_string(),
                t.to_vec().into_iter().map(f64::from).collect(),
            )
        })
        .collect()
}

/// The largest absolute value (0 for an empty slice).
pub fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// Asserts `|got_i − expected_i| ≤ rel · max_j |expected_j|` for every `i` (a relative error in
/// the max norm, which does not blow up at entries that happen to be near zero), naming the worst
/// entry.
pub fn assert_close(got: &[f32], expected: &[f64], rel: f64, what: &str) {
    let got: Vec<f64> = got.iter().map(|&x| f64::from(x)).collect();
    assert_close_f64(&got, expected, rel, what);
}

/// [`assert_close`] for f64 values.
pub fn assert_close_f64(got: &[f64], expected: &[f64], rel: f64, what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}: lengths");
    let scale = max_abs(expected);
    assert!(scale > 0.0, "{what}: the expected values are all zero");
    let (worst, error) = got
        .iter()
        .zip(expected)
        .map(|(g, e)| (g - e).abs())
        .enumerate()
        .fold((0, 0.0), |(wi, we), (i, e)| {
            if e > we || e.is_nan() {
                (i, e)
            } else {
                (wi, we)
            }
        });
    assert!(
        error <= rel * scale && got.iter().all(|g| g.is_finite()),
        "{what}: entry {worst} is {} instead of {} (error {error:.3e}, {:.3e} of the largest \
         value {scale:.3e}; tolerance {rel:.0e})",
        got[worst],
        expected[worst],
        error / scale,
    );
}

/// The bits of f32 values, for exact comparisons that also tell `0.0` from `-0.0`.
pub fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}
