//! The model: per-cell springs, lumped masses, correction forces (docs/model.md).
//!
//! Forces are computed per cell (the cell's 16 springs, then its correction
//! forces from those springs' forces, then the optional volumetric term and
//! hourglass control) and added into the node sums directly. Cells are
//! visited z-layer by z-layer in two phases, the even layers and then the odd
//! ones: a layer touches only its two node planes, so the layers of a phase
//! run in parallel without sharing a node, and each node receives its cells'
//! contributions in one fixed order. The forces are therefore bitwise
//! reproducible for any number of threads.
//!
//! The kernel is written once over a scalar type (`model/kernel.rs`). The
//! cell Jacobian is exact and in closed form (including the derivative of the
//! current cell axes in the corrections); the tests check it against that
//! same kernel evaluated with forward-mode dual numbers, which cost about
//! 2.5 times as much.

use std::fmt::Debug;
use std::sync::Arc;

use hexmesh::Lattice;
use thiserror::Error;

use rayon::prelude::*;

use crate::{BlockCsr, Mat3, Material, MaterialError, Vec3};

pub mod frequency;
pub(crate) mod kernel;

use kernel::{CellParams, Correction};

/// Why a model could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ModelError {
    /// A material parameter is invalid for the chosen parameterization.
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// The per-cell material table does not match the lattice.
    #[error("cell {cell} refers to material {index}, but only {count} materials were given")]
    MaterialIndex {
        /// Cell index.
        cell: usize,
        /// Material index given for it.
        index: u32,
        /// Number of materials.
        count: usize,
    },
    /// `cell_material` has the wrong length.
    #[error("{given} per-cell material indices given for {cells} cells")]
    MaterialCount {
        /// Entries given.
        given: usize,
        /// Cells in the lattice.
        cells: usize,
    },
    /// [`Model::union`] of no bodies.
    #[error("a model needs at least one body")]
    NoBodies,
    /// [`Model::union`] of more nodes than indices can hold.
    #[error("{0} nodes in all bodies: more than 2^32 - 1")]
    TooManyNodes(usize),
    /// The parameterization gave unusable cell constants.
    #[error(
        "parameterization '{name}' gave invalid cell constants (k_edge {k_edge}, k_diag {k_diag}, correction {correction:?}, lambda {lambda}, hourglass {hourglass}): the correction system is singular or a value is not finite; choose a Poisson's ratio inside the supported range"
    )]
    BadCoefficients {
        /// Parameterization name.
        name: String,
        /// Edge stiffness given.
        k_edge: f64,
        /// Diagonal stiffness given.
        k_diag: f64,
        /// Correction coefficient given.
        correction: Option<f64>,
        /// Volumetric lambda given.
        lambda: f64,
        /// Hourglass stiffness given.
        hourglass: f64,
    },
}

/// The per-cell constants a parameterization derives from a material and the
/// cell edge `h`. The force kernel is shared by all parameterizations; they
/// differ only in these numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellCoefficients {
    /// Stiffness of each of the cell's 12 edge springs (N/m), rest length h.
    pub k_edge: f64,
    /// Stiffness of each of the 4 body-diagonal springs (N/m), rest length sqrt(3) h.
    pub k_diag: f64,
    /// Correction coefficient `c = (4 nu - 1) / 2` of docs/model.md step 4, or
    /// `None` for no correction forces.
    pub correction: Option<f64>,
    /// Lame lambda (Pa) of the one-point volumetric energy
    /// `lambda h^3 phi(J)` (0 for none).
    pub volumetric_lambda: f64,
    /// `phi` of the volumetric energy: `(J - 1)^2 / 2` when false, the
    /// barrier `(ln J)^2 / 2` when true (the same at small strain; the
    /// barrier resists collapse to `J = 0`, docs/model.md).
    pub volumetric_barrier: bool,
    /// Stiffness (N/m) of the hourglass control on the lattice's three
    /// zero-energy mechanisms per cell (0 for none; see [`HourglassControl`]).
    pub hourglass: f64,
}

/// Maps a material to per-cell spring constants: the plugin point for spring
/// parameterizations. Implement it to try your own.
pub trait Parameterization: Send + Sync + Debug {
    /// Short name used by scene files, reports and the CLI (e.g. `"paper"`).
    fn name(&self) -> String;
    /// Checks the material against the range this parameterization supports.
    fn validate(&self, material: &Material) -> Result<(), MaterialError>;
    /// The per-cell constants for cells of edge `h` (m).
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients;
}

/// Floating-point operations per cell of the explicit force pass, by kind
/// ([`Model::force_operations`]): what one SIMD lane performs for one cell.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ForceOperations {
    /// Additions and subtractions.
    pub add: u64,
    /// Multiplications.
    pub mul: u64,
    /// Divisions.
    pub div: u64,
    /// Square roots.
    pub sqrt: u64,
    /// Other lane operations: negations, maxima, comparisons, the
    /// logarithm's exponent split, conversions between precisions.
    pub other: u64,
}

impl ForceOperations {
    /// No operations.
    pub const ZERO: Self = Self {
        add: 0,
        mul: 0,
        div: 0,
        sqrt: 0,
        other: 0,
    };

    /// The operations that go through the adders and multipliers: all but
    /// the divisions and square roots, which have a unit of their own.
    pub fn pipelined(&self) -> u64 {
        self.add + self.mul + self.other
    }
}

/// The paper's model (M2 lattice with correction forces), exact E and nu in
/// uniaxial tension for -0.25 < nu < 0.5.
#[derive(Debug, Clone, Copy, Default)]
pub struct PaperModel;

/// Springs only: the paper's stiffnesses without correction forces (the
/// "classic MSS"); it measures nu' = 1 / (4 nu + 3) in tension.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpringsOnly;

fn paper_springs(m: &Material, h: f64) -> (f64, f64) {
    let nu = m.poisson;
    let k_edge = m.young * h * (4.0 * nu + 1.0) / (8.0 * (1.0 + nu));
    let k_diag = 3.0 * m.young * h / (8.0 * (1.0 + nu));
    (k_edge, k_diag)
}

impl Parameterization for PaperModel {
    fn name(&self) -> String {
        "paper".into()
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Material::new(material.young, material.poisson, material.density).map(|_| ())
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let (k_edge, k_diag) = paper_springs(material, h);
        CellCoefficients {
            k_edge,
            k_diag,
            correction: Some((4.0 * material.poisson - 1.0) / 2.0),
            volumetric_lambda: 0.0,
            volumetric_barrier: false,
            hourglass: 0.0,
        }
    }
}

impl Parameterization for SpringsOnly {
    fn name(&self) -> String {
        "springs".into()
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Material::new(material.young, material.poisson, material.density).map(|_| ())
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let (k_edge, k_diag) = paper_springs(material, h);
        CellCoefficients {
            k_edge,
            k_diag,
            correction: None,
            volumetric_lambda: 0.0,
            volumetric_barrier: false,
            hourglass: 0.0,
        }
    }
}

/// The paper's model evaluated at the same shear modulus and nu' = 0 (springs
/// and correction forces), plus a one-point volumetric energy
/// `lambda h^3 (J - 1)^2 / 2` per cell (docs/model.md, last section). Exact E and nu in
/// uniaxial tension, and much closer to converged FEM than the paper's model.
#[derive(Debug, Clone, Copy, Default)]
pub struct Volumetric;

impl Volumetric {
    /// Lower bound (exclusive) of Poisson's ratio for this parameterization.
    pub const POISSON_MIN: f64 = -1.0;
}

impl Parameterization for Volumetric {
    fn name(&self) -> String {
        "volumetric".into()
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Material::with_poisson_range(
            material.young,
            material.poisson,
            material.density,
            Self::POISSON_MIN,
            Material::POISSON_MAX,
        )
        .map(|_| ())
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let nu = material.poisson;
        CellCoefficients {
            k_edge: material.young * h / (8.0 * (1.0 + nu)),
            k_diag: 3.0 * material.young * h / (8.0 * (1.0 + nu)),
            correction: Some(-0.5),
            volumetric_lambda: material.lambda(),
            volumetric_barrier: false,
            hourglass: 0.0,
        }
    }
}

/// [`Volumetric`] with the volumetric energy `lambda h^3 (ln J)^2 / 2` (the
/// volumetric part of the compressible neo-Hookean law) instead of
/// `lambda h^3 (J - 1)^2 / 2`: identical at small strain (same E and nu, same
/// stiffness at rest), but the energy grows without bound as a cell's volume
/// goes to zero, where the quadratic law costs only `lambda h^3 / 2`. Below
/// `J = 0.1` it continues with constant curvature so that forces stay finite
/// (docs/model.md, section 4; docs/robustness.md).
#[derive(Debug, Clone, Copy, Default)]
pub struct VolumetricBarrier;

impl Parameterization for VolumetricBarrier {
    fn name(&self) -> String {
        "volumetric-barrier".into()
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        Volumetric.validate(material)
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        CellCoefficients {
            volumetric_barrier: true,
            ..Volumetric.coefficients(material, h)
        }
    }
}

/// Hourglass control added to another parameterization: a stiffness on the
/// three zero-energy mechanisms of each cell of the M2 lattice.
///
/// Displacing the corners of a cell along axis `i` by the pattern `s_j s_k`
/// (the product of their signs along the two other axes) stretches none of the
/// cell's 16 springs, so neither the springs nor the correction forces (built
/// from the springs' forces) resist it. A block has three such global modes
/// (docs/model.md); a part one cell thick, or a few held nodes, leaves them free.
/// This adds the energy `W = k/2 sum_i q_i^2` per cell, with
/// `q_i = a_i . (1/8) sum_n s_j s_k(n) x_n` the mode's amplitude along the
/// current cell axis `a_i`. `q_i` is zero for every homogeneous deformation and
/// invariant under rotations, so the tension results (E, nu) and the rigid
/// modes are untouched; only the mechanisms gain stiffness.
///
/// `k = alpha * (8/3) mu h`: at `alpha = 1` a mode gets the strain energy that
/// linear elasticity gives its bilinear displacement field in the cell
/// (`u_x = A (2y/h)(2z/h)`: `W = 4/3 mu h A^2`).
#[derive(Debug)]
pub struct HourglassControl {
    inner: Box<dyn Parameterization>,
    alpha: f64,
}

/// Why a [`HourglassControl`] could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
#[error(
    "hourglass stiffness factor {0} is invalid: use a finite value >= 0 (0 disables it, 1 is the elastic energy of the mode)"
)]
pub struct HourglassError(pub f64);

impl HourglassControl {
    /// Default factor `alpha` of the built-in `"*+hg"` parameterizations.
    ///
    /// Chosen from a sweep of the nu = 0.3 small-load cantilever (alpha 0.01
    /// to 1; mss-validate/tests/fast/experiments.rs keeps the criterion): any alpha > 0 removes
    /// the mechanisms of the one-cell-thick 4x1x1 beam (volumetric: M 15.9 % ->
    /// 5.3 %, MAX 46.6 % -> 11.2 %; paper: M 72 % -> 25 %), while 16x4x4 moves
    /// by a few tenths of a percent of its error (M up, MAX down) at 0.05 and
    /// gets worse from about 0.3 on: a smooth field has some hourglass content,
    /// which a large stiffness over-stiffens.
    pub const DEFAULT_ALPHA: f64 = 0.05;

    /// Adds hourglass control of factor `alpha` (>= 0) to `inner`.
    pub fn new(inner: Box<dyn Parameterization>, alpha: f64) -> Result<Self, HourglassError> {
        if !(alpha.is_finite() && alpha >= 0.0) {
            return Err(HourglassError(alpha));
        }
        Ok(Self { inner, alpha })
    }

    /// The factor `alpha` of the hourglass stiffness `alpha (8/3) mu h`.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }
}

impl Parameterization for HourglassControl {
    fn name(&self) -> String {
        format!("{}+hg", self.inner.name())
    }
    fn validate(&self, material: &Material) -> Result<(), MaterialError> {
        self.inner.validate(material)
    }
    fn coefficients(&self, material: &Material, h: f64) -> CellCoefficients {
        let mut co = self.inner.coefficients(material, h);
        co.hourglass += self.alpha * 8.0 / 3.0 * material.shear_modulus() * h;
        co
    }
}

/// Builds a fresh parameterization: one entry of [`Parameterizations`].
pub type ParameterizationFactory = Arc<dyn Fn() -> Box<dyn Parameterization> + Send + Sync>;

/// The parameterizations a program knows, by name: a value that a program
/// builds, extends with its own and passes where names are resolved (scenes,
/// experiments). No global state.
///
/// [`Parameterizations::default`] holds the built-ins `"paper"`, `"springs"`,
/// `"volumetric"` and `"volumetric-barrier"`. Every registered name `NAME` also resolves as
/// `"NAME+hg"`: the same with [`HourglassControl`] at its default factor.
///
/// ```
/// use std::sync::Arc;
/// use mss_core::model::{CellCoefficients, Parameterization, Parameterizations};
/// use mss_core::{Material, MaterialError};
///
/// /// Springs of the paper's stiffness at a fixed nu = 0.25 (no corrections needed).
/// #[derive(Debug)]
/// struct QuarterSprings;
/// impl Parameterization for QuarterSprings {
///     fn name(&self) -> String {
///         "quarter".into()
///     }
///     fn validate(&self, m: &Material) -> Result<(), MaterialError> {
///         Material::new(m.young, m.poisson, m.density).map(|_| ())
///     }
///     fn coefficients(&self, m: &Material, h: f64) -> CellCoefficients {
///         CellCoefficients {
///             k_edge: m.young * h * 2.0 / (8.0 * 1.25),
///             k_diag: 3.0 * m.young * h / (8.0 * 1.25),
///             correction: None,
///             volumetric_lambda: 0.0,
///             volumetric_barrier: false,
///             hourglass: 0.0,
///         }
///     }
/// }
///
/// let mut known = Parameterizations::default();
/// known.register("quarter", Arc::new(|| Box::new(QuarterSprings)));
/// assert_eq!(known.get("quarter").unwrap().name(), "quarter");
/// assert_eq!(known.get("quarter+hg").unwrap().name(), "quarter+hg");
/// let err = known.get("fancy").unwrap_err().to_string();
/// assert!(err.contains("paper, springs, volumetric, volumetric-barrier, quarter"), "{err}");
/// ```
#[derive(Clone)]
pub struct Parameterizations {
    entries: mss_registry::Named<ParameterizationFactory>,
}

impl Default for Parameterizations {
    fn default() -> Self {
        let mut p = Self {
            entries: mss_registry::Named::new(),
        };
        p.register("paper", Arc::new(|| Box::new(PaperModel)));
        p.register("springs", Arc::new(|| Box::new(SpringsOnly)));
        p.register("volumetric", Arc::new(|| Box::new(Volumetric)));
        p.register(
            "volumetric-barrier",
            Arc::new(|| Box::new(VolumetricBarrier)),
        );
        p
    }
}

impl Debug for Parameterizations {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.entries.fmt(f)
    }
}

/// A parameterization name that no entry of [`Parameterizations`] serves.
#[derive(Debug, Error, Clone, PartialEq)]
#[error(
    "unknown parameterization \"{name}\"; use one of {known} (each also with \"+hg\": hourglass control)"
)]
pub struct UnknownParameterization {
    /// The name asked for.
    pub name: String,
    /// The registered names, comma-separated.
    pub known: String,
}

/// Suffix that adds [`HourglassControl`] to a registered parameterization.
pub const HOURGLASS_SUFFIX: &str = "+hg";

impl Parameterizations {
    /// Registers (or replaces) the parameterization called `name`.
    pub fn register(&mut self, name: &str, factory: ParameterizationFactory) {
        self.entries.register(name, factory);
    }

    /// The registered base names, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    /// Builds the parameterization `name`, or `"NAME+hg"` for a registered
    /// `NAME` with hourglass control at [`HourglassControl::DEFAULT_ALPHA`].
    pub fn get(&self, name: &str) -> Result<Box<dyn Parameterization>, ParameterizationError> {
        self.build(name, None)
    }

    /// Builds a parameterization by name with an optional hourglass factor:
    /// `Some(alpha)` adds [`HourglassControl`] of factor `alpha` to any name
    /// (and sets the factor of a `"+hg"` name).
    pub fn build(
        &self,
        name: &str,
        hourglass: Option<f64>,
    ) -> Result<Box<dyn Parameterization>, ParameterizationError> {
        let (base, suffixed) = match name.strip_suffix(HOURGLASS_SUFFIX) {
            Some(base) => (base, true),
            None => (name, false),
        };
        let factory = self
            .entries
            .lookup(base)
            .map_err(|unknown| UnknownParameterization {
                name: name.to_owned(),
                known: unknown.known,
            })?;
        let inner = factory();
        let alpha = match (hourglass, suffixed) {
            (Some(alpha), _) => alpha,
            (None, true) => HourglassControl::DEFAULT_ALPHA,
            (None, false) => return Ok(inner),
        };
        Ok(Box::new(HourglassControl::new(inner, alpha)?))
    }
}

/// Why [`Parameterizations::build`] refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ParameterizationError {
    /// No entry of that name.
    #[error(transparent)]
    Unknown(#[from] UnknownParameterization),
    /// The hourglass factor is invalid.
    #[error(transparent)]
    Hourglass(#[from] HourglassError),
}

/// Per-cell state measures for output (VTK) and inspection.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CellDiagnostics {
    /// Volumetric strain `J - 1`, with `J = det F` at the cell centre.
    pub volumetric_strain: f64,
    /// Equivalent (von Mises-like) shear strain `sqrt(2/3 dev(E) : dev(E))` of
    /// the Green-Lagrange strain `E` at the cell centre.
    pub shear_strain: f64,
    /// Magnitude of the cell's correction forces (N): the root of the sum of the
    /// squared norms of its 8 nodal correction forces (0 without corrections).
    pub correction_force: f64,
}

/// One of a cell's [`CellDiagnostics`], for [`Model::cell_measure_of`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellMeasure {
    /// [`CellDiagnostics::volumetric_strain`].
    VolumetricStrain,
    /// [`CellDiagnostics::shear_strain`].
    ShearStrain,
    /// [`CellDiagnostics::correction_force`].
    CorrectionForce,
}

/// The floating-point precision of the internal force pass.
///
/// `F32` runs the cell kernel in single precision, 8 cells per AVX2 pass
/// instead of 4 (16 per AVX-512 pass instead of 8), for interactive use; positions, velocities and the force
/// sums stay in `f64` (a sub-step moves a node by far less than the `f32`
/// spacing of its coordinates, which `f32` positions would lose), and each
/// cell's corners are taken relative to its corner 0 before rounding, so a
/// body far from the origin loses nothing to its placement. Each force
/// carries a relative error of about `1e-7 / strain` (the springs' and the
/// volume's `1 - L0 / l` and `J - 1` cancel digits); docs/solvers.md gives
/// what that costs on the cantilever and the bunny. Newton solvers need
/// `f64` and refuse `F32`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Double precision (the default).
    #[default]
    F64,
    /// Single precision for the cell kernel.
    F32,
}

impl Precision {
    /// `"f64"` or `"f32"`, the scene key's values.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }

    /// The precision named `name` (`"f64"` or `"f32"`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "f64" => Some(Precision::F64),
            "f32" => Some(Precision::F32),
            _ => None,
        }
    }

    /// The instruction set the force pass runs on this CPU in this
    /// precision (`"avx512"`, `"avx2"`, or `"portable"` where the compiler
    /// vectorizes plain lane loops) and how many cells it evaluates
    /// together, for benchmark reports.
    pub fn kernel_vectors(self) -> (&'static str, usize) {
        let lanes = match self {
            Precision::F64 => kernel::LANES,
            Precision::F32 => kernel::LANES_F32,
        };
        #[cfg(target_arch = "x86_64")]
        {
            if kernel::has_avx512() {
                return ("avx512", 2 * lanes);
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                return ("avx2", lanes);
            }
        }
        ("portable", lanes)
    }
}

/// Scratch space of the force pass, kept between passes so that a step
/// allocates nothing ([`Model::workspace`]).
#[derive(Debug, Clone, Default)]
pub struct ForceWorkspace {
    /// The stretch `1 - L0 / l` of each lattice edge, by the node it starts
    /// from and its axis: computed once per force pass and shared by the up
    /// to four cells around the edge.
    edge_stretch: Vec<[f64; 3]>,
}

impl ForceWorkspace {
    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.edge_stretch.capacity() * 24
    }
}

/// A lattice edge that is not at corner 0 of any cell (on the lattice's `+`
/// faces): the force pass computes its stretch apart from the pass over the
/// cells' corner-0 edges.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LeftoverEdge {
    node: u32,
    end: u32,
    axis: u32,
    rest: f64,
}

/// The [`LeftoverEdge`]s of `cells` on `nodes` nodes, in (cell, edge) order,
/// each once; `rest(c)` is the rest edge length of cell `c`.
fn leftover_edges(
    cells: &[[u32; 8]],
    nodes: usize,
    rest: impl Fn(usize) -> f64,
) -> Vec<LeftoverEdge> {
    // Bit `axis` of `covered[n]`: node n's edge along +axis is known.
    let mut covered = vec![0u8; nodes];
    for cell in cells {
        covered[cell[0] as usize] = 0b111;
    }
    let mut out = Vec::new();
    for (c, cell) in cells.iter().enumerate() {
        for &(a, b, axis) in &hexmesh::CELL_EDGES {
            let node = cell[a] as usize;
            if covered[node] & (1 << axis) == 0 {
                covered[node] |= 1 << axis;
                out.push(LeftoverEdge {
                    node: cell[a],
                    end: cell[b],
                    axis: axis as u32,
                    rest: rest(c),
                });
            }
        }
    }
    out
}

/// The cells of a lattice by layer along z: the lattice sorts its cells
/// z-major, so layer `l` is the range `offsets[l]..offsets[l + 1]`. Cells of
/// layers two or more apart share no node.
#[derive(Debug, Clone, Default)]
struct Layers {
    offsets: Vec<u32>,
}

impl Layers {
    /// The layers of cells whose z grid coordinates are `layer_of`, in
    /// cell order (ascending).
    fn of(layer_of: impl ExactSizeIterator<Item = u32>) -> Self {
        let mut offsets = vec![0u32];
        let count = layer_of.len();
        let mut previous: Option<u32> = None;
        for (c, z) in layer_of.enumerate() {
            if let Some(p) = previous {
                debug_assert!(p <= z, "cells sorted by layer");
                // A missing layer in between would be an empty range; the
                // parity of the layer index is what matters, so keep gaps.
                for _ in p..z {
                    offsets.push(c as u32);
                }
            }
            previous = Some(z);
        }
        offsets.push(count as u32);
        Self { offsets }
    }

    fn count(&self) -> usize {
        self.offsets.len() - 1
    }

    fn range(&self, l: usize) -> std::ops::Range<usize> {
        self.offsets[l] as usize..self.offsets[l + 1] as usize
    }
}

/// Writes the corner vectors of the cells from `first` on, one cell at a
/// time by `per_cell`, into a batch's `values` (8 `[x, y, z, 0]` per cell):
/// the cell-by-cell path of [`Model::add_batches_by_layers`]' batches.
fn fill_cells(values: &mut [[f64; 4]], first: usize, per_cell: impl Fn(usize) -> [[f64; 3]; 8]) {
    for (k, f) in values.chunks_exact_mut(8).enumerate() {
        for (f, o) in f.iter_mut().zip(per_cell(first + k)) {
            *f = [o[0], o[1], o[2], 0.0];
        }
    }
}

/// `K v` of one cell (its 8 corners' `[x, y, z]`) with the 24 x 24 matrix
/// `k`, each row summed in column order from its first product.
fn rest_product(k: &[[f64; 24]; 24], cell: &[u32; 8], v: &[[f64; 3]]) -> [[f64; 3]; 8] {
    let mut local = [0.0f64; 24];
    for (a, &n) in cell.iter().enumerate() {
        local[3 * a..3 * a + 3].copy_from_slice(&v[n as usize]);
    }
    let mut out = [[0.0f64; 3]; 8];
    for (r, row) in k.iter().enumerate() {
        let mut acc = row[0] * local[0];
        for (kj, lj) in row.iter().zip(&local).skip(1) {
            acc += kj * lj;
        }
        out[r / 3][r % 3] = acc;
    }
    out
}

/// [`rest_product`] of each cell of `cells`, all with the matrix `k`, into
/// `out` (8 `[x, y, z, 0]` per cell): eight cells per pass on AVX-512, four
/// on AVX2 and elsewhere, one cell per lane, every lane summing its rows in
/// [`rest_product`]'s order (no fused multiply-add), so the same bits. The
/// explicit step's frequency estimate takes tens of these products; cell by
/// cell they were a 24-term dependent sum per row, and a twentieth of an
/// interactive session's first minute of frames.
fn rest_products(k: &[[f64; 24]; 24], cells: &[[u32; 8]], v: &[[f64; 3]], out: &mut [[f64; 4]]) {
    #[cfg(target_arch = "x86_64")]
    {
        if kernel::has_avx512() {
            // SAFETY: the CPU has AVX-512F (checked just above).
            unsafe { rest_products_avx512(k, cells, v, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            unsafe { rest_products_avx2(k, cells, v, out) };
            return;
        }
    }
    rest_products_lanes::<4>(k, cells, v, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn rest_products_avx512(
    k: &[[f64; 24]; 24],
    cells: &[[u32; 8]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    rest_products_lanes::<8>(k, cells, v, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn rest_products_avx2(
    k: &[[f64; 24]; 24],
    cells: &[[u32; 8]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    rest_products_lanes::<4>(k, cells, v, out);
}

/// [`rest_products`] with `L` cells per pass. Plain loops over the lanes,
/// which the compiler turns into vector operations; no closures, which would
/// not inherit the caller's target features.
#[inline(always)]
fn rest_products_lanes<const L: usize>(
    k: &[[f64; 24]; 24],
    cells: &[[u32; 8]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    assert_eq!(out.len(), 8 * cells.len(), "eight corners per cell");
    let whole = cells.len() / L * L;
    for (group, o) in cells[..whole]
        .chunks_exact(L)
        .zip(out.chunks_exact_mut(8 * L))
    {
        let mut local = [[0.0f64; L]; 24];
        for (l, cell) in group.iter().enumerate() {
            for (a, &n) in cell.iter().enumerate() {
                for (d, c) in v[n as usize].iter().enumerate() {
                    local[3 * a + d][l] = *c;
                }
            }
        }
        for (r, row) in k.iter().enumerate() {
            let mut acc = [0.0f64; L];
            for (acc, lj) in acc.iter_mut().zip(&local[0]) {
                *acc = row[0] * lj;
            }
            for (kj, lj) in row.iter().zip(&local).skip(1) {
                for (acc, lj) in acc.iter_mut().zip(lj) {
                    *acc += kj * lj;
                }
            }
            for (l, acc) in acc.iter().enumerate() {
                o[8 * l + r / 3][r % 3] = *acc;
            }
        }
        for corner in o.iter_mut() {
            corner[3] = 0.0;
        }
    }
    fill_cells(&mut out[8 * whole..], whole, |c| {
        rest_product(k, &cells[c], v)
    });
}

/// `*o += [f[0], f[1], f[2]]`, the same three additions on every path:
/// x and y as one two-lane SSE2 addition where the target has it (all of
/// x86_64), which halves the loads and stores of the force pass's node sums.
///
/// # Safety
/// `o` points to a node's force that no other thread accesses meanwhile.
#[inline(always)]
unsafe fn add_corner(o: *mut Vec3, f: &[f64; 4]) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE2 is part of x86_64; `o` points to three f64 (a `Vec3` is
    // `[f64; 3]`), of which the two-lane load and store touch the first two.
    unsafe {
        use std::arch::x86_64::{_mm_add_pd, _mm_loadu_pd, _mm_storeu_pd};
        let p = o.cast::<f64>();
        _mm_storeu_pd(p, _mm_add_pd(_mm_loadu_pd(p), _mm_loadu_pd(f.as_ptr())));
        *p.add(2) += f[2];
    }
    #[cfg(not(target_arch = "x86_64"))]
    // SAFETY: the caller's contract.
    unsafe {
        let o = &mut *o;
        o.x += f[0];
        o.y += f[1];
        o.z += f[2];
    }
}

/// Adds the corner vectors `values` (8 per cell, `[x, y, z, 0]`) of `cells`
/// into the node sums `nodes`, cell by cell, corner by corner: the order
/// every path of the force pass keeps.
///
/// # Safety
/// `nodes` points to one `Vec3` per node of the lattice, and no other
/// thread accesses those of `cells` meanwhile.
#[inline(always)]
unsafe fn add_cells(cells: &[[u32; 8]], values: &[[f64; 4]], nodes: *mut Vec3) {
    for (cell, f) in cells.iter().zip(values.chunks_exact(8)) {
        for (&v, fv) in cell.iter().zip(f) {
            // SAFETY: the caller's contract; `v` is a node of the lattice.
            unsafe { add_corner(nodes.add(v as usize), fv) };
        }
    }
}

/// Node force sums written from several threads at once, each to nodes no
/// other thread touches in the same phase (see [`Model::internal_forces_with`]).
#[derive(Clone, Copy)]
struct SharedForces(*mut Vec3);
// SAFETY: the force pass hands disjoint node sets to the threads of a phase.
unsafe impl Send for SharedForces {}
unsafe impl Sync for SharedForces {}

/// Tangent blocks written from several threads at once, each to the rows of
/// nodes no other thread touches in the same phase (see [`Model::tangent`]).
#[derive(Clone, Copy)]
struct SharedBlocks(*mut Mat3);
// SAFETY: the tangent's assembly hands disjoint node sets (rows) to the
// threads of a phase.
unsafe impl Send for SharedBlocks {}
unsafe impl Sync for SharedBlocks {}

/// Edge stretches by node written from several threads at once: each cell
/// writes the node at its corner 0, which no other cell has there.
#[derive(Clone, Copy)]
struct SharedEdges(*mut [f64; 3]);
// SAFETY: every node is corner 0 of at most one cell.
unsafe impl Send for SharedEdges {}
unsafe impl Sync for SharedEdges {}

/// The batched force kernel of a precision ([`kernel::forces_batch`]).
type BatchKernel = fn(&CellParams, &[[u32; 8]], &[[f64; 3]], &[[f64; 3]], &mut [[f64; 4]]);
/// The one-cell force kernel of a precision ([`kernel::cell_forces_from_edges`]).
type CellKernel = fn(&CellParams, &[u32; 8], &[[f64; 3]], &[[f64; 3]]) -> [[f64; 3]; 8];

/// Leftover edges ([`LeftoverEdge`]) stretched per call of
/// [`kernel::stretches`].
const LEFTOVER_BATCH: usize = 64;

/// Cells whose corner forces are computed together before being added to
/// the nodes (the buffer stays in L1; a multiple of both SIMD widths).
const FORCE_BATCH: usize = 32;

/// Cells per parallel task: large enough to amortize scheduling, small enough
/// to balance 2-16 threads on 10^4-cell models.
const CHUNK: usize = 512;

/// A lattice turned into a mass-spring model. Positions are absolute (m).
#[derive(Debug, Clone)]
pub struct Model {
    /// The lattice's node positions, shared with it (see [`Model::rest_positions`]).
    rest: std::sync::Arc<[[f64; 3]]>,
    /// The lattice's cells, shared with it.
    cells: std::sync::Arc<[[u32; 8]]>,
    h: f64,
    masses: Vec<f64>,
    /// Kernel constants per material.
    params: Vec<CellParams>,
    /// Per entry of `params`: the shares of the cell's stiffness at rest that
    /// grow under large strain, for [`Model::stiffness_growth`].
    growth_shares: Vec<GrowthShares>,
    /// Parameterization output per material.
    coefficients: Vec<CellCoefficients>,
    materials: Vec<Material>,
    /// Material of each cell; empty when there is a single material.
    cell_material: Vec<u32>,
    /// CSR node -> cell corners `8 * cell + corner`, ascending.
    /// The cells by lattice layer, for the force pass.
    layers: Layers,
    num_springs: usize,
    param_name: String,
    /// Upper bound of omega_max^2 (1/s^2) at rest.
    omega_max_sq: f64,
    /// Estimate of omega_max^2 at rest (1/s^2), computed when first asked
    /// for (see [`frequency`]).
    omega_max_sq_estimate: std::sync::OnceLock<f64>,
    /// The tangent's block pattern (row offsets, column indices), built on
    /// the first [`Model::tangent`] and kept: every Newton iteration
    /// assembles on it, and building it cost a tenth of an assembly.
    tangent_pattern: std::sync::OnceLock<(Vec<u32>, Vec<u32>)>,
    /// The bodies the model is made of, in node and cell order (one for a
    /// model built from a lattice; see [`Model::union`]).
    bodies: Vec<BodySpan>,
    /// The lattice edges at corner 0 of no cell.
    leftover_edges: Vec<LeftoverEdge>,
    /// A force workspace lent to the passes that do not bring their own
    /// ([`Model::internal_forces_shared`]).
    spare_workspace: crate::cache::Cache<ForceWorkspace>,
}

/// Where one body of a [`Model`] lies in its node and cell arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct BodySpan {
    /// Its nodes, a contiguous range of the model's.
    pub nodes: std::ops::Range<usize>,
    /// Its cells, a contiguous range of the model's.
    pub cells: std::ops::Range<usize>,
    /// Its materials, a contiguous range of [`Model::materials`].
    pub materials: std::ops::Range<usize>,
    /// Its cell edge (m).
    pub h: f64,
    /// The parameterization it was built with.
    pub parameterization: String,
}

fn to_arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl Model {
    /// Builds the model of `lattice` for one material everywhere.
    pub fn new(
        lattice: &Lattice,
        material: Material,
        param: &dyn Parameterization,
    ) -> Result<Self, ModelError> {
        Self::build(lattice, &[material], None, param)
    }

    /// Builds the model of `lattice` with material `materials[cell_material[c]]`
    /// in cell `c`.
    pub fn with_cell_materials(
        lattice: &Lattice,
        materials: &[Material],
        cell_material: &[u32],
        param: &dyn Parameterization,
    ) -> Result<Self, ModelError> {
        if cell_material.len() != lattice.num_cells() {
            return Err(ModelError::MaterialCount {
                given: cell_material.len(),
                cells: lattice.num_cells(),
            });
        }
        if let Some((cell, &index)) = cell_material
            .iter()
            .enumerate()
            .find(|&(_, &m)| m as usize >= materials.len())
        {
            return Err(ModelError::MaterialIndex {
                cell,
                index,
                count: materials.len(),
            });
        }
        Self::build(lattice, materials, Some(cell_material), param)
    }

    fn build(
        lattice: &Lattice,
        materials: &[Material],
        cell_material: Option<&[u32]>,
        param: &dyn Parameterization,
    ) -> Result<Self, ModelError> {
        let h = lattice.h();
        let mut params = Vec::with_capacity(materials.len());
        let mut coefficients = Vec::with_capacity(materials.len());
        for m in materials {
            param.validate(m)?;
            let co = param.coefficients(m, h);
            let bad = || ModelError::BadCoefficients {
                name: param.name(),
                k_edge: co.k_edge,
                k_diag: co.k_diag,
                correction: co.correction,
                lambda: co.volumetric_lambda,
                hourglass: co.hourglass,
            };
            if !(co.k_edge.is_finite()
                && co.k_diag.is_finite()
                && co.volumetric_lambda.is_finite()
                && co.hourglass.is_finite()
                && co.hourglass >= 0.0
                && co.correction.is_none_or(f64::is_finite))
            {
                return Err(bad());
            }
            let correction = match co.correction {
                Some(c) => Some(Correction::new(c).ok_or_else(bad)?),
                None => None,
            };
            params.push(CellParams {
                k_edge: co.k_edge,
                k_diag: co.k_diag,
                rest_edge: h,
                rest_diag: 3f64.sqrt() * h,
                correction,
                vol_lambda_h3: co.volumetric_lambda * h * h * h,
                vol_barrier: co.volumetric_barrier,
                grad_scale: 0.25 / h,
                k_hourglass: co.hourglass,
                // The barrier law guards the corners too, at the stiffness of
                // a constrained compression (lambda + 2 mu) over each corner's
                // eighth of the cell.
                corner_barrier: if co.volumetric_barrier {
                    (m.lambda() + 2.0 * m.shear_modulus()) * h * h * h / 8.0
                } else {
                    0.0
                },
            });
            coefficients.push(co);
        }
        let cube: [[f64; 3]; 8] =
            std::array::from_fn(|k| hexmesh::CORNER_OFFSETS[k].map(|o| f64::from(o) * h));
        let growth_shares = params
            .iter()
            .map(|p| {
                if p.vol_lambda_h3 == 0.0 && p.corner_barrier == 0.0 {
                    return GrowthShares::default();
                }
                let whole = kernel::gershgorin(&kernel::cell_jacobian(p, &cube));
                let volumetric_only = CellParams {
                    k_edge: 0.0,
                    k_diag: 0.0,
                    correction: None,
                    k_hourglass: 0.0,
                    corner_barrier: 0.0,
                    ..*p
                };
                let part = kernel::gershgorin(&kernel::cell_jacobian(&volumetric_only, &cube));
                GrowthShares {
                    volumetric: (part / whole).min(1.0),
                    // The barrier's Hessian per unit psi'' or psi' is of the
                    // order of kappa / h^2 (a corner Jacobian's gradient is
                    // of the order of 1 / h).
                    corner_barrier: p.corner_barrier / (h * h * whole),
                }
            })
            .collect();
        let rest = lattice.shared_nodes();
        let cells = lattice.shared_cells();
        let n = rest.len();
        let cell_material: Vec<u32> = match cell_material {
            Some(cm) if materials.len() > 1 => cm.to_vec(),
            _ => Vec::new(),
        };
        let mat_of = |c: usize| cell_material.get(c).map_or(0, |&m| m as usize);
        // Per-node sums accumulate in ascending (cell, corner) order.
        let mut masses = vec![0.0f64; n];
        for (c, cell) in cells.iter().enumerate() {
            let m = materials[mat_of(c)].density * h * h * h / 8.0;
            for &v in cell {
                masses[v as usize] += m;
            }
        }
        // Gershgorin on M^-1 K at rest: the row sums of |K| are bounded by the sum of
        // the cells' row sums, and every cell of a material has the same rest matrix.
        let row_abs: Vec<[f64; 24]> = params
            .iter()
            .map(|p| {
                let x: [[f64; 3]; 8] =
                    std::array::from_fn(|k| hexmesh::CORNER_OFFSETS[k].map(|o| o as f64 * h));
                let jac = kernel::cell_jacobian(p, &x);
                std::array::from_fn(|r| jac[r].iter().map(|v| v.abs()).sum())
            })
            .collect();
        let mut row_sums = vec![[0.0f64; 3]; n];
        for (c, cell) in cells.iter().enumerate() {
            let r = &row_abs[mat_of(c)];
            for (k, &v) in cell.iter().enumerate() {
                for d in 0..3 {
                    row_sums[v as usize][d] += r[3 * k + d];
                }
            }
        }
        let omega_max_sq = row_sums
            .iter()
            .zip(&masses)
            .flat_map(|(s, m)| s.map(|s| s / m))
            .fold(0.0f64, f64::max);
        drop(row_sums);
        let layers = Layers::of((0..lattice.num_cells()).map(|c| lattice.cell_coord(c)[2]));
        let num_cells = cells.len();
        let num_springs = lattice.num_unique_edges() + 4 * num_cells;
        let leftover_edges = leftover_edges(&cells, n, |_| h);
        Ok(Self {
            rest,
            cells,
            h,
            masses,
            params,
            growth_shares,
            coefficients,
            materials: materials.to_vec(),
            cell_material,
            layers,
            num_springs,
            param_name: param.name(),
            omega_max_sq,
            omega_max_sq_estimate: std::sync::OnceLock::new(),
            tangent_pattern: std::sync::OnceLock::new(),
            bodies: vec![BodySpan {
                nodes: 0..n,
                cells: 0..num_cells,
                materials: 0..materials.len(),
                h,
                parameterization: param.name(),
            }],
            leftover_edges,
            spare_workspace: Default::default(),
        })
    }

    /// One model of several bodies, stepped together: `bodies[b]`'s nodes,
    /// cells and materials follow those of the bodies before it, each body
    /// keeping its own cell size, parameterization and materials. No node is
    /// shared, so the bodies interact only through contact
    /// ([`crate::contact::BodyContact`]). Forces, tangents and energies are
    /// those of each body alone, bit for bit, in the same node sums.
    pub fn union(bodies: &[Model]) -> Result<Self, ModelError> {
        let Some(first) = bodies.first() else {
            return Err(ModelError::NoBodies);
        };
        if bodies.len() == 1 {
            return Ok(first.clone());
        }
        let nodes: usize = bodies.iter().map(Model::num_nodes).sum();
        if nodes > u32::MAX as usize {
            return Err(ModelError::TooManyNodes(nodes));
        }
        let mut rest = Vec::with_capacity(nodes);
        let mut cells = Vec::new();
        let mut masses = Vec::with_capacity(nodes);
        let (mut params, mut growth_shares, mut coefficients, mut materials) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut cell_material = Vec::new();
        let mut offsets = vec![0u32];
        let mut spans = Vec::new();
        let mut leftovers = Vec::new();
        let mut num_springs = 0;
        let mut omega_max_sq = 0.0f64;
        for body in bodies {
            for span in &body.bodies {
                let shift = |r: &std::ops::Range<usize>, by: usize| r.start + by..r.end + by;
                spans.push(BodySpan {
                    nodes: shift(&span.nodes, rest.len()),
                    cells: shift(&span.cells, cells.len()),
                    materials: shift(&span.materials, params.len()),
                    ..span.clone()
                });
            }
            let node_offset = rest.len() as u32;
            let cell_offset = cells.len() as u32;
            let material_offset = params.len() as u32;
            leftovers.extend(body.leftover_edges.iter().map(|e| LeftoverEdge {
                node: e.node + node_offset,
                end: e.end + node_offset,
                ..*e
            }));
            rest.extend_from_slice(&body.rest);
            cells.extend(body.cells.iter().map(|c| c.map(|v| v + node_offset)));
            masses.extend_from_slice(&body.masses);
            cell_material
                .extend((0..body.num_cells()).map(|c| body.cell_material(c) + material_offset));
            params.extend_from_slice(&body.params);
            growth_shares.extend_from_slice(&body.growth_shares);
            coefficients.extend_from_slice(&body.coefficients);
            materials.extend_from_slice(&body.materials);
            // A body's layers keep their parity (an empty layer between
            // bodies if needed), so that each node sums its cells in the
            // order it does alone: the same bits.
            if (offsets.len() - 1) % 2 == 1 {
                offsets.push(cell_offset);
            }
            offsets.extend(body.layers.offsets[1..].iter().map(|o| o + cell_offset));
            num_springs += body.num_springs;
            omega_max_sq = omega_max_sq.max(body.omega_max_sq);
        }
        let names: Vec<&str> = spans.iter().map(|s| s.parameterization.as_str()).collect();
        let mut param_name = names[0].to_owned();
        if names.iter().any(|n| *n != names[0]) {
            param_name = names.join("+");
        }
        let h = spans.iter().map(|s| s.h).fold(f64::INFINITY, f64::min);
        Ok(Self {
            rest: rest.into(),
            cells: cells.into(),
            h,
            masses,
            params,
            growth_shares,
            coefficients,
            materials,
            cell_material,
            layers: Layers { offsets },
            num_springs,
            param_name,
            omega_max_sq,
            omega_max_sq_estimate: std::sync::OnceLock::new(),
            tangent_pattern: std::sync::OnceLock::new(),
            bodies: spans,
            leftover_edges: leftovers,
            spare_workspace: Default::default(),
        })
    }

    /// The bodies of the model, in node order (one unless built by
    /// [`Model::union`]).
    pub fn bodies(&self) -> &[BodySpan] {
        &self.bodies
    }

    /// The body that node `node` belongs to.
    pub fn body_of_node(&self, node: usize) -> usize {
        self.bodies.partition_point(|b| b.nodes.end <= node)
    }

    /// Integer lattice coordinates of the nodes (for the multigrid's
    /// coarsening): each body's own grid, the bodies side by side along x
    /// with an even gap, so that no two bodies share a coordinate or a
    /// coarse cell.
    pub(crate) fn grid_coords(&self) -> Vec<[i64; 3]> {
        let rest = self.rest_positions();
        let mut out = Vec::with_capacity(rest.len());
        let mut x_start = 0i64;
        for b in &self.bodies {
            let mut coords = crate::solver::multigrid::grid_coords(&rest[b.nodes.clone()], b.h);
            let width = coords.iter().map(|c| c[0]).max().unwrap_or(0);
            for c in &mut coords {
                c[0] += x_start;
            }
            out.extend(coords);
            // A gap and a start at a multiple of 64 keep the cells of six
            // coarse levels within one body.
            x_start = (x_start + width + 2 + 63) & !63;
        }
        out
    }

    /// Whether every material resists the lattice's three mechanisms
    /// (docs/model.md section 5) with hourglass control. Without it, a smooth
    /// field of these checkerboard patterns costs about as little energy as a
    /// smooth displacement: the Newton solves' multigrid then gives them
    /// coarse spaces of their own.
    pub fn resists_mechanisms(&self) -> bool {
        self.coefficients.iter().all(|c| c.hourglass > 0.0)
    }

    /// Rest positions of the nodes (m).
    pub fn rest_positions(&self) -> &[Vec3] {
        // SAFETY: Vector3<f64> is a repr(C) wrapper of [[f64; 3]; 1], so a
        // slice of [f64; 3] has the layout of a slice of Vec3 of the same
        // length (the force pass relies on the converse).
        unsafe { std::slice::from_raw_parts(self.rest.as_ptr().cast::<Vec3>(), self.rest.len()) }
    }
    /// Cells (VTK_HEXAHEDRON order).
    pub fn cells(&self) -> &[[u32; 8]] {
        &self.cells
    }
    /// Cell edge (m); of a [`Model::union`], the smallest body's (each
    /// body's own is in [`Model::bodies`]).
    pub fn h(&self) -> f64 {
        self.h
    }
    /// Lumped node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.rest.len()
    }
    /// Number of cells.
    pub fn num_cells(&self) -> usize {
        self.cells.len()
    }
    /// Sum of the node masses (kg).
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().sum()
    }
    /// Number of merged springs: unique edges plus 4 body diagonals per cell.
    pub fn num_springs(&self) -> usize {
        self.num_springs
    }
    /// Name of the parameterization the model was built with.
    pub fn parameterization_name(&self) -> &str {
        &self.param_name
    }
    /// The materials, indexed by [`Model::cell_material`].
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }
    /// Material index of cell `cell`.
    pub fn cell_material(&self, cell: usize) -> u32 {
        self.cell_material.get(cell).copied().unwrap_or(0)
    }
    /// The parameterization's constants for cell `cell`.
    pub fn cell_coefficients(&self, cell: usize) -> CellCoefficients {
        self.coefficients[self.cell_material(cell) as usize]
    }
    /// Nodes on the lattice's boundary (outer surface and cavities): those
    /// with fewer than 8 cells around them, ascending.
    pub fn boundary_nodes(&self) -> Vec<u32> {
        let mut count = vec![0u8; self.num_nodes()];
        for cell in self.cells.iter() {
            for &v in cell {
                count[v as usize] += 1;
            }
        }
        (0..self.num_nodes())
            .filter(|&n| count[n] < 8)
            .map(|n| n as u32)
            .collect()
    }

    /// Approximate heap memory of the model (bytes), excluding workspaces;
    /// the node positions and cells are counted although they are shared
    /// with the lattice the model was built on.
    pub fn memory_bytes(&self) -> usize {
        self.rest.len() * 24
            + self.cells.len() * 32
            + self.masses.capacity() * 8
            + self.growth_shares.capacity() * std::mem::size_of::<GrowthShares>()
            + self.cell_material.capacity() * 4
            + self.layers.offsets.capacity() * 4
            + self.leftover_edges.capacity() * std::mem::size_of::<LeftoverEdge>()
    }

    #[inline(always)]
    fn param_index(&self, cell: usize) -> usize {
        self.cell_material.get(cell).map_or(0, |&m| m as usize)
    }

    #[inline(always)]
    fn params_of(&self, cell: usize) -> &CellParams {
        &self.params[self.param_index(cell)]
    }

    #[inline(always)]
    fn corners(&self, x: &[Vec3], cell: usize) -> [[f64; 3]; 8] {
        let c = &self.cells[cell];
        std::array::from_fn(|k| to_arr(&x[c[k] as usize]))
    }

    /// Number of distinct kernel parameter sets (one per material).
    pub(crate) fn num_param_sets(&self) -> usize {
        self.params.len()
    }

    /// Index of the parameter set of `cell`, below [`Model::num_param_sets`].
    pub(crate) fn param_set_of(&self, cell: usize) -> usize {
        self.param_index(cell)
    }

    /// The rest stiffness of one cell alone, `-d f / d x` at its rest corners
    /// (24 x 24, dofs corner-major).
    pub(crate) fn cell_rest_stiffness(&self, cell: usize) -> [[f64; 24]; 24] {
        let j = kernel::cell_jacobian(
            self.params_of(cell),
            &self.corners(self.rest_positions(), cell),
        );
        j.map(|row| row.map(|v| -v))
    }

    /// A workspace sized for this model.
    pub fn workspace(&self) -> ForceWorkspace {
        ForceWorkspace {
            edge_stretch: vec![[0.0; 3]; self.num_nodes()],
        }
    }

    /// Internal forces at positions `x` (N), written to `out`, with the
    /// model's spare workspace ([`Model::internal_forces_shared`]).
    pub fn internal_forces(&self, x: &[Vec3], out: &mut [Vec3]) {
        self.internal_forces_shared(Precision::F64, x, out);
    }

    /// [`Model::internal_forces_in`] with a workspace the model lends: it
    /// keeps one, so that the callers that do not hold their own between
    /// passes (an explicit integrator, a frame writer, a Newton residual)
    /// share one node array of scratch instead of each keeping or
    /// allocating theirs. Two passes at once on one model each get one
    /// (the second allocates); the model keeps one of them.
    pub fn internal_forces_shared(&self, precision: Precision, x: &[Vec3], out: &mut [Vec3]) {
        let mut ws = self.spare_workspace.take().unwrap_or_default();
        self.internal_forces_in(precision, x, &mut ws, out);
        self.spare_workspace.put(ws);
    }

    /// Internal forces at positions `x` (N), written to `out`, using `ws` as
    /// scratch (resized if needed). Bitwise identical for any thread count.
    ///
    /// Panics if `x` or `out` does not have one entry per node.
    pub fn internal_forces_with(&self, x: &[Vec3], ws: &mut ForceWorkspace, out: &mut [Vec3]) {
        self.forces_impl(x, ws, out, true, Precision::F64);
    }

    /// [`Model::internal_forces_with`] in the given [`Precision`].
    pub fn internal_forces_in(
        &self,
        precision: Precision,
        x: &[Vec3],
        ws: &mut ForceWorkspace,
        out: &mut [Vec3],
    ) {
        self.forces_impl(x, ws, out, true, precision);
    }

    /// The arithmetic of the force pass per cell of the model's first
    /// material in `precision` (every lane of every SIMD path performs the
    /// same), counted by running the kernel once on a number type that counts
    /// its operations: the cell kernel at rest (the corner barrier's test
    /// but not its forces, which act on crushed cells only), the stretches
    /// of the three edges at the cell's corner 0, and the corner forces'
    /// additions into the node sums. Set beside the machine's rate for
    /// these operations it bounds the pass's time from below
    /// (`examples/explicit_speed.rs`).
    pub fn force_operations(&self, precision: Precision) -> ForceOperations {
        if self.cells.is_empty() {
            return ForceOperations::ZERO;
        }
        kernel::force_operations(self.params_of(0), precision == Precision::F32)
    }

    /// As [`Model::internal_forces_with`] but one cell at a time, without SIMD
    /// batching: the reference path, for tests and benchmarks. Bitwise equal.
    pub fn internal_forces_scalar_with(
        &self,
        x: &[Vec3],
        ws: &mut ForceWorkspace,
        out: &mut [Vec3],
    ) {
        self.forces_impl(x, ws, out, false, Precision::F64);
    }

    /// [`Model::internal_forces_scalar_with`] in the given [`Precision`]:
    /// bitwise equal to [`Model::internal_forces_in`].
    pub fn internal_forces_scalar_in(
        &self,
        precision: Precision,
        x: &[Vec3],
        ws: &mut ForceWorkspace,
        out: &mut [Vec3],
    ) {
        self.forces_impl(x, ws, out, false, precision);
    }

    /// The stretch of every lattice edge at `xs`, into `edges` by the node it
    /// starts from and its axis: the cells' corner-0 edges in parallel, then
    /// the leftovers. Each value is computed as [`kernel::cell_forces`] does
    /// in `f64`; in `f32`, as [`kernel::seeded_stretch`] does.
    fn edge_pass(
        &self,
        xs: &[[f64; 3]],
        edges: &mut [[f64; 3]],
        batched: bool,
        precision: Precision,
    ) {
        match precision {
            Precision::F64 => self.edge_pass_as::<false>(xs, edges, batched),
            Precision::F32 => self.edge_pass_as::<true>(xs, edges, batched),
        }
    }

    /// [`Model::edge_pass`]; `SEED`: the single-precision pass's stretches
    /// ([`kernel::seeded_stretch`]).
    fn edge_pass_as<const SEED: bool>(
        &self,
        xs: &[[f64; 3]],
        edges: &mut [[f64; 3]],
        batched: bool,
    ) {
        let shared = SharedEdges(edges.as_mut_ptr());
        for body in &self.bodies {
            // The cells of a body all rest at its cell size.
            let rest = self.params[body.materials.start].rest_edge;
            self.cells[body.cells.clone()]
                .par_chunks(CHUNK)
                .for_each(|chunk| {
                    let mut buf = [[0.0f64; 3]; FORCE_BATCH];
                    for group in chunk.chunks(FORCE_BATCH) {
                        let w = &mut buf[..group.len()];
                        // SAFETY: as below, each node is corner 0 of one
                        // cell at most.
                        if batched
                            && unsafe {
                                kernel::edge_stretches_into_nodes::<SEED>(
                                    rest,
                                    group,
                                    xs,
                                    w,
                                    shared.0.cast::<[f64; 3]>(),
                                )
                            }
                        {
                            continue;
                        }
                        if batched {
                            kernel::edge_stretches_batch::<SEED>(rest, group, xs, w);
                        } else {
                            kernel::edge_stretches_scalar::<SEED>(rest, group, xs, w);
                        }
                        let s = shared;
                        for (cell, w) in group.iter().zip(w.iter()) {
                            // SAFETY: a node is corner 0 of one cell at
                            // most, and `edges` has one entry per node.
                            unsafe { *s.0.add(cell[0] as usize) = *w };
                        }
                    }
                });
        }
        // Their vectors are gathered, then stretched several per SIMD
        // operation: one at a time, the square root and the division of
        // each made these edges (8 % of a cube's) take 2 % of a small body's
        // explicit frame.
        let mut d = [[0.0; 3]; LEFTOVER_BATCH];
        let mut rest = [0.0; LEFTOVER_BATCH];
        let mut stretches = [0.0; LEFTOVER_BATCH];
        for batch in self.leftover_edges.chunks(LEFTOVER_BATCH) {
            let n = batch.len();
            for ((e, d), rest) in batch.iter().zip(&mut d).zip(&mut rest) {
                let (a, b) = (xs[e.node as usize], xs[e.end as usize]);
                *d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                *rest = e.rest;
            }
            kernel::stretches::<SEED>(&rest[..n], &d[..n], &mut stretches[..n]);
            for (e, w) in batch.iter().zip(stretches) {
                edges[e.node as usize][e.axis as usize] = w;
            }
        }
    }

    fn forces_impl(
        &self,
        x: &[Vec3],
        ws: &mut ForceWorkspace,
        out: &mut [Vec3],
        batched: bool,
        precision: Precision,
    ) {
        let (batch_kernel, cell_kernel): (BatchKernel, CellKernel) = match precision {
            Precision::F64 => (kernel::forces_batch, kernel::cell_forces_from_edges),
            Precision::F32 => (kernel::forces_batch_f32, kernel::cell_forces_from_edges_f32),
        };
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        assert_eq!(out.len(), self.num_nodes(), "forces: one per node");
        let xs = crate::as_arrays(x);
        ws.edge_stretch.resize(self.num_nodes(), [0.0; 3]);
        self.edge_pass(xs, &mut ws.edge_stretch, batched, precision);
        let edges = &ws.edge_stretch;
        self.add_batches_by_layers(out, batched, |first, uniform, fc, nodes| {
            let cells = &self.cells[first..first + fc.len() / 8];
            if uniform {
                let params = self.params_of(first);
                // SAFETY: `nodes` is `add_batches_by_layers`' node sums, of
                // which this batch's nodes are this task's alone.
                if unsafe {
                    kernel::forces_batch_into_nodes(
                        precision,
                        params,
                        cells,
                        xs,
                        edges,
                        fc,
                        nodes.0.cast::<[f64; 3]>(),
                    )
                } {
                    return true;
                }
                batch_kernel(params, cells, xs, edges, fc);
            } else {
                fill_cells(fc, first, |cell| {
                    cell_kernel(self.params_of(cell), &self.cells[cell], xs, edges)
                });
            }
            false
        });
    }

    /// `out = sum over cells of their 8 corner vectors`, computed by
    /// `batch(first, uniform, values)` for up to [`FORCE_BATCH`] consecutive
    /// cells from `first` (8 `[x, y, z, 0]` per cell into `values`; `uniform`
    /// when `vectorize` is asked for and the cells share one parameter set, so
    /// that the vector kernel may run), added in the force pass's order.
    ///
    /// `batch` may instead add its cells' vectors into the node sums itself
    /// (it is handed them) and say so by returning true; it must then add
    /// them in the same order.
    ///
    /// Two phases: the even layers, then the odd ones. A layer's cells touch
    /// the node planes z and z + 1 only, so within a phase no two layers
    /// share a node and each layer is one task, adding its cells' corner
    /// vectors in cell order. Every node thus sums its (at most 8) cell
    /// contributions in one fixed order, whatever the thread count.
    fn add_batches_by_layers(
        &self,
        out: &mut [Vec3],
        vectorize: bool,
        batch: impl Fn(usize, bool, &mut [[f64; 4]], SharedForces) -> bool + Sync,
    ) {
        out.par_chunks_mut(4 * CHUNK)
            .for_each(|c| c.fill(Vec3::zeros()));
        let shared = SharedForces(out.as_mut_ptr());
        let one_material = self.cell_material.is_empty();
        for parity in 0..2 {
            (parity..self.layers.count())
                .into_par_iter()
                .step_by(2)
                .for_each(|l| {
                    let range = self.layers.range(l);
                    let mut buf = [[0.0f64; 4]; 8 * FORCE_BATCH];
                    let mut first = range.start;
                    while first < range.end {
                        let last = (first + FORCE_BATCH).min(range.end);
                        let cells = &self.cells[first..last];
                        let fc = &mut buf[..8 * cells.len()];
                        // A batch of one material (every batch of most
                        // models, and most of a union's or regions') runs
                        // the vector kernel: bitwise equal to the cell path.
                        let uniform = vectorize
                            && (one_material
                                || (first..last)
                                    .all(|c| self.cell_material[c] == self.cell_material[first]));
                        let s = shared;
                        if batch(first, uniform, fc, s) {
                            first = last;
                            continue;
                        }
                        // SAFETY: the cells' nodes are of a layer of this
                        // phase's parity, which no other task of the phase
                        // touches; `out` has one entry per node.
                        unsafe { add_cells(cells, fc, s.0) };
                        first = last;
                    }
                });
        }
    }

    /// The 8 corner forces of one cell at positions `x` (N).
    pub fn cell_forces(&self, x: &[Vec3], cell: usize) -> [Vec3; 8] {
        let mut fc = [[0.0; 3]; 8];
        kernel::cell_forces(self.params_of(cell), &self.corners(x, cell), &mut fc);
        fc.map(|f| Vec3::new(f[0], f[1], f[2]))
    }

    /// Jacobian d(internal force)/dx at `x` (N/m), exact, with the pattern of
    /// [`BlockCsr::lattice_pattern`]. It is minus the stiffness matrix: negative
    /// semi-definite at rest, and not symmetric at large strain when the model
    /// has correction forces.
    pub fn tangent(&self, x: &[Vec3]) -> BlockCsr {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        let (row_offsets, col_indices) = self.tangent_pattern();
        let mut m = BlockCsr {
            row_offsets: row_offsets.clone(),
            col_indices: col_indices.clone(),
            blocks: vec![Mat3::zeros(); col_indices.len()],
        };
        // Each cell's Jacobian is added where it is computed, in the force
        // pass's layer order: the even layers in parallel, then the odd ones,
        // each layer's cells in order. A block gets its cells' parts in an
        // order that does not depend on the thread count, and the adding is
        // parallel too (it was a serial pass over batches of stored cell
        // matrices: 4.5 % of a one-thread static solve, and what kept two
        // threads from paying).
        let shared = SharedBlocks(m.blocks.as_mut_ptr());
        let (row_offsets, col_indices) = (&m.row_offsets, &m.col_indices);
        self.each_cell_by_layers(|cell| {
            let jac = kernel::cell_jacobian(self.params_of(cell), &self.corners(x, cell));
            let s = shared;
            // SAFETY: a cell writes only the rows of its own nodes, and the
            // nodes of a layer of this phase's parity belong to no other task
            // of the phase (as in the force pass); every block index is
            // within the pattern, which `blocks` has one entry per.
            unsafe {
                add_cell_matrix(s.0, row_offsets, col_indices, &self.cells[cell], &jac);
            }
        });
        m
    }

    /// The tangent's block pattern (row offsets, column indices), built on
    /// first use and kept.
    fn tangent_pattern(&self) -> &(Vec<u32>, Vec<u32>) {
        self.tangent_pattern
            .get_or_init(|| BlockCsr::lattice_pattern_indices(self.num_nodes(), &self.cells))
    }

    /// Calls `visit` with every cell in the force pass's layer order: the
    /// even layers in parallel, then the odd ones, each layer's cells in
    /// order; two tasks of a phase never share a node.
    fn each_cell_by_layers(&self, visit: impl Fn(usize) + Sync) {
        for parity in 0..2 {
            (parity..self.layers.count())
                .into_par_iter()
                .step_by(2)
                .for_each(|l| self.layers.range(l).for_each(&visit));
        }
    }

    /// The symmetric part of the stiffness, `-(T + T^T) / 2` with `T` the
    /// [`Model::tangent`] at `x`, stored once per pair of blocks: each cell's
    /// matrix is symmetrized where it is computed and only its blocks on and
    /// above the diagonal are added (in the force pass's layer order, as the
    /// tangent's), so the full matrix is never held. It records whether
    /// every cell's matrix was symmetric (to 1e-10 of its largest entry).
    pub fn symmetric_stiffness_upper(&self, x: &[Vec3]) -> crate::sparse::SymmetricUpper {
        use std::sync::atomic::{AtomicBool, Ordering};
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        let (row_offsets, col_indices) = self.tangent_pattern();
        let mut m = crate::sparse::SymmetricUpper::upper_pattern_of(row_offsets, col_indices);
        let shared = SharedBlocks(m.upper.blocks.as_mut_ptr());
        let (row_offsets, col_indices) = (&m.upper.row_offsets, &m.upper.col_indices);
        // At rest every cell of a parameter set is the same cube: the rows
        // of alike nodes then get the same bits, which lets the multigrid
        // store each distinct block once.
        // The cell's symmetrized stiffness blocks, and whether its Jacobian
        // was symmetric.
        // At rest the symmetrized blocks of each parameter set are computed
        // once; elsewhere each cell's, from its Jacobian, where they are added.
        let at_rest = (x == self.rest_positions()).then(|| {
            let jacs = self.rest_cell_jacobians();
            let symmetric = jacs.iter().all(jacobian_is_symmetric);
            let blocks: Vec<[[Mat3; 8]; 8]> = jacs
                .iter()
                .map(|jac| {
                    std::array::from_fn(|b| std::array::from_fn(|a| symmetric_block(jac, b, a)))
                })
                .collect();
            (blocks, symmetric)
        });
        // Any cell's verdict decides: the same for any order of the cells.
        let skewed = AtomicBool::new(at_rest.as_ref().is_some_and(|(_, sym)| !sym));
        self.each_cell_by_layers(|cell| {
            let cell_blocks = match &at_rest {
                Some((blocks, _)) => CellBlocks::Rest(&blocks[self.param_index(cell)]),
                None => {
                    let jac = kernel::cell_jacobian(self.params_of(cell), &self.corners(x, cell));
                    if !jacobian_is_symmetric(&jac) {
                        skewed.store(true, Ordering::Relaxed);
                    }
                    CellBlocks::Deformed(jac)
                }
            };
            let nodes = &self.cells[cell];
            let s = shared;
            for (b, &rb) in nodes.iter().enumerate() {
                let lo = row_offsets[rb as usize] as usize;
                let hi = row_offsets[rb as usize + 1] as usize;
                for (a, &ca) in nodes.iter().enumerate().filter(|&(_, &ca)| ca >= rb) {
                    let k = lo
                        + col_indices[lo..hi]
                            .binary_search(&ca)
                            .expect("cell pair in the upper pattern");
                    // SAFETY: as in `tangent`: a cell writes only the rows of
                    // its own nodes, which no other task of the phase has; `k`
                    // is within the pattern, which the blocks have one entry
                    // per.
                    let blk = unsafe { &mut *s.0.add(k) };
                    *blk += cell_blocks.block(b, a);
                }
            }
        });
        m.from_symmetric = !skewed.into_inner();
        m
    }

    /// The stiffness matrix `-tangent(x)` (N/m).
    pub fn stiffness(&self, x: &[Vec3]) -> BlockCsr {
        let mut m = self.tangent(x);
        for b in &mut m.blocks {
            *b = -*b;
        }
        m
    }

    /// The rest stiffness matrix `-tangent(rest)` (N/m), symmetric positive
    /// semi-definite.
    pub fn rest_stiffness(&self) -> BlockCsr {
        self.stiffness(self.rest_positions())
    }

    /// Potential energy of the springs and the volumetric term (J). The
    /// correction forces are not conservative and have no energy.
    pub fn energy(&self, x: &[Vec3]) -> f64 {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        // Fixed-size chunks summed in order: deterministic.
        let parts: Vec<f64> = (0..self.cells.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .fold_chunks(
                CHUNK,
                || 0.0,
                |acc, c| acc + kernel::cell_energy(self.params_of(c), &self.corners(x, c)),
            )
            .collect();
        parts.iter().sum()
    }

    /// Upper bound of the highest angular eigenfrequency at rest (rad/s), from
    /// Gershgorin discs of `M^-1 K` (springs, corrections and volumetric term).
    pub fn omega_max_bound(&self) -> f64 {
        self.omega_max_sq.sqrt()
    }

    /// Estimate of the highest angular eigenfrequency at rest (rad/s): the
    /// Lanczos iteration on the rest stiffness with a 5 % margin on
    /// `omega^2`, never above [`Model::omega_max_bound`] (see
    /// [`frequency`]). Computed on the first call (tens of matrix-free
    /// stiffness products), then kept.
    pub fn omega_max(&self) -> f64 {
        self.omega_max_sq_estimate
            .get_or_init(|| {
                let mats = self.rest_cell_matrices();
                let estimate = frequency::max_eigenvalue(&self.masses, |v, out| {
                    self.rest_stiffness_mul(&mats, v, out)
                });
                (estimate * frequency::FREQUENCY_MARGIN).min(self.omega_max_sq)
            })
            .sqrt()
    }

    /// Critical time step `2 / omega_max` of explicit integration at rest (s),
    /// from [`Model::omega_max`].
    pub fn critical_time_step(&self) -> f64 {
        2.0 / self.omega_max()
    }

    /// Stable explicit time step (s): 0.9 of [`Model::critical_time_step`], a
    /// margin for the stiffening of springs under compression at large strain.
    pub fn stable_time_step(&self) -> f64 {
        0.9 * self.critical_time_step()
    }

    /// The force Jacobian of a cell of each parameter set at rest, on the
    /// ideal cube of edge h (all cells are such cubes, so one matrix per
    /// material; their corners' rounded coordinates would make alike cells'
    /// matrices differ in their last bits).
    fn rest_cell_jacobians(&self) -> Vec<[[f64; 24]; 24]> {
        self.params
            .iter()
            .map(|p| {
                let cube: [[f64; 3]; 8] = std::array::from_fn(|k| {
                    hexmesh::CORNER_OFFSETS[k].map(|o| o as f64 * p.rest_edge)
                });
                kernel::cell_jacobian(p, &cube)
            })
            .collect()
    }

    /// The symmetric rest stiffness of a cell of each parameter set, from
    /// [`Model::rest_cell_jacobians`].
    fn rest_cell_matrices(&self) -> Vec<[[f64; 24]; 24]> {
        self.rest_cell_jacobians()
            .into_iter()
            .map(|j| std::array::from_fn(|r| std::array::from_fn(|c| -0.5 * (j[r][c] + j[c][r]))))
            .collect()
    }

    /// `out = K0 v` with the rest stiffness of [`Model::rest_cell_matrices`],
    /// matrix-free, in the force pass's layer order (the same bits for any
    /// thread count); cells of one material several per SIMD pass
    /// ([`rest_products`]), the same bits as cell by cell.
    fn rest_stiffness_mul(&self, mats: &[[[f64; 24]; 24]], v: &[Vec3], out: &mut [Vec3]) {
        let vs = crate::as_arrays(v);
        self.add_batches_by_layers(out, true, |first, uniform, fc, _| {
            if uniform {
                let cells = &self.cells[first..first + fc.len() / 8];
                rest_products(&mats[self.param_index(first)], cells, vs, fc);
            } else {
                fill_cells(fc, first, |cell| {
                    rest_product(&mats[self.param_index(cell)], &self.cells[cell], vs)
                });
            }
            false
        });
    }

    /// `out = T v` with `T` the [`Model::tangent`] at `x`, matrix-free: the
    /// force kernel on dual numbers along `v`, so no matrix is stored (the
    /// same values as the assembled product to round-off), in the force
    /// pass's layer order (the same bits for any thread count). Newton's
    /// solves use the assembled tangent: docs/solvers.md ("Matrix-free or
    /// assembled") measures both.
    pub fn tangent_mul(&self, x: &[Vec3], v: &[Vec3], out: &mut [Vec3]) {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        assert_eq!(v.len(), self.num_nodes(), "directions: one per node");
        assert_eq!(out.len(), self.num_nodes(), "products: one per node");
        let (xs, vs) = (crate::as_arrays(x), crate::as_arrays(v));
        self.add_batches_by_layers(out, true, |first, uniform, fc, _| {
            let cells = &self.cells[first..first + fc.len() / 8];
            if uniform {
                kernel::tangent_action_batch(self.params_of(first), cells, xs, vs, fc);
            } else {
                fill_cells(fc, first, |cell| {
                    kernel::cell_tangent_action(self.params_of(cell), &self.cells[cell], xs, vs)
                });
            }
            false
        });
    }

    /// Per-cell strain measures and correction-force magnitude at `x`.
    pub fn cell_diagnostics(&self, x: &[Vec3]) -> Vec<CellDiagnostics> {
        let mut out = Vec::new();
        self.cell_diagnostics_into(x, &mut out);
        out
    }

    /// [`Model::cell_diagnostics`] into `out`, reusing its allocation.
    pub fn cell_diagnostics_into(&self, x: &[Vec3], out: &mut Vec<CellDiagnostics>) {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        (0..self.cells.len())
            .into_par_iter()
            .map(|c| {
                let (volumetric_strain, shear_strain) = self.cell_strains(x, c);
                CellDiagnostics {
                    volumetric_strain,
                    shear_strain,
                    correction_force: self.cell_correction_force(x, c),
                }
            })
            .collect_into_vec(out);
    }

    /// One of [`CellMeasure`] for the cells `cells` only, into `out`
    /// (reusing its allocation): a frame writer computes each of its cell
    /// fields in turn, a block of cells at a time, instead of holding every
    /// cell's diagnostics at once; and only the correction force costs
    /// force kernels.
    pub fn cell_measure_of(
        &self,
        x: &[Vec3],
        cells: std::ops::Range<usize>,
        measure: CellMeasure,
        out: &mut Vec<f64>,
    ) {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        assert!(cells.end <= self.cells.len(), "cells of the model");
        cells
            .into_par_iter()
            .map(|c| match measure {
                CellMeasure::VolumetricStrain => self.cell_strains(x, c).0,
                CellMeasure::ShearStrain => self.cell_strains(x, c).1,
                CellMeasure::CorrectionForce => self.cell_correction_force(x, c),
            })
            .collect_into_vec(out);
    }

    /// `(J - 1, shear strain)` of cell `c` at `x` ([`CellDiagnostics`]).
    fn cell_strains(&self, x: &[Vec3], c: usize) -> (f64, f64) {
        let xc = self.corners(x, c);
        let (cols, jac) = kernel::deformation_gradient(&xc, self.params_of(c).grad_scale);
        let f = Mat3::from_columns(&cols.map(|c| Vec3::new(c[0], c[1], c[2])));
        let green = 0.5 * (f.transpose() * f - Mat3::identity());
        let dev = green - Mat3::identity() * (green.trace() / 3.0);
        (jac - 1.0, (2.0 / 3.0 * dev.norm_squared()).sqrt())
    }

    /// The magnitude of cell `c`'s correction forces at `x`
    /// ([`CellDiagnostics::correction_force`]).
    fn cell_correction_force(&self, x: &[Vec3], c: usize) -> f64 {
        let p = self.params_of(c);
        if p.correction.is_none() {
            return 0.0;
        }
        let xc = self.corners(x, c);
        let mut full = [[0.0; 3]; 8];
        let no_hourglass = CellParams {
            k_hourglass: 0.0,
            corner_barrier: 0.0,
            ..*p
        };
        kernel::cell_forces(&no_hourglass, &xc, &mut full);
        let mut springs = [[0.0; 3]; 8];
        let q = CellParams {
            correction: None,
            vol_lambda_h3: 0.0,
            k_hourglass: 0.0,
            corner_barrier: 0.0,
            ..*p
        };
        kernel::cell_forces(&q, &xc, &mut springs);
        let mut vol = [[0.0; 3]; 8];
        if p.vol_lambda_h3 != 0.0 {
            let r = CellParams {
                correction: None,
                k_edge: 0.0,
                k_diag: 0.0,
                k_hourglass: 0.0,
                corner_barrier: 0.0,
                ..*p
            };
            kernel::cell_forces(&r, &xc, &mut vol);
        }
        (0..8)
            .map(|k| {
                (0..3)
                    .map(|d| (full[k][d] - springs[k][d] - vol[k][d]).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            .sqrt()
    }

    /// Per cell, how far its corners are from the best affine map of the
    /// cell (least squares over the 8 corners), as the largest corner
    /// distance divided by `h`. Zero for any affine deformation; the
    /// lattice's hourglass zigzag shows up here (docs/robustness.md).
    pub fn affine_deviation(&self, x: &[Vec3]) -> Vec<f64> {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        (0..self.cells.len())
            .into_par_iter()
            .map(|c| {
                let xc = self.corners(x, c);
                let h = self.params_of(c).rest_edge;
                // The corner sign vectors are orthogonal, so the least-squares
                // gradient is the centre gradient and the offset the mean.
                let (cols, _) = kernel::deformation_gradient(&xc, 1.0 / (4.0 * h));
                let mean = xc
                    .iter()
                    .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]);
                // Corner n sits at (h/2) s_n from the centre.
                let residual2 = |n: usize| {
                    (0..3)
                        .map(|d| {
                            let fit = mean[d] / 8.0
                                + (0..3)
                                    .map(|j| cols[j][d] * kernel::corner_sign(n, j) * 0.5 * h)
                                    .sum::<f64>();
                            (xc[n][d] - fit).powi(2)
                        })
                        .sum::<f64>()
                };
                (0..8).map(residual2).fold(0.0, f64::max).sqrt() / h
            })
            .collect()
    }

    /// How much the bound of the highest vibration frequency squared has
    /// grown since rest, at `x` (>= 1; `omega_max_bound()^2` times this
    /// bounds omega_max^2 at `x`). The volumetric term stiffens as cells are
    /// compressed (steeply with the barrier law), so cells are ranked by a
    /// cheap estimate of that growth (the term's share of the cell's
    /// stiffness at rest times the growth of its Hessian
    /// `phi''(J) b b^T + phi'(J) db/dx`), and the eight worst are
    /// bounded exactly, element by element: omega^2 <= the Gershgorin bound
    /// of the cell's exact Jacobian over its corner mass. The explicit step
    /// divides its sub-step by the square root of this (docs/robustness.md).
    /// The corner barrier (models with the barrier law) is ranked the same
    /// way, by `psi'' + |psi'|` at the cell's lowest corner Jacobian.
    /// Models without a volumetric term report 1: springs do not stiffen
    /// along their length, and their transverse stiffening when folded is
    /// left to the step control's retries.
    pub fn stiffness_growth(&self, x: &[Vec3]) -> f64 {
        self.stiffness_growth_and_lowest_corner(x).0
    }

    /// [`Model::stiffness_growth`] and, for models with the corner barrier,
    /// the lowest corner Jacobian of any cell (infinite without it), from
    /// the same pass: the explicit step checks more often as a corner nears
    /// the barrier, whose stiffness rises quickly once it is reached.
    pub fn stiffness_growth_and_lowest_corner(&self, x: &[Vec3]) -> (f64, f64) {
        let checks = self.cell_checks(x, true);
        (checks.stiffness_growth, checks.lowest_corner)
    }

    /// Cells whose Jacobian `J = det F` at the centre is `<= 0` (inverted):
    /// the solvers refuse such a state (a step that makes one is taken again
    /// with a shorter sub-step, or fails).
    pub fn inverted_cells(&self, x: &[Vec3]) -> Vec<u32> {
        self.cell_checks(x, false).inverted
    }

    /// The inverted cells ([`Model::inverted_cells`]) and, with `growth`,
    /// [`Model::stiffness_growth_and_lowest_corner`], from one pass over the
    /// cells (the explicit step's check asks for all three): several cells
    /// per SIMD pass where they share their parameters, the same bits
    /// either way, whatever the thread count.
    pub fn cell_checks(&self, x: &[Vec3], growth: bool) -> CellChecks {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        let growth = growth
            && self
                .growth_shares
                .iter()
                .any(|w| *w != GrowthShares::default());
        let corners = growth && self.growth_shares.iter().any(|w| w.corner_barrier != 0.0);
        let xs = crate::as_arrays(x);
        let one_material = self.cell_material.is_empty();
        // Per chunk of cells: the worst cells by the cheap estimate, the
        // lowest corner, the inverted cells in order.
        let chunk = |first: usize, cells: &[[u32; 8]]| {
            let mut worst = Worst::default();
            let mut lowest_corner = f64::INFINITY;
            let mut inverted = Vec::new();
            let mut survey = [kernel::CellSurvey {
                jac: 0.0,
                volumetric_growth: 0.0,
                lowest_corner: 0.0,
            }; SURVEY_BATCH];
            let mut start = 0;
            while start < cells.len() {
                // A run of cells of one parameter set, at most a batch.
                let param = self.param_index(first + start);
                let mut end = start + 1;
                while end < cells.len()
                    && end - start < SURVEY_BATCH
                    && (one_material || self.param_index(first + end) == param)
                {
                    end += 1;
                }
                let (p, shares) = (&self.params[param], self.growth_shares[param]);
                let out = &mut survey[..end - start];
                let parts = (
                    growth && shares.volumetric != 0.0,
                    corners && shares.corner_barrier != 0.0,
                );
                kernel::survey_batch(p, &cells[start..end], xs, parts, out);
                for (k, s) in out.iter().enumerate() {
                    let c = (first + start + k) as u32;
                    if s.jac <= 0.0 {
                        inverted.push(c);
                    }
                    if growth && shares != GrowthShares::default() {
                        let w = shares.volumetric;
                        let mut g = 1.0 - w;
                        if parts.0 {
                            g += w * s.volumetric_growth;
                        }
                        if parts.1 {
                            lowest_corner = lowest_corner.min(s.lowest_corner);
                            let (_, slope, curvature) = kernel::corner_barrier_law(s.lowest_corner);
                            g += 8.0 * shares.corner_barrier * (curvature + slope.abs());
                        }
                        worst.offer(g, c);
                    }
                }
                start = end;
            }
            (worst, lowest_corner, inverted)
        };
        let (worst, lowest_corner, inverted) = self
            .cells
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(k, cells)| chunk(k * CHUNK, cells))
            // The minimum is the same in any order, the worst cells are
            // ranked with ties to the lower index, and the inverted lists
            // are joined in cell order: deterministic.
            .reduce(
                || (Worst::default(), f64::INFINITY, Vec::new()),
                |(a, la, mut ia), (b, lb, ib)| {
                    ia.extend(ib);
                    (Worst::merge(a, b), la.min(lb), ia)
                },
            );
        if !growth {
            return CellChecks {
                inverted,
                stiffness_growth: 1.0,
                lowest_corner: f64::INFINITY,
            };
        }
        // Element by element: omega^2 <= max over cells of the cell's
        // stiffness bound over its corner mass (the cell's share of its
        // nodes' lumped masses), here for the cells most likely to set it.
        let worst_cell_omega_sq = worst
            .entries
            .iter()
            .filter(|&&(_, c)| c != u32::MAX)
            .map(|&(_, c)| {
                let c = c as usize;
                let p = self.params_of(c);
                let jac = kernel::cell_jacobian(p, &self.corners(x, c));
                let h3 = p.rest_edge * p.rest_edge * p.rest_edge;
                let corner_mass = self.materials[self.cell_material(c) as usize].density * h3 / 8.0;
                kernel::gershgorin(&jac) / corner_mass
            })
            .fold(0.0, f64::max);
        CellChecks {
            inverted,
            stiffness_growth: (worst_cell_omega_sq / self.omega_max_sq).max(1.0),
            lowest_corner,
        }
    }

    /// Cells folded at a corner: a corner Jacobian `J_n <= 0` (the trilinear
    /// map turned inside out near that corner) while the centre may still
    /// look healthy. The barrier law's corner barrier keeps quasi-static
    /// scenes free of them; a violent rebound can fold a corner for a few
    /// steps, which the barrier then unfolds, so the solvers report folded
    /// cells (`mss run` and `summary.json`) rather than refuse the state
    /// (docs/robustness.md).
    pub fn folded_cells(&self, x: &[Vec3]) -> Vec<u32> {
        self.corner_jacobians(x)
            .into_iter()
            .enumerate()
            .filter(|&(_, j)| j <= 0.0)
            .map(|(c, _)| c as u32)
            .collect()
    }

    /// Per cell, the smallest of its 8 corner Jacobians `J_n` (the trilinear
    /// map's determinant at each corner: 1 at rest, `<= 0` where the cell is
    /// folded through near that corner).
    pub fn corner_jacobians(&self, x: &[Vec3]) -> Vec<f64> {
        assert_eq!(x.len(), self.num_nodes(), "positions: one per node");
        (0..self.cells.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|c| Self::lowest_corner(self.params_of(c), &self.corners(x, c)))
            .collect()
    }

    fn lowest_corner(p: &CellParams, xc: &[[f64; 3]; 8]) -> f64 {
        let (_, jac) = kernel::corner_jacobians(xc, 1.0 / p.rest_edge.powi(3));
        jac.into_iter().fold(f64::INFINITY, f64::min)
    }
}

/// The shares of a cell's stiffness at rest (Gershgorin bounds) that grow
/// under large strain.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct GrowthShares {
    /// The volumetric term's share.
    volumetric: f64,
    /// The corner barrier's `kappa / h^2` over the cell's stiffness (the
    /// barrier is zero at rest).
    corner_barrier: f64,
}

/// What [`Model::cell_checks`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct CellChecks {
    /// The inverted cells ([`Model::inverted_cells`]), ascending.
    pub inverted: Vec<u32>,
    /// [`Model::stiffness_growth`] (1 when not asked for).
    pub stiffness_growth: f64,
    /// The lowest corner Jacobian of any cell, for models with the corner
    /// barrier (infinite without it, or when not asked for).
    pub lowest_corner: f64,
}

/// Cells surveyed per call of the batch kernel by [`Model::cell_checks`].
const SURVEY_BATCH: usize = 64;

/// Cells examined exactly by [`Model::stiffness_growth`].
const WORST_CELLS: usize = 8;

/// The [`WORST_CELLS`] largest `(value, cell)` pairs seen, largest first; ties
/// go to the lower cell index, so that the result does not depend on how the
/// cells were split among threads.
#[derive(Clone, Copy)]
struct Worst {
    entries: [(f64, u32); WORST_CELLS],
}

impl Default for Worst {
    fn default() -> Self {
        Self {
            entries: [(f64::NEG_INFINITY, u32::MAX); WORST_CELLS],
        }
    }
}

impl Worst {
    fn ahead(a: (f64, u32), b: (f64, u32)) -> bool {
        a.0 > b.0 || (a.0 == b.0 && a.1 < b.1)
    }

    fn offer(&mut self, value: f64, cell: u32) {
        let mut item = (value, cell);
        // The entries are in order: most cells are behind the last and
        // would pass every slot.
        if !Self::ahead(item, self.entries[WORST_CELLS - 1]) {
            return;
        }
        for slot in &mut self.entries {
            if Self::ahead(item, *slot) {
                std::mem::swap(slot, &mut item);
            }
        }
    }

    fn merge(mut self, other: Self) -> Self {
        for (value, cell) in other.entries {
            if cell != u32::MAX {
                self.offer(value, cell);
            }
        }
        self
    }
}

/// Adds a 24x24 cell matrix (rows and columns corner-major) to `m`.
/// Adds a cell's 24 x 24 Jacobian into the blocks (at `blocks`) of a matrix
/// with the lattice pattern `row_offsets`, `col_indices`.
///
/// # Safety
/// `blocks` points to one block per entry of `col_indices`, and no other
/// thread reads or writes the rows of the cell's nodes meanwhile.
unsafe fn add_cell_matrix(
    blocks: *mut Mat3,
    row_offsets: &[u32],
    col_indices: &[u32],
    cell: &[u32; 8],
    jac: &[[f64; 24]; 24],
) {
    for (b, &rb) in cell.iter().enumerate() {
        let lo = row_offsets[rb as usize] as usize;
        let hi = row_offsets[rb as usize + 1] as usize;
        for (a, &ca) in cell.iter().enumerate() {
            let k = lo
                + col_indices[lo..hi]
                    .binary_search(&ca)
                    .expect("cell pair in the lattice pattern");
            // SAFETY: `k` indexes `col_indices`, hence the blocks (caller).
            let blk = unsafe { &mut *blocks.add(k) };
            for e in 0..3 {
                for d in 0..3 {
                    blk[(e, d)] += jac[3 * b + e][3 * a + d];
                }
            }
        }
    }
}

/// Block `(b, a)` of a cell's symmetrized stiffness `-(J + J^T) / 2`.
fn symmetric_block(jac: &[[f64; 24]; 24], b: usize, a: usize) -> Mat3 {
    Mat3::from_fn(|e, d| -(0.5 * (jac[3 * b + e][3 * a + d] + jac[3 * a + d][3 * b + e])))
}

/// Whether a cell's Jacobian is symmetric to 1e-10 of its largest entry.
fn jacobian_is_symmetric(jac: &[[f64; 24]; 24]) -> bool {
    let (mut largest, mut skew) = (0.0f64, 0.0f64);
    for (p, row) in jac.iter().enumerate() {
        for (q, v) in row.iter().enumerate() {
            largest = largest.max(v.abs());
            skew = skew.max((v - jac[q][p]).abs());
        }
    }
    skew <= 1e-10 * largest
}

/// A cell's symmetrized stiffness blocks in [`Model::symmetric_stiffness_upper`]:
/// its parameter set's at rest, or from its own Jacobian (only the blocks
/// added are formed).
#[allow(clippy::large_enum_variant)] // one on the stack per cell visited
enum CellBlocks<'a> {
    Rest(&'a [[Mat3; 8]; 8]),
    Deformed([[f64; 24]; 24]),
}

impl CellBlocks<'_> {
    fn block(&self, b: usize, a: usize) -> Mat3 {
        match self {
            CellBlocks::Rest(blocks) => blocks[b][a],
            CellBlocks::Deformed(jac) => symmetric_block(jac, b, a),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::noise;

    /// The explicit step's cell survey loads eight cells that lie in one
    /// row of the lattice as runs of nodes (on CPUs with AVX-512): the bits
    /// of the one-cell survey for rows longer than eight cells, rows cut by
    /// holes and groups that straddle two rows; and the worst cells ranked
    /// the same whatever the thread count.
    #[test]
    fn surveys_of_rows_are_the_one_cell_bits() {
        let block = hexmesh::Lattice::block([19, 3, 2], 0.01, [0.0; 3]).unwrap();
        let holed = hexmesh::Lattice::from_cells(
            [0.0; 3],
            0.01,
            [21, 4, 3],
            (0..21u32)
                .flat_map(|i| (0..4u32).flat_map(move |j| (0..3u32).map(move |k| [i, j, k])))
                .filter(|&[i, j, k]| !(i == 11 && j == 1) && (i + 2 * j + 5 * k) % 23 != 4),
        )
        .unwrap();
        let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
        for lattice in [&block, &holed] {
            let model =
                Model::new(lattice, Material::new(3.0e4, 0.3, 1000.0).unwrap(), &param).unwrap();
            let mut seed = 3u64;
            let h = model.h();
            let x: Vec<Vec3> = model
                .rest_positions()
                .iter()
                .map(|p| {
                    let q = Vec3::new(1.2 * p.x + 0.3 * p.z, 0.7 * p.y, 0.9 * p.z);
                    q + Vec3::new(noise(&mut seed), noise(&mut seed), noise(&mut seed)) * (0.3 * h)
                })
                .collect();
            let xs = crate::as_arrays(&x);
            let p = &model.params[0];
            let blank = kernel::CellSurvey {
                jac: 0.0,
                volumetric_growth: 0.0,
                lowest_corner: 0.0,
            };
            let mut batch = vec![blank; model.num_cells()];
            for (cells, out) in model
                .cells
                .chunks(SURVEY_BATCH)
                .zip(batch.chunks_mut(SURVEY_BATCH))
            {
                kernel::survey_batch(p, cells, xs, (true, true), out);
            }
            for (c, s) in model.cells.iter().zip(&batch) {
                let xc: [[f64; 3]; 8] = std::array::from_fn(|k| xs[c[k] as usize]);
                let one = kernel::cell_survey(p, &xc, true, true);
                assert_eq!(s.jac.to_bits(), one.jac.to_bits());
                assert_eq!(
                    s.volumetric_growth.to_bits(),
                    one.volumetric_growth.to_bits()
                );
                assert_eq!(s.lowest_corner.to_bits(), one.lowest_corner.to_bits());
            }
            let checks = |threads| crate::on_threads(threads, || model.cell_checks(&x, true));
            let one = checks(1);
            assert!(one.stiffness_growth > 1.0 && one.lowest_corner < 1.0);
            assert_eq!(one, checks(2));
        }
    }

    /// The rest stiffness products several cells per pass are the cell by
    /// cell products' bits, on every lane count and with a tail of fewer
    /// cells than a pass; and `K0 v` is minus the tangent's action at rest
    /// (its symmetric part there), whatever the thread count.
    #[test]
    fn rest_stiffness_products_are_the_cell_by_cell_bits() {
        let lattice = hexmesh::Lattice::block([5, 3, 3], 0.01, [0.0; 3]).unwrap();
        let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
        let model =
            Model::new(&lattice, Material::new(3.0e4, 0.3, 1000.0).unwrap(), &param).unwrap();
        let mut seed = 11u64;
        let v: Vec<Vec3> = (0..model.num_nodes())
            .map(|_| Vec3::new(noise(&mut seed), noise(&mut seed), noise(&mut seed)))
            .collect();
        let vs = crate::as_arrays(&v);
        let mats = model.rest_cell_matrices();
        let k = &mats[0];
        let cells = &model.cells[..model.num_cells() - 2];
        let want: Vec<[f64; 4]> = cells
            .iter()
            .flat_map(|c| rest_product(k, c, vs).map(|p| [p[0], p[1], p[2], 0.0]))
            .collect();
        let bits =
            |o: &[[f64; 4]]| -> Vec<u64> { o.as_flattened().iter().map(|x| x.to_bits()).collect() };
        let mut got = vec![[1.0; 4]; want.len()];
        rest_products(k, cells, vs, &mut got);
        assert_eq!(bits(&got), bits(&want));
        rest_products_lanes::<8>(k, cells, vs, &mut got);
        assert_eq!(bits(&got), bits(&want));
        rest_products_lanes::<4>(k, cells, vs, &mut got);
        assert_eq!(bits(&got), bits(&want));
        let product = |threads| {
            crate::on_threads(threads, || {
                let mut out = vec![Vec3::zeros(); v.len()];
                model.rest_stiffness_mul(&mats, &v, &mut out);
                out
            })
        };
        let (one, two) = (product(1), product(2));
        assert_eq!(one, two);
        let mut tangent = vec![Vec3::zeros(); v.len()];
        model.tangent_mul(model.rest_positions(), &v, &mut tangent);
        let scale = one.iter().map(|p| p.norm()).fold(0.0, f64::max);
        for (k0v, tv) in one.iter().zip(&tangent) {
            assert!((k0v + tv).norm() <= 1e-10 * scale, "{k0v:?} vs {tv:?}");
        }
    }
}
