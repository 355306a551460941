//! The named parameters of a GNS, their shapes and their seeded initial values.
//!
//! Names and shapes follow PyTorch (a dense layer's weight is `[out, in]`, `y = x Wᵀ + b`), so
//! that `safetensors.torch.load_file` on a model file gives a state dict a PyTorch GNS of the
//! same layout loads as it is (docs/gns.md lists the names).

use std::collections::BTreeMap;

use phi_core::backend::Backend;
use phi_core::tensor::Tensor;

use super::{GnsConfig, ModelError};

/// How a parameter starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Init {
    /// Uniform in `[-bound, bound)`: PyTorch's default for the weight and bias of a dense layer,
    /// `bound = 1/√fan_in`.
    Uniform(f32),
    /// Standard normal: PyTorch's default for an embedding.
    Normal,
    /// All ones (a LayerNorm's scale).
    Ones,
    /// All zeros (a LayerNorm's shift).
    Zeros,
}

/// One parameter of the layout: its name, shape and initialisation.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterSpec {
    /// The name in the model file, e.g. `processor.3.edge.0.weight`.
    pub name: String,
    /// The shape, `[out, in]` for a dense layer's weight.
    pub shape: Vec<usize>,
    /// How it starts.
    pub init: Init,
}

/// The widths of an MLP's dense layers, input first: `[in, hidden, ..., hidden, out]`.
pub(crate) fn mlp_widths(config: &GnsConfig, input: usize, output: usize) -> Vec<usize> {
    let mut widths = vec![input];
    widths.extend(std::iter::repeat_n(
        config.hidden_size,
        config.hidden_layers,
    ));
    widths.push(output);
    widths
}

/// Every parameter of a model of `config`, in the order in which they are initialised (the
/// order of the network, which fixes each one's seed).
pub fn parameter_layout(config: &GnsConfig) -> Vec<ParameterSpec> {
    let mut layout = Vec::new();
    let latent = config.latent_size;
    if config.uses_embedding() {
        layout.push(ParameterSpec {
            name: "embedding.weight".into(),
            shape: vec![config.particle_types, config.embedding_size],
            init: Init::Normal,
        });
    }
    let mut mlp = |prefix: &str, input: usize, output: usize, layer_norm: bool| {
        let widths = mlp_widths(config, input, output);
        for (i, pair) in widths.windows(2).enumerate() {
            let bound = 1.0 / (pair[0] as f32).sqrt();
            layout.push(ParameterSpec {
                name: format!("{prefix}.{i}.weight"),
                shape: vec![pair[1], pair[0]],
                init: Init::Uniform(bound),
            });
            layout.push(ParameterSpec {
                name: format!("{prefix}.{i}.bias"),
                shape: vec![pair[1]],
                init: Init::Uniform(bound),
            });
        }
        if layer_norm {
            for (part, init) in [("weight", Init::Ones), ("bias", Init::Zeros)] {
                layout.push(ParameterSpec {
                    name: format!("{prefix}.ln.{part}"),
                    shape: vec![output],
                    init,
                });
            }
        }
    };
    mlp("encoder.node", config.node_features(), latent, true);
    mlp("encoder.edge", config.edge_features(), latent, true);
    for k in 0..config.message_passing_steps {
        mlp(&format!("processor.{k}.edge"), 3 * latent, latent, true);
        mlp(&format!("processor.{k}.node"), 2 * latent, latent, true);
    }
    mlp("decoder", latent, config.dim, false);
    layout
}

/// The parameters of a model by name.
#[derive(Debug, Clone)]
pub struct Parameters<B: Backend> {
    tensors: BTreeMap<String, Tensor<B>>,
}

impl<B: Backend> Parameters<B> {
    /// Seeded initial values for `config` on `device`: parameter `i` of
    /// [`parameter_layout`] is drawn with a seed mixed from `seed` and `i`, on the host, so that
    /// one seed gives the same weights on every backend.
    pub fn init(config: &GnsConfig, seed: u64, device: &B::Device) -> Self {
        let tensors = parameter_layout(config)
            .into_iter()
            .enumerate()
            .map(|(i, spec)| {
                let seed = mix_seed(seed, i as u64);
                let tensor = match spec.init {
                    Init::Uniform(bound) => {
                        Tensor::random_uniform(&spec.shape, -bound, bound, seed, device)
                    }
                    Init::Normal => Tensor::random_normal(&spec.shape, 0.0, 1.0, seed, device),
                    Init::Ones => Tensor::ones(&spec.shape, device),
                    Init::Zeros => Tensor::zeros(&spec.shape, device),
                };
                (spec.name, tensor)
            })
            .collect();
        Parameters { tensors }
    }

    /// Parameters from named tensors, checked against the layout of `config`: every name
    /// present with its shape, and no other. `source` names the file in errors.
    ///
    /// # Errors
    /// [`ModelError::MissingWeight`], [`ModelError::UnexpectedWeight`] or
    /// [`ModelError::WeightShape`] naming the tensor and both shapes.
    pub(crate) fn from_tensors(
        config: &GnsConfig,
        mut tensors: BTreeMap<String, Tensor<B>>,
        source: &std::path::Path,
    ) -> Result<Self, ModelError> {
        let layout = parameter_layout(config);
        let mut checked = BTreeMap::new();
        for spec in layout {
            let tensor = tensors
                .remove(&spec.name)
                .ok_or_else(|| ModelError::MissingWeight {
                    path: source.to_path_buf(),
                    name: spec.name.clone(),
                    shape: spec.shape.clone(),
                })?;
            if tensor.shape() != spec.shape {
                return Err(ModelError::WeightShape {
                    path: source.to_path_buf(),
                    name: spec.name,
                    expected: spec.shape,
                    found: tensor.shape(),
                });
            }
            checked.insert(spec.name, tensor);
        }
        if let Some(name) = tensors.into_keys().next() {
            return Err(ModelError::UnexpectedWeight {
                path: source.to_path_buf(),
                name,
            });
        }
        Ok(Parameters { tensors: checked })
    }

    /// The parameter `name`.
    ///
    /// # Panics
    /// If there is none: names come from [`parameter_layout`], which [`Parameters::init`] and
    /// `Parameters::from_tensors` guarantee are all present.
    pub fn get(&self, name: &str) -> &Tensor<B> {
        self.tensors
            .get(name)
            .unwrap_or_else(|| panic!("the layout has no parameter '{name}'"))
    }

    /// The parameters by name, in name order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Tensor<B>)> {
        self.tensors.iter().map(|(name, t)| (name.as_str(), t))
    }

    /// The number of parameter tensors.
    pub fn len(&self) -> usize {
        self.tensors.len()
    }

    /// Whether there are none (never, for a valid configuration).
    pub fn is_empty(&self) -> bool {
        self.tensors.is_empty()
    }

    /// The number of scalar parameters.
    pub fn scalar_count(&self) -> usize {
        self.tensors.values().map(Tensor::numel).sum()
    }

    /// The same names with `f` applied to every tensor (to move them to a device, make them
    /// trainable, or replace them by an optimiser's update).
    pub fn map(&self, mut f: impl FnMut(&str, &Tensor<B>) -> Tensor<B>) -> Self {
        Parameters {
            tensors: self
                .tensors
                .iter()
                .map(|(name, t)| (name.clone(), f(name, t)))
                .collect(),
        }
    }

    /// The same values on another backend (through the host).
    pub(crate) fn to_backend<C: Backend>(&self, device: &C::Device) -> Parameters<C> {
        Parameters {
            tensors: self
                .tensors
                .iter()
                .map(|(name, t)| {
                    let host = Tensor::<C>::from_vec(t.to_vec(), &t.shape(), device)
                        .expect("a tensor's own values fill its shape");
                    (name.clone(), host)
                })
                .collect(),
        }
    }
}

/// A seed for parameter `index` from the model's `seed` (SplitMix64's finaliser), so that
/// neighbouring indices get unrelated streams.
fn mix_seed(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
