//! Row-block kernels on host slices, shared by the fused GNS kernels of the CPU backends: the
//! forward passes of a dense layer, LayerNorm, the split first edge layer and the sum over
//! receivers, and their backward passes.
//!
//! Every kernel splits its rows into tasks of a fixed size run in parallel on rayon; partial
//! sums over rows (weight and bias gradients, the sums onto nodes) are formed per task and
//! added in task order, so every result is computed with the same operations in the same order
//! whatever the number of threads. The products are `gemm`'s microkernels.

use rayon::prelude::*;

/// Rows of one block: 256 rows of 128 `f32` are 128 KiB, so a block's input, hidden and output
/// activations stay in L2 together with a layer's weights (64 KiB), and `gemm` packs each
/// weight matrix once per 256 rows (at 64 rows, packing took a third of the product's time).
pub(super) const ROWS_PER_BLOCK: usize = 256;

/// `len` zeros, written by the rayon pool: the first touch of fresh pages, or the clearing of a
/// reused heap block, then runs on every thread instead of on the caller's alone (on one
/// thread it took a quarter of a training step's serial time).
pub(super) fn zeros(len: usize) -> Vec<f32> {
    /// Values a task clears, with one `memset`: enough that a task's cost dwarfs rayon's.
    const CHUNK: usize = 1 << 16;
    let mut out = Vec::with_capacity(len);
    out.spare_capacity_mut()[..len]
        .par_chunks_mut(CHUNK)
        .for_each(|chunk| chunk.fill(std::mem::MaybeUninit::new(0.0)));
    // SAFETY: the first `len` elements were written just above.
    unsafe { out.set_len(len) };
    out
}

/// A copy of `x`, written by the rayon pool (as [`zeros`]).
fn parallel_copy(x: &[f32]) -> Vec<f32> {
    let mut out = Vec::with_capacity(x.len());
    out.par_extend(x.par_iter().copied());
    out
}

/// `out += x Wᵀ` with `x [rows, k]`, `W [n, k]`, `out [rows, n]`, all row-major.
pub(super) fn accumulate_product(
    x: &[f32],
    rows: usize,
    k: usize,
    weight: &[f32],
    n: usize,
    out: &mut [f32],
) {
    if rows == 0 || n == 0 || k == 0 {
        return;
    }
    assert!(x.len() >= rows * k && weight.len() >= n * k && out.len() >= rows * n);
    // SAFETY: the three buffers hold the `rows × k`, `n × k` and `rows × n` elements the strides
    // below address (checked above), and `out` does not alias the inputs (it is `&mut`).
    unsafe {
        gemm::gemm(
            rows,
            n,
            k,
            out.as_mut_ptr(),
            1,
            n as isize,
            true,
            x.as_ptr(),
            1,
            k as isize,
            // Wᵀ: element (i, j) is W[j, i], at j·k + i.
            weight.as_ptr(),
            k as isize,
            1,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// Runs `$body` compiled for AVX2 where the CPU has it (the loops below then use 8-wide vectors
/// instead of the baseline's 4-wide ones), else for the baseline. No FMA is enabled, so both
/// compilations round every operation alike and give the same bits.
macro_rules! simd_dispatch {
    ($name:ident, $portable:ident, ($($arg:ident: $ty:ty),*)) => {
        pub(super) fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn wide($($arg: $ty),*) {
                    $portable($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2, checked just above.
                    return unsafe { wide($($arg),*) };
                }
            }
            $portable($($arg),*)
        }
    };
}

simd_dispatch!(layer_norm_rows, layer_norm_rows_portable, (x: &mut [f32], gamma: &[f32], beta: &[f32], eps: f32));
simd_dispatch!(add_into, add_into_portable, (out: &mut [f32], x: &[f32], y: &[f32]));
simd_dispatch!(
    gather_sum_rows,
    gather_sum_rows_portable,
    (out: &mut [f32], bias: &[f32], from_senders: &[f32], from_receivers: &[f32], senders: &[i64], receivers: &[i64])
);

/// LayerNorm of every row of `x [rows, k]` in place, in `f32` with the two-pass (centred)
/// variance.
#[inline(always)]
fn layer_norm_rows_portable(x: &mut [f32], gamma: &[f32], beta: &[f32], eps: f32) {
    let k = gamma.len();
    for row in x.chunks_exact_mut(k) {
        let mean = lane_sum(row, |v| v) / k as f32;
        let variance = lane_sum(row, |v| (v - mean) * (v - mean)) / k as f32;
        let inverse = 1.0 / (variance + eps).sqrt();
        for ((v, g), b) in row.iter_mut().zip(gamma).zip(beta) {
            *v = (*v - mean) * inverse * g + b;
        }
    }
}

/// `max(x, 0)` in place, keeping NaN and `-0.0`: the bits of [`phi_core::backend::relu`].
///
/// Every element is stored by a plain vector store. Left to the compiler, both `if v < 0 { 0 }`
/// and a mask over the bits become a masked store of the zeros (`vmaskmovps`), which AMD's
/// cores run in microcode: 8 % of a thesis-size inference step. With AVX, `vmaxps(0, x)`
/// returns its second operand for NaN and for `±0`, as the portable loop does.
pub(super) fn relu_in_place(x: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx")]
        fn wide(x: &mut [f32]) {
            use std::arch::x86_64::{
                _mm256_loadu_ps, _mm256_max_ps, _mm256_setzero_ps, _mm256_storeu_ps,
            };
            let zero = _mm256_setzero_ps();
            let mut lanes = x.chunks_exact_mut(8);
            for lane in &mut lanes {
                let p = lane.as_mut_ptr();
                // SAFETY: `lane` holds the 8 `f32` that the unaligned load and store address.
                unsafe { _mm256_storeu_ps(p, _mm256_max_ps(zero, _mm256_loadu_ps(p))) };
            }
            relu_in_place_portable(lanes.into_remainder());
        }
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX, checked just above.
            return unsafe { wide(x) };
        }
    }
    relu_in_place_portable(x)
}

#[inline(always)]
fn relu_in_place_portable(x: &mut [f32]) {
    for v in x {
        // All ones unless v < 0 (false for NaN and -0.0, which pass through unchanged).
        let keep = ((*v < 0.0) as u32).wrapping_sub(1);
        *v = f32::from_bits(v.to_bits() & keep);
    }
}

/// Row `e` of `out` (width `bias.len()`) set to `bias + from_senders[senders[e]] +
/// from_receivers[receivers[e]]`; the indices are checked by the caller.
#[inline(always)]
fn gather_sum_rows_portable(
    out: &mut [f32],
    bias: &[f32],
    from_senders: &[f32],
    from_receivers: &[f32],
    senders: &[i64],
    receivers: &[i64],
) {
    let width = bias.len();
    for ((row, &s), &r) in out.chunks_exact_mut(width).zip(senders).zip(receivers) {
        let (s, r) = (s as usize, r as usize);
        let a = &from_senders[s * width..(s + 1) * width];
        let c = &from_receivers[r * width..(r + 1) * width];
        for (((v, b), a), c) in row.iter_mut().zip(bias).zip(a).zip(c) {
            *v = b + a + c;
        }
    }
}

/// `out = x + y` element by element.
#[inline(always)]
fn add_into_portable(out: &mut [f32], x: &[f32], y: &[f32]) {
    for ((o, a), b) in out.iter_mut().zip(x).zip(y) {
        *o = a + b;
    }
}

/// `Σ f(xᵢ)` accumulated in 16 independent lanes, then added pairwise: a fixed order (so the
/// same result on any thread), and one that the compiler turns into vector adds instead of a
/// chain of dependent scalar adds.
#[inline(always)]
fn lane_sum(x: &[f32], f: impl Fn(f32) -> f32) -> f32 {
    const LANES: usize = 16;
    let mut lanes = [0.0f32; LANES];
    let chunks = x.chunks_exact(LANES);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (lane, v) in lanes.iter_mut().zip(chunk) {
            *lane += f(*v);
        }
    }
    for (lane, v) in lanes.iter_mut().zip(rest) {
        *lane += f(*v);
    }
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        for i in 0..width {
            lanes[i] += lanes[i + width];
        }
    }
    lanes[0]
}

/// Rows of one task of the backward kernels: a task's weight-gradient product has `k = 2048`
/// (long enough that `gemm` amortises its packing) and its partial sums are few to add.
const GRAD_ROWS: usize = 2048;

/// `dst ← lhs · rhs (+ dst when accumulate)` for an `m × k` by `k × n` product of row-major
/// storage addressed by strides: element `(i, j)` of `lhs` is `lhs[i·lhs_rs + j·lhs_cs]`, and so
/// on; `dst` is `m × n` row-major.
#[allow(clippy::too_many_arguments)]
fn product(
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    accumulate: bool,
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[f32],
    (rhs_rs, rhs_cs): (usize, usize),
) {
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    let last = |rows: usize, cols: usize, rs: usize, cs: usize| (rows - 1) * rs + (cols - 1) * cs;
    assert!(
        dst.len() >= m * n
            && lhs.len() > last(m, k, lhs_rs, lhs_cs)
            && rhs.len() > last(k, n, rhs_rs, rhs_cs),
        "product operands too short for their strides"
    );
    // SAFETY: every element the strides address lies inside its slice (checked above), and
    // `dst` does not alias the inputs (it is `&mut`).
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            rhs_cs as isize,
            rhs_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// Runs `task(t, rows, out)` for the tasks `t` of [`GRAD_ROWS`] rows each of `rows` rows, with
/// `out` the task's rows of the `[rows, width]` buffer when one is given, in parallel; the
/// results in task order.
fn row_tasks<R: Send>(
    rows: usize,
    out: Option<(&mut [f32], usize)>,
    task: impl Fn(usize, std::ops::Range<usize>, Option<&mut [f32]>) -> R + Sync,
) -> Vec<R> {
    let range = |t: usize| t * GRAD_ROWS..((t + 1) * GRAD_ROWS).min(rows);
    match out {
        Some((out, width)) if width > 0 => out[..rows * width]
            .par_chunks_mut(GRAD_ROWS * width)
            .enumerate()
            .map(|(t, chunk)| task(t, range(t), Some(chunk)))
            .collect(),
        _ => (0..rows.div_ceil(GRAD_ROWS))
            .into_par_iter()
            .map(|t| task(t, range(t), None))
            .collect(),
    }
}

/// The element-wise sum of `parts` (each of `len` values), added in order.
fn sum_parts(parts: impl IntoIterator<Item = Vec<f32>>, len: usize) -> Vec<f32> {
    let mut sum = vec![0.0f32; len];
    for part in parts {
        for (s, p) in sum.iter_mut().zip(&part) {
            *s += p;
        }
    }
    sum
}

/// `Σ_rows x` of `x [rows, width]` row-major, added to `sums [width]`.
fn add_column_sums(x: &[f32], width: usize, sums: &mut [f32]) {
    for row in x.chunks_exact(width) {
        for (s, v) in sums.iter_mut().zip(row) {
            *s += v;
        }
    }
}

/// `dy` where `output > 0`, else 0: the gradient through a ReLU, from the ReLU's output.
fn relu_gradient(dy: &[f32], output: Option<&[f32]>) -> Vec<f32> {
    match output {
        Some(y) => dy
            .iter()
            .zip(y)
            .map(|(&g, &y)| if y > 0.0 { g } else { 0.0 })
            .collect(),
        None => dy.to_vec(),
    }
}

/// A dense layer `y = x Wᵀ + b` (ReLU when `relu`): `x [rows, inputs]`, `weight [outputs,
/// inputs]`, `bias [outputs]` → `[rows, outputs]`, row-major.
pub(super) fn dense_forward(
    x: &[f32],
    rows: usize,
    weight: &[f32],
    bias: &[f32],
    relu: bool,
) -> Vec<f32> {
    let outputs = bias.len();
    let inputs = weight.len().checked_div(outputs).unwrap_or(0);
    let mut out = zeros(rows * outputs);
    if outputs == 0 {
        return out;
    }
    out.par_chunks_mut(ROWS_PER_BLOCK * outputs)
        .enumerate()
        .for_each(|(block, out)| {
            let start = block * ROWS_PER_BLOCK;
            let count = out.len() / outputs;
            for row in out.chunks_exact_mut(outputs) {
                row.copy_from_slice(bias);
            }
            let input = &x[start * inputs..(start + count) * inputs];
            accumulate_product(input, count, inputs, weight, outputs, out);
            if relu {
                relu_in_place(out);
            }
        });
    out
}

/// The gradients of a dense layer in its input (when asked), weight and bias.
pub(super) struct DenseGradients {
    /// `∂L/∂x [rows, inputs]`.
    pub input: Option<Vec<f32>>,
    /// `∂L/∂W [outputs, inputs]`.
    pub weight: Vec<f32>,
    /// `∂L/∂b [outputs]`.
    pub bias: Vec<f32>,
}

/// The backward pass of [`dense_forward`] for a layer of `shape = (rows, inputs, outputs)`:
/// `dy [rows, outputs]`, the layer's input `x` and, for a ReLU layer, its `output`. `∂L/∂z = dy ⊙ [y > 0]`, `∂L/∂x = ∂L/∂z W`, `∂L/∂W = (∂L/∂z)ᵀ x`,
/// `∂L/∂b = Σ_rows ∂L/∂z`.
pub(super) fn dense_backward(
    dy: &[f32],
    output: Option<&[f32]>,
    x: &[f32],
    (rows, inputs, outputs): (usize, usize, usize),
    weight: &[f32],
    want_input: bool,
) -> DenseGradients {
    let mut input = want_input.then(|| zeros(rows * inputs));
    let parts = row_tasks(
        rows,
        input.as_deref_mut().map(|d| (d, inputs)),
        |_, range, dx| {
            let count = range.len();
            let (a, b) = (range.start * outputs, range.end * outputs);
            let dz = relu_gradient(&dy[a..b], output.map(|y| &y[a..b]));
            let x = &x[range.start * inputs..range.end * inputs];
            let mut dw = vec![0.0f32; outputs * inputs];
            // (∂L/∂z)ᵀ x: element (o, i) is Σ_rows dz[row, o] x[row, i].
            product(
                (outputs, inputs, count),
                &mut dw,
                false,
                &dz,
                (1, outputs),
                x,
                (inputs, 1),
            );
            let mut db = vec![0.0f32; outputs];
            add_column_sums(&dz, outputs.max(1), &mut db);
            if let Some(dx) = dx {
                product(
                    (count, inputs, outputs),
                    dx,
                    false,
                    &dz,
                    (outputs, 1),
                    weight,
                    (inputs, 1),
                );
            }
            (dw, db)
        },
    );
    let (dw, db): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
    DenseGradients {
        input,
        weight: sum_parts(dw, outputs * inputs),
        bias: sum_parts(db, outputs),
    }
}

/// LayerNorm's forward pass over the rows of `x [rows, k]`: the output, the normalised rows
/// `x̂ = (x − mean) / √(var + eps)` and the inverse deviations `1 / √(var + eps)` `[rows]` (what
/// the backward pass needs).
pub(super) fn layer_norm_forward(
    x: &[f32],
    gamma: &[f32],
    beta: &[f32],
    eps: f32,
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let k = gamma.len().max(1);
    let rows = x.len() / k;
    let mut normalised = parallel_copy(x);
    let mut inverse = vec![0.0f32; rows];
    normalised
        .par_chunks_mut(ROWS_PER_BLOCK * k)
        .zip(inverse.par_chunks_mut(ROWS_PER_BLOCK))
        .for_each(|(block, inverse)| {
            for (row, inv) in block.chunks_exact_mut(k).zip(inverse) {
                let mean = lane_sum(row, |v| v) / k as f32;
                let variance = lane_sum(row, |v| (v - mean) * (v - mean)) / k as f32;
                *inv = 1.0 / (variance + eps).sqrt();
                for v in row.iter_mut() {
                    *v = (*v - mean) * *inv;
                }
            }
        });
    let mut out = zeros(x.len());
    out.par_chunks_mut(ROWS_PER_BLOCK * k)
        .zip(normalised.par_chunks(ROWS_PER_BLOCK * k))
        .for_each(|(out, normalised)| {
            for (o, n) in out.chunks_exact_mut(k).zip(normalised.chunks_exact(k)) {
                for (((o, n), g), b) in o.iter_mut().zip(n).zip(gamma).zip(beta) {
                    *o = n * g + b;
                }
            }
        });
    (out, normalised, inverse)
}

/// LayerNorm's backward pass from `dy [rows, k]`, the normalised rows and inverse deviations of
/// [`layer_norm_forward`]: `(∂L/∂x, ∂L/∂γ, ∂L/∂β)`, with `g = dy ⊙ γ`,
/// `∂L/∂x = inv · (g − mean(g) − x̂ · mean(g ⊙ x̂))`, `∂L/∂γ = Σ_rows dy ⊙ x̂`, `∂L/∂β = Σ_rows dy`.
pub(super) fn layer_norm_backward(
    dy: &[f32],
    normalised: &[f32],
    inverse: &[f32],
    gamma: &[f32],
    want_input: bool,
) -> (Option<Vec<f32>>, Vec<f32>, Vec<f32>) {
    let k = gamma.len().max(1);
    let rows = inverse.len();
    let mut input = want_input.then(|| zeros(rows * k));
    let parts = row_tasks(
        rows,
        input.as_deref_mut().map(|d| (d, k)),
        |_, range, dx| {
            let mut dgamma = vec![0.0f32; k];
            let mut dbeta = vec![0.0f32; k];
            let mut g = vec![0.0f32; k];
            let mut dx = dx.map(|d| d.chunks_exact_mut(k));
            for row in range {
                let dy = &dy[row * k..(row + 1) * k];
                let n = &normalised[row * k..(row + 1) * k];
                for ((((g, d), n), gm), (dg, db)) in g
                    .iter_mut()
                    .zip(dy)
                    .zip(n)
                    .zip(gamma)
                    .zip(dgamma.iter_mut().zip(dbeta.iter_mut()))
                {
                    *g = d * gm;
                    *dg += d * n;
                    *db += d;
                }
                if let Some(out) = dx.as_mut().and_then(|d| d.next()) {
                    let mean = lane_sum(&g, |v| v) / k as f32;
                    let mean_xg = lane_sum_product(&g, n) / k as f32;
                    let inv = inverse[row];
                    for ((o, g), n) in out.iter_mut().zip(&g).zip(n) {
                        *o = inv * (g - mean - n * mean_xg);
                    }
                }
            }
            (dgamma, dbeta)
        },
    );
    let (dgamma, dbeta): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
    (input, sum_parts(dgamma, k), sum_parts(dbeta, k))
}

/// `Σ aᵢ bᵢ` in [`lane_sum`]'s fixed order.
fn lane_sum_product(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 16;
    let mut lanes = [0.0f32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for ((lane, x), y) in lanes.iter_mut().zip(x).zip(y) {
            *lane += x * y;
        }
    }
    for ((lane, x), y) in lanes.iter_mut().zip(ra).zip(rb) {
        *lane += x * y;
    }
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        for i in 0..width {
            lanes[i] += lanes[i + width];
        }
    }
    lanes[0]
}

/// The split first edge layer `relu(e W_eᵀ + b + P_s[s] + P_r[r])` (no ReLU unless `relu`):
/// `edges [E, k]`, `edge_weight [out, k]`, `bias [out]`, the node projections `P_s`, `P_r`
/// `[N, out]`, `senders`, `receivers` `[E]` in `0..N` (checked by the caller) → `[E, out]`.
#[allow(clippy::too_many_arguments)]
pub(super) fn edge_input_forward(
    edges: &[f32],
    rows: usize,
    edge_weight: &[f32],
    bias: &[f32],
    sender_projection: &[f32],
    receiver_projection: &[f32],
    senders: &[i64],
    receivers: &[i64],
    relu: bool,
) -> Vec<f32> {
    let outputs = bias.len();
    let inputs = edge_weight.len().checked_div(outputs).unwrap_or(0);
    let mut out = zeros(rows * outputs);
    if outputs == 0 {
        return out;
    }
    out.par_chunks_mut(ROWS_PER_BLOCK * outputs)
        .enumerate()
        .for_each(|(block, out)| {
            let start = block * ROWS_PER_BLOCK;
            let count = out.len() / outputs;
            gather_sum_rows(
                out,
                bias,
                sender_projection,
                receiver_projection,
                &senders[start..start + count],
                &receivers[start..start + count],
            );
            let input = &edges[start * inputs..(start + count) * inputs];
            accumulate_product(input, count, inputs, edge_weight, outputs, out);
            if relu {
                relu_in_place(out);
            }
        });
    out
}

/// The gradients of the split first edge layer.
pub(super) struct EdgeInputGradients {
    /// `∂L/∂e [E, k]`, when asked.
    pub edges: Option<Vec<f32>>,
    /// `∂L/∂W_e [out, k]`.
    pub edge_weight: Vec<f32>,
    /// `∂L/∂b [out]`.
    pub bias: Vec<f32>,
    /// `∂L/∂P_s [N, out]`: the sum of `∂L/∂z` over each node's outgoing edges.
    pub sender_projection: Vec<f32>,
    /// `∂L/∂P_r [N, out]`: the sum over each node's incoming edges.
    pub receiver_projection: Vec<f32>,
}

/// The backward pass of [`edge_input_forward`] for `shape = (E, k, out)` from `dy [E, out]`, the
/// layer's `output` when it has the ReLU, its `edges` and indices, for `nodes` nodes.
#[allow(clippy::too_many_arguments)]
pub(super) fn edge_input_backward(
    dy: &[f32],
    output: Option<&[f32]>,
    edges: &[f32],
    shape: (usize, usize, usize),
    edge_weight: &[f32],
    senders: &[i64],
    receivers: &[i64],
    nodes: usize,
    want_edges: bool,
) -> EdgeInputGradients {
    let outputs = shape.2;
    let mut dz = zeros(dy.len());
    if outputs > 0 {
        dz.par_chunks_mut(GRAD_ROWS * outputs)
            .zip(dy.par_chunks(GRAD_ROWS * outputs))
            .enumerate()
            .for_each(|(t, (dz, dy))| {
                let a = t * GRAD_ROWS * outputs;
                let masked = relu_gradient(dy, output.map(|y| &y[a..a + dy.len()]));
                dz.copy_from_slice(&masked);
            });
    }
    let dense = dense_backward(&dz, None, edges, shape, edge_weight, want_edges);
    EdgeInputGradients {
        edges: dense.input,
        edge_weight: dense.weight,
        bias: dense.bias,
        sender_projection: sum_rows_by_index(&dz, outputs, senders, nodes),
        receiver_projection: sum_rows_by_index(&dz, outputs, receivers, nodes),
    }
}

/// `out[i] = Σ_{e : index[e] = i} x[e]` for `x [E, width]`, `index [E]` in `0..nodes` (checked by
/// the caller) → `[nodes, width]`; each node's rows are added in edge order, nodes in parallel.
pub(super) fn sum_rows_by_index(x: &[f32], width: usize, index: &[i64], nodes: usize) -> Vec<f32> {
    let mut out = zeros(nodes * width);
    if width == 0 || nodes == 0 {
        return out;
    }
    // Each node's edges, in edge order: a counting sort of the edges by index.
    let mut start = vec![0usize; nodes + 1];
    for &i in index {
        start[i as usize + 1] += 1;
    }
    for i in 0..nodes {
        start[i + 1] += start[i];
    }
    let sorted = index.windows(2).all(|w| w[0] <= w[1]);
    let order: Vec<usize> = if sorted {
        Vec::new()
    } else {
        let mut next = start.clone();
        let mut order = vec![0usize; index.len()];
        for (e, &i) in index.iter().enumerate() {
            order[next[i as usize]] = e;
            next[i as usize] += 1;
        }
        order
    };
    out.par_chunks_mut(ROWS_PER_BLOCK * width)
        .enumerate()
        .for_each(|(block, chunk)| {
            for (i, row) in chunk.chunks_exact_mut(width).enumerate() {
                let node = block * ROWS_PER_BLOCK + i;
                let slots = start[node]..start[node + 1];
                let edges: &mut dyn Iterator<Item = usize> = if sorted {
                    &mut slots.clone()
                } else {
                    &mut order[slots].iter().copied()
                };
                for e in edges {
                    add_assign(row, &x[e * width..(e + 1) * width]);
                }
            }
        });
    out
}

/// `out[e] = x[index[e]]` for `x [nodes, width]`, `index [E]` in `0..nodes` (checked by the
/// caller) → `[E, width]`.
pub(super) fn gather_rows(x: &[f32], width: usize, index: &[i64]) -> Vec<f32> {
    let mut out = zeros(index.len() * width);
    if width == 0 {
        return out;
    }
    out.par_chunks_mut(GRAD_ROWS * width)
        .zip(index.par_chunks(GRAD_ROWS))
        .for_each(|(out, index)| {
            for (row, &i) in out.chunks_exact_mut(width).zip(index) {
                let i = i as usize;
                row.copy_from_slice(&x[i * width..(i + 1) * width]);
            }
        });
    out
}

/// `out += x` element by element.
fn add_assign(out: &mut [f32], x: &[f32]) {
    for (o, v) in out.iter_mut().zip(x) {
        *o += v;
    }
}

#[cfg(test)]
mod tests {
    use super::relu_in_place;

    /// The vector ReLU gives the bits of the scalar one on every special value (NaN with its
    /// payload and sign, ±0, ±inf, subnormals) at every position of a vector and its remainder.
    #[test]
    fn relu_in_place_has_the_bits_of_the_scalar_relu() {
        let specials = [
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7fc0_1234),
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE / 2.0,
            -f32::MIN_POSITIVE / 2.0,
            f32::MAX,
            f32::MIN,
            1.5,
            -2.25,
        ];
        for len in [1, 7, 8, 15, 16, 17, 33, 100] {
            for shift in 0..specials.len() {
                let x: Vec<f32> = (0..len)
                    .map(|i| specials[(i + shift) % specials.len()])
                    .collect();
                let mut y = x.clone();
                relu_in_place(&mut y);
                for (a, b) in x.iter().zip(&y) {
                    assert_eq!(
                        phi_core::backend::relu(*a).to_bits(),
                        b.to_bits(),
                        "input {a:?}"
                    );
                }
            }
        }
    }
}
