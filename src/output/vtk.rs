//! Particle frames for ParaView and other VTK readers: one VTK XML unstructured grid (`.vtu`)
//! per frame and a `.pvd` collection that lists them with their times.
//!
//! Each `.vtu` holds the particles as points (3 coordinates; a 2D run has z = 0), one
//! `VTK_VERTEX` cell per point so that every reader draws them, and the point data `velocity`
//! (3 components, float32), `speed` (float32) and `particle_type` (int32). Arrays are written in
//! VTK's inline `binary` encoding: base64 of a UInt64 byte count followed by the little-endian
//! values. The `.pvd` is rewritten (atomically) after every frame, so a run that stops early
//! leaves a series of the frames written so far.
//!
//! ```text
//! OUT/simulation.pvd            <DataSet timestep="0.05" file="vtk/frame_00001.vtu"/> ...
//! OUT/vtk/frame_00000.vtu
//! ```

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use base64::Engine as _;
use base64::engine::general_purpose::STANDARD;

use super::{OutputError, write_atomic};

/// VTK's cell type of a single point.
const VTK_VERTEX: u8 = 1;

/// One frame of particles.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VtkFrame<'a> {
    /// The frame's time in seconds.
    pub time: f64,
    /// The spatial dimension, 1 to 3.
    pub dim: usize,
    /// Positions `[n * dim]`.
    pub positions: &'a [f32],
    /// Velocities `[n * dim]`.
    pub velocities: &'a [f32],
    /// One type per particle (the caller's convention, written as it is).
    pub particle_type: &'a [i32],
}

/// Writes a series of frames: `dir/{subdir}/frame_NNNNN.vtu` and `dir/{name}.pvd`.
#[derive(Debug)]
pub(crate) struct VtkSeries {
    dir: PathBuf,
    subdir: String,
    prefix: String,
    pvd: PathBuf,
    entries: Vec<(f64, String)>,
}

impl VtkSeries {
    /// A series in `dir` whose collection is `dir/{name}.pvd` and whose frames go into
    /// `dir/{subdir}/` (created).
    ///
    /// # Errors
    /// The frame folder cannot be created.
    pub(crate) fn create(dir: &Path, name: &str, subdir: &str) -> Result<Self, OutputError> {
        let frames = dir.join(subdir);
        std::fs::create_dir_all(&frames)
            .map_err(|e| OutputError::io(&frames, "cannot create the directory", e))?;
        Ok(VtkSeries {
            dir: dir.to_path_buf(),
            subdir: subdir.to_string(),
            prefix: "frame".to_string(),
            pvd: dir.join(format!("{name}.pvd")),
            entries: Vec::new(),
        })
    }

    /// Names the frames `{prefix}_NNNNN.vtu` instead of `frame_NNNNN.vtu` (for two series
    /// sharing a folder).
    pub(crate) fn with_prefix(mut self, prefix: &str) -> Self {
        self.prefix = prefix.to_string();
        self
    }

    /// The collection file.
    #[cfg(test)]
    pub(crate) fn pvd_path(&self) -> &Path {
        &self.pvd
    }

    /// The frames written so far.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.entries.len()
    }

    /// Writes frame `index` as `frame_{index:05}.vtu` (or with the prefix of
    /// [`VtkSeries::with_prefix`]) and rewrites the collection.
    ///
    /// # Errors
    /// Inconsistent lengths, a dimension other than 1 to 3, and I/O errors (naming the file).
    pub fn add(&mut self, index: usize, frame: &VtkFrame<'_>) -> Result<(), OutputError> {
        let file = format!("{}/{}_{index:05}.vtu", self.subdir, self.prefix);
        let path = self.dir.join(&file);
        let text = vtu_text(frame).map_err(|reason| {
            OutputError::InvalidInput(format!("'{}': {reason}", path.display()))
        })?;
        write_text(&path, &text)?;
        self.entries.push((frame.time, file));
        write_text(&self.pvd, &pvd_text(&self.entries))
    }
}

fn write_text(path: &Path, text: &str) -> Result<(), OutputError> {
    write_atomic(path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| phi_io::IoError::io(path, "cannot write", e))
    })?;
    Ok(())
}

/// The `.pvd` collection of `(time, file)` entries.
pub(crate) fn pvd_text(entries: &[(f64, String)]) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" \
         byte_order=\"LittleEndian\">\n  <Collection>\n",
    );
    for (time, file) in entries {
        let _ = writeln!(
            s,
            "    <DataSet timestep=\"{time}\" group=\"\" part=\"0\" file=\"{file}\"/>"
        );
    }
    s.push_str("  </Collection>\n</VTKFile>\n");
    s
}

/// A data array in VTK's inline binary encoding.
fn data_array(
    out: &mut String,
    vtk_type: &str,
    name: Option<&str>,
    components: usize,
    bytes: &[u8],
) {
    let mut block = Vec::with_capacity(8 + bytes.len());
    block.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
    block.extend_from_slice(bytes);
    let name = name.map(|n| format!(" Name=\"{n}\"")).unwrap_or_default();
    // One component is VTK's default, and VTK's own writers leave it unsaid: readers such as
    // meshio then read a scalar as `[n]`, not `[n, 1]`.
    let components = if components == 1 {
        String::new()
    } else {
        format!(" NumberOfComponents=\"{components}\"")
    };
    let _ = writeln!(
        out,
        "        <DataArray type=\"{vtk_type}\"{name}{components} format=\"binary\">{}</DataArray>",
        STANDARD.encode(&block)
    );
}

/// Values `[n * dim]` as `[n * 3]` little-endian bytes (missing axes 0).
fn as_xyz(values: &[f32], dim: usize) -> Vec<u8> {
    values
        .chunks(dim)
        .flat_map(|p| (0..3).map(move |a| p.get(a).copied().unwrap_or(0.0)))
        .flat_map(f32::to_le_bytes)
        .collect()
}

/// The `.vtu` document of one frame.
pub(crate) fn vtu_text(frame: &VtkFrame<'_>) -> Result<String, String> {
    let d = frame.dim;
    if !(1..=3).contains(&d) {
        return Err(format!("dimension {d} (must be 1, 2 or 3)"));
    }
    let n = frame.particle_type.len();
    if frame.positions.len() != n * d || frame.velocities.len() != n * d {
        return Err(format!(
            "{} positions and {} velocity components for {n} particles in {d}D",
            frame.positions.len(),
            frame.velocities.len()
        ));
    }
    let speed: Vec<u8> = frame
        .velocities
        .chunks(d)
        .map(|v| v.iter().map(|x| x * x).sum::<f32>().sqrt())
        .flat_map(f32::to_le_bytes)
        .collect();
    let types: Vec<u8> = frame
        .particle_type
        .iter()
        .flat_map(|t| t.to_le_bytes())
        .collect();
    let connectivity: Vec<u8> = (0..n as i64).flat_map(i64::to_le_bytes).collect();
    let offsets: Vec<u8> = (1..=n as i64).flat_map(i64::to_le_bytes).collect();
    let cell_types = vec![VTK_VERTEX; n];

    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <UnstructuredGrid>\n",
    );
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n      <PointData \
         Scalars=\"particle_type\" Vectors=\"velocity\">"
    );
    data_array(
        &mut s,
        "Float32",
        Some("velocity"),
        3,
        &as_xyz(frame.velocities, d),
    );
    data_array(&mut s, "Float32", Some("speed"), 1, &speed);
    data_array(&mut s, "Int32", Some("particle_type"), 1, &types);
    s.push_str("      </PointData>\n      <Points>\n");
    data_array(
        &mut s,
        "Float32",
        Some("Points"),
        3,
        &as_xyz(frame.positions, d),
    );
    s.push_str("      </Points>\n      <Cells>\n");
    data_array(&mut s, "Int64", Some("connectivity"), 1, &connectivity);
    data_array(&mut s, "Int64", Some("offsets"), 1, &offsets);
    data_array(&mut s, "UInt8", Some("types"), 1, &cell_types);
    s.push_str("      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The decoded bytes of the data array called `name` in a `.vtu` document: the UInt64 byte
    /// count must match the bytes that follow it.
    pub(crate) fn array_bytes(vtu: &str, name: &str) -> Vec<u8> {
        let tag = format!("Name=\"{name}\"");
        let at = vtu.find(&tag).unwrap_or_else(|| panic!("no array {name}"));
        let start = at + vtu[at..].find('>').unwrap() + 1;
        let end = start + vtu[start..].find("</DataArray>").unwrap();
        let block = STANDARD.decode(&vtu[start..end]).unwrap();
        let (count, data) = block.split_at(8);
        assert_eq!(
            u64::from_le_bytes(count.try_into().unwrap()) as usize,
            data.len()
        );
        data.to_vec()
    }

    fn f32s(bytes: &[u8]) -> Vec<f32> {
        bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn a_2d_frame_has_padded_points_speed_types_and_vertex_cells() {
        let frame = VtkFrame {
            time: 0.25,
            dim: 2,
            positions: &[1.0, 2.0, 3.5, -4.0],
            velocities: &[3.0, 4.0, 0.0, -1.5],
            particle_type: &[1, 0],
        };
        let vtu = vtu_text(&frame).unwrap();
        assert!(vtu.contains("<Piece NumberOfPoints=\"2\" NumberOfCells=\"2\">"));
        assert_eq!(
            f32s(&array_bytes(&vtu, "Points")),
            [1.0, 2.0, 0.0, 3.5, -4.0, 0.0]
        );
        assert_eq!(
            f32s(&array_bytes(&vtu, "velocity")),
            [3.0, 4.0, 0.0, 0.0, -1.5, 0.0]
        );
        assert_eq!(f32s(&array_bytes(&vtu, "speed")), [5.0, 1.5]);
        // Vectors say their components; scalars leave VTK's default of one unsaid, so that
        // readers (meshio) read them as `[n]`.
        assert!(vtu.contains("Name=\"velocity\" NumberOfComponents=\"3\""));
        assert!(vtu.contains("Name=\"speed\" format=\"binary\""));
        assert!(vtu.contains("Name=\"particle_type\" format=\"binary\""));
        let types = array_bytes(&vtu, "particle_type");
        assert_eq!(types, [1i32.to_le_bytes(), 0i32.to_le_bytes()].concat());
        let offsets = array_bytes(&vtu, "offsets");
        assert_eq!(offsets, [1i64.to_le_bytes(), 2i64.to_le_bytes()].concat());
        assert_eq!(array_bytes(&vtu, "types"), [VTK_VERTEX, VTK_VERTEX]);
    }

    #[test]
    fn inconsistent_frames_are_refused_and_the_series_lists_every_frame() {
        let bad = VtkFrame {
            time: 0.0,
            dim: 2,
            positions: &[1.0, 2.0, 3.0],
            velocities: &[0.0; 3],
            particle_type: &[1, 1],
        };
        assert!(vtu_text(&bad).unwrap_err().contains("3 positions"));
        assert!(vtu_text(&VtkFrame { dim: 4, ..bad }).is_err());

        let dir = crate::output::test_util::temp_dir("vtk-series");
        let mut series = VtkSeries::create(&dir, "run", "vtk").unwrap();
        for (index, time) in [(0, 0.0), (5, 0.25)] {
            let frame = VtkFrame {
                time,
                dim: 3,
                positions: &[0.5, 0.5, 0.5],
                velocities: &[0.0, 0.0, -1.0],
                particle_type: &[1],
            };
            series.add(index, &frame).unwrap();
        }
        assert_eq!(series.len(), 2);
        assert!(dir.join("vtk/frame_00005.vtu").is_file());
        let pvd = std::fs::read_to_string(series.pvd_path()).unwrap();
        assert!(pvd.contains(
            "<DataSet timestep=\"0\" group=\"\" part=\"0\" file=\"vtk/frame_00000.vtu\"/>"
        ));
        assert!(pvd.contains(
            "<DataSet timestep=\"0.25\" group=\"\" part=\"0\" file=\"vtk/frame_00005.vtu\"/>"
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
