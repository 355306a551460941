//! `phi_rs.Dataset`: a dataset that `phi dataset generate` wrote, read by phi-gns's reader.

use std::collections::VecDeque;
use std::path::PathBuf;

use phi_gns::train::{BatchConfig, BatchSource, HostExample, WindowSpec};
use pyo3::prelude::*;

use crate::arrays::to_numpy;
use crate::error::{Area, Error, detached};

/// A GNS dataset directory (``metadata.json`` and one ``.npz`` per trajectory), read with the
/// checks of ``phi``'s own reader (CRC-32 of every member, index and seed of every file).
///
/// ``ds[split, i]`` is trajectory ``i`` of ``split``: ``(positions, particle_type)``, float32
/// ``[frames, N, d]`` in stored units and int64 ``[N]`` (0 = obstacle, 1 = liquid). A negative
/// ``i`` counts from the end.
///
/// Raises:
///     DatasetError: a directory without a valid ``metadata.json``, an unknown split, an index
///         out of range or a damaged file (the message names the file).
#[pyclass(frozen, module = "phi_rs")]
pub struct Dataset {
    inner: phi_gns::data::Dataset,
}

#[pymethods]
impl Dataset {
    /// Opens the dataset at ``path`` and checks its ``metadata.json``.
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || Ok(phi_gns::data::Dataset::open(&path)?))?;
        Ok(Dataset { inner })
    }

    /// The dataset's directory.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.dir().to_path_buf()
    }

    /// The content of ``metadata.json`` as a dict.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(self.inner.metadata()).map_err(|e| {
            Error::argument(Area::Dataset, "metadata", format!("cannot be written: {e}"))
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The names of the splits, in the order of ``metadata.json``.
    #[getter]
    fn splits(&self) -> Vec<String> {
        self.inner.metadata().splits.keys().cloned().collect()
    }

    /// The number of trajectories in ``split``.
    #[pyo3(signature = (split = "train"))]
    fn len(&self, split: &str) -> PyResult<usize> {
        Ok(self.inner.split_len(split).map_err(Error::from)?)
    }

    /// ``len(ds)``: the number of trajectories in all splits together.
    fn __len__(&self) -> usize {
        self.inner.metadata().splits.values().sum()
    }

    /// The training windows of ``split`` as ``phi train`` cuts them: ``((window,
    /// particle_type), target)`` with ``window`` the ``C + 1`` input frames float32 ``[C + 1,
    /// N, d]`` (``C = input_velocities``, oldest first, ending at frame ``t``), the types int64
    /// ``[N]`` and ``target`` frame ``t + 1``, float32 ``[N, d]``; stored units, no noise.
    ///
    /// With ``seed=None``, every valid window once, trajectory by trajectory and ``t`` from
    /// ``C`` up (``len()`` of the iterator is their number). With a ``seed``, the windows the
    /// trainer draws with that seed: ``batch_size`` per step, uniform over all valid windows,
    /// from step ``start_step`` on, for ``steps`` steps or without end; windows
    /// ``k·batch_size ..`` are step ``start_step + k``'s batch.
    ///
    /// Raises:
    ///     DatasetError: an unknown split, trajectories shorter than a window, a damaged file.
    #[pyo3(signature = (split = "train", input_velocities = 5, seed = None, batch_size = 2, start_step = 0, steps = None))]
    #[allow(clippy::too_many_arguments)] // Python's keyword arguments
    fn windows(
        &self,
        py: Python<'_>,
        split: &str,
        input_velocities: usize,
        seed: Option<u64>,
        batch_size: usize,
        start_step: u64,
        steps: Option<u64>,
    ) -> PyResult<Windows> {
        if batch_size == 0 {
            return Err(Error::argument(
                Area::Dataset,
                "windows: batch_size",
                "must be at least 1",
            )
            .into());
        }
        let config = BatchConfig::new(
            seed.unwrap_or(0),
            batch_size,
            WindowSpec::one_step(input_velocities),
        );
        let dataset = &self.inner;
        let source = detached(py, || Ok(BatchSource::new(dataset, split, &config)?))?;
        let order = match seed {
            None => Order::All { next: 0 },
            Some(_) => Order::Drawn {
                step: start_step,
                end: steps.map(|s| start_step.saturating_add(s)),
                batch_size,
            },
        };
        Ok(Windows {
            source,
            order,
            pending: VecDeque::new(),
            input_velocities,
        })
    }

    /// Trajectory ``i`` of ``split`` as ``(positions, particle_type)``.
    fn __getitem__<'py>(
        &self,
        py: Python<'py>,
        key: (String, i64),
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (split, index) = key;
        let count = self.inner.split_len(&split).map_err(Error::from)?;
        let resolved = if index < 0 {
            (count as i64).checked_add(index)
        } else {
            Some(index)
        };
        let index = match resolved {
            Some(i) if i >= 0 && (i as u64) < count as u64 => i as usize,
            _ => {
                return Err(Error::argument(
                    Area::Dataset,
                    format!("{}: split '{split}'", self.inner.dir().display()),
                    format!("index {index} is out of range for its {count} trajectories"),
                )
                .into());
            }
        };
        let dataset = &self.inner;
        let (trajectory, _) = detached(py, || Ok(dataset.read_with_stats(&split, index)?))?;
        let shape = [trajectory.frames, trajectory.particles, trajectory.dim];
        let positions = to_numpy(py, &shape, trajectory.position)?.into_any();
        let n = trajectory.particle_type.len();
        let types = to_numpy(py, &[n], trajectory.particle_type)?.into_any();
        Ok((positions, types))
    }

    fn __repr__(&self) -> String {
        let splits: Vec<String> = self
            .inner
            .metadata()
            .splits
            .iter()
            .map(|(name, count)| format!("{name}={count}"))
            .collect();
        format!(
            "Dataset('{}', {})",
            self.inner.dir().display(),
            splits.join(", ")
        )
    }
}

/// Which windows a [`Windows`] iterator hands out.
enum Order {
    /// Every valid window once, in the sampler's order; `next` is the index of the next.
    All { next: usize },
    /// The trainer's draws: the batches of steps `step ..end` (no end: endless).
    Drawn {
        step: u64,
        end: Option<u64>,
        batch_size: usize,
    },
}

/// An iterator over the training windows of a split (``Dataset.windows``): each item is
/// ``((window [C + 1, N, d], particle_type [N]), target [N, d])``.
#[pyclass(module = "phi_rs")]
pub struct Windows {
    source: BatchSource,
    order: Order,
    /// Examples of the current step not yet handed out.
    pending: VecDeque<HostExample>,
    input_velocities: usize,
}

/// The item of `example`: `((window, particle_type), target)`.
type WindowItem<'py> = ((Bound<'py, PyAny>, Bound<'py, PyAny>), Bound<'py, PyAny>);

impl Windows {
    /// The next example, or `None` at the end.
    fn next_example(&mut self) -> Result<Option<HostExample>, Error> {
        match &mut self.order {
            Order::All { next } => {
                let Some(window) = self.source.sampler().window(*next) else {
                    return Ok(None);
                };
                *next += 1;
                Ok(Some(self.source.example(window)?))
            }
            Order::Drawn { step, end, .. } => {
                if self.pending.is_empty() {
                    if end.is_some_and(|end| *step >= end) {
                        return Ok(None);
                    }
                    let batch = self.source.batch(*step)?;
                    *step += 1;
                    self.pending.extend(batch.examples);
                }
                Ok(self.pending.pop_front())
            }
        }
    }
}

#[pymethods]
impl Windows {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Option<WindowItem<'py>>> {
        let Some(example) = detached(py, || self.next_example())? else {
            return Ok(None);
        };
        let (n, d) = (example.particles, example.dim);
        let inputs = (self.input_velocities + 1) * n * d;
        let mut frames = example.frames;
        let target = frames.split_off(inputs);
        let window = to_numpy(py, &[self.input_velocities + 1, n, d], frames)?.into_any();
        let types = to_numpy(py, &[n], example.particle_type)?.into_any();
        let target = to_numpy(py, &[n, d], target)?.into_any();
        Ok(Some(((window, types), target)))
    }

    /// The number of windows still to come: all valid windows left, or the draws of the steps
    /// left; ``TypeError`` for an endless iterator.
    fn __len__(&self) -> PyResult<usize> {
        match &self.order {
            Order::All { next } => Ok(self.source.sampler().windows().saturating_sub(*next)),
            Order::Drawn {
                step,
                end: Some(end),
                batch_size,
            } => Ok((end.saturating_sub(*step) as usize) * batch_size + self.pending.len()),
            Order::Drawn { end: None, .. } => Err(pyo3::exceptions::PyTypeError::new_err(
                "Dataset.windows(seed=...) without steps is endless: it has no len()",
            )),
        }
    }
}
