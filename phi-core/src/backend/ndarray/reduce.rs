//! Reductions: blocked full sums (the rounding does not depend on the thread count) and
//! reductions along one axis.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- reductions

/// The sum of `data`, in fixed blocks (vectorised within a block), so that the result is the
/// same with and without threads.
pub(super) fn sum(data: &[f32]) -> f32 {
    let block_sum = |block: &[f32]| ArrayView1::from(block).sum();
    let partials: Vec<f32> = if data.len() >= PAR_THRESHOLD {
        data.par_chunks(SUM_BLOCK).map(block_sum).collect()
    } else {
        data.chunks(SUM_BLOCK).map(block_sum).collect()
    };
    partials.iter().sum()
}

/// The fold of `data` with `pick` (`f32::max` or `f32::min`), which is exact in any order.
pub(super) fn extreme(data: &[f32], init: f32, pick: fn(f32, f32) -> f32) -> f32 {
    if data.len() >= PAR_THRESHOLD {
        data.par_chunks(SUM_BLOCK)
            .map(|c| c.iter().fold(init, |a, &b| pick(a, b)))
            .reduce(|| init, pick)
    } else {
        data.iter().fold(init, |a, &b| pick(a, b))
    }
}

/// `f` folded over `axis` (kept with length 1). `init` starts the fold, or the first element along
/// the axis does when it is `None` (max, min).
///
/// The tensor is seen as `[outer, n, inner]`; each output row `[inner]` accumulates the `n` input
/// rows in order, which vectorises over `inner` and keeps the rounding independent of threads.
pub(super) fn reduce_axis<T, F>(tensor: &Tensor<T>, axis: usize, init: Option<T>, f: F) -> Tensor<T>
where
    T: Copy + Default + Send + Sync,
    F: Fn(T, T) -> T + Send + Sync,
{
    let shape = tensor.shape();
    let n = shape[axis];
    let outer: usize = shape[..axis].iter().product();
    let inner: usize = shape[axis + 1..].iter().product();
    let mut out_shape = shape.to_vec();
    out_shape[axis] = 1;
    if outer * inner == 0 {
        return from_vec(Vec::new(), &out_shape);
    }
    if n == 0 {
        // Max and min of nothing are never asked for; the sum of nothing is `init`.
        return from_vec(vec![init.unwrap_or_default(); outer * inner], &out_shape);
    }
    let data = standard(tensor);
    let mut out = vec![T::default(); outer * inner];
    // Columns `cols` of the `n` rows in `src` ([n, inner]) folded into `dst`.
    let fold_block = |src: &[T], cols: Range<usize>, dst: &mut [T]| {
        let first = match init {
            Some(value) => {
                dst.fill(value);
                0
            }
            None => {
                dst.copy_from_slice(&src[cols.clone()]);
                1
            }
        };
        for k in first..n {
            let row = &src[k * inner + cols.start..k * inner + cols.end];
            for (d, &s) in dst.iter_mut().zip(row) {
                *d = f(*d, s);
            }
        }
    };
    let block = n * inner;
    if data.len() < PAR_THRESHOLD {
        for (src, dst) in data.chunks(block).zip(out.chunks_mut(inner)) {
            fold_block(src, 0..inner, dst);
        }
    } else if outer >= rayon::current_num_threads() {
        let min_len = (PAR_MIN_LEN / block).max(1);
        data.par_chunks(block)
            .zip(out.par_chunks_mut(inner))
            .with_min_len(min_len)
            .for_each(|(src, dst)| fold_block(src, 0..inner, dst));
    } else {
        // Few output rows (a reduction over a leading axis): split the columns instead.
        let cols = (PAR_MIN_LEN / n).clamp(16, inner.max(16));
        for (src, dst) in data.chunks(block).zip(out.chunks_mut(inner)) {
            dst.par_chunks_mut(cols).enumerate().for_each(|(c, dst)| {
                let start = c * cols;
                fold_block(src, start..start + dst.len(), dst);
            });
        }
    }
    from_vec(out, &out_shape)
}
