//! `phi dataset stats`: particle counts and the distribution of neighbour counts over time
//! (thesis fig. 5.4), printed and drawn as PNGs: percentiles as lines ([`plot`]) and the
//! share of particles per neighbour count as a heat map ([`heat_map`]).
//!
//! Neighbours of a liquid particle are the other particles (liquid or obstacle) within the
//! connectivity radius in stored units: the GNS graph's edges without the self-edge, counted by
//! [`phi_gns::graph::neighbour_counts`] on the graph's own cell list, `O(n)` time and memory per
//! frame.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use phi_gns::data::{Dataset, LIQUID, METADATA_FILE, Trajectory};
use phi_gns::graph::neighbour_counts;

use crate::memory::check_memory;
use crate::output::target::{OutputFile, check_file};
use rayon::prelude::*;

use phi_plot::{HeatMap, Legend, LinePlot, Series};

/// Neighbour counts from this value up share the last bin of the histograms.
pub const MAX_NEIGHBOURS: usize = 127;

/// What to measure.
#[derive(Debug, Clone)]
pub struct StatsOptions {
    /// The dataset directory.
    pub dir: PathBuf,
    /// The split (`None`: `train` if the dataset has it, else the first listed).
    pub split: Option<String>,
    /// Connectivity radius in stored units (thesis: 0.03).
    pub radius: f32,
    /// Use the first this many trajectories (thesis fig. 5.4: 50).
    pub limit: usize,
    /// Where to draw the plot, if anywhere.
    pub out: Option<PathBuf>,
    /// Replace an existing PNG `out` ([`STATS_OUTPUT`]).
    pub force: bool,
    /// Draw a progress bar over the trajectories on stderr.
    pub progress: bool,
}

/// What `phi dataset stats --out` writes: a PNG, replaced only with `--force`.
pub(crate) const STATS_OUTPUT: OutputFile = OutputFile {
    command: "phi dataset stats",
    flag: "--out",
    kind: "a PNG",
    magic: &[b"\x89PNG\r\n\x1a\n"],
};

/// Smallest, mean and largest of a count over trajectories.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Range {
    /// Smallest.
    pub min: usize,
    /// Mean.
    pub mean: f64,
    /// Largest.
    pub max: usize,
}

impl Range {
    fn of(values: &[usize]) -> Self {
        Range {
            min: values.iter().copied().min().unwrap_or(0),
            mean: values.iter().sum::<usize>() as f64 / values.len().max(1) as f64,
            max: values.iter().copied().max().unwrap_or(0),
        }
    }
}

/// The neighbour counts of one frame over all liquid particles of all trajectories.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameNeighbours {
    /// Mean.
    pub mean: f64,
    /// 5th, 25th, 50th, 75th and 95th percentiles.
    pub percentiles: [usize; 5],
    /// Largest.
    pub max: usize,
}

/// What `phi dataset stats` found.
#[derive(Debug, Clone)]
pub struct StatsReport {
    /// The split measured.
    pub split: String,
    /// Trajectories measured, and in the split.
    pub trajectories: (usize, usize),
    /// Frames per trajectory.
    pub frames: usize,
    /// Liquid particles per trajectory.
    pub liquid: Range,
    /// Obstacle particles per trajectory.
    pub obstacle: Range,
    /// All particles per trajectory.
    pub total: Range,
    /// Per frame: the neighbour distribution.
    pub neighbours: Vec<FrameNeighbours>,
    /// Per frame: how many liquid particles have `k` neighbours (`k` up to [`MAX_NEIGHBOURS`],
    /// the last bin holding that many or more).
    pub histogram: Vec<Vec<u64>>,
}

/// Measures `options.split` of the dataset (see the module docs) and draws the plot.
///
/// # Errors
/// A missing dataset or split, unreadable files, a non-positive radius.
pub fn dataset_stats(options: &StatsOptions) -> Result<StatsReport> {
    if !(options.radius.is_finite() && options.radius > 0.0) {
        bail!("--radius must be positive, got {}", options.radius);
    }
    if let Some(out) = &options.out {
        check_file(out, &STATS_OUTPUT, options.force)?;
        check_file(&heatmap_path(out), &STATS_OUTPUT, options.force)?;
    }
    let dataset = Dataset::open(&options.dir)?;
    let metadata = dataset.metadata();
    let split = match &options.split {
        Some(s) => s.clone(),
        None if metadata.splits.contains_key("train") => "train".into(),
        None => metadata
            .splits
            .keys()
            .next()
            .cloned()
            .with_context(|| format!("{} lists no split", options.dir.display()))?,
    };
    let available = crate::cli::split_len(&dataset, &options.dir, &split)?;
    let count = available.min(options.limit.max(1));
    let frames = metadata.frames();
    // The histograms of every trajectory measured and their sum; a worker's cell list and counts
    // are O(particles).
    let histograms = (count * frames) as f64 * (MAX_NEIGHBOURS + 1) as f64 * 8.0 * 2.0;
    check_memory(
        &format!(
            "the neighbour histograms of {count} {} of {frames} frames (--trajectories; split \
             {split:?} of {})",
            if count == 1 {
                "trajectory"
            } else {
                "trajectories"
            },
            options.dir.join(METADATA_FILE).display()
        ),
        histograms.min(u128::MAX as f64) as u128,
    )?;
    let bar = crate::progress::count_bar(count, "trajectories", options.progress);
    let per_trajectory: Vec<(usize, usize, Vec<Vec<u64>>)> = (0..count)
        .into_par_iter()
        .map(|index| -> Result<_> {
            let (trajectory, _) = dataset.read_with_stats(&split, index)?;
            let liquid = trajectory.liquid_particles();
            let histogram =
                neighbour_histogram(&trajectory, options.radius).with_context(|| {
                    format!(
                        "trajectory {index} of split {split:?} in {}",
                        options.dir.display()
                    )
                })?;
            bar.inc(1);
            Ok((liquid, trajectory.particles - liquid, histogram))
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();

    let liquid: Vec<usize> = per_trajectory.iter().map(|t| t.0).collect();
    let obstacle: Vec<usize> = per_trajectory.iter().map(|t| t.1).collect();
    let total: Vec<usize> = liquid.iter().zip(&obstacle).map(|(l, o)| l + o).collect();
    let mut histogram = vec![vec![0u64; MAX_NEIGHBOURS + 1]; frames];
    for (_, _, h) in &per_trajectory {
        for (sum, frame) in histogram.iter_mut().zip(h) {
            for (s, c) in sum.iter_mut().zip(frame) {
                *s += c;
            }
        }
    }
    let neighbours = histogram.iter().map(|h| summarise(h)).collect();
    let report = StatsReport {
        split,
        trajectories: (count, available),
        frames,
        liquid: Range::of(&liquid),
        obstacle: Range::of(&obstacle),
        total: Range::of(&total),
        neighbours,
        histogram,
    };
    if let Some(out) = &options.out {
        plot(&report, options.radius)?
            .write_png(out)
            .with_context(|| format!("drawing {}", out.display()))?;
        let heatmap = heatmap_path(out);
        heat_map(&report, options.radius)?
            .write_png(&heatmap)
            .with_context(|| format!("drawing {}", heatmap.display()))?;
    }
    Ok(report)
}

/// Where `--out PNG` puts the heat map: beside it, `{stem}_heatmap.png`.
pub(crate) fn heatmap_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    out.with_file_name(format!("{stem}_heatmap.png"))
}

/// Thesis fig. 5.4 as the thesis draws it: per frame (x), the share of the liquid particles of
/// every measured trajectory that have `k` neighbours (y, one row per count from 0 to the
/// largest seen), as a heat map with a colour bar.
///
/// # Errors
/// A report without frames (nothing to draw).
pub fn heat_map(report: &StatsReport, radius: f32) -> Result<HeatMap> {
    let frames = report.histogram.len();
    if frames == 0 {
        bail!("no frames to plot");
    }
    let rows = report
        .histogram
        .iter()
        .filter_map(|h| h.iter().rposition(|&c| c > 0))
        .max()
        .unwrap_or(0)
        + 1;
    let mut values = vec![0.0; rows * frames];
    for (t, histogram) in report.histogram.iter().enumerate() {
        let liquid: u64 = histogram.iter().sum();
        for (k, &count) in histogram.iter().take(rows).enumerate() {
            values[k * frames + t] = count as f64 / liquid.max(1) as f64;
        }
    }
    let (trajectories, _) = report.trajectories;
    Ok(HeatMap::new(
        format!(
            "Neighbours within R = {radius} of a liquid particle ({}, {trajectories} trajectories)",
            report.split
        ),
        "frame",
        "neighbours",
        "share of liquid particles",
        (rows, frames),
        values,
    )
    .with_extent((-0.5, frames as f64 - 0.5), (-0.5, rows as f64 - 0.5))
    .with_size(900, 520))
}

/// Per frame of `trajectory`, how many liquid particles have `k` neighbours within `radius`.
///
/// # Errors
/// A non-finite position, or a radius that is not positive and finite.
pub(crate) fn neighbour_histogram(
    trajectory: &Trajectory,
    radius: f32,
) -> Result<Vec<Vec<u64>>, phi_gns::graph::GraphError> {
    let liquid: Vec<bool> = trajectory
        .particle_type
        .iter()
        .map(|&t| t == LIQUID)
        .collect();
    (0..trajectory.frames)
        .map(|t| {
            let counts = neighbour_counts(trajectory.frame(t), trajectory.dim, f64::from(radius))?;
            let mut histogram = vec![0u64; MAX_NEIGHBOURS + 1];
            for (&count, _) in counts.iter().zip(&liquid).filter(|(_, l)| **l) {
                histogram[count.min(MAX_NEIGHBOURS)] += 1;
            }
            Ok(histogram)
        })
        .collect()
}

/// Mean, percentiles and maximum of a histogram of counts.
fn summarise(histogram: &[u64]) -> FrameNeighbours {
    let total: u64 = histogram.iter().sum();
    if total == 0 {
        return FrameNeighbours::default();
    }
    let mean = histogram
        .iter()
        .enumerate()
        .map(|(k, &c)| k as f64 * c as f64)
        .sum::<f64>()
        / total as f64;
    let percentile = |q: f64| {
        let rank = (q * total as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (k, &c) in histogram.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return k;
            }
        }
        histogram.len() - 1
    };
    FrameNeighbours {
        mean,
        percentiles: [0.05, 0.25, 0.5, 0.75, 0.95].map(percentile),
        max: histogram.iter().rposition(|&c| c > 0).unwrap_or(0),
    }
}

/// The plot of thesis fig. 5.4: the number of neighbours of a liquid particle against the
/// frame, over the liquid particles of every measured trajectory: the mean, the median with the
/// quartiles shaded, and the 5th and 95th percentiles, with axes, labels and a legend.
///
/// # Errors
/// A report without frames (nothing to draw).
pub fn plot(report: &StatsReport, radius: f32) -> Result<LinePlot> {
    if report.neighbours.is_empty() {
        bail!("no frames to plot");
    }
    let x: Vec<f64> = (0..report.neighbours.len()).map(|t| t as f64).collect();
    let column = |q: usize| -> Vec<f64> {
        report
            .neighbours
            .iter()
            .map(|f| f.percentiles[q] as f64)
            .collect()
    };
    let mean = report.neighbours.iter().map(|f| f.mean).collect();
    let (trajectories, _) = report.trajectories;
    Ok(LinePlot::new(
        format!(
            "Neighbours within R = {radius} of a liquid particle ({}, {trajectories} trajectories)",
            report.split
        ),
        "frame",
        "neighbours",
    )
    .with_size(900, 520)
    .with_legend(Legend::UpperRight)
    .with_series(Series::new("mean", x.clone(), mean))
    .with_series(
        Series::new("median, quartiles shaded", x.clone(), column(2))
            .with_band(column(1), column(3)),
    )
    .with_series(Series::new("5th percentile", x.clone(), column(0)))
    .with_series(Series::new("95th percentile", x, column(4))))
}

/// The printed form of a report: counts, then the neighbour distribution every `every` frames.
pub(crate) fn format_report(report: &StatsReport, dir: &Path, radius: f32, every: usize) -> String {
    let mut s = format!(
        "{}: split {}, {} of {} trajectories, {} frames\n",
        dir.display(),
        report.split,
        report.trajectories.0,
        report.trajectories.1,
        report.frames
    );
    for (name, r) in [
        ("liquid", report.liquid),
        ("obstacle", report.obstacle),
        ("all", report.total),
    ] {
        s += &format!(
            "  {name:<9} particles: min {:>5}  mean {:>8.1}  max {:>5}\n",
            r.min, r.mean, r.max
        );
    }
    s += &format!(
        "neighbours per liquid particle within {radius} (other particles of any type):\n\
         {:>7} {:>7} {:>4} {:>4} {:>4} {:>4} {:>4} {:>4}\n",
        "frame", "mean", "p5", "p25", "p50", "p75", "p95", "max"
    );
    for (t, f) in report.neighbours.iter().enumerate() {
        if t % every.max(1) == 0 || t + 1 == report.neighbours.len() {
            let [p5, p25, p50, p75, p95] = f.percentiles;
            s += &format!(
                "{t:>7} {:>7.2} {p5:>4} {p25:>4} {p50:>4} {p75:>4} {p95:>4} {:>4}\n",
                f.mean, f.max
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use phi_gns::data::OBSTACLE;

    use super::*;

    #[test]
    fn neighbour_histograms_match_brute_force() {
        // Two frames of 300 pseudo-random particles, a third of them obstacles.
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let n = 300;
        let position: Vec<f32> = (0..2 * n * 2).map(|_| 0.05 + 0.9 * next()).collect();
        let types: Vec<i64> = (0..n)
            .map(|i| if i % 3 == 0 { OBSTACLE } else { LIQUID })
            .collect();
        let t = Trajectory::new(2, position.clone(), types.clone(), 0, 0).unwrap();
        let radius = 0.07f32;
        let histogram = neighbour_histogram(&t, radius).unwrap();
        let r2 = f64::from(radius).powi(2);
        for frame in 0..2 {
            let p = &position[frame * n * 2..(frame + 1) * n * 2];
            let d = |i: usize, j: usize| f64::from(p[i]) - f64::from(p[j]);
            let mut expected = vec![0u64; MAX_NEIGHBOURS + 1];
            for i in (0..n).filter(|&i| types[i] == LIQUID) {
                let count = (0..n)
                    .filter(|&j| {
                        j != i && d(2 * i, 2 * j).powi(2) + d(2 * i + 1, 2 * j + 1).powi(2) <= r2
                    })
                    .count();
                expected[count.min(MAX_NEIGHBOURS)] += 1;
            }
            assert_eq!(histogram[frame], expected, "frame {frame}");
            assert!(expected[0] < 200, "the test needs neighbours");
        }
    }
}
