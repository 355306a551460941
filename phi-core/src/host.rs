//! Checks on host slices, below every other module of phi-core: the solvers and the tensor layer
//! both use them.

/// Whether every value of a host slice (`f32` or `f64`) is finite. `0 · x` is `±0` for a finite
/// `x` and NaN otherwise; the sums run in lanes over all values without an early exit, so the
/// check vectorises (a short-circuiting test per value would not).
pub fn all_finite<T>(values: &[T]) -> bool
where
    T: Copy + From<f32> + PartialEq + std::ops::Add<Output = T> + std::ops::Mul<Output = T>,
{
    const LANES: usize = 16;
    let zero = T::from(0.0);
    let mut sums = [zero; LANES];
    let blocks = values.chunks_exact(LANES);
    let rest = blocks.remainder();
    for block in blocks {
        for (sum, &x) in sums.iter_mut().zip(block) {
            *sum = *sum + x * zero;
        }
    }
    let total = rest.iter().fold(zero, |acc, &x| acc + x * zero)
        + sums.iter().fold(zero, |acc, &sum| acc + sum);
    total == zero
}

#[cfg(test)]
mod tests {
    use super::all_finite;

    /// A NaN or an infinity anywhere (in a whole block of lanes or in the remainder) fails the
    /// check; finite values of any size pass, in `f32` and in `f64`.
    #[test]
    fn all_finite_finds_every_non_finite_value() {
        for n in [0usize, 1, 15, 16, 17, 40] {
            let values: Vec<f32> = (0..n).map(|i| (i as f32 - 7.0) * 1e30).collect();
            let wide: Vec<f64> = values.iter().map(|&x| f64::from(x) * 1e270).collect();
            assert!(all_finite(&values), "n {n}");
            assert!(all_finite(&wide), "n {n} (f64)");
            for at in 0..n {
                for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                    let mut with = values.clone();
                    with[at] = bad;
                    assert!(!all_finite(&with), "n {n}, {bad} at {at}");
                    let mut with = wide.clone();
                    with[at] = f64::from(bad);
                    assert!(!all_finite(&with), "n {n}, {bad} at {at} (f64)");
                }
            }
        }
    }
}
