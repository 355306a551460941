//! Batched matrix products through ndarray's `general_mat_mul`.

#[allow(unused_imports)]
use super::*;

// -------------------------------------------------------------------- matmul

/// Batched matrix product; see [`Backend::float_matmul`].
pub(super) fn matmul(lhs: &Tensor<f32>, rhs: &Tensor<f32>) -> Tensor<f32> {
    let rank = lhs.ndim();
    let (m, k, n) = (
        lhs.shape()[rank - 2],
        lhs.shape()[rank - 1],
        rhs.shape()[rank - 1],
    );
    let batch: usize = lhs.shape()[..rank - 2].iter().product();
    let mut out_shape = lhs.shape()[..rank - 2].to_vec();
    out_shape.extend([m, n]);
    let mut out = vec![0.0; batch * m * n];
    if out.is_empty() || k == 0 {
        return from_vec(out, &out_shape);
    }
    if rank == 2 {
        // Any strides will do for the gemm kernel: no copy for transposed or sliced operands.
        let a = lhs.view().into_dimensionality::<Ix2>().expect("rank 2");
        let b = rhs.view().into_dimensionality::<Ix2>().expect("rank 2");
        gemm(a, b, &mut out);
        return from_vec(out, &out_shape);
    }
    let a = lhs
        .to_shape(((batch, m, k), Order::RowMajor))
        .expect("same element count");
    let b = rhs
        .to_shape(((batch, k, n), Order::RowMajor))
        .expect("same element count");
    let one = |(i, dst): (usize, &mut [f32])| {
        gemm(a.index_axis(Axis(0), i), b.index_axis(Axis(0), i), dst);
    };
    if batch > 1 && batch * m * n * k >= MATMUL_PAR_WORK {
        out.par_chunks_mut(m * n).enumerate().for_each(one);
    } else {
        out.chunks_mut(m * n).enumerate().for_each(one);
    }
    from_vec(out, &out_shape)
}

/// `out = a · b` for one matrix pair (`out` row-major `[m, n]`), split into blocks of rows on
/// rayon when the product is large. matrixmultiply itself runs on one thread.
pub(super) fn gemm(a: ArrayView2<'_, f32>, b: ArrayView2<'_, f32>, out: &mut [f32]) {
    let ((m, k), n) = (a.dim(), b.ncols());
    let threads = rayon::current_num_threads();
    if m * k * n < MATMUL_PAR_WORK || threads == 1 || m < 32 {
        let mut c = ArrayViewMut2::from_shape((m, n), out).expect("output sized m × n");
        general_mat_mul(1.0, &a, &b, 0.0, &mut c);
        return;
    }
    // Several blocks per thread for balance, each a multiple of the kernel's 16-row tiles.
    let rows = m.div_ceil(threads * 4).max(32).next_multiple_of(16);
    out.par_chunks_mut(rows * n)
        .enumerate()
        .for_each(|(i, dst)| {
            let start = i * rows;
            let count = dst.len() / n;
            let a = a.slice_axis(Axis(0), Slice::from(start..start + count));
            let mut c =
                ArrayViewMut2::from_shape((count, n), dst).expect("output block sized rows × n");
            general_mat_mul(1.0, &a, &b, 0.0, &mut c);
        });
}
