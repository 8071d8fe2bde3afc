//! Sparse matrices of 3x3 blocks over the lattice nodes (Jacobians, stiffness).

use crate::{Mat3, Vec3};

/// A square sparse matrix of 3x3 blocks in compressed-row form: block row `i`
/// holds the blocks `(i, col_indices[k])` for `k in row_offsets[i]..row_offsets[i+1]`,
/// columns sorted ascending. The pattern of a lattice matrix couples every pair
/// of nodes that share a cell.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockCsr {
    /// Start of each block row in `col_indices` / `blocks`; length rows + 1.
    pub row_offsets: Vec<u32>,
    /// Block column of each stored block, sorted within a row.
    pub col_indices: Vec<u32>,
    /// The stored 3x3 blocks.
    pub blocks: Vec<Mat3>,
}

impl BlockCsr {
    /// The zero matrix with the pattern "nodes that share a cell" of `cells`
    /// over `num_nodes` nodes (the diagonal is always present); a cell is
    /// any fixed number of nodes (8 for a hexahedron).
    pub fn lattice_pattern<const N: usize>(num_nodes: usize, cells: &[[u32; N]]) -> Self {
        let (row_offsets, col_indices) = Self::lattice_pattern_indices(num_nodes, cells);
        let blocks = vec![Mat3::zeros(); col_indices.len()];
        Self {
            row_offsets,
            col_indices,
            blocks,
        }
    }

    /// The row offsets and column indices of [`BlockCsr::lattice_pattern`],
    /// without its blocks (72 bytes per block, which callers that keep only
    /// the pattern used to allocate and zero).
    pub fn lattice_pattern_indices<const N: usize>(
        num_nodes: usize,
        cells: &[[u32; N]],
    ) -> (Vec<u32>, Vec<u32>) {
        use rayon::prelude::*;
        // Cells of each node (counting sort), then each row on its own: a
        // few dozen candidates sorted in cache, rather than one sort of
        // 64 pairs per cell.
        let mut cell_offsets = vec![0u32; num_nodes + 1];
        for cell in cells {
            for &a in cell {
                cell_offsets[a as usize + 1] += 1;
            }
        }
        for i in 0..num_nodes {
            cell_offsets[i + 1] += cell_offsets[i];
        }
        let mut fill = cell_offsets.clone();
        let mut node_cells = vec![0u32; cell_offsets[num_nodes] as usize];
        for (c, cell) in cells.iter().enumerate() {
            for &a in cell {
                node_cells[fill[a as usize] as usize] = c as u32;
                fill[a as usize] += 1;
            }
        }
        const ROWS_PER_TASK: usize = 1024;
        let parts: Vec<(Vec<u32>, Vec<u32>)> = (0..num_nodes.div_ceil(ROWS_PER_TASK))
            .into_par_iter()
            .map(|t| {
                let rows = t * ROWS_PER_TASK..((t + 1) * ROWS_PER_TASK).min(num_nodes);
                let mut lengths = Vec::with_capacity(rows.len());
                let mut cols = Vec::with_capacity(27 * rows.len());
                let mut row = Vec::with_capacity(64);
                for r in rows {
                    row.clear();
                    row.push(r as u32);
                    let span = cell_offsets[r] as usize..cell_offsets[r + 1] as usize;
                    for &c in &node_cells[span] {
                        row.extend_from_slice(&cells[c as usize]);
                    }
                    row.sort_unstable();
                    row.dedup();
                    lengths.push(row.len() as u32);
                    cols.extend_from_slice(&row);
                }
                (lengths, cols)
            })
            .collect();
        let mut row_offsets = Vec::with_capacity(num_nodes + 1);
        row_offsets.push(0u32);
        let mut col_indices = Vec::with_capacity(parts.iter().map(|p| p.1.len()).sum());
        for (lengths, cols) in parts {
            for l in lengths {
                row_offsets.push(row_offsets[row_offsets.len() - 1] + l);
            }
            col_indices.extend_from_slice(&cols);
        }
        (row_offsets, col_indices)
    }

    /// Number of block rows (= nodes).
    pub fn num_rows(&self) -> usize {
        self.row_offsets.len() - 1
    }

    /// Position of block `(row, col)` in `blocks`, if it is in the pattern.
    pub fn find(&self, row: usize, col: usize) -> Option<usize> {
        let lo = self.row_offsets[row] as usize;
        let hi = self.row_offsets[row + 1] as usize;
        self.col_indices[lo..hi]
            .binary_search(&(col as u32))
            .ok()
            .map(|k| lo + k)
    }

    /// Grows the pattern by the positions `extra` (`(row, col)`, in any
    /// order, repeats allowed), keeping every stored block; zero blocks at
    /// the new positions. Contact between bodies couples nodes that share
    /// no cell.
    pub fn extend_pattern(&mut self, extra: &[(u32, u32)]) {
        let mut missing: Vec<(u32, u32)> = extra
            .iter()
            .copied()
            .filter(|&(r, c)| self.find(r as usize, c as usize).is_none())
            .collect();
        if missing.is_empty() {
            return;
        }
        missing.sort_unstable();
        missing.dedup();
        let n = self.num_rows();
        let mut offsets = Vec::with_capacity(n + 1);
        let mut cols = Vec::with_capacity(self.col_indices.len() + missing.len());
        let mut blocks = Vec::with_capacity(cols.capacity());
        offsets.push(0u32);
        let mut m = 0;
        for r in 0..n {
            let lo = self.row_offsets[r] as usize;
            let hi = self.row_offsets[r + 1] as usize;
            let mut k = lo;
            // Merge the row's stored columns with its new ones.
            while k < hi || (m < missing.len() && missing[m].0 as usize == r) {
                let new = (m < missing.len() && missing[m].0 as usize == r).then(|| missing[m].1);
                match new {
                    Some(c) if k >= hi || c < self.col_indices[k] => {
                        cols.push(c);
                        blocks.push(Mat3::zeros());
                        m += 1;
                    }
                    _ => {
                        cols.push(self.col_indices[k]);
                        blocks.push(self.blocks[k]);
                        k += 1;
                    }
                }
            }
            offsets.push(cols.len() as u32);
        }
        self.row_offsets = offsets;
        self.col_indices = cols;
        self.blocks = blocks;
    }

    /// Adds `block` at `(row, col)`; panics if the position is not in the
    /// pattern, which would be a bug in the caller's assembly.
    pub fn add(&mut self, row: usize, col: usize, block: &Mat3) {
        let k = self
            .find(row, col)
            .expect("block outside the sparsity pattern");
        self.blocks[k] += block;
    }

    /// `y = A x`.
    pub fn mul_vec(&self, x: &[Vec3], y: &mut [Vec3]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let lo = self.row_offsets[i] as usize;
            let hi = self.row_offsets[i + 1] as usize;
            let mut acc = Vec3::zeros();
            for k in lo..hi {
                acc += self.blocks[k] * x[self.col_indices[k] as usize];
            }
            *yi = acc;
        }
    }

    /// Largest absolute difference between `A` and its transpose (0 for a
    /// symmetric matrix).
    pub fn asymmetry(&self) -> f64 {
        use rayon::prelude::*;
        // Each pair once (the block on or above the diagonal against its
        // mirror; a block whose mirror is missing against zero, from either
        // side), rows in parallel: a maximum does not depend on the order.
        (0..self.num_rows())
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let mut worst = 0.0f64;
                for k in self.row_offsets[i] as usize..self.row_offsets[i + 1] as usize {
                    let j = self.col_indices[k] as usize;
                    match self.find(j, i) {
                        Some(kt) if j >= i => {
                            let d = self.blocks[k] - self.blocks[kt].transpose();
                            worst = worst.max(d.abs().max());
                        }
                        Some(_) => {}
                        None => worst = worst.max(self.blocks[k].abs().max()),
                    }
                }
                worst
            })
            .reduce(|| 0.0, f64::max)
    }
}

/// Why a sparse linear solve failed.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum LinearSolveError {
    /// The matrix restricted to the free dofs is singular: typically the
    /// constraints leave mechanisms (rigid motions or hourglass modes) free.
    #[error(
        "the system matrix is singular on the free degrees of freedom ({detail}): constraints probably leave rigid or hourglass mechanisms; fix more nodes (e.g. a whole face)"
    )]
    Singular {
        /// What detected it.
        detail: String,
    },
    /// The Cholesky factorization met a non-positive pivot.
    #[error(
        "the system matrix is not positive definite on the free degrees of freedom (non-positive pivot at free dof {index}); use the general (LU) solve, or the constraints leave mechanisms"
    )]
    NotPositiveDefinite {
        /// Free-dof index where the factorization stopped.
        index: usize,
    },
    /// Vector lengths do not match the matrix.
    #[error("{what} has {given} entries, the matrix has {rows} block rows")]
    Shape {
        /// Which argument.
        what: &'static str,
        /// Entries given.
        given: usize,
        /// Block rows of the matrix.
        rows: usize,
    },
    /// Every dof is fixed or the matrix is empty: nothing to solve.
    #[error("no free degree of freedom")]
    NoFreeDof,
    /// Internal failure of the sparse library (out of memory, index overflow).
    #[error("sparse factorization failed: {0}")]
    Library(String),
}

/// Numbering of the free degrees of freedom (3 per node, dof `3 node + d`)
/// of a constrained system: free dofs are numbered in dof order. The one
/// numbering that every solve restricted to free dofs uses (direct solves,
/// Newton, the FEM reference).
///
/// ```
/// use mss_core::sparse::DofMap;
/// let map = DofMap::new(&[[true, false, false], [false, true, false]]);
/// assert_eq!(map.num_free(), 4);
/// assert_eq!(map.free_index(0), None);
/// assert_eq!(map.free_index(1), Some(0));
/// assert_eq!(map.free_index(4), None);
/// assert_eq!(map.free_index(5), Some(3));
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DofMap {
    /// Free index of each dof `3 node + d`, or `u32::MAX` if fixed.
    index: Vec<u32>,
    free: usize,
}

impl DofMap {
    /// The numbering of the dofs not held in `fixed` (per node, per axis).
    pub fn new(fixed: &[[bool; 3]]) -> Self {
        Self::from_free_flags(fixed.iter().flatten().map(|&f| !f))
    }

    /// The numbering of the dofs whose flag is true (`free[3 node + d]`).
    pub fn from_free(free: &[bool]) -> Self {
        Self::from_free_flags(free.iter().copied())
    }

    fn from_free_flags(flags: impl Iterator<Item = bool>) -> Self {
        let mut free = 0usize;
        let index = flags
            .map(|f| {
                if f {
                    free += 1;
                    (free - 1) as u32
                } else {
                    u32::MAX
                }
            })
            .collect();
        Self { index, free }
    }

    /// Number of free dofs.
    pub fn num_free(&self) -> usize {
        self.free
    }

    /// Number of dofs in all (3 per node).
    pub fn num_dofs(&self) -> usize {
        self.index.len()
    }

    /// The free index of dof `dof` (`3 node + d`), or `None` if it is held.
    pub fn free_index(&self, dof: usize) -> Option<usize> {
        match self.index[dof] {
            u32::MAX => None,
            i => Some(i as usize),
        }
    }

    /// `(dof, free index)` of every free dof, in order.
    pub fn free_dofs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.index
            .iter()
            .enumerate()
            .filter(|(_, i)| **i != u32::MAX)
            .map(|(d, &i)| (d, i as usize))
    }
}

/// A factorization of a [`BlockCsr`] restricted to its free dofs, reusable for
/// several right-hand sides (e.g. within a Newton step).
pub struct Factorization {
    map: DofMap,
    kind: FactorKind,
    /// The restricted matrix, kept for the residual check.
    matrix: faer::sparse::SparseColMat<u32, f64>,
}

enum FactorKind {
    Lu(Box<faer::sparse::linalg::solvers::Lu<u32, f64>>),
    Llt(faer::sparse::linalg::solvers::Llt<u32, f64>),
}

impl std::fmt::Debug for Factorization {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Factorization")
            .field("free_dofs", &self.map.free)
            .field(
                "kind",
                &match self.kind {
                    FactorKind::Lu(_) => "LU",
                    FactorKind::Llt(_) => "Cholesky",
                },
            )
            .finish()
    }
}

impl Factorization {
    /// Number of free dofs.
    pub fn num_free_dofs(&self) -> usize {
        self.map.free
    }

    /// Solves `A X = B` for several right-hand sides given directly in the free-dof
    /// numbering (the order of [`BlockCsr::to_faer_free`]), without residual check.
    pub fn solve_free(&self, rhs: faer::MatRef<'_, f64>) -> faer::Mat<f64> {
        use faer::linalg::solvers::Solve;
        match &self.kind {
            FactorKind::Lu(lu) => lu.solve(rhs),
            FactorKind::Llt(llt) => llt.solve(rhs),
        }
    }

    /// Solves `A u = rhs` on the free dofs; `u` is 0 on the fixed dofs and the
    /// fixed dofs' entries of `rhs` are ignored.
    pub fn solve(&self, rhs: &[Vec3]) -> Result<Vec<Vec3>, LinearSolveError> {
        use faer::linalg::solvers::Solve;
        let rows = self.map.index.len() / 3;
        if rhs.len() != rows {
            return Err(LinearSolveError::Shape {
                what: "right-hand side",
                given: rhs.len(),
                rows,
            });
        }
        let mut b = faer::Mat::<f64>::zeros(self.map.free, 1);
        for (dof, &fi) in self.map.index.iter().enumerate() {
            if fi != u32::MAX {
                b[(fi as usize, 0)] = rhs[dof / 3][dof % 3];
            }
        }
        let x = match &self.kind {
            FactorKind::Lu(lu) => lu.solve(&b),
            FactorKind::Llt(llt) => llt.solve(&b),
        };
        // Backward-stable solves of a singular system give residuals of the
        // order of the right-hand side: check it.
        let ax = &self.matrix * &x;
        let mut r2 = 0.0;
        let mut b2 = 0.0;
        let mut finite = true;
        for i in 0..self.map.free {
            finite &= x[(i, 0)].is_finite();
            r2 += (ax[(i, 0)] - b[(i, 0)]).powi(2);
            b2 += b[(i, 0)].powi(2);
        }
        if !finite {
            return Err(LinearSolveError::Singular {
                detail: "non-finite solution".into(),
            });
        }
        if r2.sqrt() > 1e-6 * b2.sqrt() {
            return Err(LinearSolveError::Singular {
                detail: format!("relative residual {:.2e}", (r2 / b2).sqrt()),
            });
        }
        let mut out = vec![Vec3::zeros(); rows];
        for (dof, &fi) in self.map.index.iter().enumerate() {
            if fi != u32::MAX {
                out[dof / 3][dof % 3] = x[(fi as usize, 0)];
            }
        }
        Ok(out)
    }
}

fn node_mask(fixed: &[bool]) -> Vec<[bool; 3]> {
    fixed.iter().map(|&f| [f; 3]).collect()
}

impl BlockCsr {
    /// Adds `s` to every diagonal entry (all blocks `(i, i)` are in the pattern
    /// of [`BlockCsr::lattice_pattern`]); panics if a diagonal block is missing.
    pub fn add_diagonal(&mut self, s: f64) {
        for i in 0..self.num_rows() {
            let k = self.find(i, i).expect("diagonal block in the pattern");
            for d in 0..3 {
                self.blocks[k][(d, d)] += s;
            }
        }
    }

    /// Largest absolute diagonal entry.
    pub fn max_diagonal(&self) -> f64 {
        (0..self.num_rows())
            .filter_map(|i| self.find(i, i))
            .map(|k| {
                (0..3)
                    .map(|d| self.blocks[k][(d, d)].abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
    }

    /// Number of stored scalar entries (9 per block).
    pub fn nnz(&self) -> usize {
        9 * self.blocks.len()
    }

    /// The scalar matrix (3 dofs per node, dof `3 node + d`) restricted to the
    /// free dofs (`fixed[node][d] == false`), in faer's compressed-column form.
    /// With `lower_only`, only entries with row >= column are kept.
    pub fn to_faer_free(
        &self,
        fixed: &[[bool; 3]],
        lower_only: bool,
    ) -> Result<faer::sparse::SparseColMat<u32, f64>, LinearSolveError> {
        let map = self.check(fixed)?;
        self.restricted(&map, lower_only)
    }

    /// The whole scalar matrix (3 dofs per node) in faer's compressed-column form.
    pub fn to_faer(&self) -> Result<faer::sparse::SparseColMat<u32, f64>, LinearSolveError> {
        self.to_faer_free(&vec![[false; 3]; self.num_rows()], false)
    }

    fn check(&self, fixed: &[[bool; 3]]) -> Result<DofMap, LinearSolveError> {
        if fixed.len() != self.num_rows() {
            return Err(LinearSolveError::Shape {
                what: "fixed mask",
                given: fixed.len(),
                rows: self.num_rows(),
            });
        }
        let map = DofMap::new(fixed);
        if map.free == 0 {
            return Err(LinearSolveError::NoFreeDof);
        }
        Ok(map)
    }

    fn restricted(
        &self,
        map: &DofMap,
        lower_only: bool,
    ) -> Result<faer::sparse::SparseColMat<u32, f64>, LinearSolveError> {
        use faer::sparse::Triplet;
        let mut trips = Vec::with_capacity(if lower_only { 5 } else { 9 } * self.blocks.len());
        for i in 0..self.num_rows() {
            for k in self.row_offsets[i] as usize..self.row_offsets[i + 1] as usize {
                let j = self.col_indices[k] as usize;
                let b = &self.blocks[k];
                for e in 0..3 {
                    let r = map.index[3 * i + e];
                    if r == u32::MAX {
                        continue;
                    }
                    for d in 0..3 {
                        let c = map.index[3 * j + d];
                        if c == u32::MAX || (lower_only && r < c) {
                            continue;
                        }
                        trips.push(Triplet::new(r, c, b[(e, d)]));
                    }
                }
            }
        }
        faer::sparse::SparseColMat::try_new_from_triplets(map.free, map.free, &trips)
            .map_err(|e| LinearSolveError::Library(format!("{e:?}")))
    }

    /// LU factorization (partial pivoting; for general, possibly non-symmetric
    /// matrices) restricted to the free dofs.
    pub fn factor_lu(&self, fixed: &[[bool; 3]]) -> Result<Factorization, LinearSolveError> {
        sequential_factorizations();
        let map = self.check(fixed)?;
        let matrix = self.restricted(&map, false)?;
        let lu = matrix.sp_lu().map_err(|e| match e {
            faer::sparse::linalg::LuError::SymbolicSingular { index } => {
                LinearSolveError::Singular {
                    detail: format!("structurally singular at free dof {index}"),
                }
            }
            other => LinearSolveError::Library(format!("{other:?}")),
        })?;
        Ok(Factorization {
            map,
            kind: FactorKind::Lu(Box::new(lu)),
            matrix,
        })
    }

    /// Memory (bytes) that the values of a sparse Cholesky factor of the matrix
    /// restricted to the free dofs would take (symbolic analysis only): check it
    /// before factoring large 3D systems, whose fill-in grows fast.
    pub fn cholesky_factor_bytes(&self, fixed: &[[bool; 3]]) -> Result<usize, LinearSolveError> {
        let map = self.check(fixed)?;
        let lower = self.restricted(&map, true)?;
        let sym = faer::sparse::linalg::cholesky::factorize_symbolic_cholesky(
            lower.symbolic(),
            faer::Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| LinearSolveError::Library(format!("{e:?}")))?;
        Ok(sym.len_val() * std::mem::size_of::<f64>())
    }

    /// Cholesky factorization restricted to the free dofs, for a symmetric
    /// positive definite matrix (only the lower triangle is read).
    pub fn factor_cholesky(&self, fixed: &[[bool; 3]]) -> Result<Factorization, LinearSolveError> {
        sequential_factorizations();
        let map = self.check(fixed)?;
        let lower = self.restricted(&map, true)?;
        let llt = lower.sp_cholesky(faer::Side::Lower).map_err(|e| match e {
            faer::sparse::linalg::LltError::Numeric(
                faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index },
            ) => LinearSolveError::NotPositiveDefinite { index },
            other => LinearSolveError::Library(format!("{other:?}")),
        })?;
        // The residual check needs the full matrix.
        let matrix = self.restricted(&map, false)?;
        Ok(Factorization {
            map,
            kind: FactorKind::Llt(llt),
            matrix,
        })
    }

    /// Solves `A u = rhs` with whole nodes fixed (`u = 0` there) by sparse LU.
    pub fn solve(&self, rhs: &[Vec3], fixed: &[bool]) -> Result<Vec<Vec3>, LinearSolveError> {
        self.solve_dofs(rhs, &node_mask(fixed))
    }

    /// Solves `A u = rhs` with individual dofs fixed (`u = 0` there, e.g.
    /// rollers) by sparse LU.
    pub fn solve_dofs(
        &self,
        rhs: &[Vec3],
        fixed: &[[bool; 3]],
    ) -> Result<Vec<Vec3>, LinearSolveError> {
        self.factor_lu(fixed)?.solve(rhs)
    }

    /// Solves `A u = rhs` with whole nodes fixed, for a symmetric positive
    /// definite `A` (e.g. a rest stiffness), by sparse Cholesky.
    pub fn solve_symmetric(
        &self,
        rhs: &[Vec3],
        fixed: &[bool],
    ) -> Result<Vec<Vec3>, LinearSolveError> {
        self.solve_symmetric_dofs(rhs, &node_mask(fixed))
    }

    /// Solves `A u = rhs` with individual dofs fixed, for a symmetric positive
    /// definite `A`, by sparse Cholesky.
    pub fn solve_symmetric_dofs(
        &self,
        rhs: &[Vec3],
        fixed: &[[bool; 3]],
    ) -> Result<Vec<Vec3>, LinearSolveError> {
        self.factor_cholesky(fixed)?.solve(rhs)
    }
}

/// Makes faer's factorizations and solves run sequentially.
///
/// faer splits dense kernels by the number of rayon threads, which changes the
/// order of floating-point sums: static and implicit results would then depend
/// on the thread count. Our own parallel parts (force and tangent assembly)
/// are deterministic, so only faer needs pinning. This is process-wide, which
/// is what a simulator wants; a caller that needs faer in parallel elsewhere
/// can set it back after our solves.
pub fn sequential_factorizations() {
    faer::set_global_parallelism(faer::Par::Seq);
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// The symmetric part stored once per pair of blocks multiplies as the
    /// full `(K + K^T) / 2` of a non-symmetric tangent (the paper model's,
    /// deformed), to round-off, with the same bits on any thread count.
    #[test]
    fn symmetric_upper_half_multiplies_as_the_symmetric_part() {
        let l = hexmesh::Lattice::block([5, 4, 3], 0.1, [0.0; 3]).unwrap();
        let model = crate::Model::new(
            &l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::PaperModel,
        )
        .unwrap();
        let wave = |i: usize, k: usize| 0.02 * ((i * 7 + k * 3) as f64).sin();
        let x: Vec<Vec3> = model
            .rest_positions()
            .iter()
            .enumerate()
            .map(|(i, p)| p + Vec3::new(wave(i, 0), wave(i, 1), wave(i, 2)))
            .collect();
        let k = model.stiffness(&x);
        let v: Vec<Vec3> = (0..x.len())
            .map(|i| Vec3::new(wave(i, 5), wave(i, 6), wave(i, 7)))
            .collect();
        let mut kv = vec![Vec3::zeros(); v.len()];
        let mut ktv = vec![Vec3::zeros(); v.len()];
        for i in 0..k.num_rows() {
            for p in k.row_offsets[i] as usize..k.row_offsets[i + 1] as usize {
                let j = k.col_indices[p] as usize;
                kv[i] += k.blocks[p] * v[j];
                ktv[j] += k.blocks[p].transpose() * v[i];
            }
        }
        let asymmetry = kv
            .iter()
            .zip(&ktv)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        let scale = kv.iter().map(|a| a.norm()).fold(0.0, f64::max);
        assert!(
            asymmetry > 1e-6 * scale,
            "the test needs a non-symmetric tangent"
        );
        let upper = model.symmetric_stiffness_upper(&x);
        assert!(!upper.of_a_symmetric_matrix());
        // At rest, and for a conservative model anywhere, the tangent is
        // symmetric, and the half says so.
        assert!(
            model
                .symmetric_stiffness_upper(model.rest_positions())
                .of_a_symmetric_matrix()
        );
        let springs = crate::Model::new(
            &l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::SpringsOnly,
        )
        .unwrap();
        assert!(
            springs
                .symmetric_stiffness_upper(&x)
                .of_a_symmetric_matrix()
        );
        let run = |threads: usize| {
            let mut out = vec![Vec3::zeros(); v.len()];
            crate::on_threads(threads, || upper.mul(&v, &mut out));
            out
        };
        let one = run(1);
        assert_eq!(one, run(3));
        for ((o, a), b) in one.iter().zip(&kv).zip(&ktv) {
            assert!(
                (o - (a + b) * 0.5).norm() <= 1e-12 * scale,
                "{o} vs {}",
                (a + b) * 0.5
            );
        }
    }

    /// The pattern is exactly "the diagonal and every pair of nodes that
    /// share a cell", rows sorted, on cells scattered over more rows than one
    /// task takes (and nodes in no cell).
    #[test]
    fn lattice_pattern_couples_exactly_the_nodes_of_shared_cells() {
        let num_nodes = 3000;
        let mut seed = 11u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((seed >> 33) % (num_nodes as u64 - 100)) as u32
        };
        let cells: Vec<[u32; 8]> = (0..700)
            .map(|_| {
                let base = next();
                std::array::from_fn(|k| base + [0, 1, 3, 7, 20, 41, 64, 99][k])
            })
            .collect();
        let m = BlockCsr::lattice_pattern(num_nodes, &cells);
        let mut rows = vec![BTreeSet::new(); num_nodes];
        for (i, r) in rows.iter_mut().enumerate() {
            r.insert(i as u32);
        }
        for cell in &cells {
            for &a in cell {
                rows[a as usize].extend(cell.iter().copied());
            }
        }
        assert_eq!(m.num_rows(), num_nodes);
        for (i, r) in rows.iter().enumerate() {
            let lo = m.row_offsets[i] as usize;
            let hi = m.row_offsets[i + 1] as usize;
            let expected: Vec<u32> = r.iter().copied().collect();
            assert_eq!(&m.col_indices[lo..hi], &expected[..], "row {i}");
        }
        assert_eq!(m.blocks.len(), m.col_indices.len());
    }
}

/// A symmetric block matrix stored once per pair of blocks: the blocks on and
/// above the diagonal (`upper`, column `>=` row in each row), with an index
/// of the blocks strictly above the diagonal by column, so that the product
/// gathers per row (in parallel, each row summed in a fixed order: the same
/// bits for any thread count) without a transposed copy. Half the `f64`
/// blocks of the full matrix: the static solver's stability test holds one
/// beside its preconditioner at its memory peak, and the multigrid of a large
/// solve builds its levels from one without a full matrix ever being held
/// ([`crate::solver::NonlinearSystem::symmetric_stiffness`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SymmetricUpper {
    /// Row offsets, columns and blocks of the upper half.
    pub upper: BlockCsr,
    /// Whether the matrix this is the symmetric part of was itself
    /// symmetric (to round-off) as far as its assembly could tell: false
    /// when some summed part had a skew part.
    pub(crate) from_symmetric: bool,
    /// Start of each column's entries in `by_column`; length rows + 1.
    column_offsets: Vec<u32>,
    /// For each column `j`, the blocks `k` (indices into `upper`) strictly
    /// above the diagonal in that column, with their rows, by row.
    by_column: Vec<(u32, u32)>,
}

impl SymmetricUpper {
    /// The zero matrix on the upper half of `full`'s pattern (which must hold
    /// the diagonal; a block whose mirror it lacks has its place above the
    /// diagonal all the same).
    pub(crate) fn upper_pattern_of(full_rows: &[u32], full_cols: &[u32]) -> Self {
        let mut m = Self::upper_pattern_only(full_rows, full_cols);
        m.upper.blocks = vec![Mat3::zeros(); m.upper.col_indices.len()];
        m
    }

    /// The upper half of `full`'s pattern with its by-column index and no
    /// blocks (`upper.blocks` empty): the structure of a matrix whose blocks
    /// are kept elsewhere (in single precision, by the multigrid's levels).
    pub(crate) fn upper_pattern_only(full_rows: &[u32], full_cols: &[u32]) -> Self {
        let n = full_rows.len() - 1;
        // Each block `(i, j)` as the upper block `(min, max)`: a block whose
        // mirror the pattern lacks (contact can add one side) is kept too.
        let upper_of = |i: usize, j: u32| {
            if j as usize >= i {
                (i, j)
            } else {
                (j as usize, i as u32)
            }
        };
        let rows_of = |i: usize| &full_cols[full_rows[i] as usize..full_rows[i + 1] as usize];
        let mut starts = vec![0usize; n + 1];
        for i in 0..n {
            for &j in rows_of(i) {
                starts[upper_of(i, j).0 + 1] += 1;
            }
        }
        for r in 0..n {
            starts[r + 1] += starts[r];
        }
        let mut gathered = vec![0u32; starts[n]];
        let mut next = starts.clone();
        for i in 0..n {
            for &j in rows_of(i) {
                let (r, c) = upper_of(i, j);
                gathered[next[r]] = c;
                next[r] += 1;
            }
        }
        let mut row_offsets = Vec::with_capacity(n + 1);
        let mut col_indices = Vec::with_capacity(full_cols.len() / 2 + n);
        row_offsets.push(0u32);
        let mut column_counts = vec![0u32; n + 1];
        for i in 0..n {
            let row = &mut gathered[starts[i]..starts[i + 1]];
            row.sort_unstable();
            let first = col_indices.len();
            for &j in row.iter() {
                if col_indices.len() == first || col_indices.last() != Some(&j) {
                    col_indices.push(j);
                    if j as usize > i {
                        column_counts[j as usize + 1] += 1;
                    }
                }
            }
            row_offsets.push(col_indices.len() as u32);
        }
        drop(gathered);
        for j in 0..n {
            column_counts[j + 1] += column_counts[j];
        }
        let column_offsets = column_counts;
        let mut next = column_offsets.clone();
        let mut by_column = vec![(0u32, 0u32); column_offsets[n] as usize];
        for i in 0..n {
            let row = row_offsets[i] as usize..row_offsets[i + 1] as usize;
            for (k, &j) in row.clone().zip(&col_indices[row]) {
                let j = j as usize;
                if j > i {
                    by_column[next[j] as usize] = (k as u32, i as u32);
                    next[j] += 1;
                }
            }
        }
        Self {
            upper: BlockCsr {
                row_offsets,
                col_indices,
                blocks: Vec::new(),
            },
            column_offsets,
            by_column,
            from_symmetric: true,
        }
    }

    /// Number of block rows.
    pub fn num_rows(&self) -> usize {
        self.upper.num_rows()
    }

    /// Whether the matrix this is the symmetric part of was itself symmetric
    /// (every part its assembly summed was, to round-off).
    pub fn of_a_symmetric_matrix(&self) -> bool {
        self.from_symmetric
    }

    /// The largest absolute entry of the diagonal blocks.
    pub fn max_diagonal_block_entry(&self) -> f64 {
        let a = &self.upper;
        (0..a.num_rows())
            .filter_map(|i| {
                let k = a.row_offsets[i] as usize;
                (k < a.row_offsets[i + 1] as usize && a.col_indices[k] as usize == i)
                    .then(|| a.blocks[k].abs().max())
            })
            .fold(0.0, f64::max)
    }

    /// The blocks strictly above the diagonal in column `j`, as (index into
    /// `upper`, row), by row: row `j`'s blocks below the diagonal are their
    /// transposes.
    pub(crate) fn column(&self, j: usize) -> &[(u32, u32)] {
        &self.by_column[self.column_range(j)]
    }

    /// Where column `j`'s entries are in the by-column index (the order of
    /// [`SymmetricUpper::by_column`]).
    pub(crate) fn column_range(&self, j: usize) -> std::ops::Range<usize> {
        self.column_offsets[j] as usize..self.column_offsets[j + 1] as usize
    }

    /// The whole by-column index: every column's [`SymmetricUpper::column`]
    /// one after the other.
    pub(crate) fn by_column(&self) -> &[(u32, u32)] {
        &self.by_column
    }

    /// The full pattern's rows and columns (both halves), in order.
    pub(crate) fn full_pattern(&self) -> (Vec<u32>, Vec<u32>) {
        let n = self.num_rows();
        let mut rows = Vec::with_capacity(n + 1);
        let mut cols = Vec::with_capacity(2 * self.upper.col_indices.len());
        rows.push(0u32);
        for i in 0..n {
            cols.extend(self.column(i).iter().map(|&(_, r)| r));
            let (lo, hi) = (
                self.upper.row_offsets[i] as usize,
                self.upper.row_offsets[i + 1] as usize,
            );
            cols.extend_from_slice(&self.upper.col_indices[lo..hi]);
            rows.push(cols.len() as u32);
        }
        (rows, cols)
    }

    /// `out = A v` (rows in parallel, each summed in a fixed order: the same
    /// bits for any thread count).
    pub fn mul(&self, v: &[Vec3], out: &mut [Vec3]) {
        use rayon::prelude::*;
        let a = &self.upper;
        out.par_iter_mut().enumerate().for_each(|(i, o)| {
            let mut acc = Vec3::zeros();
            for k in a.row_offsets[i] as usize..a.row_offsets[i + 1] as usize {
                acc += a.blocks[k] * v[a.col_indices[k] as usize];
            }
            let column = self.column_offsets[i] as usize..self.column_offsets[i + 1] as usize;
            for &(k, row) in &self.by_column[column] {
                acc += a.blocks[k as usize].tr_mul(&v[row as usize]);
            }
            *o = acc;
        });
    }
}
