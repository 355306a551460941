//! The masked Poisson matrix of FLIP's pressure projection (thesis eq. 2.9), assembled from plain
//! grid data ([`PoissonGrid`]: a resolution, cell sizes, which sides are open) and cell and face
//! masks, so that the solvers need no domain type; the fields layer describes its domains this
//! way.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use super::SolveError;
use super::sparse::SparseMatrix;

/// A per-cell or per-face flag or weight: `bool`, `f32` or `f64`.
///
/// As a liquid flag, a cell is liquid when its weight exceeds `0.5`. As a face weight, the value
/// (clamped to `[0, 1]`) is the open fraction of the face: `0` is a wall or an obstacle, `1` a
/// fully accessible face.
pub trait Weight: Copy {
    /// The value as a number in `[0, 1]` (`bool`: `0` or `1`).
    fn weight(self) -> f64;
}

impl Weight for bool {
    #[inline]
    fn weight(self) -> f64 {
        if self { 1.0 } else { 0.0 }
    }
}

impl Weight for f32 {
    #[inline]
    fn weight(self) -> f64 {
        f64::from(self).clamp(0.0, 1.0)
    }
}

impl Weight for f64 {
    #[inline]
    fn weight(self) -> f64 {
        self.clamp(0.0, 1.0)
    }
}

/// The Poisson system of one pressure solve: the matrix over the liquid cells and the maps
/// between cells and unknowns.
#[derive(Debug, Clone)]
pub struct PoissonSystem {
    /// The negative masked Laplacian over the unknowns (symmetric positive definite).
    pub matrix: Arc<SparseMatrix>,
    /// For each cell (row-major over the grid's resolution), its unknown, or `None` for a cell
    /// that is not liquid.
    pub cell_to_unknown: Vec<Option<usize>>,
    /// For each unknown, its cell.
    pub unknown_to_cell: Vec<usize>,
    /// The unknowns pinned to make an otherwise singular (pure Neumann) liquid region solvable:
    /// one per connected liquid region that touches neither air nor an open side.
    pub pinned: Vec<usize>,
    /// For each unknown, the connected liquid region it belongs to.
    pub region_of: Vec<usize>,
    /// For each region, whether it is pure Neumann (and therefore has a pinned unknown).
    pub region_is_singular: Vec<bool>,
}

impl PoissonSystem {
    /// Number of unknowns (liquid cells).
    pub fn unknowns(&self) -> usize {
        self.unknown_to_cell.len()
    }

    /// The cell index of each unknown as `i64`, for gathers and scatters of tensors
    /// (`IntTensor::from_vec`).
    pub(crate) fn unknown_cells_i64(&self) -> Vec<i64> {
        self.unknown_to_cell.iter().map(|&c| c as i64).collect()
    }

    /// Per-cell values (row-major over the resolution) restricted to the unknowns.
    ///
    /// # Errors
    /// [`SolveError::DimensionMismatch`] when `cells` does not hold one value per cell.
    pub fn gather<T: Copy>(&self, cells: &[T]) -> Result<Vec<T>, SolveError> {
        check_len("cell values", self.cell_to_unknown.len(), cells.len())?;
        Ok(self.unknown_to_cell.iter().map(|&c| cells[c]).collect())
    }

    /// Values of the unknowns spread to all cells, `fill` in the cells that are not liquid.
    ///
    /// # Errors
    /// [`SolveError::DimensionMismatch`] when `values` does not hold one value per unknown.
    pub fn scatter<T: Copy>(&self, values: &[T], fill: T) -> Result<Vec<T>, SolveError> {
        check_len("unknown values", self.unknowns(), values.len())?;
        let mut cells = vec![fill; self.cell_to_unknown.len()];
        for (&c, &v) in self.unknown_to_cell.iter().zip(values) {
            cells[c] = v;
        }
        Ok(cells)
    }

    /// Subtracts, in each pure-Neumann region, the region's mean from `rhs` (one value per
    /// unknown), making the right-hand side compatible with the singular operator. With a
    /// compatible right-hand side the pinned system gives the exact solution that is zero at the
    /// pinned cell; see [`PoissonSystem::assemble`].
    ///
    /// # Errors
    /// [`SolveError::DimensionMismatch`] when `rhs` does not hold one value per unknown.
    pub fn remove_singular_means(&self, rhs: &mut [f64]) -> Result<(), SolveError> {
        check_len("right-hand side", self.unknowns(), rhs.len())?;
        let regions = self.region_is_singular.len();
        let mut sums = vec![0.0; regions];
        let mut counts = vec![0usize; regions];
        for (u, &r) in self.region_of.iter().enumerate() {
            sums[r] += rhs[u];
            counts[r] += 1;
        }
        for (u, &r) in self.region_of.iter().enumerate() {
            if self.region_is_singular[r] {
                rhs[u] -= sums[r] / counts[r] as f64;
            }
        }
        Ok(())
    }
}

fn check_len(what: &str, expected: usize, got: usize) -> Result<(), SolveError> {
    if expected == got {
        Ok(())
    } else {
        Err(SolveError::DimensionMismatch {
            what: what.into(),
            expected,
            got,
        })
    }
}

/// The grid a Poisson matrix is assembled on, as plain numbers: `d` axes (1 to 3), cells
/// numbered row-major over `resolution`, and the faces of axis `a` row-major over the
/// resolution with one more layer along `a` (a MAC grid's staggered component `a`).
#[derive(Debug, Clone, Copy)]
pub struct PoissonGrid<'a> {
    /// Cells per axis.
    pub resolution: &'a [usize],
    /// The width of a cell along each axis (positive, in length units): the face coefficients
    /// are `1/h²`.
    pub cell_size: &'a [f64],
    /// Per axis, `[lower side, upper side]`: `true` where the side is open (air beyond it, a
    /// Dirichlet `p = 0`), `false` where it is a closed wall (no flux).
    pub open_sides: &'a [[bool; 2]],
}

impl PoissonGrid<'_> {
    /// Number of axes.
    pub fn dim(&self) -> usize {
        self.resolution.len()
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.resolution.iter().product()
    }

    /// Number of faces normal to `axis`: the cells' grid with one more layer along `axis`.
    ///
    /// # Panics
    /// When `axis` is not below [`Self::dim`].
    pub fn face_count(&self, axis: usize) -> usize {
        assert!(axis < self.dim(), "axis {axis} of a {}-d grid", self.dim());
        (0..self.dim())
            .map(|a| self.resolution[a] + usize::from(a == axis))
            .product()
    }

    /// Checks that the grid has 1 to 3 axes, one cell size and one pair of sides per axis, no
    /// empty axis and positive finite cell sizes.
    fn check(&self) -> Result<(), SolveError> {
        let d = self.dim();
        if !(1..=3).contains(&d) {
            return Err(SolveError::Invalid {
                reason: format!("a Poisson grid has 1 to 3 axes, not {d}"),
            });
        }
        check_len("cell sizes (one per axis)", d, self.cell_size.len())?;
        check_len("open sides (one pair per axis)", d, self.open_sides.len())?;
        for axis in 0..d {
            let (n, h) = (self.resolution[axis], self.cell_size[axis]);
            if n == 0 || !(h.is_finite() && h > 0.0) {
                return Err(SolveError::Invalid {
                    reason: format!(
                        "axis {axis} of the Poisson grid has {n} cells of size {h}; it needs at \
                         least one cell and a positive finite size"
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Row-major strides of `shape`.
fn strides(shape: &[usize]) -> Vec<usize> {
    let mut strides = vec![1; shape.len()];
    for axis in (0..shape.len().saturating_sub(1)).rev() {
        strides[axis] = strides[axis + 1] * shape[axis + 1];
    }
    strides
}

impl PoissonSystem {
    /// The negative masked Laplacian `A` of the pressure projection on `grid`: `A p ≈ −∇²p` on
    /// the liquid cells, with `p = 0` in air.
    ///
    /// - `liquid`: one flag per cell, row-major over `grid.resolution` (a [`Weight`] above `0.5`
    ///   is liquid). Only liquid cells are unknowns.
    /// - `face_open[axis]`: one weight per face normal to `axis` ([`PoissonGrid::face_count`]),
    ///   row-major: `0` for a face that is not accessible (a wall, an obstacle), `1` for an open
    ///   face, fractions in between scale the face's coefficient.
    ///
    /// For every open face (weight `w`) of a liquid cell, with `h` the cell size along the
    /// face's axis, the cell's diagonal gains `w/h²`; if the neighbour is liquid, the
    /// off-diagonal entry gets `−w/h²` (a flux between two unknowns); if the neighbour is air,
    /// nothing else (the `p = 0` Dirichlet term, ghost value at the air cell's centre). A face on
    /// the grid's side leads to air when that side is open and is a wall (no flux) when it is
    /// closed, whatever its weight. A face of weight 0 contributes nothing (Neumann).
    ///
    /// # Singular regions
    /// A connected liquid region (connected through faces of positive weight) that touches no
    /// air and no open side is a pure Neumann problem: its block of `A` is singular (constants
    /// are in the null space). Each such region gets one *pinned* unknown (its first cell in
    /// row-major order), whose diagonal gains `max_axis 1/h²`, i.e. `A + c e_k e_kᵀ`, which is
    /// symmetric positive definite. If the right-hand side sums to zero over the region (the
    /// compatibility condition, see [`PoissonSystem::remove_singular_means`]), the solution is
    /// the exact one with `p = 0` at the pinned cell; pressure gradients, all the projection
    /// uses, do not depend on that constant. Otherwise the incompatible part ends up at the
    /// pinned cell. Pinned unknowns are listed in [`PoissonSystem::pinned`].
    ///
    /// # Errors
    /// [`SolveError::Invalid`] for a grid of other than 1 to 3 axes, an empty axis or a cell
    /// size that is not positive; [`SolveError::DimensionMismatch`] when the grid's lists,
    /// `liquid` or a face array have the wrong length or there is not one face array per axis.
    pub fn assemble<L: Weight, W: Weight, F: AsRef<[W]>>(
        grid: &PoissonGrid<'_>,
        liquid: &[L],
        face_open: &[F],
    ) -> Result<Self, SolveError> {
        grid.check()?;
        let resolution = grid.resolution;
        let d = grid.dim();
        let cells = grid.cell_count();
        check_len("liquid flags (one per cell)", cells, liquid.len())?;
        check_len("face arrays (one per axis)", d, face_open.len())?;
        for (axis, faces) in face_open.iter().enumerate() {
            check_len(
                &format!("face weights of axis {axis}"),
                grid.face_count(axis),
                faces.as_ref().len(),
            )?;
        }
        let coefficients: Vec<f64> = grid.cell_size.iter().map(|&h| 1.0 / (h * h)).collect();

        let mut cell_to_unknown = vec![None; cells];
        let mut unknown_to_cell = Vec::new();
        for (cell, flag) in liquid.iter().enumerate() {
            if flag.weight() > 0.5 {
                cell_to_unknown[cell] = Some(unknown_to_cell.len());
                unknown_to_cell.push(cell);
            }
        }
        let n = unknown_to_cell.len();

        let Rows {
            row_ptr,
            col_indices,
            mut values,
            diagonal_at,
            anchored,
        } = match d {
            1 => assemble_rows::<1, W, F>(grid, face_open, &coefficients, &cell_to_unknown, n),
            2 => assemble_rows::<2, W, F>(grid, face_open, &coefficients, &cell_to_unknown, n),
            3 => assemble_rows::<3, W, F>(grid, face_open, &coefficients, &cell_to_unknown, n),
            _ => unreachable!("checked: one to three axes"),
        };

        // Regions, numbered in order of their first unknown: a flood fill from each unknown not yet
        // reached, over the matrix's off-diagonal entries (exactly the open faces between unknowns).
        let mut region_of = vec![usize::MAX; n];
        let mut region_anchored = Vec::new();
        let mut region_first = Vec::new();
        let mut pending = Vec::new();
        for first in 0..n {
            if region_of[first] != usize::MAX {
                continue;
            }
            let region = region_anchored.len();
            let mut is_anchored = false;
            region_of[first] = region;
            pending.push(first);
            while let Some(u) = pending.pop() {
                is_anchored |= anchored[u];
                for &v in &col_indices[row_ptr[u]..row_ptr[u + 1]] {
                    if region_of[v] == usize::MAX {
                        region_of[v] = region;
                        pending.push(v);
                    }
                }
            }
            region_anchored.push(is_anchored);
            region_first.push(first);
        }
        let pin = coefficients.iter().copied().fold(0.0, f64::max);
        let mut pinned = Vec::new();
        for (region, &is_anchored) in region_anchored.iter().enumerate() {
            if !is_anchored {
                let u = region_first[region];
                pinned.push(u);
                values[diagonal_at[u]] += pin;
            }
        }
        let mut matrix = SparseMatrix::from_assembled_csr(n, n, row_ptr, col_indices, values)?
            .assume_symmetric();
        if d <= 2 {
            // Eliminate in the grid's AMD order restricted to the liquid cells: in 2D its fill stays
            // within 1.25× of an AMD analysis of this matrix (measured 1.14–1.17× on pools), and it
            // saves that analysis, which costs as much as factorising a matrix used once. 3D keeps
            // the per-matrix AMD (the restricted order filled 1.7× more at 16³; 3D uses CG by
            // default anyway).
            let order: Vec<usize> = grid_elimination_order(resolution)
                .iter()
                .filter_map(|&cell| cell_to_unknown[cell as usize])
                .collect();
            matrix = matrix.with_ordering(order)?;
        }
        Ok(PoissonSystem {
            matrix: Arc::new(matrix),
            cell_to_unknown,
            unknown_to_cell,
            pinned,
            region_of,
            region_is_singular: region_anchored.iter().map(|&a| !a).collect(),
        })
    }
}

/// The CSR rows of the Poisson matrix (before pinning), the position of each row's diagonal
/// entry, and whether each unknown reaches air or an open side.
struct Rows {
    row_ptr: Vec<usize>,
    col_indices: Vec<usize>,
    values: Vec<f64>,
    diagonal_at: Vec<usize>,
    anchored: Vec<bool>,
}

/// The rows of [`PoissonSystem::assemble`] on a `D`-dimensional grid, assembled in column order: unknowns
/// are numbered in row-major cell order, so a row's columns increase as lower neighbours from
/// axis 0 to D−1 (strides decreasing), the diagonal, then upper neighbours from axis D−1 to 0.
/// The diagonal sums its face terms axis by axis, lower face before upper.
fn assemble_rows<const D: usize, W: Weight, F: AsRef<[W]>>(
    grid: &PoissonGrid<'_>,
    face_open: &[F],
    coefficients: &[f64],
    cell_to_unknown: &[Option<usize>],
    n: usize,
) -> Rows {
    let resolution: [usize; D] = std::array::from_fn(|axis| grid.resolution[axis]);
    let row_major = |shape: [usize; D]| -> [usize; D] {
        let strides = strides(&shape);
        std::array::from_fn(|axis| strides[axis])
    };
    let cell_strides = row_major(resolution);
    // The faces of `axis` lie on the cells' grid with one more layer along `axis`; the lower
    // face of a cell along `axis` has the cell's own multi-index there.
    let face_strides: [[usize; D]; D] = std::array::from_fn(|axis| {
        let mut shape = resolution;
        shape[axis] += 1;
        row_major(shape)
    });
    let faces: [&[W]; D] = std::array::from_fn(|axis| face_open[axis].as_ref());
    let open_side: [[bool; 2]; D] = std::array::from_fn(|axis| grid.open_sides[axis]);
    let coefficients: [f64; D] = std::array::from_fn(|axis| coefficients[axis]);

    let mut rows = Rows {
        row_ptr: Vec::with_capacity(n + 1),
        col_indices: Vec::with_capacity(n * (2 * D + 1)),
        values: Vec::with_capacity(n * (2 * D + 1)),
        diagonal_at: Vec::with_capacity(n),
        anchored: vec![false; n],
    };
    rows.row_ptr.push(0);
    let mut index = [0usize; D];
    for (cell, &unknown) in cell_to_unknown.iter().enumerate() {
        if cell > 0 {
            // Advance the multi-index (row-major).
            let mut axis = D - 1;
            loop {
                index[axis] += 1;
                if index[axis] < resolution[axis] || axis == 0 {
                    break;
                }
                index[axis] = 0;
                axis -= 1;
            }
        }
        let Some(u) = unknown else {
            continue;
        };
        let mut diagonal = 0.0;
        let mut anchored = false;
        // Per axis, the off-diagonal entries towards the lower and the upper neighbour.
        let mut lower: [Option<(usize, f64)>; D] = [None; D];
        let mut upper: [Option<(usize, f64)>; D] = [None; D];
        for axis in 0..D {
            let face: usize = (0..D).map(|b| index[b] * face_strides[axis][b]).sum();
            for is_upper in [false, true] {
                let (face, at_side) = if is_upper {
                    (
                        face + face_strides[axis][axis],
                        index[axis] + 1 == resolution[axis],
                    )
                } else {
                    (face, index[axis] == 0)
                };
                let w = faces[axis][face].weight();
                if w <= 0.0 {
                    continue;
                }
                let coefficient = w * coefficients[axis];
                if at_side {
                    if open_side[axis][usize::from(is_upper)] {
                        diagonal += coefficient;
                        anchored = true;
                    }
                    continue;
                }
                let neighbour = if is_upper {
                    cell + cell_strides[axis]
                } else {
                    cell - cell_strides[axis]
                };
                diagonal += coefficient;
                match cell_to_unknown[neighbour] {
                    Some(v) if is_upper => upper[axis] = Some((v, -coefficient)),
                    Some(v) => lower[axis] = Some((v, -coefficient)),
                    None => anchored = true,
                }
            }
        }
        rows.anchored[u] = anchored;
        for &(v, value) in lower.iter().flatten() {
            rows.col_indices.push(v);
            rows.values.push(value);
        }
        rows.diagonal_at.push(rows.values.len());
        rows.col_indices.push(u);
        rows.values.push(diagonal);
        for &(v, value) in upper.iter().rev().flatten() {
            rows.col_indices.push(v);
            rows.values.push(value);
        }
        rows.row_ptr.push(rows.col_indices.len());
    }
    rows
}

/// A fill-reducing elimination order of the cells of a grid of `resolution` (row-major cell
/// indices): faer's approximate minimum degree (AMD) ordering of the grid's `2d + 1`-point
/// stencil, computed once per resolution and cached. Restricted to the liquid cells of a step it
/// orders that step's Poisson matrix nearly as well as an AMD analysis of the matrix itself,
/// which for a matrix used once costs as much as its factorization.
pub fn grid_elimination_order(resolution: &[usize]) -> Arc<[u32]> {
    type OrderCache = Mutex<HashMap<Vec<usize>, Arc<[u32]>>>;
    static CACHE: OnceLock<OrderCache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(order) = cache.lock().ok().and_then(|c| c.get(resolution).cloned()) {
        return order;
    }
    let order: Arc<[u32]> = stencil_amd(resolution).into();
    if let Ok(mut c) = cache.lock() {
        c.insert(resolution.to_vec(), order.clone());
    }
    order
}

/// AMD of the full pattern of the grid's `2d + 1`-point stencil.
fn stencil_amd(resolution: &[usize]) -> Vec<u32> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::sparse::SymbolicSparseColMatRef;
    use faer::sparse::linalg::amd;

    let cells: usize = resolution.iter().product();
    let strides = strides(resolution);
    let mut col_ptr = Vec::with_capacity(cells + 1);
    let mut row_idx = Vec::with_capacity(cells * (2 * resolution.len() + 1));
    col_ptr.push(0);
    let mut index = vec![0usize; resolution.len()];
    for cell in 0..cells {
        let mut rest = cell;
        for (axis, &stride) in strides.iter().enumerate() {
            index[axis] = rest / stride;
            rest %= stride;
        }
        // Sorted: lower neighbours (largest stride first), the cell, upper neighbours.
        for (axis, &stride) in strides.iter().enumerate() {
            if index[axis] > 0 {
                row_idx.push(cell - stride);
            }
        }
        row_idx.push(cell);
        for (axis, &stride) in strides.iter().enumerate().rev() {
            if index[axis] + 1 < resolution[axis] {
                row_idx.push(cell + stride);
            }
        }
        col_ptr.push(row_idx.len());
    }
    let pattern = SymbolicSparseColMatRef::new_checked(cells, cells, &col_ptr, None, &row_idx);
    let mut perm = vec![0usize; cells];
    let mut perm_inv = vec![0usize; cells];
    let mut scratch = MemBuffer::new(amd::order_scratch::<usize>(cells, row_idx.len()));
    let ordered = amd::order(
        &mut perm,
        &mut perm_inv,
        pattern,
        amd::Control::default(),
        MemStack::new(&mut scratch),
    );
    match ordered {
        Ok(_) => perm.into_iter().map(|c| c as u32).collect(),
        // Only an index overflow can fail: fall back to the natural order.
        Err(_) => (0..cells as u32).collect(),
    }
}
