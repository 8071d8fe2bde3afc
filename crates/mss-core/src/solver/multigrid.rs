//! Geometric multigrid on the voxel lattice, as a preconditioner of Krylov
//! solves of the Newton systems (static, implicit, the FEM reference).
//!
//! The lattice's nodes sit on a regular grid, so the hierarchy is built from
//! grid coordinates alone (Zhu, Sifakis, Teran and Brandt 2010; McAdams et
//! al. 2011):
//!
//! - **Coarsening**: a coarse cell exists where any of its 2 x 2 x 2 fine
//!   children does; coarse nodes are the corners of coarse cells. Every fine
//!   node then lies in a coarse cell, and every corner of that coarse cell
//!   exists, so trilinear interpolation is always defined.
//! - **Prolongation** `P`: trilinear weights (1, 1/2, 1/4 or 1/8 per coarse
//!   node), applied per component and masked by the held dofs (a held fine dof
//!   receives no correction).
//! - **The lattice's mechanisms** (3D lattices): the paper's model, `springs`
//!   and `volumetric` give no stiffness to three checkerboard patterns per
//!   cell (docs/model.md section 5; along axis `i`, the node's signs along the
//!   two other axes). A field of them under a smooth envelope costs as little
//!   energy as a smooth displacement, yet trilinear interpolation cannot
//!   represent it, and no point smoother reduces it: with the grid's coarse
//!   spaces alone the Krylov method needed 83 to 173 iterations where the
//!   hourglass-controlled models needed 24 to 26. So each coarse node also
//!   has a *companion* node whose three dofs are the three patterns'
//!   amplitudes: the first prolongation gives a fine node its parents'
//!   companions with its trilinear weight times its sign for each axis, and
//!   coarser levels interpolate the companions trilinearly (an envelope is
//!   smooth). The two coarse spaces are not coupled on coarse levels
//!   (their coupling is small on a regular lattice, and leaving it out kept
//!   the iteration counts while halving the coarse operators); the cycle
//!   corrects with both at once. A companion space may be rank deficient
//!   where a part is thinner than a coarse cell; the coarse right-hand side
//!   has no component along the prolongation's null space, and the coarsest
//!   solve is regularized there (see [`COARSEST_REGULARIZATION`]).
//! - **Coarse operators**: Galerkin, `A_c = P^T A P`, assembled block by block;
//!   its pattern is that of the coarse lattice (nodes sharing a coarse cell),
//!   which contains `P^T A P` because every coarse parent of every corner of a
//!   fine cell is a corner of that cell's parent. Coarse dofs whose every child
//!   is held get an identity row.
//! - **Smoother**: Chebyshev polynomials of the 3 x 3 block-Jacobi iteration,
//!   on the interval `[1.5 rho / 30, 1.5 rho]` with `rho` the largest eigenvalue of
//!   `D^-1 A` estimated by power iterations. Chebyshev needs no inner products
//!   and updates every node from the previous iterate only, so the result is
//!   bitwise the same for any thread count (colouring is not needed).
//! - **What the levels hold**: the *symmetric part* of the operator, once per
//!   pair of blocks (the blocks on and above the diagonal, [`HalfMatrix`]),
//!   in single precision (sums in `f64`). The products are memory bound and
//!   a preconditioner needs no more digits; the symmetric part is the
//!   operator itself for the conservative models and at rest, and differs
//!   from it by the correction forces' small skew part at large strain,
//!   which the Krylov method (GMRES, with the `f64` operator's own products)
//!   takes care of. A quarter of the bytes of the `f64` operator, so that a
//!   million-node hierarchy fits beside the solver's vectors, and half the
//!   work of the Galerkin products.
//! - **Coarsest level**: a sparse direct solve (LU) once it has at most
//!   [`COARSEST_NODES`] nodes.
//!
//! The Krylov methods are preconditioned conjugate gradients for a symmetric
//! tangent and restarted GMRES for the non-symmetric ones (the correction forces make
//! the tangent non-symmetric at large strain). Every inner product is summed
//! in fixed chunks, in order, so the iterates do not depend on the number of
//! threads either.

use std::collections::HashMap;

use rayon::prelude::*;

use crate::krylov::dot;
use crate::sparse::{BlockCsr, Factorization, SymmetricUpper};
use crate::{Mat3, Vec3};

/// A level stops being coarsened once it has at most this many nodes; it is
/// then solved directly.
pub const COARSEST_NODES: usize = 1000;

/// Factor on the power-iteration estimate of the largest eigenvalue of
/// `D^-1 A`: twelve power iterations underestimate it by some percent, and a
/// Chebyshev smoother whose interval misses the top of the spectrum amplifies
/// those modes (with 1.1, the cantilever at 48x12x12 took 150 iterations per
/// solve instead of 10).
const RHO_SAFETY: f64 = 1.5;

/// Chebyshev steps before and after the coarse correction (2 to 4 cost the
/// same on the cantilever: fewer Krylov iterations pay for the extra sweeps).
const SMOOTHING_STEPS: usize = 3;

/// Krylov vectors kept by restarted GMRES (the non-symmetric solves).
const GMRES_RESTART: usize = 40;

/// Rows per chunk of the parallel loops and of the ordered reductions.
const CHUNK: usize = 2048;

/// Integer grid coordinates of nodes, from rest positions and the cell edge.
pub(crate) fn grid_coords(rest: &[Vec3], h: f64) -> Vec<[i64; 3]> {
    let mut lo = [f64::INFINITY; 3];
    for p in rest {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
        }
    }
    rest.iter()
        .map(|p| std::array::from_fn(|k| ((p[k] - lo[k]) / h).round() as i64))
        .collect()
}

/// Prolongation from a coarse level: for each fine node, its coarse parents
/// and their weights per component (CSR). Trilinear weights are the same for
/// the three components; the hourglass companions' carry the mode's signs.
#[derive(Debug, Clone)]
struct Prolongation {
    offsets: Vec<u32>,
    parents: Vec<u32>,
    weights: Vec<Vec3>,
}

/// The signs of the lattice's three mechanisms at grid node `g` (docs/model.md
/// section 5): along axis `i`, the product of the node's signs along the two
/// other axes.
fn hourglass_signs(g: [i64; 3]) -> Vec3 {
    let sign = |v: i64| if v.rem_euclid(2) == 0 { 1.0 } else { -1.0 };
    Vec3::new(sign(g[1] + g[2]), sign(g[0] + g[2]), sign(g[0] + g[1]))
}

/// A symmetric block matrix in single precision, stored once per pair of
/// blocks: the pattern of the blocks on and above the diagonal with its
/// by-column index ([`SymmetricUpper`], without `f64` blocks) and the blocks,
/// 9 per block in column-major order plus 3 of padding at the end (see
/// [`HalfMatrix::mul`]).
#[derive(Debug, Clone)]
pub(crate) struct HalfMatrix {
    pattern: SymmetricUpper,
    /// The blocks in the pattern's order; empty once they are `shared`.
    blocks: Vec<f32>,
    /// The blocks stored once per distinct value, when few values repeat.
    shared: Option<SharedBlocks>,
}

/// The blocks of a [`HalfMatrix`] in which a few distinct blocks repeat, each
/// stored once. A lattice at rest has such a matrix: the interior nodes'
/// rows are all alike (their cells' matrices summed in the same order give
/// the same bits), and only the boundary's rows differ; so have the coarse
/// levels built from it. The product then reads 8 bytes per block (a
/// column and an entry of the table, which stays in cache) instead of 40,
/// which is what it waits on (the smoothing products are memory bound).
#[derive(Debug, Clone)]
struct SharedBlocks {
    /// The distinct blocks, 9 entries each in column-major order, plus 3 of
    /// padding at the end (as [`HalfMatrix::blocks`]): the single-precision
    /// values held in `f64` (exactly), since the table is small, so that the
    /// product does not convert them at every use (it is then bound by its
    /// arithmetic, not by memory).
    distinct: Vec<f64>,
    /// For each block of the upper half, its entry in `distinct`.
    upper: Vec<u32>,
    /// The pattern's by-column index with each block's entry in `distinct`
    /// in place of its position in the upper half.
    below: Vec<(u32, u32)>,
}

/// Fewest blocks a level needs for [`HalfMatrix::share_repeated_blocks`] to
/// be tried: below it the matrix is in cache anyway.
const SHARE_MIN_BLOCKS: usize = 20_000;

/// Most distinct blocks [`HalfMatrix::share_repeated_blocks`] accepts, as a
/// fraction of the blocks (and at most [`SHARE_MAX_DISTINCT`]): beyond it the
/// table would not stay in cache, or would save little.
const SHARE_MAX_FRACTION: usize = 16;
const SHARE_MAX_DISTINCT: usize = 1 << 15;

impl HalfMatrix {
    /// Single-precision blocks of `blocks`, padded.
    fn single(blocks: &[Mat3]) -> Vec<f32> {
        // Written in place by chunks of a known length (collecting a
        // flattened parallel iterator went through lists of pieces).
        let mut out = vec![0.0f32; 9 * blocks.len() + 3];
        out[..9 * blocks.len()]
            .par_chunks_mut(9 * CHUNK)
            .zip(blocks.par_chunks(CHUNK))
            .for_each(|(o, b)| {
                for (o, b) in o.chunks_exact_mut(9).zip(b) {
                    for (o, &v) in o.iter_mut().zip(b.as_slice()) {
                        *o = v as f32;
                    }
                }
            });
        out
    }

    /// The matrix `m` in single precision (its `f64` blocks are freed).
    pub(crate) fn from_upper(mut m: SymmetricUpper) -> Self {
        let blocks = Self::single(&m.upper.blocks);
        m.upper.blocks = Vec::new();
        Self {
            pattern: m,
            blocks,
            shared: None,
        }
    }

    /// The symmetric part `(A + A^T) / 2` of `a` (with its diagonal; a
    /// block whose mirror the pattern lacks counts with a zero mirror) in
    /// single precision.
    fn symmetric_part_of(a: &BlockCsr) -> Self {
        let pattern = SymmetricUpper::upper_pattern_only(&a.row_offsets, &a.col_indices);
        let upper = &pattern.upper;
        let mut blocks = vec![0.0f32; 9 * upper.col_indices.len() + 3];
        let body = blocks.len() - 3;
        row_chunks(&upper.row_offsets, &mut blocks[..body])
            .into_par_iter()
            .for_each(|(rows, chunk)| {
                let first = upper.row_offsets[rows.start] as usize;
                for i in rows {
                    for k in upper.row_offsets[i] as usize..upper.row_offsets[i + 1] as usize {
                        let j = upper.col_indices[k] as usize;
                        let here = a.find(i, j).map_or(Mat3::zeros(), |q| a.blocks[q]);
                        let mirror = a.find(j, i).map_or(Mat3::zeros(), |q| a.blocks[q]);
                        let sym = (here + mirror.transpose()) * 0.5;
                        let out = &mut chunk[9 * (k - first)..9 * (k - first) + 9];
                        for (o, v) in out.iter_mut().zip(sym.as_slice()) {
                            *o = *v as f32;
                        }
                    }
                }
            });
        Self {
            pattern,
            blocks,
            shared: None,
        }
    }

    /// Number of block rows.
    fn num_rows(&self) -> usize {
        self.pattern.num_rows()
    }

    /// Block `k` (of the upper half) in `f64`.
    fn block(&self, k: usize) -> Mat3 {
        match &self.shared {
            Some(s) => {
                let entry = 9 * s.upper[k] as usize;
                Mat3::from_fn(|e, d| s.distinct[entry + 3 * d + e])
            }
            None => Mat3::from_fn(|e, d| f64::from(self.blocks[9 * k + 3 * d + e])),
        }
    }

    /// Stores each distinct block once ([`SharedBlocks`]) when few distinct
    /// blocks repeat over a matrix large enough to leave the cache; else
    /// leaves the matrix as it is. The values, and so every product's bits,
    /// do not change.
    fn share_repeated_blocks(&mut self) {
        let count = self.pattern.upper.col_indices.len();
        if self.shared.is_some() || count < SHARE_MIN_BLOCKS {
            return;
        }
        let limit = (count / SHARE_MAX_FRACTION).min(SHARE_MAX_DISTINCT);
        let mut seen: std::collections::HashMap<[u32; 9], u32, rustc_hash::FxBuildHasher> =
            std::collections::HashMap::default();
        let mut distinct: Vec<f64> = Vec::new();
        let mut upper = Vec::with_capacity(count);
        for block in self.blocks[..9 * count].chunks_exact(9) {
            // By bits: blocks that compare equal but differ in bits (the
            // signs of zeros) stay apart, so the products keep their bits.
            let key: [u32; 9] = std::array::from_fn(|e| block[e].to_bits());
            let next = seen.len() as u32;
            let entry = *seen.entry(key).or_insert_with(|| {
                distinct.extend(block.iter().map(|&v| f64::from(v)));
                next
            });
            if seen.len() > limit {
                log::trace!("multigrid level of {count} blocks: over {limit} distinct, kept whole");
                return;
            }
            upper.push(entry);
        }
        log::trace!(
            "multigrid level of {count} blocks: {} distinct, stored once each",
            seen.len()
        );
        distinct.extend([0.0; 3]);
        let below = self
            .pattern
            .by_column()
            .iter()
            .map(|&(k, row)| (upper[k as usize], row))
            .collect();
        self.shared = Some(SharedBlocks {
            distinct,
            upper,
            below,
        });
        self.blocks = Vec::new();
    }

    /// Calls `f(j, A_ij)` for every block of row `i`, in column order.
    fn for_each_in_row(&self, i: usize, mut f: impl FnMut(usize, Mat3)) {
        for &(k, row) in self.pattern.column(i) {
            f(row as usize, self.block(k as usize).transpose());
        }
        let u = &self.pattern.upper;
        for k in u.row_offsets[i] as usize..u.row_offsets[i + 1] as usize {
            f(u.col_indices[k] as usize, self.block(k));
        }
    }

    /// The diagonal block of row `i` (zero if the pattern lacks it).
    fn diagonal(&self, i: usize) -> Mat3 {
        let u = &self.pattern.upper;
        let k = u.row_offsets[i] as usize;
        if k < u.row_offsets[i + 1] as usize && u.col_indices[k] as usize == i {
            self.block(k)
        } else {
            Mat3::zeros()
        }
    }

    /// Held dofs decoupled (identity rows and columns), in place.
    fn decouple(&mut self, mask: &[[bool; 3]]) {
        assert!(
            self.shared.is_none(),
            "decoupled before its blocks are shared"
        );
        let u = &self.pattern.upper;
        let body = self.blocks.len() - 3;
        row_chunks(&u.row_offsets, &mut self.blocks[..body])
            .into_par_iter()
            .for_each(|(rows, chunk)| {
                let first = u.row_offsets[rows.start] as usize;
                for i in rows {
                    for k in u.row_offsets[i] as usize..u.row_offsets[i + 1] as usize {
                        let j = u.col_indices[k] as usize;
                        let b = &mut chunk[9 * (k - first)..9 * (k - first) + 9];
                        for d in 0..3 {
                            for e in 0..3 {
                                if !(mask[i][e] && mask[j][d]) {
                                    b[3 * d + e] = if i == j && e == d { 1.0 } else { 0.0 };
                                }
                            }
                        }
                    }
                }
            });
    }

    /// Both halves in `f64` (for the coarsest level's factorization).
    fn to_full(&self) -> BlockCsr {
        let (row_offsets, col_indices) = self.pattern.full_pattern();
        let mut blocks = Vec::with_capacity(col_indices.len());
        for i in 0..self.num_rows() {
            self.for_each_in_row(i, |_, b| blocks.push(b));
        }
        BlockCsr {
            row_offsets,
            col_indices,
            blocks,
        }
    }

    /// `y = A x`, rows in parallel, each row summed in a fixed order (the
    /// same bits for any thread count), in `f64`. Row `i`'s blocks below the
    /// diagonal are read from the rows above it through the by-column index:
    /// those were read shortly before (a plane of the lattice back), so the
    /// second read mostly hits the cache. Each block adds its three columns
    /// to a four-lane accumulator (the fourth lane reads the next block's
    /// first entry and is discarded, hence the padding); a transposed block
    /// multiplies its columns by `x` lane-wise into three accumulators
    /// summed at the row's end. With AVX2 each accumulator is one register
    /// (written out: the compiler's version wasted a quarter of them).
    fn mul(&self, x: &[Vec3], y: &mut [Vec3]) {
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the CPU supports AVX2 (checked above). The rows are
                // a separate function: the closure would not get the feature.
                unsafe { half_mul_rows_avx2(self, x, yc, ci * CHUNK) };
                return;
            }
            half_mul_rows(self, x, yc, ci * CHUNK);
        });
    }
}

/// `blocks` (9 entries per block of the pattern `row_offsets`) split into
/// chunks of [`CHUNK`] rows, with the rows of each: for loops over rows in
/// parallel that write their rows' blocks.
fn row_chunks<'a>(
    row_offsets: &[u32],
    mut blocks: &'a mut [f32],
) -> Vec<(std::ops::Range<usize>, &'a mut [f32])> {
    let n = row_offsets.len() - 1;
    let mut out = Vec::with_capacity(n.div_ceil(CHUNK));
    for start in (0..n).step_by(CHUNK) {
        let end = (start + CHUNK).min(n);
        let len = 9 * (row_offsets[end] - row_offsets[start]) as usize;
        let (head, tail) = blocks.split_at_mut(len);
        out.push((start..end, head));
        blocks = tail;
    }
    out
}

/// [`half_mul_rows`] in AVX registers: the same operations in the same
/// order on each lane (so the same bits). Left to itself the compiler drops
/// the discarded fourth lane and splits the other three into a 2-wide and a
/// scalar instruction, which doubled the product's instruction count.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn half_mul_rows_avx2(a: &HalfMatrix, x: &[Vec3], y: &mut [Vec3], first: usize) {
    half_mul_rows_with::<Avx2Rows>(a, x, y, first);
}

/// The rows of [`HalfMatrix::mul`] for either storage of the blocks.
trait HalfRows {
    /// Rows `first..first + y.len()`: row `i`'s blocks below the diagonal
    /// are `below_of(i)` (entry in `blocks`, row), block `p` of the upper
    /// half is entry `upper_entry(p)`.
    fn rows<'a, B: BlockEntry>(
        a: &HalfMatrix,
        blocks: &[B],
        below_of: impl Fn(usize) -> &'a [(u32, u32)],
        upper_entry: impl Fn(usize) -> usize,
        x: &[Vec3],
        y: &mut [Vec3],
        first: usize,
    );
}

/// The rows on `f64` lanes, left to the compiler.
struct PortableRows;
impl HalfRows for PortableRows {
    #[inline(always)]
    fn rows<'a, B: BlockEntry>(
        a: &HalfMatrix,
        blocks: &[B],
        below_of: impl Fn(usize) -> &'a [(u32, u32)],
        upper_entry: impl Fn(usize) -> usize,
        x: &[Vec3],
        y: &mut [Vec3],
        first: usize,
    ) {
        let u = &a.pattern.upper;
        for (k, yi) in y.iter_mut().enumerate() {
            let i = first + k;
            let mut below = [[0.0f64; 4]; 3];
            for &(p, j) in below_of(i) {
                let v = &x[j as usize];
                let xv = [v.x, v.y, v.z, 0.0];
                let b = &blocks[9 * p as usize..9 * p as usize + 12];
                for (e, acc) in below.iter_mut().enumerate() {
                    let col = &b[3 * e..3 * e + 4];
                    for l in 0..4 {
                        acc[l] += col[l].widen() * xv[l];
                    }
                }
            }
            // One accumulator per column of the blocks: three independent
            // chains of additions instead of one three times as long, which
            // bounded the product by the adder's latency.
            let mut acc = [[0.0f64; 4]; 3];
            let lo = u.row_offsets[i] as usize;
            let hi = u.row_offsets[i + 1] as usize;
            for (p, &c) in (lo..hi).zip(&u.col_indices[lo..hi]) {
                let v = &x[c as usize];
                let e = upper_entry(p);
                let b = &blocks[9 * e..9 * e + 12];
                for (d, xd) in [v.x, v.y, v.z].into_iter().enumerate() {
                    let col = &b[3 * d..3 * d + 4];
                    for l in 0..4 {
                        acc[d][l] += col[l].widen() * xd;
                    }
                }
            }
            *yi = Vec3::from_fn(|e, _| {
                ((acc[0][e] + acc[1][e]) + acc[2][e]) + ((below[e][0] + below[e][1]) + below[e][2])
            });
        }
    }
}

/// [`half_mul_rows_avx2_of`]: used by [`half_mul_rows_avx2`] only.
#[cfg(target_arch = "x86_64")]
struct Avx2Rows;
#[cfg(target_arch = "x86_64")]
impl HalfRows for Avx2Rows {
    #[inline(always)]
    fn rows<'a, B: BlockEntry>(
        a: &HalfMatrix,
        blocks: &[B],
        below_of: impl Fn(usize) -> &'a [(u32, u32)],
        upper_entry: impl Fn(usize) -> usize,
        x: &[Vec3],
        y: &mut [Vec3],
        first: usize,
    ) {
        // SAFETY: only `half_mul_rows_avx2`, which runs with AVX2, uses
        // these rows.
        unsafe { half_mul_rows_avx2_of(a, blocks, below_of, upper_entry, x, y, first) }
    }
}

/// The rows `R` on `a`'s blocks, shared or not.
#[inline(always)]
fn half_mul_rows_with<R: HalfRows>(a: &HalfMatrix, x: &[Vec3], y: &mut [Vec3], first: usize) {
    match &a.shared {
        Some(s) => R::rows(
            a,
            &s.distinct,
            |i| &s.below[a.pattern.column_range(i)],
            |p| s.upper[p] as usize,
            x,
            y,
            first,
        ),
        None => R::rows(a, &a.blocks, |i| a.pattern.column(i), |p| p, x, y, first),
    }
}

/// [`PortableRows`] with each four-lane accumulator one AVX register.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn half_mul_rows_avx2_of<'a, B: BlockEntry>(
    a: &HalfMatrix,
    blocks: &[B],
    below_of: impl Fn(usize) -> &'a [(u32, u32)],
    upper_entry: impl Fn(usize) -> usize,
    x: &[Vec3],
    y: &mut [Vec3],
    first: usize,
) {
    use std::arch::x86_64::*;
    let u = &a.pattern.upper;
    for (k, yi) in y.iter_mut().enumerate() {
        let i = first + k;
        let mut below = [_mm256_setzero_pd(); 3];
        for &(p, j) in below_of(i) {
            let v = &x[j as usize];
            let xv = _mm256_set_pd(0.0, v.z, v.y, v.x);
            let b = &blocks[9 * p as usize..9 * p as usize + 12];
            for (e, acc) in below.iter_mut().enumerate() {
                // SAFETY: this function runs with AVX2.
                let col = unsafe { B::load4(&b[3 * e..3 * e + 4]) };
                *acc = _mm256_add_pd(*acc, _mm256_mul_pd(col, xv));
            }
        }
        let mut acc = [_mm256_setzero_pd(); 3];
        let lo = u.row_offsets[i] as usize;
        let hi = u.row_offsets[i + 1] as usize;
        for (p, &c) in (lo..hi).zip(&u.col_indices[lo..hi]) {
            let v = &x[c as usize];
            let e = upper_entry(p);
            let b = &blocks[9 * e..9 * e + 12];
            for (d, xd) in [v.x, v.y, v.z].into_iter().enumerate() {
                // SAFETY: this function runs with AVX2.
                let col = unsafe { B::load4(&b[3 * d..3 * d + 4]) };
                acc[d] = _mm256_add_pd(acc[d], _mm256_mul_pd(col, _mm256_set1_pd(xd)));
            }
        }
        let upper = _mm256_add_pd(_mm256_add_pd(acc[0], acc[1]), acc[2]);
        let mut up = [0.0f64; 4];
        let mut bl = [[0.0f64; 4]; 3];
        // SAFETY: each array is 4 f64 long.
        unsafe {
            _mm256_storeu_pd(up.as_mut_ptr(), upper);
            for (out, acc) in bl.iter_mut().zip(&below) {
                _mm256_storeu_pd(out.as_mut_ptr(), *acc);
            }
        }
        *yi = Vec3::from_fn(|e, _| up[e] + ((bl[e][0] + bl[e][1]) + bl[e][2]));
    }
}

/// Rows `first..first + y.len()` of [`HalfMatrix::mul`]; no FMA on any
/// path, so every path (and either storage of the blocks) gives the same
/// bits.
#[inline(always)]
fn half_mul_rows(a: &HalfMatrix, x: &[Vec3], y: &mut [Vec3], first: usize) {
    half_mul_rows_with::<PortableRows>(a, x, y, first);
}

/// A stored block entry: single precision, or its exact `f64` value.
trait BlockEntry: Copy {
    fn widen(self) -> f64;
    /// The first four entries of `four` widened into an AVX register.
    ///
    /// # Safety
    /// The CPU supports AVX2.
    #[cfg(target_arch = "x86_64")]
    unsafe fn load4(four: &[Self]) -> std::arch::x86_64::__m256d;
}
impl BlockEntry for f32 {
    #[inline(always)]
    fn widen(self) -> f64 {
        f64::from(self)
    }
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn load4(four: &[f32]) -> std::arch::x86_64::__m256d {
        use std::arch::x86_64::*;
        assert!(four.len() >= 4);
        // SAFETY: four entries are there (checked).
        _mm256_cvtps_pd(unsafe { _mm_loadu_ps(four.as_ptr()) })
    }
}
impl BlockEntry for f64 {
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn load4(four: &[f64]) -> std::arch::x86_64::__m256d {
        use std::arch::x86_64::*;
        assert!(four.len() >= 4);
        // SAFETY: four entries are there (checked).
        unsafe { _mm256_loadu_pd(four.as_ptr()) }
    }
}

/// One level of the hierarchy above the finest (or the finest itself).
#[derive(Debug, Clone)]
struct Level {
    /// The symmetric part of the level's operator, held dofs decoupled
    /// (identity rows and columns), in single precision: the smoother's and
    /// the cycle's residuals' matrix.
    a: HalfMatrix,
    /// Inverses of the 3 x 3 diagonal blocks.
    inv_diag: Vec<Mat3>,
    /// Largest eigenvalue estimate of `D^-1 A` (for Chebyshev).
    rho: f64,
    /// Free-dof mask of the level, per node.
    mask: Vec<[bool; 3]>,
}

/// The structure of a hierarchy: grid coordinates, prolongations and coarse
/// patterns, which depend only on the lattice and the held dofs and are
/// reused for every matrix of a Newton solve.
#[derive(Debug, Clone)]
pub(crate) struct HierarchyShape {
    /// Prolongation from level `k + 1` to level `k`.
    prolongations: Vec<Prolongation>,
    /// The upper half's pattern of each coarse level.
    coarse_patterns: Vec<SymmetricUpper>,
    /// Per coarse level, the index of its first companion node
    /// (`u32::MAX`: none).
    first_companions: Vec<u32>,
    /// Free-dof mask of the finest level (the key of the cache).
    fine_free: Vec<bool>,
}

impl HierarchyShape {
    /// The hierarchy structure of a lattice given by its cells and node grid
    /// coordinates, with free dofs `free[3 node + d]`. With `enrich`, every
    /// coarse level also carries the lattice's mechanisms (see the module
    /// docs): each coarse node has a companion whose three dofs are the
    /// amplitudes of the three hourglass patterns around it.
    pub(crate) fn new(
        cells: &[[u32; 8]],
        coords: &[[i64; 3]],
        free: &[bool],
        enrich: bool,
    ) -> Self {
        let mut prolongations = Vec::new();
        let mut coarse_patterns = Vec::new();
        let mut first_companions = Vec::new();
        let mut cells_k: Vec<[i64; 3]> = cells
            .iter()
            .map(|c| {
                let p = coords[c[0] as usize];
                let mut m = p;
                for &n in c {
                    for k in 0..3 {
                        m[k] = m[k].min(coords[n as usize][k]);
                    }
                }
                m
            })
            .collect();
        // Level k's nodes: the grid nodes `nodes_k`, then (on coarse levels
        // of an enriched hierarchy) their companions in the same order.
        let mut nodes_k: Vec<[i64; 3]> = coords.to_vec();
        let mut companions_k = false;
        let level_size = |nodes: usize, companions: bool| nodes * (1 + companions as usize);
        while level_size(nodes_k.len(), companions_k) > COARSEST_NODES {
            // Coarse cells: parents of the fine cells.
            let mut coarse_cells: Vec<[i64; 3]> =
                cells_k.iter().map(|c| c.map(|v| v.div_euclid(2))).collect();
            coarse_cells.sort_unstable();
            coarse_cells.dedup();
            // Coarse nodes: corners of the coarse cells.
            let mut coarse_nodes: Vec<[i64; 3]> = coarse_cells
                .iter()
                .flat_map(|c| {
                    (0..8).map(move |o| [c[0] + (o & 1), c[1] + ((o >> 1) & 1), c[2] + (o >> 2)])
                })
                .collect();
            coarse_nodes.sort_unstable();
            coarse_nodes.dedup();
            if level_size(coarse_nodes.len(), enrich) * 10
                > level_size(nodes_k.len(), companions_k) * 9
            {
                // Hardly coarser (a flat or thin part): stop here.
                break;
            }
            let nc = coarse_nodes.len() as u32;
            let index: HashMap<[i64; 3], u32> = coarse_nodes
                .iter()
                .enumerate()
                .map(|(i, &c)| (c, i as u32))
                .collect();
            // Trilinear parents of a fine grid node.
            let trilinear = |f: &[i64; 3]| {
                let axis = |v: i64| -> Vec<(i64, f64)> {
                    if v.rem_euclid(2) == 0 {
                        vec![(v / 2, 1.0)]
                    } else {
                        vec![(v.div_euclid(2), 0.5), (v.div_euclid(2) + 1, 0.5)]
                    }
                };
                let mut out = Vec::with_capacity(8);
                for (z, wz) in axis(f[2]) {
                    for (y, wy) in axis(f[1]) {
                        for (x, wx) in axis(f[0]) {
                            // Every parent exists (see the module docs); a
                            // missing one would only drop a weight.
                            if let Some(&p) = index.get(&[x, y, z]) {
                                out.push((p, wx * wy * wz));
                            }
                        }
                    }
                }
                out
            };
            let mut offsets = Vec::with_capacity(level_size(nodes_k.len(), companions_k) + 1);
            let mut parents = Vec::new();
            let mut weights = Vec::new();
            offsets.push(0u32);
            for f in &nodes_k {
                let tri = trilinear(f);
                for &(p, w) in &tri {
                    parents.push(p);
                    weights.push(Vec3::repeat(w));
                }
                if enrich && !companions_k {
                    // The first coarsening: a fine node's share of each
                    // parent's hourglass amplitudes, with the node's signs.
                    let signs = hourglass_signs(*f);
                    for &(p, w) in &tri {
                        parents.push(p + nc);
                        weights.push(signs * w);
                    }
                }
                offsets.push(parents.len() as u32);
            }
            if companions_k {
                // A companion's amplitudes vary smoothly: trilinear, from
                // the coarse companions.
                for f in &nodes_k {
                    for (p, w) in trilinear(f) {
                        parents.push(p + nc);
                        weights.push(Vec3::repeat(w));
                    }
                    offsets.push(parents.len() as u32);
                }
            }
            let corner = |c: &[i64; 3], o: usize| {
                let o = o as i64;
                index[&[c[0] + (o & 1), c[1] + ((o >> 1) & 1), c[2] + (o >> 2)]]
            };
            // The companions' cells are the grid's, shifted: the two coarse
            // spaces are not coupled.
            let mut cells: Vec<[u32; 8]> = coarse_cells
                .iter()
                .map(|c| std::array::from_fn(|o| corner(c, o)))
                .collect();
            if enrich {
                let shifted: Vec<[u32; 8]> = cells.iter().map(|c| c.map(|n| n + nc)).collect();
                cells.extend(shifted);
            }
            let (rows, cols) =
                BlockCsr::lattice_pattern_indices(level_size(nc as usize, enrich), &cells);
            coarse_patterns.push(SymmetricUpper::upper_pattern_only(&rows, &cols));
            first_companions.push(if enrich { nc } else { u32::MAX });
            prolongations.push(Prolongation {
                offsets,
                parents,
                weights,
            });
            cells_k = coarse_cells;
            nodes_k = coarse_nodes;
            companions_k = enrich;
        }
        Self {
            prolongations,
            coarse_patterns,
            first_companions,
            fine_free: free.to_vec(),
        }
    }

    /// Whether this shape was built for the free mask `free`.
    pub(crate) fn fits(&self, free: &[bool]) -> bool {
        self.fine_free == free
    }

    /// Number of levels (the finest included).
    pub(crate) fn num_levels(&self) -> usize {
        self.prolongations.len() + 1
    }
}

fn masks_of(free: &[bool]) -> Vec<[bool; 3]> {
    free.chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// `M A M + (I - M)` for the free-dof mask `M` (held dofs decoupled), in
/// place.
fn decouple(a: &mut BlockCsr, mask: &[[bool; 3]]) {
    let offsets = &a.row_offsets;
    let cols = &a.col_indices;
    a.blocks
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(ci, chunk)| {
            // Rows of this chunk of blocks: found from the offsets.
            let start = ci * CHUNK;
            let mut row = offsets.partition_point(|&o| o as usize <= start) - 1;
            for (k, b) in chunk.iter_mut().enumerate() {
                let pos = start + k;
                while offsets[row + 1] as usize <= pos {
                    row += 1;
                }
                let col = cols[pos] as usize;
                for e in 0..3 {
                    for d in 0..3 {
                        let keep = mask[row][e] && mask[col][d];
                        if !keep {
                            b[(e, d)] = if row == col && e == d { 1.0 } else { 0.0 };
                        }
                    }
                }
            }
        });
}

fn inverse_diagonal(a: &HalfMatrix) -> Vec<Mat3> {
    (0..a.num_rows())
        .into_par_iter()
        .map(|i| {
            let d = a.diagonal(i);
            d.try_inverse().unwrap_or_else(|| {
                // A singular diagonal block: invert what can be inverted.
                Mat3::from_diagonal(&Vec3::from_fn(|k, _| {
                    let v = d[(k, k)];
                    if v.abs() > 0.0 { 1.0 / v } else { 0.0 }
                }))
            })
        })
        .collect()
}

/// `y = A x`, rows in parallel (each row is summed in order: deterministic).
pub(crate) fn mul(a: &BlockCsr, x: &[Vec3], y: &mut [Vec3]) {
    y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
        for (k, yi) in yc.iter_mut().enumerate() {
            let i = ci * CHUNK + k;
            let lo = a.row_offsets[i] as usize;
            let hi = a.row_offsets[i + 1] as usize;
            let mut acc = Vec3::zeros();
            for p in lo..hi {
                acc += a.blocks[p] * x[a.col_indices[p] as usize];
            }
            *yi = acc;
        }
    });
}

fn axpy(y: &mut [Vec3], alpha: f64, x: &[Vec3]) {
    y.par_iter_mut()
        .zip(x.par_iter())
        .for_each(|(yi, xi)| *yi += xi * alpha);
}

/// Largest eigenvalue estimate of `D^-1 A` by power iterations from a fixed
/// start vector.
fn spectral_radius(a: &HalfMatrix, inv_diag: &[Mat3], mask: &[[bool; 3]]) -> f64 {
    let n = a.num_rows();
    let mut v: Vec<Vec3> = (0..n)
        .map(|i| {
            // A fixed, non-smooth start vector (a hash of the index).
            let s =
                ((i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40) as f64 / (1u64 << 24) as f64;
            Vec3::from_fn(|k, _| {
                if mask[i][k] {
                    s - 0.5 + 0.1 * k as f64
                } else {
                    0.0
                }
            })
        })
        .collect();
    let mut av = vec![Vec3::zeros(); n];
    let mut rho = 1.0;
    for _ in 0..12 {
        let norm = dot(&v, &v).sqrt();
        if !(norm > 0.0 && norm.is_finite()) {
            break;
        }
        v.par_iter_mut().for_each(|x| *x /= norm);
        a.mul(&v, &mut av);
        av.par_iter_mut()
            .zip(inv_diag.par_iter())
            .for_each(|(x, d)| *x = d * *x);
        rho = dot(&v, &av).abs().max(1e-300);
        std::mem::swap(&mut v, &mut av);
    }
    rho
}

/// A multigrid V-cycle preconditioner for one matrix.
pub(crate) struct Multigrid {
    /// The finest level's operator in `f64` (held dofs decoupled), for the
    /// Krylov method's products; without blocks when the caller multiplies
    /// without a matrix or the hierarchy is only a preconditioner.
    operator: BlockCsr,
    levels: Vec<Level>,
    prolongations: Vec<Prolongation>,
    coarsest: Option<Factorization>,
    /// Work vectors per level (residual, Chebyshev direction, restricted
    /// residual, coarse correction), allocated once: a V-cycle allocates
    /// nothing.
    scratch: std::cell::RefCell<Vec<Scratch>>,
}

/// Work vectors of one level.
#[derive(Debug, Clone)]
struct Scratch {
    r: Vec<Vec3>,
    d: Vec<Vec3>,
    t: Vec<Vec3>,
    /// This level's right-hand side and solution when it is the coarse one.
    b: Vec<Vec3>,
    x: Vec<Vec3>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Self {
            r: vec![Vec3::zeros(); n],
            d: vec![Vec3::zeros(); n],
            t: vec![Vec3::zeros(); n],
            b: vec![Vec3::zeros(); n],
            x: vec![Vec3::zeros(); n],
        }
    }
}

impl std::fmt::Debug for Multigrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Multigrid")
            .field(
                "level_nodes",
                &self
                    .levels
                    .iter()
                    .map(|l| l.a.num_rows())
                    .collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// Why the hierarchy could not be set up.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SetupError(pub String);

impl Multigrid {
    /// The hierarchy of the operator `a` (free dofs `shape`'s) with the
    /// cached `shape`. When `lean`, the finest level's `f64` blocks are
    /// dropped as soon as their single-precision copy is made, before the
    /// coarse levels are built from that copy: the caller multiplies by the
    /// operator without a matrix, and [`Multigrid::operator`] then has no
    /// blocks.
    pub(crate) fn new(a: Operator, shape: &HierarchyShape, lean: bool) -> Result<Self, SetupError> {
        let fine = HalfMatrix::symmetric_part_of(&a.a);
        let mut operator = a.a;
        if lean {
            operator.blocks = Vec::new();
        }
        Self::on(operator, fine, a.mask, shape)
    }

    /// The hierarchy of the symmetric `upper` (the dofs not in `free`, which
    /// must be `shape`'s, are decoupled here), for a caller that multiplies
    /// by the operator without a matrix: [`Multigrid::operator`] has no
    /// pattern and no blocks. No `f64` copy of the operator is ever made.
    pub(crate) fn of_symmetric(
        upper: SymmetricUpper,
        free: &[bool],
        shape: &HierarchyShape,
    ) -> Result<Self, SetupError> {
        let mask = masks_of(free);
        let mut fine = HalfMatrix::from_upper(upper);
        fine.decouple(&mask);
        let operator = BlockCsr {
            row_offsets: vec![0],
            col_indices: Vec::new(),
            blocks: Vec::new(),
        };
        Self::on(operator, fine, mask, shape)
    }

    /// The levels below `fine` (mask `mask`), built by Galerkin products.
    fn on(
        operator: BlockCsr,
        fine: HalfMatrix,
        mask: Vec<[bool; 3]>,
        shape: &HierarchyShape,
    ) -> Result<Self, SetupError> {
        let mut levels = Vec::with_capacity(shape.num_levels());
        levels.push(level_of(fine, mask));
        for ((p, pattern), &companions) in shape
            .prolongations
            .iter()
            .zip(&shape.coarse_patterns)
            .zip(&shape.first_companions)
        {
            let fine = &levels[levels.len() - 1];
            let (ac, mask) = galerkin(&fine.a, &fine.mask, p, pattern, companions);
            levels.push(level_of(ac, mask));
        }
        let last = &levels[levels.len() - 1];
        let mut coarsest_matrix = last.a.to_full();
        if let Some(&first) = shape.first_companions.last() {
            regularize_companions(&mut coarsest_matrix, first as usize);
        }
        let coarsest = match coarsest_matrix.factor_lu(&vec![[false; 3]; last.a.num_rows()]) {
            Ok(f) => Some(f),
            Err(e) => return Err(SetupError(format!("coarsest level: {e}"))),
        };
        let scratch = levels
            .iter()
            .map(|l| Scratch::new(l.a.num_rows()))
            .collect();
        Ok(Self {
            operator,
            levels,
            prolongations: shape.prolongations.clone(),
            coarsest,
            scratch: std::cell::RefCell::new(scratch),
        })
    }

    /// The hierarchy as a preconditioner only: the finest level's `f64`
    /// blocks, which only [`Multigrid::operator`] reads (the cycle reads the
    /// single-precision copy), are dropped. `operator()` then returns the
    /// pattern with no blocks.
    pub(crate) fn into_preconditioner(mut self) -> Self {
        self.operator.blocks = Vec::new();
        self
    }

    /// Free-dof mask of the finest level, per node.
    pub(crate) fn mask(&self) -> &[[bool; 3]] {
        &self.levels[0].mask
    }

    /// Nodes per level, finest first.
    pub(crate) fn level_sizes(&self) -> Vec<usize> {
        self.levels.iter().map(|l| l.a.num_rows()).collect()
    }

    /// The operator of the finest level (held dofs decoupled).
    pub(crate) fn operator(&self) -> (&BlockCsr, &[[bool; 3]]) {
        (&self.operator, &self.levels[0].mask)
    }

    /// `z = M^-1 r`: one V-cycle from zero.
    pub(crate) fn apply(&self, r: &[Vec3], z: &mut [Vec3]) {
        let mut scratch = self.scratch.borrow_mut();
        self.vcycle(0, r, z, &mut scratch[..]);
    }

    /// One V-cycle from zero on level `k`; `scratch` holds the work
    /// vectors of levels `k` and below.
    fn vcycle(&self, k: usize, b: &[Vec3], x: &mut [Vec3], scratch: &mut [Scratch]) {
        let level = &self.levels[k];
        let Some((s, below)) = scratch.split_first_mut() else {
            return;
        };
        if k + 1 == self.levels.len() {
            match self.coarsest.as_ref().map(|f| f.solve(b)) {
                Some(Ok(sol)) => x.copy_from_slice(&sol),
                _ => {
                    x.iter_mut().for_each(|v| *v = Vec3::zeros());
                    chebyshev(level, b, x, 8, &mut s.r, &mut s.d, true);
                }
            }
            return;
        }
        x.iter_mut().for_each(|v| *v = Vec3::zeros());
        chebyshev(level, b, x, SMOOTHING_STEPS, &mut s.r, &mut s.d, true);
        // Residual, restricted into the coarse level's right-hand side.
        level.a.mul(x, &mut s.t);
        s.t.par_iter_mut()
            .zip(b.par_iter())
            .for_each(|(ri, bi)| *ri = bi - *ri);
        let p = &self.prolongations[k];
        let Some(c) = below.first_mut() else {
            return;
        };
        let (mut rc, mut ec) = (std::mem::take(&mut c.b), std::mem::take(&mut c.x));
        restrict(p, &level.mask, &s.t, &mut rc);
        self.vcycle(k + 1, &rc, &mut ec, below);
        prolong_add(p, &level.mask, &ec, x);
        if let Some(c) = below.first_mut() {
            (c.b, c.x) = (rc, ec);
        }
        chebyshev(level, b, x, SMOOTHING_STEPS, &mut s.r, &mut s.d, false);
    }
}

/// Relative shift added to the diagonal of the coarsest level's companions
/// before it is factored: where a part is thinner than a coarse cell, the
/// patterns interpolated from neighbouring companions can cancel, and the
/// Galerkin operator is singular along those combinations. The coarse
/// right-hand side has no component there (it is `P^T r`), so the shift
/// leaves every other component as it was to this relative order.
const COARSEST_REGULARIZATION: f64 = 1e-10;

/// Adds [`COARSEST_REGULARIZATION`] times `a`'s largest diagonal entry to
/// the diagonal of the nodes from `first` on (the companions; none when
/// `first` is past the last row).
fn regularize_companions(a: &mut BlockCsr, first: usize) {
    if first >= a.num_rows() {
        return;
    }
    let largest = (0..a.num_rows())
        .filter_map(|i| a.find(i, i))
        .map(|k| a.blocks[k].diagonal().abs().max())
        .fold(0.0, f64::max);
    for i in first..a.num_rows() {
        if let Some(k) = a.find(i, i) {
            a.blocks[k] += Mat3::identity() * (COARSEST_REGULARIZATION * largest);
        }
    }
}

fn level_of(mut a: HalfMatrix, mask: Vec<[bool; 3]>) -> Level {
    a.share_repeated_blocks();
    let inv_diag = inverse_diagonal(&a);
    let rho = spectral_radius(&a, &inv_diag, &mask);
    Level {
        a,
        inv_diag,
        rho,
        mask,
    }
}

/// The symmetric `P^T A P` on the coarse pattern's upper half (only the
/// coarse blocks on and above the diagonal are summed); coarse dofs without
/// a free child are decoupled (identity).
fn galerkin(
    a: &HalfMatrix,
    mask: &[[bool; 3]],
    p: &Prolongation,
    pattern: &SymmetricUpper,
    companions: u32,
) -> (HalfMatrix, Vec<[bool; 3]>) {
    let nc = pattern.num_rows();
    let upper = &pattern.upper;
    // A coarse dof is free if some free fine dof interpolates from it.
    let mut cmask = vec![[false; 3]; nc];
    for (i, m) in mask.iter().enumerate() {
        for q in p.offsets[i] as usize..p.offsets[i + 1] as usize {
            let c = p.parents[q] as usize;
            for d in 0..3 {
                cmask[c][d] |= m[d];
            }
        }
    }
    // Coarse rows in parallel: each coarse row a collects the fine rows that
    // interpolate from it (transpose of P), in fine order (deterministic).
    let mut children: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); nc];
    for i in 0..mask.len() {
        for q in p.offsets[i] as usize..p.offsets[i + 1] as usize {
            children[p.parents[q] as usize].push((i as u32, p.weights[q]));
        }
    }
    // Per task, each coarse column's position in the row being summed (a
    // dense map over the coarse nodes, cleared after each row): a lookup
    // instead of a binary search per block and parent.
    let rows: Vec<Vec<Mat3>> = (0..nc)
        .into_par_iter()
        .map_init(
            || vec![u32::MAX; nc],
            |position, ca| {
                let lo = upper.row_offsets[ca] as usize;
                let hi = upper.row_offsets[ca + 1] as usize;
                let cols = &upper.col_indices[lo..hi];
                for (k, &c) in cols.iter().enumerate() {
                    position[c as usize] = k as u32;
                }
                let companion_row = ca as u32 >= companions;
                let mut row = vec![Mat3::zeros(); hi - lo];
                for &(i, wa) in &children[ca] {
                    let i = i as usize;
                    a.for_each_in_row(i, |j, mut blk| {
                        // M A M: a held row or column contributes nothing; the
                        // row's weights scale the block's rows once.
                        for e in 0..3 {
                            for d in 0..3 {
                                blk[(e, d)] = if mask[i][e] && mask[j][d] {
                                    blk[(e, d)] * wa[e]
                                } else {
                                    0.0
                                };
                            }
                        }
                        // Only the parents of the row's kind: the grid's and the
                        // mechanisms' coarse spaces are not coupled (see the
                        // module docs), and a node's parents list the grid's
                        // first.
                        let parents = p.offsets[j] as usize..p.offsets[j + 1] as usize;
                        let split = parents.start
                            + p.parents[parents.clone()].partition_point(|&c| c < companions);
                        let parents = if companion_row {
                            split..parents.end
                        } else {
                            parents.start..split
                        };
                        // Columns left of the diagonal are not in the
                        // upper half's map: skipped.
                        for q in parents {
                            let pos = position[p.parents[q] as usize];
                            if pos != u32::MAX {
                                let wb = p.weights[q];
                                let target = &mut row[pos as usize];
                                for d in 0..3 {
                                    for e in 0..3 {
                                        target[(e, d)] += blk[(e, d)] * wb[d];
                                    }
                                }
                            }
                        }
                    });
                }
                for &c in cols {
                    position[c as usize] = u32::MAX;
                }
                row
            },
        )
        .collect();
    let blocks: Vec<Mat3> = rows.into_iter().flatten().collect();
    let mut ac = HalfMatrix {
        pattern: pattern.clone(),
        blocks: HalfMatrix::single(&blocks),
        shared: None,
    };
    // Decouple coarse dofs that no free fine dof reaches.
    ac.decouple(&cmask);
    (ac, cmask)
}

fn restrict(p: &Prolongation, mask: &[[bool; 3]], r: &[Vec3], rc: &mut [Vec3]) {
    // Sequential scatter in fine order: deterministic.
    rc.iter_mut().for_each(|v| *v = Vec3::zeros());
    for (i, ri) in r.iter().enumerate() {
        let m = mask[i];
        let masked = Vec3::new(
            if m[0] { ri.x } else { 0.0 },
            if m[1] { ri.y } else { 0.0 },
            if m[2] { ri.z } else { 0.0 },
        );
        for q in p.offsets[i] as usize..p.offsets[i + 1] as usize {
            rc[p.parents[q] as usize] += masked.component_mul(&p.weights[q]);
        }
    }
}

fn prolong_add(p: &Prolongation, mask: &[[bool; 3]], ec: &[Vec3], x: &mut [Vec3]) {
    x.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, xc)| {
        for (k, xi) in xc.iter_mut().enumerate() {
            let i = ci * CHUNK + k;
            let mut e = Vec3::zeros();
            for q in p.offsets[i] as usize..p.offsets[i + 1] as usize {
                e += ec[p.parents[q] as usize].component_mul(&p.weights[q]);
            }
            for d in 0..3 {
                if mask[i][d] {
                    xi[d] += e[d];
                }
            }
        }
    });
}

/// `steps` Chebyshev iterations of block Jacobi on `A x = b`, from `x`, with
/// work vectors `r` and `d` (one entry per node). `x_is_zero` says that `x`
/// is zero: the first residual is then `b` itself, without a product (the
/// same bits: the product of zero is zero).
fn chebyshev(
    level: &Level,
    b: &[Vec3],
    x: &mut [Vec3],
    steps: usize,
    r: &mut [Vec3],
    d: &mut [Vec3],
    x_is_zero: bool,
) {
    let hi = RHO_SAFETY * level.rho;
    let lo = hi / 30.0;
    let theta = 0.5 * (hi + lo);
    let delta = 0.5 * (hi - lo);
    let sigma = theta / delta;
    let mut rho_k = 1.0 / sigma;
    let residual = |x: &[Vec3], r: &mut [Vec3]| {
        level.a.mul(x, r);
        r.par_iter_mut()
            .zip(b.par_iter())
            .zip(level.inv_diag.par_iter())
            .for_each(|((ri, bi), di)| *ri = di * (bi - *ri));
    };
    if x_is_zero {
        r.par_iter_mut()
            .zip(b.par_iter())
            .zip(level.inv_diag.par_iter())
            .for_each(|((ri, bi), di)| *ri = di * bi);
    } else {
        residual(x, r);
    }
    d.par_iter_mut()
        .zip(r.par_iter())
        .for_each(|(di, ri)| *di = ri / theta);
    for step in 0..steps {
        axpy(x, 1.0, d);
        if step + 1 == steps {
            break;
        }
        residual(x, r);
        let rho_next = 1.0 / (2.0 * sigma - rho_k);
        let (c1, c2) = (rho_next * rho_k, 2.0 * rho_next / delta);
        d.par_iter_mut()
            .zip(r.par_iter())
            .for_each(|(di, ri)| *di = *di * c1 + ri * c2);
        rho_k = rho_next;
    }
}

/// A matrix with its held dofs decoupled (identity rows and columns), the
/// operator of a Krylov solve.
pub(crate) struct Operator {
    a: BlockCsr,
    mask: Vec<[bool; 3]>,
}

impl Operator {
    /// `sign * a` with the dofs not in `free` decoupled, in place (no copy).
    pub(crate) fn from_owned_signed(mut a: BlockCsr, free: &[bool], sign: f64) -> Self {
        if sign != 1.0 {
            a.blocks.par_iter_mut().for_each(|blk| *blk *= sign);
        }
        Self::from_owned(a, free)
    }

    /// `a` with the dofs not in `free` decoupled, in place (no copy).
    pub(crate) fn from_owned(mut a: BlockCsr, free: &[bool]) -> Self {
        let mask = masks_of(free);
        decouple(&mut a, &mask);
        Self { a, mask }
    }

    /// The matrix (with held dofs decoupled).
    pub(crate) fn matrix(&self) -> &BlockCsr {
        &self.a
    }
}

/// Zeroes the held components (`!mask`) of `v`.
fn zero_held(v: &mut [Vec3], mask: &[[bool; 3]]) {
    v.par_iter_mut().zip(mask.par_iter()).for_each(|(vi, m)| {
        for d in 0..3 {
            if !m[d] {
                vi[d] = 0.0;
            }
        }
    })
}

/// Outcome of a Krylov solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct KrylovInfo {
    /// Iterations taken.
    pub iterations: u32,
    /// Final residual norm relative to the right-hand side's.
    pub relative_residual: f64,
    /// Whether the tolerance was reached.
    pub converged: bool,
}

/// Solves `A x = b` on the free dofs (`mask`; held components of `b` and `x`
/// are zero) to a relative residual `rtol`, preconditioned by `mg`: CG when
/// `symmetric`, GMRES otherwise. `x` starts at zero. `product` is
/// `out = A v` for `v` zero on the held dofs (zero there too): the product
/// with `mg`'s operator, or the same without a matrix.
pub(crate) fn krylov(
    mg: &Multigrid,
    product: &dyn Fn(&[Vec3], &mut [Vec3]),
    b: &[Vec3],
    x: &mut [Vec3],
    rtol: f64,
    max_iterations: u32,
    symmetric: bool,
) -> KrylovInfo {
    let mask = mg.mask();
    let n = mask.len();
    let masked = |v: &mut [Vec3]| zero_held(v, mask);
    let mut r: Vec<Vec3> = b.to_vec();
    masked(&mut r);
    x.iter_mut().for_each(|v| *v = Vec3::zeros());
    let bnorm = dot(&r, &r).sqrt();
    if bnorm == 0.0 {
        return KrylovInfo {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
    }
    let target = rtol * bnorm;
    let mut iterations = max_iterations;
    let mut z = vec![Vec3::zeros(); n];
    let mut q = vec![Vec3::zeros(); n];
    if symmetric {
        mg.apply(&r, &mut z);
        let mut pdir = z.clone();
        let mut rz = dot(&r, &z);
        for it in 1..=max_iterations {
            product(&pdir, &mut q);
            let pq = dot(&pdir, &q);
            if !(pq.is_finite() && pq > 0.0) {
                return KrylovInfo {
                    iterations: it,
                    relative_residual: dot(&r, &r).sqrt() / bnorm,
                    converged: false,
                };
            }
            let alpha = rz / pq;
            axpy(x, alpha, &pdir);
            axpy(&mut r, -alpha, &q);
            let rn = dot(&r, &r).sqrt();
            if rn <= target {
                return KrylovInfo {
                    iterations: it,
                    relative_residual: rn / bnorm,
                    converged: true,
                };
            }
            mg.apply(&r, &mut z);
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            rz = rz_next;
            pdir.par_iter_mut()
                .zip(z.par_iter())
                .for_each(|(pi, zi)| *pi = zi + *pi * beta);
        }
    } else {
        // Right-preconditioned restarted GMRES: x = M^-1 (V y), the residual
        // norm is known from the Hessenberg least-squares problem.
        let restart = GMRES_RESTART.min(max_iterations as usize).max(1);
        let mut total = 0u32;
        let mut basis: Vec<Vec<Vec3>> = Vec::with_capacity(restart + 1);
        let mut w = vec![Vec3::zeros(); n];
        while total < max_iterations {
            // r = b - A x (masked b, held rows are identity with x = 0 there).
            product(x, &mut q);
            r.par_iter_mut()
                .zip(b.par_iter().zip(q.par_iter().zip(mask.par_iter())))
                .for_each(|(ri, (bi, (qi, m)))| {
                    for d in 0..3 {
                        ri[d] = if m[d] { bi[d] - qi[d] } else { 0.0 };
                    }
                });
            let beta = dot(&r, &r).sqrt();
            if !beta.is_finite() {
                break;
            }
            if beta <= target {
                return KrylovInfo {
                    iterations: total,
                    relative_residual: beta / bnorm,
                    converged: true,
                };
            }
            basis.clear();
            basis.push(r.iter().map(|v| v / beta).collect());
            let mut hess = vec![vec![0.0f64; restart]; restart + 1];
            let (mut cs, mut sn) = (vec![0.0f64; restart], vec![0.0f64; restart]);
            let mut g = vec![0.0f64; restart + 1];
            g[0] = beta;
            let mut k_used = 0;
            let mut res = beta;
            for k in 0..restart {
                mg.apply(&basis[k], &mut z);
                product(&z, &mut w);
                // Modified Gram-Schmidt with ordered reductions.
                for (j, vj) in basis.iter().enumerate() {
                    let hjk = dot(&w, vj);
                    hess[j][k] = hjk;
                    axpy(&mut w, -hjk, vj);
                }
                let hn = dot(&w, &w).sqrt();
                hess[k + 1][k] = hn;
                // Apply the previous rotations, then a new one.
                for j in 0..k {
                    let t = cs[j] * hess[j][k] + sn[j] * hess[j + 1][k];
                    hess[j + 1][k] = -sn[j] * hess[j][k] + cs[j] * hess[j + 1][k];
                    hess[j][k] = t;
                }
                let denom = (hess[k][k].powi(2) + hn * hn).sqrt();
                if !(denom.is_finite() && denom > 0.0) {
                    break;
                }
                cs[k] = hess[k][k] / denom;
                sn[k] = hn / denom;
                hess[k][k] = denom;
                hess[k + 1][k] = 0.0;
                g[k + 1] = -sn[k] * g[k];
                g[k] *= cs[k];
                k_used = k + 1;
                total += 1;
                res = g[k + 1].abs();
                if res <= target || hn == 0.0 || total >= max_iterations {
                    break;
                }
                basis.push(w.iter().map(|v| v / hn).collect());
            }
            if k_used == 0 {
                break;
            }
            // Solve the triangular system and update x = x + M^-1 V y.
            let mut y = vec![0.0f64; k_used];
            for i in (0..k_used).rev() {
                let mut acc = g[i];
                for j in i + 1..k_used {
                    acc -= hess[i][j] * y[j];
                }
                y[i] = acc / hess[i][i];
            }
            let mut vy = vec![Vec3::zeros(); n];
            for (j, yj) in y.iter().enumerate() {
                axpy(&mut vy, *yj, &basis[j]);
            }
            mg.apply(&vy, &mut z);
            axpy(x, 1.0, &z);
            if res <= target {
                break;
            }
        }
        iterations = total;
    }
    // Report the true residual of the iterate.
    product(x, &mut q);
    let mut res = b.to_vec();
    masked(&mut res);
    let rn = res
        .iter()
        .zip(&q)
        .map(|(bi, qi)| (bi - qi).norm_squared())
        .sum::<f64>()
        .sqrt();
    KrylovInfo {
        iterations,
        relative_residual: rn / bnorm,
        converged: rn <= target,
    }
}

/// What [`definiteness`] found about a symmetric matrix on the free dofs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Definiteness {
    /// Positive definite: the smallest eigenvalue of `M^-1 A` converged
    /// above the margin.
    Positive,
    /// Not positive definite: a direction with `v . A v` at or below the
    /// margin was found.
    NotPositive,
    /// The iteration did not decide within its steps.
    Undecided,
}

/// Smallest eigenvalue of `M^-1 A`, relative to `M` (a multigrid cycle of a
/// positive definite matrix), at or below which `A` counts as not positive
/// definite: the tangent has lost all but this fraction of the
/// preconditioner's stiffness along some motion.
pub(crate) const DEFINITENESS_MARGIN: f64 = 1e-6;

/// Lanczos steps of [`definiteness`]: fewest before deciding in any case,
/// fewest that always suffice (see [`steps_to_reveal`]), most.
const DEFINITENESS_STEPS: (usize, usize, usize) = (6, 15, 200);

/// Lanczos steps after which an eigenvalue at zero below a spectrum from
/// `bottom` to `top` would have pulled the smallest Ritz value to half of
/// `bottom`, for a start vector with a component of about `1 / sqrt(dofs)`
/// along every eigenvector: the Kaniel-Paige bound
/// `theta - lambda_1 <= (lambda_n - lambda_1) tan^2(phi) / T_{k-1}(1 + 2 gamma)^2`,
/// `gamma = (lambda_2 - lambda_1) / (lambda_n - lambda_2)`, with `lambda_1 = 0`
/// and `tan^2(phi) = dofs`. A well-separated bottom (the paper model's
/// 0.64 of the rest stiffness on the cantilever) needs 6 to 7 steps; a
/// spectrum reaching down to 0.19 (the default model's) 12 to 14 from
/// 50,000 to 3 million dofs. Clamped to [`DEFINITENESS_STEPS`]' first two.
fn steps_to_reveal(dofs: usize, bottom: f64, top: f64) -> usize {
    let (fewest, enough, _) = DEFINITENESS_STEPS;
    if !(bottom > 0.0 && top > bottom) {
        return enough;
    }
    let growth = (2.0 * dofs as f64 * top / bottom).sqrt().max(1.0).acosh();
    let rate = (1.0 + 2.0 * bottom / (top - bottom)).acosh();
    let steps = 1.0 + (growth / rate).ceil();
    if steps.is_finite() {
        (steps as usize).clamp(fewest, enough)
    } else {
        enough
    }
}

/// Whether the symmetric `a`, given by `product` (`out = a v` for `v` zero
/// on the held dofs, zero there too; same free dofs as `mg`'s operator), is
/// positive definite on the free dofs, by the Lanczos
/// iteration on the pencil `(a, M)` with `M^-1` the V-cycle of `mg` (built
/// on a positive definite matrix, so `M` is symmetric positive definite and
/// `M^-1 a` has the inertia of `a`, Sylvester). The smallest Ritz value is
/// a Rayleigh quotient `y.a y / y.M y`: a negative one is a certificate.
/// A positive one is accepted once its residual is small against it and it
/// has settled. Deterministic (fixed start vector, fixed-order sums).
pub(crate) fn definiteness(
    product: &dyn Fn(&[Vec3], &mut [Vec3]),
    mg: &Multigrid,
) -> (Definiteness, f64) {
    let mask = mg.mask();
    let n = mask.len();
    let masked = |v: &mut [Vec3]| zero_held(v, mask);
    let mut v = crate::krylov::start_vector(n);
    masked(&mut v);
    let mut w = vec![Vec3::zeros(); n];
    mg.apply(&v, &mut w);
    masked(&mut w);
    let b0 = dot(&v, &w);
    if !(b0.is_finite() && b0 > 0.0) {
        return (Definiteness::Undecided, f64::NAN);
    }
    let b0 = b0.sqrt();
    v.par_iter_mut().for_each(|x| *x /= b0);
    w.par_iter_mut().for_each(|x| *x /= b0);
    let mut v_prev = vec![Vec3::zeros(); n];
    let mut u = vec![Vec3::zeros(); n];
    let mut z = vec![Vec3::zeros(); n];
    let (mut alpha, mut beta) = (Vec::<f64>::new(), Vec::<f64>::new());
    let mut history: Vec<f64> = Vec::new();
    let dofs = mask.iter().flatten().filter(|m| **m).count();
    for step in 0..DEFINITENESS_STEPS.2 {
        product(&w, &mut u);
        masked(&mut u);
        let al = dot(&w, &u);
        let b_prev = beta.last().copied().unwrap_or(0.0);
        u.par_iter_mut()
            .zip(v.par_iter().zip(v_prev.par_iter()))
            .for_each(|(ui, (vi, vp))| *ui -= vi * al + vp * b_prev);
        alpha.push(al);
        mg.apply(&u, &mut z);
        masked(&mut z);
        let bb = dot(&u, &z);
        let (theta, last) = crate::krylov::extreme_ritz(&alpha, &beta, true);
        if theta <= -DEFINITENESS_MARGIN {
            return (Definiteness::NotPositive, theta);
        }
        let b = if bb.is_finite() && bb > 0.0 {
            bb.sqrt()
        } else {
            0.0
        };
        let residual = (b * last).abs();
        history.push(theta);
        // Ritz values only fall towards the smallest eigenvalue; an outlier
        // below the multigrid's cluster (a softening mode) shows within a
        // few steps, so a value that has stopped moving is the bottom.
        // "Stopped": within 5 % over five steps. At 1 % the test crept
        // down the cluster's continuum (19-25 steps at 64x16x16 and
        // 128x32x32, more the larger the lattice) to a bottom it had
        // already seen to within a few percent, far above the margin.
        let settled =
            history.len() > 5 && (history[history.len() - 6] - theta).abs() <= 5e-2 * theta.abs();
        let revealed = step + 1 >= DEFINITENESS_STEPS.0 && {
            let (top, _) = crate::krylov::extreme_ritz(&alpha, &beta, false);
            step + 1 >= steps_to_reveal(dofs, theta, top)
        };
        let decided = b == 0.0 || (revealed && settled && residual <= 0.1 * theta);
        if decided {
            return if theta > DEFINITENESS_MARGIN {
                (Definiteness::Positive, theta)
            } else {
                (Definiteness::NotPositive, theta)
            };
        }
        beta.push(b);
        std::mem::swap(&mut v_prev, &mut v);
        // v <- u / b, w <- z / b.
        v.par_iter_mut()
            .zip(u.par_iter())
            .for_each(|(vi, ui)| *vi = ui / b);
        w.par_iter_mut()
            .zip(z.par_iter())
            .for_each(|(wi, zi)| *wi = zi / b);
    }
    let theta = history.last().copied().unwrap_or(f64::NAN);
    (Definiteness::Undecided, theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default model (`volumetric-barrier+hg`) on `l`, E = 10 kPa.
    fn default_model(l: &hexmesh::Lattice) -> crate::Model {
        crate::Model::new(
            l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::HourglassControl::new(Box::new(crate::model::VolumetricBarrier), 1.0)
                .unwrap(),
        )
        .unwrap()
    }

    /// The smoothing product gives the same bits on the AVX2 path and the
    /// portable one and for any thread count, and agrees with the `f64`
    /// product of the symmetric part to single precision; the full matrix
    /// rebuilt from the half is that symmetric part.
    #[test]
    fn smoothing_product_is_the_same_on_every_path() {
        let l = hexmesh::Lattice::block([5, 4, 3], 0.1, [0.0; 3]).unwrap();
        let mut a = BlockCsr::lattice_pattern(l.num_nodes(), l.cells());
        let mut seed = 3u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        for b in &mut a.blocks {
            *b = Mat3::from_fn(|_, _| noise());
        }
        let x: Vec<Vec3> = (0..a.num_rows())
            .map(|_| Vec3::new(noise(), noise(), noise()))
            .collect();
        let half = HalfMatrix::symmetric_part_of(&a);
        let mut sym = a.clone();
        for i in 0..a.num_rows() {
            for k in a.row_offsets[i] as usize..a.row_offsets[i + 1] as usize {
                let j = a.col_indices[k] as usize;
                sym.blocks[k] = (a.blocks[k] + a.blocks[a.find(j, i).unwrap()].transpose()) * 0.5;
            }
        }
        let full = half.to_full();
        assert_eq!(full.row_offsets, a.row_offsets);
        assert_eq!(full.col_indices, a.col_indices);
        for (f, e) in full.blocks.iter().zip(&sym.blocks) {
            assert!((f - e).amax() <= 1e-7, "{f} vs {e}");
        }
        let mut fast = vec![Vec3::zeros(); x.len()];
        half.mul(&x, &mut fast);
        let mut portable = vec![Vec3::zeros(); x.len()];
        half_mul_rows(&half, &x, &mut portable, 0);
        let mut threaded = vec![Vec3::zeros(); x.len()];
        crate::on_threads(3, || half.mul(&x, &mut threaded));
        let mut exact = vec![Vec3::zeros(); x.len()];
        mul(&sym, &x, &mut exact);
        for (((f, p), t), e) in fast.iter().zip(&portable).zip(&threaded).zip(&exact) {
            for d in 0..3 {
                assert_eq!(f[d].to_bits(), p[d].to_bits());
                assert_eq!(f[d].to_bits(), t[d].to_bits());
                assert!((f[d] - e[d]).abs() <= 1e-6 * 27.0 * 3.0, "{f} vs {e}");
            }
        }
    }

    /// The rest stiffness of a lattice has few distinct blocks: its half is
    /// stored once per distinct block, and multiplies (and gives its blocks)
    /// with the same bits as the whole half, on every path and thread
    /// count; a deformed stiffness, whose blocks all differ, stays whole.
    #[test]
    fn repeated_blocks_are_stored_once_with_the_same_products() {
        let l = hexmesh::Lattice::block([24, 12, 12], 0.01, [0.3, -0.2, 0.1]).unwrap();
        let model = default_model(&l);
        let rest = model.rest_positions();
        let mask: Vec<[bool; 3]> = rest.iter().map(|p| [p.x > 0.3 + 1e-9; 3]).collect();
        let mut whole = HalfMatrix::from_upper(model.symmetric_stiffness_upper(rest));
        whole.decouple(&mask);
        let blocks = whole.pattern.upper.col_indices.len();
        assert!(blocks >= SHARE_MIN_BLOCKS, "{blocks}");
        let mut shared = whole.clone();
        shared.share_repeated_blocks();
        let distinct = shared.shared.as_ref().map(|s| s.distinct.len() / 9);
        assert!(
            distinct.is_some_and(|d| d <= 100),
            "{distinct:?} of {blocks}"
        );
        assert!(shared.blocks.is_empty());
        for k in 0..blocks {
            assert_eq!(whole.block(k), shared.block(k), "block {k}");
        }
        let x: Vec<Vec3> = (0..rest.len())
            .map(|i| {
                let t = i as f64;
                Vec3::new((0.7 * t).sin(), (1.3 * t).cos(), (0.4 * t).sin() - 0.2)
            })
            .collect();
        let product = |a: &HalfMatrix, threads: usize| {
            let mut y = vec![Vec3::zeros(); x.len()];
            crate::on_threads(threads, || a.mul(&x, &mut y));
            y
        };
        let expected = product(&whole, 1);
        let mut portable = vec![Vec3::zeros(); x.len()];
        half_mul_rows(&shared, &x, &mut portable, 0);
        for got in [product(&shared, 1), product(&shared, 2), portable] {
            assert!(
                got.iter()
                    .zip(&expected)
                    .all(|(a, b)| (0..3).all(|d| a[d].to_bits() == b[d].to_bits()))
            );
        }
        // Deformed: every cell's matrix its own.
        let bent: Vec<Vec3> = rest
            .iter()
            .map(|p| p + Vec3::new(0.01 * (40.0 * p.z).sin(), 0.0, 0.02 * (30.0 * p.x).sin()))
            .collect();
        let mut deformed = HalfMatrix::from_upper(model.symmetric_stiffness_upper(&bent));
        deformed.share_repeated_blocks();
        assert!(deformed.shared.is_none());
    }

    /// A pattern that lacks the mirror of some blocks (contact may add one
    /// side only) loses nothing: the half holds `(A + A^T) / 2` whole.
    #[test]
    fn the_symmetric_half_of_a_structurally_asymmetric_matrix_is_whole() {
        let m = |v: f64| Mat3::from_fn(|e, d| v + (3 * e + d) as f64);
        // Blocks (0, 2) and (2, 1) have no mirror.
        let a = BlockCsr {
            row_offsets: vec![0, 2, 3, 5],
            col_indices: vec![0, 2, 1, 1, 2],
            blocks: vec![m(10.0), m(1.0), m(20.0), m(-2.0), m(30.0)],
        };
        let full = HalfMatrix::symmetric_part_of(&a).to_full();
        let dense =
            |b: &BlockCsr, i: usize, j: usize| b.find(i, j).map_or(Mat3::zeros(), |k| b.blocks[k]);
        for i in 0..3 {
            for j in 0..3 {
                let expected = (dense(&a, i, j) + dense(&a, j, i).transpose()) * 0.5;
                assert!((dense(&full, i, j) - expected).amax() <= 1e-5, "({i}, {j})");
            }
        }
    }

    /// The Lanczos test stops earlier the better the bottom of the spectrum
    /// is separated from zero, needs more steps for more dofs, and never
    /// more than the fixed count it used to take.
    #[test]
    fn steps_to_reveal_follow_the_lanczos_bound() {
        let (fewest, enough, _) = DEFINITENESS_STEPS;
        let paper = steps_to_reveal(421_443, 0.64, 1.5);
        let default = steps_to_reveal(421_443, 0.19, 1.5);
        assert!(paper < default, "{paper} vs {default}");
        assert!(steps_to_reveal(50_000, 0.19, 1.5) <= default);
        assert!(default <= steps_to_reveal(3_000_000, 0.19, 1.5));
        for (dofs, bottom) in [(10, 0.9), (1 << 30, 1e-3), (1000, 0.0), (1000, -1.0)] {
            let k = steps_to_reveal(dofs, bottom, 1.5);
            assert!((fewest..=enough).contains(&k), "{dofs} {bottom}: {k}");
        }
        assert_eq!(steps_to_reveal(1000, 0.0, 1.5), enough);
    }

    /// A negative eigenvalue localized at one node (a component softened
    /// below zero), which the start vector hardly contains, is found before
    /// the test stops; the unsoftened matrix is positive definite.
    #[test]
    fn definiteness_finds_a_localized_negative_direction() {
        let l = hexmesh::Lattice::block([16, 8, 8], 0.01, [0.0; 3]).unwrap();
        let model = default_model(&l);
        let rest = model.rest_positions();
        let free: Vec<bool> = rest.iter().flat_map(|p| [p.x > 1e-9; 3]).collect();
        let shape = HierarchyShape::new(l.cells(), &model.grid_coords(), &free, false);
        let k0 = model.rest_stiffness();
        let mg = Multigrid::new(Operator::from_owned(k0.clone(), &free), &shape, false).unwrap();
        let middle = rest
            .iter()
            .position(|p| (p - Vec3::new(0.1, 0.04, 0.04)).norm() < 1e-9)
            .unwrap();
        for softening in [0.0, 1.0005, 1.002, 1.01, 1.05, 1.5] {
            let mut k = k0.clone();
            let d = k.find(middle, middle).unwrap();
            k.blocks[d][(1, 1)] *= 1.0 - softening;
            let op = Operator::from_owned(k, &free);
            let product = |v: &[Vec3], out: &mut [Vec3]| mul(op.matrix(), v, out);
            let (verdict, theta) = definiteness(&product, &mg);
            let expected = if softening > 1.0 {
                Definiteness::NotPositive
            } else {
                Definiteness::Positive
            };
            assert_eq!(verdict, expected, "softening {softening}: theta {theta:e}");
        }
    }

    /// The first prolongation of an enriched hierarchy carries the lattice's
    /// three mechanisms: constant companion amplitudes give each fine node
    /// its hourglass signs, a field the springs-only model does not resist,
    /// and the grid's coarse space alone does not contain it.
    #[test]
    fn companions_prolong_to_the_lattice_mechanisms() {
        let l = hexmesh::Lattice::block([12, 10, 10], 0.05, [0.0; 3]).unwrap();
        let model = crate::Model::new(
            &l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::SpringsOnly,
        )
        .unwrap();
        assert!(!model.resists_mechanisms());
        let coords = model.grid_coords();
        let free = vec![true; 3 * l.num_nodes()];
        let shape = HierarchyShape::new(l.cells(), &coords, &free, true);
        let p = &shape.prolongations[0];
        let nc = shape.first_companions[0] as usize;
        assert_eq!(shape.coarse_patterns[0].num_rows(), 2 * nc);
        let mut coarse = vec![Vec3::zeros(); 2 * nc];
        coarse[nc..].iter_mut().for_each(|v| *v = Vec3::repeat(1.0));
        let mask = vec![[true; 3]; l.num_nodes()];
        let mut fine = vec![Vec3::zeros(); l.num_nodes()];
        prolong_add(p, &mask, &coarse, &mut fine);
        for (u, g) in fine.iter().zip(&coords) {
            assert_eq!(*u, hourglass_signs(*g));
        }
        let k = model.rest_stiffness();
        let mut force = vec![Vec3::zeros(); fine.len()];
        mul(&k, &fine, &mut force);
        let scale = k.blocks.iter().map(|b| b.abs().max()).fold(0.0, f64::max);
        let largest = force.iter().map(|f| f.abs().max()).fold(0.0, f64::max);
        assert!(largest <= 1e-12 * scale, "{largest:e} of {scale:e}");
        // The same amplitudes with hourglass control are resisted.
        let hg = crate::Model::new(
            &l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::HourglassControl::new(Box::new(crate::model::SpringsOnly), 0.05)
                .unwrap(),
        )
        .unwrap();
        assert!(hg.resists_mechanisms());
        mul(&hg.rest_stiffness(), &fine, &mut force);
        let largest = force.iter().map(|f| f.abs().max()).fold(0.0, f64::max);
        assert!(largest > 1e-3 * scale, "{largest:e} of {scale:e}");
        // Without enrichment the coarse level has the grid's nodes only.
        let plain = HierarchyShape::new(l.cells(), &coords, &free, false);
        assert_eq!(plain.coarse_patterns[0].num_rows(), nc);
        assert_eq!(plain.first_companions[0], u32::MAX);
    }
}
