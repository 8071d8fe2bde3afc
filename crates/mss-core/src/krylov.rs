//! Pieces shared by the Lanczos iterations of the frequency estimate
//! ([`model::frequency`](crate::model)) and of the multigrid's smoother
//! bounds ([`solver::multigrid`](crate::solver::multigrid)): a dot product
//! whose bits do not depend on the thread count, the fixed start vector,
//! and the extreme Ritz value of the tridiagonal matrix. Both users depend
//! on this module and it on neither.

use rayon::prelude::*;

use crate::Vec3;

/// Entries per partial sum of [`dot`]: fixed, so that the sum's order (and
/// its rounding) is the same for any thread count.
const CHUNK: usize = 2048;

/// `a . b` summed in fixed chunks, in order: the same bits for any thread count.
pub(crate) fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    let partial: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p.dot(q)).sum::<f64>())
        .collect();
    partial.iter().sum()
}

/// The largest (or, with `smallest`, the smallest) eigenvalue of the
/// symmetric tridiagonal matrix of a Lanczos iteration (`alpha` on the
/// diagonal, `beta` beside it) and the last component of its eigenvector,
/// whose product with the next `beta` is the Ritz pair's residual norm.
pub(crate) fn extreme_ritz(alpha: &[f64], beta: &[f64], smallest: bool) -> (f64, f64) {
    let m = alpha.len();
    let t = nalgebra::DMatrix::<f64>::from_fn(m, m, |i, j| {
        if i == j {
            alpha[i]
        } else if i + 1 == j {
            beta[i]
        } else if j + 1 == i {
            beta[j]
        } else {
            0.0
        }
    });
    let eig = nalgebra::SymmetricEigen::new(t);
    let order = |a: &(usize, &f64), b: &(usize, &f64)| {
        if smallest {
            b.1.total_cmp(a.1)
        } else {
            a.1.total_cmp(b.1)
        }
    };
    let (k, &theta) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(order)
        .expect("at least one Lanczos step");
    (theta, eig.eigenvectors[(m - 1, k)])
}

/// A fixed, rough start vector for `n` nodes (a hash of the index): it has
/// components along every mode, the localized ones included.
pub(crate) fn start_vector(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            Vec3::from_fn(|d, _| {
                let s = ((3 * i + d) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
                s as f64 / (1u64 << 24) as f64 - 0.5
            })
        })
        .collect()
}
