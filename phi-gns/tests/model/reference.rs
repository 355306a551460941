//! A plain-Rust f64 forward pass of the GNS as its documentation describes it, written from the
//! documented layout and nothing of the model's code, so that every backend is checked against
//! the maths rather than against another backend:
//!
//! - node features: the `C` velocities `p_{t+1} − p_t` normalised by `(v − vel_mean) /
//!   √(vel_std² + σ²)`, oldest first; the distances of the latest position to the lower bounds
//!   per axis, then to the upper bounds per axis, over `R`, clipped to `[−1, 1]`; the row of
//!   `embedding.weight` of the particle's type;
//! - edge features: `(p_s − p_r) / R` per axis, then its Euclidean norm;
//! - an MLP `{prefix}` is dense layers `{prefix}.{i}` (`y = x Wᵀ + b`, `W [out, in]`) with a ReLU
//!   after every layer but the last, then a LayerNorm `{prefix}.ln` (biased variance, eps 1e-5)
//!   on every MLP but the decoder;
//! - encoder `encoder.node` and `encoder.edge`; processor step `k`: `e′ = processor.k.edge([e,
//!   v_s, v_r])` on the concatenation, `v′ = processor.k.node([v, Σ_{edges into v} e′])`, then
//!   `v += v′`, `e += e′`; decoder `decoder(v)`, the normalised acceleration.

use std::collections::BTreeMap;

use phi_core::Backend;
use phi_gns::model::{ModelSpec, Parameters};

use crate::common::host_params;

/// LayerNorm's epsilon (PyTorch's default).
pub const EPS: f64 = 1e-5;

/// The model in f64 on the host.
#[derive(Debug, Clone)]
pub struct HostGns {
    pub spec: ModelSpec,
    pub params: BTreeMap<String, Vec<f64>>,
}

/// A graph's edges on the host.
#[derive(Debug, Clone, Copy)]
pub struct Edges<'a> {
    pub senders: &'a [i64],
    pub receivers: &'a [i64],
}

impl HostGns {
    /// The model of `spec` with the values of `params`.
    pub fn new<B: Backend>(spec: &ModelSpec, params: &Parameters<B>) -> Self {
        HostGns {
            spec: spec.clone(),
            params: host_params(params),
        }
    }

    fn param(&self, name: &str) -> &[f64] {
        self.params
            .get(name)
            .unwrap_or_else(|| panic!("no parameter '{name}'"))
    }

    /// Node features `[N, F]` of a window `[N, C + 1, dim]`.
    pub fn node_features(&self, window: &[f64], types: &[i64]) -> Vec<f64> {
        let config = &self.spec.config;
        let (dim, frames, n) = (config.dim, config.input_velocities + 1, types.len());
        assert_eq!(window.len(), n * frames * dim, "window size");
        let r = config.connectivity_radius;
        let norm = &self.spec.normalisation;
        let noise = config.noise_std;
        let scale: Vec<f64> = norm
            .vel_std
            .iter()
            .map(|s| (s * s + noise * noise).sqrt())
            .collect();
        let mut features = Vec::with_capacity(n * config.node_features());
        for (i, &t) in types.iter().enumerate() {
            let p = |frame: usize, a: usize| window[(i * frames + frame) * dim + a];
            for frame in 0..frames - 1 {
                for (a, (mean, scale)) in norm.vel_mean.iter().zip(&scale).enumerate() {
                    let v = p(frame + 1, a) - p(frame, a);
                    features.push((v - mean) / scale);
                }
            }
            if config.boundary_features {
                for a in 0..dim {
                    let d =
                        (p(frames - 1, a) - self.spec.bounds[a][0]) / (r * config.boundary_horizon);
                    features.push(d.clamp(-1.0, 1.0));
                }
                for a in 0..dim {
                    let d =
                        (self.spec.bounds[a][1] - p(frames - 1, a)) / (r * config.boundary_horizon);
                    features.push(d.clamp(-1.0, 1.0));
                }
            }
            if config.uses_embedding() {
                let width = config.embedding_size;
                let row = t as usize * width;
                features.extend_from_slice(&self.param("embedding.weight")[row..row + width]);
            }
        }
        assert_eq!(features.len(), n * config.node_features());
        features
    }

    /// Edge features `[E, dim + 1]` of a window.
    pub fn edge_features(&self, window: &[f64], n: usize, edges: Edges<'_>) -> Vec<f64> {
        let config = &self.spec.config;
        let (dim, frames) = (config.dim, config.input_velocities + 1);
        let r = config.connectivity_radius;
        let latest = |i: i64, a: usize| window[(i as usize * frames + frames - 1) * dim + a];
        assert!(
            edges
                .senders
                .iter()
                .chain(edges.receivers)
                .all(|&i| (i as usize) < n)
        );
        let mut features = Vec::with_capacity(edges.senders.len() * (dim + 1));
        for (&s, &rcv) in edges.senders.iter().zip(edges.receivers) {
            let d: Vec<f64> = (0..dim)
                .map(|a| (latest(s, a) - latest(rcv, a)) / r)
                .collect();
            let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            features.extend(d);
            features.push(norm);
        }
        features
    }

    /// `x W ᵀ + b` of the dense layer `name` on `rows` rows, with the ReLU when `relu`.
    pub fn dense(&self, name: &str, x: &[f64], rows: usize, relu: bool) -> Vec<f64> {
        let w = self.param(&format!("{name}.weight"));
        let b = self.param(&format!("{name}.bias"));
        let out = b.len();
        let inputs = w.len() / out;
        assert_eq!(x.len(), rows * inputs, "{name}: input width");
        let mut y = Vec::with_capacity(rows * out);
        for xi in x.chunks_exact(inputs) {
            for (wo, bo) in w.chunks_exact(inputs).zip(b) {
                let s = xi.iter().zip(wo).fold(*bo, |s, (x, w)| s + x * w);
                y.push(if relu { s.max(0.0) } else { s });
            }
        }
        y
    }

    /// LayerNorm `name` over rows of width `gamma.len()`.
    pub fn layer_norm(&self, name: &str, x: &[f64]) -> Vec<f64> {
        layer_norm(
            x,
            self.param(&format!("{name}.weight")),
            self.param(&format!("{name}.bias")),
        )
    }

    /// The MLP `prefix` on `rows` rows, with its LayerNorm when `ln`.
    pub fn mlp(&self, prefix: &str, x: &[f64], rows: usize, ln: bool) -> Vec<f64> {
        let layers = self.spec.config.hidden_layers;
        let mut x = x.to_vec();
        for i in 0..=layers {
            x = self.dense(&format!("{prefix}.{i}"), &x, rows, i < layers);
        }
        if ln {
            x = self.layer_norm(&format!("{prefix}.ln"), &x);
        }
        x
    }

    /// The normalised acceleration `[N, dim]` of a window `[N, C + 1, dim]` on a given graph.
    pub fn normalised_acceleration(
        &self,
        window: &[f64],
        types: &[i64],
        edges: Edges<'_>,
    ) -> Vec<f64> {
        let config = &self.spec.config;
        let (n, e) = (types.len(), edges.senders.len());
        let latent = config.latent_size;
        let mut v = self.mlp("encoder.node", &self.node_features(window, types), n, true);
        let mut ev = self.mlp(
            "encoder.edge",
            &self.edge_features(window, n, edges),
            e,
            true,
        );
        for k in 0..config.message_passing_steps {
            let row =
                |x: &[f64], i: i64| x[i as usize * latent..(i as usize + 1) * latent].to_vec();
            let mut input = Vec::with_capacity(e * 3 * latent);
            for (j, (&s, &r)) in edges.senders.iter().zip(edges.receivers).enumerate() {
                input.extend_from_slice(&ev[j * latent..(j + 1) * latent]);
                input.extend(row(&v, s));
                input.extend(row(&v, r));
            }
            let messages = self.mlp(&format!("processor.{k}.edge"), &input, e, true);
            let mut sums = vec![0.0; n * latent];
            for (j, &r) in edges.receivers.iter().enumerate() {
                for c in 0..latent {
                    sums[r as usize * latent + c] += messages[j * latent + c];
                }
            }
            let mut node_input = Vec::with_capacity(n * 2 * latent);
            for i in 0..n {
                node_input.extend_from_slice(&v[i * latent..(i + 1) * latent]);
                node_input.extend_from_slice(&sums[i * latent..(i + 1) * latent]);
            }
            let update = self.mlp(&format!("processor.{k}.node"), &node_input, n, true);
            for (x, u) in v.iter_mut().zip(&update) {
                *x += u;
            }
            for (x, m) in ev.iter_mut().zip(&messages) {
                *x += m;
            }
        }
        self.mlp("decoder", &v, n, false)
    }
}

/// LayerNorm of rows of width `gamma.len()`: `(x − mean) / √(var + eps) · gamma + beta`, the
/// variance biased (divided by the width).
pub fn layer_norm(x: &[f64], gamma: &[f64], beta: &[f64]) -> Vec<f64> {
    let k = gamma.len();
    let mut y = Vec::with_capacity(x.len());
    for row in x.chunks_exact(k) {
        let mean = row.iter().sum::<f64>() / k as f64;
        let var = row.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / k as f64;
        let inv = 1.0 / (var + EPS).sqrt();
        for ((x, g), b) in row.iter().zip(gamma).zip(beta) {
            y.push((x - mean) * inv * g + b);
        }
    }
    y
}

/// The one-step loss: `Σ_i w_i Σ_a (acc_ia − target_ia)²` with `w_i = 1 / (non-kinematic
/// particles)` for a non-kinematic particle and 0 for a kinematic one.
pub fn loss(acceleration: &[f64], target: &[f64], weights: &[f64], dim: usize) -> f64 {
    acceleration
        .chunks_exact(dim)
        .zip(target.chunks_exact(dim))
        .zip(weights)
        .map(|((a, t), w)| w * a.iter().zip(t).map(|(a, t)| (a - t) * (a - t)).sum::<f64>())
        .sum()
}
