//! The linear assignment problem `min_σ Σᵢ C(aᵢ, b_σ(i))` on a sparse candidate graph, made exact
//! by a sweep over every pair that certifies the result or grows the graph.
//!
//! Notation: rows `i` are the points of `a`, columns `j` those of `b`; `uᵢ`, `vⱼ` are the dual
//! potentials and `rᵢⱼ = Cᵢⱼ − uᵢ − vⱼ` the reduced costs. An auction (Bertsekas 1988) settles
//! most rows quickly but only to within its `ε`; the shortest augmenting paths that finish the
//! job keep two invariants on the edges of the graph: `rᵢⱼ ≥ 0` (dual feasibility) and `rᵢⱼ = 0`
//! on assigned edges (complementary slackness). A shortest path in the reduced costs from a free
//! row to a free column (Dijkstra: the costs are non-negative) lengthens the assignment by one,
//! and shifting the potentials by the path distances keeps both invariants (Jonker & Volgenant
//! 1987; Burkard, Dell'Amico & Martello, *Assignment Problems*, § 4.4). With every row assigned,
//! the assignment is optimal on the graph.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::GroundCost;
use super::neighbours::{candidates, curve_orders, squared_distance};

/// No partner (a free row or column).
const FREE: u32 = u32::MAX;

/// Two point sets of `n` points in `d` dimensions (`f64`, row-major), the ground cost between
/// them, and `b` transposed `[d][n]` for the exact sweep of a row over all columns.
pub(super) struct Problem<'p> {
    pub a: &'p [f64],
    pub b: &'p [f64],
    pub b_by_coordinate: &'p [f64],
    pub n: usize,
    pub d: usize,
    pub cost: GroundCost,
}

impl Problem<'_> {
    #[inline]
    fn point_a(&self, i: usize) -> &[f64] {
        &self.a[i * self.d..(i + 1) * self.d]
    }

    #[inline]
    fn point_b(&self, j: usize) -> &[f64] {
        &self.b[j * self.d..(j + 1) * self.d]
    }

    /// `C(aᵢ, bⱼ)`.
    #[inline]
    pub fn cost(&self, i: usize, j: usize) -> f64 {
        let s = squared_distance(self.point_a(i), self.point_b(j));
        match self.cost {
            GroundCost::SquaredEuclidean => s,
            GroundCost::Euclidean => s.sqrt(),
        }
    }

    /// `out[j] = C(aᵢ, bⱼ) − vⱼ` for every column, bitwise equal to `cost(i, j) − v[j]` (the
    /// squares are summed in the same order); returns the minimum.
    fn reduced_row(&self, i: usize, v: &[f64], out: &mut [f64]) -> f64 {
        let n = self.n;
        out.fill(0.0);
        for (k, &x) in self.point_a(i).iter().enumerate() {
            let column = &self.b_by_coordinate[k * n..(k + 1) * n];
            for (s, &y) in out.iter_mut().zip(column) {
                *s += (x - y) * (x - y);
            }
        }
        if self.cost == GroundCost::Euclidean {
            for s in out.iter_mut() {
                *s = s.sqrt();
            }
        }
        for (s, &vj) in out.iter_mut().zip(v) {
            *s -= vj;
        }
        // Eight running minima, so that the loop vectorises (a single `f64::min` chain cannot be
        // reordered by the compiler).
        let mut lanes = [f64::INFINITY; 8];
        let mut chunks = out.chunks_exact(8);
        for chunk in &mut chunks {
            for (m, &s) in lanes.iter_mut().zip(chunk) {
                *m = if s < *m { s } else { *m };
            }
        }
        let tail = chunks.remainder().iter().copied();
        lanes.into_iter().chain(tail).fold(f64::INFINITY, f64::min)
    }

    /// Whether some column has `C(aᵢ, bⱼ) − vⱼ < t`, up to rounding far below the margin the
    /// caller leaves: returns the minimum over the columns the screening looks at of a `gⱼ` that
    /// is negative exactly then (infinite if it skips every block). Blocks whose box is too far
    /// from `aᵢ` are skipped on a lower bound: `Cᵢⱼ ≥ C(aᵢ, box)` and `vⱼ ≤ max v` over the
    /// block. Within a block no square roots are taken: for the Euclidean cost `|x − y| < t + vⱼ`
    /// is `|x − y|² < (t + vⱼ)²` with `t + vⱼ > 0`.
    fn screen(&self, blocks: &Blocks, i: usize, t: f64) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, as just checked.
            return unsafe { self.screen_avx2(blocks, i, t) };
        }
        self.screen_portable(blocks, i, t)
    }

    /// [`Problem::screen`] compiled for AVX2 (four `f64` lanes instead of SSE2's two).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn screen_avx2(&self, blocks: &Blocks, i: usize, t: f64) -> f64 {
        self.screen_portable(blocks, i, t)
    }

    #[inline(always)]
    fn screen_portable(&self, blocks: &Blocks, i: usize, t: f64) -> f64 {
        match self.d {
            1 => self.screen_in::<1>(blocks, i, t),
            2 => self.screen_in::<2>(blocks, i, t),
            3 => self.screen_in::<3>(blocks, i, t),
            _ => self.screen_in::<0>(blocks, i, t),
        }
    }

    /// [`Problem::screen`] in `D` dimensions (`D = 0`: any), so that the loops over the
    /// coordinates unroll.
    #[inline(always)]
    fn screen_in<const D: usize>(&self, blocks: &Blocks, i: usize, t: f64) -> f64 {
        let n = self.n;
        let d = if D == 0 { self.d } else { D };
        let x = self.point_a(i);
        let euclidean = self.cost == GroundCost::Euclidean;
        let mut squares = [0.0; BLOCK];
        let mut least = f64::INFINITY;
        for (block, v_max) in blocks.v_max.iter().enumerate() {
            let (lo, hi) = (&blocks.lo[block * d..][..d], &blocks.hi[block * d..][..d]);
            let mut to_box = 0.0;
            for k in 0..d {
                let gap = (lo[k] - x[k]).max(x[k] - hi[k]).max(0.0);
                to_box += gap * gap;
            }
            let bound = if euclidean { to_box.sqrt() } else { to_box } - v_max;
            if bound >= t {
                continue;
            }
            let slots = block * BLOCK..((block + 1) * BLOCK).min(n);
            let squares = &mut squares[..slots.len()];
            let first = &blocks.coordinates[slots.clone()];
            for (s, &y) in squares.iter_mut().zip(first) {
                *s = (x[0] - y) * (x[0] - y);
            }
            for (k, &x) in x.iter().enumerate().skip(1) {
                let column = &blocks.coordinates[k * n..][slots.clone()];
                for (s, &y) in squares.iter_mut().zip(column) {
                    *s += (x - y) * (x - y);
                }
            }
            let v = &blocks.v[slots];
            let g = |s: f64, vj: f64| {
                if euclidean {
                    let w = t + vj;
                    s - w * if w > 0.0 { w } else { 0.0 }
                } else {
                    s - vj - t
                }
            };
            // Four running minima, so that the loop vectorises.
            let mut lanes = [f64::INFINITY; 4];
            let whole = squares.len() / 4 * 4;
            for (s, vj) in squares[..whole].chunks_exact(4).zip(v.chunks_exact(4)) {
                for ((m, &s), &vj) in lanes.iter_mut().zip(s).zip(vj) {
                    let g = g(s, vj);
                    *m = if g < *m { g } else { *m };
                }
            }
            let tail = squares[whole..]
                .iter()
                .zip(&v[whole..])
                .map(|(&s, &vj)| g(s, vj));
            least = lanes.into_iter().chain(tail).fold(least, f64::min);
        }
        least
    }
}

/// Points of `b` per block of the sweep's screening.
const BLOCK: usize = 64;

/// The points of `b` in blocks of [`BLOCK`] consecutive points along the Z-order curve (compact
/// clusters), by coordinate, with each block's bounding box and largest potential `vⱼ`.
#[derive(Default)]
struct Blocks {
    /// The column of each slot.
    column: Vec<u32>,
    /// Coordinates by slot, `[d][N]`.
    coordinates: Vec<f64>,
    /// Bounding boxes, `[blocks][d]`.
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// `vⱼ` by slot, and its maximum per block (refreshed before each sweep).
    v: Vec<f64>,
    v_max: Vec<f64>,
}

impl Blocks {
    fn new(problem: &Problem, order: Vec<u32>) -> Self {
        let (n, d) = (problem.n, problem.d);
        let mut coordinates = vec![0.0; d * n];
        for (slot, &j) in order.iter().enumerate() {
            for (k, &y) in problem.point_b(j as usize).iter().enumerate() {
                coordinates[k * n + slot] = y;
            }
        }
        let count = n.div_ceil(BLOCK);
        let mut lo = vec![f64::INFINITY; count * d];
        let mut hi = vec![f64::NEG_INFINITY; count * d];
        for slot in 0..n {
            let block = slot / BLOCK;
            for k in 0..d {
                let y = coordinates[k * n + slot];
                lo[block * d + k] = lo[block * d + k].min(y);
                hi[block * d + k] = hi[block * d + k].max(y);
            }
        }
        Self {
            column: order,
            coordinates,
            lo,
            hi,
            v: vec![0.0; n],
            v_max: vec![0.0; count],
        }
    }

    fn refresh(&mut self, v: &[f64]) {
        for (slot, &j) in self.column.iter().enumerate() {
            self.v[slot] = v[j as usize];
        }
        for (m, block) in self.v_max.iter_mut().zip(self.v.chunks(BLOCK)) {
            *m = block.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        }
    }
}

/// A candidate pair: the column of `b` and its cost from the row's point of `a`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Edge {
    cost: f64,
    column: u32,
}

/// The candidate edges, row by row (compressed rows; each row's columns distinct).
struct Graph {
    start: Vec<usize>,
    edges: Vec<Edge>,
}

impl Graph {
    /// The pairs of each point of `a` with the points of `b` around it and of each point of `b`
    /// with the points of `a` around it (at least `k` each, see [`candidates`]), plus `extra`.
    fn nearest(problem: &Problem, k: usize, extra: &[(u32, u32)]) -> Self {
        let n = problem.n;
        let mut rows: Vec<Vec<u32>> = vec![Vec::with_capacity(3 * k); n];
        candidates(problem.a, problem.b, problem.d, k, &mut rows);
        let mut columns: Vec<Vec<u32>> = vec![Vec::new(); n];
        candidates(problem.b, problem.a, problem.d, k, &mut columns);
        for (j, column) in columns.iter().enumerate() {
            for &i in column {
                rows[i as usize].push(j as u32);
            }
        }
        for &(i, j) in extra {
            rows[i as usize].push(j);
        }
        // Both directions find most pairs twice: keep each once.
        let mut seen = vec![FREE; n];
        let mut start = Vec::with_capacity(n + 1);
        start.push(0);
        let mut edges = Vec::with_capacity(rows.iter().map(Vec::len).sum());
        for (i, row) in rows.iter().enumerate() {
            for &j in row {
                if seen[j as usize] != i as u32 {
                    seen[j as usize] = i as u32;
                    edges.push(Edge {
                        cost: problem.cost(i, j as usize),
                        column: j,
                    });
                }
            }
            start.push(edges.len());
        }
        Self { start, edges }
    }

    /// The graph with `pairs` added: pairs it lacks, in the order of their rows.
    fn with(self, problem: &Problem, pairs: &[(u32, u32)]) -> Self {
        if pairs.is_empty() {
            return self;
        }
        let mut start = Vec::with_capacity(self.start.len());
        start.push(0);
        let mut edges = Vec::with_capacity(self.edges.len() + pairs.len());
        let mut next = pairs.iter().peekable();
        for i in 0..problem.n {
            edges.extend_from_slice(self.row(i));
            while let Some(&(_, j)) = next.next_if(|&&(row, _)| row as usize == i) {
                edges.push(Edge {
                    cost: problem.cost(i, j as usize),
                    column: j,
                });
            }
            start.push(edges.len());
        }
        Self { start, edges }
    }

    #[inline]
    fn row(&self, i: usize) -> &[Edge] {
        &self.edges[self.start[i]..self.start[i + 1]]
    }

    fn edges(&self) -> usize {
        self.edges.len()
    }
}

/// The mean over rows of the cheapest edge, the scale of the auction's `ε` (1 for sets that
/// coincide).
fn typical_cost(graph: &Graph) -> f64 {
    let n = graph.start.len() - 1;
    let mean = (0..n)
        .map(|i| {
            graph
                .row(i)
                .iter()
                .map(|e| e.cost)
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / n as f64;
    let widest = graph.edges.iter().map(|e| e.cost).fold(0.0, f64::max);
    if mean > 0.0 {
        mean
    } else if widest > 0.0 {
        widest
    } else {
        1.0
    }
}

/// The auction's first `ε`, in units of [`typical_cost`] (a cold start)...
const AUCTION_START: f64 = 30.0;
/// ... and when warm-starting from the previous frame's potentials.
const AUCTION_WARM_START: f64 = 1.0;
/// Its last `ε`: the paths settle the near-ties that the auction leaves.
const AUCTION_END: f64 = 1e-2;
/// The factor by which `ε` shrinks between phases.
const AUCTION_SCALING: f64 = 8.0;

/// A distance in Dijkstra's heap, ordered by `total_cmp`.
#[derive(Clone, Copy, PartialEq)]
struct Distance(f64);

impl Eq for Distance {}

impl PartialOrd for Distance {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Distance {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// What a solve did, for tests and benches.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolveStats {
    /// Candidate edges at the start (the nearest-neighbour graph).
    pub initial_edges: usize,
    /// Candidate edges at the end (with those that the certification added).
    pub final_edges: usize,
    /// Sweeps over all `N²` pairs (the last one certifies).
    pub certifications: usize,
    /// Phases of the ε-scaling auction that starts the solve.
    pub auction_phases: usize,
    /// Shortest augmenting paths after the auction.
    pub augmentations: usize,
}

/// The optimal assignment and the potentials that certify it, with the scratch space of the
/// searches. Reused between solves of the same size to warm-start.
#[derive(Default)]
pub(super) struct Assignment {
    /// The column of each row, `FREE` if none.
    col_of: Vec<u32>,
    /// The row of each column, `FREE` if none.
    row_of: Vec<u32>,
    u: Vec<f64>,
    v: Vec<f64>,
    /// `C(i, σ(i))` for the auction's assigned rows.
    assigned_cost: Vec<f64>,
    /// Dijkstra's tentative distances (valid where `stamp` is the current search's).
    dist: Vec<f64>,
    /// The row each column was reached from.
    pred: Vec<u32>,
    stamp: Vec<u32>,
    search: u32,
    /// Columns whose distance is final in the current search.
    done: Vec<bool>,
    popped: Vec<u32>,
    heap: BinaryHeap<Reverse<(Distance, u32)>>,
    /// One row of `C − v` (the certification's sweep).
    row_buffer: Vec<f64>,
    /// The points of `b` in the blocks of the sweep's screening.
    blocks: Blocks,
    pub stats: SolveStats,
    /// Upper bound on `Σᵢ C(i, σ(i))` minus the optimum, from the last certification.
    pub gap: f64,
}

/// Options of the sparse solve.
pub(super) struct SparseOptions {
    /// Neighbours per point in the candidate graph.
    pub k: usize,
    /// Start from the previous solve's potentials and assignment (same `n`).
    pub warm: bool,
}

impl Assignment {
    /// The assignment `σ` (`σ(i)` is the point of `b` assigned to point `i` of `a`).
    pub fn columns(&self) -> impl Iterator<Item = usize> + '_ {
        self.col_of.iter().map(|&j| j as usize)
    }

    /// Solves the assignment problem exactly: an auction on the candidate graph, shortest
    /// augmenting paths from the rows it leaves free, then a sweep over all pairs that either
    /// certifies the result or adds the edges that violate dual feasibility, until certified.
    /// Leaves the assignment in `col_of`.
    pub fn solve(&mut self, problem: &Problem, options: &SparseOptions) {
        let n = problem.n;
        let warm = options.warm && self.col_of.len() == n && self.col_of.iter().all(|&j| j != FREE);
        // A curve pairing, and the previous assignment: perfect matchings, so that the graph
        // has one and a free row always has an augmenting path.
        let (order_a, order_b) = curve_orders(problem.a, problem.b, problem.d);
        let mut extra: Vec<(u32, u32)> = order_a.into_iter().zip(order_b.iter().copied()).collect();
        if warm {
            extra.extend(self.col_of.iter().enumerate().map(|(i, &j)| (i as u32, j)));
        }
        let mut graph = Graph::nearest(problem, options.k, &extra);
        self.reset(n, warm);
        self.blocks = Blocks::new(problem, order_b);
        self.stats = SolveStats {
            initial_edges: graph.edges(),
            ..SolveStats::default()
        };
        let scale = typical_cost(&graph);
        let start = if warm {
            self.refresh_assigned_costs(problem);
            AUCTION_WARM_START
        } else {
            self.reduce_columns(&graph);
            AUCTION_START
        };
        // Should the bids run out, the paths finish from wherever the auction stopped.
        self.auction(&graph, start * scale, AUCTION_END * scale);
        self.tighten(&graph);
        loop {
            for s in 0..n {
                if self.col_of[s] == FREE {
                    let found = self.augment(&graph, s);
                    assert!(found, "the candidate graph holds a perfect matching");
                    self.stats.augmentations += 1;
                }
            }
            let added = self.certify(problem, &graph);
            if added.is_empty() {
                break;
            }
            graph = graph.with(problem, &added);
        }
        self.stats.final_edges = graph.edges();
    }

    fn refresh_assigned_costs(&mut self, problem: &Problem) {
        for (i, &j) in self.col_of.iter().enumerate() {
            if j != FREE {
                self.assigned_cost[i] = problem.cost(i, j as usize);
            }
        }
    }

    fn reset(&mut self, n: usize, warm: bool) {
        if !warm {
            self.col_of = vec![FREE; n];
            self.row_of = vec![FREE; n];
            self.v = vec![0.0; n];
        }
        self.u = vec![0.0; n];
        if self.assigned_cost.len() != n {
            self.assigned_cost = vec![0.0; n];
        }
        self.dist = vec![0.0; n];
        self.pred = vec![FREE; n];
        self.stamp = vec![0; n];
        self.search = 0;
        self.done = vec![false; n];
        self.row_buffer = vec![0.0; n];
    }

    /// Column reduction `vⱼ = minᵢ Cᵢⱼ` over the graph's edges, nothing assigned.
    fn reduce_columns(&mut self, graph: &Graph) {
        self.v.fill(f64::INFINITY);
        self.col_of.fill(FREE);
        self.row_of.fill(FREE);
        for i in 0..self.col_of.len() {
            for e in graph.row(i) {
                let vj = &mut self.v[e.column as usize];
                *vj = vj.min(e.cost);
            }
        }
    }

    /// The smallest `Cᵢⱼ − vⱼ` over row `i`'s edges with its column, and the second smallest
    /// (infinite where the row has fewer edges).
    #[inline]
    fn best_two(&self, graph: &Graph, i: usize) -> (f64, u32, f64) {
        let (mut first, mut column, mut second) = (f64::INFINITY, FREE, f64::INFINITY);
        for e in graph.row(i) {
            debug_assert!((e.column as usize) < self.v.len());
            // SAFETY: a graph's columns index the `n` columns of its problem (`Graph::nearest`,
            // `Graph::with`), and `v` has one entry per column.
            let h = e.cost - unsafe { *self.v.get_unchecked(e.column as usize) };
            if h < second {
                if h < first {
                    second = first;
                    first = h;
                    column = e.column;
                } else {
                    second = h;
                }
            }
        }
        (first, column, second)
    }

    /// The forward auction with ε-scaling (Bertsekas 1988), Gauss–Seidel: a free row bids for
    /// its best column `j₁`, lowering `v_j₁` by the margin over its second best plus `ε`, and
    /// takes it from its owner, who bids next. At the end of a phase every row is assigned and
    /// within `ε` of its best (`ε`-complementary slackness); `ε` then shrinks by
    /// [`AUCTION_SCALING`] and the rows that lose that property bid again, down to `end`. Each bid
    /// lowers a price by at least `ε`, which bounds the bids (the graph has a perfect matching);
    /// a phase that exceeds a budget of `50 N` bids ends the auction where it stands.
    fn auction(&mut self, graph: &Graph, start: f64, end: f64) {
        let n = self.col_of.len();
        let mut epsilon = start.max(end);
        let mut queue = std::collections::VecDeque::with_capacity(n);
        loop {
            for i in 0..n {
                let j = self.col_of[i];
                if j == FREE {
                    queue.push_back(i as u32);
                    continue;
                }
                let (best, _, _) = self.best_two(graph, i);
                if self.assigned_cost[i] - self.v[j as usize] > best + epsilon {
                    self.col_of[i] = FREE;
                    self.row_of[j as usize] = FREE;
                    queue.push_back(i as u32);
                }
            }
            let mut budget = 50 * n + 1000;
            while let Some(i) = queue.pop_front() {
                if budget == 0 {
                    return;
                }
                budget -= 1;
                let i = i as usize;
                let (w1, j, w2) = self.best_two(graph, i);
                let jj = j as usize;
                // A row with one edge has no second best: it only needs to outbid by ε.
                let margin = if w2.is_finite() { w2 - w1 } else { 0.0 };
                self.v[jj] -= margin + epsilon;
                let owner = self.row_of[jj];
                if owner != FREE {
                    self.col_of[owner as usize] = FREE;
                    queue.push_back(owner);
                }
                self.row_of[jj] = i as u32;
                self.col_of[i] = j;
                self.assigned_cost[i] = w1 + self.v[jj] + margin + epsilon;
            }
            self.stats.auction_phases += 1;
            if epsilon <= end {
                return;
            }
            epsilon = (epsilon / AUCTION_SCALING).max(end);
        }
    }

    /// From the auction's `ε`-complementary slackness to the exact invariants of the paths:
    /// raises each assigned column's `vⱼ` by its row's slack, so that the assigned edge attains
    /// the row minimum, sets `uᵢ` to the row minimum, and frees the rows whose assigned edge no
    /// longer attains it (a near-tie with a column whose price rose too; few when `ε` is small).
    fn tighten(&mut self, graph: &Graph) {
        let n = self.col_of.len();
        for i in 0..n {
            let j = self.col_of[i];
            if j != FREE {
                let (best, _, _) = self.best_two(graph, i);
                self.u[i] = self.assigned_cost[i] - self.v[j as usize] - best;
            }
        }
        for i in 0..n {
            let j = self.col_of[i];
            if j != FREE {
                self.v[j as usize] += self.u[i];
            }
        }
        let magnitude = self.v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
            + self
                .assigned_cost
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()));
        let tie = 1e-14 * magnitude;
        for i in 0..n {
            let (best, _, _) = self.best_two(graph, i);
            self.u[i] = best;
            let j = self.col_of[i];
            if j != FREE && self.assigned_cost[i] - self.v[j as usize] - best > tie {
                self.col_of[i] = FREE;
                self.row_of[j as usize] = FREE;
            }
        }
    }

    /// One shortest augmenting path from the free row `s` over the graph's edges (Dijkstra on
    /// the reduced costs, with a binary heap); false if no free column can be reached.
    fn augment(&mut self, graph: &Graph, s: usize) -> bool {
        self.search += 1;
        let search = self.search;
        self.heap.clear();
        self.popped.clear();
        let relax = |this: &mut Self, i: usize, base: f64| {
            let ui = this.u[i];
            for e in graph.row(i) {
                let j = e.column as usize;
                let fresh = this.stamp[j] != search;
                if !fresh && this.done[j] {
                    continue;
                }
                let dj = base + (e.cost - ui - this.v[j]);
                if fresh || dj < this.dist[j] {
                    this.stamp[j] = search;
                    this.done[j] = false;
                    this.dist[j] = dj;
                    this.pred[j] = i as u32;
                    this.heap.push(Reverse((Distance(dj), e.column)));
                }
            }
        };
        relax(self, s, 0.0);
        let (sink, length) = loop {
            let Some(Reverse((Distance(dj), j))) = self.heap.pop() else {
                return false;
            };
            let jj = j as usize;
            if self.done[jj] || dj > self.dist[jj] {
                continue;
            }
            self.done[jj] = true;
            let i = self.row_of[jj];
            if i == FREE {
                break (jj, dj);
            }
            self.popped.push(j);
            relax(self, i as usize, dj);
        };
        self.update_and_augment(s, sink, length);
        true
    }

    /// Shifts the potentials by the search's distances, `vⱼ −= L − dⱼ` and `u_row(j) += L − dⱼ`
    /// for the columns settled before the sink at distance `L`, `u_s += L`, which keeps every
    /// reduced cost non-negative and makes the path tight; then flips the path.
    fn update_and_augment(&mut self, s: usize, sink: usize, length: f64) {
        for &j in &self.popped {
            let j = j as usize;
            let delta = length - self.dist[j];
            self.v[j] -= delta;
            self.u[self.row_of[j] as usize] += delta;
        }
        self.u[s] += length;
        let mut j = sink;
        loop {
            let i = self.pred[j] as usize;
            let next = self.col_of[i];
            self.col_of[i] = j as u32;
            self.row_of[j] = i as u32;
            if i == s {
                break;
            }
            j = next as usize;
        }
    }

    /// The sweep over all pairs, with every row assigned. For row `i` with `hᵢ = C(i, σ(i)) −
    /// v_σ(i)` and `mᵢ = minⱼ (Cᵢⱼ − vⱼ)` over all columns, `uᵢ = mᵢ` is feasible on every pair,
    /// so for any assignment `τ`, `Σ C(i, τ(i)) ≥ Σ (mᵢ + v_τ(i)) = Σ C(i, σ(i)) − Σ (hᵢ − mᵢ)`:
    /// `σ` is optimal to within the gap `Σ (hᵢ − mᵢ)`, recorded in `self.gap`. A row is certified
    /// when no column beats its assignment by more than `tol` (`10⁻¹³` of the scale of the costs
    /// and potentials), which a screening without square roots shows for most rows; it adds
    /// `tol` to the gap. Otherwise the row's pairs with `Cᵢⱼ − vⱼ < hᵢ − tol` that the graph lacks
    /// are returned to be added, and the row gets `uᵢ = mᵢ` and loses its column. A row whose
    /// better pairs are all in the graph already is left as it is: its excess over `mᵢ` is
    /// rounding in the potentials, and stays in the gap.
    fn certify(&mut self, problem: &Problem, graph: &Graph) -> Vec<(u32, u32)> {
        self.stats.certifications += 1;
        let n = problem.n;
        let mut row = std::mem::take(&mut self.row_buffer);
        let scale = self.v.iter().fold(0.0f64, |m, &x| m.max(x.abs()))
            + (0..n)
                .map(|i| problem.cost(i, self.col_of[i] as usize))
                .fold(0.0, f64::max);
        let tol = 1e-13 * scale;
        self.blocks.refresh(&self.v);
        let mut added = Vec::new();
        let mut in_graph = vec![false; n];
        self.gap = 0.0;
        for i in 0..n {
            let j = self.col_of[i] as usize;
            let h = problem.cost(i, j) - self.v[j];
            if problem.screen(&self.blocks, i, h - tol) >= 0.0 {
                self.u[i] = h;
                self.gap += tol;
                continue;
            }
            let m = problem.reduced_row(i, &self.v, &mut row).min(h);
            let before = added.len();
            for e in graph.row(i) {
                in_graph[e.column as usize] = true;
            }
            for (jj, &r) in row.iter().enumerate() {
                if r < h - tol && !in_graph[jj] {
                    added.push((i as u32, jj as u32));
                }
            }
            for e in graph.row(i) {
                in_graph[e.column as usize] = false;
            }
            if added.len() > before {
                self.u[i] = m;
                self.row_of[j] = FREE;
                self.col_of[i] = FREE;
            } else {
                self.u[i] = h;
                self.gap += h - m;
            }
        }
        self.row_buffer = row;
        added
    }
}
