//! Published figures as named data, so that reports compare against values
//! with a name and a source instead of anonymous tuples.
//!
//! Two sources:
//! - the paper (Baudet et al., WSCG 2009, Figures 5 and 6): its own model
//!   against its FEM reference, as mean / standard deviation / maximum of the
//!   node-wise error in % of the largest reference displacement;
//! - an independent implementation of the same model whose figures
//!   `docs/model.md` records (mean / maximum only), for the paper's model and
//!   the volumetric variant.
//!
//! ```
//! use mss_validate::figures::{INDEPENDENT_BEAM, BeamCase};
//! let row = INDEPENDENT_BEAM
//!     .iter()
//!     .find(|r| r.case == BeamCase::SmallLoad && r.cells_across == 4)
//!     .unwrap();
//! assert_eq!((row.paper.mean, row.paper.max), (4.3, 10.1));
//! ```

/// Mean and maximum of the node-wise error (% of the largest reference displacement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanMax {
    /// Mean over the lattice nodes (%).
    pub mean: f64,
    /// Maximum over the lattice nodes (%).
    pub max: f64,
}

/// Mean, standard deviation and maximum of the node-wise error (%).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanSdMax {
    /// Mean over the lattice nodes (%).
    pub mean: f64,
    /// Standard deviation over the lattice nodes (%).
    pub sd: f64,
    /// Maximum over the lattice nodes (%).
    pub max: f64,
}

/// Which cantilever experiment a figure belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeamCase {
    /// Small load, linear (small-strain) solutions on both sides.
    SmallLoad,
    /// Large deflection (total mass 0.0125 kg, tip about 0.116 m) against a
    /// St. Venant-Kirchhoff FEM reference.
    LargeDeflectionSvk,
}

impl BeamCase {
    /// Short description for report tables.
    pub fn label(self) -> &'static str {
        match self {
            BeamCase::SmallLoad => "small load",
            BeamCase::LargeDeflectionSvk => "large deflection (SVK reference)",
        }
    }
}

/// One row of the independent implementation's cantilever figures: the
/// 0.4 x 0.1 x 0.1 m cantilever with `4n x n x n` cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndependentBeamFigure {
    /// The experiment.
    pub case: BeamCase,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Cells across the beam's thickness (`n` of `4n x n x n`).
    pub cells_across: u32,
    /// The paper's model.
    pub paper: MeanMax,
    /// The volumetric variant.
    pub volumetric: MeanMax,
}

const fn mm(mean: f64, max: f64) -> MeanMax {
    MeanMax { mean, max }
}

/// The independent implementation's cantilever figures (docs/model.md).
pub const INDEPENDENT_BEAM: [IndependentBeamFigure; 4] = [
    IndependentBeamFigure {
        case: BeamCase::SmallLoad,
        poisson: 0.3,
        cells_across: 2,
        paper: mm(12.5, 29.0),
        volumetric: mm(3.2, 6.7),
    },
    IndependentBeamFigure {
        case: BeamCase::SmallLoad,
        poisson: 0.3,
        cells_across: 4,
        paper: mm(4.3, 10.1),
        volumetric: mm(1.05, 2.2),
    },
    IndependentBeamFigure {
        case: BeamCase::SmallLoad,
        poisson: 0.3,
        cells_across: 8,
        paper: mm(1.3, 3.0),
        volumetric: mm(0.35, 0.71),
    },
    IndependentBeamFigure {
        case: BeamCase::LargeDeflectionSvk,
        poisson: 0.3,
        cells_across: 4,
        paper: mm(4.4, 10.1),
        volumetric: mm(1.5, 3.0),
    },
];

/// The independent implementation's L-shape figures at a cell edge of
/// 0.25 m (8 cells per 2 m cube).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndependentLShapeFigure {
    /// Cells per 2 m cube of the L.
    pub cells_per_cube: u32,
    /// The paper's model.
    pub paper: MeanMax,
    /// The volumetric variant.
    pub volumetric: MeanMax,
}

/// The independent implementation's L-shape row (docs/model.md).
pub const INDEPENDENT_L: IndependentLShapeFigure = IndependentLShapeFigure {
    cells_per_cube: 8,
    paper: mm(1.2, 6.0),
    volumetric: mm(0.68, 3.4),
};

/// One of the paper's published figures for its own model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperFigure {
    /// Cells across the beam (cantilever `4n x n x n`) or per 2 m cube (L-shape).
    pub cells: u32,
    /// The published error statistics (%).
    pub error: MeanSdMax,
}

const fn paper(cells: u32, mean: f64, sd: f64, max: f64) -> PaperFigure {
    PaperFigure {
        cells,
        error: MeanSdMax { mean, sd, max },
    }
}

/// The paper's Figure 5 (cantilever).
pub const PAPER_BEAM: [PaperFigure; 3] = [
    paper(1, 16.31, 2.83, 38.0),
    paper(2, 7.08, 0.58, 16.7),
    paper(4, 0.68, 0.03, 4.05),
];

/// The paper's Figure 6 (L-shape).
pub const PAPER_L: [PaperFigure; 3] = [
    paper(2, 6.99, 0.94, 18.0),
    paper(4, 3.37, 0.20, 7.0),
    paper(8, 0.66, 0.01, 1.6),
];

/// Mean tip deflection (m) of the linear-regime calibration cantilever
/// (0.4 x 0.1 x 0.1 m, E = 1000 Pa, nu = 0, rho = 0.01 kg/m^3, gravity 9.81,
/// x = 0 clamped) for the paper's model on `4n x n x n` cells, as
/// `(n, deflection)`; checked by the model's tests.
pub const CALIBRATION_TIP_DEFLECTION: [(u32, f64); 5] = [
    (1, 2.6732e-4),
    (2, 3.5060e-4),
    (4, 3.8293e-4),
    (8, 3.9219e-4),
    (16, 3.9459e-4),
];

/// Timoshenko beam theory's tip deflection of the calibration cantilever (m).
pub const CALIBRATION_TIMOSHENKO: f64 = 3.9554e-4;
/// Euler-Bernoulli beam theory's tip deflection of the calibration cantilever (m).
pub const CALIBRATION_EULER_BERNOULLI: f64 = 3.7670e-4;
