//! `phi dataset generate | merge | stats` and `phi render` end to end.

use std::path::{Path, PathBuf};
use std::process::Output;

use phi::phi_gns::data::{
    Dataset, LIQUID, OBSTACLE, Trajectory, read_metadata, read_trajectory, read_trajectory_stats,
};

use super::rollout::failed;
use super::{ok, phi, scratch};

fn run(args: &[&str], dirs: &[&Path]) -> Output {
    let mut command = phi();
    command.args(args);
    for d in dirs {
        command.arg(d);
    }
    command.output().unwrap()
}

fn generate(out: &Path, extra: &[&str]) -> Output {
    let mut command = phi();
    command
        .args(["dataset", "generate", "--out"])
        .arg(out)
        .args(["--steps", "5", "--trajectories", "3"])
        .args(extra);
    command.output().unwrap()
}

/// Every trajectory file of a dataset directory: `split/name`, its content and its stored
/// statistics.
fn files(dir: &Path) -> Vec<(String, Trajectory, String)> {
    let mut all = Vec::new();
    for split in ["train", "valid", "test"] {
        let Ok(entries) = std::fs::read_dir(dir.join(split)) else {
            continue;
        };
        let mut names: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).collect();
        names.sort();
        for path in names {
            let name = format!("{split}/{}", path.file_name().unwrap().to_string_lossy());
            let stats = format!("{:?}", read_trajectory_stats(&path).unwrap());
            all.push((name, read_trajectory(&path).unwrap(), stats));
        }
    }
    all
}

#[test]
fn generate_writes_a_dataset_that_opens() {
    let dir = scratch("dataset-generate");
    let out = dir.join("data");
    let stdout = ok(generate(&out, &[]));
    assert!(stdout.contains("wrote 9 trajectories"), "{stdout}");
    let dataset = Dataset::open(&out).unwrap();
    let m = dataset.metadata();
    assert_eq!(m.sequence_length, 5);
    assert_eq!(
        (m.dt, m.dim, m.position_scale, m.position_offset),
        (0.05, 2, 0.025, 0.1)
    );
    assert_eq!(m.bounds, vec![[0.1, 0.9]; 2]);
    for split in ["train", "valid", "test"] {
        assert_eq!(m.splits[split], 3);
    }
    assert_ne!(m.seeds["train"], m.seeds["valid"]);
    assert!(m.vel_std.iter().chain(&m.acc_std).all(|s| *s > 0.0));
    assert_eq!(m.generator["params"]["pool_probability"], 0.3);
    let mut seeds = Vec::new();
    for split in ["train", "valid", "test"] {
        for t in dataset.split(split).unwrap() {
            let t = t.unwrap();
            assert_eq!(t.frames, 6);
            assert!(t.particles <= 1300);
            assert!(t.position.iter().all(|x| (0.1..=0.9).contains(x)));
            // Liquid first, then static obstacle particles.
            let liquid = t.liquid_particles();
            assert!(t.particle_type[..liquid].iter().all(|&k| k == LIQUID));
            assert!(t.particle_type[liquid..].iter().all(|&k| k == OBSTACLE));
            let (first, last) = (t.frame(0), t.frame(5));
            assert_eq!(&first[liquid * 2..], &last[liquid * 2..]);
            seeds.push(t.seed);
        }
    }
    seeds.sort();
    seeds.dedup();
    assert_eq!(seeds.len(), 9, "every trajectory has its own seed");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn rerunning_skips_finished_files_and_threads_do_not_change_bytes() {
    let dir = scratch("dataset-resume");
    let one = dir.join("one");
    ok(generate(&one, &["--split", "train", "--threads", "1"]));
    let path = one.join("train/traj_00001.npz");
    let modified = std::fs::metadata(&path).unwrap().modified().unwrap();
    // A killed run: one file lost, one left half-written.
    std::fs::remove_file(one.join("train/traj_00000.npz")).unwrap();
    std::fs::write(one.join("train/traj_00002.npz"), b"PK\x03\x04 truncated").unwrap();
    let stdout = ok(generate(&one, &["--split", "train", "--threads", "1"]));
    assert!(
        stdout.contains("wrote 2 trajectories") && stdout.contains("kept 1"),
        "{stdout}"
    );
    assert_eq!(
        std::fs::metadata(&path).unwrap().modified().unwrap(),
        modified
    );

    let two = dir.join("two");
    ok(generate(&two, &["--split", "train", "--threads", "2"]));
    assert_eq!(files(&one), files(&two));
    for i in 0..3 {
        let name = format!("train/traj_0000{i}.npz");
        assert_eq!(
            std::fs::read(one.join(&name)).unwrap(),
            std::fs::read(two.join(&name)).unwrap(),
            "{name}: the bytes depend on the thread count"
        );
    }
    assert_eq!(
        std::fs::read(one.join("metadata.json")).unwrap(),
        std::fs::read(two.join("metadata.json")).unwrap()
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn merged_shards_equal_an_unsharded_run() {
    let dir = scratch("dataset-shards");
    let whole = dir.join("whole");
    ok(generate(&whole, &["--variant", "walls"]));
    let (a, b) = (dir.join("a"), dir.join("b"));
    // Indices 0 and 2 of each split.
    let stdout = ok(generate(&a, &["--variant", "walls", "--shard", "0/2"]));
    assert!(stdout.contains("wrote 6 trajectories"), "{stdout}");
    ok(generate(&b, &["--variant", "walls", "--shard", "1/2"]));
    assert!(
        !a.join("metadata.json").exists(),
        "a shard is not a dataset"
    );
    let merged = dir.join("merged");
    // A missing shard is an error naming the trajectory, and nothing is written.
    let output = run(&["dataset", "merge", "--out"], &[&merged, &a]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("traj_00001.npz"));
    assert!(
        !merged.exists(),
        "a failed merge wrote into {}",
        merged.display()
    );
    ok(run(&["dataset", "merge", "--out"], &[&merged, &a, &b]));
    assert_eq!(files(&whole), files(&merged));
    let (mw, mm) = (
        read_metadata(&whole).unwrap(),
        read_metadata(&merged).unwrap(),
    );
    assert_eq!(mw, mm);
    assert_eq!(format!("{:?}", mm.variant), "WallsAsParticles");
    // Walls as particles: the ring of 124 obstacle particles is in every trajectory.
    let t = read_trajectory(&merged.join("train/traj_00000.npz")).unwrap();
    assert!(t.particles - t.liquid_particles() >= 124);
    // Shards of another configuration do not merge.
    let c = dir.join("c");
    ok(generate(&c, &["--shard", "1/2"]));
    let output = run(&["dataset", "merge", "--out"], &[&dir.join("m2"), &a, &c]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("variant"));
    let _ = std::fs::remove_dir_all(dir);
}

/// `phi dataset merge` writes a new or empty --out; it replaces a dataset there only with
/// `--force`, and refuses a folder holding anything else, or a shard itself, even then.
#[test]
fn merge_replaces_a_dataset_only_with_force() {
    let dir = scratch("dataset-merge-force");
    let (a, b) = (dir.join("a"), dir.join("b"));
    ok(generate(&a, &["--split", "train", "--shard", "0/2"]));
    ok(generate(&b, &["--split", "train", "--shard", "1/2"]));
    let merged = dir.join("merged");
    std::fs::create_dir_all(&merged).unwrap();
    ok(run(&["dataset", "merge", "--out"], &[&merged, &a, &b]));
    let before = files(&merged);
    let metadata = std::fs::read(merged.join("metadata.json")).unwrap();
    let stderr = failed(run(&["dataset", "merge", "--out"], &[&merged, &a, &b]));
    assert!(
        stderr.contains("merged") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(files(&merged), before);
    // A file of the old dataset that the new one does not have is gone after --force.
    std::fs::copy(
        merged.join("train/traj_00000.npz"),
        merged.join("train/traj_00009.npz"),
    )
    .unwrap();
    ok(run(
        &["dataset", "merge", "--force", "--out"],
        &[&merged, &a, &b],
    ));
    assert_eq!(files(&merged), before);
    assert_eq!(
        std::fs::read(merged.join("metadata.json")).unwrap(),
        metadata
    );
    Dataset::open(&merged).unwrap();

    for foreign in ["notes.txt", "train/notes.txt"] {
        let other = dir.join(format!("other-{}", foreign.replace('/', "-")));
        std::fs::create_dir_all(other.join("train")).unwrap();
        std::fs::write(other.join(foreign), "mine").unwrap();
        for force in [&[][..], &["--force"][..]] {
            let stderr = failed(run(
                &[&["dataset", "merge"], force, &["--out"]].concat(),
                &[&other, &a, &b],
            ));
            assert!(
                stderr.contains(&format!("'{foreign}'")) && stderr.contains("does not write"),
                "{stderr}"
            );
        }
        assert_eq!(std::fs::read(other.join(foreign)).unwrap(), b"mine");
        assert!(!other.join("metadata.json").exists());
    }
    let shard = files(&a);
    let stderr = failed(run(
        &["dataset", "merge", "--force", "--out"],
        &[&a, &a, &b],
    ));
    assert!(stderr.contains("is the shard"), "{stderr}");
    assert_eq!(files(&a), shard);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_directory_of_another_dataset_is_refused() {
    let dir = scratch("dataset-foreign");
    let out = dir.join("data");
    ok(generate(&out, &["--split", "valid"]));
    let output = generate(&out, &["--split", "valid", "--seed", "7"]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("another configuration") && stderr.contains("seed"),
        "{stderr}"
    );
    // --resume takes it over: files of the old seed are remade.
    let stdout = ok(generate(
        &out,
        &["--split", "valid", "--seed", "7", "--resume"],
    ));
    assert!(stdout.contains("wrote 3 trajectories"), "{stdout}");

    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let output = generate(&foreign, &[]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("not empty"));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_bad_config_key_names_the_file_and_the_key() {
    let dir = scratch("dataset-config");
    let config = dir.join("gen.toml");
    std::fs::write(&config, "pool_probability = 0.5\nblock_sise = [2, 4]\n").unwrap();
    let output = run(
        &["dataset", "generate", "--out"],
        &[&dir.join("data"), Path::new("--config"), &config],
    );
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("gen.toml") && stderr.contains("block_sise"),
        "{stderr}"
    );
    // A good one is used.
    std::fs::write(&config, "pool_probability = 1.0\nsteps = 4\n").unwrap();
    let data = dir.join("data");
    ok(run(
        &[
            "dataset",
            "generate",
            "--split=train",
            "--trajectories=2",
            "--out",
        ],
        &[&data, Path::new("--config"), &config],
    ));
    let m = read_metadata(&data).unwrap();
    assert_eq!(m.sequence_length, 4);
    assert_eq!(m.generator["params"]["pool_probability"], 1.0);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn render_writes_a_gif_and_stats_a_png() {
    let dir = scratch("dataset-render");
    let out = dir.join("data");
    ok(generate(&out, &["--split", "test"]));
    let gif = dir.join("t.gif");
    let stdout = ok(run(
        &[
            "render",
            "--split",
            "test",
            "--trajectory",
            "1",
            "--frame-every",
            "1",
            "--out",
        ],
        &[&gif, Path::new("--data"), &out],
    ));
    assert!(stdout.contains("6 pictures"), "{stdout}");
    assert_eq!(&std::fs::read(&gif).unwrap()[..6], b"GIF89a");

    let png = dir.join("n.png");
    let stdout = ok(run(
        &["dataset", "stats", "--split", "test", "--out"],
        &[&png, Path::new("--data"), &out],
    ));
    assert!(stdout.contains("3 of 3 trajectories"), "{stdout}");
    assert!(stdout.contains("liquid    particles: min"), "{stdout}");
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    // The IHDR chunk: width and height of the labelled plot.
    let size = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    assert_eq!((size(16), size(20)), (900, 520));
    // The heat map beside it: as large, and the same as drawn from the report.
    let heat = std::fs::read(dir.join("n_heatmap.png")).unwrap();
    assert_eq!(&heat[1..4], b"PNG");
    let size = |at: usize| u32::from_be_bytes(heat[at..at + 4].try_into().unwrap());
    assert_eq!((size(16), size(20)), (900, 520));
    let report = phi::dataset::stats::dataset_stats(&phi::dataset::stats::StatsOptions {
        dir: out.clone(),
        split: Some("test".into()),
        radius: 0.03,
        limit: 50,
        out: None,
        force: false,
        progress: false,
    })
    .unwrap();
    let map = phi::dataset::stats::heat_map(&report, 0.03).unwrap();
    assert_eq!(map.columns, report.frames);
    // Each frame's shares sum to one.
    for t in 0..map.columns {
        let sum: f64 = (0..map.rows).map(|k| map.values[k * map.columns + t]).sum();
        assert!((sum - 1.0).abs() < 1e-9, "frame {t}: {sum}");
    }
    let path = dir.join("again.png");
    map.write_png(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), heat);

    // An existing PNG is replaced only with --force; any other file is refused even then.
    let stats = |png: &Path, force: bool| {
        let force: &[&str] = if force { &["--force"] } else { &[] };
        run(
            &[&["dataset", "stats", "--split", "test"], force, &["--out"]].concat(),
            &[png, Path::new("--data"), &out],
        )
    };
    std::fs::write(&png, b"\x89PNG\r\n\x1a\n old").unwrap();
    let stderr = failed(stats(&png, false));
    assert!(
        stderr.contains("n.png") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&png).unwrap(), b"\x89PNG\r\n\x1a\n old");
    ok(stats(&png, true));
    assert_eq!(std::fs::read(&png).unwrap(), bytes);
    let notes = dir.join("notes.txt");
    std::fs::write(&notes, "mine").unwrap();
    let stderr = failed(stats(&notes, true));
    assert!(stderr.contains("is not a PNG"), "{stderr}");
    assert_eq!(std::fs::read(&notes).unwrap(), b"mine");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn export_to_tfrecord_and_npz_and_import_back() {
    let dir = scratch("dataset-export");
    let data = dir.join("data");
    ok(generate(&data, &["--split", "train"]));
    let records = dir.join("records");
    ok(run(
        &["dataset", "export", "--format", "tfrecord", "--out"],
        &[&records, Path::new("--data"), &data],
    ));
    assert!(records.join("train.tfrecord").is_file());
    let back = dir.join("back");
    ok(run(
        &["dataset", "import", "--out"],
        &[&back, Path::new("--data"), &records],
    ));
    assert_eq!(files(&data), files(&back));
    Dataset::open(&back).unwrap();

    let arrays = dir.join("arrays");
    ok(run(
        &["dataset", "export", "--format", "npz", "--out"],
        &[&arrays, Path::new("--data"), &data],
    ));
    let exported = phi::output::read_npz(arrays.join("train.npz")).unwrap();
    let original = read_trajectory(&data.join("train/traj_00001.npz")).unwrap();
    let (_, position) = exported
        .iter()
        .find(|(name, _)| name == "trajectory_1_position")
        .expect("trajectory 1 exported");
    assert_eq!(
        position.shape,
        vec![original.frames, original.particles, original.dim]
    );
    assert_eq!(position.as_f32().unwrap(), &original.position[..]);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_test_split_from_scene_files_keeps_the_thesis_scale_on_a_taller_domain() {
    let dir = scratch("dataset-scenes");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/generalisation");
    let out = dir.join("tall");
    let make_split = |split: &str, out: &Path, scenes: &Path, extra: &[&str]| {
        let mut command = phi();
        command
            .args([
                "dataset", "generate", "--split", split, "--steps", "3", "--out",
            ])
            .arg(out)
            .arg("--scenes")
            .arg(scenes)
            .args(extra);
        command.output().unwrap()
    };
    let make = |out: &Path, scenes: &Path, extra: &[&str]| make_split("test", out, scenes, extra);
    let stdout = ok(make(&out, &scenes, &["--position-scale", "0.025"]));
    assert!(stdout.contains("wrote 2 trajectories"), "{stdout}");
    let dataset = Dataset::open(&out).unwrap();
    let m = dataset.metadata();
    assert_eq!(m.position_scale, 0.025);
    let expected = [[0.1, 0.9], [0.1, 1.7]];
    assert_eq!(m.bounds.len(), 2);
    for (got, want) in m.bounds.iter().flatten().zip(expected.iter().flatten()) {
        assert!((got - want).abs() < 1e-12, "bounds {:?}", m.bounds);
    }
    assert_eq!(m.splits.get("test"), Some(&2));
    // Scene 01's block spans cells 50..60 in y: at 1/40 per cell from 0.1, its particles start
    // between 1.35 and 1.6, above the 32×32 domain's top (0.9).
    let (t, _) = dataset.read_with_stats("test", 0).unwrap();
    let ys: Vec<f32> = t.frame(0).iter().skip(1).step_by(2).copied().collect();
    let (low, high) = ys
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), &y| (l.min(y), h.max(y)));
    assert!(low > 1.35 && high < 1.6, "y from {low} to {high}");
    assert_eq!(t.seed, 2001);

    // The scenes decide the files: an edited scene is another configuration.
    let edited = dir.join("edited");
    std::fs::create_dir_all(&edited).unwrap();
    for name in ["01_tall_drop.toml", "02_drop_into_pool.toml"] {
        std::fs::copy(scenes.join(name), edited.join(name)).unwrap();
    }
    let text = std::fs::read_to_string(edited.join("01_tall_drop.toml")).unwrap();
    std::fs::write(
        edited.join("01_tall_drop.toml"),
        text.replace("seed = 2001", "seed = 7"),
    )
    .unwrap();
    let stderr = failed(make(&out, &edited, &["--position-scale", "0.025"]));
    assert!(stderr.contains("test_scenes_crc32"), "{stderr}");

    // Refusals: other splits, mixed domain sizes, a bad scale.
    let stderr = failed(make_split("all", &dir.join("all"), &scenes, &[]));
    assert!(stderr.contains("--split test"), "{stderr}");
    let text = std::fs::read_to_string(edited.join("02_drop_into_pool.toml")).unwrap();
    std::fs::write(
        edited.join("02_drop_into_pool.toml"),
        text.replace("resolution = [32, 64]", "resolution = [32, 32]")
            .replace(
                "lower = [10, 44], upper = [18, 52]",
                "lower = [10, 20], upper = [18, 28]",
            ),
    )
    .unwrap();
    let stderr = failed(make(&dir.join("mixed"), &edited, &[]));
    assert!(
        stderr.contains("02_drop_into_pool.toml") && stderr.contains("domain.resolution"),
        "{stderr}"
    );
    let stderr = failed(make(
        &dir.join("scale"),
        &scenes,
        &["--position-scale", "0"],
    ));
    assert!(stderr.contains("--position-scale"), "{stderr}");
    assert!(!dir.join("mixed").exists() && !dir.join("scale").exists());
    let _ = std::fs::remove_dir_all(dir);
}

/// The spellings before one vocabulary across commands work for one release, with a warning:
/// the positional dataset (`--data`), merge's positional OUT (`--out`), `--count` and
/// `--limit` (`--trajectories`), render's `--index` (`--trajectory`). A positional dataset and
/// a different `--data` are refused.
#[test]
fn the_spellings_before_data_and_trajectories_still_work() {
    let dir = scratch("dataset-old-spellings");
    let (a, b, data) = (dir.join("a"), dir.join("b"), dir.join("data"));
    for (shard, out) in [("0/2", &a), ("1/2", &b)] {
        let args = ["dataset", "generate", "--split", "test", "--steps", "3"];
        let shard = ["--count", "2", "--shard", shard, "--out"];
        ok(run(&[&args[..], &shard].concat(), &[out]));
    }
    let deprecated = |output: Output, form: &str| {
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        let stdout = ok(output);
        assert!(
            stderr.contains(&format!("`{form}` is deprecated")),
            "{form}: {stderr}"
        );
        stdout
    };
    deprecated(
        run(&["dataset", "merge"], &[&data, &a, &b]),
        "phi dataset merge OUT SHARDS...",
    );
    assert_eq!(Dataset::open(&data).unwrap().metadata().splits["test"], 2);

    let stdout = deprecated(
        run(
            &["dataset", "stats", "--split", "test", "--limit", "1"],
            &[&data],
        ),
        "phi dataset stats DATA",
    );
    assert!(stdout.contains("1 of 2 trajectories"), "{stdout}");
    let other = dir.join("other");
    let stderr = failed(run(&["dataset", "stats", "--data"], &[&other, &data]));
    assert!(
        stderr.contains("--data") && stderr.contains("differ"),
        "{stderr}"
    );
    ok(run(&["dataset", "stats", "--data"], &[&data, &data]));

    let (old, new) = (dir.join("old.gif"), dir.join("new.gif"));
    deprecated(
        run(&["render", "--index", "1", "--out"], &[&old, &data]),
        "phi render DATA",
    );
    ok(run(
        &["render", "--trajectory", "1", "--out"],
        &[&new, Path::new("--data"), &data],
    ));
    assert_eq!(std::fs::read(&old).unwrap(), std::fs::read(&new).unwrap());

    let (records, back) = (dir.join("records"), dir.join("back"));
    deprecated(
        run(
            &["dataset", "export", "--format", "tfrecord", "--out"],
            &[&records, &data],
        ),
        "phi dataset export DATA",
    );
    deprecated(
        run(&["dataset", "import", "--out"], &[&back, &records]),
        "phi dataset import DATA",
    );
    assert_eq!(files(&data), files(&back));
    let _ = std::fs::remove_dir_all(dir);
}

/// `--split` names a split the dataset's metadata.json lists; another is refused naming the
/// flag and the splits there are.
#[test]
fn a_split_the_dataset_lacks_is_refused_naming_the_flag_and_the_splits() {
    let dir = scratch("dataset-split");
    let data = dir.join("data");
    ok(generate(&data, &["--split", "test"]));
    let gif = dir.join("x.gif");
    let gif = gif.to_str().unwrap();
    for command in [&["dataset", "stats"][..], &["render", "--out", gif]] {
        let stderr = failed(run(
            &[command, &["--split", "valid", "--data"]].concat(),
            &[&data],
        ));
        assert!(
            stderr.contains("--split valid") && stderr.contains("its metadata.json lists test"),
            "{command:?}: {stderr}"
        );
        let stderr = failed(run(
            &[command, &["--split", "test/../valid", "--data"]].concat(),
            &[&data],
        ));
        assert!(
            stderr.contains("'--split <SPLIT>'") && stderr.contains("not a split name"),
            "{command:?}: {stderr}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A closed standard output (`phi dataset stats --data D | head -1`) ends a command quietly:
/// killed by SIGPIPE as `cat` would be (status 141 in a shell), not a panic.
#[test]
fn a_closed_stdout_ends_a_command_quietly() {
    let dir = scratch("dataset-closed-stdout");
    let data = dir.join("data");
    ok(generate(&data, &["--split", "test"]));
    let mut child = phi()
        .args(["dataset", "stats", "--data"])
        .arg(&data)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The reader is gone before the report's first line is written.
    drop(child.stdout.take());
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        const SIGPIPE: i32 = 13;
        assert_eq!(output.status.signal(), Some(SIGPIPE), "{:?}", output.status);
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn compare_measures_a_test_split_against_itself_and_another_jitter() {
    let dir = scratch("dataset-compare");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/test");
    // The first two test scenes, their jitter seeds moved.
    let reseeded = dir.join("scenes");
    std::fs::create_dir_all(&reseeded).unwrap();
    for name in ["01_tall_drop.toml", "02_narrow_gap.toml"] {
        let text = std::fs::read_to_string(scenes.join(name)).unwrap();
        let text = text.replace("seed = 100", "seed = 900");
        assert!(text.contains("seed = 900"), "{name}: {text}");
        std::fs::write(reseeded.join(name), text).unwrap();
    }
    let (data, other) = (dir.join("data"), dir.join("other"));
    let make = |out: &Path, extra: &[&str]| {
        let mut command = phi();
        command
            .args(["dataset", "generate", "--split", "test", "--steps", "12"])
            .args(["--trajectories", "2", "--out"])
            .arg(out)
            .args(extra);
        ok(command.output().unwrap())
    };
    make(&data, &[]);
    make(&other, &["--scenes", reseeded.to_str().unwrap()]);
    let compare = |a: &Path, b: &Path| {
        let mut command = phi();
        command
            .args(["dataset", "compare", "--data"])
            .arg(a)
            .arg("--other")
            .arg(b);
        command.output().unwrap()
    };
    let mean_row = |stdout: &str| -> Vec<String> {
        let row = stdout.lines().find(|l| l.starts_with("| mean")).unwrap();
        row.split('|').map(|c| c.trim().to_string()).collect()
    };
    // Against itself every distance is zero and every ratio one.
    let same = ok(compare(&data, &data));
    assert_eq!(
        same.lines().filter(|l| l.starts_with("| ")).count(),
        4,
        "{same}"
    );
    let row = mean_row(&same);
    assert_eq!(&row[2..4], ["0.000", "0.000"], "{same}");
    assert_eq!(&row[6..9], ["1.00", "1.00", "0.0"], "{same}");
    // Another jitter of the same liquid: the particles part, the liquid stays in the box.
    let moved = ok(compare(&data, &other));
    let row = mean_row(&moved);
    let emd: f64 = row[2].parse().unwrap();
    let mse: f64 = row[3].parse().unwrap();
    assert!(emd > 0.0 && mse > 0.0, "{moved}");
    assert_eq!(row[4], "0.0 %", "{moved}");
    // Another domain is refused, naming both datasets.
    let tall = dir.join("tall");
    ok(phi()
        .args([
            "dataset", "generate", "--split", "test", "--steps", "3", "--out",
        ])
        .arg(&tall)
        .arg("--scenes")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/generalisation"))
        .args(["--position-scale", "0.025"])
        .output()
        .unwrap());
    let err = failed(compare(&data, &tall));
    assert!(
        err.contains("not the same domain") && err.contains("--other"),
        "{err}"
    );
}
