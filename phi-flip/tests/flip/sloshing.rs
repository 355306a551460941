//! First-mode sloshing in a closed tank against linear wave theory, for every transfer and
//! update scheme: the period of the surface at a wall and how much of its amplitude each half
//! cycle keeps.

use phi_core::fields::Transfer;

use super::*;

/// Tank length `L` and still depth `h` (cells), the initial amplitude of the surface (cells),
/// the time step (s) and particles per cell. The period error shrinks with the cells per
/// wavelength (measured with linear transfer and FLIP: +6 % at 32 × 16 cells deep 16, +3 % here,
/// +2 % at 64 × 32), so this is the coarsest tank that keeps it at a few per cent.
const LENGTH: f32 = 48.0;
const DEPTH: f32 = 16.0;
const AMPLITUDE: f32 = 2.0;
const DT: f32 = 0.1;
const PARTICLES_PER_CELL: usize = 8;
/// Half cycles over which the amplitude decay is measured.
const HALF_CYCLES: usize = 3;

/// The update of the particle velocities.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scheme {
    Flip,
    Pic,
    /// `flip_ratio = 0.9`.
    Blend,
    Apic,
}

/// Linear theory's period of the first mode, `2π / ω` with `ω² = g k tanh(k h)`, `k = π / L`.
fn linear_theory_period() -> f32 {
    let k = std::f32::consts::PI / LENGTH;
    2.0 * std::f32::consts::PI / (9.81 * k * (k * DEPTH).tanh()).sqrt()
}

/// The surface elevation at the left wall over `steps` steps, for liquid starting at rest with
/// its surface at `h + a cos(π x / L)`.
///
/// The elevation is the first mode's amplitude read from the liquid's horizontal centroid: for
/// a surface `h + η(x)` the centroid lies `(1 / L h) ∫ x η dx` right of `L / 2`, which for
/// `η = a cos(π x / L)` is `−2 a L / (π² h)`. Of the other modes the even ones do not move it
/// and the third enters with a ninth of its weight, and it averages over every particle, where
/// the liquid's height in the wall's columns moves in steps of one particle.
fn wall_elevation(transfer: Transfer, scheme: Scheme, steps: usize) -> Vec<f32> {
    let mut params = FlipParams::thesis(2, DT);
    params.transfer = transfer;
    (params.flip_ratio, params.apic) = match scheme {
        Scheme::Flip => (1.0, false),
        Scheme::Pic => (0.0, false),
        Scheme::Blend => (0.9, false),
        Scheme::Apic => (0.0, true),
    };
    let height = (DEPTH + 4.0 * AMPLITUDE) as usize;
    let sim = FlipSimulation::<Nd>::new(
        closed(&[LENGTH as usize, height]),
        params,
        vec![],
        vec![],
        0,
        &Default::default(),
    )
    .unwrap();
    let k = std::f32::consts::PI / LENGTH;
    let region = boxed(&[0.0, 0.0], &[LENGTH, DEPTH + AMPLITUDE]);
    let seeded = sim
        .seed(
            &region,
            &[0.0, 0.0],
            PARTICLES_PER_CELL,
            Placement::Jittered,
            11,
        )
        .unwrap()
        .positions
        .to_vec();
    let positions: Vec<f32> = seeded
        .chunks(2)
        .filter(|p| p[1] < DEPTH + AMPLITUDE * (k * p[0]).cos())
        .flatten()
        .copied()
        .collect();
    let elevation = |p: &[f32]| -> f32 {
        let offset = centre(p, 2)[0] - LENGTH / 2.0;
        -offset * std::f32::consts::PI.powi(2) * DEPTH / (2.0 * LENGTH)
    };
    let n = positions.len() / 2;
    let mut p = Particles::from_host(positions, vec![0.0; 2 * n], 2, &Default::default()).unwrap();
    let mut series = vec![elevation(&p.positions.to_vec())];
    for step in 0..steps {
        p = sim.step(&p, step).unwrap().0;
        series.push(elevation(&p.positions.to_vec()));
    }
    series
}

/// The period (s) from the first and the third zero crossing of `x` (linearly interpolated
/// between steps), or `None` with fewer than three crossings.
fn period_from_zero_crossings(x: &[f32]) -> Option<f32> {
    let crossings: Vec<f32> = x
        .windows(2)
        .enumerate()
        .filter(|(_, w)| w[0] != 0.0 && w[0].signum() != w[1].signum())
        .map(|(i, w)| (i as f32 + w[0] / (w[0] - w[1])) * DT)
        .collect();
    (crossings.len() >= 3).then(|| crossings[2] - crossings[0])
}

/// The largest `|x|` of each half cycle (from one zero crossing to the next), starting with
/// the half cycle that holds `x[0]`.
fn half_cycle_amplitudes(x: &[f32]) -> Vec<f32> {
    let mut out = vec![x[0].abs()];
    for w in x.windows(2) {
        if w[0].signum() != w[1].signum() {
            out.push(0.0);
        }
        let last = out.last_mut().expect("starts with one");
        *last = last.max(w[1].abs());
    }
    out
}

struct Sloshing {
    transfer: Transfer,
    scheme: Scheme,
    /// Seconds.
    period: f32,
    /// The fraction of the amplitude kept per half cycle: the geometric mean over the first
    /// `HALF_CYCLES`.
    kept: f32,
}

fn slosh(transfer: Transfer, scheme: Scheme) -> Sloshing {
    // The third half cycle ends at 1.75 periods (a little later on this grid): run for two.
    let steps = (2.0 * linear_theory_period() / DT).ceil() as usize;
    let x = wall_elevation(transfer, scheme, steps);
    let amplitudes = half_cycle_amplitudes(&x);
    assert!(
        amplitudes.len() > HALF_CYCLES + 1,
        "{transfer:?} {scheme:?}: only {} half cycles: {amplitudes:?}",
        amplitudes.len()
    );
    Sloshing {
        transfer,
        scheme,
        period: period_from_zero_crossings(&x)
            .unwrap_or_else(|| panic!("{transfer:?} {scheme:?}: fewer than three zero crossings")),
        kept: (amplitudes[HALF_CYCLES] / amplitudes[0]).powf(1.0 / HALF_CYCLES as f32),
    }
}

/// A 48 × 16 cells deep first mode (`k h = π / 3`, amplitude 2 cells) for each transfer and
/// scheme. Measured (period against linear theory, amplitude kept per half cycle):
///
/// | | FLIP | PIC | blend 0.9 | APIC |
/// |---|---|---|---|---|
/// | linear | +3.3 %, 95.2 % | +3.5 %, 91.2 % | +3.9 %, 95.6 % | +1.8 %, 92.3 % |
/// | nearest | +3.6 %, 93.7 % | +3.1 %, 91.0 % | +3.3 %, 92.4 % | +3.0 %, 94.0 % |
///
/// Held to: the period within 5 % of theory; at least 88 % kept (90 % with FLIP) and never
/// more than all of it; PIC keeping less than FLIP; and nearest within 5 points of linear. The
/// last is what broke when the projection saw the nearest transfer's empty surface faces
/// without the extrapolation of `make_incompressible`: nearest then kept 48–55 %.
#[test]
fn sloshing_period_and_decay_for_every_transfer_and_scheme() {
    let theory = linear_theory_period();
    let cases: Vec<(Transfer, Scheme)> = [Transfer::Linear, Transfer::NearestFace]
        .into_iter()
        .flat_map(|t| [Scheme::Flip, Scheme::Pic, Scheme::Blend, Scheme::Apic].map(move |s| (t, s)))
        .collect();
    let results: Vec<Sloshing> = std::thread::scope(|scope| {
        let runs: Vec<_> = cases
            .iter()
            .map(|&(t, s)| scope.spawn(move || slosh(t, s)))
            .collect();
        runs.into_iter().map(|r| r.join().unwrap()).collect()
    });
    println!("linear theory: period {theory:.3} s");
    println!("transfer     scheme  period (s)  against theory  kept per half cycle");
    for r in &results {
        println!(
            "{:<12} {:<6} {:>10.3} {:>+13.1} % {:>17.1} %",
            format!("{:?}", r.transfer),
            format!("{:?}", r.scheme),
            r.period,
            100.0 * (r.period / theory - 1.0),
            100.0 * r.kept
        );
    }
    let find = |t: Transfer, s: Scheme| {
        results
            .iter()
            .find(|r| r.transfer == t && r.scheme == s)
            .expect("every case ran")
    };
    for r in &results {
        let name = format!("{:?} {:?}", r.transfer, r.scheme);
        assert!(
            (r.period / theory - 1.0).abs() < 0.05,
            "{name}: period {:.3} s, linear theory {theory:.3} s",
            r.period
        );
        let least = if r.scheme == Scheme::Flip { 0.90 } else { 0.88 };
        assert!(
            r.kept > least && r.kept < 1.0,
            "{name}: keeps {:.1} % of the amplitude per half cycle",
            100.0 * r.kept
        );
        let linear = find(Transfer::Linear, r.scheme);
        assert!(
            (r.kept - linear.kept).abs() < 0.05,
            "{name}: keeps {:.1} % per half cycle, linear transfer {:.1} %",
            100.0 * r.kept,
            100.0 * linear.kept
        );
    }
    for t in [Transfer::Linear, Transfer::NearestFace] {
        let (flip, pic) = (find(t, Scheme::Flip), find(t, Scheme::Pic));
        assert!(
            pic.kept < flip.kept,
            "{t:?}: PIC keeps {:.1} %, FLIP {:.1} %",
            100.0 * pic.kept,
            100.0 * flip.kept
        );
    }
}
