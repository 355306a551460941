//! DeepMind `learning_to_simulate` TFRecords: export a dataset to `{split}.tfrecord` files and
//! import such files (ours or DeepMind's) as a dataset.
//!
//! # Records
//!
//! A TFRecord file is a sequence of records, each framed as
//!
//! ```text
//! u64 LE  length
//! u32 LE  masked CRC-32C of the 8 length bytes
//! [u8]    data (length bytes)
//! u32 LE  masked CRC-32C of the data
//! ```
//!
//! with `masked(crc) = ((crc >> 15) | (crc << 17)) + 0xa282ead8` (wrapping).
//!
//! Each record's data is one `tf.train.SequenceExample` (protobuf, encoded by hand here), as
//! `learning_to_simulate/reading_utils.py` parses it:
//!
//! - context feature `key`: `int64_list` holding the trajectory's index (on import any value is
//!   accepted; keys other than 0, 1, ... are kept in the metadata);
//! - context feature `particle_type`: `bytes_list` with one value, the raw little-endian bytes of
//!   the `int64` types `[n]`;
//! - context feature `seed`: `int64_list`, the generator's seed (ours; DeepMind's parser ignores
//!   context features it does not ask for, and files without it import with seed 0);
//! - feature list `position`: one `Feature` per frame, each a `bytes_list` with one value, the
//!   raw little-endian `float32` bytes of `[n, dim]`.
//!
//! Protobuf field numbers (tensorflow `example.proto`, `feature.proto`):
//! `SequenceExample { Features context = 1; FeatureLists feature_lists = 2; }`,
//! `Features { map<string, Feature> feature = 1; }`,
//! `FeatureLists { map<string, FeatureList> feature_list = 1; }`,
//! `FeatureList { repeated Feature feature = 1; }`,
//! `Feature { oneof { BytesList bytes_list = 1; FloatList float_list = 2; Int64List int64_list
//! = 3; } }`, `BytesList { repeated bytes value = 1; }`, `Int64List { repeated int64 value = 1
//! [packed]; }`; a map entry is a message `{ key = 1; value = 2; }`.
//!
//! # Particle types
//!
//! On export ours become DeepMind's: obstacle 0 → 3 (`KINEMATIC_PARTICLE_ID`), liquid 1 → 5
//! (water); on import 3 → 0 and 5 → 1, and any other type is an error naming the record.
//!
//! # Metadata
//!
//! The export writes our full `metadata.json` beside the `.tfrecord` files (a superset of
//! DeepMind's keys, which their code reads). The import reads either ours or DeepMind's; for
//! DeepMind's, the statistics and other DeepMind keys are taken as they are, the splits are the
//! `train`, `valid` and `test` files present, and `position_scale` / `position_offset` are 1 and
//! 0 (the original units are unknown).

use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};

use phi_io::{IoError, write_atomic};

use super::metadata::{FORMAT, METADATA_FILE};
use super::{
    DataError, Dataset, LIQUID, Metadata, OBSTACLE, SPLITS, Trajectory, TrajectoryStats,
    write_metadata, write_trajectory,
};

/// DeepMind's particle type of kinematic (obstacle, boundary) particles.
pub(crate) const DEEPMIND_KINEMATIC: i64 = 3;
/// DeepMind's particle type of water.
pub(crate) const DEEPMIND_WATER: i64 = 5;

/// Our particle type ([`OBSTACLE`], [`LIQUID`]) as DeepMind's; `None` for other values.
pub(crate) fn to_deepmind_type(t: i64) -> Option<i64> {
    match t {
        OBSTACLE => Some(DEEPMIND_KINEMATIC),
        LIQUID => Some(DEEPMIND_WATER),
        _ => None,
    }
}

/// DeepMind's particle type as ours; `None` for types other than kinematic and water.
pub(crate) fn from_deepmind_type(t: i64) -> Option<i64> {
    match t {
        DEEPMIND_KINEMATIC => Some(OBSTACLE),
        DEEPMIND_WATER => Some(LIQUID),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------------
// CRC-32C and record framing

/// The CRC-32C (Castagnoli, reflected polynomial `0x82F63B78`) of `data`
/// (`crc32c(b"123456789") == 0xE3069283`), with the CPU's CRC instructions where it has them
/// (SSE 4.2, ARMv8).
pub(crate) fn crc32c(data: &[u8]) -> u32 {
    crc32c::crc32c(data)
}

/// TFRecord's masked CRC-32C: `((crc >> 15) | (crc << 17)) + 0xa282ead8`.
pub(crate) fn masked_crc32c(data: &[u8]) -> u32 {
    let crc = crc32c(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// Frames one record: length, masked CRC of the length, data, masked CRC of the data.
pub(crate) fn write_record(w: &mut impl Write, data: &[u8]) -> std::io::Result<()> {
    let len = (data.len() as u64).to_le_bytes();
    w.write_all(&len)?;
    w.write_all(&masked_crc32c(&len).to_le_bytes())?;
    w.write_all(data)?;
    w.write_all(&masked_crc32c(data).to_le_bytes())
}

/// Reads the records of one TFRecord file in order, checking both CRCs of each.
pub(crate) struct RecordReader {
    reader: BufReader<File>,
    path: PathBuf,
    /// Bytes left in the file, which bounds a record's claimed length.
    remaining: u64,
    record: u64,
}

impl RecordReader {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<Self, DataError> {
        let file = File::open(path).map_err(|e| DataError::io(path, "cannot open", e))?;
        let remaining = file
            .metadata()
            .map_err(|e| DataError::io(path, "cannot read the metadata of", e))?
            .len();
        Ok(RecordReader {
            reader: BufReader::new(file),
            path: path.to_path_buf(),
            remaining,
            record: 0,
        })
    }

    fn error(&self, reason: impl Into<String>) -> DataError {
        DataError::Record {
            path: self.path.clone(),
            record: self.record,
            reason: reason.into(),
        }
    }

    fn read_exact(&mut self, buf: &mut [u8], what: &str) -> Result<(), DataError> {
        if (buf.len() as u64) > self.remaining {
            return Err(self.error(format!("truncated: the file ends inside the {what}")));
        }
        self.reader.read_exact(buf).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                self.error(format!("truncated: the file ends inside the {what}"))
            } else {
                DataError::io(&self.path, "cannot read", e)
            }
        })?;
        self.remaining -= buf.len() as u64;
        Ok(())
    }

    /// The number of the record the next [`RecordReader::next_record`] returns.
    pub(crate) fn record_number(&self) -> u64 {
        self.record
    }

    /// The data of the next record, `None` at the end of the file.
    pub(crate) fn next_record(&mut self) -> Result<Option<Vec<u8>>, DataError> {
        if self.remaining == 0 {
            return Ok(None);
        }
        let mut header = [0u8; 12];
        self.read_exact(&mut header, "record header")?;
        let (len_bytes, len_crc) = header.split_at(8);
        let len_crc = u32::from_le_bytes([len_crc[0], len_crc[1], len_crc[2], len_crc[3]]);
        if masked_crc32c(len_bytes) != len_crc {
            return Err(self.error("the CRC-32C of the length does not match"));
        }
        let mut len = [0u8; 8];
        len.copy_from_slice(len_bytes);
        let len = u64::from_le_bytes(len);
        if len.saturating_add(4) > self.remaining {
            return Err(self.error(format!(
                "truncated: the record claims {len} bytes but {} remain",
                self.remaining
            )));
        }
        // Bounded by the file's remaining length, checked above.
        let mut data = vec![0u8; len as usize];
        self.read_exact(&mut data, "record data")?;
        let mut crc = [0u8; 4];
        self.read_exact(&mut crc, "record data CRC")?;
        if masked_crc32c(&data) != u32::from_le_bytes(crc) {
            return Err(self.error("the CRC-32C of the data does not match"));
        }
        self.record += 1;
        Ok(Some(data))
    }
}

// ---------------------------------------------------------------------------------------------
// Protobuf encoding

const WIRE_VARINT: u64 = 0;
const WIRE_FIXED64: u64 = 1;
const WIRE_LEN: u64 = 2;
const WIRE_FIXED32: u64 = 5;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_len_field(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    put_varint(out, (field << 3) | WIRE_LEN);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// `Feature { bytes_list = 1: BytesList { value = 1: bytes } }` holding one value.
fn bytes_feature(value: &[u8]) -> Vec<u8> {
    let mut list = Vec::with_capacity(value.len() + 10);
    put_len_field(&mut list, 1, value);
    let mut feature = Vec::with_capacity(list.len() + 10);
    put_len_field(&mut feature, 1, &list);
    feature
}

/// `Feature { int64_list = 3: Int64List { value = 1: packed int64 } }`.
fn int64_feature(values: &[i64]) -> Vec<u8> {
    let mut packed = Vec::new();
    for &v in values {
        put_varint(&mut packed, v as u64);
    }
    let mut list = Vec::new();
    put_len_field(&mut list, 1, &packed);
    let mut feature = Vec::new();
    put_len_field(&mut feature, 3, &list);
    feature
}

/// A map entry `{ key = 1: string, value = 2: message }`.
fn map_entry(key: &str, value: &[u8]) -> Vec<u8> {
    let mut entry = Vec::with_capacity(key.len() + value.len() + 20);
    put_len_field(&mut entry, 1, key.as_bytes());
    put_len_field(&mut entry, 2, value);
    entry
}

/// The `tf.train.SequenceExample` of one trajectory (see the module docs); particle types are
/// mapped to DeepMind's.
pub(crate) fn encode_sequence_example(traj: &Trajectory) -> Vec<u8> {
    let types: Vec<u8> = traj
        .particle_type
        .iter()
        .flat_map(|&t| to_deepmind_type(t).unwrap_or(t).to_le_bytes())
        .collect();
    let mut context = Vec::new();
    put_len_field(
        &mut context,
        1,
        &map_entry("key", &int64_feature(&[traj.index as i64])),
    );
    put_len_field(
        &mut context,
        1,
        &map_entry("particle_type", &bytes_feature(&types)),
    );
    put_len_field(
        &mut context,
        1,
        &map_entry("seed", &int64_feature(&[traj.seed as i64])),
    );

    let mut feature_list = Vec::with_capacity(traj.position.len() * 4 + traj.frames * 16);
    let mut frame_bytes = Vec::with_capacity(traj.particles * traj.dim * 4);
    for t in 0..traj.frames {
        frame_bytes.clear();
        frame_bytes.extend(traj.frame(t).iter().flat_map(|x| x.to_le_bytes()));
        put_len_field(&mut feature_list, 1, &bytes_feature(&frame_bytes));
    }
    let mut feature_lists = Vec::with_capacity(feature_list.len() + 32);
    put_len_field(&mut feature_lists, 1, &map_entry("position", &feature_list));

    let mut example = Vec::with_capacity(context.len() + feature_lists.len() + 16);
    put_len_field(&mut example, 1, &context);
    put_len_field(&mut example, 2, &feature_lists);
    example
}

// ---------------------------------------------------------------------------------------------
// Protobuf decoding

/// One field of a protobuf message.
enum Value<'a> {
    Varint(u64),
    Len(&'a [u8]),
    Fixed,
}

/// Iterates over the fields of a protobuf message; `Err` carries what is wrong.
struct Message<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Message<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Message { bytes, pos: 0 }
    }

    fn varint(&mut self) -> Result<u64, String> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let Some(&byte) = self.bytes.get(self.pos) else {
                return Err("truncated varint".into());
            };
            self.pos += 1;
            v |= u64::from(byte & 0x7F) << shift;
            if byte & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err("varint longer than 10 bytes".into())
    }

    fn take(&mut self, n: u64) -> Result<&'a [u8], String> {
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| self.pos.checked_add(n))
            .filter(|&end| end <= self.bytes.len())
            .ok_or_else(|| format!("a field of {n} bytes runs past the end of its message"))?;
        let out = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(out)
    }

    /// The next `(field number, value)`, `None` at the end.
    fn next_field(&mut self) -> Result<Option<(u64, Value<'a>)>, String> {
        if self.pos >= self.bytes.len() {
            return Ok(None);
        }
        let tag = self.varint()?;
        let field = tag >> 3;
        let value = match tag & 7 {
            WIRE_VARINT => Value::Varint(self.varint()?),
            WIRE_FIXED64 => {
                self.take(8)?;
                Value::Fixed
            }
            WIRE_LEN => {
                let len = self.varint()?;
                Value::Len(self.take(len)?)
            }
            WIRE_FIXED32 => {
                self.take(4)?;
                Value::Fixed
            }
            wire => return Err(format!("unsupported protobuf wire type {wire}")),
        };
        Ok(Some((field, value)))
    }

    /// Every length-delimited value of `field` (other fields skipped).
    fn len_fields(bytes: &'a [u8], field: u64) -> Result<Vec<&'a [u8]>, String> {
        let mut message = Message::new(bytes);
        let mut out = Vec::new();
        while let Some((number, value)) = message.next_field()? {
            if number == field {
                match value {
                    Value::Len(b) => out.push(b),
                    _ => return Err(format!("field {field} is not length-delimited")),
                }
            }
        }
        Ok(out)
    }
}

/// The entries `(key, value message)` of a `map<string, Message> = 1` field.
fn map_entries(bytes: &[u8]) -> Result<Vec<(String, &[u8])>, String> {
    let mut out = Vec::new();
    for entry in Message::len_fields(bytes, 1)? {
        let mut key = String::new();
        let mut value: &[u8] = &[];
        let mut message = Message::new(entry);
        while let Some((number, field)) = message.next_field()? {
            match (number, field) {
                (1, Value::Len(b)) => {
                    key = String::from_utf8(b.to_vec())
                        .map_err(|_| "a feature name is not UTF-8".to_string())?;
                }
                (2, Value::Len(b)) => value = b,
                _ => {}
            }
        }
        out.push((key, value));
    }
    Ok(out)
}

/// A decoded `Feature`.
enum Feature {
    Bytes(Vec<u8>),
    Int64(Vec<i64>),
    Float,
    Empty,
}

/// Decodes a `Feature`; the values of a `bytes_list` are concatenated (as DeepMind's reader
/// does).
fn decode_feature(bytes: &[u8]) -> Result<Feature, String> {
    let mut message = Message::new(bytes);
    let mut feature = Feature::Empty;
    while let Some((number, value)) = message.next_field()? {
        let Value::Len(list) = value else {
            return Err(format!("Feature field {number} is not a list"));
        };
        feature = match number {
            1 => Feature::Bytes(Message::len_fields(list, 1)?.concat()),
            2 => Feature::Float,
            3 => {
                let mut values = Vec::new();
                let mut list = Message::new(list);
                while let Some((number, value)) = list.next_field()? {
                    match (number, value) {
                        (1, Value::Varint(v)) => values.push(v as i64),
                        (1, Value::Len(packed)) => {
                            let mut packed = Message::new(packed);
                            while packed.pos < packed.bytes.len() {
                                values.push(packed.varint()? as i64);
                            }
                        }
                        _ => {}
                    }
                }
                Feature::Int64(values)
            }
            _ => feature,
        };
    }
    Ok(feature)
}

/// Decodes one record of the `learning_to_simulate` format into a trajectory of `dim`
/// dimensions; `index` is used when the record has no `key`. Particle types are mapped from
/// DeepMind's to ours. `path` and `record` name the record in errors.
#[cfg(test)]
pub(crate) fn decode_sequence_example(
    bytes: &[u8],
    dim: usize,
    index: usize,
    path: &Path,
    record: u64,
) -> Result<Trajectory, DataError> {
    let (mut traj, key) = decode_record(bytes, dim, index, path, record)?;
    if let Some(k) = key {
        traj.index = usize::try_from(k).map_err(|_| DataError::Record {
            path: path.to_path_buf(),
            record,
            reason: format!("'key' is negative ({k})"),
        })?;
    }
    Ok(traj)
}

/// Decodes one record into a trajectory with index `index` and the value of its `key` context
/// feature, if it has one (any value: DeepMind's reader ignores it).
pub(crate) fn decode_record(
    bytes: &[u8],
    dim: usize,
    index: usize,
    path: &Path,
    record: u64,
) -> Result<(Trajectory, Option<i64>), DataError> {
    let error = |reason: String| DataError::Record {
        path: path.to_path_buf(),
        record,
        reason,
    };
    let mut key = None;
    let mut seed = 0u64;
    let mut types = None;
    let mut frames = Vec::new();
    let contexts = Message::len_fields(bytes, 1).map_err(&error)?;
    for context in contexts {
        for (name, value) in map_entries(context).map_err(&error)? {
            match (name.as_str(), decode_feature(value).map_err(&error)?) {
                ("key", Feature::Int64(v)) if v.len() == 1 => key = Some(v[0]),
                ("seed", Feature::Int64(v)) if v.len() == 1 => seed = v[0] as u64,
                ("particle_type", Feature::Bytes(b)) => types = Some(b),
                ("key" | "seed" | "particle_type", _) => {
                    return Err(error(format!(
                        "context feature '{name}' has the wrong type"
                    )));
                }
                _ => {}
            }
        }
    }
    for lists in Message::len_fields(bytes, 2).map_err(&error)? {
        for (name, value) in map_entries(lists).map_err(&error)? {
            if name != "position" {
                continue;
            }
            for feature in Message::len_fields(value, 1).map_err(&error)? {
                match decode_feature(feature).map_err(&error)? {
                    Feature::Bytes(b) => frames.push(b),
                    _ => return Err(error("a 'position' frame is not a bytes_list".into())),
                }
            }
        }
    }
    let types = types.ok_or_else(|| error("no context feature 'particle_type'".into()))?;
    if !types.len().is_multiple_of(8) {
        return Err(error(format!(
            "'particle_type' has {} bytes, not a whole number of int64",
            types.len()
        )));
    }
    let particle_type = types
        .chunks_exact(8)
        .enumerate()
        .map(|(i, b)| {
            let mut a = [0u8; 8];
            a.copy_from_slice(b);
            let t = i64::from_le_bytes(a);
            from_deepmind_type(t).ok_or_else(|| {
                error(format!(
                    "particle {i} has DeepMind type {t} (only {DEEPMIND_KINEMATIC} = kinematic \
                     and {DEEPMIND_WATER} = water are supported)"
                ))
            })
        })
        .collect::<Result<Vec<i64>, DataError>>()?;
    if frames.is_empty() {
        return Err(error("no feature list 'position'".into()));
    }
    let frame_bytes = particle_type.len() * dim * 4;
    if let Some(t) = frames.iter().position(|f| f.len() != frame_bytes) {
        return Err(error(format!(
            "'position' frame {t} has {} bytes; {} particles in {dim}D need {frame_bytes}",
            frames[t].len(),
            particle_type.len()
        )));
    }
    let position: Vec<f32> = frames
        .iter()
        .flat_map(|f| f.chunks_exact(4))
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let traj = Trajectory::new(dim, position, particle_type, seed, index)
        .map_err(|e| error(e.to_string()))?;
    Ok((traj, key))
}

// ---------------------------------------------------------------------------------------------
// Export and import

/// The TFRecord file of `split` in `dir`: `dir/{split}.tfrecord`.
pub(crate) fn tfrecord_path(dir: &Path, split: &str) -> PathBuf {
    dir.join(format!("{split}.tfrecord"))
}

/// Writes every split of `dataset` to `out_dir/{split}.tfrecord` (one record per trajectory, in
/// index order, one trajectory in memory at a time) and the dataset's `metadata.json` beside
/// them. Each file is written atomically.
pub fn export_tfrecord(dataset: &Dataset, out_dir: &Path) -> Result<(), DataError> {
    std::fs::create_dir_all(out_dir)
        .map_err(|e| DataError::io(out_dir, "cannot create the directory", e))?;
    for split in dataset.metadata().splits.keys() {
        let path = tfrecord_path(out_dir, split);
        let reader = dataset.split(split)?;
        write_atomic(&path, |w| {
            for traj in reader {
                let data = encode_sequence_example(&traj?);
                write_record(w, &data).map_err(|e| IoError::io(&path, "cannot write", e))?;
            }
            Ok::<(), DataError>(())
        })?;
    }
    write_metadata(out_dir, dataset.metadata())
}

/// The DeepMind keys of `metadata.json`.
#[derive(serde::Deserialize)]
struct DeepMindMetadata {
    bounds: Vec<[f64; 2]>,
    sequence_length: usize,
    default_connectivity_radius: f64,
    dim: usize,
    dt: f64,
    vel_mean: Vec<f64>,
    vel_std: Vec<f64>,
    acc_mean: Vec<f64>,
    acc_std: Vec<f64>,
}

/// Reads `metadata.json` of a TFRecord directory: ours if its `format` says so, else DeepMind's
/// keys completed with ours (splits to be filled in).
fn read_tfrecord_metadata(dir: &Path) -> Result<(Metadata, bool), DataError> {
    let path = dir.join(METADATA_FILE);
    let text =
        std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, "cannot read", e))?;
    let json = |source| DataError::Json {
        path: path.clone(),
        source,
    };
    let value: serde_json::Value = serde_json::from_str(&text).map_err(json)?;
    if value.get("format").and_then(|f| f.as_str()) == Some(FORMAT) {
        let metadata: Metadata = serde_json::from_value(value).map_err(json)?;
        metadata.validate(&path)?;
        return Ok((metadata, true));
    }
    let dm: DeepMindMetadata = serde_json::from_value(value).map_err(json)?;
    let mut metadata = Metadata::new(dm.dim);
    metadata.bounds = dm.bounds;
    metadata.sequence_length = dm.sequence_length;
    metadata.default_connectivity_radius = dm.default_connectivity_radius;
    metadata.dt = dm.dt;
    metadata.vel_mean = dm.vel_mean;
    metadata.vel_std = dm.vel_std;
    metadata.acc_mean = dm.acc_mean;
    metadata.acc_std = dm.acc_std;
    metadata.position_scale = 1.0;
    metadata.position_offset = 0.0;
    metadata.generator = serde_json::json!({ "imported_from": dir.display().to_string() });
    metadata.validate(&path)?;
    Ok((metadata, false))
}

/// Records the `key` features of splits whose keys are not their record numbers as
/// `generator.tfrecord_keys.{split}` (a list, `null` for a record without a key), keeping the
/// rest of `generator` (an earlier value that is not an object goes to `generator.previous`).
fn keep_foreign_keys(metadata: &mut Metadata, keys: serde_json::Map<String, serde_json::Value>) {
    let mut generator = match std::mem::take(&mut metadata.generator) {
        serde_json::Value::Object(map) => map,
        serde_json::Value::Null => serde_json::Map::new(),
        other => serde_json::Map::from_iter([("previous".to_string(), other)]),
    };
    generator.insert("tfrecord_keys".into(), serde_json::Value::Object(keys));
    metadata.generator = serde_json::Value::Object(generator);
}

/// Imports the TFRecord directory `in_dir` (`metadata.json` and `{split}.tfrecord` files,
/// written by [`export_tfrecord`] or by DeepMind) as a dataset in `out_dir`, and opens it.
///
/// With our metadata the splits it lists are read; with DeepMind's, whichever of
/// `train`, `valid` and `test` have a file. Trajectory `i` of a split is record `i`; each gets
/// its statistics computed from its positions. The `key` feature is not needed and may hold any
/// value, as in DeepMind's reader, which ignores it; keys other than 0, 1, ... are kept in the
/// metadata as `generator.tfrecord_keys.{split}`. Every record must have `sequence_length + 1`
/// frames; a damaged, truncated or malformed record is a [`DataError::Record`] naming the file
/// and the record's number.
///
/// `out_dir` must be absent or empty ([`DataError::NotEmpty`] otherwise), so that an import never
/// overwrites a dataset or mixes with one; a failed import leaves a partial `out_dir` without
/// `metadata.json` (`phi dataset import` imports into a staging directory and moves it into place
/// only when complete).
pub fn import_tfrecord(in_dir: &Path, out_dir: &Path) -> Result<Dataset, DataError> {
    import_tfrecord_with(in_dir, out_dir, &|| {})
}

/// [`import_tfrecord`], calling `imported` after each trajectory is written (a progress bar's
/// tick).
///
/// # Errors
/// As [`import_tfrecord`].
pub fn import_tfrecord_with(
    in_dir: &Path,
    out_dir: &Path,
    imported: &dyn Fn(),
) -> Result<Dataset, DataError> {
    if let Ok(mut entries) = std::fs::read_dir(out_dir)
        && entries.next().is_some()
    {
        return Err(DataError::NotEmpty {
            path: out_dir.to_path_buf(),
        });
    }
    let (mut metadata, ours) = read_tfrecord_metadata(in_dir)?;
    let splits: Vec<String> = if ours {
        metadata.splits.keys().cloned().collect()
    } else {
        SPLITS
            .iter()
            .filter(|s| tfrecord_path(in_dir, s).is_file())
            .map(|s| s.to_string())
            .collect()
    };
    let mut foreign_keys = serde_json::Map::new();
    for split in &splits {
        let path = tfrecord_path(in_dir, split);
        let split_dir = out_dir.join(split);
        std::fs::create_dir_all(&split_dir)
            .map_err(|e| DataError::io(&split_dir, "cannot create the directory", e))?;
        let mut records = RecordReader::open(&path)?;
        let mut count = 0;
        let mut keys = Vec::new();
        loop {
            let record = records.record_number();
            let Some(data) = records.next_record()? else {
                break;
            };
            let (traj, key) = decode_record(&data, metadata.dim, count, &path, record)?;
            keys.push(key);
            let bad = |reason: String| DataError::Record {
                path: path.clone(),
                record,
                reason,
            };
            if traj.frames != metadata.frames() {
                return Err(bad(format!(
                    "{} frames, but the metadata's sequence_length {} needs {}",
                    traj.frames,
                    metadata.sequence_length,
                    metadata.frames()
                )));
            }
            let stats = TrajectoryStats::of(&traj);
            write_trajectory(
                &Dataset::trajectory_path(out_dir, split, count),
                &traj,
                &stats,
            )?;
            imported();
            count += 1;
        }
        if ours && metadata.splits.get(split) != Some(&count) {
            return Err(DataError::metadata(
                &path,
                format!("splits.{split}"),
                format!(
                    "the metadata lists {:?} trajectories but the file holds {count} records",
                    metadata.splits.get(split)
                ),
            ));
        }
        metadata.splits.insert(split.clone(), count);
        let in_order = keys
            .iter()
            .enumerate()
            .all(|(i, k)| *k == Some(i as i64) || k.is_none());
        if !in_order {
            foreign_keys.insert(split.clone(), serde_json::json!(keys));
        }
    }
    if !foreign_keys.is_empty() {
        keep_foreign_keys(&mut metadata, foreign_keys);
    }
    write_metadata(out_dir, &metadata)?;
    Dataset::open(out_dir)
}

#[cfg(test)]
#[path = "tfrecord_tests.rs"]
mod tests;
