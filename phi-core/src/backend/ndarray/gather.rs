//! Gathers and scatter-adds of rows, with index checks that return errors.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- gather and scatter

/// `Ok` when every index lies in `0..bound`, else the first one that does not.
pub(super) fn check_indices(indices: &[i64], bound: usize, op: &'static str) -> Result<()> {
    // A branch-free pass first (negative indices wrap to huge unsigned values), which vectorises;
    // the search for the culprit only runs on failure.
    let valid = indices
        .iter()
        .fold(true, |valid, &i| valid & ((i as u64) < bound as u64));
    if valid {
        return Ok(());
    }
    let outside = |&&i: &&i64| usize::try_from(i).map_or(true, |i| i >= bound);
    match indices.iter().find(outside) {
        Some(&index) => Err(TensorError::IndexOutOfRange { op, index, bound }),
        None => Ok(()),
    }
}

/// Rows of `tensor` picked by `indices` (checked here); see [`Backend::float_gather_rows`].
pub(super) fn gather_rows<T: Copy + Default + Send + Sync>(
    tensor: &Tensor<T>,
    indices: &Tensor<i64>,
    op: &'static str,
) -> Result<Tensor<T>> {
    let rows = standard(indices);
    check_indices(&rows, tensor.shape()[0], op)?;
    let mut out_shape = tensor.shape().to_vec();
    out_shape[0] = rows.len();
    let width: usize = tensor.shape()[1..].iter().product();
    if width == 0 || rows.is_empty() {
        return Ok(from_vec(Vec::new(), &out_shape));
    }
    let source = standard(tensor);
    let mut data = vec![T::default(); rows.len() * width];
    if data.len() >= PAR_THRESHOLD {
        // Tasks of a few thousand elements: a single narrow row is too little work to schedule.
        let per_task = (PAR_MIN_LEN / width).max(1);
        data.par_chunks_mut(per_task * width)
            .zip(rows.par_chunks(per_task))
            .for_each(|(dst, rows)| gather_into(&source, width, rows, dst));
    } else {
        gather_into(&source, width, &rows, &mut data);
    }
    Ok(from_vec(data, &out_shape))
}

/// `dst[i] = source[rows[i]]` for rows of `width` elements.
pub(super) fn gather_into<T: Copy>(source: &[T], width: usize, rows: &[i64], dst: &mut [T]) {
    // Narrow rows (scalars, 2-D and 3-D vectors) as fixed-size arrays: one register move per row
    // rather than a call to memcpy.
    match width {
        1 => gather_fixed::<T, 1>(source, rows, dst),
        2 => gather_fixed::<T, 2>(source, rows, dst),
        3 => gather_fixed::<T, 3>(source, rows, dst),
        4 => gather_fixed::<T, 4>(source, rows, dst),
        _ => {
            for (dst, &r) in dst.chunks_exact_mut(width).zip(rows) {
                dst.copy_from_slice(&source[r as usize * width..(r as usize + 1) * width]);
            }
        }
    }
}

/// [`gather_into`] for rows of `W` elements.
pub(super) fn gather_fixed<T: Copy, const W: usize>(source: &[T], rows: &[i64], dst: &mut [T]) {
    let (source, _) = source.as_chunks::<W>();
    let (dst, _) = dst.as_chunks_mut::<W>();
    for (dst, &r) in dst.iter_mut().zip(rows) {
        *dst = source[r as usize];
    }
}

/// `dst[rows[i]] += values[i]` for rows of `width` elements, in the order of `i`.
pub(super) fn scatter_add_into(dst: &mut [f32], width: usize, rows: &[i64], values: &[f32]) {
    match width {
        1 => scatter_add_fixed::<1>(dst, rows, values),
        2 => scatter_add_fixed::<2>(dst, rows, values),
        3 => scatter_add_fixed::<3>(dst, rows, values),
        4 => scatter_add_fixed::<4>(dst, rows, values),
        _ => {
            for (&r, src) in rows.iter().zip(values.chunks_exact(width)) {
                let row = &mut dst[r as usize * width..(r as usize + 1) * width];
                for (d, &v) in row.iter_mut().zip(src) {
                    *d += v;
                }
            }
        }
    }
}

/// [`scatter_add_into`] for rows of `W` elements.
pub(super) fn scatter_add_fixed<const W: usize>(dst: &mut [f32], rows: &[i64], values: &[f32]) {
    let (dst, _) = dst.as_chunks_mut::<W>();
    let (values, _) = values.as_chunks::<W>();
    for (&r, src) in rows.iter().zip(values) {
        for (d, &v) in dst[r as usize].iter_mut().zip(src) {
            *d += v;
        }
    }
}

/// `tensor` with `values[i]` added to row `rows[i]` (rows already checked); repeated rows
/// accumulate in the order of `i`.
///
/// In parallel, each task owns a disjoint part of the output and applies the updates that fall
/// into it in the original order, so the result is bit for bit the sequential one, with no
/// atomics and no write conflicts. Wide rows are split by columns, narrow rows by destination row
/// ranges.
pub(super) fn scatter_add(tensor: Tensor<f32>, rows: &[i64], values: &Tensor<f32>) -> Tensor<f32> {
    // Reuses the buffer when this is its only owner and it is row-major, else copies once.
    let mut out = if tensor.is_standard_layout() {
        tensor.into_owned()
    } else {
        tensor.as_standard_layout().into_owned()
    };
    let n = out.shape()[0];
    let width: usize = out.shape()[1..].iter().product();
    if width == 0 || rows.is_empty() {
        return out.into_shared();
    }
    let values = standard(values);
    let dst = out.as_slice_mut().expect("row-major");
    let add = |dst: &mut [f32], i: usize| {
        for (d, &v) in dst.iter_mut().zip(&values[i * width..(i + 1) * width]) {
            *d += v;
        }
    };
    let threads = rayon::current_num_threads();
    let work = rows.len() * width;
    // Wide rows: split the columns in whole cache lines. Every task streams through all the
    // values in order, which keeps the hardware prefetcher busy, and load is even however the
    // indices cluster.
    let blocks = threads.min(width / CACHE_LINE_F32);
    if work >= PAR_THRESHOLD && blocks >= 2 {
        let cols = width.div_ceil(blocks).next_multiple_of(CACHE_LINE_F32);
        let mut grid = ArrayViewMut2::from_shape((n, width), dst).expect("rows × width");
        grid.axis_chunks_iter_mut(Axis(1), cols)
            .into_par_iter()
            .enumerate()
            .for_each(|(c, mut block)| {
                let (start, len) = (c * cols, block.ncols());
                for (i, &r) in rows.iter().enumerate() {
                    let dst = block.row_mut(r as usize).into_slice().expect("unit stride");
                    let src = &values[i * width + start..i * width + start + len];
                    for (d, &v) in dst.iter_mut().zip(src) {
                        *d += v;
                    }
                }
            });
        return out.into_shared();
    }
    // Narrow rows: one destination row range per thread; every task scans all the indices and
    // applies those in its range. Scanning costs far less than sorting the updates by range
    // (which would be a sequential pass as slow as the scatter itself), but it is repeated per
    // thread, so it pays only for more work than the other kernels need.
    if work < 4 * PAR_THRESHOLD || threads == 1 || n < 2 {
        scatter_add_into(dst, width, rows, &values);
        return out.into_shared();
    }
    let per_range = n.div_ceil(threads);
    dst.par_chunks_mut(per_range * width)
        .enumerate()
        .for_each(|(b, dst)| {
            let base = b * per_range;
            for (i, &r) in rows.iter().enumerate() {
                // Rows below `base` wrap around to huge values and fail the test too.
                let local = (r as usize).wrapping_sub(base);
                if local < per_range {
                    add(&mut dst[local * width..(local + 1) * width], i);
                }
            }
        });
    out.into_shared()
}

/// Row indices into `tensor` reshaped to `[d₀·…·d_{k-1}, rest...]` for multi-indices `[m, k]`,
/// each component checked against its own axis (an out-of-range component could otherwise alias a
/// valid flat row). Returns the reshaped shape and the flat indices.
pub(super) fn flat_nd_indices(
    shape: &[usize],
    indices: &Tensor<i64>,
    op: &'static str,
) -> Result<(Vec<usize>, Vec<i64>)> {
    let (m, k) = (indices.shape()[0], indices.shape()[1]);
    let data = standard(indices);
    let mut flat = Vec::with_capacity(m);
    if k > 0 {
        for multi in data.chunks_exact(k) {
            let mut row = 0i64;
            for (&index, &bound) in multi.iter().zip(shape) {
                if usize::try_from(index).map_or(true, |i| i >= bound) {
                    return Err(TensorError::IndexOutOfRange { op, index, bound });
                }
                row = row * bound as i64 + index;
            }
            flat.push(row);
        }
    }
    let mut flat_shape = vec![shape[..k].iter().product()];
    flat_shape.extend_from_slice(&shape[k..]);
    Ok((flat_shape, flat))
}
