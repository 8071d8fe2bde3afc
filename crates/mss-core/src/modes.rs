//! Mechanism detection: zero-energy modes of the rest stiffness left free by
//! the constraints.
//!
//! The M2 lattice (edges and body diagonals) of any block has 9 zero-energy
//! modes: 6 rigid motions and 3 hourglass mechanisms. Clamping a face removes
//! them; fixing a few nodes may not. A static solve of a model with mechanisms
//! is singular, and a dynamic one drifts.
//!
//! Small systems are decided exactly by the dense symmetric eigenvalues of the
//! restricted rest stiffness. Large ones by block inverse (subspace) iteration
//! with a sparse Cholesky factorization of `K_ff + sigma I` (sigma tiny): zero
//! modes are amplified by `1 / sigma`, the others by at most `1 / lambda_1`, so
//! a few iterations and a Rayleigh-Ritz step separate them. The count is exact
//! up to the block size ([`SUBSPACE_SIZE`] - 1).
//!
//! Models whose cells are rigid when undistorted (every model with hourglass
//! control, the default) need no matrix at all: their mechanisms are those of
//! a linkage of rigid bodies, counted exactly in time linear in the cells
//! ([`zero_energy_modes_rigid_cells`], module docs of its file). On a
//! 2-million-cell block it takes seconds where the factorization took
//! minutes and 20 GB.

use nalgebra::{DMatrix, SymmetricEigen};
use thiserror::Error;

use crate::Model;
use crate::sparse::LinearSolveError;

mod rigid_cells;
pub use rigid_cells::{MAX_GROUP_BODIES, cells_are_rigid, zero_energy_modes_rigid_cells};

/// Why the mode count failed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ModesError {
    /// The fixed mask does not have one entry per node.
    #[error("fixed mask has {given} entries for {nodes} nodes")]
    Shape {
        /// Entries given.
        given: usize,
        /// Nodes of the model.
        nodes: usize,
    },
    /// The sparse factorization failed.
    #[error(transparent)]
    Linear(#[from] LinearSolveError),
    /// The factorization would need more memory than allowed.
    #[error(
        "mechanism check skipped: the sparse factorization would need {needed} MB (limit {limit} MB); coarsen the lattice or raise the limit"
    )]
    TooLarge {
        /// Memory needed (MB).
        needed: usize,
        /// Limit (MB).
        limit: usize,
    },
}

/// Result of a zero-energy mode search.
#[derive(Debug, Clone, PartialEq)]
pub struct ZeroModes {
    /// Number of zero-energy modes found on the free dofs.
    pub count: usize,
    /// False when the count reached the search's capacity: there may be more.
    pub exact: bool,
    /// `"dense"`, `"subspace"` or `"rigid cells"`.
    pub method: &'static str,
    /// The smallest eigenvalues of the restricted rest stiffness found,
    /// relative to its largest diagonal entry, ascending (empty for the
    /// `"rigid cells"` count, which does not compute them).
    pub smallest_relative: Vec<f64>,
}

impl ZeroModes {
    /// True when mechanisms remain.
    pub fn has_mechanisms(&self) -> bool {
        self.count > 0
    }
}

/// Free dofs up to which the dense eigenvalue method is used.
pub const DENSE_LIMIT: usize = 1200;
/// Block size of the subspace iteration.
pub const SUBSPACE_SIZE: usize = 16;
/// Largest Cholesky factor (bytes) the subspace method builds.
pub const MAX_FACTOR_BYTES: usize = 2 << 30;
/// Eigenvalues below this fraction of the largest diagonal entry count as zero.
pub const ZERO_THRESHOLD: f64 = 1e-9;

/// Number of zero-energy modes with whole nodes fixed (`fixed[node]`). A lower
/// bound when there are more than [`SUBSPACE_SIZE`] - 1 of them in a large model.
pub fn count_zero_energy_modes(model: &Model, fixed: &[bool]) -> Result<usize, ModesError> {
    let mask: Vec<[bool; 3]> = fixed.iter().map(|&f| [f; 3]).collect();
    zero_energy_modes(model, &mask).map(|z| z.count)
}

/// Zero-energy modes with individual dofs fixed (`fixed[node][axis]`): dense
/// for small systems; otherwise the rigid-cell count where the cells are
/// rigid ([`cells_are_rigid`]), else subspace iteration.
pub fn zero_energy_modes(model: &Model, fixed: &[[bool; 3]]) -> Result<ZeroModes, ModesError> {
    check(model, fixed)?;
    let free = fixed.iter().flatten().filter(|&&f| !f).count();
    if free <= DENSE_LIMIT {
        return zero_energy_modes_dense(model, fixed);
    }
    if cells_are_rigid(model)
        && let Some(z) = zero_energy_modes_rigid_cells(model, fixed)
    {
        return Ok(z);
    }
    zero_energy_modes_subspace(model, fixed)
}

fn check(model: &Model, fixed: &[[bool; 3]]) -> Result<(), ModesError> {
    if fixed.len() != model.num_nodes() {
        return Err(ModesError::Shape {
            given: fixed.len(),
            nodes: model.num_nodes(),
        });
    }
    Ok(())
}

/// Exact count from all eigenvalues of the dense restricted rest stiffness.
pub fn zero_energy_modes_dense(
    model: &Model,
    fixed: &[[bool; 3]],
) -> Result<ZeroModes, ModesError> {
    check(model, fixed)?;
    let k = model.rest_stiffness();
    let scale = k.max_diagonal();
    let index: Vec<Option<usize>> = {
        let mut next = 0;
        fixed
            .iter()
            .flatten()
            .map(|&f| {
                (!f).then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let free = index.iter().flatten().count();
    if free == 0 {
        // Every dof held: nothing can move, so nothing is a mechanism.
        return Ok(ZeroModes {
            count: 0,
            exact: true,
            method: "dense",
            smallest_relative: Vec::new(),
        });
    }
    let mut dense = DMatrix::<f64>::zeros(free, free);
    for i in 0..k.num_rows() {
        for kk in k.row_offsets[i] as usize..k.row_offsets[i + 1] as usize {
            let j = k.col_indices[kk] as usize;
            for e in 0..3 {
                for d in 0..3 {
                    if let (Some(r), Some(c)) = (index[3 * i + e], index[3 * j + d]) {
                        dense[(r, c)] = k.blocks[kk][(e, d)];
                    }
                }
            }
        }
    }
    let mut ev: Vec<f64> = SymmetricEigen::new(dense)
        .eigenvalues
        .iter()
        .map(|&v| v / scale)
        .collect();
    ev.sort_by(f64::total_cmp);
    let count = ev.iter().filter(|&&v| v < ZERO_THRESHOLD).count();
    ev.truncate(SUBSPACE_SIZE.max(count + 1));
    Ok(ZeroModes {
        count,
        exact: true,
        method: "dense",
        smallest_relative: ev,
    })
}

/// Count by block inverse iteration with a sparse Cholesky factorization; for
/// large models (seconds for 10^5 nodes).
pub fn zero_energy_modes_subspace(
    model: &Model,
    fixed: &[[bool; 3]],
) -> Result<ZeroModes, ModesError> {
    check(model, fixed)?;
    let k = model.rest_stiffness();
    let scale = k.max_diagonal();
    let kff = k.to_faer_free(fixed, false)?;
    let n = kff.nrows();
    let p = SUBSPACE_SIZE.min(n);
    let needed = k.cholesky_factor_bytes(fixed)?;
    if needed > MAX_FACTOR_BYTES {
        return Err(ModesError::TooLarge {
            needed: needed >> 20,
            limit: MAX_FACTOR_BYTES >> 20,
        });
    }
    let mut shifted = k;
    shifted.add_diagonal(1e-10 * scale);
    let fac = shifted.factor_cholesky(fixed)?;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut q = faer::Mat::<f64>::from_fn(n, p, |_, _| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    });
    orthonormalize(&mut q);
    for _ in 0..4 {
        q = fac.solve_free(q.as_ref());
        orthonormalize(&mut q);
    }
    // Rayleigh-Ritz on span(q).
    let kq = &kff * &q;
    let h = q.transpose() * &kq;
    let small = DMatrix::<f64>::from_fn(p, p, |i, j| 0.5 * (h[(i, j)] + h[(j, i)]));
    let mut ev: Vec<f64> = SymmetricEigen::new(small)
        .eigenvalues
        .iter()
        .map(|&v| v / scale)
        .collect();
    ev.sort_by(f64::total_cmp);
    let count = ev.iter().filter(|&&v| v < ZERO_THRESHOLD).count();
    Ok(ZeroModes {
        count,
        exact: count < p,
        method: "subspace",
        smallest_relative: ev,
    })
}

/// Modified Gram-Schmidt on the columns (twice, for stability).
fn orthonormalize(q: &mut faer::Mat<f64>) {
    let (n, p) = (q.nrows(), q.ncols());
    for _ in 0..2 {
        for j in 0..p {
            for i in 0..j {
                let d: f64 = (0..n).map(|r| q[(r, i)] * q[(r, j)]).sum();
                for r in 0..n {
                    let v = q[(r, i)];
                    q[(r, j)] -= d * v;
                }
            }
            let norm = (0..n).map(|r| q[(r, j)].powi(2)).sum::<f64>().sqrt();
            // A column that vanished (more columns than dofs) is left as is.
            if norm > 0.0 {
                for r in 0..n {
                    q[(r, j)] /= norm;
                }
            }
        }
    }
}
