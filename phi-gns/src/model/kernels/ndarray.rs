//! The GNS kernels of [`NdArray`]: whole MLPs evaluated block by block of rows.
//!
//! An MLP's rows are independent, so each block of [`MLP_ROWS`] rows goes through every
//! layer (the gather and the sum of the split first layer, the bias, the ReLU, the LayerNorm)
//! while it is in the core's cache, instead of streaming a `[30000, 128]` activation through
//! memory once per operation. Blocks run in parallel on rayon; the block size is fixed, so every
//! row is computed with the same operations in the same order whatever the number of threads.
//! The products are `gemm`'s microkernels (AVX-512 or AVX2 where the CPU has them).

use std::borrow::Cow;

use ndarray::{ArcArray, IxDyn};
use phi_core::backend::ndarray::NdArray;
use phi_core::error::{Result, TensorError};
use rayon::prelude::*;

use super::host::{
    ROWS_PER_BLOCK, accumulate_product, add_into, gather_sum_rows, layer_norm_rows, relu_in_place,
};
use super::{Dense, EdgeInput, GnsKernels, LAYER_NORM_EPS, Norm};

type Array = ArcArray<f32, IxDyn>;

/// Rows of an MLP block. `gemm` packs a layer's weights once per block, so larger blocks pack
/// less often (512 and 1,024 rows were 1 and 2 % faster than 384 on a Zen 5 core); at 384 a
/// block's two `[rows, 128]` activations and the packed weights still fit the 512 KiB L2 of
/// older AVX2 cores. The results depend on it (through `gemm`'s tiles), not on the threads.
const MLP_ROWS: usize = 384;

/// The values of a tensor in row-major order (a copy only for a non-standard view).
fn row_major(x: &Array) -> Cow<'_, [f32]> {
    match x.as_slice() {
        Some(values) => Cow::Borrowed(values),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

fn shape_error(op: &'static str, lhs: &[usize], rhs: &[usize], reason: &str) -> TensorError {
    TensorError::ShapeMismatch {
        op,
        lhs: lhs.to_vec(),
        rhs: rhs.to_vec(),
        reason: reason.to_string(),
    }
}

/// A dense layer on the host: `weight [out, in]`, `bias [out]`, both row-major.
struct HostDense<'a> {
    weight: Cow<'a, [f32]>,
    bias: Cow<'a, [f32]>,
    inputs: usize,
    outputs: usize,
}

impl<'a> HostDense<'a> {
    fn new(layer: &'a Dense<Array>, inputs: usize, op: &'static str) -> Result<Self> {
        let (w, b) = (layer.weight.shape(), layer.bias.shape());
        if w.len() != 2 || w[1] != inputs || b != [w[0]] {
            return Err(shape_error(
                op,
                w,
                b,
                &format!("a dense layer on {inputs} inputs needs W [out, {inputs}] and b [out]"),
            ));
        }
        Ok(HostDense {
            weight: row_major(&layer.weight),
            bias: row_major(&layer.bias),
            inputs,
            outputs: w[0],
        })
    }

    /// `out = x Wᵀ + out` for `rows` rows: `x [rows, in]`, `out [rows, out]` row-major, `out`
    /// holding the bias (or more) beforehand.
    fn accumulate(&self, x: &[f32], rows: usize, out: &mut [f32]) {
        accumulate_product(x, rows, self.inputs, &self.weight, self.outputs, out);
    }

    /// `out = x Wᵀ + b`, with the ReLU when `relu`.
    fn apply(&self, x: &[f32], rows: usize, out: &mut [f32], relu: bool) {
        for row in out.chunks_exact_mut(self.outputs) {
            row.copy_from_slice(&self.bias);
        }
        self.accumulate(x, rows, out);
        if relu {
            relu_in_place(out);
        }
    }
}

struct HostNorm<'a> {
    gamma: Cow<'a, [f32]>,
    beta: Cow<'a, [f32]>,
}

impl<'a> HostNorm<'a> {
    fn new(norm: &'a Norm<Array>, width: usize, op: &'static str) -> Result<Self> {
        if norm.gamma.shape() != [width] || norm.beta.shape() != [width] {
            return Err(shape_error(
                op,
                norm.gamma.shape(),
                norm.beta.shape(),
                &format!("the LayerNorm of a width-{width} output needs [{width}] scale and shift"),
            ));
        }
        Ok(HostNorm {
            gamma: row_major(&norm.gamma),
            beta: row_major(&norm.beta),
        })
    }
}

/// Runs `layers` (ReLU between them) and `norm` over the rows of `[rows, width]`, one block of
/// rows per task. `first(block_start, rows, out)` writes the first layer's output (before its
/// ReLU) for the rows `block_start..block_start + rows` into `out`. With a `residual`
/// (`[rows, width]`), also returns `residual + output`, computed while the block is in cache.
///
/// A block runs in two scratch buffers in the core's cache and is then copied out: the outputs
/// are written once, never cleared beforehand (clearing `[E, 128]` first was a pass through
/// memory of its own, ~3 % of an inference step).
fn blocked_mlp(
    rows: usize,
    first_width: usize,
    first_relu: bool,
    layers: &[HostDense<'_>],
    norm: Option<&HostNorm<'_>>,
    residual: Option<&[f32]>,
    first: impl Fn(usize, usize, &mut [f32]) + Sync,
) -> (Vec<f32>, Option<Vec<f32>>) {
    let width = layers.last().map_or(first_width, |l| l.outputs).max(1);
    let len = rows * width;
    let mut out = Vec::<f32>::with_capacity(len);
    let mut updated = residual.map(|_| Vec::<f32>::with_capacity(len));
    let widest = layers
        .iter()
        .map(|l| l.outputs)
        .chain([first_width, width])
        .max()
        .unwrap_or(width);
    // Two activation buffers of a block, allocated once per rayon job (not per block); every
    // layer writes the part it reads next before it is read.
    let scratch = || {
        let len = MLP_ROWS * widest;
        (vec![0.0f32; len], vec![0.0f32; len])
    };
    type Uninit = std::mem::MaybeUninit<f32>;
    let block = |(a, b): &mut (Vec<f32>, Vec<f32>),
                 (index, (out_block, updated_block)): (
        usize,
        (&mut [Uninit], Option<&mut [Uninit]>),
    )| {
        let start = index * MLP_ROWS;
        let count = out_block.len() / width;
        first(start, count, &mut a[..count * first_width]);
        let mut current = first_width;
        if let Some((last, hidden)) = layers.split_last() {
            if first_relu {
                relu_in_place(&mut a[..count * first_width]);
            }
            for layer in hidden {
                layer.apply(
                    &a[..count * current],
                    count,
                    &mut b[..count * layer.outputs],
                    true,
                );
                std::mem::swap(a, b);
                current = layer.outputs;
            }
            last.apply(&a[..count * current], count, &mut b[..count * width], false);
            std::mem::swap(a, b);
        }
        let result = &mut a[..count * width];
        if let Some(norm) = norm {
            layer_norm_rows(result, &norm.gamma, &norm.beta, LAYER_NORM_EPS);
        }
        out_block.write_copy_of_slice(result);
        if let (Some(dst), Some(residual)) = (updated_block, residual) {
            add_into(
                &mut b[..count * width],
                &residual[start * width..(start + count) * width],
                result,
            );
            dst.write_copy_of_slice(&b[..count * width]);
        }
    };
    let chunk = MLP_ROWS * width;
    let out_values = &mut out.spare_capacity_mut()[..len];
    match updated.as_mut() {
        Some(updated) => out_values
            .par_chunks_mut(chunk)
            .zip(updated.spare_capacity_mut()[..len].par_chunks_mut(chunk))
            .enumerate()
            .for_each_init(scratch, |s, (i, (o, u))| block(s, (i, (o, Some(u))))),
        None => out_values
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each_init(scratch, |s, (i, o)| block(s, (i, (o, None)))),
    }
    // SAFETY: the blocks cover the `len` values of each output, and every block wrote all of
    // its values (`write_copy_of_slice` of a slice of the block's length) just above.
    unsafe {
        out.set_len(len);
        if let Some(updated) = updated.as_mut() {
            updated.set_len(len);
        }
    }
    (out, updated)
}

fn matrix_shape(x: &Array, op: &'static str) -> Result<(usize, usize)> {
    match x.shape() {
        [rows, cols] => Ok((*rows, *cols)),
        shape => Err(TensorError::InvalidArgument {
            op,
            shape: shape.to_vec(),
            reason: "the input of an MLP is a matrix [rows, features]".into(),
        }),
    }
}

fn to_array(values: Vec<f32>, rows: usize, cols: usize) -> Array {
    ArcArray::from_shape_vec(IxDyn(&[rows, cols]), values).expect("rows × cols values")
}

impl GnsKernels for NdArray {
    fn gns_mlp(x: Array, layers: &[Dense<Array>], norm: Option<&Norm<Array>>) -> Result<Array> {
        const OP: &str = "gns_mlp";
        let (rows, inputs) = matrix_shape(&x, OP)?;
        let Some((first, rest)) = layers.split_first() else {
            return super::composite_mlp::<Self>(x, layers, norm);
        };
        let first = HostDense::new(first, inputs, OP)?;
        let mut host = Vec::with_capacity(rest.len());
        let mut width = first.outputs;
        for layer in rest {
            let layer = HostDense::new(layer, width, OP)?;
            width = layer.outputs;
            host.push(layer);
        }
        let norm = norm.map(|n| HostNorm::new(n, width, OP)).transpose()?;
        let values = row_major(&x);
        let (out, _) = blocked_mlp(
            rows,
            first.outputs,
            !rest.is_empty(),
            &host,
            norm.as_ref(),
            None,
            |start, count, out| {
                let input = &values[start * inputs..(start + count) * inputs];
                first.apply(input, count, out, false);
            },
        );
        Ok(to_array(out, rows, width))
    }

    fn gns_edge_mlp(
        edges: Array,
        input: &EdgeInput<Array, ArcArray<i64, IxDyn>>,
        rest: &[Dense<Array>],
        norm: Option<&Norm<Array>>,
    ) -> Result<Array> {
        Ok(edge_mlp(&edges, input, rest, norm, false)?.0)
    }

    fn gns_edge_update(
        edges: Array,
        input: &EdgeInput<Array, ArcArray<i64, IxDyn>>,
        rest: &[Dense<Array>],
        norm: Option<&Norm<Array>>,
    ) -> Result<(Array, Array)> {
        let (messages, updated) = edge_mlp(&edges, input, rest, norm, true)?;
        Ok((messages, updated.expect("asked for the residual")))
    }

    fn gns_sum_by_receiver(
        edges: Array,
        receivers: ArcArray<i64, IxDyn>,
        nodes: usize,
    ) -> Result<Array> {
        let index = row_major_i64(&receivers);
        let sorted = index.windows(2).all(|w| w[0] <= w[1]);
        let in_range = index.iter().all(|&i| i >= 0 && (i as usize) < nodes);
        let (rows, width) = match edges.shape() {
            [rows, width] => (*rows, *width),
            _ => return super::composite_sum_by_receiver::<Self>(edges, receivers, nodes),
        };
        if !sorted || !in_range || index.len() != rows {
            // The composite reports the misfit (or sums unsorted receivers correctly).
            return super::composite_sum_by_receiver::<Self>(edges, receivers, nodes);
        }
        let values = row_major(&edges);
        // Node i's edges are start[i]..start[i + 1]: each sum is one task's, in edge order.
        let mut start = vec![0usize; nodes + 1];
        for &r in index.iter() {
            start[r as usize + 1] += 1;
        }
        for i in 0..nodes {
            start[i + 1] += start[i];
        }
        let mut out = vec![0.0f32; nodes * width];
        out.par_chunks_mut(ROWS_PER_BLOCK * width.max(1))
            .enumerate()
            .for_each(|(block, chunk)| {
                for (i, row) in chunk.chunks_exact_mut(width.max(1)).enumerate() {
                    let node = block * ROWS_PER_BLOCK + i;
                    for e in start[node]..start[node + 1] {
                        for (acc, v) in row.iter_mut().zip(&values[e * width..(e + 1) * width]) {
                            *acc += v;
                        }
                    }
                }
            });
        Ok(to_array(out, nodes, width))
    }
}

fn row_major_i64(x: &ArcArray<i64, IxDyn>) -> Cow<'_, [i64]> {
    match x.as_slice() {
        Some(values) => Cow::Borrowed(values),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

/// The fused edge MLP, and with `residual` also `edges + e′`.
fn edge_mlp(
    edges: &Array,
    input: &EdgeInput<Array, ArcArray<i64, IxDyn>>,
    rest: &[Dense<Array>],
    norm: Option<&Norm<Array>>,
    residual: bool,
) -> Result<(Array, Option<Array>)> {
    const OP: &str = "gns_edge_mlp";
    let (rows, inputs) = matrix_shape(edges, OP)?;
    let first_layer = Dense {
        weight: input.edge_weight.clone(),
        bias: input.bias.clone(),
    };
    let first = HostDense::new(&first_layer, inputs, OP)?;
    let hidden = first.outputs;
    let (senders, receivers) = (
        row_major_i64(&input.senders),
        row_major_i64(&input.receivers),
    );
    let (sp, rp) = (&input.sender_projection, &input.receiver_projection);
    let nodes = sp.shape().first().copied().unwrap_or(0);
    if sp.shape() != [nodes, hidden] || rp.shape() != [nodes, hidden] {
        return Err(shape_error(
            OP,
            sp.shape(),
            rp.shape(),
            &format!("node projections must be [nodes, {hidden}]"),
        ));
    }
    if senders.len() != rows || receivers.len() != rows {
        return Err(shape_error(
            OP,
            &[senders.len()],
            &[receivers.len()],
            &format!("{rows} edges need {rows} senders and receivers"),
        ));
    }
    if let Some(&bad) = senders
        .iter()
        .chain(receivers.iter())
        .find(|&&i| i < 0 || i as usize >= nodes)
    {
        return Err(TensorError::IndexOutOfRange {
            op: OP,
            index: bad,
            bound: nodes,
        });
    }
    let mut host = Vec::with_capacity(rest.len());
    let mut width = hidden;
    for layer in rest {
        let layer = HostDense::new(layer, width, OP)?;
        width = layer.outputs;
        host.push(layer);
    }
    let norm = norm.map(|n| HostNorm::new(n, width, OP)).transpose()?;
    let values = row_major(edges);
    let (sp, rp) = (row_major(sp), row_major(rp));
    let (out, updated) = blocked_mlp(
        rows,
        hidden,
        !rest.is_empty(),
        &host,
        norm.as_ref(),
        residual.then_some(&values[..]),
        |start, count, out| {
            gather_sum_rows(
                out,
                &first.bias,
                &sp,
                &rp,
                &senders[start..start + count],
                &receivers[start..start + count],
            );
            first.accumulate(
                &values[start * inputs..(start + count) * inputs],
                count,
                out,
            );
        },
    );
    Ok((
        to_array(out, rows, width),
        updated.map(|u| to_array(u, rows, width)),
    ))
}
