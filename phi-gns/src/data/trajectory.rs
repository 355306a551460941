//! One trajectory in memory and its `.npz` file.

use std::path::Path;

use phi_io::npz::{NpyArray, NpzReader, write_npz};

use super::{DataError, LIQUID, Moments, OBSTACLE, TrajectoryStats};

/// The positions and particle types of one simulation, as stored in a trajectory file.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// The number of spatial dimensions (2 or 3).
    pub dim: usize,
    /// The number of frames, `sequence_length + 1` (401 in the thesis).
    pub frames: usize,
    /// The number of particles (liquid and obstacle), the same in every frame.
    pub particles: usize,
    /// Stored positions `[frames, particles, dim]`, C order.
    pub position: Vec<f32>,
    /// [`OBSTACLE`] or [`LIQUID`] per particle, `[particles]`.
    pub particle_type: Vec<i64>,
    /// The seed the generator drew this trajectory's scene from.
    pub seed: u64,
    /// The trajectory's index in its split (its file is [`trajectory_file_name`]`(index)`).
    pub index: usize,
}

impl Trajectory {
    /// A trajectory of `particle_type.len()` particles whose `position` holds
    /// `[frames, particles, dim]` values.
    ///
    /// Fails unless `dim` is 1, 2 or 3, there is at least one particle and one frame,
    /// `position.len()` is a multiple of `particles · dim`, every position is finite and every
    /// type is [`OBSTACLE`] or [`LIQUID`].
    pub fn new(
        dim: usize,
        position: Vec<f32>,
        particle_type: Vec<i64>,
        seed: u64,
        index: usize,
    ) -> Result<Self, DataError> {
        let bad = |reason: String| {
            Err(DataError::InvalidInput {
                what: "trajectory",
                reason,
            })
        };
        if !(1..=3).contains(&dim) {
            return bad(format!("dimension {dim} (must be 1, 2 or 3)"));
        }
        let particles = particle_type.len();
        if particles == 0 {
            return bad("no particles".into());
        }
        let per_frame = particles * dim;
        if position.is_empty() || !position.len().is_multiple_of(per_frame) {
            return bad(format!(
                "{} position values are not a positive number of frames of {particles} \
                 particles in {dim}D",
                position.len()
            ));
        }
        if let Some(i) = position.iter().position(|x| !x.is_finite()) {
            return bad(format!(
                "position of particle {} in frame {} is not finite ({})",
                (i % per_frame) / dim,
                i / per_frame,
                position[i]
            ));
        }
        if let Some(i) = particle_type
            .iter()
            .position(|&t| t != OBSTACLE && t != LIQUID)
        {
            return bad(format!(
                "particle {i} has type {} (must be {OBSTACLE} = obstacle or {LIQUID} = liquid)",
                particle_type[i]
            ));
        }
        Ok(Trajectory {
            dim,
            frames: position.len() / per_frame,
            particles,
            position,
            particle_type,
            seed,
            index,
        })
    }

    /// The positions of frame `t`, `[particles, dim]`. Panics when `t >= frames`.
    pub fn frame(&self, t: usize) -> &[f32] {
        let per_frame = self.particles * self.dim;
        &self.position[t * per_frame..(t + 1) * per_frame]
    }

    /// The number of liquid particles.
    pub fn liquid_particles(&self) -> usize {
        self.particle_type.iter().filter(|&&t| t == LIQUID).count()
    }
}

/// The file name of trajectory `index`: `traj_00000.npz`, five digits or more.
pub fn trajectory_file_name(index: usize) -> String {
    format!("traj_{index:05}.npz")
}

/// The index in a trajectory file name (`traj_00042.npz` → 42); `None` for other names,
/// including ones with fewer than five digits or leading zeros beyond five.
pub fn trajectory_index_from_file_name(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("traj_")?.strip_suffix(".npz")?;
    if digits.len() < 5 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let index: usize = digits.parse().ok()?;
    (trajectory_file_name(index) == name).then_some(index)
}

/// The `[3, dim]` rows (count, mean, M2) stored for a [`Moments`].
fn moments_array(m: &Moments) -> NpyArray {
    let mut rows = vec![m.count() as f64; m.dim()];
    rows.extend_from_slice(m.mean());
    rows.extend_from_slice(m.m2());
    NpyArray {
        shape: vec![3, m.dim()],
        data: rows.into(),
    }
}

/// Writes `traj` and its statistics (normally [`TrajectoryStats::of`]`(traj)`) to the `.npz`
/// file `path`, atomically (temporary file in the same directory, synced, renamed).
///
/// Fails when the statistics' dimension differs from the trajectory's, and on I/O errors
/// (naming the file).
pub fn write_trajectory(
    path: &Path,
    traj: &Trajectory,
    stats: &TrajectoryStats,
) -> Result<(), DataError> {
    for (what, m) in [
        ("velocity", &stats.velocity),
        ("acceleration", &stats.acceleration),
    ] {
        if m.dim() != traj.dim {
            return Err(DataError::InvalidInput {
                what: "trajectory statistics",
                reason: format!(
                    "{what} statistics of {} components for a {}D trajectory written to '{}'",
                    m.dim(),
                    traj.dim,
                    path.display()
                ),
            });
        }
    }
    let position = NpyArray {
        shape: vec![traj.frames, traj.particles, traj.dim],
        data: traj.position.clone().into(),
    };
    let particle_type = NpyArray::from_vec(traj.particle_type.clone());
    let velocity = moments_array(&stats.velocity);
    let acceleration = moments_array(&stats.acceleration);
    // The seed is a u64 kept bit for bit in an i64 (numpy: `.view(np.uint64)`).
    let seed = NpyArray::from_vec(vec![traj.seed as i64]);
    let index = NpyArray::from_vec(vec![traj.index as i64]);
    write_npz(
        path,
        &[
            ("position", &position),
            ("particle_type", &particle_type),
            ("stats_velocity", &velocity),
            ("stats_acceleration", &acceleration),
            ("seed", &seed),
            ("index", &index),
        ],
    )?;
    Ok(())
}

/// Reads the member `name` and checks its dtype and rank.
fn read_member(npz: &mut NpzReader, name: &str, rank: usize) -> Result<NpyArray, DataError> {
    let array = npz.read(name)?;
    if array.shape.len() != rank {
        return Err(DataError::invalid(
            npz.path(),
            format!("'{name}' has shape {:?}, expected {rank} axes", array.shape),
        ));
    }
    Ok(array)
}

fn wrong_dtype(path: &Path, name: &str, expected: &str, array: &NpyArray) -> DataError {
    DataError::invalid(
        path,
        format!(
            "'{name}' has dtype {}, expected {expected}",
            array.data.descr()
        ),
    )
}

/// Reads a one-element i64 member.
fn read_scalar_i64(npz: &mut NpzReader, name: &str) -> Result<i64, DataError> {
    let array = read_member(npz, name, 1)?;
    match array.as_i64() {
        Some(&[x]) => Ok(x),
        Some(_) => Err(DataError::invalid(
            npz.path(),
            format!("'{name}' has shape {:?}, expected [1]", array.shape),
        )),
        None => Err(wrong_dtype(npz.path(), name, "int64", &array)),
    }
}

/// Reads a `[3, dim]` statistics member.
fn read_moments(npz: &mut NpzReader, name: &str) -> Result<Moments, DataError> {
    let array = read_member(npz, name, 2)?;
    let Some(rows) = array.as_f64() else {
        return Err(wrong_dtype(npz.path(), name, "float64", &array));
    };
    let dim = array.shape[1];
    if array.shape[0] != 3 {
        return Err(DataError::invalid(
            npz.path(),
            format!("'{name}' has shape {:?}, expected [3, dim]", array.shape),
        ));
    }
    let counts = &rows[..dim];
    let count = counts.first().copied().unwrap_or(0.0);
    if counts.iter().any(|&c| c != count)
        || !(0.0..=9.0e15).contains(&count)
        || count.fract() != 0.0
    {
        return Err(DataError::invalid(
            npz.path(),
            format!("'{name}': the count row {counts:?} is not one whole number repeated"),
        ));
    }
    Moments::from_parts(
        count as u64,
        rows[dim..2 * dim].to_vec(),
        rows[2 * dim..].to_vec(),
    )
    .map_err(|e| DataError::invalid(npz.path(), format!("'{name}': {e}")))
}

/// Reads both statistics members of an open trajectory file.
fn read_stats(npz: &mut NpzReader) -> Result<TrajectoryStats, DataError> {
    let velocity = read_moments(npz, "stats_velocity")?;
    let acceleration = read_moments(npz, "stats_acceleration")?;
    if velocity.dim() != acceleration.dim() {
        return Err(DataError::invalid(
            npz.path(),
            format!(
                "'stats_velocity' has {} components but 'stats_acceleration' has {}",
                velocity.dim(),
                acceleration.dim()
            ),
        ));
    }
    Ok(TrajectoryStats {
        velocity,
        acceleration,
    })
}

/// Reads a trajectory file written by [`write_trajectory`] (or by numpy with the same members).
///
/// Every member's CRC-32 is checked; fails, naming the file, when the file is truncated or
/// damaged, a member is missing or has the wrong dtype or shape, or the values are invalid for
/// [`Trajectory::new`].
pub fn read_trajectory(path: &Path) -> Result<Trajectory, DataError> {
    let mut npz = NpzReader::open(path)?;
    read_trajectory_from(&mut npz)
}

/// Reads a trajectory and its stored statistics (checking that they have its dimension): every
/// member of the file is read and its CRC-32 checked, so a file this accepts is whole.
pub fn read_trajectory_and_stats(path: &Path) -> Result<(Trajectory, TrajectoryStats), DataError> {
    let mut npz = NpzReader::open(path)?;
    let traj = read_trajectory_from(&mut npz)?;
    let stats = read_stats(&mut npz)?;
    if stats.velocity.dim() != traj.dim {
        return Err(DataError::invalid(
            path,
            format!(
                "statistics of {} components for positions in {}D",
                stats.velocity.dim(),
                traj.dim
            ),
        ));
    }
    Ok((traj, stats))
}

fn read_trajectory_from(npz: &mut NpzReader) -> Result<Trajectory, DataError> {
    let position = read_member(npz, "position", 3)?;
    let shape = position.shape.clone();
    let position = match position.data {
        phi_io::npz::ArrayData::F32(v) => v,
        _ => return Err(wrong_dtype(npz.path(), "position", "float32", &position)),
    };
    let particle_type = read_member(npz, "particle_type", 1)?;
    let Some(types) = particle_type.as_i64() else {
        return Err(wrong_dtype(
            npz.path(),
            "particle_type",
            "int64",
            &particle_type,
        ));
    };
    if types.len() != shape[1] {
        return Err(DataError::invalid(
            npz.path(),
            format!(
                "'particle_type' has {} particles but 'position' has shape {shape:?}",
                types.len()
            ),
        ));
    }
    let seed = read_scalar_i64(npz, "seed")? as u64;
    let index = read_scalar_i64(npz, "index")?;
    let index = usize::try_from(index)
        .map_err(|_| DataError::invalid(npz.path(), format!("'index' is negative ({index})")))?;
    Trajectory::new(shape[2], position, types.to_vec(), seed, index)
        .map_err(|e| DataError::invalid(npz.path(), e.to_string()))
}

/// Reads only the statistics stored in a trajectory file (two `[3, dim]` members, a few hundred
/// bytes, found through the ZIP central directory), so that merging shards does not read
/// positions. The members' CRC-32 are checked; the positions are not read.
pub fn read_trajectory_stats(path: &Path) -> Result<TrajectoryStats, DataError> {
    let mut npz = NpzReader::open(path)?;
    read_stats(&mut npz)
}

/// What [`read_trajectory_identity`] reads of a trajectory file.
pub(crate) struct TrajectoryIdentity {
    pub(crate) frames: usize,
    pub(crate) particles: usize,
    pub(crate) dim: usize,
    pub(crate) seed: u64,
    pub(crate) index: usize,
}

/// The frame count, particle count and dimension of a trajectory file's positions (from the `.npy` header
/// only; the positions are not read, nor their CRC-32 checked) and its stored seed and index
/// (two small members, CRC-checked).
pub(crate) fn read_trajectory_identity(path: &Path) -> Result<TrajectoryIdentity, DataError> {
    let mut npz = NpzReader::open(path)?;
    let header = npz.header("position")?;
    let (frames, particles, dim) = match header.shape[..] {
        [frames, particles, dim] if header.descr == "<f4" => (frames, particles, dim),
        _ => {
            return Err(DataError::invalid(
                path,
                format!(
                    "'position' is '{}' of shape {:?}, expected '<f4' of shape [frames, n, dim]",
                    header.descr, header.shape
                ),
            ));
        }
    };
    let seed = read_scalar_i64(&mut npz, "seed")? as u64;
    let index = read_scalar_i64(&mut npz, "index")?;
    let index = usize::try_from(index)
        .map_err(|_| DataError::invalid(path, format!("'index' is negative ({index})")))?;
    Ok(TrajectoryIdentity {
        frames,
        particles,
        dim,
        seed,
        index,
    })
}
