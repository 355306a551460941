//! Axis ranges, tick positions and tick labels.
//!
//! An [`Axis`] works in *plot space*: the data value itself on a linear axis, `log10` of it on a
//! logarithmic one. Drawing then only ever needs a linear mapping from plot space to pixels, and
//! one tick algorithm serves both kinds of axis.

use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};

/// Fraction of the data span added on each side of an axis, so that no curve lies on the frame.
const MARGIN: f64 = 0.04;

/// Half-width, in decades, of a logarithmic axis over data of one single value.
const CONSTANT_LOG_HALF_WIDTH: f64 = 0.1;

/// Relative half-width of a linear axis over data of one single non-zero value.
const CONSTANT_LINEAR_HALF_WIDTH: f64 = 0.05;

/// One axis of a chart: its range, its ticks and their labels, all in plot space.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Axis {
    /// Lower end of the axis in plot space.
    pub lo: f64,
    /// Upper end of the axis in plot space.
    pub hi: f64,
    /// Whether plot space is `log10` of the data.
    pub log: bool,
    /// Positions of the labelled ticks in plot space, ascending.
    pub ticks: Vec<f64>,
    /// The label of each tick.
    pub labels: Vec<String>,
    /// Unlabelled minor ticks in plot space (2·10ᵏ … 9·10ᵏ on a logarithmic axis), drawn as light
    /// grid lines.
    pub minor: Vec<f64>,
}

/// Where an axis must reach regardless of the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Anchor {
    /// The range is the data's, with a margin on both sides.
    None,
    /// The range includes zero exactly, with no margin beyond it (bar charts on a linear axis).
    Zero,
}

impl Axis {
    /// An axis over `values` (plot-space values of the drawable data: finite, and on a
    /// logarithmic axis `log10` of the positive data), with about `target_ticks` labelled
    /// ticks.
    ///
    /// The range is the values' extent plus [`MARGIN`] of it on each side. Values that are all
    /// equal get a range of ±5 % around them (±1 around zero; ±0.1 decade on a logarithmic
    /// axis), so that the axis is never degenerate. Returns `None` when there is no value.
    pub fn from_data(
        values: impl IntoIterator<Item = f64>,
        log: bool,
        anchor: Anchor,
        target_ticks: usize,
    ) -> Option<Axis> {
        let (mut lo, mut hi) =
            values
                .into_iter()
                .fold(None, |acc: Option<(f64, f64)>, v| match acc {
                    None => Some((v, v)),
                    Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
                })?;
        let include_zero = anchor == Anchor::Zero && !log;
        if include_zero {
            lo = lo.min(0.0);
            hi = hi.max(0.0);
        }
        if hi - lo <= f64::EPSILON * lo.abs().max(hi.abs()) {
            let centre = 0.5 * (lo + hi);
            let half = if log {
                CONSTANT_LOG_HALF_WIDTH
            } else if centre != 0.0 {
                CONSTANT_LINEAR_HALF_WIDTH * centre.abs()
            } else {
                1.0
            };
            (lo, hi) = (centre - half, centre + half);
        } else {
            let pad = MARGIN * (hi - lo);
            if !(include_zero && lo == 0.0) {
                lo -= pad;
            }
            if !(include_zero && hi == 0.0) {
                hi += pad;
            }
        }
        Some(Axis::with_range(lo, hi, log, target_ticks))
    }

    /// An axis over the plot-space range `lo..hi` (`lo < hi`) with about `target_ticks` ticks.
    pub(crate) fn with_range(lo: f64, hi: f64, log: bool, target_ticks: usize) -> Axis {
        let target = target_ticks.max(2);
        let (ticks, labels, minor) = if log {
            log_ticks(lo, hi, target)
        } else {
            let (ticks, labels) = linear_ticks(lo, hi, target);
            (ticks, labels, Vec::new())
        };
        Axis {
            lo,
            hi,
            log,
            ticks,
            labels,
            minor,
        }
    }

    /// A categorical axis over `names`: category `i` spans `i..i + 1`, labelled at its centre.
    pub(crate) fn categories(names: &[String]) -> Axis {
        Axis {
            lo: 0.0,
            hi: names.len() as f64,
            log: false,
            ticks: (0..names.len()).map(|i| i as f64 + 0.5).collect(),
            labels: names.to_vec(),
            minor: Vec::new(),
        }
    }

    /// The label of the tick nearest to the plot-space value `v` (the chart library asks for
    /// labels by position; the positions are exactly [`Axis::ticks`]).
    pub(crate) fn label_at(&self, v: f64) -> String {
        self.ticks
            .iter()
            .zip(&self.labels)
            .min_by(|(a, _), (b, _)| (*a - v).abs().total_cmp(&(*b - v).abs()))
            .map(|(_, label)| label.clone())
            .unwrap_or_default()
    }
}

/// The pixel of plot-space value `v` on an axis from `lo` to `hi` drawn from pixel `limit.0`
/// to pixel `limit.1` (in either direction).
pub(crate) fn pixel_of(lo: f64, hi: f64, v: f64, (start, end): (i32, i32)) -> i32 {
    let fraction = (v - lo) / (hi - lo);
    start + (f64::from(end - start) * fraction).round() as i32
}

/// The axis as plotters' coordinate along one direction: a linear map of plot space, with our
/// ticks as its bold key points and the minor ticks as its light ones.
impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        pixel_of(self.lo, self.hi, *value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// The step of a "nice" tick sequence over `lo..=hi`: of the steps 1, 2 and 5 times a power of
/// ten that give at least two ticks, the one whose number of intervals is nearest to `target`
/// (by ratio).
fn nice_step(lo: f64, hi: f64, target: usize) -> f64 {
    let span = hi - lo;
    let raw = span / target as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let misfit = |step: f64| (span / step / target as f64).ln().abs();
    // A tenth of the magnitude gives at least ten times `target` intervals, so some candidate
    // always has two ticks.
    [0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|f| f * magnitude)
        .filter(|&step| tick_range(lo, hi, step).count() >= 2)
        .min_by(|&a, &b| misfit(a).total_cmp(&misfit(b)))
        .unwrap_or(raw)
}

/// The multiples `k` of `step` with `k · step` in `lo..=hi`.
fn tick_range(lo: f64, hi: f64, step: f64) -> std::ops::RangeInclusive<i64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    first..=last
}

/// Ticks at the multiples of a nice step inside `lo..=hi`, with labels of one common precision.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, Vec<String>) {
    let step = nice_step(lo, hi, target);
    let ticks: Vec<f64> = tick_range(lo, hi, step).map(|k| k as f64 * step).collect();
    let labels = format_linear(&ticks, step);
    (ticks, labels)
}

/// The decimals that the positive `step` needs: the least `d` with `step · 10ᵈ` a whole number
/// (up to rounding), e.g. 2 for 0.25, 0 for 3 and −1 for 50.
fn decimals_of(step: f64) -> i32 {
    let first = -(step.log10().floor() as i32);
    (first..first + 17)
        .find(|&d| {
            let scaled = step * 10f64.powi(d);
            (scaled - scaled.round()).abs() < 1e-6 * scaled
        })
        .unwrap_or(first + 16)
}

/// Labels for ticks spaced `step` apart: plain decimals with as many digits as the step needs,
/// or scientific notation (`2.5×10⁻⁴`) when the largest tick is below 10⁻³ or at least 10⁶.
pub(crate) fn format_linear(ticks: &[f64], step: f64) -> Vec<String> {
    let max_abs = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let step_decimals = decimals_of(step);
    let scientific = max_abs > 0.0 && !(1e-3..1e6).contains(&max_abs);
    if !scientific {
        let decimals = step_decimals.max(0) as usize;
        return ticks
            .iter()
            .map(|v| with_minus_sign(format!("{v:.decimals$}")))
            .collect();
    }
    // One mantissa precision for all ticks: what the tick with the largest exponent needs to
    // show the step.
    let precision = ticks
        .iter()
        .filter(|v| **v != 0.0)
        .map(|v| ((v.abs().log10() + 1e-9).floor() as i32 + step_decimals).max(0))
        .max()
        .unwrap_or(0) as usize;
    ticks
        .iter()
        .map(|&v| {
            if v == 0.0 {
                "0".to_string()
            } else {
                scientific_label(&format!("{v:.precision$e}"))
            }
        })
        .collect()
}

/// Rewrites Rust's `{:e}` output (`-2.5e-4`) as `−2.5×10⁻⁴` (`10⁻⁴` for a mantissa of 1).
fn scientific_label(rust_e: &str) -> String {
    let (mantissa, exponent) = rust_e.split_once('e').unwrap_or((rust_e, "0"));
    let power = format!("10{}", superscript(exponent));
    let label = match mantissa {
        "1" => power,
        "-1" => format!("-{power}"),
        _ => format!("{mantissa}×{power}"),
    };
    with_minus_sign(label)
}

/// Digits and minus sign as Unicode superscripts (DejaVu Sans has them all).
fn superscript(digits: &str) -> String {
    digits
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            '0' => '⁰',
            '1' => '¹',
            '2' => '²',
            '3' => '³',
            '4' => '⁴',
            '5' => '⁵',
            '6' => '⁶',
            '7' => '⁷',
            '8' => '⁸',
            '9' => '⁹',
            other => other,
        })
        .collect()
}

/// A typographic minus sign (U+2212) instead of a hyphen in front of a number.
fn with_minus_sign(label: String) -> String {
    match label.strip_prefix('-') {
        Some(rest) => format!("−{rest}"),
        None => label,
    }
}

/// The value `m·10ᵏ`, parsed from its decimal text so that it is the double nearest to it
/// (`10f64.powi(-3)` is not).
fn decimal(m: u32, k: i32) -> f64 {
    format!("{m}e{k}").parse().unwrap_or(f64::NAN)
}

/// Labels of the ticks `m·10ᵏ` of a logarithmic axis: plain decimals when every tick lies
/// between 10⁻³ and 10⁴, otherwise all as `m×10ᵏ` (`10ᵏ` for m = 1).
fn log_labels(ticks: &[(u32, i32)]) -> Vec<String> {
    let plain = ticks.iter().all(|(_, k)| (-3..=4).contains(k));
    ticks
        .iter()
        .map(|&(m, k)| {
            if plain {
                format!("{}", decimal(m, k))
            } else {
                scientific_label(&format!("{m}e{k}"))
            }
        })
        .collect()
}

/// The values `m·10ᵏ` for the mantissas `m` inside the plot-space range `lo..=hi`, ascending.
fn mantissa_ticks(lo: f64, hi: f64, mantissas: &[u32]) -> Vec<(u32, i32)> {
    let mut ticks = Vec::new();
    for k in (lo.floor() as i32)..=(hi.ceil() as i32) {
        for &m in mantissas {
            let v = decimal(m, k).log10();
            if v >= lo - 1e-9 && v <= hi + 1e-9 {
                ticks.push((m, k));
            }
        }
    }
    ticks
}

/// Ticks of a logarithmic axis over the plot-space (decade) range `lo..=hi`: positions,
/// labels and minor positions.
///
/// Over three or more powers of ten: those powers (every n-th one if there are more than
/// `target`), with 2…9·10ᵏ as minor ticks when every power is labelled. Over less: 1, 2 and
/// 5·10ᵏ (the other mantissas as minor ticks), or failing that 1…9·10ᵏ; over a range too narrow
/// for two of those, linear ticks in data space.
fn log_ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, Vec<String>, Vec<f64>) {
    let position = |&(m, k): &(u32, i32)| decimal(m, k).log10();
    let powers = mantissa_ticks(lo, hi, &[1]);
    let one_two_five = mantissa_ticks(lo, hi, &[1, 2, 5]);
    let fits = |ticks: &[(u32, i32)]| ticks.len() >= 2 && ticks.len() <= target + 2;
    if powers.len() >= 3 || (powers.len() == 2 && !fits(&one_two_five)) {
        let stride = powers.len().div_ceil(target) as i32;
        // Every stride-th power, at multiples of the stride (so that 10⁰ is one) unless that
        // leaves fewer than two.
        let every = |offset: i32| -> Vec<(u32, i32)> {
            powers
                .iter()
                .copied()
                .filter(|(_, k)| (k - offset).rem_euclid(stride) == 0)
                .collect()
        };
        let mut labelled = every(0);
        if labelled.len() < 2 {
            labelled = every(powers[0].1);
        }
        let minor = if stride == 1 {
            mantissa_ticks(lo, hi, &[2, 3, 4, 5, 6, 7, 8, 9])
                .iter()
                .map(position)
                .collect()
        } else {
            Vec::new()
        };
        return (
            labelled.iter().map(position).collect(),
            log_labels(&labelled),
            minor,
        );
    }
    if fits(&one_two_five) {
        let minor = mantissa_ticks(lo, hi, &[3, 4, 6, 7, 8, 9])
            .iter()
            .map(position)
            .collect();
        return (
            one_two_five.iter().map(position).collect(),
            log_labels(&one_two_five),
            minor,
        );
    }
    let all = mantissa_ticks(lo, hi, &[1, 2, 3, 4, 5, 6, 7, 8, 9]);
    if fits(&all) {
        return (
            all.iter().map(position).collect(),
            log_labels(&all),
            Vec::new(),
        );
    }
    let (values, labels) = linear_ticks(10f64.powf(lo), 10f64.powf(hi), target.min(4));
    let ticks = values.iter().map(|v| v.log10()).collect();
    (ticks, labels, Vec::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps_are_one_two_five_times_a_power_of_ten() {
        assert_eq!(nice_step(0.0, 1.0, 5), 0.2);
        assert_eq!(nice_step(0.0, 1.0, 10), 0.1);
        // For 5 intervals over 7, steps of 1 (7 intervals) are nearer by ratio than steps of 2
        // (3.5 intervals).
        assert_eq!(nice_step(0.0, 7.0, 5), 1.0);
        assert_eq!(nice_step(0.0, 300.0, 4), 100.0);
        assert!((nice_step(0.0, 3e-4, 6) - 5e-5).abs() < 1e-20);
        // A narrow range off zero still gets two ticks.
        let step = nice_step(7.7e-13, 8.4e-13, 2);
        assert!(tick_range(7.7e-13, 8.4e-13, step).count() >= 2, "{step}");
    }

    #[test]
    fn linear_ticks_are_step_multiples_with_common_precision() {
        let axis = Axis::with_range(-0.04, 1.04, false, 5);
        assert_eq!(axis.ticks, [0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]);
        assert_eq!(axis.labels, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        let axis = Axis::with_range(-130.0, 40.0, false, 4);
        assert_eq!(axis.labels, ["−100", "−50", "0"]);
        assert!(axis.minor.is_empty());
    }

    #[test]
    fn decimals_are_those_of_the_step() {
        assert_eq!(decimals_of(0.25), 2);
        assert_eq!(decimals_of(0.2), 1);
        assert_eq!(decimals_of(3.0), 0);
        assert_eq!(decimals_of(50.0), -1);
        assert_eq!(decimals_of(2e-4), 4);
        assert_eq!(decimals_of(2.5e-7), 8);
    }

    #[test]
    fn small_and_large_values_get_scientific_labels() {
        assert_eq!(
            format_linear(&[0.0, 2e-4, 4e-4, 6e-4], 2e-4),
            ["0", "2×10⁻⁴", "4×10⁻⁴", "6×10⁻⁴"]
        );
        assert_eq!(
            format_linear(&[2e-5, 4e-5, 6e-5, 8e-5, 1e-4], 2e-5),
            ["2.0×10⁻⁵", "4.0×10⁻⁵", "6.0×10⁻⁵", "8.0×10⁻⁵", "1.0×10⁻⁴"]
        );
        // From 10⁻³ on, plain decimals.
        assert_eq!(format_linear(&[5e-4, 1e-3], 5e-4), ["0.0005", "0.0010"]);
        assert_eq!(
            format_linear(&[0.5e-4, 0.75e-4], 0.25e-4),
            ["5.0×10⁻⁵", "7.5×10⁻⁵"]
        );
        assert_eq!(format_linear(&[0.25, 0.5], 0.25), ["0.25", "0.50"]);
        assert_eq!(format_linear(&[-1e6, 1e6], 1e6), ["−10⁶", "10⁶"]);
        assert_eq!(
            format_linear(&[0.0, 5e4, 1e5], 5e4),
            ["0", "50000", "100000"]
        );
        assert_eq!(format_linear(&[2e6, 2.5e6], 5e5), ["2.0×10⁶", "2.5×10⁶"]);
        assert_eq!(format_linear(&[0.001, 0.002], 0.001), ["0.001", "0.002"]);
    }

    #[test]
    fn ranges_have_a_margin_and_never_collapse() {
        let axis = Axis::from_data([0.0, 10.0, 4.0], false, Anchor::None, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (-0.4, 10.4));
        let axis = Axis::from_data([5.0, 5.0], false, Anchor::None, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (4.75, 5.25));
        let axis = Axis::from_data([0.0], false, Anchor::None, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (-1.0, 1.0));
        let axis = Axis::from_data([-3.0], true, Anchor::None, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (-3.1, -2.9));
        assert!(axis.ticks.len() >= 2, "{axis:?}");
        // Bars: zero is included exactly, without a margin below it.
        let axis = Axis::from_data([1.0, 3.0], false, Anchor::Zero, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (0.0, 3.12));
        let axis = Axis::from_data([-2.0, -2.0], false, Anchor::Zero, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (-2.08, 0.0));
        let axis = Axis::from_data([0.0, 0.0], false, Anchor::Zero, 5).unwrap();
        assert_eq!((axis.lo, axis.hi), (-1.0, 1.0));
        assert!(Axis::from_data([], false, Anchor::None, 5).is_none());
    }

    #[test]
    fn log_ticks_over_many_decades_are_powers_of_ten() {
        let axis = Axis::with_range(-6.2, 2.3, true, 5);
        assert_eq!(axis.ticks, [-6.0, -4.0, -2.0, 0.0, 2.0]);
        assert_eq!(axis.labels, ["10⁻⁶", "10⁻⁴", "10⁻²", "10⁰", "10²"]);
        assert!(axis.minor.is_empty());
        let axis = Axis::with_range(-3.1, 0.2, true, 6);
        assert_eq!(axis.labels, ["0.001", "0.01", "0.1", "1"]);
        // 8 and 9·10⁻⁴ (above 10^-3.1), then 2…9 in each of the three decades up to 1.
        assert_eq!(axis.minor.len(), 2 + 3 * 8);
        // Three powers for two ticks: the outer two.
        let axis = Axis::with_range(-13.3, -10.8, true, 2);
        assert_eq!(axis.labels, ["10⁻¹³", "10⁻¹¹"]);
    }

    #[test]
    fn log_ticks_within_two_decades_use_one_two_five() {
        let axis = Axis::with_range(-4.1, -2.4, true, 6);
        assert_eq!(axis.labels, ["10⁻⁴", "2×10⁻⁴", "5×10⁻⁴", "10⁻³", "2×10⁻³"]);
        // Narrower than 1 … 2: linear ticks in data space.
        let axis = Axis::with_range(2.5f64.log10(), 3.5f64.log10(), true, 5);
        assert_eq!(axis.labels, ["2.6", "2.8", "3.0", "3.2", "3.4"]);
    }

    /// Over ranges of every width and position, ticks lie inside the axis, ascend, and have
    /// distinct labels (the precision is enough to tell them apart).
    #[test]
    fn ticks_are_inside_ascending_and_distinct_for_any_range() {
        for log in [false, true] {
            for exponent in -12..=12 {
                for &width in &[1e-3, 0.07, 0.3, 1.0, 2.5, 9.0, 40.0] {
                    for &offset in &[-1.3, 0.0, 0.77] {
                        let (lo, hi) = if log {
                            let lo = f64::from(exponent) + offset;
                            (lo, lo + width)
                        } else {
                            let scale = 10f64.powi(exponent);
                            (offset * scale, (offset + width) * scale)
                        };
                        for target in [2, 5, 10] {
                            let axis = Axis::with_range(lo, hi, log, target);
                            let context = format!("{lo}..{hi} log={log} target={target}: {axis:?}");
                            assert!(axis.ticks.len() >= 2, "{context}");
                            assert!(axis.ticks.len() <= 2 * target + 2, "{context}");
                            let span = hi - lo;
                            assert!(
                                axis.ticks
                                    .iter()
                                    .all(|t| *t >= lo - 1e-9 * span && *t <= hi + 1e-9 * span),
                                "{context}"
                            );
                            assert!(axis.ticks.windows(2).all(|w| w[0] < w[1]), "{context}");
                            let mut labels = axis.labels.clone();
                            labels.dedup();
                            assert_eq!(labels.len(), axis.ticks.len(), "{context}");
                        }
                    }
                }
            }
        }
    }
}
