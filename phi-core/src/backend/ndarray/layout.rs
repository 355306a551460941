//! Layout helpers: row-major buffers, views read by rows of a collapsed index space, slicing,
//! concatenation and broadcast shapes.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- layout and shape helpers

/// A tensor of `shape` holding `data` in row-major order.
pub(super) fn from_vec<T>(data: Vec<T>, shape: &[usize]) -> Tensor<T> {
    ArcArray::from_shape_vec(IxDyn(shape), data).expect("the front end checked the data length")
}

/// The number of elements of `shape`.
pub(super) fn out_len(shape: &[usize]) -> usize {
    shape.iter().product()
}

/// The elements of `tensor` in row-major order: borrowed when the tensor is row-major already,
/// else copied (with a strided loop rather than element-by-element index arithmetic).
pub(super) fn standard<T: Copy + Default + Send + Sync>(tensor: &Tensor<T>) -> Cow<'_, [T]> {
    if let Some(slice) = tensor.as_slice() {
        return Cow::Borrowed(slice);
    }
    if tensor.len() < PAR_THRESHOLD {
        return Cow::Owned(strided_map(tensor, tensor.shape(), |x| x));
    }
    let mut out = Array::from_elem(tensor.raw_dim(), T::default());
    Zip::from(&mut out).and(tensor).par_for_each(|o, &x| *o = x);
    Cow::Owned(out.into_raw_vec_and_offset().0)
}

/// `tensor` under `shape`: a view of the same buffer when the tensor is row-major.
pub(super) fn reshape<T: Copy + Default + Send + Sync>(
    tensor: Tensor<T>,
    shape: &[usize],
) -> Tensor<T> {
    if tensor.is_standard_layout() {
        return tensor
            .into_shape_with_order(IxDyn(shape))
            .expect("the front end checked the element count");
    }
    from_vec(standard(&tensor).into_owned(), shape)
}

/// A view of the block `ranges` (no copy).
pub(super) fn slice<T>(mut tensor: Tensor<T>, ranges: &[Range<usize>]) -> Tensor<T> {
    tensor.slice_each_axis_inplace(|axis| Slice::from(ranges[axis.axis.index()].clone()));
    tensor
}

/// The tensors joined along `axis`, copied block by block: for each index of the axes before
/// `axis`, one contiguous run of every tensor.
pub(super) fn concat<T: Copy + Default + Send + Sync>(
    tensors: Vec<Tensor<T>>,
    axis: usize,
) -> Tensor<T> {
    if tensors.len() == 1 {
        return tensors.into_iter().next().expect("one tensor");
    }
    let mut shape = tensors[0].shape().to_vec();
    shape[axis] = tensors.iter().map(|t| t.shape()[axis]).sum();
    let outer: usize = shape[..axis].iter().product();
    let inner: usize = shape[axis + 1..].iter().product();
    let parts: Vec<(Cow<'_, [T]>, usize)> = tensors
        .iter()
        .map(|t| (standard(t), t.shape()[axis] * inner))
        .collect();
    let row: usize = parts.iter().map(|(_, block)| block).sum();
    let mut data = vec![T::default(); out_len(&shape)];
    if row == 0 {
        return from_vec(data, &shape);
    }
    // Two or three columns (per-axis samples joined into points): interleaved in one pass.
    if parts.iter().all(|(_, block)| *block == 1) {
        let columns: Vec<&[T]> = parts.iter().map(|(part, _)| &part[..]).collect();
        match columns[..] {
            [a, b] => {
                for ((out, &a), &b) in data.chunks_exact_mut(2).zip(a).zip(b) {
                    out.copy_from_slice(&[a, b]);
                }
                return from_vec(data, &shape);
            }
            [a, b, c] => {
                for (((out, &a), &b), &c) in data.chunks_exact_mut(3).zip(a).zip(b).zip(c) {
                    out.copy_from_slice(&[a, b, c]);
                }
                return from_vec(data, &shape);
            }
            _ => {}
        }
    }
    let mut at = 0;
    for (part, block) in &parts {
        if *block == 1 {
            // Columns (e.g. per-axis samples joined into points): element by element, without a
            // slice copy per element.
            for (out, &x) in data[at..].iter_mut().step_by(row).zip(part.iter()) {
                *out = x;
            }
        } else if *block > 0 {
            for (o, out) in data.chunks_exact_mut(row).enumerate().take(outer) {
                out[at..at + block].copy_from_slice(&part[o * block..(o + 1) * block]);
            }
        }
        at += block;
    }
    from_vec(data, &shape)
}

/// The shape that `a` and `b` broadcast to (NumPy rules; the front end checked that they do).
pub(super) fn broadcast_shape(a: &[usize], b: &[usize]) -> Vec<usize> {
    let rank = a.len().max(b.len());
    (0..rank)
        .map(|i| {
            let da = if i + a.len() >= rank {
                a[i + a.len() - rank]
            } else {
                1
            };
            let db = if i + b.len() >= rank {
                b[i + b.len() - rank]
            } else {
                1
            };
            if da == 1 { db } else { da }
        })
        .collect()
}

// -------------------------------------------------------------------- strided loops
//
// Views (slices, permutes, broadcasts) are read with one loop per row of a collapsed index space
// rather than ndarray's per-element dynamic-rank iteration, which dominates small kernels.

/// Element strides of `t` seen in the (broadcast) `shape`, right-aligned: 0 along the axes where
/// `t` has length 1 or no axis at all.
pub(super) fn strides_in<T>(t: &Tensor<T>, shape: &[usize]) -> Vec<isize> {
    let offset = shape.len() - t.ndim();
    (0..shape.len())
        .map(|i| {
            if i < offset {
                return 0;
            }
            let k = i - offset;
            if t.shape()[k] == 1 { 0 } else { t.strides()[k] }
        })
        .collect()
}

/// `shape` with its length-1 axes dropped and neighbouring axes merged wherever every operand
/// walks them as one (`stride[i − 1] = stride[i] · shape[i]`); at least one axis is left.
pub(super) fn collapse<const K: usize>(
    shape: &[usize],
    strides: [Vec<isize>; K],
) -> (Vec<usize>, [Vec<isize>; K]) {
    let mut out_shape: Vec<usize> = Vec::with_capacity(shape.len());
    let mut out: [Vec<isize>; K] = std::array::from_fn(|_| Vec::with_capacity(shape.len()));
    for (i, &n) in shape.iter().enumerate() {
        if n == 1 {
            continue;
        }
        let merge = !out_shape.is_empty()
            && (0..K).all(|k| out[k].last() == Some(&(strides[k][i] * n as isize)));
        if merge {
            *out_shape.last_mut().expect("not empty") *= n;
            for k in 0..K {
                *out[k].last_mut().expect("not empty") = strides[k][i];
            }
        } else {
            out_shape.push(n);
            for k in 0..K {
                out[k].push(strides[k][i]);
            }
        }
    }
    if out_shape.is_empty() {
        out_shape.push(1);
        for stride in &mut out {
            stride.push(0);
        }
    }
    (out_shape, out)
}

/// Calls `row(offsets, len, strides)` for each row of the last axis of a collapsed index space,
/// in row-major order: `offsets` are the operands' element offsets of the row's start.
pub(super) fn for_each_row<const K: usize>(
    shape: &[usize],
    strides: &[Vec<isize>; K],
    mut row: impl FnMut([isize; K], usize, [isize; K]),
) {
    let last = shape.len() - 1;
    let inner_strides = std::array::from_fn(|k| strides[k][last]);
    let outer: usize = shape[..last].iter().product();
    let mut index = vec![0usize; last];
    let mut offsets = [0isize; K];
    for _ in 0..outer {
        row(offsets, shape[last], inner_strides);
        for axis in (0..last).rev() {
            index[axis] += 1;
            for k in 0..K {
                offsets[k] += strides[k][axis];
            }
            if index[axis] < shape[axis] {
                break;
            }
            for k in 0..K {
                offsets[k] -= strides[k][axis] * shape[axis] as isize;
            }
            index[axis] = 0;
        }
    }
}

/// `f` of each element of `t` broadcast to `shape`, in row-major order.
pub(super) fn strided_map<T: Copy, U>(
    t: &Tensor<T>,
    shape: &[usize],
    f: impl Fn(T) -> U,
) -> Vec<U> {
    let (cshape, [st]) = collapse(shape, [strides_in(t, shape)]);
    let mut out = Vec::with_capacity(out_len(shape));
    let base = t.as_ptr();
    for_each_row(&cshape, &[st], |[o], len, [s]| {
        // SAFETY: `strides_in` and `collapse` only re-describe `t`'s own index space (broadcast
        // axes have stride 0), so every offset addresses an element of `t`.
        unsafe {
            if s == 1 {
                let row = std::slice::from_raw_parts(base.offset(o), len);
                out.extend(row.iter().map(|&x| f(x)));
            } else {
                out.extend((0..len).map(|k| f(*base.offset(o + k as isize * s))));
            }
        }
    });
    out
}

/// `f(a, b)` over `shape` (both broadcast to it), in row-major order.
pub(super) fn strided_zip<T: Copy, U>(
    a: &Tensor<T>,
    b: &Tensor<T>,
    shape: &[usize],
    f: impl Fn(T, T) -> U,
) -> Vec<U> {
    let (cshape, strides) = collapse(shape, [strides_in(a, shape), strides_in(b, shape)]);
    // One row-major operand against one row repeated (a `[1, k]` bias or bound against points
    // `[N, k]`): long loops against the row repeated (`zip_rows`).
    if let ([outer, inner], [sa, sb]) = (&cshape[..], &strides) {
        let (outer, inner) = (*outer, *inner);
        let row = [inner as isize, 1];
        let repeated = [0, 1];
        if sa[..] == row && sb[..] == repeated {
            let (x, y) = (rows_of(a, outer * inner), rows_of(b, inner));
            return zip_rows(x, y, inner, &f);
        }
        if sa[..] == repeated && sb[..] == row {
            let (x, y) = (rows_of(a, inner), rows_of(b, outer * inner));
            return zip_rows(y, x, inner, |y, x| f(x, y));
        }
    }
    let mut out = Vec::with_capacity(out_len(shape));
    let (pa, pb) = (a.as_ptr(), b.as_ptr());
    for_each_row(&cshape, &strides, |[oa, ob], len, [sa, sb]| {
        // SAFETY: as in `strided_map`, every offset addresses an element of its operand.
        unsafe {
            match (sa, sb) {
                (1, 1) => {
                    let x = std::slice::from_raw_parts(pa.offset(oa), len);
                    let y = std::slice::from_raw_parts(pb.offset(ob), len);
                    out.extend(x.iter().zip(y).map(|(&x, &y)| f(x, y)));
                }
                (1, 0) => {
                    let x = std::slice::from_raw_parts(pa.offset(oa), len);
                    let y = *pb.offset(ob);
                    out.extend(x.iter().map(|&x| f(x, y)));
                }
                (0, 1) => {
                    let x = *pa.offset(oa);
                    let y = std::slice::from_raw_parts(pb.offset(ob), len);
                    out.extend(y.iter().map(|&y| f(x, y)));
                }
                _ => out.extend((0..len).map(|k| {
                    let k = k as isize;
                    f(*pa.offset(oa + k * sa), *pb.offset(ob + k * sb))
                })),
            }
        }
    });
    out
}

/// The first `len` elements of `t` in memory order, from its first element (for a view whose
/// collapsed strides say that they are consecutive).
pub(super) fn rows_of<T>(t: &Tensor<T>, len: usize) -> &[T] {
    assert!(len <= t.len(), "a view holds its own elements");
    // SAFETY: the caller's collapsed strides walk `len` consecutive elements from `t`'s first
    // one, all within `t`'s buffer (its elements, as `strided_map` reads them); checked above
    // that `t` has that many.
    unsafe { std::slice::from_raw_parts(t.as_ptr(), len) }
}

/// `f(x, y)` for each row of `rows` (row-major, rows of `inner`) against the one row `y`.
pub(super) fn zip_rows<T: Copy, U>(
    rows: &[T],
    y: &[T],
    inner: usize,
    f: impl Fn(T, T) -> U,
) -> Vec<U> {
    if inner == 0 {
        return Vec::new();
    }
    // Short rows (point coordinates) are repeated into a pattern of at least 16 values, so that
    // each chunk is one long loop over two slices, which the compiler vectorises.
    let pattern: Vec<T> = y
        .iter()
        .copied()
        .cycle()
        .take(inner * 16usize.div_ceil(inner))
        .collect();
    let mut out = Vec::with_capacity(rows.len());
    let mut chunks = rows.chunks_exact(pattern.len());
    for chunk in &mut chunks {
        out.extend(chunk.iter().zip(&pattern).map(|(&x, &y)| f(x, y)));
    }
    // A whole number of rows: the pattern lines up with it as with every chunk.
    let rest = chunks.remainder();
    out.extend(rest.iter().zip(&pattern).map(|(&x, &y)| f(x, y)));
    out
}
