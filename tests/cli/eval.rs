//! `phi eval` end to end on a tiny dataset and untrained models: every file, the table against
//! the per-frame curves and the per-trajectory results, resumption from the cache, --force, and
//! the refusals (another model's cache, a model that does not fit, a missing split, a foreign
//! output directory).

use std::path::Path;
use std::process::Output;

use phi::phi_gns::data::Variant;

use super::rollout::{failed, init, json, tiny_dataset_with};
use super::{ok, phi, scratch};

fn eval(models: &[String], data: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut command = phi();
    command.arg("eval");
    for model in models {
        command.arg("--model").arg(model);
    }
    command
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn f64_of(value: &serde_json::Value) -> f64 {
    value
        .as_f64()
        .unwrap_or_else(|| panic!("not a number: {value}"))
}

#[test]
fn eval_writes_tables_plots_gif_and_resumes_from_its_cache() {
    let dir = scratch("eval");
    let data = dir.join("data");
    tiny_dataset_with(&data, 2, [0.1, 0.9], Variant::Obstacles, &[("test", 3)], 30);
    let (a, b) = (dir.join("a"), dir.join("b"));
    ok(init(&data, &a, &["--seed", "1"]));
    ok(init(&data, &b, &["--seed", "2"]));
    let out = dir.join("out");
    let models = [format!("first={}", a.display()), b.display().to_string()];
    let options = ["--short-rollout", "10", "--sinkhorn-every", "8"];
    let stdout = ok(eval(&models, &data, &out, &options));
    assert!(
        stdout.contains("| first |") && stdout.contains("| b |"),
        "{stdout}"
    );
    for file in [
        "eval.json",
        "table.md",
        "table.csv",
        "error_over_time.png",
        "metrics.png",
        "rollouts.gif",
    ] {
        assert!(out.join(file).is_file(), "{file} is missing: {stdout}");
    }

    let record = json(&out.join("eval.json"));
    assert_eq!(record["format"], "phi-eval");
    assert_eq!(record["complete"], true);
    assert_eq!(record["trajectories"], serde_json::json!([0, 1, 2]));
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    let header = &rows[0];
    let acc_std: Vec<f64> = json(&data.join("metadata.json"))["acc_std"]
        .as_array()
        .unwrap()
        .iter()
        .map(f64_of)
        .collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for (m, label) in ["first", "b"].iter().enumerate() {
        let model = &record["models"][m];
        assert_eq!(model["label"], *label);
        let summary = &model["summary"];
        // The per-trajectory results are in the cache; the summary is their mean, and each
        // trajectory's MSE 400 is the mean of its per-frame curve.
        let mut mse400 = Vec::new();
        let (mut acc, mut acc_data) = (Vec::new(), Vec::new());
        for index in 0..3 {
            let entry = json(&out.join(format!("cache/{label}/test_{index}.json")));
            let evaluation = &entry["evaluation"];
            let curve: Vec<f64> = evaluation["curves"]["mse"]
                .as_array()
                .unwrap()
                .iter()
                .map(f64_of)
                .collect();
            assert_eq!(curve.len(), 30 - 1 - 5);
            let mean = curve.iter().sum::<f64>() / curve.len() as f64;
            approx::assert_relative_eq!(f64_of(&evaluation["mse400"]), mean, max_relative = 1e-12);
            mse400.push(mean);
            acc.push(f64_of(&evaluation["mse_acc1"]));
            // MSE-acc 1 in the dataset's normalisation, from the stored-unit errors.
            let error: Vec<f64> = evaluation["acc_error"]
                .as_array()
                .unwrap()
                .iter()
                .map(f64_of)
                .collect();
            assert_eq!(error.len(), 2);
            acc_data.push((0..2).map(|a| error[a] / acc_std[a].powi(2)).sum::<f64>() / 2.0);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        approx::assert_relative_eq!(
            f64_of(&summary["mse400"]),
            mean(&mse400),
            max_relative = 1e-12
        );
        approx::assert_relative_eq!(
            f64_of(&summary["mse_acc1_own"]),
            mean(&acc),
            max_relative = 1e-12
        );
        approx::assert_relative_eq!(
            f64_of(&summary["mse_acc1"]),
            mean(&acc_data),
            max_relative = 1e-12
        );
        // Without training noise the two normalisations are one, up to f32 rounding.
        approx::assert_relative_eq!(mean(&acc_data), mean(&acc), max_relative = 1e-4);
        // The band's mean over frames is the table's MSE 400 (the trajectories are equally long).
        let band: Vec<f64> = model["mse_band"]["mean"]
            .as_array()
            .unwrap()
            .iter()
            .map(f64_of)
            .collect();
        approx::assert_relative_eq!(
            mean(&band),
            f64_of(&summary["mse400"]),
            max_relative = 1e-12
        );
        // The CSV row holds the same numbers.
        let row = &rows[m + 1];
        assert_eq!(row[0], *label);
        let value: f64 = row[column("mse400")].parse().unwrap();
        approx::assert_relative_eq!(value, f64_of(&summary["mse400"]), max_relative = 1e-12);
        let emd: f64 = row[column("emd")].parse().unwrap();
        assert!(
            emd > 0.0 && emd <= 2.0 * value * (1.0 + 1e-9),
            "EMD {emd}, MSE {value}"
        );
    }
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("MSE 400 (10⁻²)") && table.contains("EMD (10⁻²)"),
        "{table}"
    );

    // A second run is refused without --force; with it, it reuses every cached result and
    // writes the same table.
    let cache = out.join("cache/b/test_1.json");
    let before = std::fs::read(&cache).unwrap();
    // The first run drew the GIF from the frames its evaluations kept; a run from the cache
    // rolls the models out again for it, and must draw the same pictures.
    let gif = std::fs::read(out.join("rollouts.gif")).unwrap();
    let stderr = failed(eval(&models, &data, &out, &options));
    assert!(
        stderr.contains("previous `phi eval` output") && stderr.contains("--force"),
        "{stderr}"
    );
    let forced = [&options[..], &["--force"]].concat();
    let again = ok(eval(&models, &data, &out, &forced));
    assert_eq!(
        std::fs::read_to_string(out.join("table.md")).unwrap(),
        table
    );
    assert!(again.contains("| first |"), "{again}");
    assert_eq!(std::fs::read(&cache).unwrap(), before);
    assert!(
        std::fs::read(out.join("rollouts.gif")).unwrap() == gif,
        "the GIF of kept frames differs from the GIF of a second rollout"
    );

    // An entry from before the stored-unit one-step errors were recorded is completed with
    // them, its other results kept: the same entry and the same table.
    let mut old: serde_json::Value = serde_json::from_slice(&before).unwrap();
    old["evaluation"]
        .as_object_mut()
        .unwrap()
        .remove("acc_error");
    std::fs::write(&cache, serde_json::to_vec_pretty(&old).unwrap()).unwrap();
    ok(eval(&models, &data, &out, &forced));
    assert_eq!(
        json(&cache),
        serde_json::from_slice::<serde_json::Value>(&before).unwrap()
    );
    assert_eq!(
        std::fs::read_to_string(out.join("table.md")).unwrap(),
        table
    );

    // A killed evaluation (its record says "complete": false) resumes without --force,
    // computing only what is not cached, and stale figures of the earlier run go.
    let unfinished = || {
        let mut record = json(&out.join("eval.json"));
        record["complete"] = serde_json::json!(false);
        std::fs::write(out.join("eval.json"), record.to_string()).unwrap();
    };
    unfinished();
    std::fs::remove_file(out.join("cache/first/test_2.json")).unwrap();
    let no_gif = [&options[..], &["--frame-every", "0"]].concat();
    ok(eval(&models, &data, &out, &no_gif));
    assert_eq!(json(&out.join("eval.json"))["complete"], true);
    assert!(out.join("cache/first/test_2.json").is_file());
    assert!(!out.join("rollouts.gif").exists());
    assert_eq!(std::fs::read(&cache).unwrap(), before);

    // Other weights under the same name: a resumed evaluation refuses the cache, naming the
    // entry and both digests; with --force the entries are recomputed.
    ok(init(&data, &b, &["--seed", "5", "--force"]));
    unfinished();
    let stderr = failed(eval(&models, &data, &out, &options));
    assert!(
        stderr.contains("test_0.json")
            && stderr.contains("digest")
            && stderr.contains("'b'")
            && stderr.contains("--force"),
        "{stderr}"
    );
    // ... and other options too.
    let stderr = failed(eval(&models[..1], &data, &out, &["--short-rollout", "7"]));
    assert!(stderr.contains("other options"), "{stderr}");
    ok(eval(&models, &data, &out, &forced));
    assert_ne!(std::fs::read(&cache).unwrap(), before);
    assert_eq!(json(&out.join("eval.json"))["complete"], true);

    // Files it does not write are refused even with --force, and kept; the cache is never
    // removed.
    std::fs::write(out.join("cache/notes.txt"), "mine").unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let stderr = failed(eval(&models, &data, &out, &forced));
    assert!(
        stderr.contains("'notes.txt'") && stderr.contains("does not write"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"mine");
    assert_eq!(std::fs::read(out.join("cache/notes.txt")).unwrap(), b"mine");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn eval_refuses_what_does_not_fit() {
    let dir = scratch("eval-refusals");
    let (plane, space) = (dir.join("2d"), dir.join("3d"));
    tiny_dataset_with(
        &plane,
        2,
        [0.1, 0.9],
        Variant::Obstacles,
        &[("test", 1)],
        12,
    );
    tiny_dataset_with(
        &space,
        3,
        [0.1, 0.9],
        Variant::Obstacles,
        &[("test", 1)],
        12,
    );
    let (m2, m3) = (dir.join("m2"), dir.join("m3"));
    ok(init(&plane, &m2, &[]));
    ok(init(&space, &m3, &[]));
    let out = dir.join("out");
    let m3s = [m3.display().to_string()];
    let stderr = failed(eval(&m3s, &plane, &out, &[]));
    assert!(
        stderr.contains("m3") && stderr.contains("metadata.json") && stderr.contains("key 'dim'"),
        "{stderr}"
    );
    let m2s = [m2.display().to_string()];
    let stderr = failed(eval(&m2s, &plane, &out, &["--split", "valid"]));
    assert!(
        stderr.contains("--split valid") && stderr.contains("its metadata.json lists test"),
        "{stderr}"
    );
    // --gif-index and --gif-every, the names before --gif-trajectory and --frame-every, still
    // work.
    for gif in [
        ["--gif-trajectory", "1", "--frame-every", "3"],
        ["--gif-index", "1", "--gif-every", "3"],
    ] {
        let stderr = failed(eval(&m2s, &plane, &out, &gif));
        assert!(
            stderr.contains("--gif-trajectory 1: only trajectories 0..1"),
            "{stderr}"
        );
    }
    let twice = [m2.display().to_string(), m2.display().to_string()];
    let stderr = failed(eval(&twice, &plane, &out, &[]));
    assert!(stderr.contains("NAME=DIR"), "{stderr}");
    let stderr = failed(eval(&m2s, &plane, &out, &["--trajectories", "2"]));
    assert!(stderr.contains("--trajectories 2"), "{stderr}");
    // The per-model options name the flag and what is wrong.
    let no_run = dir.display().to_string();
    let no_run = format!("m2={no_run}");
    for (extra, says) in [
        (
            &["--model-obstacles", "m2=bounce"][..],
            "'bounce' is not one of its values",
        ),
        (
            &["--model-obstacles", "other=push"][..],
            "no --model is named 'other'",
        ),
        (
            &["--model-walls", "m2=clamp", "--model-walls", "m2=open"][..],
            "named twice",
        ),
        (&["--model-walls", "m2"][..], "expected NAME=VALUE"),
        (&["--model-run", no_run.as_str()][..], "no train.csv there"),
    ] {
        let stderr = failed(eval(&m2s, &plane, &out, extra));
        assert!(
            stderr.contains(extra[0]) && stderr.contains(says),
            "{extra:?}: {stderr}"
        );
    }
    let nothing = [dir.join("nothing").display().to_string()];
    let stderr = failed(eval(&nothing, &plane, &out, &[]));
    assert!(stderr.contains("model.json"), "{stderr}");
    assert!(
        !out.exists(),
        "a refused evaluation wrote {}",
        out.display()
    );
    // A directory it did not write is refused, even with --force, and left alone; so is one
    // holding its file names without its eval.json.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    for force in [&[][..], &["--force"][..]] {
        let stderr = failed(eval(&m2s, &plane, &out, force));
        assert!(stderr.contains("does not write"), "{stderr}");
    }
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    std::fs::remove_file(out.join("notes.txt")).unwrap();
    std::fs::write(out.join("table.md"), "mine").unwrap();
    let stderr = failed(eval(&m2s, &plane, &out, &["--force"]));
    assert!(stderr.contains("no eval.json"), "{stderr}");
    assert_eq!(std::fs::read(out.join("table.md")).unwrap(), b"mine");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_model_evaluated_on_the_walls_variant_joins_the_same_table() {
    let dir = scratch("eval-model-data");
    let (data, walls, short) = (dir.join("data"), dir.join("walls"), dir.join("short"));
    let splits = [("test", 2)];
    tiny_dataset_with(&data, 2, [0.1, 0.9], Variant::Obstacles, &splits, 20);
    tiny_dataset_with(
        &walls,
        2,
        [0.1, 0.9],
        Variant::WallsAsParticles,
        &splits,
        20,
    );
    tiny_dataset_with(
        &short,
        2,
        [0.1, 0.9],
        Variant::WallsAsParticles,
        &splits,
        16,
    );
    let (a, w) = (dir.join("a"), dir.join("w"));
    ok(init(&data, &a, &["--seed", "1"]));
    ok(init(&walls, &w, &["--seed", "2"]));
    let options = [
        "--short-rollout",
        "5",
        "--sinkhorn-every",
        "0",
        "--frame-every",
        "4",
    ];
    let models = [a.display().to_string(), w.display().to_string()];
    let mut both = options.to_vec();
    let pair = format!("w={}", walls.display());
    both.extend(["--model-data", &pair]);
    let out = dir.join("out");
    let stdout = ok(eval(&models, &data, &out, &both));
    assert!(stdout.contains("w: on"), "{stdout}");
    let record = json(&out.join("eval.json"));
    assert!(record["models"][0].get("dataset").is_none(), "{record}");
    assert_eq!(record["models"][1]["dataset"], walls.display().to_string());
    assert_eq!(record["gif"]["panels"].as_array().unwrap().len(), 3);
    // w's row is what it scores on its own dataset alone.
    let alone = dir.join("alone");
    ok(eval(&models[1..], &walls, &alone, &options));
    let alone = json(&alone.join("eval.json"));
    for key in ["mse_acc1", "mse20", "mse400", "emd"] {
        let (x, y) = (
            &record["models"][1]["summary"][key],
            &alone["models"][0]["summary"][key],
        );
        assert!(x.is_number(), "{key}: {x}");
        assert_eq!(x, y, "{key}");
    }
    // A name no model has, and a dataset of other scenes, are refused before anything is written.
    let refused = dir.join("refused");
    let stray = format!("x={}", walls.display());
    let stderr = failed(eval(&models, &data, &refused, &["--model-data", &stray]));
    assert!(stderr.contains("no --model is named 'x'"), "{stderr}");
    let other = format!("w={}", short.display());
    let stderr = failed(eval(&models, &data, &refused, &["--model-data", &other]));
    assert!(
        stderr.contains("sequence_length") && stderr.contains("not the same scenes"),
        "{stderr}"
    );
    assert!(!refused.exists());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_floors_join_the_table_and_constant_velocity_rolls_out_straight_lines() {
    let dir = scratch("eval-floors");
    let data = dir.join("data");
    tiny_dataset_with(&data, 2, [0.1, 0.9], Variant::Obstacles, &[("test", 1)], 20);
    let model = dir.join("model");
    ok(init(&data, &model, &["--seed", "1"]));
    let out = dir.join("out");
    let stdout = ok(eval(
        &[model.display().to_string()],
        &data,
        &out,
        &["--floors", "--short-rollout", "5", "--sinkhorn-every", "0"],
    ));
    assert!(
        stdout.contains("| constant-velocity |") && stdout.contains("| mean-acceleration |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("misplaced (%)") && stdout.contains("| plausible |"),
        "{stdout}"
    );
    // The Sinkhorn divergence was switched off: its column reads "–", not a blown-up "inf".
    let row = stdout
        .lines()
        .find(|l| l.starts_with("| constant-velocity |"))
        .unwrap();
    assert!(row.contains(" – |") && !row.contains("inf"), "{row}");
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let row = csv
        .lines()
        .find(|l| l.starts_with("constant-velocity,"))
        .unwrap();
    assert_eq!(row.split(',').nth(5), Some(""), "{row}");
    let record = json(&out.join("eval.json"));
    let labels: Vec<&str> = record["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["model", "constant-velocity", "mean-acceleration"]);
    assert_eq!(record["models"][1]["dir"], "floor:constant-velocity");
    // Constant velocity: frame C + k is p_C + k (p_C − p_{C−1}) for every liquid particle.
    let dataset = phi::phi_gns::data::Dataset::open(&data).unwrap();
    let truth = dataset.split("test").unwrap().next().unwrap().unwrap();
    let liquid: Vec<usize> = (0..truth.particles)
        .filter(|&i| truth.particle_type[i] == phi::phi_gns::data::LIQUID)
        .collect();
    let entry = json(&out.join("cache/constant-velocity/test_0.json"));
    let curve: Vec<f64> = entry["evaluation"]["curves"]["mse"]
        .as_array()
        .unwrap()
        .iter()
        .map(f64_of)
        .collect();
    assert_eq!(curve.len(), 20 - 1 - 5);
    let plausibility = &entry["evaluation"]["plausibility"];
    assert!(
        f64_of(&plausibility["final_centre_distance_cells"]) >= 0.0,
        "{plausibility}"
    );
    let at = |t: usize, i: usize, a: usize| f64::from(truth.frame(t)[i * 2 + a]);
    for (k, got) in curve.iter().enumerate() {
        let k = k + 1;
        let mut sum = 0.0;
        for &i in &liquid {
            for a in 0..2 {
                let predicted = at(5, i, a) + k as f64 * (at(5, i, a) - at(4, i, a));
                sum += (predicted - at(5 + k, i, a)).powi(2);
            }
        }
        let want = sum / (2 * liquid.len()) as f64;
        approx::assert_relative_eq!(*got, want, max_relative = 1e-3, epsilon = 1e-12);
    }
    // An entry written before the plausibility figures is recomputed with them.
    let path = out.join("cache/model/test_0.json");
    let mut old = json(&path);
    old["options"].as_object_mut().unwrap().remove("container");
    old["evaluation"]
        .as_object_mut()
        .unwrap()
        .remove("plausibility");
    std::fs::write(&path, serde_json::to_vec(&old).unwrap()).unwrap();
    // Again over the same output, reusing what the cache holds.
    let rerun = || {
        ok(eval(
            &[model.display().to_string()],
            &data,
            &out,
            &[
                "--floors",
                "--short-rollout",
                "5",
                "--sinkhorn-every",
                "0",
                "--force",
            ],
        ))
    };
    rerun();
    let again = json(&path);
    assert!(again["evaluation"]["plausibility"].is_object(), "{again}");
    assert!(again["options"]["container"].is_object(), "{again}");

    // The peak share inside obstacles is the largest count of the curve over the liquid; an
    // entry written before it is filled in from its curves (here with three particles inside
    // obstacles in one frame).
    let peak = |entry: &serde_json::Value| {
        entry["evaluation"]["curves"]["inside_obstacles"]
            .as_array()
            .unwrap()
            .iter()
            .map(f64_of)
            .fold(0.0, f64::max)
            / liquid.len() as f64
    };
    assert_eq!(f64_of(&plausibility["peak_inside_obstacles"]), peak(&entry));
    let path = out.join("cache/constant-velocity/test_0.json");
    let mut old = json(&path);
    old["evaluation"]["curves"]["inside_obstacles"][4] = 3.into();
    let fields = old["evaluation"]["plausibility"].as_object_mut().unwrap();
    fields.remove("peak_inside_obstacles").unwrap();
    fields.remove("peak_inside_obstacles_true").unwrap();
    std::fs::write(&path, serde_json::to_vec(&old).unwrap()).unwrap();
    rerun();
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let column = csv
        .lines()
        .next()
        .unwrap()
        .split(',')
        .position(|c| c == "peak_inside_obstacles")
        .unwrap();
    let row = csv
        .lines()
        .find(|l| l.starts_with("constant-velocity,"))
        .unwrap();
    let value: f64 = row.split(',').nth(column).unwrap().parse().unwrap();
    approx::assert_relative_eq!(value, 3.0 / liquid.len() as f64, max_relative = 1e-12);
}

#[test]
fn probe_reads_free_fall_and_rest_beside_the_floors() {
    let dir = scratch("probe");
    let data = dir.join("data");
    tiny_dataset_with(&data, 2, [0.1, 0.9], Variant::Obstacles, &[("test", 1)], 20);
    let model = dir.join("model");
    ok(init(&data, &model, &["--seed", "1"]));
    let report = dir.join("probe.json");
    let run = |extra: &[&str]| {
        phi()
            .args(["model", "probe", "--data"])
            .arg(&data)
            .arg("--model")
            .arg(&model)
            .args(extra)
            .output()
            .unwrap()
    };
    let stdout = ok(run(&["--json", report.to_str().unwrap(), "--seeds", "2"]));
    assert!(stdout.contains("constant-velocity"), "{stdout}");
    let rows = json(&report);
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0]["label"], "model");
    let still = &rows[1]["result"];
    assert_eq!(rows[1]["label"], "constant-velocity");
    assert!(
        f64_of(&still["falling_along_gravity"]).abs() < 1e-4,
        "{still}"
    );
    // g = 9.81 cells/s² · position_scale · dt² in stored units per frame².
    let g = f64_of(&still["gravity"][1]);
    let metadata = json(&data.join("metadata.json"));
    let (scale, dt) = (f64_of(&metadata["position_scale"]), f64_of(&metadata["dt"]));
    approx::assert_relative_eq!(g, -9.81 * scale * dt * dt, max_relative = 1e-12);
    let e = failed(run(&["--gravity", "0,0"]));
    assert!(e.contains("--gravity") && e.contains("not zero"), "{e}");
}
