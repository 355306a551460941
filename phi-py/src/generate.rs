//! `phi_rs.generate_dataset` and `phi_rs.merge_dataset`: `phi dataset generate` (with a
//! progress callback) and `phi dataset merge` from Python (phi-dataset's `generate` and
//! `merge`).

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Mutex;

use phi_dataset::{GenerateEvent, GenerateOptions, Shard, Split, generate, merge};
use phi_flip::SceneVariant;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::{Area, Error, detached};

/// Simulates the trajectories of a dataset of random FLIP scenes (thesis table 5.1) into
/// ``out``, as ``phi dataset generate`` does: the same files, byte for byte, for the same
/// options, whatever the thread count or shard. A folder it wrote before is continued (finished
/// trajectories are kept); ``force=True`` replaces it; a folder holding anything else is
/// refused. The GIL is released while the workers simulate.
///
/// Args:
///     out: the dataset directory.
///     split: ``"train"``, ``"valid"``, ``"test"`` or ``"all"``.
///     trajectories: per split (``None``: 2000, 20 and 10; the test split has at most 10).
///     seed: the dataset seed.
///     variant: ``"obstacles"`` or ``"walls"`` (walls as a ring of obstacle particles).
///     steps: steps per trajectory (``None``: table 5.1's 400).
///     threads: worker threads (``None``: one per core).
///     shard: ``(k, n)``: only the trajectories ``i`` with ``i mod n = k``.
///     resume, prune, force: as ``phi dataset generate``'s flags.
///     progress: called as ``progress(done, total)`` after each trajectory written (from the
///         calling thread's interpreter, with the GIL); an exception it raises stops the run,
///         keeping the finished files, and is raised again.
///
/// Returns:
///     A dict: ``written``, ``skipped``, ``remade``, ``seconds``.
#[pyfunction]
#[pyo3(signature = (
    out, split = "all", trajectories = None, seed = 0, variant = "obstacles", steps = None,
    threads = None, shard = (0, 1), resume = false, prune = false, force = false, progress = None
))]
#[allow(clippy::too_many_arguments)]
pub fn generate_dataset(
    py: Python<'_>,
    out: PathBuf,
    split: &str,
    trajectories: Option<usize>,
    seed: u64,
    variant: &str,
    steps: Option<usize>,
    threads: Option<usize>,
    shard: (usize, usize),
    resume: bool,
    prune: bool,
    force: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Py<PyDict>> {
    let argument = |what: &str, reason: String| -> PyErr {
        Error::argument(Area::Dataset, format!("generate_dataset: {what}"), reason).into()
    };
    let mut options = GenerateOptions::new(out);
    options.splits = match split {
        "all" => Split::ALL.to_vec(),
        name => match Split::ALL.iter().find(|s| s.name() == name) {
            Some(s) => vec![*s],
            None => {
                return Err(argument(
                    "split",
                    format!("'{name}' is not 'train', 'valid', 'test' or 'all'"),
                ));
            }
        },
    };
    options.trajectories = trajectories;
    options.seed = seed;
    options.variant = variant
        .parse::<SceneVariant>()
        .map_err(|e| argument("variant", e))?;
    if let Some(steps) = steps {
        options.params.steps = steps;
    }
    options.threads = threads;
    let (index, count) = shard;
    if count == 0 || index >= count {
        return Err(argument(
            "shard",
            format!("({index}, {count}): expected (k, n) with 0 <= k < n"),
        ));
    }
    options.shard = Shard { index, count };
    (options.resume, options.prune, options.force) = (resume, prune, force);

    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let (mut done, mut total) = (0usize, 0usize);
    let summary = detached(py, || {
        let report = |event: GenerateEvent| -> ControlFlow<()> {
            match event {
                GenerateEvent::Planned { trajectories, .. } => {
                    total = trajectories;
                    return ControlFlow::Continue(());
                }
                GenerateEvent::Written { .. } => done += 1,
            }
            let Some(callback) = &progress else {
                return ControlFlow::Continue(());
            };
            Python::attach(|py| match callback.call1(py, (done, total)) {
                Ok(_) => ControlFlow::Continue(()),
                Err(e) => {
                    *raised.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                    ControlFlow::Break(())
                }
            })
        };
        Ok(generate(&options, report)?)
    });
    if let Some(e) = raised.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    let summary = summary?;
    let dict = PyDict::new(py);
    dict.set_item("written", summary.written)?;
    dict.set_item("skipped", summary.skipped)?;
    dict.set_item("remade", summary.remade)?;
    dict.set_item("seconds", summary.seconds)?;
    Ok(dict.unbind())
}

/// Joins shard directories that ``generate_dataset(shard=(k, n))`` wrote with one configuration
/// into the dataset ``out``, as ``phi dataset merge`` does: the trajectory files are hard-linked
/// (copied across file systems), and the dataset equals the one ``generate_dataset`` writes
/// without shards, byte for byte. A dataset already at ``out`` is replaced only with
/// ``force=True``.
///
/// Args:
///     out: the dataset directory (not one of the shards).
///     shards: the shard directories, all ``n`` of them, in any order.
///     force: replace a dataset at ``out``.
///
/// Returns:
///     A dict: ``counts`` (trajectories per split) and ``files`` (files linked or copied).
///
/// Raises:
///     DatasetError: shards of different configurations, a missing trajectory, an output that
///         is a shard or holds something else.
#[pyfunction]
#[pyo3(signature = (out, shards, force = false))]
pub fn merge_dataset(
    py: Python<'_>,
    out: PathBuf,
    shards: Vec<PathBuf>,
    force: bool,
) -> PyResult<Py<PyDict>> {
    let summary = detached(py, || Ok(merge(&out, &shards, force)?))?;
    let dict = PyDict::new(py);
    dict.set_item("counts", summary.counts)?;
    dict.set_item("files", summary.files)?;
    Ok(dict.unbind())
}
