//! The mean of several models' weights: checkpoint averaging.
//!
//! Late in a run at a low learning rate the weights wander about one basin, and two checkpoints a
//! few thousand steps apart can differ on held-out rollouts by more than the steps between them
//! improved either. The mean of such checkpoints' weights (stochastic weight averaging, Izmailov
//! et al. 2018, over checkpoints rather than every step) sits nearer the middle of that basin.
//! It only makes sense for models that share a configuration and normalisation (checkpoints of
//! one run, or runs that started from one model), which [`average_models`] checks.

use std::collections::BTreeMap;
use std::path::Path;

use super::{Gns, GnsKernels, ModelError, ModelSpec, Parameters};
use phi_core::tensor::Tensor;

/// The model whose every weight is the mean of that weight over `models`, accumulated in `f64`
/// and rounded once. Its [`ModelSpec`](super::ModelSpec) is the first model's; the others must
/// have the same configuration, normalisation, bounds, particle types and kinematic types.
///
/// # Errors
/// [`ModelError::Input`] for no models, or for one whose specification differs from the
/// first's, naming the key.
pub fn average_models<B: GnsKernels>(models: &[&Gns<B>]) -> Result<Gns<B>, ModelError> {
    let Some(first) = models.first() else {
        return Err(ModelError::Input {
            what: "models to average",
            reason: "none given".into(),
        });
    };
    let spec = first.spec();
    let reference = comparable(spec);
    for (i, model) in models.iter().enumerate().skip(1) {
        if let Some(key) = difference("", &reference, &comparable(model.spec())) {
            return Err(ModelError::Input {
                what: "models to average",
                reason: format!(
                    "model {} differs from model 1 in model.json key '{key}'; only models of \
                     one configuration and normalisation can be averaged",
                    i + 1
                ),
            });
        }
    }
    let n = models.len() as f64;
    let mut tensors = BTreeMap::new();
    for (name, tensor) in first.params().iter() {
        let mut sum: Vec<f64> = tensor.to_vec().iter().map(|v| f64::from(*v)).collect();
        for model in &models[1..] {
            for (s, v) in sum.iter_mut().zip(model.params().get(name).to_vec()) {
                *s += f64::from(v);
            }
        }
        let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        let averaged = Tensor::from_vec(mean, &tensor.shape(), &tensor.device())?;
        tensors.insert(name.to_string(), averaged);
    }
    let params = Parameters::from_tensors(&spec.config, tensors, Path::new("the average"))?;
    Gns::new(spec.clone(), params)
}

/// The `model.json` of `spec` without what may differ between models averaged: the seed of
/// the initial weights and the provenance.
fn comparable(spec: &ModelSpec) -> serde_json::Value {
    let mut value = serde_json::to_value(spec).unwrap_or_default();
    if let Some(object) = value.as_object_mut() {
        object.remove("seed");
        object.remove("provenance");
    }
    value
}

/// The first key (dotted, below `key`) where `a` and `b` differ, if any.
fn difference(key: &str, a: &serde_json::Value, b: &serde_json::Value) -> Option<String> {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => x
            .keys()
            .chain(y.keys().filter(|k| !x.contains_key(*k)))
            .find_map(|k| {
                let here = if key.is_empty() {
                    k.clone()
                } else {
                    format!("{key}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(u), Some(v)) => difference(&here, u, v),
                    _ => Some(here),
                }
            }),
        _ => (a != b).then(|| key.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Metadata;
    use crate::model::GnsConfig;
    use phi_core::backend::Host;

    fn spec(seed: u64) -> ModelSpec {
        let mut metadata = Metadata::new(2);
        metadata.vel_std = vec![1e-3; 2];
        metadata.acc_std = vec![1e-4; 2];
        let mut config = GnsConfig::thesis(2);
        config.latent_size = 8;
        config.hidden_size = 8;
        config.message_passing_steps = 2;
        ModelSpec::for_dataset(&metadata, config, seed)
    }

    fn model(seed: u64) -> Gns<Host> {
        Gns::init(spec(seed), &Default::default()).unwrap()
    }

    #[test]
    fn the_average_is_the_mean_of_every_weight() {
        let (a, b, c) = (model(1), model(2), model(3));
        let mean = average_models(&[&a, &b, &c]).unwrap();
        for (name, t) in mean.params().iter() {
            let values = [a.params(), b.params(), c.params()].map(|p| p.get(name).to_vec());
            for (k, v) in t.to_vec().iter().enumerate() {
                let expected = (values.iter().map(|w| f64::from(w[k])).sum::<f64>() / 3.0) as f32;
                assert_eq!(*v, expected, "{name}[{k}]");
            }
        }
        assert_eq!(mean.spec(), a.spec());
    }

    #[test]
    fn one_model_averages_to_itself() {
        let a = model(7);
        let mean = average_models(&[&a, &a]).unwrap();
        for (name, t) in mean.params().iter() {
            assert_eq!(t.to_vec(), a.params().get(name).to_vec(), "{name}");
        }
    }

    #[test]
    fn models_of_other_sizes_or_statistics_are_refused_naming_the_key() {
        let a = model(1);
        let mut wide = spec(1);
        wide.config.latent_size = 16;
        let wide = Gns::<Host>::init(wide, &Default::default()).unwrap();
        let err = average_models(&[&a, &wide]).unwrap_err().to_string();
        assert!(err.contains("'config.latent_size'"), "{err}");
        let mut other = spec(1);
        other.normalisation.acc_std[1] = 2.0;
        let other = Gns::<Host>::init(other, &Default::default()).unwrap();
        let err = average_models(&[&a, &other]).unwrap_err().to_string();
        assert!(err.contains("'normalisation.acc_std'"), "{err}");
        assert!(average_models::<Host>(&[]).is_err());
    }
}
