//! The exact earth mover's distance between point sets of equal size, a metric on host data.
//!
//! For sets `a` and `b` of `N` points each with uniform weights `1/N`, the optimal transport cost
//! `min_π Σᵢⱼ πᵢⱼ C(aᵢ, bⱼ)` over plans with marginals `1/N` (thesis eq. 5.3) is attained at a
//! permutation (Birkhoff–von Neumann: the plans form a polytope whose vertices are permutation
//! matrices scaled by `1/N`), so
//!
//! ```text
//! EMD(a, b) = (1/N) min_σ Σᵢ C(aᵢ, b_σ(i)),
//! ```
//!
//! the linear assignment problem, with the ground cost `C` squared Euclidean (the default of
//! POT's `ot.dist`, with which the thesis computed it) or Euclidean.
//!
//! # Algorithm
//!
//! 1. **Candidate graph.** Each point of `a` is paired with the points of `b` in the block of
//!    grid cells around it (`3ᵈ` cells of ~`k/3ᵈ` points, or more until they hold `k = 24`), and
//!    each point of `b` with the points of `a` around it (for `d > 3`: the `k` nearest, by brute
//!    force). A pairing of both sets in the order of a Z-order curve is added: a perfect
//!    matching, so the graph has one and a free point always has an augmenting path.
//! 2. **Auction** (Bertsekas 1988) on the graph, with `ε`-scaling: unassigned points of `a` bid
//!    for their best point of `b`, lowering its potential `vⱼ` by their margin over the second
//!    best plus `ε`. It settles the bulk of the assignment in `O(k)` per bid, but only to within
//!    `ε`. The assigned pairs are then made tight (`vⱼ` raised by each row's slack) and the rows
//!    that no longer attain their minimum are freed.
//! 3. **Shortest augmenting paths** (Jonker & Volgenant 1987) from each free point of `a`:
//!    Dijkstra's search in the reduced costs `Cᵢⱼ − uᵢ − vⱼ ≥ 0` to the nearest free point of
//!    `b`, after which the potentials shift by the search distances and the path flips. The
//!    result is optimal on the graph, exactly.
//! 4. **Certification on all `N²` pairs.** A sweep checks `mᵢ = minⱼ (Cᵢⱼ − vⱼ)` over every
//!    `j`. If each assigned pair attains it, `C(i, σ(i)) − v_σ(i) = mᵢ`, then for every
//!    permutation `τ`, `Σᵢ C(i, τ(i)) ≥ Σᵢ (mᵢ + v_τ(i)) = Σᵢ C(i, σ(i))`: `σ` is optimal on the
//!    full problem (LP duality, with `uᵢ = mᵢ` feasible on every pair). The sweep is vectorised
//!    and skips blocks of 64 points of `b` (consecutive along the Z-order curve) whose bounding
//!    box is too far: `C(aᵢ, box) − max vⱼ` bounds `Cᵢⱼ − vⱼ` over the block from below. Points of
//!    `a` whose pairs outside the graph beat their assignment get those pairs added, `uᵢ = mᵢ`,
//!    and lose their partner; step 3 resumes from the current potentials and assignment, and the
//!    sweep repeats. Pairs are only ever added, so this ends, usually after one to four sweeps.
//!
//! Cost: `O(N k)` for the graph, a few bids per point and `ε`-phase (`O(k)` each), short searches
//! (a few columns each in practice), and per sweep `O(N²/64)` box tests plus the pairs of the
//! blocks that pass, which dominates at `N` in the tens of thousands. Everything is computed in `f64` from the `f32` (or `f64`) coordinates, and the
//! distance is the mean of the assigned costs. Exactness holds up to rounding: pairs within
//! `10⁻¹³` of the scale of the costs and potentials count as ties, and
//! [`EmdSolver::optimality_gap`] bounds, from the potentials, how far the returned value can be
//! above the minimum.
//!
//! ```
//! use phi_core::point_sets::{EmdSolver, GroundCost, earth_movers_distance};
//!
//! // Two particles that swapped places: the paired distance is positive, the EMD zero.
//! let truth = [0.0f32, 0.0, 1.0, 0.0];
//! let predicted = [1.0f32, 0.0, 0.0, 0.0];
//! assert_eq!(earth_movers_distance(&predicted, &truth, 2, GroundCost::SquaredEuclidean)?, 0.0);
//!
//! // A rigid shift by s = (0.3, 0.4) costs |s|² = 0.25 squared and |s| = 0.5 Euclidean.
//! let shifted = [0.3f32, 0.4, 1.3, 0.4];
//! let emd = earth_movers_distance(&shifted, &truth, 2, GroundCost::Euclidean)?;
//! assert!((emd - 0.5).abs() < 1e-7);
//!
//! // Frames of a rollout in order: one solver, warm-started from the previous frame.
//! let mut solver = EmdSolver::new();
//! let emd = solver.solve(&shifted, &truth, 2, GroundCost::SquaredEuclidean)?;
//! assert!((emd - 0.25).abs() < 1e-7);
//! assert_eq!(solver.assignment(), vec![0, 1]);
//! # Ok::<(), phi_core::point_sets::PointSetError>(())
//! ```

mod assignment;
mod neighbours;

#[cfg(test)]
mod tests;

pub use assignment::SolveStats;

use super::{PointSetError, Result};
use assignment::{Assignment, Problem, SparseOptions};

/// The ground cost `C(x, y)` between a point of one set and a point of the other.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum GroundCost {
    /// `|x − y|²` (domain units²): POT's `ot.dist` default, `metric="sqeuclidean"`.
    #[default]
    SquaredEuclidean,
    /// `|x − y|` (domain units): `metric="euclidean"`, the 1-Wasserstein distance.
    Euclidean,
}

/// The exact earth mover's distance `(1/N) min_σ Σᵢ C(aᵢ, b_σ(i))` between host point sets `a`
/// and `b` of `N` points each, `[N·d]` row-major (`f32` or `f64`), in the units of `cost`; see
/// the [module documentation](self) for the algorithm. Equal to POT's
/// `ot.emd2(1/N, 1/N, ot.dist(a, b, metric))`. For a sequence of frames use [`EmdSolver`].
///
/// # Errors
/// [`PointSetError::Invalid`] for `d = 0`, lengths that are not whole numbers of points, an empty
/// set, sets of different counts or a coordinate that is not finite (or beyond `10¹⁰⁰`).
pub fn earth_movers_distance<T: Copy + Into<f64>>(
    a: &[T],
    b: &[T],
    d: usize,
    cost: GroundCost,
) -> Result<f64> {
    EmdSolver::new().solve(a, b, d, cost)
}

/// A reusable solver of [`earth_movers_distance`]: it keeps its buffers, the last assignment and
/// the potentials that certify it. When it next solves sets of the same size, dimension and
/// cost (the next frame of a rollout), it starts from them: the previous pairs join the
/// candidate graph, and the auction starts from the previous assignment and potentials at a
/// smaller `ε` (on consecutive rollout-like frames, about 30 % less work than a cold start).
pub struct EmdSolver {
    neighbours: usize,
    warm_start: bool,
    last: Option<(usize, usize, GroundCost)>,
    a: Vec<f64>,
    b: Vec<f64>,
    b_by_coordinate: Vec<f64>,
    assignment: Assignment,
}

impl EmdSolver {
    /// A solver with at least 24 neighbours per point in the candidate graph, warm-starting.
    pub fn new() -> Self {
        Self {
            neighbours: 24,
            warm_start: true,
            last: None,
            a: Vec::new(),
            b: Vec::new(),
            b_by_coordinate: Vec::new(),
            assignment: Assignment::default(),
        }
    }

    /// The same with at least `k` (at least 1) neighbours per point: more make the first sweep
    /// certify more often, at the price of a larger graph. The result does not depend on `k`.
    pub fn with_neighbours(mut self, k: usize) -> Self {
        self.neighbours = k.max(1);
        self
    }

    /// The same, starting every solve from scratch (`false`) or from the previous one (`true`).
    /// The result does not depend on it.
    pub fn with_warm_start(mut self, warm_start: bool) -> Self {
        self.warm_start = warm_start;
        self
    }

    /// [`earth_movers_distance`] of `a` and `b` `[N·d]`.
    ///
    /// # Errors
    /// As [`earth_movers_distance`].
    pub fn solve<T: Copy + Into<f64>>(
        &mut self,
        a: &[T],
        b: &[T],
        d: usize,
        cost: GroundCost,
    ) -> Result<f64> {
        let n = check(a, b, d)?;
        to_f64(a, d, "first", &mut self.a)?;
        to_f64(b, d, "second", &mut self.b)?;
        self.b_by_coordinate.clear();
        for k in 0..d {
            let column = self.b.iter().skip(k).step_by(d);
            self.b_by_coordinate.extend(column);
        }
        let problem = Problem {
            a: &self.a,
            b: &self.b,
            b_by_coordinate: &self.b_by_coordinate,
            n,
            d,
            cost,
        };
        let warm = self.warm_start && self.last == Some((n, d, cost));
        self.last = None;
        self.assignment.solve(
            &problem,
            &SparseOptions {
                k: self.neighbours.max(1),
                warm,
            },
        );
        self.last = Some((n, d, cost));
        let total: f64 = self
            .assignment
            .columns()
            .enumerate()
            .map(|(i, j)| problem.cost(i, j))
            .sum();
        Ok(total / n as f64)
    }

    /// The optimal assignment of the last solve: entry `i` is the point of `b` that carries the
    /// mass of point `i` of `a`. Empty before the first solve.
    pub fn assignment(&self) -> Vec<usize> {
        if self.last.is_none() {
            return Vec::new();
        }
        self.assignment.columns().collect()
    }

    /// An upper bound on how far the last distance can be above the true minimum (in the units of
    /// the cost), from the certifying potentials: `(1/N) Σᵢ (C(i, σ(i)) − v_σ(i) − mᵢ)`. Zero up
    /// to rounding.
    pub fn optimality_gap(&self) -> f64 {
        match self.last {
            Some((n, _, _)) => self.assignment.gap / n as f64,
            None => 0.0,
        }
    }

    /// What the last solve did: the graph's size, auction phases, augmenting paths and sweeps.
    pub fn stats(&self) -> SolveStats {
        self.assignment.stats
    }
}

impl Default for EmdSolver {
    fn default() -> Self {
        Self::new()
    }
}

/// Checks the shapes for [`earth_movers_distance`]; returns `N`.
fn check<T>(a: &[T], b: &[T], d: usize) -> Result<usize> {
    let invalid = |reason: String| {
        Err(PointSetError::Invalid {
            what: "earth mover's distance",
            reason,
        })
    };
    if d == 0 {
        return invalid("the points must have at least one coordinate (d = 0)".into());
    }
    for (name, set) in [("first", a), ("second", b)] {
        if !set.len().is_multiple_of(d) {
            return invalid(format!(
                "the {name} set has {} values, not a whole number of {d}-dimensional points",
                set.len()
            ));
        }
    }
    let (n, m) = (a.len() / d, b.len() / d);
    if n == 0 || m == 0 {
        return invalid(format!(
            "empty point set ({n} points in the first set, {m} in the second)"
        ));
    }
    if n != m {
        return invalid(format!(
            "equal counts are required (the assignment of uniform weights), but the first set \
             has {n} points and the second {m}"
        ));
    }
    Ok(n)
}

/// Coordinates beyond this magnitude could overflow the squared distances.
const LARGEST_COORDINATE: f64 = 1e100;

/// Copies `values` into `out` as `f64`, refusing a coordinate that is not finite or beyond
/// [`LARGEST_COORDINATE`].
fn to_f64<T: Copy + Into<f64>>(
    values: &[T],
    d: usize,
    name: &str,
    out: &mut Vec<f64>,
) -> Result<()> {
    out.clear();
    out.extend(values.iter().map(|&x| x.into()));
    if let Some(at) = out
        .iter()
        .position(|x| x.is_nan() || x.abs() > LARGEST_COORDINATE)
    {
        return Err(PointSetError::Invalid {
            what: "earth mover's distance",
            reason: format!(
                "coordinate {} of point {} of the {name} set is {} (finite values up to \
                 {LARGEST_COORDINATE:e} in magnitude are supported)",
                at % d,
                at / d,
                out[at]
            ),
        });
    }
    Ok(())
}
