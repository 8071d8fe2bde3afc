//! Solvers: explicit time stepping (velocity Verlet, symplectic Euler),
//! implicit backward Euler, and static equilibrium.
//!
//! A [`Problem`] bundles a [`Model`] with its boundary conditions, loads and
//! damping; a [`State`] holds positions, velocities and time. Time integrators
//! implement the [`Integrator`] plugin trait, registered by name in an
//! [`Integrators`] value; [`solve_static`] finds equilibrium.
//!
//! Every solver checks for divergence (non-finite values, exploding motion,
//! inverted cells, Newton failure) and then returns a typed [`SolverError`]
//! that names the step and time and says what to try; the state is then left
//! at the last good step, never overwritten with garbage.
//!
//! ```
//! use hexmesh::Lattice;
//! use mss_core::constraints::{ConstraintSpec, NodeSelector, Face};
//! use mss_core::loads::{Damping, LoadSpec};
//! use mss_core::model::PaperModel;
//! use mss_core::solver::{Problem, State, solve_static, StaticOptions};
//! use mss_core::{Material, Model};
//!
//! let lattice = Lattice::block([8, 2, 2], 0.05, [0.0; 3]).unwrap();
//! let model = Model::new(&lattice, Material::new(1000.0, 0.3, 0.01).unwrap(), &PaperModel).unwrap();
//! let problem = Problem::from_specs(
//!     model,
//!     &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
//!     &[LoadSpec::Gravity { g: [0.0, 0.0, -9.81] }],
//!     Damping::NONE,
//! ).unwrap();
//! let mut state = State::at_rest(problem.model());
//! solve_static(&problem, &mut state, &StaticOptions::default()).unwrap();
//! assert!(state.x.iter().map(|p| p.z).fold(0.0, f64::min) < 0.0);
//! ```

mod explicit;
mod implicit;
mod linear;
pub(crate) mod multigrid;
mod settle;
mod statics;

use std::sync::OnceLock;

use thiserror::Error;

pub use explicit::{
    CONTACT_RESOLUTION, Explicit, ExplicitOptions, ExplicitScheme, NODE_CONTACT_ANGLE,
    explicit_time_step_limit,
};
pub use implicit::{IMPLICIT_MATRIX_FREE_ABOVE, Implicit, ImplicitOptions};
pub use linear::{DIRECT_MAX_FREE_DOFS, LinearSolver, LinearSolverKind, LinearStats};
pub use settle::{SettleInfo, SettleOptions, settle, settle_cancellable};
pub use statics::{
    FOLLOW_DEPTH, MATRIX_FREE_ABOVE, MAX_FAILED_INCREMENTS, OBSTACLE_INCREMENT,
    STABILITY_TEST_MAX_FACTOR_BYTES, Stability, StaticInfo, StaticOptions, solve_static,
    solve_static_cancellable,
};

use crate::constraints::{ConstraintError, ConstraintSpec, Constraints};
use crate::contact::Contact;
use crate::loads::{Damping, Load, LoadError, LoadSpec};
use crate::{BlockCsr, Model, Precision, Vec3};

/// Why a problem could not be assembled.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ProblemError {
    /// A boundary condition is invalid.
    #[error("boundary condition {index}: {source}")]
    Constraint {
        /// Position of the constraint in the list given.
        index: usize,
        /// What is wrong.
        source: ConstraintError,
    },
    /// A load is invalid.
    #[error("load {index}: {source}")]
    Load {
        /// Position of the load in the list given.
        index: usize,
        /// What is wrong.
        source: LoadError,
    },
    /// Damping coefficients are invalid.
    #[error(transparent)]
    Damping(LoadError),
    /// The bodies do not make one model.
    #[error(transparent)]
    Model(crate::ModelError),
    /// Constraints made for another model.
    #[error("constraints cover {given} nodes but the model has {expected}")]
    ConstraintSize {
        /// Nodes the constraints cover.
        given: usize,
        /// Nodes of the model.
        expected: usize,
    },
}

/// A model with its boundary conditions, loads and damping.
#[derive(Debug)]
pub struct Problem {
    model: Model,
    constraints: Constraints,
    loads: Vec<Box<dyn Load>>,
    contact: Option<Contact>,
    damping: Damping,
    rest_stiffness: OnceLock<BlockCsr>,
}

impl Problem {
    /// The model alone: free, unloaded, undamped.
    pub fn new(model: Model) -> Self {
        let constraints = Constraints::none(model.num_nodes());
        Self {
            model,
            constraints,
            loads: Vec::new(),
            contact: None,
            damping: Damping::NONE,
            rest_stiffness: OnceLock::new(),
        }
    }

    /// Builds a problem from user-facing descriptions (scene files): every
    /// selector must select at least one node.
    pub fn from_specs(
        model: Model,
        constraints: &[ConstraintSpec],
        loads: &[LoadSpec],
        damping: Damping,
    ) -> Result<Self, ProblemError> {
        let mut c = Constraints::none(model.num_nodes());
        for (index, spec) in constraints.iter().enumerate() {
            let nodes = spec
                .select
                .select_checked(model.rest_positions(), model.h())
                .map_err(|source| ProblemError::Constraint { index, source })?;
            c.hold(&nodes, spec.dofs, spec.motion.clone())
                .map_err(|source| ProblemError::Constraint { index, source })?;
        }
        let mut built = Vec::with_capacity(loads.len());
        for (index, spec) in loads.iter().enumerate() {
            built.push(
                spec.resolve(&model)
                    .map_err(|source| ProblemError::Load { index, source })?,
            );
        }
        let mut p = Self::new(model).with_constraints(c)?;
        p.loads = built;
        p.set_damping(damping)?;
        Ok(p)
    }

    /// The problems of several bodies stepped together: the model is the
    /// [`Model::union`] of theirs, each body keeps its constraints and loads
    /// (on its own nodes). Contact is the union's to add
    /// ([`Problem::with_contact`], with [`crate::contact::BodyContact`]); a
    /// part's own contact is dropped. Damping is scene-wide: the first
    /// part's.
    pub fn union(parts: Vec<Problem>) -> Result<Self, ProblemError> {
        let models: Vec<Model> = parts.iter().map(|p| p.model.clone()).collect();
        let model = Model::union(&models).map_err(ProblemError::Model)?;
        let constraints = Constraints::union(
            &parts
                .iter()
                .map(|p| p.constraints.clone())
                .collect::<Vec<_>>(),
        );
        let damping = parts.first().map_or(Damping::NONE, |p| p.damping);
        let mut loads: Vec<Box<dyn Load>> = Vec::new();
        let mut start = 0;
        for part in parts {
            let nodes = start..start + part.model.num_nodes();
            start = nodes.end;
            if part.loads.is_empty() {
                continue;
            }
            let body = std::sync::Arc::new(part.model);
            for load in part.loads {
                loads.push(Box::new(crate::loads::OnBody::new(
                    body.clone(),
                    nodes.clone(),
                    load,
                )));
            }
        }
        let mut p = Self::new(model).with_constraints(constraints)?;
        p.loads = loads;
        p.set_damping(damping)?;
        Ok(p)
    }

    /// Replaces the constraints.
    pub fn with_constraints(mut self, constraints: Constraints) -> Result<Self, ProblemError> {
        if constraints.num_nodes() != self.model.num_nodes() {
            return Err(ProblemError::ConstraintSize {
                given: constraints.num_nodes(),
                expected: self.model.num_nodes(),
            });
        }
        self.constraints = constraints;
        Ok(self)
    }

    /// Adds a load (built-in or user-defined).
    pub fn with_load(mut self, load: Box<dyn Load>) -> Self {
        self.loads.push(load);
        self
    }

    /// Adds contact with obstacles ([`crate::contact`]).
    pub fn with_contact(mut self, contact: Contact) -> Self {
        self.contact = Some(contact);
        self
    }

    /// Adds contact between the model's bodies (or of a body with
    /// itself) to the contact with obstacles, if any.
    pub fn with_body_contact(mut self, bodies: crate::contact::BodyContact) -> Self {
        let contact = self
            .contact
            .take()
            .unwrap_or_else(|| Contact::new(&self.model, Vec::new()));
        self.contact = Some(contact.with_bodies(bodies));
        self
    }

    /// The contact with obstacles, if any.
    pub fn contact(&self) -> Option<&Contact> {
        self.contact.as_ref()
    }

    /// Contact forces at `state` (N per node; zero without obstacles).
    pub fn contact_forces(&self, state: &State) -> Vec<Vec3> {
        match &self.contact {
            Some(c) => c.forces(state.time, &state.x, &state.v, &state.contact),
            None => vec![Vec3::zeros(); state.x.len()],
        }
    }

    /// Updates the friction anchors of `state` after a step (see
    /// [`Contact::update_anchors`]); nothing without obstacles.
    pub fn update_contact(&self, state: &mut State) {
        if let Some(c) = &self.contact {
            c.update_anchors(state.time, &state.x, &state.v, &mut state.contact);
        }
    }

    /// Sets the damping.
    pub fn with_damping(mut self, damping: Damping) -> Result<Self, ProblemError> {
        self.set_damping(damping)?;
        Ok(self)
    }

    fn set_damping(&mut self, damping: Damping) -> Result<(), ProblemError> {
        damping.validate().map_err(ProblemError::Damping)?;
        self.damping = damping;
        Ok(())
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// The resolved boundary conditions.
    pub fn constraints(&self) -> &Constraints {
        &self.constraints
    }
    /// The loads.
    pub fn loads(&self) -> &[Box<dyn Load>] {
        &self.loads
    }
    /// The damping.
    pub fn damping(&self) -> Damping {
        self.damping
    }

    /// The rest stiffness `K0` used by stiffness-proportional damping
    /// (computed on first use).
    pub fn rest_stiffness(&self) -> &BlockCsr {
        self.rest_stiffness
            .get_or_init(|| self.model.rest_stiffness())
    }

    /// External forces (N) at time `t` and positions `x`, times `scale`,
    /// written to `out` (not allocating if the loads do not).
    pub fn external_forces(&self, t: f64, x: &[Vec3], scale: f64, out: &mut [Vec3]) {
        out.iter_mut().for_each(|f| *f = Vec3::zeros());
        for l in &self.loads {
            l.add_forces(&self.model, t, x, scale, out);
        }
    }

    /// Whether some load restrains motion (a drag spring).
    fn has_restraining_load(&self) -> bool {
        self.loads.iter().any(|l| l.restrains())
    }

    /// The free-dof mask `free[3 n + d]`.
    fn free_mask(&self) -> Vec<bool> {
        (0..3 * self.model.num_nodes())
            .map(|i| !self.constraints.is_held(i / 3, i % 3))
            .collect()
    }

    /// Diameter of the rest bounding box (m).
    fn size(&self) -> f64 {
        let rest = self.model.rest_positions();
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in rest {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (hi - lo).norm().max(self.model.h())
    }

    /// Sets the held components of `state` to their prescribed values at
    /// `state.time` (fixed ones keep their position and get zero velocity).
    pub fn apply_constraints(&self, state: &mut State) {
        let rest = self.model.rest_positions();
        self.constraints
            .prescribe_all(state.time, 0.0, rest, &mut state.x, &mut state.v);
    }
}

/// Positions (m), velocities (m/s) and time (s) of every node.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Absolute positions.
    pub x: Vec<Vec3>,
    /// Velocities.
    pub v: Vec<Vec3>,
    /// Time.
    pub time: f64,
    /// Friction anchors of the contacts, one per contact node and obstacle
    /// ([`Contact::update_anchors`]; `None`: not touching; empty without
    /// obstacles).
    pub contact: Vec<Option<Vec3>>,
}

impl State {
    /// The rest configuration at time 0, with zero velocity.
    pub fn at_rest(model: &Model) -> Self {
        Self {
            x: model.rest_positions().to_vec(),
            v: vec![Vec3::zeros(); model.num_nodes()],
            time: 0.0,
            contact: Vec::new(),
        }
    }

    /// Kinetic energy `sum m v^2 / 2` (J), summed in node order.
    pub fn kinetic_energy(&self, masses: &[f64]) -> f64 {
        self.v
            .iter()
            .zip(masses)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum()
    }

    /// Linear momentum `sum m v` (kg m/s).
    pub fn momentum(&self, masses: &[f64]) -> Vec3 {
        self.v.iter().zip(masses).map(|(v, m)| v * *m).sum()
    }

    /// Displacements from the model's rest positions (m).
    pub fn displacements(&self, model: &Model) -> Vec<Vec3> {
        self.x
            .iter()
            .zip(model.rest_positions())
            .map(|(x, r)| x - r)
            .collect()
    }

    fn check_size(&self, model: &Model) -> Result<(), SolverError> {
        if self.x.len() != model.num_nodes() || self.v.len() != model.num_nodes() {
            return Err(SolverError::StateSize {
                positions: self.x.len(),
                velocities: self.v.len(),
                nodes: model.num_nodes(),
            });
        }
        Ok(())
    }
}

/// What one call to [`Integrator::step`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// Time reached (s).
    pub time: f64,
    /// Time advanced (s).
    pub dt: f64,
    /// Sub-steps taken (1 unless sub-stepping or step halving happened).
    pub substeps: u32,
    /// Newton iterations in total (0 for explicit schemes).
    pub newton_iterations: u32,
}

/// How a run diverged.
#[derive(Debug, Clone, PartialEq)]
pub enum Divergence {
    /// A position or velocity became NaN or infinite.
    NonFinite,
    /// Cells turned inside out (`det F <= 0`).
    InvertedCells {
        /// How many.
        count: usize,
        /// The first few.
        first: Vec<u32>,
    },
    /// A cell deformed by more than a quarter of its size in one step: the
    /// motion explodes.
    Explosion {
        /// The cell.
        cell: u32,
        /// Relative deformation in one step.
        strain_per_step: f64,
    },
    /// Newton's method did not converge.
    NewtonFailed {
        /// Iterations done.
        iterations: u32,
        /// Residual reached (N).
        residual: f64,
        /// Residual needed (N).
        target: f64,
    },
    /// The tangent stiffness became singular in a deformed state, while it
    /// is regular at rest: the structure buckles, snaps through or collapses
    /// under the load (not a mechanism of the boundary conditions).
    SingularUnderLoad {
        /// Load factor (0..1) of the last equilibrium found.
        load_factor: f64,
        /// Nodes that move most in the singular direction.
        nodes: Vec<u32>,
    },
}

impl std::fmt::Display for Divergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Divergence::NonFinite => write!(f, "positions or velocities became NaN or infinite"),
            Divergence::InvertedCells { count, first } => {
                write!(f, "{count} cells turned inside out (first: {first:?})")
            }
            Divergence::Explosion {
                cell,
                strain_per_step,
            } => write!(
                f,
                "cell {cell} deformed by {:.0}% of its size in one step (exploding motion)",
                strain_per_step * 100.0
            ),
            Divergence::NewtonFailed {
                iterations,
                residual,
                target,
            } => write!(
                f,
                "Newton's method did not converge in {iterations} iterations (residual {residual:.3e} N, needed {target:.3e} N)"
            ),
            Divergence::SingularUnderLoad { load_factor, nodes } => write!(
                f,
                "the stiffness became singular under load beyond {:.1}% of it (the body buckles or collapses there; at rest it is held well, so this is not a mechanism of the boundary conditions; nodes that move most: {nodes:?})",
                100.0 * load_factor
            ),
        }
    }
}

/// Why a solver stopped.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SolverError {
    /// The explicit step is above the stability limit.
    #[error(
        "time step {dt:.3e} s is above the explicit stability limit {limit:.3e} s (safety factor times 2/omega_max, reduced by damping); use dt <= {limit:.3e} s, enable sub-stepping, or use the implicit solver"
    )]
    TimeStepTooLarge {
        /// Requested step (s).
        dt: f64,
        /// Largest stable step (s).
        limit: f64,
    },
    /// The time step is not a positive finite number.
    #[error("time step {0} s must be a positive finite number")]
    BadTimeStep(f64),
    /// An option is invalid.
    #[error("invalid solver option: {0}")]
    BadOption(String),
    /// No integrator of that name.
    #[error("unknown integrator \"{name}\"; use one of {known}")]
    UnknownIntegrator {
        /// Name given.
        name: String,
        /// Names accepted, comma-separated.
        known: String,
    },
    /// The state does not fit the model.
    #[error(
        "state has {positions} positions and {velocities} velocities but the model has {nodes} nodes"
    )]
    StateSize {
        /// Positions given.
        positions: usize,
        /// Velocities given.
        velocities: usize,
        /// Nodes of the model.
        nodes: usize,
    },
    /// The run diverged; the state was left at the last good step.
    #[error(
        "the {solver} solver diverged at step {step} (t = {time:.3e} s): {reason}; the state was kept at the last good time t = {kept_time:.3e} s. {hint}"
    )]
    Diverged {
        /// Which solver.
        solver: &'static str,
        /// Step count of the integrator (or load step of the static solver).
        step: u64,
        /// Time (s) the failing step was going to reach.
        time: f64,
        /// What went wrong.
        reason: Divergence,
        /// Time of the state that was kept (s).
        kept_time: f64,
        /// What to try.
        hint: &'static str,
    },
    /// The problem has zero-stiffness motions (rigid motions or hourglass
    /// modes) that the loads can excite: no unique static solution.
    #[error("{message}{}", free_nodes_note(nodes))]
    Mechanism {
        /// Explanation and what to fix.
        message: String,
        /// Nodes the mechanism moves most.
        nodes: Vec<u32>,
    },
    /// The static solve found an equilibrium whose stiffness is not positive
    /// definite: a small disturbance leads away from it (the body buckles,
    /// or the lattice folds), so a dynamic run ends elsewhere. The state is
    /// left at that equilibrium, for inspection.
    /// Front ends add how to keep it anyway in their own terms (a scene's
    /// `[solver] accept_unstable`, Python's `accept_unstable=True`,
    /// [`StaticOptions::accept_unstable`]).
    #[error(
        "the static equilibrium found is unstable: its stiffness (symmetric part, on the free dofs) is not positive definite, so a dynamic run would leave it: {}",
        if *hourglass_control {
            "the body buckles under these loads (its model has hourglass control, so the lattice does not fold); lower the loads, stiffen the material or hold a larger region"
        } else {
            "the lattice folds (a mechanism appears under load: use hourglass control, the \"volumetric-barrier+hg\" model with hourglass 1.0), or the body buckles under these loads"
        }
    )]
    UnstableEquilibrium {
        /// Whether every cell of the model has hourglass control (then the
        /// lattice cannot fold: the body itself buckles).
        hourglass_control: bool,
    },
    /// The static solve carried part of the loads and no more: the
    /// equilibrium path has a limit point (the body buckles or folds under
    /// more load), so there is no static answer near it for the full load.
    #[error(
        "the static solve carried {:.1} % of the loads and no more ({reason}): most likely the equilibrium path ends there (a limit point: the body buckles or folds under more load, and a dynamic run collapses rather than settles; the refined FEM of docs/robustness.md tells the two apart). Lower the loads or stiffen the body (E); if the lattice folds rather than the body, use hourglass control",
        100.0 * load_factor
    )]
    LoadLimit {
        /// The largest load factor reached (0..1).
        load_factor: f64,
        /// Why the next increment failed.
        reason: Divergence,
    },
    /// A static solve was asked to stop ([`solve_static_cancellable`]).
    #[error("the static solve was stopped at {:.1} % of the loads", 100.0 * load_factor)]
    Cancelled {
        /// The load factor reached (0..1).
        load_factor: f64,
    },
    /// The sparse linear solver failed for another reason.
    #[error("linear solver failed: {0}")]
    LinearSolver(String),
    /// A settling ([`settle_cancellable`]) was asked to stop.
    #[error("the settling was stopped after {settle_time:.3e} s of simulated time")]
    SettleCancelled {
        /// The simulated time the settling had taken (s).
        settle_time: f64,
    },
    /// A settled start ([`settle`]) did not come to rest in its time.
    #[error(
        "the bodies did not come to rest in {max_time} s of settling (residual force {relative_residual:.2e} of the loads, {rtol:.0e} asked): a body that slides down a slope steeper than its friction, or falls with nothing below it, has no rest to settle into, so start such a run without settling; a large or soft body may need a longer settle time"
    )]
    NotSettled {
        /// The settle time allowed (s of simulated time).
        max_time: f64,
        /// The residual force over the loads' reached.
        relative_residual: f64,
        /// The residual force over the loads' asked.
        rtol: f64,
    },
}

const EXPLICIT_HINT: &str = "Try a smaller time step, the implicit solver, or more damping.";
const IMPLICIT_HINT: &str = "Try a smaller time step, more damping, or smaller loads (the deformation may be beyond what the lattice can represent).";
const STATIC_HINT: &str =
    "Try more load steps (a scene's [solver] load_steps), a smaller load, or more fixed nodes.";

/// A time-stepping scheme: the plugin point for integrators.
///
/// Contract, which the built-ins keep and every implementation must keep:
/// - [`step`](Self::step) advances `state` by exactly [`dt`](Self::dt) (it may
///   take sub-steps) and sets `state.time` accordingly;
/// - held dofs are the constraints' business, not the forces': update only
///   the components that [`Constraints::mask`] reports free (a held
///   component's velocity and position are never changed by forces), then
///   call [`Problem::apply_constraints`] at the new time, which puts
///   prescribed dofs on their motion and keeps fixed ones at rest velocity;
/// - external forces come from [`Problem::external_forces`], and damping
///   ([`Problem::damping`]) acts as the forces `-alpha m v` and `-beta K0 v`;
/// - it is deterministic: the same inputs give bitwise the same state for
///   any thread count;
/// - on failure it returns a [`SolverError`] and leaves `state` at the last
///   good state (never a NaN).
///
/// ```
/// use hexmesh::Lattice;
/// use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
/// use mss_core::loads::{Damping, LoadSpec};
/// use mss_core::solver::{Integrator, IntegratorSettings, Integrators, Problem, SolverError, State, StepInfo};
/// use mss_core::{Material, Model, PaperModel, Vec3};
///
/// /// Symplectic Euler written from outside, honouring the contract.
/// struct MyEuler {
///     dt: f64,
///     f_int: Vec<Vec3>,
///     f_ext: Vec<Vec3>,
/// }
/// impl Integrator for MyEuler {
///     fn name(&self) -> &'static str {
///         "my-euler"
///     }
///     fn dt(&self) -> f64 {
///         self.dt
///     }
///     fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
///         let model = problem.model();
///         model.internal_forces(&state.x, &mut self.f_int);
///         self.f_ext.iter_mut().for_each(|f| *f = Vec3::zeros());
///         problem.external_forces(state.time, &state.x, 1.0, &mut self.f_ext);
///         let alpha = problem.damping().alpha;
///         for n in 0..model.num_nodes() {
///             let m = model.masses()[n];
///             let a = (self.f_int[n] + self.f_ext[n] - alpha * m * state.v[n]) / m;
///             let free = problem.constraints().mask(n).map(|held| !held);
///             for d in (0..3).filter(|&d| free[d]) {
///                 state.v[n][d] += self.dt * a[d];
///                 state.x[n][d] += self.dt * state.v[n][d];
///             }
///         }
///         state.time += self.dt;
///         problem.apply_constraints(state);
///         Ok(StepInfo { time: state.time, dt: self.dt, substeps: 1, newton_iterations: 0 })
///     }
/// }
///
/// let lattice = Lattice::block([4, 2, 2], 0.05, [0.0; 3]).unwrap();
/// let model = Model::new(&lattice, Material::new(1e4, 0.3, 1000.0).unwrap(), &PaperModel).unwrap();
/// let problem = Problem::from_specs(
///     model,
///     &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
///     &[LoadSpec::Gravity { g: [0.0, 0.0, -9.81] }],
///     Damping::NONE,
/// )
/// .unwrap();
/// let mut known = Integrators::default();
/// known.register(
///     "my-euler",
///     std::sync::Arc::new(|p: &Problem, s: &IntegratorSettings| {
///         let n = p.model().num_nodes();
///         let dt = s.dt.unwrap_or(mss_core::solver::explicit_time_step_limit(p, s.safety));
///         Ok(Box::new(MyEuler { dt, f_int: vec![Vec3::zeros(); n], f_ext: vec![Vec3::zeros(); n] })
///             as Box<dyn Integrator>)
///     }),
/// );
/// let mut it = known.build("my-euler", &problem, &IntegratorSettings::default()).unwrap();
/// let mut state = State::at_rest(problem.model());
/// for _ in 0..10 {
///     it.step(&problem, &mut state).unwrap();
/// }
/// // Held nodes stayed where they were; free ones fell.
/// let rest = problem.model().rest_positions();
/// assert!((0..rest.len()).all(|n| !problem.constraints().is_held(n, 2) || state.x[n] == rest[n]));
/// assert!(state.x.iter().any(|p| p.z < -1e-9));
/// ```
pub trait Integrator: Send {
    /// Short name (the name it is registered under in [`Integrators`]).
    fn name(&self) -> &'static str;
    /// Advances `state` by [`Integrator::dt`]. On error, `state` is left at the
    /// last good state.
    fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError>;
    /// The time advanced by one call to [`Integrator::step`] (s).
    fn dt(&self) -> f64;
    /// Asks that the next [`Integrator::step`] end with every divergence
    /// check the integrator has (an integrator that checks only every few
    /// sub-steps, like [`Explicit`], checks at the end of that step too), so
    /// that the state it returns can be written as a frame. The default does
    /// nothing: an integrator that checks every step needs nothing more.
    fn check_next_step(&mut self) {}
    /// A node array (one entry per node) that the integrator does not need
    /// until its next step, lent as scratch: a frame writer computes the
    /// frame's derived fields into it instead of holding an array of its
    /// own. Its contents are the caller's to overwrite; the integrator
    /// fills it again before it reads it. The default lends nothing.
    fn lend_scratch(&mut self) -> Option<&mut [Vec3]> {
        None
    }
    /// What the integrator carries from one step to the next beyond the
    /// [`State`] (step control, counters, cached forces), for checkpoints.
    /// The default is nothing: right for an integrator whose steps depend
    /// on the state alone.
    fn memory(&self) -> IntegratorMemory {
        IntegratorMemory::default()
    }
    /// Puts back what [`Integrator::memory`] took, into an integrator built
    /// for the same problem with the same settings: the steps that follow
    /// are then bitwise those that followed when the memory was taken. A
    /// memory that does not fit is refused ([`SolverError::BadOption`]).
    fn restore(&mut self, memory: &IntegratorMemory) -> Result<(), SolverError> {
        if memory.is_empty() {
            Ok(())
        } else {
            Err(SolverError::BadOption(format!(
                "the {} integrator keeps no memory between steps, but the checkpoint carries some: it was written by another integrator",
                self.name()
            )))
        }
    }
}

/// An integrator's memory between steps ([`Integrator::memory`]): counters,
/// values and states, in an order only the integrator that took it knows.
/// Checkpoint files store it as it is.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IntegratorMemory {
    /// Integer counters and flags (and `f64`s kept bit for bit, as `to_bits`).
    pub counters: Vec<u64>,
    /// Floating-point values (cached forces, positions).
    pub values: Vec<f64>,
    /// Whole states (a fallback state).
    pub states: Vec<State>,
}

impl IntegratorMemory {
    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.counters.is_empty() && self.values.is_empty() && self.states.is_empty()
    }
}

/// Newton iteration limit per step or load increment of the implicit and
/// static solvers, unless set otherwise (scenes: `[solver] max_iterations`).
pub const DEFAULT_MAX_NEWTON: u32 = 50;
/// Newton tolerance on the residual force relative to the largest force term,
/// unless set otherwise (scenes: `[solver] tolerance`).
pub const DEFAULT_NEWTON_RTOL: f64 = 1e-8;

/// What an integrator factory is given besides the problem (a scene's
/// `[solver]` table, or a program's choice).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegratorSettings {
    /// Time step (s); `None` for the integrator's own choice (explicit: the
    /// stable limit times `safety`; implicit: [`ImplicitOptions::default`]'s).
    pub dt: Option<f64>,
    /// Fraction of the stable explicit step used (0 < safety <= 1).
    pub safety: f64,
    /// Explicit schemes: if `dt` is above the stability limit, sub-step
    /// instead of refusing.
    pub substep: bool,
    /// Newton tolerance (implicit schemes).
    pub rtol: f64,
    /// Newton iterations per step (implicit schemes).
    pub max_newton: u32,
    /// Linear solver of the Newton steps (implicit schemes).
    pub linear_solver: LinearSolverKind,
    /// Precision of the explicit force pass; Newton solvers refuse `F32`.
    pub precision: Precision,
}

impl Default for IntegratorSettings {
    fn default() -> Self {
        Self {
            dt: None,
            safety: ExplicitOptions::default().safety,
            substep: false,
            rtol: DEFAULT_NEWTON_RTOL,
            max_newton: DEFAULT_MAX_NEWTON,
            linear_solver: LinearSolverKind::Auto,
            precision: Precision::F64,
        }
    }
}

/// Builds an integrator for a problem: one entry of [`Integrators`].
pub type IntegratorFactory = std::sync::Arc<
    dyn Fn(&Problem, &IntegratorSettings) -> Result<Box<dyn Integrator>, SolverError> + Send + Sync,
>;

/// The time integrators a program knows, by name: a value that a program
/// extends with its own and passes where names are resolved. No global state.
///
/// [`Integrators::default`] holds `"explicit"` (velocity Verlet, alias
/// `"verlet"`), `"symplectic-euler"` and `"implicit"` (backward Euler).
/// See [`Integrator`] for an example of a custom one.
#[derive(Clone)]
pub struct Integrators {
    entries: mss_registry::Named<IntegratorEntry>,
}

/// One entry of [`Integrators`]: how to build the integrator, and what a
/// caller needs to know before building it.
#[derive(Clone)]
pub struct IntegratorEntry {
    /// Builds it for a problem.
    pub factory: IntegratorFactory,
    /// Whether it is explicit: its step is bounded by the stability limit
    /// (`dt = "auto"` means that limit) and it assembles no matrices (so
    /// the memory a run needs is smaller).
    pub explicit: bool,
}

fn explicit_factory(scheme: ExplicitScheme) -> IntegratorFactory {
    std::sync::Arc::new(move |problem: &Problem, s: &IntegratorSettings| {
        let opts = ExplicitOptions {
            dt: s.dt,
            scheme,
            safety: s.safety,
            substep: s.substep,
            precision: s.precision,
            ..ExplicitOptions::default()
        };
        Ok(Box::new(Explicit::new(problem, opts)?) as Box<dyn Integrator>)
    })
}

impl Default for Integrators {
    fn default() -> Self {
        let mut known = Self {
            entries: mss_registry::Named::new(),
        };
        known.register_explicit("explicit", explicit_factory(ExplicitScheme::VelocityVerlet));
        known.register_explicit("verlet", explicit_factory(ExplicitScheme::VelocityVerlet));
        known.register_explicit(
            "symplectic-euler",
            explicit_factory(ExplicitScheme::SymplecticEuler),
        );
        known.register(
            "implicit",
            std::sync::Arc::new(|problem: &Problem, s: &IntegratorSettings| {
                if s.precision != Precision::F64 {
                    return Err(SolverError::BadOption(format!(
                        "precision \"{}\" is for explicit solvers: Newton's method needs f64 \
                         forces and tangents",
                        s.precision.name()
                    )));
                }
                let opts = ImplicitOptions {
                    dt: s.dt.unwrap_or(ImplicitOptions::default().dt),
                    max_newton: s.max_newton,
                    rtol: s.rtol,
                    linear_solver: s.linear_solver,
                    ..ImplicitOptions::default()
                };
                Ok(Box::new(Implicit::new(problem, opts)?) as Box<dyn Integrator>)
            }),
        );
        known
    }
}

impl std::fmt::Debug for Integrators {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.entries.fmt(f)
    }
}

impl Integrators {
    /// Registers (or replaces) the integrator called `name`, one that is
    /// not explicit (see [`IntegratorEntry::explicit`]).
    pub fn register(&mut self, name: &str, factory: IntegratorFactory) {
        self.entries.register(
            name,
            IntegratorEntry {
                factory,
                explicit: false,
            },
        );
    }

    /// Registers (or replaces) the explicit integrator called `name`.
    pub fn register_explicit(&mut self, name: &str, factory: IntegratorFactory) {
        self.entries.register(
            name,
            IntegratorEntry {
                factory,
                explicit: true,
            },
        );
    }

    /// The registered names, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    /// Whether `name` is registered.
    pub fn contains(&self, name: &str) -> bool {
        self.entries.contains(name)
    }

    /// Whether `name` is a registered explicit integrator.
    pub fn is_explicit(&self, name: &str) -> bool {
        self.entries.get(name).is_some_and(|e| e.explicit)
    }

    /// Builds the integrator `name` for `problem`.
    pub fn build(
        &self,
        name: &str,
        problem: &Problem,
        settings: &IntegratorSettings,
    ) -> Result<Box<dyn Integrator>, SolverError> {
        let entry =
            self.entries
                .lookup(name)
                .map_err(|unknown| SolverError::UnknownIntegrator {
                    name: unknown.name,
                    known: unknown.known,
                })?;
        (entry.factory)(problem, settings)
    }
}

/// Options of [`newton`], the Newton solver shared by the implicit and static
/// solvers and the FEM reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonOptions {
    /// Iteration limit.
    pub max_iterations: u32,
    /// Target: residual norm over the free dofs at most `rtol` times the
    /// scale [`NonlinearSystem::residual`] returns.
    pub rtol: f64,
    /// Choose the step length from the slope `g(alpha) = delta . R(x + alpha delta)`
    /// (the energy's directional derivative for conservative forces) instead of
    /// backtracking on `|R|`; `|R|` backtracking remains the fallback.
    pub slope_line_search: bool,
    /// Keep a tangent's multigrid hierarchy over solves: the next solves
    /// with the same linear solver start on it (their tangents' actions the
    /// Krylov operator) where they are matrix-free. Within one solve a
    /// matrix-free Newton iteration always does so: no symmetric part and
    /// no set-up per tangent. A solve it does not serve falls back to a
    /// new hierarchy, and one that takes many more Krylov iterations on it
    /// than its first solve took per decade of residual releases it. For
    /// implicit steps, whose mass term keeps an earlier tangent's hierarchy
    /// a good preconditioner of the later ones.
    pub keep_hierarchy: bool,
}

/// Relative accuracy of the first linear solve of a Newton solve (iterative
/// solvers); it is raised to what reaches the Newton target in one step when
/// that is looser. Later ones follow Eisenstat and Walker's choice 2,
/// `0.9 (|R_k| / |R_k-1|)^2`. Solving the first one exactly (it was 1e-8)
/// bought nothing on the lattice: its step leaves a nonlinear remainder of a
/// few percent on the cantilever and the bunny, which the next iteration
/// solves anyway, and a nearly linear problem finishes with chord steps on
/// the same tangent (see [`newton`]). Looser than 1e-3 (0.1) costs Newton
/// iterations, each a tangent assembly and a hierarchy set-up.
const INITIAL_FORCING: f64 = 1e-3;

/// Share of the Newton target that a linear solve's residual is allowed
/// (the forcing term is never below it).
const NEWTON_TARGET_SHARE: f64 = 0.25;

/// Loosest linear solve of a Newton step (iterative solvers) before the
/// target is near. Eisenstat and Walker allow 0.1, but on the lattice a
/// Newton iteration (tangent assembly and hierarchy set-up) costs more than
/// the Krylov iterations a looser solve saves: with 0.1 the cantilever took
/// 4 Newton iterations instead of 2.
const MAX_FORCING: f64 = 1e-3;

/// A nonlinear system `R(x) = 0` on the free dofs, `J = dR/dx`, solved by
/// [`newton`]. `x` holds three components per node (positions, or
/// displacements for the FEM); held components are set by the caller and
/// never changed.
pub trait NonlinearSystem {
    /// Writes `R(x)` to `r` and returns the force scale the residual is
    /// measured against (N).
    fn residual(&mut self, x: &[Vec3], r: &mut [Vec3]) -> f64;
    /// The Jacobian at `x`.
    fn jacobian(&mut self, x: &[Vec3]) -> BlockCsr;
    /// Whether [`NonlinearSystem::jacobian_mul`] gives the product with the
    /// Jacobian. Then large solves keep no matrix for their Krylov products
    /// (only the preconditioner's single-precision copy).
    fn has_jacobian_mul(&self) -> bool {
        false
    }
    /// `out = J(x) v`, without a matrix; called only when
    /// [`NonlinearSystem::has_jacobian_mul`]. The default writes zeros.
    fn jacobian_mul(&self, x: &[Vec3], v: &[Vec3], out: &mut [Vec3]) {
        let _ = (x, v);
        out.fill(Vec3::zeros());
    }
    /// The symmetric part of the stiffness `-J(x)`, stored once per pair of
    /// blocks ([`crate::Model::symmetric_stiffness_upper`]), when
    /// [`NonlinearSystem::has_jacobian_mul`]: a solve that keeps no matrix
    /// builds its preconditioner from it, so the Jacobian is never
    /// assembled. The default (`None`) makes such solves assemble it.
    fn symmetric_stiffness(&mut self, x: &[Vec3]) -> Option<crate::sparse::SymmetricUpper> {
        let _ = x;
        None
    }
    /// The factor of the masses that [`NonlinearSystem::symmetric_stiffness`]
    /// adds to the model's symmetric stiffness on its diagonal (an implicit
    /// step's inertia, `(1 + alpha dt) / dt^2`): with the positions, what
    /// builds the same preconditioner again after a checkpoint.
    fn stiffness_shift(&self) -> f64 {
        0.0
    }
    /// Whether the caller asked to stop (checked before every Newton
    /// iteration, so that a stop takes one iteration, not a whole solve).
    fn cancelled(&self) -> bool {
        false
    }
}

/// Why [`newton`] stopped without converging.
#[derive(Debug, Clone, PartialEq)]
pub enum NewtonFailure {
    /// The iteration diverged or did not reach the target.
    Diverged(Divergence),
    /// The Jacobian is singular; the nodes a mechanism moves most.
    Singular(Vec<u32>),
    /// The linear solver failed otherwise.
    Linear(String),
    /// [`NonlinearSystem::cancelled`] said stop.
    Cancelled,
}

fn free_norm(r: &[Vec3], free: &[bool]) -> f64 {
    let mut s = 0.0;
    for (i, f) in free.iter().enumerate() {
        if *f {
            s += r[i / 3][i % 3].powi(2);
        }
    }
    s.sqrt()
}

/// Newton's method on the free dofs (`free[3 node + d]`): inexact linear
/// solves with `linear` (direct, or multigrid-preconditioned Krylov with
/// Eisenstat-Walker forcing terms), a line search on the energy's slope when
/// `opts.slope_line_search` (conservative problems) and backtracking on the
/// residual norm otherwise. `size` is a length scale of the body and `h` the
/// cell edge (for the round-off floor of the target). `x` is updated in place
/// (also on failure: callers keep their own copy). Returns the iterations.
///
/// An iteration whose last step showed the tangent still accurate reuses
/// that tangent and its multigrid hierarchy instead of assembling new ones
/// (a chord step): after a step with a new tangent whose nonlinear
/// remainder `R(x + d) - R(x) - J d` predicts a contraction of at most 1e-2;
/// once per solve, on trial, after a step with a new tangent that
/// contracted the residual by less than a factor of twenty (far from the
/// solution) but deformed no cell by more than a twentieth of its size; and
/// after a chord step while chord steps contract it by a factor of twenty or
/// more. Nearly linear problems then cost one assembly and one set-up,
/// however loosely the first linear solve was asked for. When `sys` has the
/// Jacobian's product ([`NonlinearSystem::has_jacobian_mul`]), `linear` may
/// keep no matrix and multiply through it.
pub fn newton(
    sys: &mut dyn NonlinearSystem,
    x: &mut [Vec3],
    free: &[bool],
    size: f64,
    h: f64,
    opts: NewtonOptions,
    linear: &mut linear::LinearSolver,
) -> Result<u32, NewtonFailure> {
    // Nothing of another solve's matrices may serve this one's chord steps;
    // a hierarchy kept over solves serves only as a preconditioner.
    if !opts.keep_hierarchy {
        linear.release_last();
    }
    let result = newton_iterations(sys, x, free, size, h, opts, linear);
    if !opts.keep_hierarchy || result.is_err() {
        linear.release_last();
    }
    result
}

/// Largest contraction per step, predicted from the last step, for which
/// [`newton`] reuses the last tangent (a chord step) instead of assembling
/// one: a reused step costs Krylov iterations only, a new tangent its
/// assembly and a hierarchy set-up besides (about ten Krylov iterations).
const CHORD_MAX_CONTRACTION: f64 = 1e-2;

/// Largest contraction a chord step may have shown for [`newton`] to take
/// another, and smallest that a step with a new tangent may have shown for
/// it to try a chord step whatever the remainder predicts. A chord step
/// contracting by `c` costs one Krylov solve per factor `1/c`; a new tangent
/// costs its assembly and set-up (about two solves) besides, and near the
/// solution gains about three decades: the two cost the same per decade near
/// `c` = 0.1, and half that leaves room for chord steps slowing down as the
/// tangent ages (the paper model's soft modes at 128x32x32: 0.03, 0.02, 0.09,
/// then 0.78). Far from the solution, where a step with a new tangent gains
/// less than a decade, the remainder misjudges the next chord step: it is
/// quadratic in the whole step just taken, while the chord step's error is
/// the tangent's change times a mere correction (the small-load cantilever
/// from rest: remainder 0.83 of the residual, chord steps then contracting
/// by 0.03 and 0.02). The trial needs a step that moved no node of a cell
/// from the cell's mean by more than this fraction of the cell edge: the
/// tangent of a cell changes about as much as the cell deforms or turns, and
/// after a step that changed it more, chord steps lead elsewhere (large
/// deflections with several equilibria).
const CHORD_KEEP_CONTRACTION: f64 = 0.05;

/// What a Newton step's linear solve is given: the assembled Jacobian, or
/// (for a solve that keeps no matrix) the symmetric part of the stiffness
/// its preconditioner is built from.
enum Tangent {
    Assembled(BlockCsr),
    SymmetricHalf(crate::sparse::SymmetricUpper),
}

fn newton_iterations(
    sys: &mut dyn NonlinearSystem,
    x: &mut [Vec3],
    free: &[bool],
    size: f64,
    h: f64,
    opts: NewtonOptions,
    linear: &mut linear::LinearSolver,
) -> Result<u32, NewtonFailure> {
    let n = x.len();
    let mut r = vec![Vec3::zeros(); n];
    let mut trial = vec![Vec3::zeros(); n];
    let mut r_trial = vec![Vec3::zeros(); n];
    let mut scale = sys.residual(x, &mut r);
    let mut norm = free_norm(&r, free);
    if !norm.is_finite() {
        return Err(NewtonFailure::Diverged(Divergence::NonFinite));
    }
    // Absolute floor: the force that moves a node by 1e-12 h against the
    // stiffest diagonal entry, set from the first Jacobian.
    let mut floor = 0.0;
    let mut target = opts.rtol * scale;
    let mut previous_norm: Option<f64> = None;
    // The contraction a step with the last tangent is predicted to reach.
    let mut chord: Option<f64> = None;
    let mut trial_left = true;
    // Where the last tangent was taken, for its product without a matrix.
    let matrix_free = sys.has_jacobian_mul();
    let free_dofs = free.iter().filter(|f| **f).count();
    let mut x_lin: Vec<Vec3> = Vec::new();
    for it in 0..opts.max_iterations {
        // The floor needs a tangent: a state already within the target
        // needs none.
        if norm == 0.0 || norm <= target || (it > 0 && norm <= floor) {
            return Ok(it);
        }
        if sys.cancelled() {
            return Err(NewtonFailure::Cancelled);
        }
        let neg_r: Vec<Vec3> = r.iter().map(|v| -v).collect();
        // Inexact Newton (Eisenstat-Walker forcing terms): solve only as
        // accurately as the nonlinear residual warrants, and never beyond
        // the Newton target. The direct solver ignores it.
        let forcing = match previous_norm {
            Some(prev) if prev > 0.0 => (0.9 * (norm / prev).powi(2)).clamp(1e-8, MAX_FORCING),
            _ => INITIAL_FORCING,
        };
        // Never beyond what reaches the Newton target from here: a linear
        // residual of a quarter of the target leaves the nonlinear one below
        // it near convergence, where the remainder is quadratic (a
        // twentieth asked for Krylov iterations that saved no Newton
        // iteration).
        let eta = forcing
            .max(NEWTON_TARGET_SHARE * target.max(floor) / norm)
            .min(0.1);
        previous_norm = Some(norm);
        let reused = match chord.take() {
            // A chord step contracts by about q whatever the linear
            // accuracy: solving much beyond q is wasted.
            Some(q) => {
                let product = jacobian_product(&*sys, &x_lin);
                let action: Option<linear::Action<'_>> = matrix_free.then_some(&product);
                linear.solve_again(&neg_r, free, size, eta.max(0.25 * q).min(0.1), action)
            }
            None => None,
        };
        let chord_step = reused.is_some();
        // A new tangent on the kept hierarchy (this solve's first, or an
        // earlier solve's): its action at `x`.
        let kept_scale = linear.newton_scale();
        let reused = match reused {
            None if matrix_free && (it > 0 || (opts.keep_hierarchy && kept_scale.is_some())) => {
                if it == 0 {
                    // The round-off floor from the earlier solve's tangent.
                    let kmax = kept_scale.unwrap_or(0.0);
                    floor = 1e-12 * kmax * h * (free_dofs as f64).sqrt();
                    if norm <= target.max(floor) {
                        return Ok(0);
                    }
                }
                // The fallback below takes its tangent at `x` too.
                x_lin.clear();
                x_lin.extend_from_slice(x);
                let product = jacobian_product(&*sys, &x_lin);
                linear.solve_with_new_action(&neg_r, free, size, eta, &product)
            }
            other => other,
        };
        let delta = match reused {
            Some(d) => d,
            None => {
                // Never two tangents alive at once.
                linear.release_last();
                // A solve that keeps no matrix needs only the stiffness's
                // symmetric part, for its preconditioner.
                let tangent = match (matrix_free && linear.keeps_no_matrix(free_dofs))
                    .then(|| sys.symmetric_stiffness(x))
                    .flatten()
                {
                    Some(half) => Tangent::SymmetricHalf(half),
                    None => Tangent::Assembled(sys.jacobian(x)),
                };
                if it == 0 {
                    let kmax = match &tangent {
                        Tangent::Assembled(jac) => (0..n)
                            .filter_map(|i| jac.find(i, i))
                            .map(|k| jac.blocks[k].abs().max())
                            .fold(0.0, f64::max),
                        Tangent::SymmetricHalf(half) => half.max_diagonal_block_entry(),
                    };
                    floor = 1e-12 * kmax * h * (free_dofs as f64).sqrt();
                    linear.set_newton_scale(kmax);
                    if norm <= target.max(floor) {
                        return Ok(0);
                    }
                }
                if matrix_free {
                    x_lin.clear();
                    x_lin.extend_from_slice(x);
                }
                let product = jacobian_product(&*sys, &x_lin);
                let action: Option<linear::Action<'_>> = matrix_free.then_some(&product);
                let solved = match tangent {
                    Tangent::Assembled(jac) => linear.solve(jac, &neg_r, free, size, eta, action),
                    Tangent::SymmetricHalf(half) => {
                        let origin = linear::StiffnessOrigin {
                            x: x_lin.clone(),
                            shift: sys.stiffness_shift(),
                        };
                        linear.solve_without_matrix(
                            (half, origin),
                            &neg_r,
                            free,
                            size,
                            eta,
                            &product,
                        )
                    }
                };
                match solved {
                    Ok(d) => d,
                    Err(linear::LinearFailure::Singular { nodes }) => {
                        return Err(NewtonFailure::Singular(nodes));
                    }
                    Err(linear::LinearFailure::Other(m)) => {
                        return Err(NewtonFailure::Linear(m));
                    }
                }
            }
        };
        let norm_before = norm;
        let mut accepted = false;
        let mut full_step = false;
        if opts.slope_line_search {
            // The residual norm is a poor merit function in bending: full
            // Newton steps that rotate the body raise |R| (the rest tangent
            // has no geometric stiffness) while lowering the energy, and
            // backtracking on |R| then crawls with steps of 1/32. Take the
            // full step unless it overshoots the minimum of the energy along
            // delta by much (g(1) < -g(0) / 2), else regula falsi on g.
            let slope = |r: &[Vec3]| -> f64 {
                let mut g = 0.0;
                for i in 0..n {
                    g += delta[i].dot(&r[i]);
                }
                g
            };
            let g0 = slope(&r[..]);
            if g0.is_finite() && g0 > 0.0 {
                let mut eval = |alpha: f64, trial: &mut [Vec3], r_trial: &mut [Vec3]| {
                    for i in 0..n {
                        trial[i] = x[i] + delta[i] * alpha;
                    }
                    let s = sys.residual(trial, r_trial);
                    (s, free_norm(r_trial, free), slope(r_trial))
                };
                let (s1, n1, g1) = eval(1.0, &mut trial[..], &mut r_trial[..]);
                let mut found = n1.is_finite() && g1 >= -0.5 * g0;
                let mut alpha = 1.0;
                let (mut st, mut nt) = (s1, n1);
                if !found {
                    let (mut lo, mut glo, mut hi, mut ghi) = (0.0f64, g0, 1.0f64, g1);
                    for _ in 0..12 {
                        alpha = if ghi.is_finite() && n1.is_finite() {
                            (lo + (hi - lo) * glo / (glo - ghi))
                                .clamp(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo))
                        } else {
                            0.5 * (lo + hi)
                        };
                        let (sa, na, ga) = eval(alpha, &mut trial[..], &mut r_trial[..]);
                        if na.is_finite() && ga.is_finite() && ga.abs() <= 0.5 * g0 {
                            (st, nt) = (sa, na);
                            found = true;
                            break;
                        }
                        if na.is_finite() && ga.is_finite() && ga > 0.0 {
                            (lo, glo) = (alpha, ga);
                        } else {
                            (hi, ghi) = (alpha, ga);
                        }
                    }
                }
                if found {
                    full_step = alpha == 1.0;
                    log::trace!(
                        "Newton iteration {it}: slope step {alpha}, residual {norm:e} -> {nt:e}"
                    );
                    x.copy_from_slice(&trial);
                    std::mem::swap(&mut r, &mut r_trial);
                    norm = nt;
                    scale = st;
                    accepted = true;
                }
            }
        }
        let mut alpha = 1.0;
        let backtracks = if accepted { 0 } else { 12 };
        for _ in 0..backtracks {
            for i in 0..n {
                trial[i] = x[i] + delta[i] * alpha;
            }
            let s = sys.residual(&trial, &mut r_trial);
            let nt = free_norm(&r_trial, free);
            if nt.is_finite() && nt <= (1.0 - 1e-4 * alpha) * norm {
                full_step = alpha == 1.0;
                log::trace!("Newton iteration {it}: step {alpha}, residual {norm:e} -> {nt:e}");
                x.copy_from_slice(&trial);
                std::mem::swap(&mut r, &mut r_trial);
                norm = nt;
                scale = s;
                accepted = true;
                break;
            }
            alpha *= 0.5;
        }
        target = opts.rtol * scale;
        if !accepted && chord_step {
            // The old tangent's direction did not descend: a new tangent.
            linear.release_last();
            continue;
        }
        if accepted && full_step {
            let contracted = norm / norm_before;
            let far = contracted > CHORD_KEEP_CONTRACTION;
            chord = if chord_step && far {
                None
            } else {
                let product = jacobian_product(&*sys, &x_lin);
                let action: Option<linear::Action<'_>> = matrix_free.then_some(&product);
                match chord_contraction(linear, action, &delta, &neg_r, &r, free, norm_before) {
                    Some(q) if chord_step || q <= CHORD_MAX_CONTRACTION => Some(q),
                    Some(q)
                        if far
                            && trial_left
                            && linear.largest_cell_distortion(&delta)
                                <= CHORD_KEEP_CONTRACTION * h =>
                    {
                        trial_left = false;
                        Some(q)
                    }
                    _ => None,
                }
            };
        }
        if !accepted {
            // No decrease along the Newton direction: converged to round-off
            // if the step is negligible, else a failure.
            let step = delta.iter().map(|d| d.amax()).fold(0.0, f64::max);
            // Also accept a residual within 100 times the target: the
            // round-off floor of ill-conditioned lattices (one cell through
            // the thickness) can sit just above it.
            if (step <= 1e-13 * size && norm <= 1e3 * target.max(floor))
                || norm <= 100.0 * target.max(floor)
            {
                log::debug!("Newton stagnated at residual {norm:e} (target {target:e}): accepted");
                return Ok(it + 1);
            }
            return Err(NewtonFailure::Diverged(Divergence::NewtonFailed {
                iterations: it + 1,
                residual: norm,
                target: target.max(floor),
            }));
        }
    }
    if norm <= 100.0 * target.max(floor) {
        log::debug!("Newton ended at residual {norm:e} (target {target:e}): accepted");
        return Ok(opts.max_iterations);
    }
    Err(NewtonFailure::Diverged(Divergence::NewtonFailed {
        iterations: opts.max_iterations,
        residual: norm,
        target: target.max(floor),
    }))
}

/// The contraction that a step from the new residual `r` with the last
/// solve's tangent `J` (taken at the start of the step `delta`, whose
/// residual was `-neg_r`) is predicted to reach: twice the step's nonlinear
/// remainder `|R(x + d) - R(x) - J d| / |R(x)|`, since the tangent changed
/// along the step by what the remainder shows. `None` without a kept
/// tangent (direct solves).
/// `out = J(x_lin) v` through `sys`'s product (the tangent a Newton step
/// took at `x_lin`, for a solve that kept no matrix).
fn jacobian_product<'a>(
    sys: &'a dyn NonlinearSystem,
    x_lin: &'a [Vec3],
) -> impl Fn(&[Vec3], &mut [Vec3]) + 'a {
    move |v: &[Vec3], out: &mut [Vec3]| sys.jacobian_mul(x_lin, v, out)
}

fn chord_contraction(
    linear: &linear::LinearSolver,
    action: Option<linear::Action<'_>>,
    delta: &[Vec3],
    neg_r: &[Vec3],
    r: &[Vec3],
    free: &[bool],
    norm_before: f64,
) -> Option<f64> {
    let mut remainder = vec![Vec3::zeros(); delta.len()];
    if !(norm_before > 0.0 && linear.last_product(delta, &mut remainder, action)) {
        return None;
    }
    // J d, turned into R(x + d) - R(x) - J d in place.
    for ((e, ri), ni) in remainder.iter_mut().zip(r).zip(neg_r) {
        *e = ri + ni - *e;
    }
    let q = 2.0 * free_norm(&remainder, free) / norm_before;
    q.is_finite().then_some(q)
}

fn check_inverted(model: &Model, x: &[Vec3]) -> Option<Divergence> {
    let inv = model.inverted_cells(x);
    (!inv.is_empty()).then(|| inverted_divergence(inv))
}

/// The divergence of a state with the inverted cells `inverted` (not empty).
fn inverted_divergence(inverted: Vec<u32>) -> Divergence {
    Divergence::InvertedCells {
        count: inverted.len(),
        first: inverted.into_iter().take(8).collect(),
    }
}

/// " (nodes that move freely include [..])", or nothing when no node is known
/// (e.g. nothing is held at all, so every node moves).
fn free_nodes_note(nodes: &[u32]) -> String {
    if nodes.is_empty() {
        String::new()
    } else {
        format!(" (nodes that move freely include {nodes:?})")
    }
}
