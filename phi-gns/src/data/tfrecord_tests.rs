//! Tests of DeepMind TFRecords: CRC-32C, record framing, protobuf layout, round trips and damage.

use super::{
    RecordReader, crc32c, decode_sequence_example, encode_sequence_example, export_tfrecord,
    import_tfrecord, masked_crc32c, tfrecord_path, write_record,
};
use crate::data::{DataError, Dataset, LIQUID, OBSTACLE, Trajectory, read_metadata};

use crate::test_data::{temp_dir, write_sample_dataset};

#[test]
fn crc32c_matches_the_check_value() {
    assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    assert_eq!(crc32c(b""), 0);
    // Computed independently (bitwise CRC-32C and the mask formula in Python).
    assert_eq!(masked_crc32c(b"abc"), 0x21f1_576e);
}

#[test]
fn a_record_is_framed_as_tensorflow_frames_it() {
    // Computed independently (bitwise CRC-32C in Python) for the data "abc".
    let expected = [
        0x03, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xb0, 0x99, 0x49, 0x0e, 0x61, 0x62, 0x63,
        0x6e, 0x57, 0xf1, 0x21,
    ];
    let mut out = Vec::new();
    write_record(&mut out, b"abc").unwrap();
    assert_eq!(out, expected);
}

#[test]
fn a_sequence_example_has_the_protobuf_layout_of_learning_to_simulate() {
    // One liquid particle, one frame at x = 1.0 in 1D, index 2, seed 7, encoded by hand from
    // example.proto / feature.proto (field numbers and wire types in the comments).
    let traj = Trajectory::new(1, vec![1.0], vec![LIQUID], 7, 2).unwrap();
    let mut expected: Vec<u8> = Vec::new();
    // SequenceExample.context (1, LEN 60): Features.feature (1) map entries.
    expected.extend([0x0a, 60]);
    // {key = "key", value = Feature{int64_list (3) = Int64List{value (1) packed = [2]}}}
    expected.extend([
        0x0a, 12, 0x0a, 3, b'k', b'e', b'y', 0x12, 5, 0x1a, 3, 0x0a, 1, 2,
    ]);
    // {key = "particle_type", value = Feature{bytes_list (1) = BytesList{value (1) = i64 LE 5}}}
    expected.extend([0x0a, 29, 0x0a, 13]);
    expected.extend(b"particle_type");
    expected.extend([0x12, 12, 0x0a, 10, 0x0a, 8, 5, 0, 0, 0, 0, 0, 0, 0]);
    // {key = "seed", value = Feature{int64_list = [7]}}
    expected.extend([
        0x0a, 13, 0x0a, 4, b's', b'e', b'e', b'd', 0x12, 5, 0x1a, 3, 0x0a, 1, 7,
    ]);
    // SequenceExample.feature_lists (2, LEN 24): FeatureLists.feature_list (1) map entry
    // {key = "position", value = FeatureList{feature (1) = Feature{bytes_list = [f32 LE 1.0]}}}
    expected.extend([0x12, 24, 0x0a, 22, 0x0a, 8]);
    expected.extend(b"position");
    expected.extend([0x12, 10, 0x0a, 8, 0x0a, 6, 0x0a, 4, 0x00, 0x00, 0x80, 0x3f]);
    let encoded = encode_sequence_example(&traj);
    assert_eq!(encoded, expected);
    let path = std::path::Path::new("hand.tfrecord");
    assert_eq!(
        decode_sequence_example(&encoded, 1, 0, path, 0).unwrap(),
        traj
    );
}

#[test]
fn decoding_accepts_unpacked_int64_and_rejects_foreign_particle_types() {
    let path = std::path::Path::new("x.tfrecord");
    // key as an unpacked varint (wire type 0), particle_type DeepMind 3 (kinematic), 2 frames,
    // no seed.
    let mut entry = vec![0x0a, 3, b'k', b'e', b'y', 0x12, 4, 0x1a, 2, 0x08, 4];
    let mut types_entry = vec![0x0a, 13];
    types_entry.extend(b"particle_type");
    types_entry.extend([0x12, 12, 0x0a, 10, 0x0a, 8, 3, 0, 0, 0, 0, 0, 0, 0]);
    let mut context = vec![0x0a, entry.len() as u8];
    context.append(&mut entry);
    context.extend([0x0a, types_entry.len() as u8]);
    context.extend(&types_entry);
    let mut list = Vec::new();
    for x in [0.25f32, 0.5] {
        let mut feature = vec![0x0a, 6, 0x0a, 4];
        feature.extend(x.to_le_bytes());
        list.extend([0x0a, feature.len() as u8]);
        list.extend(feature);
    }
    let mut lists_entry = vec![0x0a, 8];
    lists_entry.extend(b"position");
    lists_entry.extend([0x12, list.len() as u8]);
    lists_entry.extend(&list);
    let mut example = vec![0x0a, context.len() as u8];
    example.extend(&context);
    example.extend([
        0x12,
        lists_entry.len() as u8 + 2,
        0x0a,
        lists_entry.len() as u8,
    ]);
    example.extend(&lists_entry);
    let traj = decode_sequence_example(&example, 1, 9, path, 3).unwrap();
    assert_eq!(traj.index, 4);
    assert_eq!(traj.particle_type, [OBSTACLE]);
    assert_eq!(traj.position, [0.25, 0.5]);
    assert_eq!(traj.seed, 0, "no seed feature: seed 0");

    // Sand (DeepMind type 6) has no equivalent here.
    let mut sand = example.clone();
    let type_at = sand
        .windows(13)
        .position(|w| w == b"particle_type")
        .unwrap()
        + 13
        + 6;
    assert_eq!(sand[type_at], 3);
    sand[type_at] = 6;
    let err = decode_sequence_example(&sand, 1, 0, path, 3).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, DataError::Record { record: 3, .. }), "{msg}");
    assert!(
        msg.contains("x.tfrecord") && msg.contains("type 6"),
        "{msg}"
    );

    // Garbage does not panic.
    for len in 0..example.len() {
        let _ = decode_sequence_example(&example[..len], 1, 0, path, 0);
    }
    assert!(decode_sequence_example(&[0xff; 20], 1, 0, path, 0).is_err());
}

#[test]
fn dataset_to_tfrecord_to_dataset_is_identical() {
    let dir = temp_dir("tfrecord-round-trip");
    let (original, records, imported) = (dir.join("a"), dir.join("tf"), dir.join("b"));
    let written = write_sample_dataset(&original, &[("train", 3), ("valid", 2), ("test", 1)], 7, 2);
    let dataset = Dataset::open(&original).unwrap();
    export_tfrecord(&dataset, &records).unwrap();
    for split in ["train", "valid", "test"] {
        assert!(tfrecord_path(&records, split).is_file());
    }
    let back = import_tfrecord(&records, &imported).unwrap();
    assert_eq!(back.metadata(), dataset.metadata());
    for (split, expected) in ["train", "valid", "test"].into_iter().zip(&written) {
        let read: Vec<Trajectory> = back.split(split).unwrap().map(Result::unwrap).collect();
        assert_eq!(&read, expected, "{split}");
        assert_eq!(
            back.split_statistics(split).unwrap(),
            dataset.split_statistics(split).unwrap()
        );
    }
    // The records hold DeepMind's particle types.
    let mut reader = RecordReader::open(&tfrecord_path(&records, "train")).unwrap();
    let first = reader.next_record().unwrap().unwrap();
    let water = 5i64.to_le_bytes();
    let kinematic = 3i64.to_le_bytes();
    let types_at = first
        .windows(13)
        .position(|w| w == b"particle_type")
        .unwrap()
        + 13
        + 6;
    assert_eq!(first[types_at..types_at + 8], water);
    let n = written[0][0].particles;
    assert_eq!(first[types_at + 8 * (n - 1)..types_at + 8 * n], kinematic);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `metadata.json` as DeepMind writes it (no splits, seeds or position scale), for
/// trajectories of `sequence_length + 1` frames in 2D.
fn deepmind_metadata(sequence_length: usize) -> serde_json::Value {
    serde_json::json!({
        "bounds": [[0.1, 0.9], [0.1, 0.9]],
        "sequence_length": sequence_length,
        "default_connectivity_radius": 0.015,
        "dim": 2,
        "dt": 0.0025,
        "vel_mean": [1e-5, -2e-4],
        "vel_std": [1e-3, 1e-3],
        "acc_mean": [0.0, -1e-5],
        "acc_std": [1e-4, 1e-4],
    })
}

#[test]
fn deepmind_metadata_imports_with_its_own_statistics() {
    let dir = temp_dir("tfrecord-deepmind");
    let (original, records, imported) = (dir.join("a"), dir.join("tf"), dir.join("b"));
    write_sample_dataset(&original, &[("train", 2), ("valid", 1)], 5, 2);
    export_tfrecord(&Dataset::open(&original).unwrap(), &records).unwrap();
    let deepmind = deepmind_metadata(4);
    std::fs::write(records.join("metadata.json"), deepmind.to_string()).unwrap();
    let back = import_tfrecord(&records, &imported).unwrap();
    let m = back.metadata();
    assert_eq!((m.dt, m.default_connectivity_radius), (0.0025, 0.015));
    assert_eq!(m.vel_mean, [1e-5, -2e-4]);
    assert_eq!((m.position_scale, m.position_offset), (1.0, 0.0));
    assert_eq!(m.splits.get("train"), Some(&2));
    assert_eq!(m.splits.get("valid"), Some(&1));
    assert_eq!(m.splits.get("test"), None);
    assert_eq!(read_metadata(&imported).unwrap(), *m);

    // A record of the wrong length for the metadata's sequence_length is refused.
    let mut short = deepmind.clone();
    short["sequence_length"] = 9.into();
    std::fs::write(records.join("metadata.json"), short.to_string()).unwrap();
    let err = import_tfrecord(&records, &dir.join("c")).unwrap_err();
    assert!(matches!(err, DataError::Record { record: 0, .. }), "{err}");
    assert!(err.to_string().contains("5 frames"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn damaged_and_truncated_records_name_the_file_and_record() {
    let dir = temp_dir("tfrecord-damage");
    let (original, records) = (dir.join("a"), dir.join("tf"));
    write_sample_dataset(&original, &[("train", 3)], 5, 2);
    export_tfrecord(&Dataset::open(&original).unwrap(), &records).unwrap();
    let path = tfrecord_path(&records, "train");
    let good = std::fs::read(&path).unwrap();
    let first_len = u64::from_le_bytes(good[..8].try_into().unwrap()) as usize;
    let second = 8 + 4 + first_len + 4;

    let read_all = || -> Result<usize, DataError> {
        let mut reader = RecordReader::open(&path)?;
        let mut n = 0;
        while reader.next_record()?.is_some() {
            n += 1;
        }
        Ok(n)
    };
    assert_eq!(read_all().unwrap(), 3);

    let cases: [(usize, u64, &str); 3] = [
        (second + 20, 1, "CRC-32C of the data"),
        (second + 3, 1, "CRC-32C of the length"),
        (5, 0, "CRC-32C of the length"),
    ];
    for (at, record, reason) in cases {
        let mut bad = good.clone();
        bad[at] ^= 0x04;
        std::fs::write(&path, &bad).unwrap();
        let err = read_all().unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, DataError::Record { record: r, .. } if r == record),
            "{msg}"
        );
        assert!(
            msg.contains("train.tfrecord") && msg.contains(reason),
            "{msg}"
        );
        // The import fails too, naming the same record.
        let imported = import_tfrecord(&records, &dir.join(format!("out-{at}")));
        assert!(
            imported
                .unwrap_err()
                .to_string()
                .contains(&format!("record {record}"))
        );
    }
    for len in [1, 11, second - 1, second + 8, good.len() - 1] {
        std::fs::write(&path, &good[..len]).unwrap();
        let msg = read_all().unwrap_err().to_string();
        assert!(
            msg.contains("train.tfrecord") && msg.contains("truncated"),
            "{len}: {msg}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn records_whose_keys_are_not_their_positions_import_in_file_order_with_the_keys_kept() {
    // DeepMind's reader ignores the `key` feature, so a file whose records are not keyed 0, 1, …
    // (here the train records in reverse order: keys 2, 1, 0) is a valid dataset.
    let dir = temp_dir("tfrecord-foreign-keys");
    let (original, records, imported) = (dir.join("a"), dir.join("tf"), dir.join("b"));
    let written = write_sample_dataset(&original, &[("train", 3), ("test", 1)], 5, 2);
    export_tfrecord(&Dataset::open(&original).unwrap(), &records).unwrap();
    let path = tfrecord_path(&records, "train");
    let mut reader = RecordReader::open(&path).unwrap();
    let mut all = Vec::new();
    while let Some(record) = reader.next_record().unwrap() {
        all.push(record);
    }
    let mut file = std::fs::File::create(&path).unwrap();
    for record in all.iter().rev() {
        write_record(&mut file, record).unwrap();
    }
    drop(file);
    // DeepMind's metadata, which has no split seeds to check the stored ones against.
    let deepmind = deepmind_metadata(4);
    std::fs::write(records.join("metadata.json"), deepmind.to_string()).unwrap();

    let back = import_tfrecord(&records, &imported).unwrap();
    let read: Vec<Trajectory> = back.split("train").unwrap().map(Result::unwrap).collect();
    assert_eq!(read.len(), 3);
    for (i, (got, want)) in read.iter().zip(written[0].iter().rev()).enumerate() {
        assert_eq!(got.index, i, "trajectory i is record i");
        assert_eq!(
            (&got.position, &got.particle_type),
            (&want.position, &want.particle_type)
        );
        assert_eq!(
            got.seed, want.seed,
            "the stored seed travels with its record"
        );
    }
    let keys = &back.metadata().generator["tfrecord_keys"];
    assert_eq!(keys["train"], serde_json::json!([2, 1, 0]));
    assert!(
        keys.get("test").is_none(),
        "in-order keys are not stored: {keys}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
