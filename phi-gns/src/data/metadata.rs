//! `metadata.json`: DeepMind's keys plus ours.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{DataError, LIQUID, OBSTACLE, TrajectoryStats};

/// The name of the metadata file in a dataset directory.
pub const METADATA_FILE: &str = "metadata.json";
/// The value of [`Metadata::format`].
pub const FORMAT: &str = "phi-dataset";
/// The value of [`Metadata::format_version`] this code reads and writes.
pub(crate) const FORMAT_VERSION: u32 = 1;

/// How the domain boundary appears in a dataset (thesis section 5.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    /// Obstacles are particles, the domain walls are not (the model is given the distance to
    /// the walls).
    Obstacles,
    /// The domain walls are also obstacle particles (a one-cell ring), model `1snb`.
    WallsAsParticles,
}

/// The content of `metadata.json`.
///
/// The first nine keys are those of DeepMind's `learning_to_simulate` datasets, with their
/// meaning, so that its training code reads ours; the rest are ours. Per-component lists have
/// `dim` entries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metadata {
    /// `[min, max]` of the stored positions per axis (`[[0.1, 0.9], [0.1, 0.9]]` in 2D).
    pub bounds: Vec<[f64; 2]>,
    /// Steps per trajectory; files hold `sequence_length + 1` frames.
    pub sequence_length: usize,
    /// The GNS connectivity radius in stored units (0.03).
    pub default_connectivity_radius: f64,
    /// The number of spatial dimensions.
    pub dim: usize,
    /// The time step between frames in seconds (0.05).
    pub dt: f64,
    /// Mean velocity per component over the training split (velocity = difference of
    /// consecutive stored positions, not divided by `dt`; liquid particles only).
    pub vel_mean: Vec<f64>,
    /// Population standard deviation of the velocity per component.
    pub vel_std: Vec<f64>,
    /// Mean acceleration (second difference of stored positions) per component.
    pub acc_mean: Vec<f64>,
    /// Population standard deviation of the acceleration per component.
    pub acc_std: Vec<f64>,
    /// Always [`FORMAT`] (`"phi-dataset"`).
    pub format: String,
    /// Always `FORMAT_VERSION`.
    pub format_version: u32,
    /// The number of trajectories in each split, e.g. `{"train": 2000, "valid": 20}`.
    pub splits: BTreeMap<String, usize>,
    /// The legend of `particle_type`: `{"0": "obstacle", "1": "liquid"}`.
    pub particle_types: BTreeMap<String, String>,
    /// `x_stored = x_cells * position_scale + position_offset` (1/40).
    pub position_scale: f64,
    /// See [`Metadata::position_scale`] (0.1).
    pub position_offset: f64,
    /// How the domain boundary appears.
    pub variant: Variant,
    /// The generator's configuration, free-form (the generator fills it).
    #[serde(default)]
    pub generator: serde_json::Value,
    /// The base seed of each split drawn at random (splits made by hand have none); each
    /// trajectory's own seed is in its file.
    #[serde(default)]
    pub seeds: BTreeMap<String, u64>,
}

impl Metadata {
    /// The thesis' defaults for a `dim`-dimensional dataset with no splits yet: bounds
    /// `[0.1, 0.9]` per axis, 400 steps of 0.05 s, connectivity radius 0.03, scale 1/40 and
    /// offset 0.1, zero statistics, variant [`Variant::Obstacles`].
    pub fn new(dim: usize) -> Self {
        Metadata {
            bounds: vec![[0.1, 0.9]; dim],
            sequence_length: 400,
            default_connectivity_radius: 0.03,
            dim,
            dt: 0.05,
            vel_mean: vec![0.0; dim],
            vel_std: vec![0.0; dim],
            acc_mean: vec![0.0; dim],
            acc_std: vec![0.0; dim],
            format: FORMAT.to_string(),
            format_version: FORMAT_VERSION,
            splits: BTreeMap::new(),
            particle_types: BTreeMap::from([
                (OBSTACLE.to_string(), "obstacle".to_string()),
                (LIQUID.to_string(), "liquid".to_string()),
            ]),
            position_scale: 1.0 / 40.0,
            position_offset: 0.1,
            variant: Variant::Obstacles,
            generator: serde_json::Value::Null,
            seeds: BTreeMap::new(),
        }
    }

    /// Sets `vel_mean`, `vel_std`, `acc_mean` and `acc_std` from statistics (normally those of
    /// the training split). Fails when their dimension is not [`Metadata::dim`].
    pub fn set_statistics(&mut self, stats: &TrajectoryStats) -> Result<(), DataError> {
        if stats.velocity.dim() != self.dim || stats.acceleration.dim() != self.dim {
            return Err(DataError::InvalidInput {
                what: "metadata statistics",
                reason: format!(
                    "statistics of {} components for a {}D dataset",
                    stats.velocity.dim(),
                    self.dim
                ),
            });
        }
        self.vel_mean = stats.velocity.mean().to_vec();
        self.vel_std = stats.velocity.std();
        self.acc_mean = stats.acceleration.mean().to_vec();
        self.acc_std = stats.acceleration.std();
        Ok(())
    }

    /// The number of frames in each trajectory file, `sequence_length + 1`.
    pub fn frames(&self) -> usize {
        self.sequence_length + 1
    }

    /// Checks that the values are consistent (format, dimension of every per-component list,
    /// finite numbers, positive `dt`); `path` names the file in the error.
    pub fn validate(&self, path: &Path) -> Result<(), DataError> {
        let bad = |key: &str, reason: String| Err(DataError::metadata(path, key, reason));
        if self.format != FORMAT {
            return bad("format", format!("'{}', expected '{FORMAT}'", self.format));
        }
        if self.format_version != FORMAT_VERSION {
            return bad(
                "format_version",
                format!(
                    "{} is not supported (this code reads version {FORMAT_VERSION})",
                    self.format_version
                ),
            );
        }
        if !(1..=3).contains(&self.dim) {
            return bad("dim", format!("{} (must be 1, 2 or 3)", self.dim));
        }
        if self.bounds.len() != self.dim {
            return bad(
                "bounds",
                format!("{} axes for dim {}", self.bounds.len(), self.dim),
            );
        }
        for (key, list) in [
            ("vel_mean", &self.vel_mean),
            ("vel_std", &self.vel_std),
            ("acc_mean", &self.acc_mean),
            ("acc_std", &self.acc_std),
        ] {
            if list.len() != self.dim {
                return bad(
                    key,
                    format!("{} components for dim {}", list.len(), self.dim),
                );
            }
            if !list.iter().all(|x| x.is_finite()) {
                return bad(key, format!("{list:?} is not finite"));
            }
        }
        for (axis, &[lo, hi]) in self.bounds.iter().enumerate() {
            if !(lo.is_finite() && hi.is_finite()) {
                return bad(
                    &format!("bounds[{axis}]"),
                    format!("[{lo}, {hi}] is not finite"),
                );
            }
            if lo >= hi {
                return bad(
                    &format!("bounds[{axis}]"),
                    format!(
                        "[{lo}, {hi}] is empty or reversed (the minimum must be below the maximum)"
                    ),
                );
            }
        }
        if !(self.position_scale.is_finite() && self.position_scale > 0.0) {
            return bad(
                "position_scale",
                format!("{} (must be a positive number)", self.position_scale),
            );
        }
        if !self.position_offset.is_finite() {
            return bad(
                "position_offset",
                format!("{} is not finite", self.position_offset),
            );
        }
        let radius = self.default_connectivity_radius;
        if !(radius.is_finite() && radius > 0.0) {
            return bad(
                "default_connectivity_radius",
                format!("{radius} (must be a positive number)"),
            );
        }
        let training = self.splits.get("train").copied().unwrap_or(0);
        for (key, std) in [("vel_std", &self.vel_std), ("acc_std", &self.acc_std)] {
            if let Some(s) = std.iter().find(|s| **s < 0.0) {
                return bad(
                    key,
                    format!("{std:?} holds {s}, a negative standard deviation"),
                );
            }
            // A training split whose liquid moved has spread in its velocities and
            // accelerations; all zeros are statistics that were never filled in, and cannot
            // normalise a model's inputs.
            if training > 0 && std.iter().all(|s| *s == 0.0) {
                return bad(
                    key,
                    format!(
                        "{std:?} for a train split of {training} trajectories: the statistics \
                         are missing (all zero), and a standard deviation of 0 cannot normalise"
                    ),
                );
            }
        }
        if !(self.dt > 0.0 && self.dt.is_finite()) {
            return bad("dt", format!("{} (must be positive)", self.dt));
        }
        if self.sequence_length == 0 {
            return bad("sequence_length", "0 (must be positive)".into());
        }
        Ok(())
    }
}

/// Reads and validates `dir/metadata.json`.
pub fn read_metadata(dir: &Path) -> Result<Metadata, DataError> {
    let path = dir.join(METADATA_FILE);
    let text =
        std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, "cannot read", e))?;
    let metadata: Metadata = serde_json::from_str(&text).map_err(|source| DataError::Json {
        path: path.clone(),
        source,
    })?;
    metadata.validate(&path)?;
    Ok(metadata)
}

/// Validates `metadata` and writes it to `dir/metadata.json` (pretty-printed), atomically.
pub fn write_metadata(dir: &Path, metadata: &Metadata) -> Result<(), DataError> {
    let path = dir.join(METADATA_FILE);
    metadata.validate(&path)?;
    Ok(phi_io::write_json(&path, metadata)?)
}
