//! The symmetric Chamfer distance, a metric on host data.

/// Symmetric Chamfer distance between host point sets `a` `[N·d]` and `b` `[M·d]` (row-major):
/// the mean over both sets of the distance to the nearest point of the other (domain units),
/// accumulated in `f64`; `NaN` for an empty set or `d = 0`.
pub fn chamfer_distance(a: &[f32], b: &[f32], d: usize) -> f32 {
    if d == 0 || a.is_empty() || b.is_empty() {
        return f32::NAN;
    }
    let nearest = |from: &[f32], to: &[f32]| -> f64 {
        let count = from.len() / d;
        from.chunks(d)
            .map(|x| {
                to.chunks(d)
                    .map(|y| {
                        x.iter()
                            .zip(y)
                            .map(|(p, q)| f64::from(p - q).powi(2))
                            .sum::<f64>()
                    })
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
            })
            .sum::<f64>()
            / count as f64
    };
    (0.5 * (nearest(a, b) + nearest(b, a))) as f32
}
