//! External loads and damping.
//!
//! A [`Load`] adds forces (N) to an external-force vector at a given time and
//! positions; position-dependent loads also add their Jacobian for the
//! implicit and static solvers. It is the plugin point for user loads. The
//! built-ins are described by [`LoadSpec`] (serde-friendly, for scene files)
//! and resolved against a model by [`LoadSpec::resolve`].

use std::collections::HashMap;
use std::fmt::Debug;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::constraints::{ConstraintError, NodeSelector, check_finite, check_finite3};
use crate::{BlockCsr, Mat3, Model, Vec3};

/// An external load, the plug point for forces from outside the body.
///
/// Contract: [`add_forces`](Self::add_forces) adds (never overwrites) its
/// forces, is deterministic, and does not allocate (it runs every explicit
/// step); a position-dependent load also adds its exact Jacobian in
/// [`add_jacobian`](Self::add_jacobian), which the implicit and static solvers
/// use; a load that stiffens the body says so in
/// [`restrains`](Self::restrains).
///
/// ```
/// use hexmesh::Lattice;
/// use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
/// use mss_core::loads::{Damping, Load};
/// use mss_core::solver::{Problem, State, StaticOptions, solve_static};
/// use mss_core::{Material, Model, PaperModel, Vec3};
///
/// /// A uniform pull along +x on every node (N per node), scaled by the load factor.
/// #[derive(Debug)]
/// struct Wind(f64);
/// impl Load for Wind {
///     fn name(&self) -> String {
///         format!("wind of {} N per node", self.0)
///     }
///     fn add_forces(&self, _m: &Model, _t: f64, _x: &[Vec3], scale: f64, f: &mut [Vec3]) {
///         f.iter_mut().for_each(|fi| fi.x += scale * self.0);
///     }
/// }
///
/// let lattice = Lattice::block([4, 2, 2], 0.05, [0.0; 3]).unwrap();
/// let model = Model::new(&lattice, Material::new(1e4, 0.3, 1000.0).unwrap(), &PaperModel).unwrap();
/// let problem = Problem::from_specs(
///     model,
///     &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
///     &[],
///     Damping::NONE,
/// )
/// .unwrap()
/// .with_load(Box::new(Wind(1e-3)));
/// let mut state = State::at_rest(problem.model());
/// solve_static(&problem, &mut state, &StaticOptions::default()).unwrap();
/// // The free end moved along the wind.
/// let rest = problem.model().rest_positions();
/// assert!((0..rest.len()).all(|n| state.x[n].x >= rest[n].x - 1e-12));
/// assert!(state.x.iter().zip(rest).any(|(x, r)| x.x - r.x > 1e-6));
/// ```
pub trait Load: Send + Sync + Debug {
    /// Short description for logs and error messages.
    fn name(&self) -> String;
    /// Adds this load's nodal forces (N) at time `t` (s) and absolute positions
    /// `x` (m) to `f`. `scale` multiplies the load (the static solver's load
    /// factor; 1 otherwise).
    fn add_forces(&self, model: &Model, t: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]);
    /// Adds `scale * d(force)/dx` to `jac`, whose pattern is
    /// [`BlockCsr::lattice_pattern`] of the model (diagonal always present).
    /// The default is for loads that do not depend on positions.
    fn add_jacobian(&self, model: &Model, t: f64, x: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let _ = (model, t, x, scale, jac);
    }
    /// Whether the load's forces do not depend on positions, so that
    /// [`Load::add_jacobian`] adds nothing: the static solver may then
    /// multiply by the model's tangent without assembling it. The default,
    /// `false`, keeps any load that overrides `add_jacobian` right.
    fn independent_of_positions(&self) -> bool {
        false
    }
    /// Whether the load stiffens the structure (like a drag spring): a static
    /// problem held only by such loads is not a mechanism.
    fn restrains(&self) -> bool {
        false
    }
}

/// A load of one body of a [`Model::union`]: `inner` was built for the
/// body's own model, whose nodes are `nodes` of the union.
#[derive(Debug)]
pub struct OnBody {
    body: std::sync::Arc<Model>,
    nodes: std::ops::Range<usize>,
    inner: Box<dyn Load>,
    /// The body's matrix pattern, for the inner load's derivative (made on
    /// first use, for loads that have one).
    pattern: std::sync::OnceLock<BlockCsr>,
}

impl OnBody {
    /// `inner`, built for the body model `body`, acting on the union's
    /// nodes `nodes` (as many as `body` has).
    pub fn new(
        body: std::sync::Arc<Model>,
        nodes: std::ops::Range<usize>,
        inner: Box<dyn Load>,
    ) -> Self {
        debug_assert_eq!(body.num_nodes(), nodes.len());
        Self {
            body,
            nodes,
            inner,
            pattern: std::sync::OnceLock::new(),
        }
    }
}

impl Load for OnBody {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn independent_of_positions(&self) -> bool {
        self.inner.independent_of_positions()
    }
    fn add_forces(&self, _model: &Model, t: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        let r = self.nodes.clone();
        self.inner
            .add_forces(&self.body, t, &x[r.clone()], scale, &mut f[r]);
    }
    fn add_jacobian(&self, _model: &Model, t: f64, x: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let pattern = self
            .pattern
            .get_or_init(|| BlockCsr::lattice_pattern(self.body.num_nodes(), self.body.cells()));
        let mut local = pattern.clone();
        self.inner
            .add_jacobian(&self.body, t, &x[self.nodes.clone()], scale, &mut local);
        let shift = self.nodes.start;
        for row in 0..local.num_rows() {
            for k in local.row_offsets[row] as usize..local.row_offsets[row + 1] as usize {
                let block = local.blocks[k];
                if block != Mat3::zeros() {
                    jac.add(row + shift, local.col_indices[k] as usize + shift, &block);
                }
            }
        }
    }
    fn restrains(&self) -> bool {
        self.inner.restrains()
    }
}

/// How a force given on a selection of nodes is shared among them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ForceDistribution {
    /// The force is the total, split equally over the selected nodes.
    #[default]
    Total,
    /// Every selected node gets the full force.
    PerNode,
}

/// The built-in loads, as written in scene files.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LoadSpec {
    /// Uniform gravitational acceleration (m/s^2): force `m_i g` on every node.
    Gravity {
        /// Acceleration vector, e.g. `[0, 0, -9.81]`.
        g: [f64; 3],
    },
    /// A constant force (N) on the selected nodes.
    Force {
        /// Which nodes.
        select: NodeSelector,
        /// Force vector (N).
        force: [f64; 3],
        /// Total (default) or per node.
        #[serde(default)]
        distribution: ForceDistribution,
    },
    /// A uniform traction (Pa, force per rest area) on the boundary faces whose
    /// rest centre lies in a box (inclusive, tolerance 1e-9 h). Each face gives
    /// `traction * h^2 / 4` to each of its 4 nodes: for a bilinear face under a
    /// uniform traction this is the consistent nodal load. The force does not
    /// follow the face as it rotates (a dead load).
    Traction {
        /// Box minimum corner (m).
        min: [f64; 3],
        /// Box maximum corner (m).
        max: [f64; 3],
        /// Traction vector (Pa).
        traction: [f64; 3],
    },
    /// A drag spring: each selected node `i` is pulled by a zero-length spring
    /// of stiffness `stiffness / n` (n the number of selected nodes) toward
    /// `X_i + (target - c)`, where `X_i` is its rest position and `c` the rest
    /// centroid of the selection. The selection as a whole is pulled toward
    /// `target` with total stiffness `stiffness`, without being collapsed.
    Drag {
        /// Which nodes.
        select: NodeSelector,
        /// Target of the selection's centroid (m).
        target: [f64; 3],
        /// Total stiffness (N/m).
        stiffness: f64,
    },
}

/// Why a load was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LoadError {
    /// The selection is invalid or empty.
    #[error("load {load}: {source}")]
    Selection {
        /// Which load.
        load: String,
        /// What is wrong.
        source: ConstraintError,
    },
    /// A parameter is invalid.
    #[error("load {load}: {message}")]
    Invalid {
        /// Which load.
        load: String,
        /// What is wrong and what to do.
        message: String,
    },
}

impl LoadSpec {
    fn kind(&self) -> &'static str {
        match self {
            LoadSpec::Gravity { .. } => "gravity",
            LoadSpec::Force { .. } => "force",
            LoadSpec::Traction { .. } => "traction",
            LoadSpec::Drag { .. } => "drag",
        }
    }

    /// Builds the load for `model`, checking numbers and selections.
    pub fn resolve(&self, model: &Model) -> Result<Box<dyn Load>, LoadError> {
        let kind = self.kind();
        let sel_err = |source| LoadError::Selection {
            load: kind.to_string(),
            source,
        };
        let rest = model.rest_positions();
        let h = model.h();
        match self {
            LoadSpec::Gravity { g } => {
                check_finite3("gravity", g).map_err(sel_err)?;
                Ok(Box::new(Gravity { g: Vec3::from(*g) }))
            }
            LoadSpec::Force {
                select,
                force,
                distribution,
            } => {
                check_finite3("force", force).map_err(sel_err)?;
                let nodes = select.select_checked(rest, h).map_err(sel_err)?;
                let per_node = match distribution {
                    ForceDistribution::Total => Vec3::from(*force) / nodes.len() as f64,
                    ForceDistribution::PerNode => Vec3::from(*force),
                };
                Ok(Box::new(NodalForce { nodes, per_node }))
            }
            LoadSpec::Traction { min, max, traction } => {
                check_finite3("traction", traction).map_err(sel_err)?;
                check_finite3("box min", min).map_err(sel_err)?;
                check_finite3("box max", max).map_err(sel_err)?;
                let tol = 1e-9 * h;
                let faces: Vec<[u32; 4]> = boundary_faces(model.cells())
                    .into_iter()
                    .filter(|f| {
                        let c = f.iter().map(|&n| rest[n as usize]).sum::<Vec3>() / 4.0;
                        (0..3).all(|k| c[k] >= min[k] - tol && c[k] <= max[k] + tol)
                    })
                    .collect();
                if faces.is_empty() {
                    return Err(LoadError::Invalid {
                        load: kind.into(),
                        message: format!(
                            "no boundary face has its centre in the box {min:?}..{max:?}; widen the box so that it contains the centres of the faces to load"
                        ),
                    });
                }
                Ok(Box::new(Traction {
                    faces,
                    nodal: Vec3::from(*traction) * (h * h / 4.0),
                }))
            }
            LoadSpec::Drag {
                select,
                target,
                stiffness,
            } => {
                check_finite3("drag target", target).map_err(sel_err)?;
                check_finite("drag stiffness", *stiffness).map_err(sel_err)?;
                if *stiffness < 0.0 {
                    return Err(LoadError::Invalid {
                        load: kind.into(),
                        message: format!(
                            "stiffness {stiffness} N/m is negative; give a positive stiffness"
                        ),
                    });
                }
                let nodes = select.select_checked(rest, h).map_err(sel_err)?;
                let c = nodes.iter().map(|&n| rest[n as usize]).sum::<Vec3>() / nodes.len() as f64;
                Ok(Box::new(Drag {
                    offset: Vec3::from(*target) - c,
                    k: stiffness / nodes.len() as f64,
                    nodes,
                }))
            }
        }
    }
}

/// The cell faces that belong to one cell only, as 4 node indices
/// (counter-clockwise from outside).
pub fn boundary_faces(cells: &[[u32; 8]]) -> Vec<[u32; 4]> {
    let mut count: HashMap<[u32; 4], (u32, [u32; 4])> = HashMap::new();
    for cell in cells {
        for corners in hexmesh::CELL_FACES {
            let f = corners.map(|k| cell[k]);
            let mut key = f;
            key.sort_unstable();
            count.entry(key).or_insert((0, f)).0 += 1;
        }
    }
    let mut out: Vec<[u32; 4]> = count
        .into_values()
        .filter(|(c, _)| *c == 1)
        .map(|(_, f)| f)
        .collect();
    // HashMap order is random: sort for reproducible force summation.
    out.sort_unstable();
    out
}

/// Gravity: `m_i g` on every node.
#[derive(Debug, Clone)]
pub struct Gravity {
    /// Acceleration (m/s^2).
    pub g: Vec3,
}

impl Load for Gravity {
    fn name(&self) -> String {
        format!("gravity {:?}", self.g.as_slice())
    }
    fn independent_of_positions(&self) -> bool {
        true
    }
    fn add_forces(&self, model: &Model, _t: f64, _x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        let g = self.g * scale;
        for (fi, &m) in f.iter_mut().zip(model.masses()) {
            *fi += g * m;
        }
    }
}

/// The same force on each of a set of nodes.
#[derive(Debug, Clone)]
pub struct NodalForce {
    /// The nodes.
    pub nodes: Vec<u32>,
    /// Force on each (N).
    pub per_node: Vec3,
}

impl Load for NodalForce {
    fn name(&self) -> String {
        format!("force on {} nodes", self.nodes.len())
    }
    fn independent_of_positions(&self) -> bool {
        true
    }
    fn add_forces(&self, _model: &Model, _t: f64, _x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        for &n in &self.nodes {
            f[n as usize] += self.per_node * scale;
        }
    }
}

/// Uniform dead traction on boundary faces.
#[derive(Debug, Clone)]
pub struct Traction {
    /// Loaded faces.
    pub faces: Vec<[u32; 4]>,
    /// Force per face node (traction times h^2 / 4) (N).
    pub nodal: Vec3,
}

impl Load for Traction {
    fn name(&self) -> String {
        format!("traction on {} faces", self.faces.len())
    }
    fn independent_of_positions(&self) -> bool {
        true
    }
    fn add_forces(&self, _model: &Model, _t: f64, _x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        for face in &self.faces {
            for &n in face {
                f[n as usize] += self.nodal * scale;
            }
        }
    }
}

/// Zero-length springs pulling nodes toward their rest position shifted by
/// `offset`.
#[derive(Debug, Clone)]
pub struct Drag {
    /// The dragged nodes.
    pub nodes: Vec<u32>,
    /// Shift of the anchors from the rest positions (m).
    pub offset: Vec3,
    /// Stiffness of each node's spring (N/m).
    pub k: f64,
}

impl Load for Drag {
    fn name(&self) -> String {
        format!("drag of {} nodes", self.nodes.len())
    }
    fn add_forces(&self, model: &Model, _t: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        let rest = model.rest_positions();
        for &n in &self.nodes {
            let n = n as usize;
            f[n] += (rest[n] + self.offset - x[n]) * (self.k * scale);
        }
    }
    fn add_jacobian(&self, _model: &Model, _t: f64, _x: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let block = Mat3::identity() * (-self.k * scale);
        for &n in &self.nodes {
            jac.add(n as usize, n as usize, &block);
        }
    }
    fn restrains(&self) -> bool {
        self.k > 0.0
    }
}

/// Rayleigh-type damping: force `-alpha m_i v_i - beta K0 v`.
///
/// `K0` is the stiffness at rest (minus the internal-force Jacobian at the rest
/// positions): constant and symmetric, so it is cheap in explicit steps and
/// keeps the implicit Jacobian simple. Being the rest stiffness, it does not
/// rotate with the body: after a large rotation, beta damping also resists
/// rigid rotation somewhat. Use alpha for bodies that rotate a lot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Damping {
    /// Mass-proportional coefficient (1/s).
    #[serde(default)]
    pub alpha: f64,
    /// Stiffness-proportional coefficient (s).
    #[serde(default)]
    pub beta: f64,
}

impl Damping {
    /// No damping.
    pub const NONE: Damping = Damping {
        alpha: 0.0,
        beta: 0.0,
    };

    /// Checks that both coefficients are finite and non-negative.
    pub fn validate(&self) -> Result<(), LoadError> {
        for (name, v) in [("alpha", self.alpha), ("beta", self.beta)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(LoadError::Invalid {
                    load: "damping".into(),
                    message: format!(
                        "{name} = {v} must be a finite number >= 0 (0 for no damping)"
                    ),
                });
            }
        }
        Ok(())
    }
}
