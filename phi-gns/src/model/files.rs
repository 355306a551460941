//! Model directories: `model.safetensors` (the weights, PyTorch's layout and names) and
//! `model.json` (the [`ModelSpec`]), both written atomically.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use phi_core::backend::Backend;
use phi_core::tensor::Tensor;
use phi_io::{write_all, write_atomic};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use super::{Gns, GnsKernels, ModelError, ModelSpec, Parameters};

/// The configuration file of a model directory.
pub const MODEL_FILE: &str = "model.json";
/// The weights file of a model directory.
pub const WEIGHTS_FILE: &str = "model.safetensors";

fn file_error(path: &Path, reason: impl std::fmt::Display) -> ModelError {
    ModelError::File {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Writes `model` to the directory `dir` (created if missing): the weights first, then
/// `model.json`, each atomically, so that a directory with a `model.json` always has its weights.
///
/// # Errors
/// [`ModelError::File`] when a file cannot be written.
pub fn save_model<B: GnsKernels>(dir: &Path, model: &Gns<B>) -> Result<(), ModelError> {
    std::fs::create_dir_all(dir).map_err(|e| file_error(dir, format!("cannot create: {e}")))?;
    let weights = dir.join(WEIGHTS_FILE);
    let bytes = weights_to_bytes(model.params(), &weights)?;
    write_atomic(&weights, |w| write_all(w, &bytes, &weights))?;
    let spec = dir.join(MODEL_FILE);
    let json = serde_json::to_vec_pretty(model.spec()).map_err(|e| file_error(&spec, e))?;
    write_atomic(&spec, |w| write_all(w, &json, &spec))?;
    Ok(())
}

/// The safetensors bytes of `params` (little-endian `f32`, metadata `{"format": "pt"}`).
///
/// # Errors
/// [`ModelError::File`] naming `path` if serialisation fails.
pub(crate) fn weights_to_bytes<B: Backend>(
    params: &Parameters<B>,
    path: &Path,
) -> Result<Vec<u8>, ModelError> {
    tensors_to_bytes(params.iter().map(|(n, t)| (n.to_string(), t)), path)
}

/// The safetensors bytes of named `f32` tensors (little-endian, metadata `{"format": "pt"}`).
///
/// # Errors
/// [`ModelError::File`] naming `path` if serialisation fails.
pub(crate) fn tensors_to_bytes<'a, B: Backend>(
    tensors: impl IntoIterator<Item = (String, &'a Tensor<B>)>,
    path: &Path,
) -> Result<Vec<u8>, ModelError> {
    let data: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .into_iter()
        .map(|(name, t)| {
            let bytes = t.to_vec().iter().flat_map(|v| v.to_le_bytes()).collect();
            (name, t.shape(), bytes)
        })
        .collect();
    let views = data
        .iter()
        .map(|(name, shape, bytes)| {
            TensorView::new(Dtype::F32, shape.clone(), bytes)
                .map(|view| (name.clone(), view))
                .map_err(|e| file_error(path, format!("tensor '{name}': {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let metadata = HashMap::from([("format".to_string(), "pt".to_string())]);
    safetensors::serialize(views, Some(metadata)).map_err(|e| file_error(path, e))
}

/// `model.json` of the model directory `dir`, validated.
///
/// # Errors
/// [`ModelError::File`] when it is missing or not JSON of the format, [`ModelError::Config`]
/// for a value out of range.
pub fn read_spec(dir: &Path) -> Result<ModelSpec, ModelError> {
    let path = dir.join(MODEL_FILE);
    let text = std::fs::read(&path).map_err(|e| file_error(&path, format!("cannot read: {e}")))?;
    let mut de = serde_json::Deserializer::from_slice(&text);
    let spec: ModelSpec = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| file_error(&path, format!("key '{}': {}", e.path(), e.inner())))?;
    spec.validate(&path)?;
    Ok(spec)
}

/// The model in directory `dir`, on `device` of backend `B`.
///
/// # Errors
/// As [`read_spec`], and [`ModelError::MissingWeight`], [`ModelError::UnexpectedWeight`],
/// [`ModelError::WeightShape`] or [`ModelError::File`] for weights that do not fit.
pub fn load_model<B: GnsKernels>(dir: &Path, device: &B::Device) -> Result<Gns<B>, ModelError> {
    let spec = read_spec(dir)?;
    let path = dir.join(WEIGHTS_FILE);
    let bytes = std::fs::read(&path).map_err(|e| file_error(&path, format!("cannot read: {e}")))?;
    let tensors = weights_from_bytes::<B>(&bytes, &path, device)?;
    let params = Parameters::from_tensors(&spec.config, tensors, &path)?;
    Gns::new(spec, params)
}

/// The `f32` tensors of safetensors bytes by name.
///
/// # Errors
/// [`ModelError::File`] naming `path` for bytes that are not safetensors, or a tensor that is
/// not `f32`.
pub(crate) fn weights_from_bytes<B: Backend>(
    bytes: &[u8],
    path: &Path,
    device: &B::Device,
) -> Result<BTreeMap<String, Tensor<B>>, ModelError> {
    let file = SafeTensors::deserialize(bytes).map_err(|e| file_error(path, e))?;
    let mut tensors = BTreeMap::new();
    for (name, view) in file.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(file_error(
                path,
                format!("tensor '{name}' is {:?}, not F32", view.dtype()),
            ));
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let tensor = Tensor::from_vec(values, view.shape(), device)?;
        tensors.insert(name, tensor);
    }
    Ok(tensors)
}
