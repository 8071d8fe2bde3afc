//! Exact mode count for models whose cells are rigid when undistorted.
//!
//! With hourglass control every cell's rest stiffness has exactly the 6 rigid
//! motions as zero modes. A displacement then has zero energy if and only if
//! it moves every cell as an infinitesimal rigid body, so the mechanisms are
//! those of a linkage, decided without touching the stiffness matrix:
//!
//! 1. Cells sharing a face (4 nodes, not collinear) move as one rigid
//!    *body*: union-find over face neighbours.
//! 2. Bodies that meet at nodes are *joints*: one node lets them turn about
//!    it (rank 3), collinear nodes about their line (rank 5), anything else
//!    joins them rigidly (rank 6). Rank-6 joints merge their bodies, until
//!    none is left.
//! 3. What remains is a small linear system in 6 unknowns per body (a
//!    translation and a rotation in a frame scaled to the body): each joint
//!    and each body's held dofs contribute the orthogonal projector onto
//!    their constraint rows. The zero-energy modes are the null space of the
//!    sum, counted per connected group of bodies by a dense eigenvalue
//!    decomposition. Each projector has eigenvalues 0 and 1, so the count
//!    does not depend on how many nodes a joint or a clamp has.
//!
//! Cost: linear in the cells plus a dense solve per group (6 unknowns per
//! body); a lattice is usually one body.

use nalgebra::{DMatrix, Matrix3, Matrix6, SymmetricEigen, Vector3};

use super::{ZERO_THRESHOLD, ZeroModes};
use crate::Model;

/// Largest group of bodies (connected by joints) solved densely; beyond it
/// the caller falls back to the linear-algebra methods.
pub const MAX_GROUP_BODIES: usize = 400;

/// Eigenvalues of the sum of constraint projectors below this count as zero.
/// The sum's nonzero eigenvalues are bounded below by the geometry of the
/// joints (order `(h / L)^2` for a hinge in a body of size `L`), far above.
const PROJECTOR_ZERO: f64 = 1e-10;

/// True when every cell's rest stiffness has exactly the 6 rigid motions as
/// zero modes (one cell per material is enough: all cells are cubes of the
/// same size).
pub fn cells_are_rigid(model: &Model) -> bool {
    let mut first = vec![None; model.num_param_sets()];
    for c in 0..model.num_cells() {
        let p = model.param_set_of(c);
        if first[p].is_none() {
            first[p] = Some(c);
        }
    }
    first.into_iter().flatten().all(|c| {
        let k = model.cell_rest_stiffness(c);
        let m = DMatrix::<f64>::from_fn(24, 24, |i, j| 0.5 * (k[i][j] + k[j][i]));
        let scale = (0..24).map(|i| m[(i, i)]).fold(0.0, f64::max);
        if scale <= 0.0 || !scale.is_finite() {
            return false;
        }
        let zero = SymmetricEigen::new(m)
            .eigenvalues
            .iter()
            .filter(|&&v| v < ZERO_THRESHOLD * scale)
            .count();
        zero == 6
    })
}

/// Disjoint sets with path halving.
struct Sets(Vec<u32>);

impl Sets {
    fn new(n: usize) -> Self {
        Sets((0..n as u32).collect())
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let up = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = up;
            x = up;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            // The smaller root wins: the labels do not depend on the order.
            let (lo, hi) = (a.min(b), a.max(b));
            self.0[hi as usize] = lo;
        }
    }
}

/// Skew matrix `[v]x` with `[v]x w = v x w`.
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The bodies of the current partition: a dense label per cell, and per
/// body a reference point and size for its unknowns' frame.
struct Bodies {
    of_cell: Vec<u32>,
    centre: Vec<Vector3<f64>>,
    size: Vec<f64>,
}

fn label_bodies(model: &Model, sets: &mut Sets) -> Bodies {
    let nc = model.num_cells();
    let mut label = vec![u32::MAX; nc];
    let mut of_cell = vec![0u32; nc];
    let mut count = 0u32;
    for (c, body) in of_cell.iter_mut().enumerate() {
        let root = sets.find(c as u32) as usize;
        if label[root] == u32::MAX {
            label[root] = count;
            count += 1;
        }
        *body = label[root];
    }
    let rest = model.rest_positions();
    let centre_of = |c: usize| {
        model.cells()[c]
            .iter()
            .fold(Vector3::zeros(), |s, &n| s + rest[n as usize])
            / 8.0
    };
    let mut sum = vec![Vector3::zeros(); count as usize];
    let mut cells = vec![0usize; count as usize];
    for (c, &b) in of_cell.iter().enumerate() {
        sum[b as usize] += centre_of(c);
        cells[b as usize] += 1;
    }
    let centre: Vec<Vector3<f64>> = sum.iter().zip(&cells).map(|(s, &k)| s / k as f64).collect();
    let mut size = vec![model.h(); count as usize];
    for (c, &b) in of_cell.iter().enumerate() {
        let b = b as usize;
        size[b] = size[b].max((centre_of(c) - centre[b]).norm() + model.h());
    }
    Bodies {
        of_cell,
        centre,
        size,
    }
}

/// Constraint rows `[I | -[r]x]` of the nodes (`r` from their mean, in
/// units of h), restricted to the held axes; returns the orthonormal basis
/// of their row space (columns) in the local unknowns (velocity at the
/// mean, rotation times h) and the mean.
fn local_row_space(
    model: &Model,
    nodes: &[(u32, [bool; 3])],
) -> (Vec<nalgebra::Vector6<f64>>, Vector3<f64>) {
    let rest = model.rest_positions();
    let mean = nodes
        .iter()
        .fold(Vector3::zeros(), |s, &(n, _)| s + rest[n as usize])
        / nodes.len() as f64;
    let mut gram = Matrix6::<f64>::zeros();
    for &(n, axes) in nodes {
        let r = (rest[n as usize] - mean) / model.h();
        let rot = -skew(&r);
        for (a, &held) in axes.iter().enumerate() {
            if held {
                let mut row = nalgebra::Vector6::<f64>::zeros();
                row[a] = 1.0;
                for k in 0..3 {
                    row[3 + k] = rot[(a, k)];
                }
                gram += row * row.transpose();
            }
        }
    }
    let eig = SymmetricEigen::new(gram);
    let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let basis = (0..6)
        .filter(|&i| top > 0.0 && eig.eigenvalues[i] > 1e-10 * top)
        .map(|i| eig.eigenvectors.column(i).into_owned())
        .collect();
    (basis, mean)
}

/// The map from a body's unknowns (translation at its centre, rotation
/// times its size) to the local unknowns at `point`.
fn to_local(bodies: &Bodies, body: usize, point: &Vector3<f64>, h: f64) -> Matrix6<f64> {
    let size = bodies.size[body];
    let d = (point - bodies.centre[body]) / size;
    let mut t = Matrix6::<f64>::identity();
    t.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&d)));
    t.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * (h / size)));
    t
}

/// The orthogonal projector onto the row space of `rows` (full row rank).
fn projector(rows: &DMatrix<f64>) -> DMatrix<f64> {
    let gram = rows * rows.transpose();
    let inv = gram
        .cholesky()
        .map(|c| c.inverse())
        .unwrap_or_else(|| DMatrix::zeros(rows.nrows(), rows.nrows()));
    rows.transpose() * inv * rows
}

/// Nodes with the axes that constrain them.
type NodeAxes = Vec<(u32, [bool; 3])>;

/// A joint: two bodies and the nodes they share.
struct Joint {
    a: u32,
    b: u32,
    nodes: NodeAxes,
}

/// Joints between bodies and each body's held dofs, in a fixed order.
fn constraints(
    model: &Model,
    incidence: &(Vec<u32>, Vec<u32>),
    bodies: &Bodies,
    held: &[[bool; 3]],
) -> (Vec<Joint>, Vec<NodeAxes>) {
    let (start, cells_of) = incidence;
    let mut shared: Vec<(u32, u32, u32)> = Vec::new();
    let mut clamps: Vec<NodeAxes> = vec![Vec::new(); bodies.centre.len()];
    let mut here: Vec<u32> = Vec::with_capacity(8);
    for n in 0..model.num_nodes() {
        here.clear();
        here.extend(
            cells_of[start[n] as usize..start[n + 1] as usize]
                .iter()
                .map(|&c| bodies.of_cell[c as usize]),
        );
        here.sort_unstable();
        here.dedup();
        let Some(&first) = here.first() else { continue };
        for &other in &here[1..] {
            shared.push((first, other, n as u32));
        }
        if held[n].iter().any(|&h| h) {
            clamps[first as usize].push((n as u32, held[n]));
        }
    }
    shared.sort_unstable();
    let mut joints: Vec<Joint> = Vec::new();
    for (a, b, n) in shared {
        match joints.last_mut() {
            Some(j) if j.a == a && j.b == b => j.nodes.push((n, [true; 3])),
            _ => joints.push(Joint {
                a,
                b,
                nodes: vec![(n, [true; 3])],
            }),
        }
    }
    (joints, clamps)
}

/// Node -> incident cells, CSR.
fn incidence(model: &Model) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; model.num_nodes() + 1];
    for cell in model.cells() {
        for &n in cell {
            start[n as usize + 1] += 1;
        }
    }
    for i in 0..model.num_nodes() {
        start[i + 1] += start[i];
    }
    let mut cursor = start.clone();
    let mut cells_of = vec![0u32; 8 * model.num_cells()];
    for (c, cell) in model.cells().iter().enumerate() {
        for &n in cell {
            cells_of[cursor[n as usize] as usize] = c as u32;
            cursor[n as usize] += 1;
        }
    }
    (start, cells_of)
}

/// The count, or `None` when a group of bodies joined by hinges or ball
/// joints is larger than [`MAX_GROUP_BODIES`]. The caller has checked
/// [`cells_are_rigid`] and the mask's length.
pub fn zero_energy_modes_rigid_cells(model: &Model, held: &[[bool; 3]]) -> Option<ZeroModes> {
    let inc = incidence(model);
    let (start, cells_of) = &inc;
    let mut sets = Sets::new(model.num_cells());
    // Face neighbours: in a lattice two cells share 0, 1, 2 or 4 nodes.
    let mut met: Vec<(u32, u8)> = Vec::with_capacity(27);
    for (c, cell) in model.cells().iter().enumerate() {
        met.clear();
        for &n in cell {
            for &d in &cells_of[start[n as usize] as usize..start[n as usize + 1] as usize] {
                if d as usize > c {
                    match met.iter_mut().find(|(e, _)| *e == d) {
                        Some((_, k)) => *k += 1,
                        None => met.push((d, 1)),
                    }
                }
            }
        }
        for &(d, k) in &met {
            if k >= 3 {
                sets.union(c as u32, d);
            }
        }
    }
    // Merge bodies joined rigidly (non-collinear shared nodes) until none is.
    let (bodies, joints, clamps) = loop {
        let bodies = label_bodies(model, &mut sets);
        let (joints, clamps) = constraints(model, &inc, &bodies, held);
        let mut representative = vec![u32::MAX; bodies.centre.len()];
        for (c, &b) in bodies.of_cell.iter().enumerate() {
            if representative[b as usize] == u32::MAX {
                representative[b as usize] = c as u32;
            }
        }
        let mut merged = false;
        for j in &joints {
            if local_row_space(model, &j.nodes).0.len() == 6 {
                sets.union(representative[j.a as usize], representative[j.b as usize]);
                merged = true;
            }
        }
        if !merged {
            break (bodies, joints, clamps);
        }
    };
    let nb = bodies.centre.len();
    let mut groups = Sets::new(nb);
    for j in &joints {
        groups.union(j.a, j.b);
    }
    // Bodies of each group, and each body's place in its group.
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); nb];
    let mut place = vec![0usize; nb];
    for b in 0..nb as u32 {
        let g = groups.find(b) as usize;
        place[b as usize] = members[g].len();
        members[g].push(b);
    }
    let mut joints_of: Vec<Vec<usize>> = vec![Vec::new(); nb];
    for (i, j) in joints.iter().enumerate() {
        joints_of[groups.find(j.a) as usize].push(i);
    }
    let h = model.h();
    let mut count = 0;
    for (g, group) in members.iter().enumerate() {
        if group.is_empty() {
            continue;
        }
        if group.len() > MAX_GROUP_BODIES {
            return None;
        }
        let dim = 6 * group.len();
        let mut sum = DMatrix::<f64>::zeros(dim, dim);
        for &i in &joints_of[g] {
            let j = &joints[i];
            let (basis, mean) = local_row_space(model, &j.nodes);
            let ta = to_local(&bodies, j.a as usize, &mean, h);
            let tb = to_local(&bodies, j.b as usize, &mean, h);
            let mut rows = DMatrix::<f64>::zeros(basis.len(), 12);
            for (r, w) in basis.iter().enumerate() {
                let wa = w.transpose() * ta;
                let wb = w.transpose() * tb;
                for k in 0..6 {
                    rows[(r, k)] = wa[k];
                    rows[(r, 6 + k)] = -wb[k];
                }
            }
            let p = projector(&rows);
            let offsets = [6 * place[j.a as usize], 6 * place[j.b as usize]];
            for (bi, &oi) in offsets.iter().enumerate() {
                for (bj, &oj) in offsets.iter().enumerate() {
                    let mut view = sum.view_mut((oi, oj), (6, 6));
                    view += p.view((6 * bi, 6 * bj), (6, 6));
                }
            }
        }
        for &b in group {
            let clamp = &clamps[b as usize];
            if clamp.is_empty() {
                continue;
            }
            let (basis, mean) = local_row_space(model, clamp);
            let t = to_local(&bodies, b as usize, &mean, h);
            let mut rows = DMatrix::<f64>::zeros(basis.len(), 6);
            for (r, w) in basis.iter().enumerate() {
                let wt = w.transpose() * t;
                for k in 0..6 {
                    rows[(r, k)] = wt[k];
                }
            }
            let o = 6 * place[b as usize];
            let mut view = sum.view_mut((o, o), (6, 6));
            view += projector(&rows);
        }
        count += SymmetricEigen::new(sum)
            .eigenvalues
            .iter()
            .filter(|&&v| v < PROJECTOR_ZERO)
            .count();
    }
    log::debug!(
        "mode count by rigid cells: {nb} bodies, {} joints, {count} zero-energy modes",
        joints.len()
    );
    Some(ZeroModes {
        count,
        exact: true,
        method: "rigid cells",
        smallest_relative: Vec::new(),
    })
}
