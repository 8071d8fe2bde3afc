//! Sparse LU solve of a [`BlockCsr`] system restricted to the free dofs, with
//! the symbolic analysis kept per sparsity pattern (`LuCache`).

use faer::Mat;
use faer::prelude::Solve;
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};

use crate::sparse::DofMap;
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

/// The restricted (free-dof) scalar pattern of a [`BlockCsr`] and its
/// symbolic LU factorization (COLAMD column ordering, elimination tree,
/// supernodes), computed once per pattern and reused for every matrix with the
/// same block pattern and free mask: Newton iterations then only scatter the
/// values and refactor numerically.
///
/// The pattern, and therefore the ordering, depends only on the lattice and the
/// free mask, so the factors (and the results) are the same as with a fresh
/// symbolic analysis per matrix, for any thread count.
pub(crate) struct LuCache {
    row_offsets: Vec<u32>,
    col_indices: Vec<u32>,
    free: Vec<bool>,
    /// Numbering of the free dofs.
    dofs: DofMap,
    /// Free dofs.
    m: usize,
    /// Compressed-column structure of the restricted matrix.
    symbolic: Option<SymbolicSparseColMat<usize>>,
    /// Copies of the structure's column starts and row indices.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Source of each stored value: `9 * block + 3 * e + d`.
    source: Vec<u32>,
    lu_symbolic: Option<SymbolicLu<usize>>,
    /// Symbolic analyses done (shown by `Debug`).
    analyses: u32,
    /// The last numeric factorization (of the cached pattern), kept to
    /// precondition later matrices of the same pattern, and the values of
    /// the matrix it factors (for [`LinearSolver::kept_factors`]).
    kept: Option<(Lu<usize, f64>, Vec<f64>)>,
    /// [`pattern_key`] of the cached pattern.
    key: u64,
    /// A matrix to factor as the kept one when the next solve's pattern
    /// has this key ([`LinearSolver::restore_kept_factors`]).
    pending: Option<(u64, Vec<f64>)>,
    /// Numeric factorizations done, and solves the kept one served.
    factorizations: u32,
    kept_solves: u32,
}

impl std::fmt::Debug for LuCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LuCache")
            .field("free_dofs", &self.m)
            .field("analyses", &self.analyses)
            .field("factorizations", &self.factorizations)
            .field("kept_solves", &self.kept_solves)
            .finish()
    }
}

impl LuCache {
    pub(crate) fn new() -> Self {
        Self {
            row_offsets: Vec::new(),
            col_indices: Vec::new(),
            free: Vec::new(),
            dofs: DofMap::from_free(&[]),
            m: 0,
            symbolic: None,
            col_ptr: Vec::new(),
            row_idx: Vec::new(),
            source: Vec::new(),
            lu_symbolic: None,
            analyses: 0,
            kept: None,
            key: 0,
            pending: None,
            factorizations: 0,
            kept_solves: 0,
        }
    }

    /// Makes the cached pattern that of `a` restricted to `free`.
    fn prepare(&mut self, a: &BlockCsr, free: &[bool]) -> Result<(), LinearFailure> {
        if self.symbolic.is_some()
            && self.row_offsets == a.row_offsets
            && self.col_indices == a.col_indices
            && self.free == free
        {
            return Ok(());
        }
        let n = a.num_rows();
        let dofs = DofMap::from_free(free);
        let m = dofs.num_free();
        // (column, row, source) of every free-free entry, sorted by column
        // then row: the compressed-column order.
        let mut entries: Vec<(usize, usize, u32)> = Vec::with_capacity(a.blocks.len() * 9);
        for r in 0..n {
            for k in a.row_offsets[r] as usize..a.row_offsets[r + 1] as usize {
                let c = a.col_indices[k] as usize;
                for e in 0..3 {
                    let Some(ri) = dofs.free_index(3 * r + e) else {
                        continue;
                    };
                    for d in 0..3 {
                        if let Some(ci) = dofs.free_index(3 * c + d) {
                            entries.push((ci, ri, (9 * k + 3 * e + d) as u32));
                        }
                    }
                }
            }
        }
        entries.sort_unstable();
        let mut col_ptr = vec![0usize; m + 1];
        for &(c, _, _) in &entries {
            col_ptr[c + 1] += 1;
        }
        for j in 0..m {
            col_ptr[j + 1] += col_ptr[j];
        }
        let row_idx: Vec<usize> = entries.iter().map(|&(_, r, _)| r).collect();
        let source: Vec<u32> = entries.iter().map(|&(_, _, s)| s).collect();
        let symbolic =
            SymbolicSparseColMat::new_checked(m, m, col_ptr.clone(), None, row_idx.clone());
        let lu_symbolic = if m > 0 {
            crate::sparse::sequential_factorizations();
            Some(
                SymbolicLu::try_new(symbolic.as_ref())
                    .map_err(|e| LinearFailure::Other(format!("{e:?}")))?,
            )
        } else {
            None
        };
        self.row_offsets.clone_from(&a.row_offsets);
        self.col_indices.clone_from(&a.col_indices);
        self.free = free.to_vec();
        self.dofs = dofs;
        self.m = m;
        self.symbolic = Some(symbolic);
        self.col_ptr = col_ptr;
        self.row_idx = row_idx;
        self.source = source;
        self.lu_symbolic = lu_symbolic;
        self.kept = None;
        self.key = pattern_key(a, free);
        self.analyses += 1;
        Ok(())
    }
}

/// Relative residual to which a solve on kept factors iterates.
const KEPT_RTOL: f64 = 1e-10;
/// Most corrections of a solve on kept factors.
const KEPT_MAX_CORRECTIONS: usize = 8;
/// Largest residual contraction per correction for which a solve goes on with
/// kept factors rather than factoring its own matrix.
const KEPT_MAX_CONTRACTION: f64 = 0.25;

/// Solves `A y = b` on the free dofs (`free[3 n + d]`); held components of
/// `y` are zero. `size` is a length scale of the body (m): a solution larger
/// than `1e6 size` is taken as a sign of a singular matrix. The symbolic
/// analysis of `cache` is reused when `a` has its pattern.
pub(crate) fn solve_free(
    cache: &mut LuCache,
    a: &BlockCsr,
    b: &[Vec3],
    free: &[bool],
    size: f64,
) -> Result<Vec<Vec3>, LinearFailure> {
    let n = a.num_rows();
    cache.prepare(a, free)?;
    let mut kept = cache.kept.take();
    let pending = cache.pending.take();
    let m = cache.m;
    let dofs = &cache.dofs;
    let mut y = vec![Vec3::zeros(); n];
    if m == 0 {
        return Ok(y);
    }
    let values: Vec<f64> = cache
        .source
        .iter()
        .map(|&s| {
            let s = s as usize;
            a.blocks[s / 9][((s % 9) / 3, s % 3)]
        })
        .collect();
    let (Some(pattern), Some(lu_symbolic)) = (&cache.symbolic, &cache.lu_symbolic) else {
        return Err(LinearFailure::Other(
            "missing symbolic factorization".into(),
        ));
    };
    let factor = |values: &[f64]| {
        crate::sparse::sequential_factorizations();
        Lu::try_new_with_symbolic(
            lu_symbolic.clone(),
            SparseColMatRef::new(pattern.as_ref(), values),
        )
    };
    // A checkpoint's kept factors, made again for the pattern they were
    // kept for.
    if let Some((key, values)) = pending
        && key == cache.key
        && values.len() == cache.source.len()
    {
        kept = factor(&values).ok().map(|lu| (lu, values));
    }
    let mut rhs = Mat::<f64>::zeros(m, 1);
    for (i, k) in dofs.free_dofs() {
        rhs[(k, 0)] = b[i / 3][i % 3];
    }
    let residual = |x: &Mat<f64>| {
        let mut r = rhs.clone();
        for j in 0..m {
            let xj = x[(j, 0)];
            for p in cache.col_ptr[j]..cache.col_ptr[j + 1] {
                r[(cache.row_idx[p], 0)] -= values[p] * xj;
            }
        }
        r
    };
    // Richardson iteration preconditioned by the kept factors: worth it
    // while it contracts fast, since a factorization costs some twenty of
    // its iterations. Factors that do not serve are dropped before new ones
    // are made: never two alive at once.
    let on_kept = |lu: &Lu<usize, f64>| {
        let tol = KEPT_RTOL * rhs.norm_l2();
        let mut x = lu.solve(&rhs);
        let mut previous = rhs.norm_l2();
        for _ in 0..KEPT_MAX_CORRECTIONS {
            let r = residual(&x);
            let rn = r.norm_l2();
            if !rn.is_finite() || rn > KEPT_MAX_CONTRACTION * previous {
                return None;
            }
            if rn <= tol {
                return Some(x);
            }
            previous = rn;
            x += lu.solve(&r);
        }
        None
    };
    let served = kept.and_then(|kept| on_kept(&kept.0).map(|sol| (sol, kept)));
    let (sol, kept, factored) = match served {
        Some((sol, kept)) => (sol, kept, false),
        None => {
            let lu = match factor(&values) {
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
                let r = residual(&sol);
                let rn = r.norm_l2();
                if !(rn.is_finite() && rn < 0.5 * best) {
                    break;
                }
                best = rn;
                let corr = lu.solve(&r);
                sol += &corr;
            }
            (sol, (lu, values), true)
        }
    };
    let mut worst = 0.0f64;
    for (i, k) in dofs.free_dofs() {
        let v = sol[(k, 0)];
        y[i / 3][i % 3] = v;
        worst = if v.is_finite() {
            worst.max(v.abs())
        } else {
            f64::INFINITY
        };
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
    if factored {
        cache.factorizations += 1;
    } else {
        cache.kept_solves += 1;
    }
    cache.kept = Some(kept);
    Ok(y)
}

/// A fingerprint (FNV-1a) of a block pattern and free mask, stable across
/// builds: a checkpoint's kept factors are put back only for their pattern.
fn pattern_key(a: &BlockCsr, free: &[bool]) -> u64 {
    let words = a
        .row_offsets
        .iter()
        .chain(&a.col_indices)
        .copied()
        .chain(free.iter().map(|&f| u32::from(f)));
    crate::fnv1a(words.flat_map(u32::to_le_bytes))
}

/// Which linear solver the Newton steps use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolverKind {
    /// Direct up to [`DIRECT_MAX_FREE_DOFS`] free dofs, multigrid-preconditioned
    /// Krylov above (default).
    #[default]
    Auto,
    /// Sparse LU, whatever the size (memory and time grow fast in 3D).
    Direct,
    /// Multigrid-preconditioned conjugate gradients (symmetric tangent) or
    /// BiCGStab (non-symmetric), whatever the size.
    Iterative,
}

/// Largest number of free dofs that [`LinearSolverKind::Auto`] solves
/// directly. Measured on the small-load cantilever (paper's model, one
/// thread, `examples/static_scaling.rs`): the two cost the same at 24x6x6
/// (1,225 nodes, 0.10 s); at 32x8x8 the LU takes 0.39 s and 150 MiB against
/// 0.28 s and 35 MiB, at 48x12x12 3.6 s and 879 MiB against 1.0 s and 75 MiB.
/// The LU's fill-in makes its cost grow as nodes^2 while multigrid stays
/// near-linear.
pub const DIRECT_MAX_FREE_DOFS: usize = 4_000;

/// Largest problem (free dofs) that falls back to the direct solver when the
/// iterative one stalls (about 1 GB of LU factors).
pub(crate) const FALLBACK_MAX_FREE_DOFS: usize = 30_000;

/// A kept hierarchy is stale for a new operator that takes more than
/// `STALE_GROWTH` times the Krylov iterations the solve that built it would
/// have taken to the new solve's accuracy (its iterations per decade of
/// residual, times the decades asked for), plus `STALE_SLACK`
/// ([`LinearSolver::solve_with_new_action`]): a new set-up then costs less
/// than the iterations it saves. Counted per decade, since a Newton solve's
/// later iterations ask for more decades than its first.
const STALE_GROWTH: f64 = 2.0;
const STALE_SLACK: f64 = 4.0;

/// A solve on a kept hierarchy with a new operator stops at this many times
/// the iterations that make the hierarchy stale: its result stands if it
/// is within 0.1 (an inexact Newton step), and the next tangent gets a new
/// hierarchy either way. A hierarchy far from the operator would otherwise
/// run to the Krylov iteration limit.
const STALE_CAP: f64 = 2.0;

/// Most Krylov iterations of a solve.
const MAX_KRYLOV_ITERATIONS: u32 = 500;

/// Decades of residual reduction that `rtol` asks for (at least one).
fn decades(rtol: f64) -> f64 {
    (-rtol.log10()).max(1.0)
}

/// `out = A v` for the Jacobian `A` of a Newton iteration, without a matrix.
pub(crate) type Action<'a> = &'a dyn Fn(&[Vec3], &mut [Vec3]);

/// A product `out = A v` owned by whoever made it.
type Product<'a> = Box<dyn Fn(&[Vec3], &mut [Vec3]) + 'a>;

/// `action` times `sign` on the free dofs (`mask`), as the product of the
/// operator with the held dofs decoupled: the held components of the input
/// are taken as zero and those of the output are zero.
fn masked_action<'a>(
    action: Action<'a>,
    mask: &'a [[bool; 3]],
    sign: f64,
) -> impl Fn(&[Vec3], &mut [Vec3]) + 'a {
    let free_part = std::cell::RefCell::new(Vec::<Vec3>::new());
    move |v: &[Vec3], out: &mut [Vec3]| {
        let mut w = free_part.borrow_mut();
        w.clear();
        w.extend(
            v.iter()
                .zip(mask)
                .map(|(vi, m)| Vec3::from_fn(|d, _| if m[d] { vi[d] } else { 0.0 })),
        );
        action(&w, out);
        for (o, m) in out.iter_mut().zip(mask) {
            for d in 0..3 {
                o[d] = if m[d] { sign * o[d] } else { 0.0 };
            }
        }
    }
}

/// `out = A v` with `mg`'s operator (the matrix times `sign`, held dofs
/// decoupled): through `action` when given (the solve kept no matrix),
/// else with the operator's blocks.
fn operator_product<'a>(
    mg: &'a super::multigrid::Multigrid,
    action: Option<Action<'a>>,
    sign: f64,
) -> Product<'a> {
    match action {
        Some(action) => Box::new(masked_action(action, mg.mask(), sign)),
        None => Box::new(move |v: &[Vec3], out: &mut [Vec3]| {
            super::multigrid::mul(mg.operator().0, v, out)
        }),
    }
}

/// The stiffness whose definiteness is tested: assembled, or its product.
pub(crate) enum Stiffness<'a> {
    /// The symmetric matrix.
    Matrix(BlockCsr),
    /// `out = K v` of a symmetric `K`, given by its product.
    Action(Action<'a>),
}

/// Counts of what the linear solver of a Newton solve did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinearStats {
    /// Linear solves.
    pub solves: u32,
    /// Of which iterative.
    pub iterative_solves: u32,
    /// Krylov iterations over all iterative solves.
    pub krylov_iterations: u32,
    /// Multigrid hierarchies built.
    pub hierarchy_builds: u32,
    /// Iterative solves that reused the previous solve's matrix and
    /// hierarchy (Newton's chord steps, [`newton`](super::newton)).
    pub reused_solves: u32,
}

/// The last iterative solve's operator and hierarchy, kept until the next
/// Newton iteration decides whether its tangent is still good enough.
struct LastSolve {
    mg: super::multigrid::Multigrid,
    /// Krylov iterations per decade of residual of the solve that built
    /// the hierarchy: a later operator that takes many more on it finds it
    /// stale.
    fresh_rate: f64,
    /// The operator is the matrix times `sign`.
    sign: f64,
    symmetric: bool,
    /// Whether the hierarchy becomes the stability test's when released
    /// (asked for, and built for a symmetric operator: it stays so when a
    /// new operator is solved on it).
    keep: bool,
    /// Whether the matrix was dropped: products go through the Jacobian's
    /// action.
    lean: bool,
    /// Where the stiffness a matrix-free hierarchy was built from was
    /// taken, and its mass shift ([`StiffnessOrigin`]).
    origin: Option<StiffnessOrigin>,
}

/// Where the symmetric stiffness of a matrix-free solve was taken: the
/// positions, and the factor of the masses added to its diagonal
/// ([`NonlinearSystem::stiffness_shift`](super::NonlinearSystem::stiffness_shift)).
/// Enough to build its hierarchy again, bit for bit.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StiffnessOrigin {
    pub x: Vec<Vec3>,
    pub shift: f64,
}

/// A kept matrix-free hierarchy as a checkpoint stores it
/// ([`LinearSolver::kept_hierarchy`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct KeptHierarchy {
    pub origin: StiffnessOrigin,
    pub fresh_rate: f64,
    pub symmetric: bool,
    pub newton_scale: f64,
}

/// The 8 nodes where the unusable solution `y` of a singular solve is
/// largest (non-finite first): where the mechanism moves most.
fn largest_entries(y: &[Vec3]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..y.len() as u32).collect();
    let mag = |i: u32| {
        let v = y[i as usize].norm();
        if v.is_finite() { v } else { f64::INFINITY }
    };
    order.sort_by(|&p, &q| mag(q).total_cmp(&mag(p)));
    order.truncate(8);
    order
}

/// The linear solver of a Newton solve ([`newton`](super::newton)): a sparse
/// LU with its symbolic analysis cached per pattern, or multigrid-
/// preconditioned Krylov with the hierarchy's structure cached per free mask.
pub struct LinearSolver {
    kind: LinearSolverKind,
    lu: LuCache,
    cells: Vec<[u32; 8]>,
    coords: Vec<[i64; 3]>,
    /// Whether the hierarchy's coarse levels carry the hexahedral lattice's
    /// mechanisms (3D lattices; not the 2D element's degenerate cells).
    enrich: bool,
    shape: Option<super::multigrid::HierarchyShape>,
    stats: LinearStats,
    /// Whether the next iterative solve keeps its hierarchy (when its
    /// matrix is symmetric) for [`LinearSolver::is_positive_definite`].
    keep_next: bool,
    /// The kept hierarchy: a multigrid cycle of a symmetric stiffness.
    kept: Option<super::multigrid::Multigrid>,
    /// The last iterative solve, for [`LinearSolver::solve_again`].
    last: Option<LastSolve>,
    /// Free dofs above which a solve given the matrix's action keeps no
    /// `f64` matrix.
    matrix_free_above: usize,
    /// The largest diagonal entry of the first tangent of the last Newton
    /// solve (its round-off floor's scale), for a later solve that starts
    /// on a kept hierarchy without a tangent of its own.
    newton_scale: Option<f64>,
}

impl std::fmt::Debug for LinearSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinearSolver")
            .field("kind", &self.kind)
            .field("stats", &self.stats)
            .finish()
    }
}

impl LinearSolver {
    /// A solver for matrices over the nodes of `model`'s lattice. Unless
    /// every material has hourglass control, the multigrid's coarse levels
    /// also carry the lattice's three mechanisms (see
    /// [`Model::resists_mechanisms`](crate::Model::resists_mechanisms)).
    pub fn new(model: &crate::Model, kind: LinearSolverKind) -> Self {
        Self::with_coords(
            model.cells(),
            model.grid_coords(),
            kind,
            !model.resists_mechanisms(),
        )
    }

    /// A solver for matrices over the nodes of a lattice given by its cells,
    /// rest positions and cell edge, for operators without the mass-spring
    /// lattice's mechanisms (such as trilinear finite elements): the
    /// multigrid's coarse spaces are the grid's alone.
    pub fn for_lattice(cells: &[[u32; 8]], rest: &[Vec3], h: f64, kind: LinearSolverKind) -> Self {
        Self::with_coords(cells, super::multigrid::grid_coords(rest, h), kind, false)
    }

    /// A solver for a 2D lattice of rectangles `size` (m) whose cells are
    /// given as degenerate hexahedra (each quad twice, z held): the grid
    /// indices are per axis, so the multigrid coarsens the plane as it
    /// coarsens a cube lattice.
    pub fn for_rect_lattice(
        cells: &[[u32; 8]],
        rest: &[Vec3],
        size: [f64; 2],
        kind: LinearSolverKind,
    ) -> Self {
        let (mut lx, mut ly) = (f64::INFINITY, f64::INFINITY);
        for p in rest {
            lx = lx.min(p.x);
            ly = ly.min(p.y);
        }
        let coords = rest
            .iter()
            .map(|p| {
                [
                    ((p.x - lx) / size[0]).round() as i64,
                    ((p.y - ly) / size[1]).round() as i64,
                    0,
                ]
            })
            .collect();
        Self::with_coords(cells, coords, kind, false)
    }

    fn with_coords(
        cells: &[[u32; 8]],
        coords: Vec<[i64; 3]>,
        kind: LinearSolverKind,
        enrich: bool,
    ) -> Self {
        Self {
            kind,
            lu: LuCache::new(),
            cells: cells.to_vec(),
            coords,
            enrich,
            shape: None,
            stats: LinearStats::default(),
            keep_next: false,
            kept: None,
            last: None,
            matrix_free_above: usize::MAX,
            newton_scale: None,
        }
    }

    /// Iterative solves of more than `free_dofs` free dofs that are given
    /// the matrix's action keep no `f64` matrix: the hierarchy drops it once
    /// its single-precision copy is made, and the Krylov products (and
    /// [`LinearSolver::last_product`]) use the action. Never by default.
    pub(crate) fn set_matrix_free_above(&mut self, free_dofs: usize) {
        self.matrix_free_above = free_dofs;
    }

    /// [`LinearSolver::newton_scale`]'s value.
    pub(crate) fn set_newton_scale(&mut self, largest_diagonal_entry: f64) {
        self.newton_scale = Some(largest_diagonal_entry);
    }

    /// The largest diagonal entry of the last Newton solve's first tangent,
    /// while a matrix-free hierarchy is kept for a new tangent to use.
    pub(crate) fn newton_scale(&self) -> Option<f64> {
        self.newton_scale
            .filter(|_| self.last.as_ref().is_some_and(|l| l.lean))
    }

    /// The direct solver's kept factorization, as the key of its pattern
    /// and the values of the matrix it factors: what a checkpoint stores so
    /// that a resumed run's solves are bitwise those of the run that was not
    /// interrupted ([`LinearSolver::restore_kept_factors`]).
    pub(crate) fn kept_factors(&self) -> Option<(u64, &[f64])> {
        match (&self.lu.kept, &self.lu.pending) {
            (Some((_, values)), _) => Some((self.lu.key, values.as_slice())),
            (None, Some((key, values))) => Some((*key, values.as_slice())),
            (None, None) => None,
        }
    }

    /// Puts back what [`LinearSolver::kept_factors`] gave: the next direct
    /// solve factors `values` first if its pattern has `key` (else, as an
    /// uninterrupted run would, it drops them).
    pub(crate) fn restore_kept_factors(&mut self, key: u64, values: Vec<f64>) {
        self.lu.kept = None;
        self.lu.pending = Some((key, values));
    }

    /// What the solver did so far.
    pub fn stats(&self) -> LinearStats {
        self.stats
    }

    /// Whether the symmetric `stiffness` is positive definite on the free
    /// dofs, by a Lanczos iteration preconditioned with a multigrid cycle of
    /// the positive definite `reference` (the rest stiffness): no
    /// factorization, so it costs about as much as one iterative solve.
    /// `None` when the test does not decide (or `reference` is singular).
    ///
    /// A hierarchy kept by [`LinearSolver::keep_next_hierarchy`] (for the
    /// same free dofs) serves instead of one of `reference`, which is then
    /// not called.
    pub(crate) fn is_positive_definite(
        &mut self,
        stiffness: Stiffness<'_>,
        reference: impl FnOnce() -> BlockCsr,
        free: &[bool],
    ) -> Option<bool> {
        self.release_last();
        self.fit_shape(free);
        let shape = self.shape.as_ref()?;
        let mg = match self.kept.take() {
            Some(mg) => mg,
            None => {
                let pre = super::multigrid::Operator::from_owned(reference(), free);
                match super::multigrid::Multigrid::new(pre, shape, false) {
                    Ok(mg) => mg,
                    Err(e) => {
                        log::debug!("definiteness test: no preconditioner ({})", e.0);
                        return None;
                    }
                }
            }
        };
        let (verdict, theta) = match stiffness {
            Stiffness::Matrix(k) => {
                let op = super::multigrid::Operator::from_owned(k, free);
                let product = |v: &[Vec3], out: &mut [Vec3]| {
                    super::multigrid::mul(op.matrix(), v, out);
                };
                super::multigrid::definiteness(&product, &mg)
            }
            Stiffness::Action(action) => {
                let product = masked_action(action, mg.mask(), 1.0);
                super::multigrid::definiteness(&product, &mg)
            }
        };
        log::debug!(
            "definiteness test: {verdict:?}, smallest eigenvalue against the rest stiffness {theta:.3e}"
        );
        match verdict {
            super::multigrid::Definiteness::Positive => Some(true),
            super::multigrid::Definiteness::NotPositive => Some(false),
            super::multigrid::Definiteness::Undecided => None,
        }
    }

    /// Asks the next iterative solve to keep its multigrid hierarchy if its
    /// matrix is symmetric, as the preconditioner of a later
    /// [`LinearSolver::is_positive_definite`] (a static solve's first
    /// tangent, at its start, is the stability test's reference).
    pub(crate) fn keep_next_hierarchy(&mut self) {
        self.keep_next = true;
    }

    /// Solves `A y = b` on the free dofs (`free[3 node + d]`; held components
    /// of `y` are zero) to a relative residual `rtol` (direct solves are
    /// exact). `size` is a length scale of the body: a solution above
    /// `1e6 size` is taken for a singular matrix.
    pub fn solve_dofs(
        &mut self,
        a: &BlockCsr,
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
    ) -> Result<Vec<Vec3>, crate::sparse::LinearSolveError> {
        let solved = self.solve(a.clone(), b, free, size, rtol, None);
        // A caller of this entry point gets no chord steps: hold nothing.
        self.release_last();
        solved.map_err(|e| match e {
            LinearFailure::Singular { nodes } => crate::sparse::LinearSolveError::Singular {
                detail: format!("the solution grows without bound at nodes {nodes:?}"),
            },
            LinearFailure::Other(m) => crate::sparse::LinearSolveError::Library(m),
        })
    }

    /// Solves `A y = b` on the free dofs to a relative residual `rtol` (the
    /// direct solve is exact). `size` is a length scale of the body: a
    /// solution above `1e6 size` means a singular matrix. With `action`
    /// (`A`'s product), a large iterative solve keeps no `f64` matrix
    /// ([`LinearSolver::set_matrix_free_above`]); later [`LinearSolver::solve_again`] and
    /// [`LinearSolver::last_product`] calls then need that action again.
    pub(crate) fn solve(
        &mut self,
        a: BlockCsr,
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
        action: Option<Action<'_>>,
    ) -> Result<Vec<Vec3>, LinearFailure> {
        self.release_last();
        self.stats.solves += 1;
        // Only the very next solve may keep its hierarchy.
        let keep = std::mem::take(&mut self.keep_next);
        let free_dofs = free.iter().filter(|f| **f).count();
        let iterative = match self.kind {
            LinearSolverKind::Direct => false,
            LinearSolverKind::Iterative => true,
            LinearSolverKind::Auto => free_dofs > DIRECT_MAX_FREE_DOFS,
        };
        if !iterative || free_dofs == 0 {
            return solve_free(&mut self.lu, &a, b, free, size);
        }
        self.stats.iterative_solves += 1;
        self.fit_shape(free);
        let Some(shape) = self.shape.as_ref() else {
            return Err(LinearFailure::Other("no multigrid hierarchy".into()));
        };
        // Newton Jacobians of force residuals are negative definite (they are
        // minus a stiffness): solve (-A) y = -b, whose matrix CG and the
        // Chebyshev smoother need positive.
        let trace: f64 = (0..a.num_rows())
            .filter_map(|i| a.find(i, i))
            .map(|k| a.blocks[k].trace())
            .sum();
        let sign = if trace < 0.0 { -1.0 } else { 1.0 };
        let b_signed: Vec<Vec3> = b.iter().map(|v| v * sign).collect();
        let n = a.num_rows();
        let op = super::multigrid::Operator::from_owned_signed(a, free, sign);
        let scale = op
            .matrix()
            .blocks
            .iter()
            .map(|b| b.abs().max())
            .fold(0.0, f64::max);
        let symmetric = op.matrix().asymmetry() <= 1e-10 * scale;
        let mut y = vec![Vec3::zeros(); n];
        // A hierarchy is built for every matrix: reusing the previous one
        // for an assembled tangent was tried and lost, since a stale
        // hierarchy took more Krylov iterations than a new set-up cost.
        // (Newton's chord steps reuse a matrix with its own hierarchy:
        // `solve_again`; Newton solves without a matrix keep their
        // hierarchy for new tangents, `solve_with_new_action`: there a new
        // hierarchy also costs the symmetric part's assembly, and with
        // staleness counted per decade of residual and the iterations
        // capped, keeping it won everywhere measured: the 128x32x32
        // cantilever's static solve with `paper` 6.0 -> 4.5 s.)
        let lean = action.is_some() && free_dofs > self.matrix_free_above;
        let mg = super::multigrid::Multigrid::new(op, shape, lean)
            .map_err(|e| LinearFailure::Other(e.0))?;
        let (usable, fresh_rate) = self.solve_on_new_hierarchy(
            &mg,
            action.filter(|_| lean),
            (sign, symmetric),
            &b_signed,
            &mut y,
            (size, rtol),
        );
        // A solve that kept no matrix has none to factor: it reports as a
        // large solve does.
        if !usable && free_dofs <= FALLBACK_MAX_FREE_DOFS && !lean {
            // Near-mechanisms (the lattice's hourglass modes) can stall the
            // preconditioned iteration; a problem that still fits a direct
            // solve gets one, which also tells a singular matrix apart.
            log::debug!("iterative solve stalled: solving directly");
            // The operator is the matrix times `sign` with the held dofs
            // decoupled: its free block is that of `sign * a`.
            return solve_free(&mut self.lu, mg.operator().0, &b_signed, free, size);
        }
        let last = LastSolve {
            mg,
            fresh_rate,
            sign,
            symmetric,
            keep: keep && symmetric,
            lean,
            origin: None,
        };
        self.finish(y, usable, last)
    }

    /// Makes the cached hierarchy shape that of `free` (a new one drops any
    /// kept hierarchy, which was built for other free dofs).
    fn fit_shape(&mut self, free: &[bool]) {
        if !self.shape.as_ref().is_some_and(|s| s.fits(free)) {
            self.kept = None;
            self.shape = Some(super::multigrid::HierarchyShape::new(
                &self.cells,
                &self.coords,
                free,
                self.enrich,
            ));
        }
    }

    /// Whether a solve of `free_dofs` free dofs given the matrix's action
    /// keeps no matrix ([`LinearSolver::set_matrix_free_above`]): its caller
    /// then gives [`LinearSolver::solve_without_matrix`] the symmetric part
    /// of the stiffness instead of assembling the matrix.
    pub(crate) fn keeps_no_matrix(&self, free_dofs: usize) -> bool {
        let iterative = match self.kind {
            LinearSolverKind::Direct => false,
            LinearSolverKind::Iterative => true,
            LinearSolverKind::Auto => free_dofs > DIRECT_MAX_FREE_DOFS,
        };
        iterative && free_dofs > self.matrix_free_above
    }

    /// Solves `J y = b` on the free dofs to a relative residual `rtol`, for
    /// a Jacobian `J = -K` known by its product `action` and the symmetric
    /// part of the stiffness `K`, `stiffness` (positive definite where the
    /// solve is well posed), from which the hierarchy is built, with where it
    /// was taken (kept for [`LinearSolver::kept_hierarchy`]): no `f64`
    /// matrix is ever held. A solve that fails is not retried directly (it
    /// reports as a large solve does). Later [`LinearSolver::solve_again`]
    /// and [`LinearSolver::last_product`] calls need the action again.
    pub(crate) fn solve_without_matrix(
        &mut self,
        (stiffness, origin): (crate::sparse::SymmetricUpper, StiffnessOrigin),
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
        action: Action<'_>,
    ) -> Result<Vec<Vec3>, LinearFailure> {
        self.release_last();
        self.stats.solves += 1;
        self.stats.iterative_solves += 1;
        let keep = std::mem::take(&mut self.keep_next);
        self.fit_shape(free);
        let Some(shape) = self.shape.as_ref() else {
            return Err(LinearFailure::Other("no multigrid hierarchy".into()));
        };
        // The operator is the stiffness, -J: solve K y = -b.
        let sign = -1.0;
        let symmetric = stiffness.of_a_symmetric_matrix();
        let b_signed: Vec<Vec3> = b.iter().map(|v| v * sign).collect();
        let mg = super::multigrid::Multigrid::of_symmetric(stiffness, free, shape)
            .map_err(|e| LinearFailure::Other(e.0))?;
        let mut y = vec![Vec3::zeros(); b.len()];
        let (usable, fresh_rate) = self.solve_on_new_hierarchy(
            &mg,
            Some(action),
            (sign, symmetric),
            &b_signed,
            &mut y,
            (size, rtol),
        );
        let last = LastSolve {
            mg,
            fresh_rate,
            sign,
            symmetric,
            keep: keep && symmetric,
            lean: true,
            origin: Some(origin),
        };
        self.finish(y, usable, last)
    }

    /// The kept matrix-free hierarchy and what built it, for a checkpoint:
    /// [`LinearSolver::restore_kept_hierarchy`] builds the same again.
    pub(crate) fn kept_hierarchy(&self) -> Option<KeptHierarchy> {
        let last = self.last.as_ref().filter(|l| l.lean)?;
        Some(KeptHierarchy {
            origin: last.origin.clone()?,
            fresh_rate: last.fresh_rate,
            symmetric: last.symmetric,
            newton_scale: self.newton_scale?,
        })
    }

    /// Builds again the hierarchy [`LinearSolver::kept_hierarchy`] gave,
    /// from `stiffness`, the symmetric stiffness at its origin, for the free
    /// dofs `free`: the next Newton solve starts on it as the run that kept
    /// it did.
    pub(crate) fn restore_kept_hierarchy(
        &mut self,
        stiffness: crate::sparse::SymmetricUpper,
        free: &[bool],
        kept: KeptHierarchy,
    ) -> Result<(), LinearFailure> {
        self.release_last();
        self.fit_shape(free);
        let Some(shape) = self.shape.as_ref() else {
            return Err(LinearFailure::Other("no multigrid hierarchy".into()));
        };
        let mg = super::multigrid::Multigrid::of_symmetric(stiffness, free, shape)
            .map_err(|e| LinearFailure::Other(e.0))?;
        self.last = Some(LastSolve {
            mg,
            fresh_rate: kept.fresh_rate,
            sign: -1.0,
            symmetric: kept.symmetric,
            keep: false,
            lean: true,
            origin: Some(kept.origin),
        });
        self.newton_scale = Some(kept.newton_scale);
        Ok(())
    }

    /// The first solve on the new hierarchy `mg` (counted as built), of
    /// its operator's matrix times `sign`, or of `action` times `sign`
    /// when given: whether `y` is usable, and the Krylov iterations per
    /// decade of residual.
    fn solve_on_new_hierarchy(
        &mut self,
        mg: &super::multigrid::Multigrid,
        action: Option<Action<'_>>,
        (sign, symmetric): (f64, bool),
        b_signed: &[Vec3],
        y: &mut [Vec3],
        (size, rtol): (f64, f64),
    ) -> (bool, f64) {
        self.stats.hierarchy_builds += 1;
        let product = operator_product(mg, action, sign);
        let (usable, _, rate) = self.krylov(
            mg,
            &*product,
            symmetric,
            b_signed,
            y,
            size,
            (rtol, MAX_KRYLOV_ITERATIONS),
        );
        (usable, rate)
    }

    /// The solution `y` of an iterative solve, kept as `last` for chord
    /// steps when `usable`; otherwise the singular solve's nodes.
    fn finish(
        &mut self,
        y: Vec<Vec3>,
        usable: bool,
        last: LastSolve,
    ) -> Result<Vec<Vec3>, LinearFailure> {
        if !usable {
            return Err(LinearFailure::Singular {
                nodes: largest_entries(&y),
            });
        }
        self.last = Some(last);
        Ok(y)
    }

    /// Krylov iterations on `mg`'s operator from `y` (zero) to a relative
    /// residual `rtol`, at most `max_iterations`, counted in the stats;
    /// whether the solution is usable (finite, below `1e6 size`, converged
    /// or at least within 0.1), the iterations taken, and the iterations
    /// per decade of residual reached.
    #[allow(clippy::too_many_arguments)]
    fn krylov(
        &mut self,
        mg: &super::multigrid::Multigrid,
        product: &dyn Fn(&[Vec3], &mut [Vec3]),
        symmetric: bool,
        b: &[Vec3],
        y: &mut [Vec3],
        size: f64,
        (rtol, max_iterations): (f64, u32),
    ) -> (bool, u32, f64) {
        let info = super::multigrid::krylov(mg, product, b, y, rtol, max_iterations, symmetric);
        self.stats.krylov_iterations += info.iterations;
        log::debug!(
            "{} with multigrid ({:?} nodes per level): {} iterations, relative residual {:.2e}",
            if symmetric { "CG" } else { "GMRES" },
            mg.level_sizes(),
            info.iterations,
            info.relative_residual
        );
        let worst = y.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let usable = info.relative_residual.is_finite()
            && worst.is_finite()
            && worst <= 1e6 * size
            && (info.converged || info.relative_residual <= 0.1);
        let rate = f64::from(info.iterations) / decades(info.relative_residual);
        (usable, info.iterations, rate)
    }

    /// Solves `A y = b` with the matrix and hierarchy of the last iterative
    /// solve (a chord step of Newton's method: no assembly, no set-up), to a
    /// relative residual `rtol`. `None` when there is no such solve (direct
    /// solves keep nothing), its free dofs differ, or the result is not
    /// usable; the caller then assembles a new matrix. `action` is the
    /// matrix's product, needed when the solve kept no matrix.
    pub(crate) fn solve_again(
        &mut self,
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
        action: Option<Action<'_>>,
    ) -> Option<Vec<Vec3>> {
        self.solve_on_last_hierarchy(b, free, size, rtol, action, false)
    }

    /// Solves with a new operator, given by its action (a Newton tangent
    /// taken at a new point), preconditioned by the last solve's hierarchy
    /// (no assembly, no set-up), with GMRES (the new operator's symmetry is
    /// not known); later [`LinearSolver::solve_again`] calls multiply by the
    /// action they are given, as after any solve without a matrix. `None`
    /// when the last solve kept no matrix-free hierarchy for these dofs, or
    /// when this solve is not usable (the hierarchy is then released).
    pub(crate) fn solve_with_new_action(
        &mut self,
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
        action: Action<'_>,
    ) -> Option<Vec<Vec3>> {
        if !self.last.as_ref().is_some_and(|l| l.lean) {
            return None;
        }
        self.solve_on_last_hierarchy(b, free, size, rtol, Some(action), true)
    }

    /// [`LinearSolver::solve_again`], and with `new_operator` the operator
    /// changed (see [`LinearSolver::solve_with_new_action`]).
    fn solve_on_last_hierarchy(
        &mut self,
        b: &[Vec3],
        free: &[bool],
        size: f64,
        rtol: f64,
        action: Option<Action<'_>>,
        new_operator: bool,
    ) -> Option<Vec<Vec3>> {
        let mut last = self.last.take()?;
        if new_operator {
            last.symmetric = false;
        }
        let same_dofs = last
            .mg
            .mask()
            .iter()
            .flatten()
            .zip(free)
            .all(|(m, f)| m == f);
        if !same_dofs || last.mg.mask().len() != b.len() || (last.lean && action.is_none()) {
            self.last = Some(last);
            self.release_last();
            return None;
        }
        self.stats.solves += 1;
        self.stats.iterative_solves += 1;
        self.stats.reused_solves += 1;
        let b_signed: Vec<Vec3> = b.iter().map(|v| v * last.sign).collect();
        let mut y = vec![Vec3::zeros(); b.len()];
        let product = operator_product(&last.mg, action.filter(|_| last.lean), last.sign);
        let stale_above = STALE_GROWTH * last.fresh_rate * decades(rtol) + STALE_SLACK;
        let max_iterations = if new_operator {
            (STALE_CAP * stale_above).ceil() as u32
        } else {
            MAX_KRYLOV_ITERATIONS
        };
        let (usable, iterations, _) = self.krylov(
            &last.mg,
            &*product,
            last.symmetric,
            &b_signed,
            &mut y,
            size,
            (rtol, max_iterations),
        );
        drop(product);
        // A new operator that takes many more iterations than the one the
        // hierarchy was built for has moved away from it (a body turned far,
        // a shorter step): this solve stands, the next tangent gets a new
        // hierarchy.
        let stale = new_operator && f64::from(iterations) > stale_above;
        self.last = Some(last);
        if usable && !stale {
            Some(y)
        } else if usable {
            log::debug!("kept hierarchy stale ({iterations} Krylov iterations): released");
            self.release_last();
            Some(y)
        } else {
            self.release_last();
            None
        }
    }

    /// Largest distance of a node of a cell from its cell's mean under the
    /// displacement `d` (m): how far `d` deforms or turns any cell, which
    /// bounds how much it changes the cell's tangent. Zero without cells
    /// (direct solvers).
    pub(crate) fn largest_cell_distortion(&self, d: &[Vec3]) -> f64 {
        use rayon::prelude::*;
        self.cells
            .par_iter()
            .map(|cell| {
                let mean = cell.iter().map(|&n| d[n as usize]).sum::<Vec3>() / 8.0;
                cell.iter()
                    .map(|&n| (d[n as usize] - mean).norm())
                    .fold(0.0, f64::max)
            })
            .reduce(|| 0.0, f64::max)
    }

    /// `out = A v` on the free dofs (zero on the held ones) with the matrix
    /// of the last iterative solve, for `v` zero on the held dofs (through
    /// `action` when the solve kept no matrix); false when no such solve is
    /// kept.
    pub(crate) fn last_product(
        &self,
        v: &[Vec3],
        out: &mut [Vec3],
        action: Option<Action<'_>>,
    ) -> bool {
        let Some(last) = &self.last else {
            return false;
        };
        let (a, mask) = last.mg.operator();
        if v.len() != mask.len() {
            return false;
        }
        if last.lean {
            let Some(action) = action else {
                return false;
            };
            masked_action(action, mask, 1.0)(v, out);
            return true;
        }
        if a.blocks.is_empty() {
            return false;
        }
        super::multigrid::mul(a, v, out);
        for (o, m) in out.iter_mut().zip(mask) {
            for d in 0..3 {
                o[d] = if m[d] { o[d] * last.sign } else { 0.0 };
            }
        }
        true
    }

    /// Drops the last solve's matrix and hierarchy (before a new matrix is
    /// assembled, so that two are never held); a hierarchy asked for by
    /// [`LinearSolver::keep_next_hierarchy`] becomes the stability test's.
    pub(crate) fn release_last(&mut self) {
        if let Some(last) = self.last.take()
            && last.keep
        {
            self.kept = Some(last.mg.into_preconditioner());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A new operator far from the one a kept hierarchy was built for: its
    /// solve stops at the cap (twice the stale count for its accuracy), the
    /// hierarchy is released, and a new operator close to the first one
    /// (the same tangent) is solved on it within the stale count.
    #[test]
    fn a_stale_hierarchy_stops_its_solve_at_the_cap_and_is_released() {
        let l = hexmesh::Lattice::block([16, 4, 4], 0.01, [0.0; 3]).unwrap();
        let model = crate::Model::new(
            &l,
            crate::Material::new(1e4, 0.3, 1000.0).unwrap(),
            &crate::model::HourglassControl::new(Box::new(crate::model::Volumetric), 0.05).unwrap(),
        )
        .unwrap();
        let n = model.num_nodes();
        let rest = model.rest_positions().to_vec();
        // The x- face held.
        let free: Vec<bool> = rest.iter().flat_map(|p| [p.x > 1e-9; 3]).collect();
        let b: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(0.0, 0.0, if rest[i].x > 1e-9 { -1.0 } else { 0.0 }))
            .collect();
        let tangent = |v: &[Vec3], out: &mut [Vec3]| model.tangent_mul(&rest, v, out);
        let first = || {
            let mut linear = LinearSolver::new(&model, LinearSolverKind::Iterative);
            linear.set_matrix_free_above(0);
            let half = model.symmetric_stiffness_upper(&rest);
            linear
                .solve_without_matrix(
                    (
                        half,
                        StiffnessOrigin {
                            x: rest.clone(),
                            shift: 0.0,
                        },
                    ),
                    &b,
                    &free,
                    0.16,
                    1e-3,
                    &tangent,
                )
                .unwrap();
            let fresh_rate = linear.last.as_ref().unwrap().fresh_rate;
            (linear, fresh_rate)
        };
        let rtol = 1e-8;

        // The same tangent: the hierarchy serves, and is kept.
        let (mut linear, fresh_rate) = first();
        let stale_above = STALE_GROWTH * fresh_rate * decades(rtol) + STALE_SLACK;
        let before = linear.stats().krylov_iterations;
        assert!(
            linear
                .solve_with_new_action(&b, &free, 0.16, rtol, &tangent)
                .is_some()
        );
        let iterations = linear.stats().krylov_iterations - before;
        assert!(
            f64::from(iterations) <= stale_above,
            "{iterations} > {stale_above}"
        );
        assert!(linear.last.is_some(), "a serving hierarchy was released");

        // A far operator: the tangent plus a coupling of every node to a
        // distant one as strong as the diagonal (non-symmetric).
        let diagonal = {
            let mut e = vec![Vec3::zeros(); n];
            let mut out = vec![Vec3::zeros(); n];
            e[n / 2] = Vec3::new(1.0, 0.0, 0.0);
            tangent(&e, &mut out);
            out[n / 2].x.abs()
        };
        let far = |v: &[Vec3], out: &mut [Vec3]| {
            tangent(v, out);
            for (i, o) in out.iter_mut().enumerate() {
                *o += v[(7 * i + n / 3) % n] * diagonal;
            }
        };
        let (mut linear, fresh_rate) = first();
        let stale_above = STALE_GROWTH * fresh_rate * decades(rtol) + STALE_SLACK;
        let before = linear.stats().krylov_iterations;
        let _ = linear.solve_with_new_action(&b, &free, 0.16, rtol, &far);
        let iterations = linear.stats().krylov_iterations - before;
        assert!(
            f64::from(iterations) > stale_above,
            "the far operator converged in {iterations} iterations"
        );
        assert!(
            f64::from(iterations) <= (STALE_CAP * stale_above).ceil(),
            "{iterations} iterations past the cap {}",
            STALE_CAP * stale_above
        );
        assert!(linear.last.is_none(), "a stale hierarchy was kept");
    }
}
