//! Interactive stepping: a [`Simulation`] owns a problem and its state and
//! advances them frame by frame, with a drag on picked nodes and obstacles
//! moved by hand ([`Steered`](crate::contact::Steered)), for viewers and games.
//!
//! Each [`Simulation::step`] advances by the frame time it is given with the
//! explicit integrator, in as many sub-steps as stability asks (so a frame
//! of 1/60 s may take several). A pick holds nodes by zero-length springs to
//! points that keep their offsets from the picked nodes' centroid, so the
//! grab is rigid; [`Simulation::drag_to`] moves the centroid's target.
//!
//! ```
//! use mss_core::contact::{Contact, ContactSettings, Plane, Steered};
//! use mss_core::simulation::Simulation;
//! use mss_core::solver::Problem;
//! use mss_core::{Material, Model, Vec3, Volumetric};
//!
//! let lattice = hexmesh::Lattice::block([4, 4, 2], 0.025, [0.0; 3]).unwrap();
//! let model = Model::new(&lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &Volumetric).unwrap();
//! let (ground, _handle) = Steered::new(Box::new(Plane::new(Vec3::zeros(), Vec3::z()).unwrap()));
//! let settings = ContactSettings::for_model(&model);
//! let contact = Contact::new(&model, vec![(Box::new(ground), settings)]);
//! let mut sim = Simulation::new(Problem::new(model).with_contact(contact)).unwrap();
//! let corner = sim.nearest_node(Vec3::new(0.1, 0.1, 0.05));
//! sim.pick(&[corner], 50.0).unwrap();
//! sim.drag_to(Vec3::new(0.1, 0.1, 0.08));
//! for _ in 0..10 {
//!     sim.step(1.0 / 60.0).unwrap();
//! }
//! assert!(sim.positions()[corner as usize].z > 0.05);
//! sim.release();
//! ```

use std::sync::{Arc, RwLock};

use crate::loads::Load;
use crate::solver::{
    Explicit, ExplicitOptions, Integrator, Problem, SettleInfo, SettleOptions, SolverError, State,
    StepInfo, settle,
};
use crate::{BlockCsr, Mat3, Model, Precision, Vec3};

/// What a pick holds: nodes, their offsets from the target, the stiffness.
#[derive(Debug, Clone, Default)]
struct Grab {
    nodes: Vec<u32>,
    offsets: Vec<Vec3>,
    target: Vec3,
    stiffness: f64,
}

/// The load of the picks: reads the grab shared with the [`Simulation`].
#[derive(Debug)]
struct PickLoad(Arc<RwLock<Option<Grab>>>);

impl Load for PickLoad {
    fn name(&self) -> String {
        "drag of picked nodes".into()
    }
    fn add_forces(&self, _model: &Model, _t: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        let guard = self.0.read().unwrap_or_else(|e| e.into_inner());
        if let Some(g) = guard.as_ref() {
            for (&n, o) in g.nodes.iter().zip(&g.offsets) {
                let n = n as usize;
                f[n] += (g.target + o - x[n]) * (g.stiffness * scale);
            }
        }
    }
    fn add_jacobian(&self, _model: &Model, _t: f64, _x: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let guard = self.0.read().unwrap_or_else(|e| e.into_inner());
        if let Some(g) = guard.as_ref() {
            let block = Mat3::identity() * (-g.stiffness * scale);
            for &n in &g.nodes {
                jac.add(n as usize, n as usize, &block);
            }
        }
    }
}

/// A problem being stepped interactively.
pub struct Simulation {
    problem: Problem,
    state: State,
    integrator: Option<Explicit>,
    grab: Arc<RwLock<Option<Grab>>>,
    precision: Precision,
}

impl std::fmt::Debug for Simulation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulation")
            .field("nodes", &self.state.x.len())
            .field("time", &self.state.time)
            .finish()
    }
}

/// Why a pick was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PickError {
    /// No node given, or one that does not exist.
    #[error("pick {given:?}: give at least one node index below {nodes}")]
    Nodes {
        /// The nodes given.
        given: Vec<u32>,
        /// Nodes of the model.
        nodes: usize,
    },
    /// The stiffness is not a positive number.
    #[error("drag stiffness {0} must be a positive number (N/m)")]
    Stiffness(f64),
}

impl Simulation {
    /// A simulation of `problem` from rest (held nodes prescribed at t = 0).
    pub fn new(problem: Problem) -> Result<Self, SolverError> {
        let grab = Arc::new(RwLock::new(None));
        let problem = problem.with_load(Box::new(PickLoad(Arc::clone(&grab))));
        let mut state = State::at_rest(problem.model());
        problem.apply_constraints(&mut state);
        Ok(Self {
            problem,
            state,
            integrator: None,
            grab,
            precision: Precision::F64,
        })
    }

    /// Advances by `dt` seconds (a frame), in as many explicit sub-steps as
    /// stability asks. On error the state is the last good one.
    pub fn step(&mut self, dt: f64) -> Result<StepInfo, SolverError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SolverError::BadTimeStep(dt));
        }
        let reuse = self.integrator.as_ref().is_some_and(|i| i.dt() == dt);
        if !reuse {
            self.integrator = Some(Explicit::new(
                &self.problem,
                ExplicitOptions {
                    dt: Some(dt),
                    substep: true,
                    precision: self.precision,
                    ..ExplicitOptions::default()
                },
            )?);
        }
        let integrator = self
            .integrator
            .as_mut()
            .ok_or(SolverError::BadTimeStep(dt))?;
        integrator.step(&self.problem, &mut self.state)
    }

    /// Brings the state to rest under the loads at its time, contact and
    /// friction included ([`settle`], with the
    /// explicit scheme at its stable step), so that the frames that follow
    /// start from equilibrium (a scene's `[solver] start = "settled"`). On
    /// error the state is where the settling got to.
    pub fn settle(&mut self, opts: &SettleOptions) -> Result<SettleInfo, SolverError> {
        let mut integrator = Explicit::new(
            &self.problem,
            ExplicitOptions {
                precision: self.precision,
                ..ExplicitOptions::default()
            },
        )?;
        // The frame integrator's cached forces are of the state before.
        self.integrator = None;
        settle(&self.problem, &mut integrator, &mut self.state, opts)
    }

    /// Runs the internal force pass in `precision` from the next step on
    /// ([`Precision::F32`] for interactive rates; the default is `F64`).
    pub fn set_precision(&mut self, precision: Precision) {
        if precision != self.precision {
            self.precision = precision;
            self.integrator = None;
        }
    }

    /// The precision of the internal force pass.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// Holds `nodes` by springs of `stiffness` (N/m each) at their current
    /// places; [`drag_to`](Self::drag_to) then moves them. Replaces an
    /// earlier pick.
    pub fn pick(&mut self, nodes: &[u32], stiffness: f64) -> Result<(), PickError> {
        let n = self.state.x.len();
        if nodes.is_empty() || nodes.iter().any(|&i| i as usize >= n) {
            return Err(PickError::Nodes {
                given: nodes.to_vec(),
                nodes: n,
            });
        }
        if !(stiffness.is_finite() && stiffness > 0.0) {
            return Err(PickError::Stiffness(stiffness));
        }
        let points: Vec<Vec3> = nodes.iter().map(|&i| self.state.x[i as usize]).collect();
        let centre = points.iter().sum::<Vec3>() / points.len() as f64;
        let grab = Grab {
            nodes: nodes.to_vec(),
            offsets: points.iter().map(|p| p - centre).collect(),
            target: centre,
            stiffness,
        };
        *self.grab.write().unwrap_or_else(|e| e.into_inner()) = Some(grab);
        Ok(())
    }

    /// Moves the target of the picked nodes' centroid (m); nothing without a pick.
    pub fn drag_to(&mut self, target: Vec3) {
        if let Some(g) = self
            .grab
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .as_mut()
        {
            g.target = target;
        }
    }

    /// The nodes a pick holds (empty without a pick).
    pub fn grabbed_nodes(&self) -> Vec<u32> {
        self.grab
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
            .map_or_else(Vec::new, |g| g.nodes.clone())
    }

    /// Lets the picked nodes go.
    pub fn release(&mut self) {
        *self.grab.write().unwrap_or_else(|e| e.into_inner()) = None;
    }

    /// The node nearest to `p` (to pick under a cursor).
    pub fn nearest_node(&self, p: Vec3) -> u32 {
        self.state
            .x
            .iter()
            .enumerate()
            .min_by(|a, b| {
                (a.1 - p)
                    .norm_squared()
                    .total_cmp(&(b.1 - p).norm_squared())
            })
            .map_or(0, |(i, _)| i as u32)
    }

    /// Current node positions (m).
    pub fn positions(&self) -> &[Vec3] {
        &self.state.x
    }

    /// The full state (positions, velocities, time, contact anchors).
    pub fn state(&self) -> &State {
        &self.state
    }

    /// The problem being stepped (with the pick's load added last).
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// Positions of an embedded surface's vertices at the current state.
    pub fn surface(&self, embedding: &hexmesh::Embedding) -> Vec<[f64; 3]> {
        let nodes: Vec<[f64; 3]> = self.state.x.iter().map(|p| [p.x, p.y, p.z]).collect();
        embedding.deform(&nodes)
    }
}
