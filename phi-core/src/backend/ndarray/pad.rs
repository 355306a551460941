//! Padding in every [`PadMode`](crate::backend::PadMode) in one pass.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- padding

/// The source index along an axis of length `n` for output cell `o`, padded by `before` cells
/// in front; `None` for a constant cell.
pub(super) fn pad_source(o: usize, n: usize, before: usize, mode: PadMode) -> Option<usize> {
    if (before..before + n).contains(&o) {
        return Some(o - before);
    }
    if n == 0 {
        return None;
    }
    match mode {
        PadMode::Constant(_) => None,
        PadMode::Edge => Some(if o < before { 0 } else { n - 1 }),
        PadMode::Periodic => Some((o as isize - before as isize).rem_euclid(n as isize) as usize),
        PadMode::Symmetric => {
            // Mirror around the edge cell, reflecting again for widths beyond the axis.
            let period = 2 * n;
            let offset = (o as isize - before as isize).rem_euclid(period as isize) as usize;
            Some(if offset < n {
                offset
            } else {
                period - 1 - offset
            })
        }
    }
}

/// What [`pad_fill`] needs besides its position: the source and, per axis, where each output
/// cell comes from.
pub(super) struct PadPlan<'a> {
    source: &'a [f32],
    source_strides: Vec<usize>,
    /// Per axis, the source index of each output cell (`None`: the constant).
    maps: Vec<Vec<Option<usize>>>,
    /// Per axis, the untouched run: output offset, source length.
    interior: Vec<(usize, usize)>,
    fill: f32,
}

/// Fills `out` (one output block spanning `axis..`) from the source block at `offset`.
pub(super) fn pad_fill(plan: &PadPlan<'_>, axis: usize, offset: usize, out: &mut [f32]) {
    let map = &plan.maps[axis];
    if axis + 1 == plan.maps.len() {
        let (before, n) = plan.interior[axis];
        out[before..before + n].copy_from_slice(&plan.source[offset..offset + n]);
        let edges = (0..before).chain(before + n..map.len());
        for o in edges {
            out[o] = map[o].map_or(plan.fill, |s| plan.source[offset + s]);
        }
        return;
    }
    let block = out.len() / map.len();
    for (o, out) in out.chunks_exact_mut(block).enumerate() {
        pad_entry(plan, axis, o, offset, out);
    }
}

/// Fills output entry `o` of `axis` (`out` spans the axes after it).
pub(super) fn pad_entry(plan: &PadPlan<'_>, axis: usize, o: usize, offset: usize, out: &mut [f32]) {
    match plan.maps[axis][o] {
        Some(s) => pad_fill(plan, axis + 1, offset + s * plan.source_strides[axis], out),
        None => out.fill(plan.fill),
    }
}

/// Native padding in one pass over the output; see [`Backend::float_pad`].
pub(super) fn pad(tensor: Tensor<f32>, widths: &[(usize, usize)], mode: PadMode) -> Tensor<f32> {
    if widths
        .iter()
        .all(|&(before, after)| before == 0 && after == 0)
    {
        return tensor;
    }
    let shape = tensor.shape().to_vec();
    let out_shape: Vec<usize> = shape
        .iter()
        .zip(widths)
        .map(|(&n, &(before, after))| before + n + after)
        .collect();
    let total = out_len(&out_shape);
    if total == 0 {
        return from_vec(Vec::new(), &out_shape);
    }
    let source = standard(&tensor);
    let mut source_strides = vec![1; shape.len()];
    for axis in (0..shape.len().saturating_sub(1)).rev() {
        source_strides[axis] = source_strides[axis + 1] * shape[axis + 1];
    }
    let plan = PadPlan {
        source: &source,
        source_strides,
        maps: shape
            .iter()
            .zip(&out_shape)
            .zip(widths)
            .map(|((&n, &len), &(before, _))| {
                (0..len).map(|o| pad_source(o, n, before, mode)).collect()
            })
            .collect(),
        interior: shape
            .iter()
            .zip(widths)
            .map(|(&n, &(before, _))| (before, n))
            .collect(),
        fill: match mode {
            PadMode::Constant(value) => value,
            _ => 0.0,
        },
    };
    let mut out = vec![0.0; total];
    if shape.len() > 1 && total >= PAR_THRESHOLD {
        let block = total / out_shape[0];
        out.par_chunks_mut(block)
            .enumerate()
            .for_each(|(o, out)| pad_entry(&plan, 0, o, 0, out));
    } else {
        pad_fill(&plan, 0, 0, &mut out);
    }
    from_vec(out, &out_shape)
}
