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
    /// over `num_nodes` nodes (the diagonal is always present).
    pub fn lattice_pattern(num_nodes: usize, cells: &[[u32; 8]]) -> Self {
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(cells.len() * 64 + num_nodes);
        for cell in cells {
            for &a in cell {
                for &b in cell {
                    pairs.push((a, b));
                }
            }
        }
        pairs.extend((0..num_nodes as u32).map(|i| (i, i)));
        pairs.sort_unstable();
        pairs.dedup();
        let mut row_offsets = vec![0u32; num_nodes + 1];
        for &(r, _) in &pairs {
            row_offsets[r as usize + 1] += 1;
        }
        for i in 0..num_nodes {
            row_offsets[i + 1] += row_offsets[i];
        }
        let col_indices: Vec<u32> = pairs.iter().map(|&(_, c)| c).collect();
        let blocks = vec![Mat3::zeros(); col_indices.len()];
        Self {
            row_offsets,
            col_indices,
            blocks,
        }
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
        let mut worst = 0.0f64;
        for i in 0..self.num_rows() {
            for k in self.row_offsets[i] as usize..self.row_offsets[i + 1] as usize {
                let j = self.col_indices[k] as usize;
                let t = self
                    .find(j, i)
                    .map_or(Mat3::zeros(), |kt| self.blocks[kt].transpose());
                worst = worst.max((self.blocks[k] - t).abs().max());
            }
        }
        worst
    }
}
