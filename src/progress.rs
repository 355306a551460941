//! Progress bars: of step-by-step runs (`phi simulate`, `phi rollout`) and of work over
//! trajectories (`phi dataset generate`, `export`, `import`, `stats`, `phi eval`); and whether
//! `phi -q` asked for no progress at all, bars or lines.

use std::sync::atomic::{AtomicBool, Ordering};

use indicatif::{ProgressBar, ProgressStyle};

/// Set by `phi -q`: no bar is drawn, whatever the callers pass.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Hides every progress bar made from now on (`phi --quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether `phi -q` asked for results and errors only: no bars, and no progress lines either.
pub(crate) fn is_quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// Whether a bar that the caller would `show` is drawn.
fn drawn(show: bool) -> bool {
    show && !is_quiet()
}

/// A bar of `steps` steps on stderr, or a hidden one unless `show` (callers pass whether stderr
/// is a terminal).
pub(crate) fn step_bar(steps: usize, show: bool) -> ProgressBar {
    if !drawn(show) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(steps as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {elapsed_precise} [{bar:40}] {pos}/{len} steps, {per_sec}, ETA {eta} {msg}",
        )
        .expect("a valid template")
        .progress_chars("=> "),
    );
    bar
}

/// A bar of `len` items (`unit`, e.g. "trajectories") on stderr, or a hidden one unless `show`.
pub(crate) fn count_bar(len: usize, unit: &str, show: bool) -> ProgressBar {
    if !drawn(show) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len as u64);
    let template = format!(
        "{{spinner}} {{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{per_sec}}, ETA {{eta}} {{msg}}"
    );
    bar.set_style(
        ProgressStyle::with_template(&template)
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar
}

/// A counter of items (`unit`) whose total is not known in advance, or a hidden one unless
/// `show`.
pub(crate) fn counter(unit: &str, show: bool) -> ProgressBar {
    if !drawn(show) {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    let template = format!("{{spinner}} {{elapsed_precise}} {{pos}} {unit}, {{per_sec}} {{msg}}");
    bar.set_style(ProgressStyle::with_template(&template).expect("a valid template"));
    bar
}

#[cfg(test)]
mod tests {
    use super::{drawn, is_quiet, set_quiet};

    /// `-q` hides a bar that would be drawn; without it, `show` decides.
    #[test]
    fn quiet_hides_every_bar() {
        set_quiet(true);
        let quiet = (is_quiet(), drawn(true), drawn(false));
        set_quiet(false);
        assert_eq!(quiet, (true, false, false));
        assert_eq!(
            (is_quiet(), drawn(true), drawn(false)),
            (false, true, false)
        );
    }
}
