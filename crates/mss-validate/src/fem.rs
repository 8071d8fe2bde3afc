//! A small hexahedral finite-element solver used as the reference solution.
//!
//! Trilinear hexahedra (Q1) with full 2x2x2 Gauss quadrature on a [`Lattice`],
//! optionally refined `r` times per cell (each cell split into `r^3` cubes), so
//! that a fine reference solution can be evaluated at the rest positions of a
//! coarse lattice's nodes. Small-strain isotropic linear elasticity, and two
//! hyperelastic laws (St. Venant-Kirchhoff and compressible neo-Hookean) solved
//! with adaptive load stepping.
//!
//! The solves are the simulator's own: the stiffness is assembled into the
//! core's 3 x 3-block matrix ([`BlockCsr`]), the nonlinear laws go through the
//! core's Newton solver ([`mss_core::solver::newton`], line search on the
//! energy's slope), and every linear solve through its
//! [`LinearSolver`]: a sparse direct solve on small meshes, multigrid-
//! preconditioned conjugate gradients on the refined references. Dirichlet
//! degrees of freedom are decoupled. Assembly is sequential in a fixed order
//! (element matrices are computed in parallel), so results do not depend on
//! the number of threads.
//!
//! Loads are consistent with the shape functions: on a cube, the consistent
//! nodal load of a uniform body force is `V/8` per corner and that of a uniform
//! traction `A/4` per face corner, which are also the MSS's lumped values, so
//! the same loads can be applied to both.

use hexmesh::lattice::CORNER_OFFSETS;
use hexmesh::{Lattice, LatticeError};
use mss_core::solver::{
    LinearSolver, LinearSolverKind, NewtonOptions as CoreNewtonOptions, NonlinearSystem, newton,
};
use mss_core::{BlockCsr, Mat3, Material, MaterialError, Vec3};
use rayon::prelude::*;
use thiserror::Error;

/// Relative residual of the linear (small-strain) solve when it is iterative.
const LINEAR_RTOL: f64 = 1e-12;

/// Why a finite-element problem could not be set up or solved.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FemError {
    /// The refined lattice could not be built.
    #[error("cannot refine the lattice: {0}")]
    Lattice(#[from] LatticeError),
    /// Refinement factor 0.
    #[error("refinement factor must be at least 1, got {0}")]
    Refinement(u32),
    /// Invalid material for finite elements (needs E > 0, -1 < nu < 0.5).
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// A vector does not have one entry per node.
    #[error("{what} has {given} entries for {nodes} nodes")]
    Length {
        /// Which input.
        what: &'static str,
        /// Entries given.
        given: usize,
        /// Nodes of the (refined) mesh.
        nodes: usize,
    },
    /// A cell's material index is out of range.
    #[error("material index {index} does not exist ({count} materials given)")]
    MaterialIndex {
        /// Index given.
        index: u32,
        /// Materials given.
        count: usize,
    },
    /// A cell material list does not have one entry per cell.
    #[error("{given} cell materials for {cells} cells")]
    CellCount {
        /// Entries given.
        given: usize,
        /// Cells of the lattice.
        cells: usize,
    },
    /// A node index is out of range.
    #[error("node {node} does not exist (the mesh has {nodes} nodes)")]
    Node {
        /// Index given.
        node: u32,
        /// Nodes of the mesh.
        nodes: usize,
    },
    /// The stiffness matrix is singular or not positive definite: the
    /// constraints do not remove all rigid motions, or the deformation is
    /// unstable.
    #[error(
        "the stiffness matrix is not positive definite ({0}); fix enough degrees of freedom to remove every rigid motion"
    )]
    NotPositiveDefinite(String),
    /// Newton's method did not converge even with small load steps.
    #[error(
        "Newton's method did not converge at load factor {load_factor} (residual {residual:e}); try more load steps"
    )]
    NoConvergence {
        /// Fraction of the total load that was reached.
        load_factor: f64,
        /// Relative residual at the failure.
        residual: f64,
    },
    /// Every degree of freedom is fixed: nothing to solve.
    #[error("every degree of freedom is fixed")]
    NoFreeDofs,
}

/// Constitutive law of the finite-element solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FemLaw {
    /// Small-strain linear elasticity (one linear solve).
    Linear,
    /// St. Venant-Kirchhoff: `S = lambda tr(E) I + 2 mu E`, Green strain `E`.
    StVenantKirchhoff,
    /// Compressible neo-Hookean:
    /// `W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`.
    NeoHookean,
}

/// Settings of the nonlinear (Newton) solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonOptions {
    /// Initial number of equal load increments (halved adaptively on failure).
    pub load_steps: u32,
    /// Newton iterations allowed per increment.
    pub max_iterations: u32,
    /// Convergence: residual norm below `tolerance` times the load norm.
    pub tolerance: f64,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        Self {
            load_steps: 8,
            max_iterations: 30,
            tolerance: 1e-10,
        }
    }
}

/// Prescribed displacement components (Dirichlet conditions), per node.
#[derive(Debug, Clone, PartialEq)]
pub struct FemConstraints {
    values: Vec<[Option<f64>; 3]>,
}

impl FemConstraints {
    /// No constraint on any of `num_nodes` nodes.
    pub fn new(num_nodes: usize) -> Self {
        Self {
            values: vec![[None; 3]; num_nodes],
        }
    }

    /// Prescribes component `axis` (0, 1, 2) of node `node` to `value` (m).
    pub fn fix(&mut self, node: u32, axis: usize, value: f64) -> Result<(), FemError> {
        let nodes = self.values.len();
        let slot = self
            .values
            .get_mut(node as usize)
            .ok_or(FemError::Node { node, nodes })?;
        slot[axis.min(2)] = Some(value);
        Ok(())
    }

    /// Prescribes the whole displacement of node `node` (m).
    pub fn fix_node(&mut self, node: u32, value: Vec3) -> Result<(), FemError> {
        for k in 0..3 {
            self.fix(node, k, value[k])?;
        }
        Ok(())
    }

    /// The prescribed value of each component, per node.
    pub fn values(&self) -> &[[Option<f64>; 3]] {
        &self.values
    }

    /// Number of prescribed components.
    pub fn num_fixed(&self) -> usize {
        self.values.iter().flatten().filter(|v| v.is_some()).count()
    }
}

/// A finite-element solution.
#[derive(Debug, Clone, PartialEq)]
pub struct FemSolution {
    /// Nodal displacements of the (refined) mesh (m).
    pub displacement: Vec<Vec3>,
    /// Newton iterations used in total (1 for a linear solve).
    pub iterations: u32,
    /// Load increments used (1 for a linear solve).
    pub load_steps: u32,
    /// Final residual norm relative to the load norm.
    pub relative_residual: f64,
}

/// A Q1 finite-element discretization of a lattice (possibly refined).
#[derive(Debug, Clone)]
pub struct Fem {
    lattice: Lattice,
    refinement: u32,
    /// Lamé constants, density and linear element stiffness per material.
    materials: Vec<FemMaterial>,
    /// Material of each (refined) cell; empty when there is one material.
    cell_material: Vec<u32>,
    /// Shape-function gradients (1/m) at the 8 Gauss points, `[gp][node][axis]`.
    grads: [[[f64; 3]; 8]; 8],
    /// Gauss weight times Jacobian determinant (same for every point).
    wdet: f64,
    /// The stiffness pattern (nodes sharing a cell), zero.
    pattern: BlockCsr,
}

/// One material of the reference: constants and its linear element stiffness.
#[derive(Debug, Clone)]
struct FemMaterial {
    mu: f64,
    lambda: f64,
    density: f64,
    /// Linear element stiffness, row-major 24 x 24, dof `3 a + i`.
    ke: Vec<f64>,
}

/// Splits every cell of `lattice` into `r^3` cubes of edge `h / r`.
pub fn refine(lattice: &Lattice, r: u32) -> Result<Lattice, FemError> {
    if r == 0 {
        return Err(FemError::Refinement(r));
    }
    if r == 1 {
        return Ok(lattice.clone());
    }
    let dims = lattice.dims().map(|d| d.saturating_mul(r));
    let cells = lattice.cell_coords().iter().flat_map(move |&c| {
        (0..r).flat_map(move |k| {
            (0..r)
                .flat_map(move |j| (0..r).map(move |i| [c[0] * r + i, c[1] * r + j, c[2] * r + k]))
        })
    });
    Ok(Lattice::from_cells(
        lattice.origin(),
        lattice.h() / r as f64,
        dims,
        cells,
    )?)
}

impl Fem {
    /// Discretizes `lattice`, each cell refined `refinement` times per axis, with
    /// an isotropic material (E > 0, -1 < nu < 0.5; the density is used by
    /// [`Fem::gravity_load`]).
    pub fn new(lattice: &Lattice, refinement: u32, material: Material) -> Result<Self, FemError> {
        Self::build(lattice, refinement, &[material], None)
    }

    /// Like [`Fem::new`], with material `materials[cell_material[c]]` in cell
    /// `c` of `lattice` (and in every refined cell inside it).
    pub fn with_cell_materials(
        lattice: &Lattice,
        refinement: u32,
        materials: &[Material],
        cell_material: &[u32],
    ) -> Result<Self, FemError> {
        if cell_material.len() != lattice.num_cells() {
            return Err(FemError::CellCount {
                given: cell_material.len(),
                cells: lattice.num_cells(),
            });
        }
        if let Some(&bad) = cell_material
            .iter()
            .find(|&&m| m as usize >= materials.len())
        {
            return Err(FemError::MaterialIndex {
                index: bad,
                count: materials.len(),
            });
        }
        Self::build(lattice, refinement, materials, Some(cell_material))
    }

    fn build(
        coarse: &Lattice,
        refinement: u32,
        materials: &[Material],
        cell_material: Option<&[u32]>,
    ) -> Result<Self, FemError> {
        let lattice = refine(coarse, refinement)?;
        let h = lattice.h();
        let g = 1.0 / 3f64.sqrt();
        let mut grads = [[[0.0; 3]; 8]; 8];
        for (gp, o) in CORNER_OFFSETS.iter().enumerate() {
            let xi: [f64; 3] = o.map(|v| if v == 0 { -g } else { g });
            for (a, oa) in CORNER_OFFSETS.iter().enumerate() {
                let s: [f64; 3] = oa.map(|v| if v == 0 { -1.0 } else { 1.0 });
                for j in 0..3 {
                    let mut d = 0.125 * s[j] * 2.0 / h;
                    for mm in 0..3 {
                        if mm != j {
                            d *= 1.0 + s[mm] * xi[mm];
                        }
                    }
                    grads[gp][a][j] = d;
                }
            }
        }
        let wdet = (h / 2.0).powi(3);
        let mut fem_materials = Vec::with_capacity(materials.len());
        for material in materials {
            let m = Material::with_poisson_range(
                material.young,
                material.poisson,
                material.density,
                -1.0,
                0.5,
            )?;
            let (mu, lambda) = (m.shear_modulus(), m.lambda());
            let mut ke = vec![0.0; 576];
            for gr in &grads {
                for a in 0..8 {
                    for b in 0..8 {
                        let ga = gr[a];
                        let gb = gr[b];
                        let dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
                        for i in 0..3 {
                            for k in 0..3 {
                                let mut v = lambda * ga[i] * gb[k] + mu * ga[k] * gb[i];
                                if i == k {
                                    v += mu * dot;
                                }
                                ke[(3 * a + i) * 24 + 3 * b + k] += wdet * v;
                            }
                        }
                    }
                }
            }
            fem_materials.push(FemMaterial {
                mu,
                lambda,
                density: m.density,
                ke,
            });
        }
        // A refined cell takes the material of the coarse cell it lies in.
        let cell_material = match cell_material {
            None => Vec::new(),
            Some(per_coarse) => {
                let index: std::collections::HashMap<[u32; 3], u32> = coarse
                    .cell_coords()
                    .iter()
                    .enumerate()
                    .map(|(c, &k)| (k, per_coarse[c]))
                    .collect();
                let r = refinement;
                lattice
                    .cell_coords()
                    .iter()
                    .map(|k| index.get(&k.map(|v| v / r)).copied().unwrap_or(0))
                    .collect()
            }
        };
        let pattern = BlockCsr::lattice_pattern(lattice.num_nodes(), lattice.cells());
        Ok(Self {
            pattern,
            lattice,
            refinement,
            materials: fem_materials,
            cell_material,
            grads,
            wdet,
        })
    }

    fn material_of(&self, cell: usize) -> &FemMaterial {
        let m = self.cell_material.get(cell).map_or(0, |&m| m as usize);
        &self.materials[m]
    }

    /// The (refined) mesh the solution lives on.
    pub fn lattice(&self) -> &Lattice {
        &self.lattice
    }

    /// Refinement factor per axis relative to the input lattice.
    pub fn refinement(&self) -> u32 {
        self.refinement
    }

    /// Number of nodes of the refined mesh.
    pub fn num_nodes(&self) -> usize {
        self.lattice.num_nodes()
    }

    /// Indices of the nodes whose rest position satisfies `pred`.
    pub fn nodes_where(&self, pred: impl Fn([f64; 3]) -> bool) -> Vec<u32> {
        (0..self.num_nodes() as u32)
            .filter(|&n| pred(self.lattice.nodes()[n as usize]))
            .collect()
    }

    /// Constraints clamping (zero displacement) every node where `pred` holds.
    pub fn clamp_where(&self, pred: impl Fn([f64; 3]) -> bool) -> FemConstraints {
        let mut c = FemConstraints::new(self.num_nodes());
        for n in self.nodes_where(pred) {
            c.values[n as usize] = [Some(0.0); 3];
        }
        c
    }

    /// Consistent nodal forces (N) of the body force `density * g` (`g` in m/s^2).
    pub fn gravity_load(&self, g: Vec3) -> Vec<Vec3> {
        let volume = self.lattice.h().powi(3);
        let mut f = vec![Vec3::zeros(); self.num_nodes()];
        for (c, cell) in self.lattice.cells().iter().enumerate() {
            let per_node = self.material_of(c).density * volume / 8.0;
            for &n in cell {
                f[n as usize] += g * per_node;
            }
        }
        f
    }

    /// Consistent nodal forces (N) of a uniform traction `t` (Pa) on the boundary
    /// faces for which `select(face centre, outward normal)` holds.
    pub fn traction_load(&self, select: impl Fn([f64; 3], [f64; 3]) -> bool, t: Vec3) -> Vec<Vec3> {
        let per_node = self.lattice.h().powi(2) / 4.0;
        let mut f = vec![Vec3::zeros(); self.num_nodes()];
        for face in self.lattice.boundary_faces() {
            let p = face.nodes.map(|n| self.lattice.nodes()[n as usize]);
            let centre = std::array::from_fn(|k| p.iter().map(|q| q[k]).sum::<f64>() / 4.0);
            if select(centre, face.rest_normal()) {
                for &n in &face.nodes {
                    f[n as usize] += t * per_node;
                }
            }
        }
        f
    }

    /// Solves for the static equilibrium under nodal forces `f` (N) and the
    /// prescribed displacements `bc`, with the constitutive `law`.
    pub fn solve(
        &self,
        law: FemLaw,
        bc: &FemConstraints,
        f: &[Vec3],
        opts: &NewtonOptions,
    ) -> Result<FemSolution, FemError> {
        let n = self.num_nodes();
        if f.len() != n {
            return Err(FemError::Length {
                what: "load vector",
                given: f.len(),
                nodes: n,
            });
        }
        if bc.values.len() != n {
            return Err(FemError::Length {
                what: "constraints",
                given: bc.values.len(),
                nodes: n,
            });
        }
        let free: Vec<bool> = bc
            .values
            .iter()
            .flat_map(|v| v.map(|c| c.is_none()))
            .collect();
        if !free.iter().any(|&f| f) {
            return Err(FemError::NoFreeDofs);
        }
        let rest: Vec<Vec3> = self
            .lattice
            .nodes()
            .iter()
            .map(|&p| Vec3::from(p))
            .collect();
        // The core's linear solver: direct for small meshes, multigrid-
        // preconditioned Krylov for the refined references.
        let mut linear = LinearSolver::for_lattice(
            self.lattice.cells(),
            &rest,
            self.lattice.h(),
            LinearSolverKind::Auto,
        );
        match law {
            FemLaw::Linear => self.solve_linear(bc, f, &free, &mut linear),
            _ => self.solve_newton(law, bc, f, opts, &free, &mut linear),
        }
    }

    /// Small-strain linear solve (same as `solve(FemLaw::Linear, ..)`).
    pub fn solve_linear_elastic(
        &self,
        bc: &FemConstraints,
        f: &[Vec3],
    ) -> Result<FemSolution, FemError> {
        self.solve(FemLaw::Linear, bc, f, &NewtonOptions::default())
    }

    /// Length scale of the mesh (its bounding box diagonal).
    fn size(&self) -> f64 {
        self.lattice.bounding_box().diagonal()
    }

    fn solve_linear(
        &self,
        bc: &FemConstraints,
        f: &[Vec3],
        free: &[bool],
        linear: &mut LinearSolver,
    ) -> Result<FemSolution, FemError> {
        let mut u = initial_displacement(bc, 1.0, None);
        let (fint, k) = self.assemble(FemLaw::Linear, &u);
        let r: Vec<Vec3> = f.iter().zip(&fint).map(|(a, b)| a - b).collect();
        let fnorm = free_norm(&r, free).max(f64::MIN_POSITIVE);
        let du = linear
            .solve_dofs(&k, &r, free, self.size(), LINEAR_RTOL)
            .map_err(|e| FemError::NotPositiveDefinite(e.to_string()))?;
        // Check the solve: a (numerically) singular matrix can give a
        // solution that does not satisfy the system.
        let mut kdu = vec![Vec3::zeros(); u.len()];
        k.mul_vec(&du, &mut kdu);
        let res: Vec<Vec3> = r.iter().zip(&kdu).map(|(a, b)| a - b).collect();
        let rel = free_norm(&res, free) / fnorm;
        if rel.is_nan() || rel >= 1e-6 {
            return Err(FemError::NotPositiveDefinite(format!(
                "linear solve residual {rel:e}"
            )));
        }
        for (ui, di) in u.iter_mut().zip(&du) {
            *ui += di;
        }
        Ok(FemSolution {
            displacement: u,
            iterations: 1,
            load_steps: 1,
            relative_residual: rel,
        })
    }

    fn solve_newton(
        &self,
        law: FemLaw,
        bc: &FemConstraints,
        f: &[Vec3],
        opts: &NewtonOptions,
        free: &[bool],
        linear: &mut LinearSolver,
    ) -> Result<FemSolution, FemError> {
        let steps = opts.load_steps.max(1);
        let mut u = initial_displacement(bc, 0.0, None);
        let mut lam = 0.0f64;
        let mut dlam = 1.0 / steps as f64;
        let min_dlam = dlam / 1024.0;
        let mut iterations = 0u32;
        let mut increments = 0u32;
        let fnorm_total = free_norm(f, free);
        let mut last_rel = 0.0;
        let newton_opts = CoreNewtonOptions {
            max_iterations: opts.max_iterations,
            rtol: opts.tolerance,
            // Hyperelastic: the residual is minus the energy's gradient.
            slope_line_search: true,
            keep_hierarchy: false,
        };
        while lam < 1.0 {
            let target = (lam + dlam).min(1.0);
            let mut trial = initial_displacement(bc, target, Some(&u));
            let scale = (fnorm_total * target).max(self.reaction_scale(law, free, &trial));
            let mut sys = FemSystem {
                fem: self,
                law,
                f,
                load: target,
                scale,
            };
            match newton(
                &mut sys,
                &mut trial,
                free,
                self.size(),
                self.lattice.h(),
                newton_opts,
                linear,
            ) {
                Ok(its) => {
                    iterations += its;
                    increments += 1;
                    let mut r = vec![Vec3::zeros(); trial.len()];
                    sys.residual(&trial, &mut r);
                    last_rel = free_norm(&r, free) / scale;
                    u = trial;
                    lam = target;
                    log::debug!("FEM load factor {lam:.4}: {its} Newton iterations");
                }
                Err(failure) => {
                    iterations += opts.max_iterations;
                    dlam *= 0.5;
                    if dlam < min_dlam {
                        let mut r = vec![Vec3::zeros(); trial.len()];
                        sys.residual(&trial, &mut r);
                        return Err(FemError::NoConvergence {
                            load_factor: lam,
                            residual: free_norm(&r, free) / scale,
                        });
                    }
                    log::debug!(
                        "FEM increment failed at {target:.4} ({failure:?}), halving to {dlam:e}"
                    );
                }
            }
        }
        Ok(FemSolution {
            displacement: u,
            iterations,
            load_steps: increments,
            relative_residual: last_rel,
        })
    }

    /// Norm of the internal forces on the held dofs: a force scale for
    /// problems loaded only by prescribed displacements.
    fn reaction_scale(&self, law: FemLaw, free: &[bool], u: &[Vec3]) -> f64 {
        let fint = self.internal_forces_only(law, u);
        let mut s = 0.0;
        for (n, fi) in fint.iter().enumerate() {
            for k in 0..3 {
                if !free[3 * n + k] {
                    s += fi[k] * fi[k];
                }
            }
        }
        s.sqrt().max(f64::MIN_POSITIVE)
    }

    /// Internal (resisting) nodal forces of the displacement `u` under `law` (N).
    pub fn internal_forces(&self, law: FemLaw, u: &[Vec3]) -> Result<Vec<Vec3>, FemError> {
        if u.len() != self.num_nodes() {
            return Err(FemError::Length {
                what: "displacement",
                given: u.len(),
                nodes: self.num_nodes(),
            });
        }
        Ok(self.internal_forces_only(law, u))
    }

    fn internal_forces_only(&self, law: FemLaw, u: &[Vec3]) -> Vec<Vec3> {
        let cells = self.lattice.cells();
        let per_elem: Vec<[f64; 24]> = cells
            .par_iter()
            .enumerate()
            .map(|(c, cell)| {
                let ue = gather(cell, u);
                let mut fe = [0.0; 24];
                self.element(self.material_of(c), law, &ue, &mut fe, None);
                fe
            })
            .collect();
        let mut out = vec![Vec3::zeros(); u.len()];
        for (cell, fe) in cells.iter().zip(&per_elem) {
            for (a, &n) in cell.iter().enumerate() {
                for k in 0..3 {
                    out[n as usize][k] += fe[3 * a + k];
                }
            }
        }
        out
    }

    /// Element internal forces and (optionally) tangent for displacements `ue`.
    fn element(
        &self,
        material: &FemMaterial,
        law: FemLaw,
        ue: &[f64; 24],
        fe: &mut [f64; 24],
        ke: Option<&mut [f64]>,
    ) {
        if law == FemLaw::Linear {
            for (i, fi) in fe.iter_mut().enumerate() {
                *fi = (0..24).map(|j| material.ke[i * 24 + j] * ue[j]).sum();
            }
            if let Some(ke) = ke {
                ke.copy_from_slice(&material.ke);
            }
            return;
        }
        let mut ke = ke;
        if let Some(k) = ke.as_deref_mut() {
            k.fill(0.0);
        }
        let (mu, lambda) = (material.mu, material.lambda);
        for gr in &self.grads {
            // Deformation gradient F_iJ = delta_iJ + sum_a u_ai dN_a/dX_J.
            let mut f = [[0.0; 3]; 3];
            for (i, row) in f.iter_mut().enumerate() {
                for (jj, v) in row.iter_mut().enumerate() {
                    *v = if i == jj { 1.0 } else { 0.0 };
                    for a in 0..8 {
                        *v += ue[3 * a + i] * gr[a][jj];
                    }
                }
            }
            let (p, tangent) = stress_and_tangent(law, &f, mu, lambda);
            for a in 0..8 {
                for i in 0..3 {
                    let mut s = 0.0;
                    for jj in 0..3 {
                        s += p[i][jj] * gr[a][jj];
                    }
                    fe[3 * a + i] += self.wdet * s;
                }
            }
            if let Some(k) = ke.as_deref_mut() {
                // H[b][i][J][k] = sum_L A_iJkL dN_b/dX_L, then K_(ai)(bk) = sum_J G_aJ H.
                for b in 0..8 {
                    let gb = gr[b];
                    let mut hb = [[[0.0; 3]; 3]; 3];
                    for i in 0..3 {
                        for jj in 0..3 {
                            for kk in 0..3 {
                                let t = &tangent[i][jj][kk];
                                hb[i][jj][kk] = t[0] * gb[0] + t[1] * gb[1] + t[2] * gb[2];
                            }
                        }
                    }
                    for a in 0..8 {
                        let ga = gr[a];
                        for i in 0..3 {
                            for kk in 0..3 {
                                let v = ga[0] * hb[i][0][kk]
                                    + ga[1] * hb[i][1][kk]
                                    + ga[2] * hb[i][2][kk];
                                k[(3 * a + i) * 24 + 3 * b + kk] += self.wdet * v;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Internal forces and the stiffness matrix (3 x 3 blocks over the nodes).
    fn assemble(&self, law: FemLaw, u: &[Vec3]) -> (Vec<Vec3>, BlockCsr) {
        let cells = self.lattice.cells();
        let mut fint = vec![Vec3::zeros(); u.len()];
        let mut k = self.pattern.clone();
        const CHUNK: usize = 2048;
        for (k_chunk, chunk) in cells.chunks(CHUNK).enumerate() {
            let elems: Vec<([f64; 24], Vec<f64>)> = chunk
                .par_iter()
                .enumerate()
                .map(|(c, cell)| {
                    let ue = gather(cell, u);
                    let mut fe = [0.0; 24];
                    let mut ke = vec![0.0; 576];
                    let material = self.material_of(k_chunk * CHUNK + c);
                    self.element(material, law, &ue, &mut fe, Some(&mut ke));
                    (fe, ke)
                })
                .collect();
            // Scattered in cell order: the sums do not depend on the threads.
            for (cell, (fe, ke)) in chunk.iter().zip(&elems) {
                for (a, &na) in cell.iter().enumerate() {
                    for i in 0..3 {
                        fint[na as usize][i] += fe[3 * a + i];
                    }
                    for (b, &nb) in cell.iter().enumerate() {
                        let block = Mat3::from_fn(|i, j| ke[(3 * a + i) * 24 + 3 * b + j]);
                        k.add(na as usize, nb as usize, &block);
                    }
                }
            }
        }
        (fint, k)
    }

    /// Displacement at point `p` (m) interpolated in the cell containing it, or
    /// `None` if `p` is outside the mesh. `u` is a nodal displacement field.
    pub fn interpolate(&self, u: &[Vec3], p: [f64; 3]) -> Option<Vec3> {
        let l = &self.lattice;
        let h = l.h();
        let o = l.origin();
        let dims = l.dims();
        let tol = 1e-9;
        let t: [f64; 3] = std::array::from_fn(|k| (p[k] - o[k]) / h);
        let mut cands: [[i64; 2]; 3] = [[0; 2]; 3];
        for k in 0..3 {
            let fl = t[k].floor() as i64;
            let near = t[k].round();
            cands[k] = if (t[k] - near).abs() < tol {
                [near as i64 - 1, near as i64]
            } else {
                [fl, fl]
            };
        }
        for &cz in &cands[2] {
            for &cy in &cands[1] {
                for &cx in &cands[0] {
                    let c = [cx, cy, cz];
                    if (0..3).any(|k| c[k] < 0 || c[k] >= dims[k] as i64) {
                        continue;
                    }
                    let cc = c.map(|v| v as u32);
                    let Some(ci) = l.cell_at(cc) else { continue };
                    let xi: [f64; 3] =
                        std::array::from_fn(|k| (t[k] - c[k] as f64).clamp(0.0, 1.0));
                    if (0..3)
                        .any(|k| (t[k] - c[k] as f64) < -tol || (t[k] - c[k] as f64) > 1.0 + tol)
                    {
                        continue;
                    }
                    let cell = l.cells()[ci as usize];
                    let mut out = Vec3::zeros();
                    for (a, off) in CORNER_OFFSETS.iter().enumerate() {
                        let w: f64 = (0..3)
                            .map(|k| if off[k] == 1 { xi[k] } else { 1.0 - xi[k] })
                            .product();
                        out += u[cell[a] as usize] * w;
                    }
                    return Some(out);
                }
            }
        }
        None
    }

    /// The displacement `u` evaluated at every point of `points`; `None` if a
    /// point is outside the mesh.
    pub fn interpolate_all(&self, u: &[Vec3], points: &[[f64; 3]]) -> Option<Vec<Vec3>> {
        points.iter().map(|&p| self.interpolate(u, p)).collect()
    }
}

/// First Piola-Kirchhoff stress `P` and its derivative `A_iJkL = dP_iJ / dF_kL`.
#[allow(clippy::type_complexity, clippy::needless_range_loop)]
fn stress_and_tangent(
    law: FemLaw,
    f: &[[f64; 3]; 3],
    mu: f64,
    lambda: f64,
) -> ([[f64; 3]; 3], [[[[f64; 3]; 3]; 3]; 3]) {
    let d = |i: usize, j: usize| if i == j { 1.0 } else { 0.0 };
    let mut p = [[0.0; 3]; 3];
    let mut a = [[[[0.0; 3]; 3]; 3]; 3];
    match law {
        FemLaw::Linear | FemLaw::StVenantKirchhoff => {
            if law == FemLaw::Linear {
                // Small strain: P = lambda tr(eps) I + 2 mu eps, eps = sym(F - I).
                let tr = f[0][0] + f[1][1] + f[2][2] - 3.0;
                for i in 0..3 {
                    for j in 0..3 {
                        let eps = 0.5 * (f[i][j] + f[j][i]) - d(i, j);
                        p[i][j] = lambda * tr * d(i, j) + 2.0 * mu * eps;
                        for k in 0..3 {
                            for l in 0..3 {
                                a[i][j][k][l] = lambda * d(i, j) * d(k, l)
                                    + mu * (d(i, k) * d(j, l) + d(i, l) * d(j, k));
                            }
                        }
                    }
                }
                return (p, a);
            }
            // Green strain E = (F^T F - I) / 2, S = lambda tr(E) I + 2 mu E, P = F S.
            let mut c = [[0.0; 3]; 3];
            let mut b = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    c[i][j] = (0..3).map(|k| f[k][i] * f[k][j]).sum();
                    b[i][j] = (0..3).map(|k| f[i][k] * f[j][k]).sum();
                }
            }
            let tr_e = 0.5 * (c[0][0] + c[1][1] + c[2][2] - 3.0);
            let mut s = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    s[i][j] = lambda * tr_e * d(i, j) + mu * (c[i][j] - d(i, j));
                }
            }
            for i in 0..3 {
                for j in 0..3 {
                    p[i][j] = (0..3).map(|m| f[i][m] * s[m][j]).sum();
                }
            }
            // A_iJkL = delta_ik S_LJ + lambda F_iJ F_kL + mu (F_iL F_kJ + (F F^T)_ik delta_JL).
            for i in 0..3 {
                for j in 0..3 {
                    for k in 0..3 {
                        for l in 0..3 {
                            a[i][j][k][l] = d(i, k) * s[l][j]
                                + lambda * f[i][j] * f[k][l]
                                + mu * (f[i][l] * f[k][j] + b[i][k] * d(j, l));
                        }
                    }
                }
            }
        }
        FemLaw::NeoHookean => {
            let fm = mss_core::Mat3::from_fn(|i, j| f[i][j]);
            let det = fm.determinant();
            let finv = fm.try_inverse().unwrap_or_else(mss_core::Mat3::identity);
            // A non-positive J has no energy: return a huge stress so the line
            // search rejects the step.
            let ln_j = if det > 0.0 { det.ln() } else { f64::INFINITY };
            for i in 0..3 {
                for j in 0..3 {
                    // P = mu (F - F^-T) + lambda ln J F^-T.
                    p[i][j] = mu * (f[i][j] - finv[(j, i)]) + lambda * ln_j * finv[(j, i)];
                    for k in 0..3 {
                        for l in 0..3 {
                            a[i][j][k][l] = mu * d(i, k) * d(j, l)
                                + (mu - lambda * ln_j) * finv[(l, i)] * finv[(j, k)]
                                + lambda * finv[(j, i)] * finv[(l, k)];
                        }
                    }
                }
            }
        }
    }
    (p, a)
}

fn gather(cell: &[u32; 8], u: &[Vec3]) -> [f64; 24] {
    let mut ue = [0.0; 24];
    for (a, &n) in cell.iter().enumerate() {
        for k in 0..3 {
            ue[3 * a + k] = u[n as usize][k];
        }
    }
    ue
}

/// Start of a load increment: the previous solution with the prescribed
/// components set to `load` times their values.
fn initial_displacement(bc: &FemConstraints, load: f64, prev: Option<&[Vec3]>) -> Vec<Vec3> {
    bc.values
        .iter()
        .enumerate()
        .map(|(n, v)| {
            let base = prev.map_or(Vec3::zeros(), |p| p[n]);
            Vec3::from_fn(|k, _| v[k].map_or(base[k], |x| x * load))
        })
        .collect()
}

/// Norm of `v` over the free dofs.
fn free_norm(v: &[Vec3], free: &[bool]) -> f64 {
    v.iter()
        .enumerate()
        .map(|(n, vi)| {
            (0..3)
                .filter(|&k| free[3 * n + k])
                .map(|k| vi[k] * vi[k])
                .sum::<f64>()
        })
        .sum::<f64>()
        .sqrt()
}

/// The equilibrium `load f - f_int(u) = 0` as a system for the core's Newton
/// solver (`u` the displacement).
struct FemSystem<'a> {
    fem: &'a Fem,
    law: FemLaw,
    f: &'a [Vec3],
    load: f64,
    scale: f64,
}

impl NonlinearSystem for FemSystem<'_> {
    fn residual(&mut self, u: &[Vec3], r: &mut [Vec3]) -> f64 {
        let fint = self.fem.internal_forces_only(self.law, u);
        for ((ri, fi), ei) in r.iter_mut().zip(&fint).zip(self.f) {
            *ri = ei * self.load - fi;
        }
        self.scale
    }

    fn jacobian(&mut self, u: &[Vec3]) -> BlockCsr {
        let (_, mut k) = self.fem.assemble(self.law, u);
        k.blocks.iter_mut().for_each(|b| *b = -*b);
        k
    }
}

/// Q1 solution on `lattice` refined `refinement` times, evaluated at the rest
/// positions of `lattice`'s own nodes (they are nodes of the refined mesh).
pub fn displacement_at_coarse_nodes(fem: &Fem, lattice: &Lattice, u: &[Vec3]) -> Option<Vec<Vec3>> {
    fem.interpolate_all(u, lattice.nodes())
}
