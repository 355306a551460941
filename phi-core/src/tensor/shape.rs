//! Shape rules shared by the tensor front end: broadcasting, axis checks, matmul shapes.

use crate::error::{Result, TensorError};

/// The NumPy broadcast of two shapes: aligned at the trailing axis, missing leading axes count
/// as 1, and an axis of length 1 stretches to the other's length.
pub(crate) fn broadcast_shapes(
    op: &'static str,
    lhs: &[usize],
    rhs: &[usize],
) -> Result<Vec<usize>> {
    let rank = lhs.len().max(rhs.len());
    let mut out = vec![0; rank];
    for (i, length) in out.iter_mut().enumerate() {
        let a = axis_from_end(lhs, rank - 1 - i);
        let b = axis_from_end(rhs, rank - 1 - i);
        *length = match (a, b) {
            (a, b) if a == b => a,
            (1, b) => b,
            (a, 1) => a,
            (a, b) => {
                return Err(TensorError::ShapeMismatch {
                    op,
                    lhs: lhs.to_vec(),
                    rhs: rhs.to_vec(),
                    reason: format!(
                        "axis {i} of the broadcast has lengths {a} and {b}; one must be 1 or both equal"
                    ),
                });
            }
        };
    }
    Ok(out)
}

/// Length of the axis `from_end` places before the last one, 1 if the shape is shorter.
fn axis_from_end(shape: &[usize], from_end: usize) -> usize {
    if from_end < shape.len() {
        shape[shape.len() - 1 - from_end]
    } else {
        1
    }
}

/// Whether `from` broadcasts to exactly `to`.
pub(crate) fn broadcasts_to(from: &[usize], to: &[usize]) -> bool {
    from.len() <= to.len()
        && from
            .iter()
            .rev()
            .zip(to.iter().rev())
            .all(|(&f, &t)| f == t || f == 1)
}

/// Checks that `axis` names an axis of `shape`.
pub fn check_axis(op: &'static str, shape: &[usize], axis: usize) -> Result<()> {
    if axis < shape.len() {
        Ok(())
    } else {
        Err(TensorError::InvalidArgument {
            op,
            shape: shape.to_vec(),
            reason: format!("axis {axis} does not exist (rank {})", shape.len()),
        })
    }
}

/// The number of elements of a tensor of `shape`.
pub fn numel(shape: &[usize]) -> usize {
    shape.iter().product()
}

/// The output shape of a batched matrix product `[..., m, k] × [..., k, n]`, with the batch axes
/// broadcast.
pub(crate) fn matmul_shape(lhs: &[usize], rhs: &[usize]) -> Result<(Vec<usize>, Vec<usize>)> {
    let mismatch = |reason: String| TensorError::ShapeMismatch {
        op: "matmul",
        lhs: lhs.to_vec(),
        rhs: rhs.to_vec(),
        reason,
    };
    if lhs.len() < 2 || rhs.len() < 2 {
        return Err(mismatch("both operands need at least two axes".into()));
    }
    let (m, k) = (lhs[lhs.len() - 2], lhs[lhs.len() - 1]);
    let (k2, n) = (rhs[rhs.len() - 2], rhs[rhs.len() - 1]);
    if k != k2 {
        return Err(mismatch(format!(
            "the inner dimensions differ ({k} columns against {k2} rows)"
        )));
    }
    let batch = broadcast_shapes("matmul", &lhs[..lhs.len() - 2], &rhs[..rhs.len() - 2])
        .map_err(|_| mismatch("the batch axes do not broadcast".into()))?;
    let mut out = batch.clone();
    out.extend([m, n]);
    Ok((batch, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broadcasting_follows_numpy() {
        assert_eq!(broadcast_shapes("t", &[3, 1], &[4]).unwrap(), vec![3, 4]);
        assert_eq!(
            broadcast_shapes("t", &[2, 1, 5], &[3, 1]).unwrap(),
            vec![2, 3, 5]
        );
        assert_eq!(broadcast_shapes("t", &[0, 1], &[1, 7]).unwrap(), vec![0, 7]);
        let err = broadcast_shapes("add", &[3, 2], &[3]).unwrap_err();
        let message = err.to_string();
        assert!(
            message.contains("[3, 2]") && message.contains("[3]"),
            "{message}"
        );
        assert!(broadcasts_to(&[1, 3], &[4, 3]));
        assert!(!broadcasts_to(&[2, 3], &[4, 3]));
    }

    #[test]
    fn matmul_shapes_broadcast_batches() {
        let (batch, out) = matmul_shape(&[2, 1, 3, 4], &[5, 4, 6]).unwrap();
        assert_eq!(batch, vec![2, 5]);
        assert_eq!(out, vec![2, 5, 3, 6]);
        assert!(matmul_shape(&[3, 4], &[5, 6]).is_err());
        assert!(matmul_shape(&[3], &[3, 6]).is_err());
    }
}
