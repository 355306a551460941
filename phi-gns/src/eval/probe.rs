//! The cheapest signal of whether a model has learnt anything: its one-step prediction for a
//! block of liquid in free fall, whose true acceleration is gravity, and for a pool at rest,
//! whose true acceleration is zero. The block may also be thrown sideways: its horizontal
//! velocity stays what it is in free fall (Galilean invariance), so a model that slows it down
//! (drag) or speeds it up has learnt a force that is not there.
//!
//! The scene is built analytically in the dataset's stored units, as the random scenes of
//! thesis table 5.1 seed their liquid (a fixed number of particles per cell, uniformly at random
//! inside each cell): a pool of the bottom `POOL_CELLS` rows across the whole domain, and a
//! square block of `BLOCK_CELLS` cells a side centred horizontally in the upper part of the
//! domain, at least `GAP_CELLS` cells above the pool (beyond the reach of the model's message
//! passing for the sizes used here, so that the two do not see each other). The block has
//! fallen from rest for `fallen` frames before the window starts; its positions are
//! `p₀ + ½ g (fallen + k)²` at window frame `k`, whose second difference is exactly `g`, so the
//! truth needs no simulation: free fall is free fall in FLIP too (pressure is zero in a block
//! surrounded by air). A thrown block moves `u` per frame along the first axis across gravity
//! as well, and is centred across at the frame after the window.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::EvalError;
use crate::data::{LIQUID, Metadata};
use crate::model::{Gns, GnsKernels, GraphBatch};

/// Rows of cells of the pool at rest.
pub(crate) const POOL_CELLS: usize = 4;
/// The side of the falling block, in cells.
pub(crate) const BLOCK_CELLS: usize = 6;
/// The least gap between the pool's surface and the block's lowest point, in cells.
pub(crate) const GAP_CELLS: usize = 12;

/// The probe scene: a window the model predicts from and which particles are which.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeScene {
    /// `[N, C + 1, dim]` row-major, oldest frame first, in stored units.
    pub window: Vec<f32>,
    /// `[N]`: every particle is liquid.
    pub particle_type: Vec<i64>,
    /// `[N]`: true for the particles of the falling block, false for the pool's.
    pub falling: Vec<bool>,
    /// The true acceleration of the block per component, stored units per frame².
    pub gravity: Vec<f64>,
    /// The block's velocity across gravity per component, stored units per frame (zeros when
    /// it is not thrown).
    pub throw: Vec<f64>,
}

/// A model's one-step predictions on the probe scene, as mean accelerations per component in
/// stored units per frame², and the same as fractions of `|g|`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeResult {
    /// The true acceleration of the falling block (gravity).
    pub gravity: Vec<f64>,
    /// The mean predicted acceleration of the falling block's particles.
    pub falling: Vec<f64>,
    /// The mean predicted acceleration of the pool's particles (truth: zero).
    pub resting: Vec<f64>,
    /// The root mean square over the pool's particles of the predicted acceleration's norm: the
    /// pool's jitter, which a mean hides.
    pub resting_rms: f64,
    /// The falling block's predicted acceleration along gravity, over `|g|` (truth: 1).
    pub falling_along_gravity: f64,
    /// The norm of the falling block's predicted acceleration across gravity, over `|g|`
    /// (truth: 0): the sideways push.
    pub falling_across_gravity: f64,
    /// The norm of the pool's mean predicted acceleration over `|g|` (truth: 0).
    pub resting_over_gravity: f64,
    /// The falling block's predicted acceleration along its throw, over `|g|` (truth: 0;
    /// negative: drag, positive: a push along the motion; 0 for a block that is not thrown).
    #[serde(default)]
    pub falling_along_throw: f64,
}

impl ProbeResult {
    /// The mean of several results (of scenes of different jitter), field by field.
    ///
    /// # Panics
    /// If `results` is empty.
    pub fn mean(results: &[ProbeResult]) -> ProbeResult {
        assert!(!results.is_empty(), "the mean of no probe results");
        let n = results.len() as f64;
        let scalar = |f: fn(&ProbeResult) -> f64| results.iter().map(f).sum::<f64>() / n;
        let vector = |f: fn(&ProbeResult) -> &Vec<f64>| {
            let mut sum = vec![0.0; f(&results[0]).len()];
            for r in results {
                for (s, x) in sum.iter_mut().zip(f(r)) {
                    *s += x / n;
                }
            }
            sum
        };
        ProbeResult {
            gravity: vector(|r| &r.gravity),
            falling: vector(|r| &r.falling),
            resting: vector(|r| &r.resting),
            resting_rms: scalar(|r| r.resting_rms),
            falling_along_gravity: scalar(|r| r.falling_along_gravity),
            falling_across_gravity: scalar(|r| r.falling_across_gravity),
            resting_over_gravity: scalar(|r| r.resting_over_gravity),
            falling_along_throw: scalar(|r| r.falling_along_throw),
        }
    }
}

/// The probe scene for models of a dataset of `metadata`, with `input_velocities` past
/// velocities, gravity `gravity_cells` (cells per second², per component; the random scenes'
/// is `[0, −9.81]`), the block thrown at `throw_cells` cells per second along the first axis
/// across gravity (0: dropped), `particles_per_cell` particles in each cell, the block `fallen`
/// frames into its fall and jitter from `seed`.
///
/// # Errors
/// [`EvalError::Input`] when the domain is too small for the pool, the gap and the block, when
/// `gravity_cells` has not `dim` components or is zero, when the throw is not finite or the
/// domain has no axis across gravity for it, or when the block would leave the domain within
/// the window.
pub fn probe_scene(
    metadata: &Metadata,
    input_velocities: usize,
    gravity_cells: &[f64],
    throw_cells: f64,
    particles_per_cell: usize,
    fallen: usize,
    seed: u64,
) -> Result<ProbeScene, EvalError> {
    let dim = metadata.dim;
    let fail = |reason: String| {
        Err(EvalError::Input {
            what: "probe scene",
            reason,
        })
    };
    if gravity_cells.len() != dim {
        return fail(format!(
            "gravity has {} components for a {dim}D dataset",
            gravity_cells.len()
        ));
    }
    let g_norm = gravity_cells.iter().map(|g| g * g).sum::<f64>().sqrt();
    if !(g_norm.is_finite() && g_norm > 0.0) {
        return fail("gravity must be finite and not zero".into());
    }
    let (scale, offset) = (metadata.position_scale, metadata.position_offset);
    let cells: Vec<usize> = metadata
        .bounds
        .iter()
        .map(|[lo, hi]| ((hi - lo) / scale).round() as usize)
        .collect();
    // "Up" is against gravity's largest component; the pool lies on the wall below.
    let vertical = (0..dim)
        .max_by(|&a, &b| gravity_cells[a].abs().total_cmp(&gravity_cells[b].abs()))
        .expect("dim ≥ 1");
    let down = gravity_cells[vertical].signum();
    let height = cells[vertical];
    if height < POOL_CELLS + GAP_CELLS + BLOCK_CELLS + 2
        || cells.iter().any(|&n| n < BLOCK_CELLS + 2)
    {
        return fail(format!(
            "a domain of {cells:?} cells is too small for a pool of {POOL_CELLS} rows, a gap of \
             {GAP_CELLS} and a block of {BLOCK_CELLS}"
        ));
    }
    let g_stored: Vec<f64> = gravity_cells
        .iter()
        .map(|g| g * scale * metadata.dt * metadata.dt)
        .collect();
    let across = (0..dim).find(|&a| a != vertical);
    let throw_axis = match across {
        _ if throw_cells == 0.0 => None,
        Some(axis) if throw_cells.is_finite() => Some(axis),
        Some(_) => return fail(format!("the throw must be finite, not {throw_cells}")),
        None => return fail("a 1D domain has no axis across gravity to throw along".into()),
    };
    // The block's offset across (cells) at window frame `k`, centred at frame `C + 1`.
    let throw_per_frame = throw_cells * metadata.dt;
    let offset_across = |k: usize| throw_per_frame * (k as f64 - (input_velocities + 1) as f64);
    if let Some(axis) = throw_axis {
        let room = (cells[axis] - BLOCK_CELLS) as f64 / 2.0 - 1.0;
        if offset_across(0).abs() > room {
            return fail(format!(
                "a throw of {throw_cells} cells/s moves the block {:.1} cells across the window: \
                 more than the {room} cells between it and the walls",
                offset_across(0).abs()
            ));
        }
    }
    let mut throw = vec![0.0f64; dim];
    if let Some(axis) = throw_axis {
        throw[axis] = throw_per_frame * scale;
    }
    // The block's lowest cell row (counted from the pool's wall) at frame `fallen + C + 1`,
    // the one after the window; it starts higher by the fall it makes until then.
    let frames = (fallen + input_velocities + 1) as f64;
    let drop_cells = 0.5 * g_norm * (frames * metadata.dt).powi(2);
    let block_row = POOL_CELLS + GAP_CELLS;
    if (block_row + BLOCK_CELLS) as f64 + drop_cells > height as f64 {
        return fail(format!(
            "the block falls {drop_cells:.1} cells before the window ends: it does not fit \
             between the gap and the top of a {height}-cell domain; use fewer fallen frames"
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut start = Vec::new();
    let mut falling = Vec::new();
    let jitter = |cell: &[usize], rng: &mut ChaCha8Rng, out: &mut Vec<f64>| {
        for _ in 0..particles_per_cell {
            for axis in 0..dim {
                // Cell coordinates counted from the pool's wall along the vertical axis.
                let c = cell[axis] as f64 + rng.random::<f64>();
                let x = if axis == vertical && down > 0.0 {
                    cells[axis] as f64 - c
                } else {
                    c
                };
                out.push(x);
            }
        }
    };
    let mut cell = vec![0usize; dim];
    for_each_cell(&cells, &mut cell, &mut |cell| {
        if cell[vertical] < POOL_CELLS {
            jitter(cell, &mut rng, &mut start);
            falling.extend(std::iter::repeat_n(false, particles_per_cell));
        }
    });
    for_each_cell(&cells, &mut cell, &mut |cell| {
        let inside = (0..dim).all(|axis| {
            let (lo, n) = if axis == vertical {
                (block_row, BLOCK_CELLS)
            } else {
                let lo = (cells[axis] - BLOCK_CELLS) / 2;
                (lo, BLOCK_CELLS)
            };
            (lo..lo + n).contains(&cell[axis])
        });
        if inside {
            jitter(cell, &mut rng, &mut start);
            falling.extend(std::iter::repeat_n(true, particles_per_cell));
        }
    });
    let n = falling.len();
    let c = input_velocities;
    // The block is lifted by the fall it makes before frame `fallen + C + 1`, when it reaches
    // `block_row`.
    let mut window = vec![0.0f32; n * (c + 1) * dim];
    for i in 0..n {
        for k in 0..=c {
            let t = (fallen + k) as f64;
            for axis in 0..dim {
                let x_cells = start[i * dim + axis];
                let x = if falling[i] {
                    let lift = -gravity_cells[axis] * 0.5 * (frames * metadata.dt).powi(2);
                    let across = if throw_axis == Some(axis) {
                        offset_across(k)
                    } else {
                        0.0
                    };
                    (x_cells + lift + across) * scale + offset + 0.5 * g_stored[axis] * t * t
                } else {
                    x_cells * scale + offset
                };
                window[(i * (c + 1) + k) * dim + axis] = x as f32;
            }
        }
    }
    Ok(ProbeScene {
        window,
        particle_type: vec![LIQUID; n],
        falling,
        gravity: g_stored,
        throw,
    })
}

/// Visits every cell index of a grid of `cells` in row-major order.
fn for_each_cell(cells: &[usize], index: &mut [usize], visit: &mut dyn FnMut(&[usize])) {
    let total: usize = cells.iter().product();
    for flat in 0..total {
        let mut rest = flat;
        for axis in (0..cells.len()).rev() {
            index[axis] = rest % cells[axis];
            rest /= cells[axis];
        }
        visit(index);
    }
}

/// `model`'s one-step predictions on `scene`.
///
/// # Errors
/// Model errors (a scene of another dimension or window length than the model's).
pub fn probe<B: GnsKernels>(
    model: &Gns<B>,
    scene: &ProbeScene,
    device: &B::Device,
) -> Result<ProbeResult, EvalError> {
    let batch = GraphBatch::from_host(&scene.window, &scene.particle_type, model.spec(), device)?;
    let predicted = model.acceleration(&batch)?.to_vec();
    let dim = scene.gravity.len();
    let mean_of = |which: bool| -> Vec<f64> {
        let mut sum = vec![0.0f64; dim];
        let mut count = 0usize;
        for (i, _) in scene
            .falling
            .iter()
            .enumerate()
            .filter(|(_, f)| **f == which)
        {
            count += 1;
            for (a, s) in sum.iter_mut().enumerate() {
                *s += f64::from(predicted[i * dim + a]);
            }
        }
        sum.iter().map(|s| s / count.max(1) as f64).collect()
    };
    let falling = mean_of(true);
    let resting = mean_of(false);
    let (mut square, mut count) = (0.0f64, 0usize);
    for (i, _) in scene.falling.iter().enumerate().filter(|(_, f)| !**f) {
        count += 1;
        square += (0..dim)
            .map(|a| f64::from(predicted[i * dim + a]).powi(2))
            .sum::<f64>();
    }
    let g = &scene.gravity;
    let g_norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
    let along = falling.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() / g_norm;
    let across = (falling.iter().map(|a| a * a).sum::<f64>() - along * along)
        .max(0.0)
        .sqrt();
    let resting_norm = resting.iter().map(|a| a * a).sum::<f64>().sqrt();
    let u_norm = scene.throw.iter().map(|x| x * x).sum::<f64>().sqrt();
    let along_throw = if u_norm > 0.0 {
        falling
            .iter()
            .zip(&scene.throw)
            .map(|(a, u)| a * u)
            .sum::<f64>()
            / u_norm
    } else {
        0.0
    };
    Ok(ProbeResult {
        gravity: g.clone(),
        falling,
        resting,
        resting_rms: (square / count.max(1) as f64).sqrt(),
        falling_along_gravity: along / g_norm,
        falling_across_gravity: across / g_norm,
        resting_over_gravity: resting_norm / g_norm,
        falling_along_throw: along_throw / g_norm,
    })
}
