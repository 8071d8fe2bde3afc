//! The paper's 2D element (section 3.1): rectangles `l0 x h0` of any aspect
//! ratio in plane stress, of thickness `t`, on a [`RectLattice`].
//!
//! Each cell has two edge springs along x (`k_l`, rest length `l0`), two
//! along y (`k_h`, `h0`), two diagonals (`k_d`, `sqrt(l0^2 + h0^2)`) and,
//! in the `paper` variant, correction forces that restore Poisson's ratio.
//! docs/model.md (section 9) derives every coefficient from the Lagrangian
//! of the virtual shear and tension tests; the tests check that those tests
//! return E, nu and G at every aspect ratio.
//!
//! Nodes are [`Vec3`] in the plane `z = 0` so that the 3D solvers' pieces
//! (Newton's method, the sparse direct solves) serve the plane as they
//! are; the z components stay zero and are always held.
//!
//! Variants ([`PlaneParameterization`]):
//! - `Paper`: the paper's springs and correction forces (exact for every
//!   homogeneous strain, any nu in (-1/3, 1/2), any aspect ratio).
//! - `Springs`: the same springs without corrections (the classic MSS:
//!   exact only at nu = 1/3).
//! - `Areal`: springs exact in shear, plus an energy of the area change
//!   (`kappa t A0 (J - 1)^2 / 2`), conservative and exact for every
//!   homogeneous strain.
//!
//! Hourglass control (`hourglass = Some(alpha)`): the lattice's bending
//! modes (one cell's `u_x ~ x y` and `u_y ~ x y`) are resisted only by the
//! edge springs, whose stiffness the continuum fit sets, and `k_l < 0`
//! once `l0 / h0 > sqrt(2 + 3 nu)`: such lattices are unstable in bending.
//! The control adds, per cell, `K/2 (L_top - L_bottom)^2` on the two x
//! edges and the same on the y edges: zero for every homogeneous strain and
//! every rigid motion, exactly conservative, raising the bending modes'
//! stiffness to `alpha` times that of pure bending where the springs give
//! less.
//!
//! ```
//! use hexmesh::plane::RectLattice;
//! use mss_core::Material;
//! use mss_core::plane::{PlaneModel, PlaneParameterization};
//!
//! let lattice = RectLattice::block([4, 2], [0.02, 0.01], [0.0, 0.0]).unwrap();
//! let steel_like = Material::new(2.0e5, 0.3, 1000.0).unwrap();
//! let model = PlaneModel::new(&lattice, steel_like, 0.005, PlaneParameterization::Paper, None).unwrap();
//! // At rest no force.
//! let mut f = vec![mss_core::Vec3::zeros(); model.num_nodes()];
//! model.internal_forces(model.rest_positions(), &mut f);
//! assert!(f.iter().all(|v| v.norm() < 1e-12));
//! assert!((model.total_mass() - 1000.0 * 0.08 * 0.02 * 0.005).abs() < 1e-15);
//! ```

use hexmesh::plane::RectLattice;
use rayon::prelude::*;
use thiserror::Error;

use crate::constraints::{ConstraintError, Face, NodeSelector};
use crate::model::kernel::{Dual, Scalar};
use crate::solver::{LinearSolver, LinearSolverKind};
use crate::solver::{NewtonFailure, NewtonOptions, NonlinearSystem, newton};
use crate::{BlockCsr, Material, Precision, Vec3};

mod contact;
mod loads;

pub use contact::{PlaneContact, PlaneContactError, PlaneContactSettings, PlaneObstacle};
pub use loads::{PlaneDrag, PlaneLoad, PlaneNodalForces};

/// The 2D variants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlaneParameterization {
    /// The paper's springs and correction forces.
    Paper,
    /// The paper's springs alone.
    Springs,
    /// Springs exact in shear and an areal energy.
    Areal,
}

impl PlaneParameterization {
    /// The variants by name (`"paper"`, `"springs"`, `"areal"`).
    pub const NAMES: [&'static str; 3] = ["paper", "springs", "areal"];

    /// The variant called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "paper" => Some(Self::Paper),
            "springs" => Some(Self::Springs),
            "areal" => Some(Self::Areal),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Springs => "springs",
            Self::Areal => "areal",
        }
    }
}

/// Why a 2D model could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PlaneModelError {
    /// The thickness is not a positive finite length.
    #[error("thickness {0} must be a positive length (m)")]
    Thickness(f64),
    /// Poisson's ratio is outside what the variant reproduces.
    #[error(
        "Poisson's ratio {nu} is outside ({min}, {max}), the range the \"{variant}\" 2D element reproduces"
    )]
    Poisson {
        /// The value.
        nu: f64,
        /// Lower bound (open).
        min: f64,
        /// Upper bound (open).
        max: f64,
        /// The variant.
        variant: &'static str,
    },
    /// The hourglass strength is not a non-negative finite number.
    #[error("hourglass strength {0} must be a non-negative number")]
    Hourglass(f64),
    /// A material per cell that does not fit the lattice.
    #[error("{0}")]
    Regions(String),
}

/// The constants of one cell: spring stiffnesses (N/m), the corrections'
/// coupling, the areal modulus and the hourglass stiffnesses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneCoefficients {
    /// Each x edge (rest length `l0`).
    pub k_l: f64,
    /// Each y edge (rest length `h0`).
    pub k_h: f64,
    /// Each diagonal.
    pub k_d: f64,
    /// Face force along x per unit face force along y (corrections).
    pub c_xy: f64,
    /// Face force along y per unit face force along x.
    pub c_yx: f64,
    /// Areal modulus `kappa t` (N/m): the energy `kappa t A0 (J - 1)^2 / 2`.
    pub areal: f64,
    /// Hourglass stiffness on the x edges' length difference (N/m).
    pub hg_x: f64,
    /// Hourglass stiffness on the y edges' length difference (N/m).
    pub hg_y: f64,
}

impl PlaneCoefficients {
    /// The coefficients of an `l0 x h0` cell of thickness `t` (m).
    pub fn new(
        variant: PlaneParameterization,
        hourglass: Option<f64>,
        m: &Material,
        t: f64,
        [l0, h0]: [f64; 2],
    ) -> Result<Self, PlaneModelError> {
        if !(t.is_finite() && t > 0.0) {
            return Err(PlaneModelError::Thickness(t));
        }
        let (e, nu) = (m.young, m.poisson);
        let (min, max) = match variant {
            // The corrections' 2 x 2 system is singular at nu = -1/3.
            PlaneParameterization::Paper => (-1.0 / 3.0, 0.5),
            PlaneParameterization::Springs | PlaneParameterization::Areal => (-1.0, 0.5),
        };
        if !(nu > min && nu < max) {
            return Err(PlaneModelError::Poisson {
                nu,
                min,
                max,
                variant: variant.name(),
            });
        }
        let g = e / (2.0 * (1.0 + nu));
        let k_d = e * t * (l0 * l0 + h0 * h0) / (4.0 * l0 * h0 * (1.0 + nu));
        let (k_l, k_h, c_xy, c_yx, areal) = match variant {
            PlaneParameterization::Paper | PlaneParameterization::Springs => {
                let k = |i: f64, j: f64| {
                    e * t * (j * j * (2.0 + 3.0 * nu) - i * i) / (4.0 * l0 * h0 * (1.0 + nu))
                };
                let c = if variant == PlaneParameterization::Paper {
                    (3.0 * nu - 1.0) / 2.0
                } else {
                    0.0
                };
                (k(l0, h0), k(h0, l0), c * h0 / l0, c * l0 / h0, 0.0)
            }
            PlaneParameterization::Areal => {
                let lambda_plane = e * nu / (1.0 - nu * nu);
                (
                    g * t * (3.0 * h0 * h0 - l0 * l0) / (2.0 * l0 * h0),
                    g * t * (3.0 * l0 * l0 - h0 * h0) / (2.0 * l0 * h0),
                    0.0,
                    0.0,
                    (lambda_plane - g) * t,
                )
            }
        };
        let (hg_x, hg_y) = match hourglass {
            None => (0.0, 0.0),
            Some(alpha) if alpha.is_finite() && alpha >= 0.0 => {
                // Pure bending's stiffness in the cell's bending modes; the
                // springs give 8 k there, the penalty 16 K.
                let target_x = alpha * 4.0 / 3.0 * e * t * h0 / l0;
                let target_y = alpha * 4.0 / 3.0 * e * t * l0 / h0;
                ((target_x - 8.0 * k_l) / 16.0, (target_y - 8.0 * k_h) / 16.0)
            }
            Some(alpha) => return Err(PlaneModelError::Hourglass(alpha)),
        };
        Ok(Self {
            k_l,
            k_h,
            k_d,
            c_xy,
            c_yx,
            areal,
            hg_x,
            hg_y,
        })
    }
}

/// A 2D mass-spring model on a [`RectLattice`].
#[derive(Debug, Clone)]
pub struct PlaneModel {
    rest: Vec<Vec3>,
    cells: Vec<[u32; 4]>,
    size: [f64; 2],
    thickness: f64,
    masses: Vec<f64>,
    coefficients: PlaneCoefficients,
    material: Material,
    variant: PlaneParameterization,
    /// The coefficients of each region's material after the first
    /// (`[[regions]]`); empty in one material.
    region_coefficients: Vec<PlaneCoefficients>,
    /// Each cell's material: 0 the model's, k the k-th of
    /// `region_coefficients` (empty in one material).
    cell_material: Vec<u32>,
    /// CSR node -> (cell, corner), for a gather in a fixed order.
    node_offsets: Vec<u32>,
    node_corners: Vec<u32>,
}

/// `s_x` and `s_y` of the corners (`-1` on the low face, `+1` on the high).
const SIGNS: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

impl PlaneModel {
    /// The model of `lattice` in one material, thickness `thickness` (m).
    pub fn new(
        lattice: &RectLattice,
        material: Material,
        thickness: f64,
        variant: PlaneParameterization,
        hourglass: Option<f64>,
    ) -> Result<Self, PlaneModelError> {
        let coefficients = PlaneCoefficients::new(
            variant,
            hourglass,
            &material,
            thickness,
            lattice.cell_size(),
        )?;
        let mut model = Self::with_coefficients(lattice, material, thickness, coefficients)?;
        model.variant = variant;
        Ok(model)
    }

    /// The model with a material per cell: `cell_material[c]` is 0 for
    /// the model's material and k for `materials[k - 1]`, each with the
    /// model's variant and hourglass factor `hourglass` (as given to
    /// [`PlaneModel::new`]). The masses follow each cell's density.
    pub fn with_regions(
        mut self,
        hourglass: Option<f64>,
        materials: &[Material],
        cell_material: Vec<u32>,
    ) -> Result<Self, PlaneModelError> {
        if cell_material.len() != self.cells.len() {
            return Err(PlaneModelError::Regions(format!(
                "{} cell materials for {} cells",
                cell_material.len(),
                self.cells.len()
            )));
        }
        if let Some(m) = cell_material
            .iter()
            .find(|&&m| m as usize > materials.len())
        {
            return Err(PlaneModelError::Regions(format!(
                "a cell names material {m}, but there are {} besides the model's",
                materials.len()
            )));
        }
        self.region_coefficients = materials
            .iter()
            .map(|m| PlaneCoefficients::new(self.variant, hourglass, m, self.thickness, self.size))
            .collect::<Result<_, _>>()?;
        let area = self.size[0] * self.size[1] * self.thickness / 4.0;
        self.masses.iter_mut().for_each(|m| *m = 0.0);
        for (c, cell) in self.cells.iter().enumerate() {
            let density = match cell_material[c] {
                0 => self.material.density,
                k => materials[k as usize - 1].density,
            };
            for &a in cell {
                self.masses[a as usize] += density * area;
            }
        }
        self.cell_material = cell_material;
        Ok(self)
    }

    /// The coefficients of cell `c`.
    fn coefficients_of(&self, c: usize) -> &PlaneCoefficients {
        match self.cell_material.get(c) {
            None | Some(0) => &self.coefficients,
            Some(&k) => &self.region_coefficients[k as usize - 1],
        }
    }

    /// Each cell's material index (see [`PlaneModel::with_regions`]; empty
    /// in one material).
    pub fn cell_materials(&self) -> &[u32] {
        &self.cell_material
    }

    /// The coefficients of every material, the model's first.
    pub fn all_coefficients(&self) -> impl Iterator<Item = &PlaneCoefficients> {
        std::iter::once(&self.coefficients).chain(&self.region_coefficients)
    }

    /// The model of `lattice` with given cell coefficients (to study
    /// other parameterizations; the variant reads `paper`).
    pub fn with_coefficients(
        lattice: &RectLattice,
        material: Material,
        thickness: f64,
        coefficients: PlaneCoefficients,
    ) -> Result<Self, PlaneModelError> {
        if !(thickness.is_finite() && thickness > 0.0) {
            return Err(PlaneModelError::Thickness(thickness));
        }
        let size = lattice.cell_size();
        let rest: Vec<Vec3> = lattice
            .nodes()
            .iter()
            .map(|p| Vec3::new(p[0], p[1], 0.0))
            .collect();
        let n = rest.len();
        let corner_mass = material.density * size[0] * size[1] * thickness / 4.0;
        let mut masses = vec![0.0; n];
        let mut node_offsets = vec![0u32; n + 1];
        for c in lattice.cells() {
            for &a in c {
                masses[a as usize] += corner_mass;
                node_offsets[a as usize + 1] += 1;
            }
        }
        for i in 0..n {
            node_offsets[i + 1] += node_offsets[i];
        }
        let mut fill = node_offsets.clone();
        let mut node_corners = vec![0u32; node_offsets[n] as usize];
        for (ci, c) in lattice.cells().iter().enumerate() {
            for (k, &a) in c.iter().enumerate() {
                node_corners[fill[a as usize] as usize] = (4 * ci + k) as u32;
                fill[a as usize] += 1;
            }
        }
        Ok(Self {
            rest,
            cells: lattice.cells().to_vec(),
            size,
            thickness,
            masses,
            coefficients,
            material,
            variant: PlaneParameterization::Paper,
            region_coefficients: Vec::new(),
            cell_material: Vec::new(),
            node_offsets,
            node_corners,
        })
    }

    /// Rest positions (m, z = 0).
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }
    /// The cells (counter-clockwise).
    pub fn cells(&self) -> &[[u32; 4]] {
        &self.cells
    }
    /// The cells as 8 corners (each quad twice), for the 3D sparse patterns.
    pub fn cells_as_hex(&self) -> Vec<[u32; 8]> {
        self.cells
            .iter()
            .map(|c| [c[0], c[1], c[2], c[3], c[0], c[1], c[2], c[3]])
            .collect()
    }
    /// The cell size `[l0, h0]` (m).
    pub fn cell_size(&self) -> [f64; 2] {
        self.size
    }
    /// The thickness (m).
    pub fn thickness(&self) -> f64 {
        self.thickness
    }
    /// Lumped node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    /// Total mass (kg).
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().sum()
    }
    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.rest.len()
    }
    /// Number of cells.
    pub fn num_cells(&self) -> usize {
        self.cells.len()
    }
    /// The coefficients of the model's material (cells of other
    /// materials have their own: [`PlaneModel::with_regions`]).
    pub fn coefficients(&self) -> PlaneCoefficients {
        self.coefficients
    }
    /// The material.
    pub fn material(&self) -> Material {
        self.material
    }
    /// The variant.
    pub fn parameterization(&self) -> PlaneParameterization {
        self.variant
    }

    fn corners(&self, x: &[Vec3], c: usize) -> [[f64; 2]; 4] {
        self.cells[c].map(|a| [x[a as usize].x, x[a as usize].y])
    }

    /// The internal forces of cell `c` on its 4 corners (N).
    pub fn cell_forces(&self, x: &[Vec3], c: usize) -> [[f64; 2]; 4] {
        cell_forces(self.coefficients_of(c), self.size, &self.corners(x, c))
    }

    /// The internal forces at `x` (N; z components zero). Cells in
    /// parallel, each node summing its cells in a fixed order: the result
    /// does not depend on the thread count.
    pub fn internal_forces(&self, x: &[Vec3], out: &mut [Vec3]) {
        self.internal_forces_with(x, out, Precision::F64);
    }

    /// [`PlaneModel::internal_forces`] with the cell kernel in `precision`.
    /// In `F32` each cell's corners are taken relative to its corner 0
    /// before rounding (the forces do not depend on where the cell is, and
    /// a body far from the origin loses nothing to its placement), and the
    /// nodes' sums stay in `f64`, as the 3D force pass does.
    pub fn internal_forces_with(&self, x: &[Vec3], out: &mut [Vec3], precision: Precision) {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        let per_cell: Vec<[[f64; 2]; 4]> = match precision {
            Precision::F64 => (0..self.cells.len())
                .into_par_iter()
                .map(|c| self.cell_forces(x, c))
                .collect(),
            Precision::F32 => (0..self.cells.len())
                .into_par_iter()
                .map(|c| {
                    let p = self.corners(x, c);
                    let rel: [[f32; 2]; 4] = std::array::from_fn(|n| {
                        std::array::from_fn(|d| (p[n][d] - p[0][d]) as f32)
                    });
                    cell_forces(self.coefficients_of(c), self.size, &rel).map(|f| f.map(f64::from))
                })
                .collect(),
        };
        out.par_iter_mut().enumerate().for_each(|(i, f)| {
            let mut s = [0.0; 2];
            let span = self.node_offsets[i] as usize..self.node_offsets[i + 1] as usize;
            for &k in &self.node_corners[span] {
                let g = per_cell[k as usize / 4][k as usize % 4];
                s[0] += g[0];
                s[1] += g[1];
            }
            *f = Vec3::new(s[0], s[1], 0.0);
        });
    }

    /// Potential energy of the conservative terms (springs, areal energy,
    /// hourglass control; J). The corrections of the `paper` variant are
    /// not the gradient of an energy.
    pub fn energy(&self, x: &[Vec3]) -> f64 {
        (0..self.cells.len())
            .map(|c| cell_energy(self.coefficients_of(c), self.size, &self.corners(x, c)))
            .sum()
    }

    /// The Jacobian d(internal force)/dx (N/m) as 3 x 3 blocks (z rows and
    /// columns zero), each cell's 8 x 8 block by central differences of its
    /// forces (step `1e-6` of the smaller cell side: relative accuracy
    /// about 1e-10 on these smooth forces).
    pub fn tangent(&self, x: &[Vec3]) -> BlockCsr {
        let hex = self.cells_as_hex();
        let mut m = BlockCsr::lattice_pattern(self.num_nodes(), &hex);
        // Column `col` of each cell's 8 x 8 Jacobian, d f / d (dof col):
        // the cell's forces on dual numbers, exact.
        let columns: Vec<[[f64; 8]; 8]> = (0..self.cells.len())
            .into_par_iter()
            .map(|c| {
                let p = self.corners(x, c);
                let dual: [[Dual<8>; 2]; 4] =
                    std::array::from_fn(|n| std::array::from_fn(|d| Dual::var(p[n][d], 2 * n + d)));
                let f = cell_forces(self.coefficients_of(c), self.size, &dual);
                let mut columns = [[0.0; 8]; 8];
                for (col, column) in columns.iter_mut().enumerate() {
                    for (row, v) in column.iter_mut().enumerate() {
                        *v = f[row / 2][row % 2].g[col];
                    }
                }
                columns
            })
            .collect();
        for (c, columns) in columns.iter().enumerate() {
            for (b, &rb) in self.cells[c].iter().enumerate() {
                for (a, &ca) in self.cells[c].iter().enumerate() {
                    let k = m
                        .find(rb as usize, ca as usize)
                        .expect("pair in the pattern");
                    for e in 0..2 {
                        for d in 0..2 {
                            m.blocks[k][(e, d)] += columns[2 * a + d][2 * b + e];
                        }
                    }
                }
            }
        }
        m
    }

    /// Highest angular frequency bound at rest (1/s), by Gershgorin's
    /// theorem on the rest stiffness and the lumped masses.
    pub fn omega_max_bound(&self) -> f64 {
        let k = self.tangent(&self.rest);
        let mut worst: f64 = 0.0;
        for i in 0..self.num_nodes() {
            let span = k.row_offsets[i] as usize..k.row_offsets[i + 1] as usize;
            for d in 0..2 {
                let row: f64 = span
                    .clone()
                    .map(|j| (0..2).map(|e| k.blocks[j][(d, e)].abs()).sum::<f64>())
                    .sum();
                worst = worst.max(row / self.masses[i]);
            }
        }
        worst.sqrt()
    }

    /// The nodes `selector` picks among the rest positions, ascending. The
    /// lowest layer is the nodes of least y (the plane's "down"); the z
    /// faces do not exist in the plane. An empty selection is an error.
    pub fn select_nodes(&self, selector: &NodeSelector) -> Result<Vec<u32>, ConstraintError> {
        let h = self.size[0].min(self.size[1]);
        let rest = &self.rest;
        let nodes = match selector {
            NodeSelector::LowestLayer => {
                let low = rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
                (0..rest.len() as u32)
                    .filter(|&i| rest[i as usize].y <= low + 1e-9 * h)
                    .collect()
            }
            NodeSelector::Face {
                face: Face::ZMin | Face::ZMax,
            } => return Err(ConstraintError::NotInPlane(selector.to_string())),
            other => other.select_checked(rest, h)?,
        };
        if nodes.is_empty() {
            return Err(ConstraintError::EmptySelection {
                selector: selector.to_string(),
                min: crate::constraints::node_bounds(rest).min,
                max: crate::constraints::node_bounds(rest).max,
            });
        }
        Ok(nodes)
    }

    /// The lattice's boundary edges (sides of one cell only) as node pairs
    /// `(a, b)` with `a < b`, sorted: sums over them do not depend on a
    /// hash order.
    pub fn boundary_edges(&self) -> Vec<(u32, u32)> {
        let mut boundary: Vec<(u32, u32)> = hexmesh::plane::boundary_edges_of(&self.cells)
            .into_iter()
            .map(|[a, b]| (a.min(b), a.max(b)))
            .collect();
        boundary.sort_unstable();
        boundary
    }

    /// The nodal forces (N) of a dead traction `traction` (Pa, in the
    /// plane) on the boundary edges whose midpoints lie in the box
    /// `min..max` (z = 0 must be in it): each edge carries the traction
    /// times its length and the thickness, half at each end. `None` when
    /// no edge is in the box.
    pub fn traction_forces(
        &self,
        min: [f64; 3],
        max: [f64; 3],
        traction: [f64; 2],
    ) -> Option<Vec<(u32, [f64; 2])>> {
        let tol = 1e-9 * self.size[0].min(self.size[1]);
        let mut forces = Vec::new();
        for (a, b) in self.boundary_edges() {
            let (pa, pb) = (self.rest[a as usize], self.rest[b as usize]);
            let mid = [0.5 * (pa.x + pb.x), 0.5 * (pa.y + pb.y), 0.0];
            if !(0..3).all(|k| mid[k] >= min[k] - tol && mid[k] <= max[k] + tol) {
                continue;
            }
            let half = 0.5 * (pb - pa).norm() * self.thickness;
            for n in [a, b] {
                forces.push((n, [traction[0] * half, traction[1] * half]));
            }
        }
        (!forces.is_empty()).then_some(forces)
    }

    /// Whether the lattice is unstable in bending: a cell without hourglass
    /// control whose edge springs are negative (`k_l < 0` once
    /// `l0 / h0 > sqrt(2 + 3 nu)`, or `k_h < 0` the other way), so that its
    /// bending modes have negative stiffness and no equilibrium is stable.
    pub fn unstable_in_bending(&self) -> bool {
        self.all_coefficients()
            .any(|c| c.hg_x == 0.0 && c.hg_y == 0.0 && (c.k_l < 0.0 || c.k_h < 0.0))
    }

    /// The largest stiffness of a node at rest (N/m): the scale of a
    /// contact penalty that keeps the body out of obstacles without
    /// shortening the step much.
    pub fn max_node_stiffness(&self) -> f64 {
        let k = self.tangent(&self.rest);
        (0..self.num_nodes())
            .filter_map(|i| k.find(i, i))
            .map(|j| k.blocks[j][(0, 0)].abs().max(k.blocks[j][(1, 1)].abs()))
            .fold(0.0, f64::max)
    }

    /// A stable explicit time step (s): `2 / omega_max` times `safety`.
    pub fn stable_time_step(&self, safety: f64) -> f64 {
        safety * 2.0 / self.omega_max_bound()
    }
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn norm(a: [f64; 2]) -> f64 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}

/// The 6 springs as (node a, node b, stiffness, rest length).
fn springs(k: &PlaneCoefficients, [l0, h0]: [f64; 2]) -> [(usize, usize, f64, f64); 6] {
    let d = (l0 * l0 + h0 * h0).sqrt();
    [
        (0, 1, k.k_l, l0),
        (3, 2, k.k_l, l0),
        (1, 2, k.k_h, h0),
        (0, 3, k.k_h, h0),
        (0, 2, k.k_d, d),
        (1, 3, k.k_d, d),
    ]
}

/// The edge pairs whose length difference the hourglass control penalizes:
/// ((bottom x edge, top x edge), stiffness), then the y edges'.
fn hourglass_pairs(k: &PlaneCoefficients) -> [([usize; 2], [usize; 2], f64); 2] {
    [([0, 1], [3, 2], k.hg_x), ([0, 3], [1, 2], k.hg_y)]
}

fn area(p: &[[f64; 2]; 4]) -> f64 {
    0.5 * (0..4)
        .map(|i| p[i][0] * p[(i + 1) % 4][1] - p[(i + 1) % 4][0] * p[i][1])
        .sum::<f64>()
}

fn cell_energy(k: &PlaneCoefficients, size: [f64; 2], p: &[[f64; 2]; 4]) -> f64 {
    let mut e = 0.0;
    for (a, b, stiffness, rest) in springs(k, size) {
        let stretch = norm(sub(p[b], p[a])) - rest;
        e += 0.5 * stiffness * stretch * stretch;
    }
    if k.areal != 0.0 {
        let a0 = size[0] * size[1];
        let j = area(p) / a0;
        e += 0.5 * k.areal * a0 * (j - 1.0) * (j - 1.0);
    }
    for (lo, hi, stiffness) in hourglass_pairs(k) {
        if stiffness != 0.0 {
            let diff = norm(sub(p[hi[1]], p[hi[0]])) - norm(sub(p[lo[1]], p[lo[0]]));
            e += 0.5 * stiffness * diff * diff;
        }
    }
    e
}

/// The internal forces of one cell on its corners, in any number type of
/// the kernel: `f64`, `f32` (the single-precision force pass) or dual
/// numbers (the exact tangent).
fn cell_forces<T: Scalar>(k: &PlaneCoefficients, size: [f64; 2], p: &[[T; 2]; 4]) -> [[T; 2]; 4] {
    let zero = T::cst(0.0);
    let sub = |a: [T; 2], b: [T; 2]| [a[0] - b[0], a[1] - b[1]];
    let norm = |a: [T; 2]| (a[0] * a[0] + a[1] * a[1]).sqrt();
    let mut f = [[zero; 2]; 4];
    for (a, b, stiffness, rest) in springs(k, size) {
        let d = sub(p[b], p[a]);
        let len = norm(d);
        if len.any_below(f64::MIN_POSITIVE) {
            continue;
        }
        let s = (len - T::cst(rest)).scale(stiffness) / len;
        for c in 0..2 {
            f[a][c] += s * d[c];
            f[b][c] -= s * d[c];
        }
    }
    if k.c_xy != 0.0 || k.c_yx != 0.0 {
        // Current axes: the mean edge directions.
        let unit = |v: [T; 2]| {
            let n = norm(v);
            [v[0] / n, v[1] / n]
        };
        let ax = unit([
            p[1][0] - p[0][0] + p[2][0] - p[3][0],
            p[1][1] - p[0][1] + p[2][1] - p[3][1],
        ]);
        let ay = unit([
            p[3][0] - p[0][0] + p[2][0] - p[1][0],
            p[3][1] - p[0][1] + p[2][1] - p[1][1],
        ]);
        // Spring tension across each axis (positive when stretched).
        let mut t = [zero; 2];
        for (n, s) in SIGNS.iter().enumerate() {
            t[0] -= (f[n][0] * ax[0] + f[n][1] * ax[1]).scale(0.5 * s[0]);
            t[1] -= (f[n][0] * ay[0] + f[n][1] * ay[1]).scale(0.5 * s[1]);
        }
        // Face forces N: N_x - c_xy N_y = T_x, N_y - c_yx N_x = T_y.
        let det = 1.0 - k.c_xy * k.c_yx;
        let nx = (t[0] + t[1].scale(k.c_xy)).scale(1.0 / det);
        let ny = (t[1] + t[0].scale(k.c_yx)).scale(1.0 / det);
        let corr = [ny.scale(k.c_xy), nx.scale(k.c_yx)];
        for (n, s) in SIGNS.iter().enumerate() {
            for c in 0..2 {
                f[n][c] +=
                    (corr[0] * ax[c]).scale(-0.5 * s[0]) - (corr[1] * ay[c]).scale(0.5 * s[1]);
            }
        }
    }
    if k.areal != 0.0 {
        let a0 = size[0] * size[1];
        let twice_area = (0..4).fold(zero, |acc, i| {
            acc + p[i][0] * p[(i + 1) % 4][1] - p[(i + 1) % 4][0] * p[i][1]
        });
        let j = twice_area.scale(0.5 / a0);
        let scale = (j - T::cst(1.0)).scale(-k.areal);
        for i in 0..4 {
            let (next, prev) = (p[(i + 1) % 4], p[(i + 3) % 4]);
            f[i][0] += (scale * (next[1] - prev[1])).scale(0.5);
            f[i][1] += (scale * (prev[0] - next[0])).scale(0.5);
        }
    }
    for (lo, hi, stiffness) in hourglass_pairs(k) {
        if stiffness == 0.0 {
            continue;
        }
        let dl = sub(p[lo[1]], p[lo[0]]);
        let dh = sub(p[hi[1]], p[hi[0]]);
        let (ll, lh) = (norm(dl), norm(dh));
        let s = (lh - ll).scale(-stiffness);
        for c in 0..2 {
            // d(lh)/d p[hi[1]] = dh / lh, and the opposite at hi[0].
            let (gh, gl) = (s * dh[c] / lh, s * dl[c] / ll);
            f[hi[1]][c] += gh;
            f[hi[0]][c] -= gh;
            f[lo[1]][c] -= gl;
            f[lo[0]][c] += gl;
        }
    }
    f
}

/// A 2D problem's static residual under a fraction `load` of its loads,
/// and its Jacobian (the penalty's tangent included), for [`newton`].
struct StaticSystem<'a> {
    p: &'a PlaneProblem,
    load: f64,
    /// The size of the forces of `p.loads` where the solve starts (N):
    /// part of the residual's scale.
    loads_at_start: f64,
    /// Where the moving obstacles are (s).
    time: f64,
}

impl NonlinearSystem for StaticSystem<'_> {
    fn residual(&mut self, x: &[Vec3], r: &mut [Vec3]) -> f64 {
        let p = self.p;
        p.forces_under(x, None, self.load, self.time, Precision::F64, r);
        let weight: f64 = p
            .model
            .masses
            .iter()
            .map(|m| self.load * m * p.gravity[0].hypot(p.gravity[1]))
            .sum();
        let applied: f64 = p
            .forces
            .iter()
            .map(|f| self.load * f[0].hypot(f[1]))
            .sum::<f64>()
            + self.load * self.loads_at_start;
        let reactions: f64 = r.iter().map(|v| v.norm()).sum();
        (weight + applied).max(1e-3 * reactions).max(1e-300)
    }
    fn jacobian(&mut self, x: &[Vec3]) -> BlockCsr {
        self.p.tangent_at(x, self.time, self.load, None)
    }
}

/// A Newton failure in words (`step`: of an implicit step).
fn newton_error(e: NewtonFailure, step: Option<usize>) -> PlaneSolveError {
    let what = match e {
        NewtonFailure::Diverged(d) => d.to_string(),
        NewtonFailure::Singular(nodes) => format!(
            "the stiffness is singular: the held nodes leave a mechanism (nodes {:?} move freely)",
            &nodes[..nodes.len().min(8)]
        ),
        NewtonFailure::Linear(m) => m,
        NewtonFailure::Cancelled => "cancelled".into(),
    };
    PlaneSolveError::Newton(match step {
        Some(k) => format!("implicit step {k} did not converge: {what}"),
        None => format!("the static solve did not converge: {what}"),
    })
}

/// How many times a 2D implicit step is halved where Newton's method fails
/// before the failure is reported.
pub const MAX_IMPLICIT_HALVINGS: u32 = 6;

/// Smallest load increment of a 2D static solve, as a fraction of the load.
pub const MIN_LOAD_STEP: f64 = 1.0 / 1024.0;

/// A 2D problem: a model, held nodes, in-plane gravity, nodal forces and
/// mass-proportional damping.
#[derive(Debug, Clone)]
pub struct PlaneProblem {
    /// The model.
    pub model: PlaneModel,
    /// Held nodes (both in-plane components; `[x, y]` each).
    pub held: Vec<[bool; 2]>,
    /// Gravity in the plane (m/s^2).
    pub gravity: [f64; 2],
    /// Extra forces per node (N).
    pub forces: Vec<[f64; 2]>,
    /// Mass-proportional damping (1/s).
    pub damping: f64,
    /// Contact with rigid obstacles.
    pub contact: Option<PlaneContact>,
    /// Held nodes moved along prescribed paths ([`PlaneMotion`]); their
    /// nodes are held (`held`) too.
    pub motions: Vec<PlaneMotion>,
    /// Further loads: drag springs, custom loads ([`PlaneLoad`]); scaled
    /// by the static solve's load factor like gravity and `forces`.
    pub loads: Vec<std::sync::Arc<dyn PlaneLoad>>,
    /// The linear solver of Newton's iterations ([`LinearSolverKind::Auto`]:
    /// direct for small lattices, multigrid-preconditioned Krylov above).
    pub linear_solver: LinearSolverKind,
    /// The precision of the explicit step's force pass
    /// ([`PlaneModel::internal_forces_with`]); Newton's solves (static and
    /// implicit) always take `f64`.
    pub precision: Precision,
}

/// Held nodes moved by `displacement` (m), reached linearly from t = 0 to
/// `ramp` (s) and then kept: a scene's `[[motions]]` in the plane.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneMotion {
    /// The nodes moved.
    pub nodes: Vec<u32>,
    /// Their final displacement (m).
    pub displacement: [f64; 2],
    /// When it is reached (s, > 0).
    pub ramp: f64,
}

impl PlaneMotion {
    /// The displacement at time `t` (s).
    pub fn displacement_at(&self, t: f64) -> [f64; 2] {
        let share = (t / self.ramp).clamp(0.0, 1.0);
        self.displacement.map(|d| d * share)
    }

    /// The velocity at time `t` (s): constant during the ramp, then zero.
    pub fn velocity_at(&self, t: f64) -> [f64; 2] {
        if (0.0..self.ramp).contains(&t) {
            self.displacement.map(|d| d / self.ramp)
        } else {
            [0.0; 2]
        }
    }
}

/// Why a 2D solve failed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PlaneSolveError {
    /// Newton's method did not converge (what it was solving, and why).
    #[error("{0}")]
    Newton(String),
    /// The motion grew without bound.
    #[error("the simulation diverged at step {0} (a position is no longer finite)")]
    Diverged(usize),
}

impl PlaneProblem {
    /// A problem on `model` with nothing held and no load.
    pub fn new(model: PlaneModel) -> Self {
        let n = model.num_nodes();
        Self {
            model,
            held: vec![[false; 2]; n],
            gravity: [0.0; 2],
            forces: vec![[0.0; 2]; n],
            damping: 0.0,
            contact: None,
            motions: Vec::new(),
            loads: Vec::new(),
            linear_solver: LinearSolverKind::Auto,
            precision: Precision::F64,
        }
    }

    /// Puts the moved nodes where their motions have them at time `t`,
    /// `share` of the way (a static solve's load increment), with their
    /// velocity at `t` when `v` is given.
    fn place_moved(&self, t: f64, share: f64, x: &mut [Vec3], mut v: Option<&mut [Vec3]>) {
        let rest = &self.model.rest;
        for m in &self.motions {
            let d = m.displacement_at(t);
            let u = m.velocity_at(t);
            for &n in &m.nodes {
                let n = n as usize;
                x[n].x = rest[n].x + share * d[0];
                x[n].y = rest[n].y + share * d[1];
                if let Some(v) = v.as_deref_mut() {
                    v[n].x = u[0];
                    v[n].y = u[1];
                }
            }
        }
    }

    /// A stable explicit step (s) for the model and the contact penalty:
    /// `2 / omega_max` times `safety`.
    pub fn stable_time_step(&self, safety: f64) -> f64 {
        let omega = self.model.omega_max_bound();
        let contact = self.contact.as_ref().map_or(0.0, |c| {
            let lightest = self
                .model
                .masses
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min);
            let (stiffness, zeta) = c.stiffest();
            // The contact's damper is explicit in the step: a damped
            // oscillator stays stable up to `omega dt = 2 (sqrt(1 + z^2) - z)`.
            let shrink = (1.0 + zeta * zeta).sqrt() - zeta;
            stiffness / lightest / (shrink * shrink)
        });
        safety * 2.0 / (omega * omega + contact).sqrt()
    }

    /// Internal plus external forces at `x` (N) at time `t` (s; where the
    /// moving obstacles are), the nodes moving at `v` (`None`: at rest; the
    /// contact's dampers act on the velocity).
    pub fn total_forces(&self, t: f64, x: &[Vec3], v: Option<&[Vec3]>, out: &mut [Vec3]) {
        self.forces_under(x, v, 1.0, t, Precision::F64, out);
    }

    /// Internal and contact forces (the obstacles at time `t`) plus `load`
    /// times gravity and the nodal forces, at `x` moving at `v` (N).
    fn forces_under(
        &self,
        x: &[Vec3],
        v: Option<&[Vec3]>,
        load: f64,
        t: f64,
        precision: Precision,
        out: &mut [Vec3],
    ) {
        self.model.internal_forces_with(x, out, precision);
        for l in &self.loads {
            l.add_forces(&self.model, t, x, load, out);
        }
        for (i, f) in out.iter_mut().enumerate() {
            let m = self.model.masses[i];
            f.x += load * (m * self.gravity[0] + self.forces[i][0]);
            f.y += load * (m * self.gravity[1] + self.forces[i][1]);
            if let Some(c) = &self.contact {
                let vel = v.map(|v| [v[i].x, v[i].y]);
                let g = c.force([x[i].x, x[i].y], vel, m, t);
                f.x += g[0];
                f.y += g[1];
            }
        }
    }

    /// The Jacobian of the forces at `x` (obstacles at time `t`, `load`
    /// times the loads): the model's tangent, the loads' and the contact's (its dampers' through the velocity
    /// `(x - x0) / dt` of an implicit step: `moving = (x0, dt)`), for nodes
    /// within 1 % of a cell of touching too.
    fn tangent_at(
        &self,
        x: &[Vec3],
        t: f64,
        load: f64,
        moving: Option<(&[Vec3], f64)>,
    ) -> BlockCsr {
        let mut j = self.model.tangent(x);
        for l in &self.loads {
            l.add_jacobian(&self.model, t, x, load, &mut j);
        }
        if let Some(c) = &self.contact {
            let margin = 0.01 * self.model.size[0].min(self.model.size[1]);
            for (i, p) in x.iter().enumerate() {
                let v = moving.map(|(x0, dt)| {
                    let v = (p - x0[i]) / dt;
                    ([v.x, v.y], dt)
                });
                let m = self.model.masses[i];
                c.add_tangent(&mut j, i, [p.x, p.y], v, m, t, margin);
            }
        }
        j
    }

    /// The linear solver of the Newton iterations, of the kind
    /// `linear_solver` says (the multigrid coarsens the lattice's grid as
    /// a cube lattice's; z is always held).
    fn linear_solver(&self) -> LinearSolver {
        LinearSolver::for_rect_lattice(
            &self.model.cells_as_hex(),
            &self.model.rest,
            self.model.size,
            self.linear_solver,
        )
    }

    /// The sum of the sizes of the nodal forces of `loads` at `(t, x)` (N).
    fn loads_size(&self, x: &[Vec3], t: f64) -> f64 {
        if self.loads.is_empty() {
            return 0.0;
        }
        let mut f = vec![Vec3::zeros(); x.len()];
        for l in &self.loads {
            l.add_forces(&self.model, t, x, 1.0, &mut f);
        }
        f.iter().map(|v| v.norm()).sum()
    }

    /// The free dofs in the 3D layout `newton` takes (z always held).
    fn free_dofs(&self) -> Vec<bool> {
        self.held
            .iter()
            .flat_map(|h| [!h[0], !h[1], false])
            .collect()
    }

    /// The static equilibrium from `x` at time `time` (held nodes stay
    /// where `x` has them, moved nodes go where their motions have them at
    /// `time`). The load (and the motions) are applied whole first; when
    /// Newton's method fails (large deformation), in increments that halve
    /// on failure and grow on success. Returns the Newton iterations.
    pub fn solve_static(&self, time: f64, x: &mut [Vec3]) -> Result<u32, PlaneSolveError> {
        let mut linear = self.linear_solver();
        let (mut done, mut step) = (0.0f64, 1.0f64);
        let mut iterations = 0;
        while done < 1.0 {
            let target = (done + step).min(1.0);
            let mut trial = x.to_vec();
            self.place_moved(time, target, &mut trial, None);
            // Moving obstacles go along their paths with the increments.
            match self.newton_under(target, target * time, &mut trial, &mut linear) {
                Ok(n) => {
                    iterations += n;
                    x.copy_from_slice(&trial);
                    done = target;
                    step = (2.0 * step).min(1.0 - done);
                }
                Err(e) if step > MIN_LOAD_STEP => {
                    log::debug!("2D static solve: load step {step} failed ({e}); halving");
                    step *= 0.5;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(iterations)
    }

    /// Newton's method for the equilibrium under `load` times the loads.
    fn newton_under(
        &self,
        load: f64,
        time: f64,
        x: &mut [Vec3],
        linear: &mut LinearSolver,
    ) -> Result<u32, PlaneSolveError> {
        let free = self.free_dofs();
        let model = &self.model;
        let size = {
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for p in &model.rest {
                lo = [lo[0].min(p.x), lo[1].min(p.y)];
                hi = [hi[0].max(p.x), hi[1].max(p.y)];
            }
            (hi[0] - lo[0]).max(hi[1] - lo[1])
        };
        let h = model.size[0].min(model.size[1]);
        let opts = NewtonOptions {
            max_iterations: 60,
            rtol: 1e-10,
            slope_line_search: false,
            keep_hierarchy: false,
        };
        newton(
            &mut StaticSystem {
                p: self,
                load,
                time,
                loads_at_start: self.loads_size(x, time),
            },
            x,
            &free,
            size,
            h,
            opts,
            linear,
        )
        .map_err(|e| newton_error(e, None))
    }

    /// `steps` implicit (backward Euler) steps of `dt` (s) from `(x, v)` at
    /// time `t0` (a step where Newton's method fails is taken again in
    /// halves, [`MAX_IMPLICIT_HALVINGS`] times at most):
    /// each step solves `M (v' - v) / dt = f(x') - c M v'` with
    /// `x' = x + dt v'` by Newton's method, so any step is stable (and
    /// damps the highest modes). Friction acts on the velocity each step
    /// ends with, as in the explicit step. Returns the Newton iterations.
    pub fn step_implicit(
        &self,
        t0: f64,
        x: &mut [Vec3],
        v: &mut [Vec3],
        dt: f64,
        steps: usize,
    ) -> Result<u32, PlaneSolveError> {
        struct Step<'a> {
            p: &'a PlaneProblem,
            x0: Vec<Vec3>,
            v0: Vec<Vec3>,
            dt: f64,
            /// The step's end (s).
            t_end: f64,
            /// The velocity the step ends with, `(x - x0) / dt` (scratch).
            v_end: Vec<Vec3>,
        }
        impl NonlinearSystem for Step<'_> {
            fn residual(&mut self, x: &[Vec3], r: &mut [Vec3]) -> f64 {
                for ((v, x), x0) in self.v_end.iter_mut().zip(x).zip(&self.x0) {
                    *v = (x - x0) / self.dt;
                }
                self.p.total_forces(self.t_end, x, Some(&self.v_end), r);
                let (dt, c) = (self.dt, self.p.damping);
                let mut scale = 0.0;
                for i in 0..x.len() {
                    let m = self.p.model.masses[i];
                    let vel = (x[i] - self.x0[i]) / dt;
                    let inertia = (vel - self.v0[i]) * (m / dt) + vel * (c * m);
                    r[i] -= Vec3::new(inertia.x, inertia.y, 0.0);
                    scale += m * (9.81 + self.v0[i].norm() / dt);
                }
                scale
            }
            fn jacobian(&mut self, x: &[Vec3]) -> BlockCsr {
                let mut j = self
                    .p
                    .tangent_at(x, self.t_end, 1.0, Some((&self.x0, self.dt)));
                let (dt, c) = (self.dt, self.p.damping);
                for i in 0..x.len() {
                    let k = j.find(i, i).expect("the diagonal is in the pattern");
                    let m = self.p.model.masses[i];
                    for d in 0..2 {
                        j.blocks[k][(d, d)] -= m / (dt * dt) + c * m / dt;
                    }
                }
                j
            }
        }
        let free = self.free_dofs();
        let h = self.model.size[0].min(self.model.size[1]);
        let mut linear = self.linear_solver();
        let opts = NewtonOptions {
            max_iterations: 30,
            rtol: 1e-9,
            slope_line_search: false,
            keep_hierarchy: false,
        };
        let mut iterations = 0;
        for step in 0..steps {
            // The step, taken again in halves where Newton's method fails
            // (a node's contact switching on and off within it, which the
            // penalty's kink makes Newton cycle over), down to
            // 2^-MAX_IMPLICIT_HALVINGS of it; in time order (a stack).
            let mut pending = vec![(t0 + step as f64 * dt, dt, 0u32)];
            while let Some((start, sub_dt, halvings)) = pending.pop() {
                let t_end = start + sub_dt;
                let mut sys = Step {
                    p: self,
                    x0: x.to_vec(),
                    v0: v.to_vec(),
                    dt: sub_dt,
                    t_end,
                    v_end: vec![Vec3::zeros(); x.len()],
                };
                // Predictor: the current velocity; moved nodes where their
                // motions have them at the step's end.
                for i in 0..x.len() {
                    for d in 0..2 {
                        if !self.held[i][d] {
                            x[i][d] += sub_dt * v[i][d];
                        }
                    }
                }
                self.place_moved(t_end, 1.0, x, None);
                match newton(&mut sys, x, &free, h, h, opts, &mut linear) {
                    Ok(n) => iterations += n,
                    Err(e) if halvings >= MAX_IMPLICIT_HALVINGS => {
                        return Err(newton_error(e, Some(step)));
                    }
                    Err(e) => {
                        log::debug!(
                            "2D implicit step {step}: {}; taken again in halves",
                            newton_error(e, Some(step))
                        );
                        x.copy_from_slice(&sys.x0);
                        v.copy_from_slice(&sys.v0);
                        let half = 0.5 * sub_dt;
                        pending.push((start + half, half, halvings + 1));
                        pending.push((start, half, halvings + 1));
                        continue;
                    }
                }
                for i in 0..x.len() {
                    v[i] = (x[i] - sys.x0[i]) / sub_dt;
                    if let Some(c) = &self.contact {
                        let before = v[i];
                        c.apply_friction(t_end, x[i], &mut v[i], self.model.masses[i], sub_dt);
                        // The step's motion follows the friction: a node
                        // that sticks stays where the step began (else
                        // it creeps by a step's slip each step).
                        if v[i] != before {
                            x[i] = sys.x0[i] + v[i] * sub_dt;
                        }
                    }
                    self.hold_velocity(i, &mut v[i]);
                }
                self.place_moved(t_end, 1.0, x, Some(v));
            }
        }
        Ok(iterations)
    }

    /// Zeroes the held components of node `i`'s velocity.
    fn hold_velocity(&self, i: usize, v: &mut Vec3) {
        for (vd, &held) in v.iter_mut().zip(&self.held[i]) {
            if held {
                *vd = 0.0;
            }
        }
    }

    /// `steps` explicit steps of `dt` (s) from `(x, v)` at time `t0`:
    /// semi-implicit Euler with the damping applied implicitly; held nodes
    /// do not move, moved nodes follow their motions.
    pub fn step_explicit(
        &self,
        t0: f64,
        x: &mut [Vec3],
        v: &mut [Vec3],
        dt: f64,
        steps: usize,
    ) -> Result<(), PlaneSolveError> {
        let mut f = vec![Vec3::zeros(); x.len()];
        let keep = 1.0 / (1.0 + dt * self.damping);
        for step in 0..steps {
            let t = t0 + step as f64 * dt;
            self.forces_under(x, Some(v), 1.0, t, self.precision, &mut f);
            for i in 0..x.len() {
                let inv_m = 1.0 / self.model.masses[i];
                for d in 0..2 {
                    v[i][d] = if self.held[i][d] {
                        0.0
                    } else {
                        (v[i][d] + dt * f[i][d] * inv_m) * keep
                    };
                }
                if let Some(c) = &self.contact {
                    c.apply_friction(t, x[i], &mut v[i], self.model.masses[i], dt);
                    self.hold_velocity(i, &mut v[i]);
                }
                for d in 0..2 {
                    if !self.held[i][d] {
                        x[i][d] += dt * v[i][d];
                    }
                }
            }
            self.place_moved(t0 + (step + 1) as f64 * dt, 1.0, x, Some(v));
            if !x.iter().all(|p| p.x.is_finite() && p.y.is_finite()) {
                return Err(PlaneSolveError::Diverged(step));
            }
        }
        Ok(())
    }
}
