//! Datasets in the formats of other learned-simulator projects.
//!
//! - [`export_gns`]: geoelements/gns (PyTorch). One `{split}.npz` per split whose entries
//!   `trajectory_{i}` are object arrays `(positions [T, N, D] f32, particle_type [N] i64)`, the
//!   items gns's `data_loader.load_npz_data` iterates over, and a `metadata.json` with the keys
//!   its training code reads (`GnsMetadata`). Types: [`GNS_KINEMATIC`] (3) for obstacle and
//!   wall particles (gns moves them along the ground truth, as static), [`GNS_WATER`] (5) for
//!   liquid.
//! - [`lagrangebench_metadata`] and [`export_lagrangebench_arrays`]: the parts of a
//!   LagrangeBench export that need no HDF5 library. LagrangeBench reads `{split}.h5` with one
//!   group per trajectory (`00000`, ...) holding `position` `[T, N, D]` and `particle_type` `[N]`
//!   (FLUID 0, SOLID_WALL 1: [`LB_FLUID`], [`LB_SOLID_WALL`]); the arrays are written here as an
//!   `.npz` archive in that layout, which the `phi` command turns into HDF5.
//!
//! Both formats take the positions in the dataset's stored units and the statistics of
//! `metadata.json` as they are (velocity and acceleration as differences of stored positions,
//! not divided by `dt`), which is how gns and LagrangeBench normalise their inputs.

use std::path::Path;

use phi_io::npz::NpyArray;
use serde::Serialize;

use super::dataset::write_split_npz;
use super::{DataError, Dataset, LIQUID, Metadata, OBSTACLE, Trajectory};

/// gns's `KINEMATIC_PARTICLE_ID`: particles that follow the ground truth.
pub const GNS_KINEMATIC: i64 = 3;
/// The type given to liquid particles in a gns export (DeepMind's water, as in the TFRecords).
pub const GNS_WATER: i64 = 5;
/// LagrangeBench's `NodeType.FLUID`.
pub const LB_FLUID: i64 = 0;
/// LagrangeBench's `NodeType.SOLID_WALL` (a kinematic particle there).
pub const LB_SOLID_WALL: i64 = 1;

/// The keys of gns's `metadata.json` (the nine its `train.py` reads), with the values of the
/// dataset's own metadata.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct GnsMetadata {
    /// `[min, max]` per axis.
    pub bounds: Vec<[f64; 2]>,
    /// Steps per trajectory (frames − 1).
    pub sequence_length: usize,
    /// The connectivity radius in stored units.
    pub default_connectivity_radius: f64,
    /// Spatial dimensions.
    pub dim: usize,
    /// Seconds between frames.
    pub dt: f64,
    /// Mean velocity per component (liquid, training split).
    pub vel_mean: Vec<f64>,
    /// Standard deviation of the velocity per component.
    pub vel_std: Vec<f64>,
    /// Mean acceleration per component.
    pub acc_mean: Vec<f64>,
    /// Standard deviation of the acceleration per component.
    pub acc_std: Vec<f64>,
}

impl GnsMetadata {
    /// The gns keys of `metadata`.
    pub fn of(metadata: &Metadata) -> Self {
        GnsMetadata {
            bounds: metadata.bounds.clone(),
            sequence_length: metadata.sequence_length,
            default_connectivity_radius: metadata.default_connectivity_radius,
            dim: metadata.dim,
            dt: metadata.dt,
            vel_mean: metadata.vel_mean.clone(),
            vel_std: metadata.vel_std.clone(),
            acc_mean: metadata.acc_mean.clone(),
            acc_std: metadata.acc_std.clone(),
        }
    }
}

/// A particle type of ours as `kinematic` (obstacle) or `liquid`; other values are an error
/// naming the trajectory.
fn map_types(
    dataset: &Dataset,
    split: &str,
    traj: &Trajectory,
    kinematic: i64,
    liquid: i64,
) -> Result<Vec<i64>, DataError> {
    traj.particle_type
        .iter()
        .map(|&t| match t {
            OBSTACLE => Ok(kinematic),
            LIQUID => Ok(liquid),
            other => Err(DataError::invalid(
                Dataset::trajectory_path(dataset.dir(), split, traj.index),
                format!("particle type {other} (expected {OBSTACLE} or {LIQUID})"),
            )),
        })
        .collect()
}

fn positions(traj: &Trajectory) -> NpyArray {
    NpyArray {
        shape: vec![traj.frames, traj.particles, traj.dim],
        data: traj.position.clone().into(),
    }
}

/// Writes `json` to `path`, pretty-printed, atomically.
fn write_json(path: &Path, json: &impl Serialize) -> Result<(), DataError> {
    Ok(phi_io::write_json(path, json)?)
}

/// Writes `split` of `dataset` as gns's `{split}.npz` to `out_file`: for each trajectory `i`
/// the entry `trajectory_{i}`, an object array `[positions, particle_type]`. Streamed (one
/// trajectory in memory), written atomically; `on_trajectory` is called after each one.
/// Returns the number of trajectories.
pub(crate) fn export_gns_split(
    dataset: &Dataset,
    split: &str,
    out_file: &Path,
    on_trajectory: &mut dyn FnMut(),
) -> Result<usize, DataError> {
    write_split_npz(dataset, split, out_file, |npz, traj| {
        let types = map_types(dataset, split, &traj, GNS_KINEMATIC, GNS_WATER)?;
        let types = NpyArray::from_vec(types);
        npz.add_object_array(
            &format!("trajectory_{}", traj.index),
            &[&positions(&traj), &types],
        )?;
        on_trajectory();
        Ok(())
    })
}

/// Writes every split of `dataset` for gns into `out_dir` (`{split}.npz`, see
/// `export_gns_split`) and then `out_dir/metadata.json` (`GnsMetadata`). Returns the
/// trajectories written per split.
pub fn export_gns(
    dataset: &Dataset,
    out_dir: &Path,
    on_trajectory: &mut dyn FnMut(),
) -> Result<Vec<(String, usize)>, DataError> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| DataError::io(out_dir, "cannot create the directory", e))?;
    let mut counts = Vec::new();
    for split in dataset.metadata().splits.keys() {
        let file = out_dir.join(format!("{split}.npz"));
        counts.push((
            split.clone(),
            export_gns_split(dataset, split, &file, on_trajectory)?,
        ));
    }
    write_json(
        &out_dir.join(super::METADATA_FILE),
        &GnsMetadata::of(dataset.metadata()),
    )?;
    Ok(counts)
}

/// The `metadata.json` of a LagrangeBench export: the keys its `H5Dataset`, case setup, model
/// and metrics read (`bounds`, `dim`, `dt`, `write_every`, `dx`, `default_connectivity_radius`,
/// `periodic_boundary_conditions`, `num_particles_max`, the four statistics) and the
/// bookkeeping keys of its own datasets (`case`, `sequence_length_{split}`,
/// `num_trajs_{split}`).
///
/// `num_particles_max` is the largest particle count of any trajectory of any split (read from
/// the file headers). `dx`, the particle spacing (LagrangeBench's kinetic energy uses `dx^dim`
/// as a particle's volume), is the cell size over `particles_per_cell^(1/dim)` when the
/// generator's configuration records `params.particles_per_cell`, and the cell size otherwise.
/// The walls are not periodic.
pub fn lagrangebench_metadata(dataset: &Dataset) -> Result<serde_json::Value, DataError> {
    let m = dataset.metadata();
    let mut num_particles_max = 0;
    for (split, &count) in &m.splits {
        for index in 0..count {
            let path = Dataset::trajectory_path(dataset.dir(), split, index);
            let particles = super::trajectory::read_trajectory_identity(&path)?.particles;
            num_particles_max = num_particles_max.max(particles);
        }
    }
    let dx = match m
        .generator
        .pointer("/params/particles_per_cell")
        .and_then(serde_json::Value::as_f64)
    {
        Some(ppc) if ppc >= 1.0 => m.position_scale / ppc.powf(1.0 / m.dim as f64),
        _ => m.position_scale,
    };
    let mut json = serde_json::json!({
        "case": "PHI_FLIP",
        "solver": "phi FLIP",
        "dim": m.dim,
        "dx": dx,
        "dt": m.dt,
        "write_every": 1,
        "bounds": m.bounds,
        "periodic_boundary_conditions": vec![false; m.dim],
        "default_connectivity_radius": m.default_connectivity_radius,
        "num_particles_max": num_particles_max,
        "vel_mean": m.vel_mean,
        "vel_std": m.vel_std,
        "acc_mean": m.acc_mean,
        "acc_std": m.acc_std,
    });
    let object = json.as_object_mut().expect("a JSON object");
    for (split, &count) in &m.splits {
        object.insert(format!("sequence_length_{split}"), m.sequence_length.into());
        object.insert(format!("num_trajs_{split}"), count.into());
    }
    Ok(json)
}

/// Writes [`lagrangebench_metadata`] to `out_dir/metadata.json`, atomically.
pub fn write_lagrangebench_metadata(dataset: &Dataset, out_dir: &Path) -> Result<(), DataError> {
    write_json(
        &out_dir.join(super::METADATA_FILE),
        &lagrangebench_metadata(dataset)?,
    )
}

/// Writes `split` of `dataset` in LagrangeBench's layout as an `.npz` archive: for each
/// trajectory `i`, `{i:05}/position` (f32 `[T, N, D]`) and `{i:05}/particle_type` (i64 `[N]`,
/// [`LB_FLUID`] or [`LB_SOLID_WALL`]), in index order. Streamed, written atomically;
/// `on_trajectory` is called after each trajectory. Returns the number of trajectories.
pub fn export_lagrangebench_arrays(
    dataset: &Dataset,
    split: &str,
    out_file: &Path,
    on_trajectory: &mut dyn FnMut(),
) -> Result<usize, DataError> {
    write_split_npz(dataset, split, out_file, |npz, traj| {
        let types = map_types(dataset, split, &traj, LB_SOLID_WALL, LB_FLUID)?;
        let group = format!("{:05}", traj.index);
        npz.add(&format!("{group}/position"), &positions(&traj))?;
        npz.add(
            &format!("{group}/particle_type"),
            &NpyArray::from_vec(types),
        )?;
        on_trajectory();
        Ok(())
    })
}
