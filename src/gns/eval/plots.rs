//! The figures of `phi eval`: error over time (thesis fig. 5.7), the metric bars (fig. 5.6) and
//! the screening curves of the training logs (fig. 5.5), drawn with [`phi_plot`].

use std::path::Path;

use anyhow::{Context, Result};
use phi_plot::{BarChart, BarSeries, Figure, Legend, LinePlot, Series};

use super::{EvalRecord, ModelEntry, ModelRecord};
use crate::output::RgbImage;
use phi_gns::eval::{Band, ModelSummary};

/// The per-frame error of the models: MSE and EMD, the mean over the trajectories with the
/// min–max range shaded (fig. 5.7), logarithmic axes.
pub fn error_over_time(record: &EvalRecord, path: &Path) -> Result<()> {
    let panel = |title: &str, y_label: &str, band: fn(&ModelRecord) -> Option<&Band>| {
        let mut plot = LinePlot::new(title, "frame", y_label)
            .with_log_y(true)
            .with_legend(Legend::LowerRight);
        for model in &record.models {
            let Some(band) = band(model).filter(|b| drawable(&b.mean)) else {
                continue;
            };
            let x: Vec<f64> = band.frame.iter().map(|&f| f as f64).collect();
            plot = plot.with_series(
                Series::new(&model.label, x, band.mean.clone())
                    .with_band(band.min.clone(), band.max.clone()),
            );
        }
        plot
    };
    let figure = Figure::new(
        format!(
            "Error over time on '{}' (mean, min–max range)",
            record.split
        ),
        2,
    )
    .with_panel(panel(
        "MSE of the rollout",
        "position MSE (stored units²)",
        |m| m.mse_band.as_ref(),
    ))
    .with_panel(panel("EMD", "EMD (ground cost)", |m| m.emd_band.as_ref()));
    figure
        .write_png(path)
        .with_context(|| format!("drawing {}", path.display()))
}

/// Whether a log axis can show any of `values`.
fn drawable(values: &[f64]) -> bool {
    values.iter().any(|v| v.is_finite() && *v > 0.0)
}

/// A metric of table B.1: its label, the unit its values are shown in, and how to read it.
type Metric = (&'static str, f64, fn(&ModelSummary) -> Option<f64>);

/// One bar chart per metric of table B.1, one bar per model (fig. 5.6); a model whose
/// rollouts blew up has no bar for the rollout metrics.
pub(crate) fn metric_bars(record: &EvalRecord, path: &Path) -> Result<()> {
    let metrics: [Metric; 4] = [
        ("EMD (10⁻²)", 1e-2, |s| s.emd),
        ("MSE-acc 1 (10⁻¹)", 1e-1, |s| Some(s.mse_acc1)),
        ("MSE 20 (10⁻⁵)", 1e-5, |s| s.mse20),
        ("MSE 400 (10⁻²)", 1e-2, |s| s.mse400),
    ];
    let mut figure = Figure::new(format!("Metrics on '{}'", record.split), 4);
    for (name, scale, value) in metrics {
        let mut chart = BarChart::new(name, name, [record.split.as_str()]).with_size(420, 500);
        for model in &record.models {
            let v = model
                .summary
                .as_ref()
                .and_then(value)
                .map_or(f64::NAN, |v| v / scale);
            chart = chart.with_series(BarSeries::new(&model.label, vec![v]));
        }
        figure = figure.with_panel(chart);
    }
    figure
        .write_png(path)
        .with_context(|| format!("drawing {}", path.display()))
}

/// The named columns of the rows of a `phi train` log where all of them are filled, one vector
/// per column.
///
/// # Errors
/// A log that does not read, whose header lacks a column or whose field is not a number.
fn read_columns<const K: usize>(path: &Path, names: [&str; K]) -> Result<[Vec<f64>; K]> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let mut columns = [0usize; K];
    for (column, name) in columns.iter_mut().zip(names) {
        *column = header
            .iter()
            .position(|h| *h == name)
            .with_context(|| format!("{}: no column '{name}' in the header", path.display()))?;
    }
    let mut values: [Vec<f64>; K] = std::array::from_fn(|_| Vec::new());
    for (n, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let field = |k: usize| fields.get(k).copied().unwrap_or("");
        if columns.iter().any(|&k| field(k).is_empty()) {
            continue;
        }
        for (out, &k) in values.iter_mut().zip(&columns) {
            out.push(field(k).parse::<f64>().with_context(|| {
                format!(
                    "{}: line {}: '{}' is not a number",
                    path.display(),
                    n + 2,
                    field(k)
                )
            })?);
        }
    }
    Ok(values)
}

/// The curves of the models that come from training runs (fig. 5.5): the training loss of
/// each log row (its mean since the row before), and where the run screened, MSE-acc 1 and the
/// rollout MSE on the validation split over training steps. A run's `train.csv` is read by its
/// header, so any log with `step`, `loss`, `valid_mse_acc1` and `valid_rollout_mse` columns
/// draws (`phi train`'s, the PyTorch reference trainer's). Returns whether anything was drawn.
pub fn screening(models: &[ModelEntry], path: &Path) -> Result<bool> {
    let mut loss = LinePlot::new(
        "Training loss",
        "training step",
        "loss, mean of each log row (normalised units²)",
    )
    .with_log_y(true);
    let mut acc = LinePlot::new(
        "MSE-acc 1",
        "training step",
        "MSE-acc 1 (normalised units²)",
    )
    .with_log_y(true);
    let mut rollout = LinePlot::new(
        "Rollout MSE",
        "training step",
        "position MSE (stored units²)",
    )
    .with_log_y(true);
    let (mut logged, mut screened) = (false, false);
    for model in models {
        let Some(run) = &model.run else { continue };
        let log = run.join("train.csv");
        let [steps, losses] = read_columns(&log, ["step", "loss"])?;
        if drawable(&losses) {
            loss = loss.with_series(Series::new(&model.label, steps, losses));
            logged = true;
        }
        let [steps, accs, rollouts] =
            read_columns(&log, ["step", "valid_mse_acc1", "valid_rollout_mse"])?;
        if !drawable(&accs) || !drawable(&rollouts) {
            continue;
        }
        acc = acc.with_series(Series::new(&model.label, steps.clone(), accs));
        rollout = rollout.with_series(Series::new(&model.label, steps, rollouts));
        screened = true;
    }
    if !logged && !screened {
        return Ok(false);
    }
    let panels = usize::from(logged) + 2 * usize::from(screened);
    let title = if screened {
        "Training and screening on the validation split"
    } else {
        "Training"
    };
    let mut figure = Figure::new(title, panels);
    if logged {
        figure = figure.with_panel(loss);
    }
    if screened {
        figure = figure.with_panel(acc).with_panel(rollout);
    }
    figure
        .write_png(path)
        .with_context(|| format!("drawing {}", path.display()))?;
    Ok(true)
}

/// Height in pixels of the caption strip above each panel of `rollouts.gif`.
const CAPTION_SIZE: f64 = 14.0;

/// `picture` with a strip above it that holds `caption`, centred (clipped at the sides when the
/// picture is narrower than the text), in dark grey on `background`.
pub(crate) fn captioned(
    picture: &RgbImage,
    caption: &str,
    background: [u8; 3],
) -> Result<RgbImage> {
    let (text_width, text_height) = phi_plot::text_size(caption, CAPTION_SIZE)?;
    let strip = text_height + 6;
    let mut image = RgbImage::new(picture.width, picture.height + strip, background);
    let row = 3 * picture.width as usize;
    image.pixels[strip as usize * row..].copy_from_slice(&picture.pixels);
    let x = (i64::from(picture.width) - i64::from(text_width)) / 2;
    phi_plot::draw_text(
        &mut image.pixels,
        (image.width, image.height),
        caption,
        (x.max(2) as i32, 3),
        CAPTION_SIZE,
        [40, 40, 40],
    )
    .with_context(|| format!("drawing the caption '{caption}'"))?;
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A log named `train.csv` with `text` in a fresh folder of the test `test`.
    fn log(test: &str, text: &str) -> std::path::PathBuf {
        let path = crate::output::test_util::temp_dir(&format!("plots-{test}")).join("train.csv");
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn a_log_is_read_by_its_header_and_rows_with_a_gap_are_skipped() {
        // Columns are found by name, wherever they stand.
        let path = log(
            "header",
            "loss,step,valid_mse_acc1,valid_rollout_mse\n\
             2.5,100,,\n\
             1.5,200,0.75,0.125\n",
        );
        let [step, loss] = read_columns(&path, ["step", "loss"]).unwrap();
        assert_eq!((step, loss), (vec![100.0, 200.0], vec![2.5, 1.5]));
        let screened = read_columns(&path, ["step", "valid_mse_acc1", "valid_rollout_mse"]);
        assert_eq!(screened.unwrap(), [vec![200.0], vec![0.75], vec![0.125]]);
    }

    #[test]
    fn a_missing_column_or_a_word_in_a_number_field_names_the_file_and_the_line() {
        let path = log("column", "step,learning_rate\n100,0.001\n");
        let error = format!("{:#}", read_columns(&path, ["step", "loss"]).unwrap_err());
        assert!(
            error.contains("train.csv") && error.contains("no column 'loss'"),
            "{error}"
        );
        let path = log("number", "step,loss\n100,1.0\n200,nan?\n");
        let error = format!("{:#}", read_columns(&path, ["step", "loss"]).unwrap_err());
        assert!(
            error.contains("line 3") && error.contains("'nan?'"),
            "{error}"
        );
    }
}
