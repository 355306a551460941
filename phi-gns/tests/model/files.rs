//! Model directories: `save_model` and `load_model` round-trip exactly, and every way a
//! directory can be wrong is an error that names the file, the tensor or key, and both values
//! where two disagree.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use phi_core::backend::Host;
use phi_gns::data::Metadata;
use phi_gns::model::{
    Gns, GnsKernels, GraphBatch, MODEL_FILE, ModelError, Parameters, WEIGHTS_FILE, load_model,
    read_spec, save_model,
};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use crate::common::{self, Rng, bits, liquid_over_obstacles, perturbed, temp_dir};

phi_core::backend_tests!(save_then_load_round_trips_exactly);

/// A small model with LayerNorms off their initial values and a provenance.
fn model<B: GnsKernels>() -> Gns<B> {
    let device = B::default_device();
    let mut spec = common::spec(common::config(8, 6, 2, 2), 77);
    spec.provenance = serde_json::json!({"command": "phi train", "epochs": 3});
    let params = perturbed(&Parameters::init(&spec.config, spec.seed, &device), 4);
    Gns::new(spec, params).unwrap()
}

fn save_then_load_round_trips_exactly<B: GnsKernels>() {
    let dir = temp_dir(&format!("round-trip-{}", B::name()));
    let device = B::default_device();
    let saved = model::<B>();
    save_model(&dir, &saved).unwrap();
    let loaded = load_model::<B>(&dir, &device).unwrap();
    assert_eq!(loaded.spec(), saved.spec());
    let names = |m: &Gns<B>| {
        m.params()
            .iter()
            .map(|(n, _)| n.to_string())
            .collect::<Vec<_>>()
    };
    assert_eq!(names(&loaded), names(&saved));
    for ((name, a), (_, b)) in loaded.params().iter().zip(saved.params().iter()) {
        assert_eq!(a.shape(), b.shape(), "{name}");
        assert_eq!(bits(&a.to_vec()), bits(&b.to_vec()), "{name}");
    }
    let scene = liquid_over_obstacles(&mut Rng::new(1), 3, 3, 2, [0.3, 0.3], 6);
    let batch = GraphBatch::from_host(&scene.window, &scene.types, saved.spec(), &device).unwrap();
    assert_eq!(
        bits(&loaded.normalised_acceleration(&batch).unwrap().to_vec()),
        bits(&saved.normalised_acceleration(&batch).unwrap().to_vec())
    );
    // The file is PyTorch's: safetensors with the "pt" format tag and f32 tensors of the
    // layout's names and shapes.
    let bytes = std::fs::read(dir.join(WEIGHTS_FILE)).unwrap();
    let (_, header) = SafeTensors::read_metadata(&bytes).unwrap();
    assert_eq!(
        header.metadata().as_ref().and_then(|m| m.get("format")),
        Some(&"pt".to_string())
    );
    let file = SafeTensors::deserialize(&bytes).unwrap();
    for (name, t) in saved.params().iter() {
        let view = file.tensor(name).unwrap();
        assert_eq!(view.dtype(), Dtype::F32);
        assert_eq!(view.shape(), t.shape().as_slice());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A directory with a saved model of [`model`] on the host.
fn saved(test: &str) -> (PathBuf, Gns<Host>) {
    let dir = temp_dir(test);
    let model = model::<Host>();
    save_model(&dir, &model).unwrap();
    (dir, model)
}

/// Writes `model.safetensors` of `tensors` (name, dtype, shape, little-endian bytes).
fn write_weights(dir: &Path, tensors: &[(String, Dtype, Vec<usize>, Vec<u8>)]) {
    let views: Vec<(String, TensorView<'_>)> = tensors
        .iter()
        .map(|(name, dtype, shape, data)| {
            (
                name.clone(),
                TensorView::new(*dtype, shape.clone(), data).unwrap(),
            )
        })
        .collect();
    let metadata = HashMap::from([("format".to_string(), "pt".to_string())]);
    let bytes = safetensors::serialize(views, Some(metadata)).unwrap();
    std::fs::write(dir.join(WEIGHTS_FILE), bytes).unwrap();
}

/// The tensors of `model` as safetensors entries.
fn entries(model: &Gns<Host>) -> Vec<(String, Dtype, Vec<usize>, Vec<u8>)> {
    model
        .params()
        .iter()
        .map(|(name, t)| {
            let bytes = t.to_vec().iter().flat_map(|v| v.to_le_bytes()).collect();
            (name.to_string(), Dtype::F32, t.shape(), bytes)
        })
        .collect()
}

fn load_error(dir: &Path) -> ModelError {
    load_model::<Host>(dir, &Default::default()).expect_err("an invalid model directory loads")
}

/// Asserts that the message of `error` contains each of `parts`.
fn assert_names(error: &ModelError, parts: &[&str]) {
    let message = error.to_string();
    for part in parts {
        assert!(message.contains(part), "'{message}' does not name '{part}'");
    }
}

#[test]
fn a_weight_of_the_wrong_shape_is_named_with_both_shapes() {
    let (dir, model) = saved("wrong-shape");
    let mut tensors = entries(&model);
    let name = "processor.1.edge.2.weight";
    let entry = tensors.iter_mut().find(|t| t.0 == name).unwrap();
    // The layout's [latent 8, hidden 6]; the file has [8, 7].
    assert_eq!(entry.2, vec![8, 6]);
    entry.2 = vec![8, 7];
    entry.3 = vec![0; 8 * 7 * 4];
    write_weights(&dir, &tensors);
    let error = load_error(&dir);
    match &error {
        ModelError::WeightShape {
            path,
            name: n,
            expected,
            found,
        } => {
            assert_eq!(path, &dir.join(WEIGHTS_FILE));
            assert_eq!(n, name);
            assert_eq!(expected, &[8, 6]);
            assert_eq!(found, &[8, 7]);
        }
        other => panic!("{other:?}"),
    }
    assert_names(&error, &[WEIGHTS_FILE, name, "[8, 6]", "[8, 7]"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_weight_is_named_with_its_shape() {
    let (dir, model) = saved("missing");
    let mut tensors = entries(&model);
    tensors.retain(|t| t.0 != "encoder.edge.ln.bias");
    write_weights(&dir, &tensors);
    let error = load_error(&dir);
    assert!(
        matches!(&error, ModelError::MissingWeight { name, shape, .. }
            if name == "encoder.edge.ln.bias" && shape == &[8]),
        "{error:?}"
    );
    assert_names(&error, &[WEIGHTS_FILE, "encoder.edge.ln.bias", "[8]"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_unexpected_weight_is_named() {
    let (dir, model) = saved("unexpected");
    let mut tensors = entries(&model);
    // A third processor step, which a model of two steps does not have.
    tensors.push((
        "processor.2.node.0.bias".into(),
        Dtype::F32,
        vec![6],
        vec![0; 24],
    ));
    write_weights(&dir, &tensors);
    let error = load_error(&dir);
    assert!(
        matches!(&error, ModelError::UnexpectedWeight { name, .. } if name == "processor.2.node.0.bias"),
        "{error:?}"
    );
    assert_names(&error, &[WEIGHTS_FILE, "processor.2.node.0.bias"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_weight_that_is_not_f32_is_named_with_its_dtype() {
    let (dir, model) = saved("dtype");
    let mut tensors = entries(&model);
    let entry = tensors
        .iter_mut()
        .find(|t| t.0 == "decoder.0.bias")
        .unwrap();
    entry.1 = Dtype::F64;
    entry.3 = model
        .params()
        .get("decoder.0.bias")
        .to_vec()
        .iter()
        .flat_map(|&v| f64::from(v).to_le_bytes())
        .collect();
    write_weights(&dir, &tensors);
    let error = load_error(&dir);
    assert!(matches!(&error, ModelError::File { .. }), "{error:?}");
    assert_names(&error, &[WEIGHTS_FILE, "decoder.0.bias", "F64", "F32"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn truncated_or_garbage_weights_are_file_errors() {
    let (dir, _) = saved("truncated");
    let path = dir.join(WEIGHTS_FILE);
    let bytes = std::fs::read(&path).unwrap();
    let garbage: Vec<u8> = b"\x10\x00\x00\x00\x00\x00\x00\x00{not json at all}".to_vec();
    let cases: [(&str, Vec<u8>); 4] = [
        ("half the file", bytes[..bytes.len() / 2].to_vec()),
        ("all but the last byte", bytes[..bytes.len() - 1].to_vec()),
        ("garbage", garbage),
        ("empty", Vec::new()),
    ];
    for (what, contents) in cases {
        std::fs::write(&path, contents).unwrap();
        let error = load_error(&dir);
        assert!(
            matches!(&error, ModelError::File { path: p, .. } if p == &path),
            "{what}: {error:?}"
        );
        assert_names(&error, &[WEIGHTS_FILE]);
    }
    std::fs::remove_file(&path).unwrap();
    let error = load_error(&dir);
    assert!(matches!(&error, ModelError::File { .. }), "{error:?}");
    assert_names(&error, &[WEIGHTS_FILE, "cannot read"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Rewrites `model.json` of `dir` with `edit` applied to its JSON and returns the error of
/// reading it.
fn spec_error(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) -> ModelError {
    let path = dir.join(MODEL_FILE);
    let original = std::fs::read(&path).unwrap();
    let mut json: serde_json::Value = serde_json::from_slice(&original).unwrap();
    edit(&mut json);
    std::fs::write(&path, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    let error = read_spec(dir).expect_err("an invalid model.json reads");
    // load_model reports the same.
    assert_eq!(load_error(dir).to_string(), error.to_string());
    std::fs::write(&path, original).unwrap();
    error
}

#[test]
fn model_json_with_an_unknown_key_is_rejected_naming_it() {
    let (dir, _) = saved("unknown-key");
    let error = spec_error(&dir, |json| {
        json["config"]["latent_sise"] = 8.into();
    });
    assert!(matches!(&error, ModelError::File { .. }), "{error:?}");
    assert_names(&error, &[MODEL_FILE, "config.latent_sise"]);
    let error = spec_error(&dir, |json| {
        json["comment"] = "hello".into();
    });
    assert_names(&error, &[MODEL_FILE, "comment"]);
    // A missing key and a value of the wrong type name the key too.
    let error = spec_error(&dir, |json| {
        json["config"]
            .as_object_mut()
            .unwrap()
            .remove("hidden_size");
    });
    assert_names(&error, &[MODEL_FILE, "config", "hidden_size"]);
    let error = spec_error(&dir, |json| {
        json["config"]["latent_size"] = "big".into();
    });
    assert_names(&error, &[MODEL_FILE, "config.latent_size", "big"]);
    // The untouched file still reads.
    read_spec(&dir).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn model_json_with_a_bad_value_names_the_key_and_the_value() {
    let (dir, model) = saved("bad-value");
    // The reason names the value found and what is needed (the path, which holds digits, is
    // left out of the search).
    let config_error = |error: &ModelError, expected_key: &str, parts: &[&str]| match error {
        ModelError::Config { path, key, reason } => {
            assert_eq!(path, &dir.join(MODEL_FILE));
            assert_eq!(key, expected_key);
            for part in parts {
                assert!(
                    reason.contains(part),
                    "{key}: '{reason}' does not name '{part}'"
                );
            }
            assert_names(error, &[MODEL_FILE, expected_key]);
        }
        other => panic!("{other:?}"),
    };

    let error = spec_error(&dir, |json| json["config"]["latent_size"] = 0.into());
    config_error(&error, "config.latent_size", &["0", "at least 1"]);

    let error = spec_error(&dir, |json| {
        json["bounds"] = serde_json::json!([[0.9, 0.1], [0.1, 0.9]]);
    });
    config_error(&error, "bounds", &["[0.9, 0.1]", "min < max"]);

    let error = spec_error(&dir, |json| {
        json["normalisation"]["vel_std"] = serde_json::json!([1e-3, 1e-3, 1e-3]);
    });
    config_error(&error, "normalisation.vel_std", &["3 entries", "2D"]);

    let error = spec_error(&dir, |json| {
        json["normalisation"]["acc_std"] = serde_json::json!([1e-4, -1e-4]);
    });
    config_error(&error, "normalisation.acc_std", &["-0.0001", "≥ 0"]);

    let error = spec_error(&dir, |json| {
        json["config"]["boundary_horizon"] = (-2.0).into()
    });
    config_error(&error, "config.boundary_horizon", &["-2", "positive"]);

    let error = spec_error(&dir, |json| json["config"]["dim"] = 4.into());
    config_error(&error, "config.dim", &["4", "2 or 3"]);

    let error = spec_error(&dir, |json| json["format_version"] = 2.into());
    config_error(&error, "format_version", &["2", "1"]);

    let error = spec_error(&dir, |json| {
        json["particle_types"] = serde_json::json!({"0": "obstacle", "1": "liquid", "2": "wall"});
    });
    config_error(&error, "particle_types", &["3", "2"]);
    assert_eq!(read_spec(&dir).unwrap(), *model.spec());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_dataset_names_what_differs_with_both_values() {
    let model = model::<Host>();
    let spec = model.spec();
    let path = Path::new("dataset/metadata.json");
    let mismatch = |metadata: &Metadata, key: &str, model: &str, dataset: &str| {
        let error = spec.check_dataset(metadata, path).expect_err(key);
        match &error {
            ModelError::DatasetMismatch {
                path: p,
                key: k,
                model: m,
                dataset: d,
            } => {
                assert_eq!(p, path);
                assert_eq!(k, key);
                assert_eq!(m, model);
                assert_eq!(d, dataset);
            }
            other => panic!("{other:?}"),
        }
        assert_names(&error, &["dataset/metadata.json", key, model, dataset]);
    };

    // The training dataset fits; so does one with other statistics (test data).
    let metadata = common::metadata();
    spec.check_dataset(&metadata, path).unwrap();
    let mut other_statistics = metadata.clone();
    other_statistics.vel_std = vec![5e-3, 5e-3];
    other_statistics.acc_mean = vec![0.0, -1e-3];
    spec.check_dataset(&other_statistics, path).unwrap();

    mismatch(&Metadata::new(3), "dim", "2", "3");

    let mut other_bounds = metadata.clone();
    other_bounds.bounds = vec![[0.0, 1.0], [0.1, 0.9]];
    mismatch(
        &other_bounds,
        "bounds",
        "[[0.1, 0.9], [0.1, 0.9]]",
        "[[0.0, 1.0], [0.1, 0.9]]",
    );
    // Without boundary features the bounds do not matter.
    let mut unbounded = spec.clone();
    unbounded.config.boundary_features = false;
    unbounded.check_dataset(&other_bounds, path).unwrap();

    let mut other_types = metadata.clone();
    other_types
        .particle_types
        .insert("2".to_string(), "wall".to_string());
    mismatch(
        &other_types,
        "particle_types",
        r#"{"0": "obstacle", "1": "liquid"}"#,
        r#"{"0": "obstacle", "1": "liquid", "2": "wall"}"#,
    );
}
