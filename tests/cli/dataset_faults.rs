//! The dataset commands under faults: files swapped or damaged, kills, targets that hold data,
//! requests too large for memory, and what users see of errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use phi::phi_gns::data::{Dataset, read_metadata, read_trajectory};

use super::rollout::json;
use super::{ok, phi, scratch};

/// `phi dataset generate --out OUT --steps 2 --trajectories N --split SPLIT [extra]`.
fn generate(out: &Path, split: &str, count: usize, extra: &[&str]) -> Output {
    phi()
        .args(["dataset", "generate", "--steps", "2", "--split", split])
        .args(["--trajectories", &count.to_string(), "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

/// `phi ARGS... PATHS...`.
fn run(args: &[&str], paths: &[&Path]) -> Output {
    let mut command: Command = phi();
    command.args(args).args(paths);
    command.output().unwrap()
}

/// The standard error of a run that must have failed.
fn fails(output: Output) -> String {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(
        !output.status.success(),
        "expected a failure; stdout: {}\nstderr: {stderr}",
        String::from_utf8_lossy(&output.stdout)
    );
    stderr
}

/// Every file under `dir` with its bytes, sorted by path.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut all = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                all.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
    }
    all.sort();
    all
}

#[test]
fn a_trajectory_of_another_split_fails_every_reader() {
    let dir = scratch("faults-swap");
    let data = dir.join("data");
    ok(generate(&data, "train", 2, &[]));
    ok(generate(&data, "valid", 1, &[]));
    std::fs::copy(
        data.join("train/traj_00000.npz"),
        data.join("valid/traj_00000.npz"),
    )
    .unwrap();
    let (gif, npz, tf) = (dir.join("v.gif"), dir.join("npz"), dir.join("tf"));
    let readers: [(&[&str], Vec<&Path>); 4] = [
        (
            &["dataset", "stats", "--split", "valid", "--data"],
            vec![data.as_path()],
        ),
        (
            &["render", "--split", "valid", "--out"],
            vec![gif.as_path(), Path::new("--data"), data.as_path()],
        ),
        (
            &["dataset", "export", "--format", "npz", "--out"],
            vec![npz.as_path(), Path::new("--data"), data.as_path()],
        ),
        (
            &["dataset", "export", "--format", "tfrecord", "--out"],
            vec![tf.as_path(), Path::new("--data"), data.as_path()],
        ),
    ];
    for (args, paths) in readers {
        let stderr = fails(run(args, &paths));
        assert!(
            stderr.contains("valid/traj_00000.npz") && stderr.contains("seeds.valid"),
            "{args:?}: {stderr}"
        );
    }
    assert!(!gif.exists() && !dir.join("npz").exists() && !dir.join("tf").exists());
    let _ = std::fs::remove_dir_all(dir);
}

/// The offset of the data of member `name` in the `.npz` archive `bytes`, from its local header.
fn member_data(bytes: &[u8], name: &str) -> usize {
    let file_name = format!("{name}.npy");
    let header = bytes
        .windows(4)
        .enumerate()
        .filter(|(_, w)| *w == b"PK\x03\x04")
        .map(|(i, _)| i)
        .find(|&i| bytes[i + 30..].starts_with(file_name.as_bytes()))
        .unwrap();
    let name_len = u16::from_le_bytes([bytes[header + 26], bytes[header + 27]]) as usize;
    let extra_len = u16::from_le_bytes([bytes[header + 28], bytes[header + 29]]) as usize;
    header + 30 + name_len + extra_len
}

#[test]
fn resume_remakes_damaged_files_and_removes_stale_temporary_files() {
    let dir = scratch("faults-resume");
    let data = dir.join("data");
    ok(generate(&data, "train", 3, &[]));
    let good = snapshot(&data);
    // Damage the statistics of file 0 (which reading the positions alone does not see), the
    // central directory of file 1, and leave the empty temporary file of a killed run.
    let zero = data.join("train/traj_00000.npz");
    let mut bytes = std::fs::read(&zero).unwrap();
    let at = member_data(&bytes, "stats_velocity") + 140;
    bytes[at] ^= 0x10;
    std::fs::write(&zero, &bytes).unwrap();
    let one = data.join("train/traj_00001.npz");
    let mut bytes = std::fs::read(&one).unwrap();
    let central = bytes.windows(4).rposition(|w| w == b"PK\x01\x02").unwrap();
    bytes[central + 46] ^= 0x01; // the first byte of the last entry's name
    std::fs::write(&one, &bytes).unwrap();
    let stale = data.join("train/.traj_00002.npz.tmp-4194305");
    std::fs::write(&stale, b"").unwrap();
    // Readers call the damage corrupt, not missing.
    let stderr = fails(run(
        &["dataset", "export", "--format", "npz", "--out"],
        &[&dir.join("x"), Path::new("--data"), &data],
    ));
    assert!(
        stderr.contains("corrupt") && !stderr.contains("has no array"),
        "{stderr}"
    );

    let stdout = ok(generate(&data, "train", 3, &[]));
    assert!(
        stdout.contains("wrote 2 trajectories") && stdout.contains("kept 1 finished"),
        "{stdout}"
    );
    assert!(
        stdout.contains("remade 2 damaged or foreign file(s)"),
        "{stdout}"
    );
    if Path::new("/proc/self").exists() {
        assert!(
            stdout.contains("removed 1 stale temporary file(s)"),
            "{stdout}"
        );
        assert!(!stale.exists());
    }
    assert_eq!(
        snapshot(&data),
        good,
        "the remade files are the original bytes"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn quiet_keeps_the_results_and_drops_the_log() {
    if !Path::new("/proc/self").exists() {
        return; // stale temporary files are recognised through /proc
    }
    let dir = scratch("faults-quiet");
    let data = dir.join("data");
    ok(generate(&data, "train", 1, &[]));
    let stale = data.join("train/.traj_00000.npz.tmp-4194305");
    // Removing a killed run's temporary file is logged at info level, and said in the summary.
    std::fs::write(&stale, b"").unwrap();
    let loud = generate(&data, "train", 1, &[]);
    assert!(String::from_utf8_lossy(&loud.stderr).contains("left by a killed run"));
    std::fs::write(&stale, b"").unwrap();
    let quiet = phi()
        .args([
            "-q", "dataset", "generate", "--steps", "2", "--split", "train",
        ])
        .args(["--trajectories", "1", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&quiet.stderr).into_owned();
    let stdout = ok(quiet);
    assert!(
        !stderr.contains("left by a killed run") && !stderr.contains("INFO"),
        "{stderr}"
    );
    assert!(
        stdout.contains("removed 1 stale temporary file(s)"),
        "{stdout}"
    );
    assert!(!stale.exists());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_smaller_count_is_refused_unless_pruned() {
    let dir = scratch("faults-count");
    let data = dir.join("data");
    ok(generate(&data, "train", 2, &[]));
    let before = snapshot(&data);
    let stderr = fails(generate(&data, "train", 1, &[]));
    assert!(
        stderr.contains("train/traj_00001.npz")
            && stderr.contains("--trajectories 2")
            && stderr.contains("--prune"),
        "{stderr}"
    );
    assert_eq!(snapshot(&data), before);
    ok(generate(&data, "train", 1, &["--prune"]));
    let dataset = Dataset::open(&data).unwrap();
    assert_eq!(dataset.metadata().splits["train"], 1);
    assert!(!data.join("train/traj_00001.npz").exists());
    let _ = std::fs::remove_dir_all(dir);
}

/// `generate --force` means what it means for every command: it replaces a dataset that
/// `phi dataset generate` wrote (of any configuration), and nothing else.
#[test]
fn generate_force_replaces_only_its_own_dataset() {
    let dir = scratch("faults-generate-force");
    let data = dir.join("data");
    ok(generate(&data, "train", 2, &[]));
    let before = snapshot(&data);
    let stderr = fails(generate(&data, "train", 1, &["--seed", "5"]));
    assert!(
        stderr.contains("another configuration") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(snapshot(&data), before);
    // Replaced whole: the new seed, one trajectory, nothing of the old dataset left.
    ok(generate(&data, "train", 1, &["--seed", "5", "--force"]));
    let metadata = read_metadata(&data).unwrap();
    assert_eq!(metadata.splits["train"], 1);
    assert_eq!(metadata.generator["seed"], 5);
    assert!(!data.join("train/traj_00001.npz").exists());
    let stderr = fails(generate(&data, "train", 1, &["--force", "--resume"]));
    assert!(stderr.contains("--resume"), "{stderr}");

    // A folder holding anything else is refused even with --force, and left as it was.
    for foreign in ["notes.txt", "train/notes.txt"] {
        let other = dir.join(format!("other-{}", foreign.replace('/', "-")));
        ok(generate(&other, "train", 1, &[]));
        std::fs::write(other.join(foreign), "mine").unwrap();
        let before = snapshot(&other);
        let stderr = fails(generate(&other, "train", 1, &["--force"]));
        assert!(
            stderr.contains(&format!("'{foreign}'")) && stderr.contains("does not write"),
            "{stderr}"
        );
        assert_eq!(snapshot(&other), before);
    }
    // A dataset it did not write (no generator.json: imported, say) is not its to replace.
    let imported = dir.join("imported");
    ok(generate(&imported, "train", 1, &[]));
    std::fs::remove_file(imported.join("generator.json")).unwrap();
    let before = snapshot(&imported);
    let stderr = fails(generate(&imported, "train", 1, &["--force"]));
    assert!(stderr.contains("no generator.json"), "{stderr}");
    assert_eq!(snapshot(&imported), before);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn import_export_and_render_never_overwrite_data_unless_forced() {
    let dir = scratch("faults-overwrite");
    let data = dir.join("data");
    let other = dir.join("other");
    ok(generate(&data, "train", 2, &[]));
    ok(generate(&other, "train", 1, &["--seed", "5"]));
    let (records, two) = (dir.join("records"), dir.join("two"));
    for (out, from) in [(&records, &other), (&two, &data)] {
        ok(run(
            &["dataset", "export", "--format", "tfrecord", "--out"],
            &[out, Path::new("--data"), from],
        ));
    }
    let import = |out: &Path, from: &Path, force: &[&str]| {
        run(
            &[&["dataset", "import"], force, &["--out"]].concat(),
            &[out, Path::new("--data"), from],
        )
    };

    // Import over a dataset it did not write: refused even with --force, the dataset untouched.
    let before = snapshot(&data);
    for force in [&[][..], &["--force"][..]] {
        let stderr = fails(import(&data, &records, force));
        assert!(
            stderr.contains("does not write") && stderr.contains("phi dataset import"),
            "{stderr}"
        );
    }
    assert_eq!(snapshot(&data), before);
    // Over its own import: refused without --force.
    let imported = dir.join("imported");
    ok(import(&imported, &two, &[]));
    assert_eq!(
        json(&imported.join("import.json"))["made_by"],
        "phi dataset import"
    );
    let before = snapshot(&imported);
    let stderr = fails(import(&imported, &records, &[]));
    assert!(
        stderr.contains("previous `phi dataset import` output") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(snapshot(&imported), before);
    // A failing import (a damaged record) with --force leaves the old dataset whole.
    let damaged = dir.join("damaged");
    std::fs::create_dir_all(&damaged).unwrap();
    std::fs::copy(records.join("metadata.json"), damaged.join("metadata.json")).unwrap();
    let mut bytes = std::fs::read(records.join("train.tfrecord")).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xFF;
    std::fs::write(damaged.join("train.tfrecord"), &bytes).unwrap();
    fails(import(&imported, &damaged, &["--force"]));
    assert_eq!(snapshot(&imported), before);
    // With --force a good import replaces it whole; nothing beside it is touched.
    std::fs::write(dir.join("beside.txt"), "mine").unwrap();
    ok(import(&imported, &records, &["--force"]));
    assert_eq!(read_metadata(&imported).unwrap().splits["train"], 1);
    assert_eq!(
        read_trajectory(&imported.join("train/traj_00000.npz")).unwrap(),
        read_trajectory(&other.join("train/traj_00000.npz")).unwrap()
    );
    assert!(!imported.join("train/traj_00001.npz").exists());
    assert_eq!(std::fs::read(dir.join("beside.txt")).unwrap(), b"mine");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // A file it does not write inside its import: refused even with --force.
    std::fs::write(imported.join("train/notes.txt"), "mine").unwrap();
    let stderr = fails(import(&imported, &records, &["--force"]));
    assert!(stderr.contains("'train/notes.txt'"), "{stderr}");
    std::fs::remove_file(imported.join("train/notes.txt")).unwrap();

    // Export into a folder holding anything else, or a dataset: refused even with --force;
    // into the dataset itself: refused.
    let export = |out: &Path, from: &Path, force: &[&str]| {
        run(
            &[&["dataset", "export", "--format", "npz"], force, &["--out"]].concat(),
            &[out, Path::new("--data"), from],
        )
    };
    let notes = dir.join("notes");
    std::fs::create_dir_all(&notes).unwrap();
    std::fs::write(notes.join("a.txt"), "mine").unwrap();
    let before = snapshot(&imported);
    for force in [&[][..], &["--force"][..]] {
        let stderr = fails(export(&notes, &other, force));
        assert!(
            stderr.contains("'a.txt'") && stderr.contains("does not write"),
            "{stderr}"
        );
        let stderr = fails(export(&imported, &other, force));
        assert!(stderr.contains("does not write"), "{stderr}");
    }
    assert_eq!(std::fs::read(notes.join("a.txt")).unwrap(), b"mine");
    assert_eq!(snapshot(&imported), before);
    let stderr = fails(export(&other, &other, &["--force"]));
    assert!(stderr.contains("holds the dataset"), "{stderr}");
    Dataset::open(&other).unwrap();
    // Over its own export: refused without --force, replaced whole with it (another format's
    // files go); the same files without its export.json are not its own.
    let arrays = dir.join("arrays");
    ok(export(&arrays, &other, &[]));
    let before = snapshot(&arrays);
    let stderr = fails(export(&arrays, &data, &[]));
    assert!(
        stderr.contains("previous `phi dataset export` output") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(snapshot(&arrays), before);
    ok(run(
        &[
            "dataset", "export", "--format", "tfrecord", "--force", "--out",
        ],
        &[&arrays, Path::new("--data"), &data],
    ));
    assert!(arrays.join("train.tfrecord").is_file() && !arrays.join("train.npz").exists());
    assert_eq!(json(&arrays.join("export.json"))["format"], "tfrecord");
    std::fs::remove_file(arrays.join("export.json")).unwrap();
    let before = snapshot(&arrays);
    let stderr = fails(export(&arrays, &data, &["--force"]));
    assert!(stderr.contains("no export.json"), "{stderr}");
    assert_eq!(snapshot(&arrays), before);

    // Render over a file that is not a GIF: refused, even with --force; a new GIF is drawn;
    // over a GIF: refused, redrawn with --force.
    let metadata = other.join("metadata.json");
    let text = std::fs::read(&metadata).unwrap();
    for force in [&[][..], &["--force"][..]] {
        let stderr = fails(run(
            &[&["render", "--split", "train"], force, &["--out"]].concat(),
            &[&metadata, Path::new("--data"), &other],
        ));
        assert!(
            stderr.contains("is not a GIF") && stderr.contains("metadata.json"),
            "{stderr}"
        );
    }
    assert_eq!(std::fs::read(&metadata).unwrap(), text);
    let gif = dir.join("t.gif");
    ok(run(
        &["render", "--split", "train", "--frame-every", "1", "--out"],
        &[&gif, Path::new("--data"), &other],
    ));
    let drawn = std::fs::read(&gif).unwrap();
    let stderr = fails(run(
        &["render", "--split", "train", "--out"],
        &[&gif, Path::new("--data"), &other],
    ));
    assert!(
        stderr.contains("t.gif") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&gif).unwrap(), drawn);
    ok(run(
        &["render", "--split", "train", "--force", "--out"],
        &[&gif, Path::new("--data"), &other],
    ));
    assert_ne!(std::fs::read(&gif).unwrap(), drawn, "not redrawn");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn requests_too_large_for_memory_are_refused_naming_the_key() {
    let dir = scratch("faults-memory");
    let data = dir.join("data");
    ok(generate(&data, "train", 1, &[]));
    let with_limit = |args: &[&str], paths: &[&Path]| {
        let mut command = phi();
        command.env("PHI_MEMORY_LIMIT", "1G").args(args).args(paths);
        command.output().unwrap()
    };
    // A tiny radius needs no more memory (the cell list keeps only occupied cells); the
    // histograms of every trajectory and frame measured are what grows.
    ok(with_limit(
        &["dataset", "stats", "--radius", "1e-6", "--data"],
        &[&data],
    ));
    let mut command = phi();
    command
        .env("PHI_MEMORY_LIMIT", "2K")
        .args(["dataset", "stats", "--data"])
        .arg(&data);
    let stderr = fails(command.output().unwrap());
    assert!(
        stderr.contains("neighbour histograms of 1 trajectory of")
            && stderr.contains("--trajectories")
            && stderr.contains("metadata.json")
            && stderr.contains("more than the limit of 2.0 KiB"),
        "{stderr}"
    );
    let stderr = fails(with_limit(
        &[
            "dataset",
            "generate",
            "--split",
            "train",
            "--trajectories",
            "1000000000000000",
            "--out",
        ],
        &[&dir.join("big")],
    ));
    assert!(
        stderr.contains("--trajectories") && stderr.contains("more than the limit"),
        "{stderr}"
    );

    // Bounds up to 1e9: stats needs no more memory (its cell list keeps only occupied cells),
    // render names the keys of the picture.
    let path = data.join("metadata.json");
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    json["bounds"] = serde_json::json!([[0.0, 1e9], [0.0, 1e9]]);
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    ok(with_limit(&["dataset", "stats", "--data"], &[&data]));
    let stderr = fails(run(
        &["render", "--split", "train", "--out"],
        &[&dir.join("r.gif"), Path::new("--data"), &data],
    ));
    assert!(
        stderr.contains("metadata.json")
            && stderr.contains("bounds")
            && stderr.contains("position_scale")
            && stderr.contains("--pixels-per-cell"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn users_see_the_error_chain_and_backtraces_only_with_verbose() {
    let dir = scratch("faults-messages");
    let config = dir.join("gen.toml");
    let key = "k".repeat(1 << 20);
    std::fs::write(&config, format!("{key} = 1\n")).unwrap();
    let generate = |verbose: bool| {
        let mut command = phi();
        command
            .env("RUST_BACKTRACE", "1")
            .args(["dataset", "generate", "--out"]);
        command.arg(dir.join("data")).arg("--config").arg(&config);
        if verbose {
            command.arg("-v");
        }
        command.output().unwrap()
    };
    let stderr = fails(generate(false));
    assert!(
        stderr.starts_with("Error: ") && stderr.contains("gen.toml"),
        "{stderr}"
    );
    assert!(stderr.len() < 2_000, "{} bytes of error", stderr.len());
    // The key and the reason's echo of it, each shortened.
    assert_eq!(stderr.matches("… (1048576 bytes)").count(), 2, "{stderr}");
    assert!(
        !stderr.contains("Backtrace") && !stderr.contains("backtrace"),
        "{stderr}"
    );
    let stderr = fails(generate(true));
    assert!(stderr.contains("Backtrace:"), "{stderr}");
    let _ = std::fs::remove_dir_all(dir);
}
