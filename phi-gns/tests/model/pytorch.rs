//! Interchange with PyTorch: a phi-written model directory (`tests/fixtures/gns_reference/`)
//! loaded by a plain PyTorch GNS of the documented layout (`tests/fixtures/gns_reference.py`,
//! through `safetensors.torch.load_file` and `load_state_dict(strict=True)`), whose normalised
//! accelerations for fixed inputs are stored next to it in `expected.npz`. Every backend loads
//! the same directory and must reproduce them.
//!
//! # Regenerating the fixture
//! ```text
//! cargo test -p phi-gns --test model -- --ignored writes_the_model_of_the_pytorch_fixture
//! python phi-gns/tests/fixtures/gns_reference.py
//! ```
//! The first writes the model directory (deterministic: a seed), the second needs `torch`,
//! `safetensors` and `numpy` and writes `expected.npz`.
//!
//! # Tolerance
//! PyTorch computes in f64 from the stored f32 weights and positions, so the reference is the
//! exact maths of those values; the backends' f32 results lie within ~1e-7 of the largest
//! value (measured) on this tiny model, held to `1e-5`. The f64 host reference
//! (`reference.rs`) must agree with PyTorch to `1e-12`: two f64 implementations of the same
//! maths, written independently.

use std::path::PathBuf;

use phi_core::backend::Host;
use phi_gns::model::{Gns, GnsKernels, GraphBatch, Parameters, load_model, save_model};
use phi_io::npz::NpzReader;

use crate::common::{self, assert_close, assert_close_f64, perturbed};
use crate::reference::{Edges, HostGns};

phi_core::backend_tests!(every_backend_reproduces_pytorch);

/// The fixture's folder.
fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/gns_reference")
}

/// The inputs and PyTorch's outputs of `expected.npz`.
struct Expected {
    /// `[N, C + 1, dim]`.
    positions: Vec<f32>,
    particle_type: Vec<i64>,
    senders: Vec<i64>,
    receivers: Vec<i64>,
    /// `[N, dim]`, computed in f64.
    acceleration: Vec<f64>,
}

fn expected() -> Expected {
    let mut npz = NpzReader::open(fixture().join("expected.npz")).unwrap();
    let mut read = |name: &str| npz.read(name).unwrap();
    let positions = read("positions");
    let n = positions.shape[0];
    assert_eq!(positions.shape, vec![n, 6, 2]);
    let acceleration = read("normalised_acceleration");
    assert_eq!(acceleration.shape, vec![n, 2]);
    Expected {
        positions: positions.as_f32().unwrap().to_vec(),
        particle_type: read("particle_type").as_i64().unwrap().to_vec(),
        senders: read("senders").as_i64().unwrap().to_vec(),
        receivers: read("receivers").as_i64().unwrap().to_vec(),
        acceleration: acceleration.as_f64().unwrap().to_vec(),
    }
}

/// Writes the model of the fixture (run by hand, see the module docs).
#[test]
#[ignore = "writes the committed fixture"]
fn writes_the_model_of_the_pytorch_fixture() {
    let mut config = common::config(8, 6, 2, 2);
    config.embedding_size = 4;
    config.noise_std = 3e-4;
    let spec = common::spec(config, 2020);
    let params = Parameters::<Host>::init(&spec.config, spec.seed, &Default::default());
    let model = Gns::new(spec, perturbed(&params, 2021)).unwrap();
    save_model(&fixture(), &model).unwrap();
}

fn every_backend_reproduces_pytorch<B: GnsKernels>() {
    let device = B::default_device();
    let model = load_model::<B>(&fixture(), &device).unwrap();
    let expected = expected();
    let types = &expected.particle_type;
    assert!(types.contains(&0) && types.contains(&1));
    let batch = GraphBatch::from_host(&expected.positions, types, model.spec(), &device).unwrap();
    // PyTorch's brute-force radius graph is ours.
    assert_eq!(batch.graph().senders(), expected.senders.as_slice());
    assert_eq!(batch.graph().receivers(), expected.receivers.as_slice());
    assert!(expected.senders.len() > 3 * types.len());
    let got = model.normalised_acceleration(&batch).unwrap().to_vec();
    assert_close(
        &got,
        &expected.acceleration,
        1e-5,
        &format!("{} against PyTorch", B::name()),
    );
}

#[test]
fn the_host_reference_matches_pytorch() {
    let model = load_model::<Host>(&fixture(), &Default::default()).unwrap();
    let expected = expected();
    let host = HostGns::new(model.spec(), model.params());
    let window: Vec<f64> = expected.positions.iter().map(|&x| f64::from(x)).collect();
    let edges = Edges {
        senders: &expected.senders,
        receivers: &expected.receivers,
    };
    let got = host.normalised_acceleration(&window, &expected.particle_type, edges);
    assert_close_f64(&got, &expected.acceleration, 1e-12, "the host reference");
}
