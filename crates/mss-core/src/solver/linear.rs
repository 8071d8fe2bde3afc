//! Sparse LU solve of a [`BlockCsr`] system restricted to the free dofs.

use faer::Mat;
use faer::prelude::Solve;
use faer::sparse::{SparseColMat, Triplet};

use crate::{BlockCsr, Vec3};

/// Why a linear solve failed.
#[derive(Debug, Clone)]
pub(crate) enum LinearFailure {
    /// The matrix is singular (or nearly): the solution is not finite, far too
    /// large, or does not satisfy the system. `nodes` are the nodes with the
    /// largest solution components (the ones a mechanism moves).
    Singular { nodes: Vec<u32> },
    /// faer refused the matrix (out of memory, index overflow).
    Other(String),
}

/// Solves `A y = b` on the free dofs (`free[3 n + d]`); held components of
/// `y` are zero. `size` is a length scale of the body (m): a solution larger
/// than `1e6 size` is taken as a sign of a singular matrix.
pub(crate) fn solve_free(
    a: &BlockCsr,
    b: &[Vec3],
    free: &[bool],
    size: f64,
) -> Result<Vec<Vec3>, LinearFailure> {
    let n = a.num_rows();
    let mut index = vec![usize::MAX; 3 * n];
    let mut m = 0;
    for (i, f) in free.iter().enumerate() {
        if *f {
            index[i] = m;
            m += 1;
        }
    }
    let mut y = vec![Vec3::zeros(); n];
    if m == 0 {
        return Ok(y);
    }
    let mut trip = Vec::with_capacity(a.blocks.len() * 9);
    for r in 0..n {
        for k in a.row_offsets[r] as usize..a.row_offsets[r + 1] as usize {
            let c = a.col_indices[k] as usize;
            let blk = &a.blocks[k];
            for e in 0..3 {
                let ri = index[3 * r + e];
                if ri == usize::MAX {
                    continue;
                }
                for d in 0..3 {
                    let ci = index[3 * c + d];
                    if ci != usize::MAX {
                        trip.push(Triplet::new(ri, ci, blk[(e, d)]));
                    }
                }
            }
        }
    }
    let mat = SparseColMat::<usize, f64>::try_new_from_triplets(m, m, &trip)
        .map_err(|e| LinearFailure::Other(format!("{e:?}")))?;
    let mut rhs = Mat::<f64>::zeros(m, 1);
    for (i, &k) in index.iter().enumerate() {
        if k != usize::MAX {
            rhs[(k, 0)] = b[i / 3][i % 3];
        }
    }
    crate::sparse::sequential_factorizations();
    let lu = match mat.sp_lu() {
        Ok(lu) => lu,
        Err(faer::sparse::linalg::LuError::SymbolicSingular { .. }) => {
            return Err(LinearFailure::Singular { nodes: Vec::new() });
        }
        Err(e) => return Err(LinearFailure::Other(format!("{e:?}"))),
    };
    let mut sol = lu.solve(&rhs);
    // Iterative refinement: a few residual corrections with the same factors
    // recover the accuracy that pivoting on ill-conditioned lattices loses.
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let ax = &mat * &sol;
        let r = &rhs - &ax;
        let rn = r.norm_l2();
        if !(rn.is_finite() && rn < 0.5 * best) {
            break;
        }
        best = rn;
        let corr = lu.solve(&r);
        sol += &corr;
    }
    let mut worst = 0.0f64;
    for (i, &k) in index.iter().enumerate() {
        if k != usize::MAX {
            let v = sol[(k, 0)];
            y[i / 3][i % 3] = v;
            worst = if v.is_finite() {
                worst.max(v.abs())
            } else {
                f64::INFINITY
            };
        }
    }
    // A singular matrix factors with round-off pivots and gives a huge, or
    // inaccurate, solution: check both.
    let mut singular = worst.is_nan() || worst > 1e6 * size;
    if !singular {
        let mut ay = vec![Vec3::zeros(); n];
        a.mul_vec(&y, &mut ay);
        let (mut res, mut nb) = (0.0f64, 0.0f64);
        for (i, f) in free.iter().enumerate() {
            if *f {
                res += (ay[i / 3][i % 3] - b[i / 3][i % 3]).powi(2);
                nb += b[i / 3][i % 3].powi(2);
            }
        }
        singular = res.sqrt() > 1e-6 * nb.sqrt();
    }
    if singular {
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mag = |i: u32| {
            let v = y[i as usize].norm();
            if v.is_finite() { v } else { f64::INFINITY }
        };
        order.sort_by(|&p, &q| mag(q).total_cmp(&mag(p)));
        order.truncate(8);
        return Err(LinearFailure::Singular { nodes: order });
    }
    Ok(y)
}
