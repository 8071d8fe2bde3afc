//! Explicit time stepping: velocity Verlet (default) and symplectic Euler.
//!
//! Both are conditionally stable: `dt < 2 / omega_max` without damping. The
//! limit used here is `safety * 4 / (sqrt(c^2 + 4 w^2) + c)` with
//! `w = 2 / Model::critical_time_step()` (an upper bound of omega_max at rest)
//! and `c = alpha + beta w^2` the damping rate of the highest mode: the exact
//! stability bound of symplectic Euler for a damped oscillator, which reduces
//! to `safety * 2 / w` without damping.
//!
//! **Contact of the lattice's nodes is implicit, node by node.** A contact
//! spring is as stiff as the lattice's stiffest mode (it must be, or a
//! pressing obstacle sinks into the body), so integrated explicitly it
//! would set the step, and twice over, since an explicit step has to
//! resolve each contact oscillation for an elastic bounce to keep its
//! energy. But a node's contact force depends on that node alone, so its
//! implicit update is a 3 x 3 Newton solve: with velocity Verlet, the node's
//! position follows the trapezoidal rule in its contact force,
//! `x1 = x0 + dt v0 + dt^2 / 2m (F0 + (G0 + G1) / 2)` (Newmark's average
//! acceleration in `G`, central differences in the lattice's `F`; `G1`
//! at `x1`, its damping at the chord velocity `(x1 - x0) / dt`), and the
//! kicks use `G0` and `G1`; with symplectic Euler, backward Euler in `G`.
//! Such implicit-explicit partitions are stable whenever the explicit part
//! is on its own (Hughes and Liu 1978), the trapezoidal part keeps a
//! linear spring's energy, and a body at rest sits at the exact
//! equilibrium. So node contact does not shorten the step at all. The
//! points of the embedded surface share their force among 8 nodes; they stay
//! explicit and count in the limit, their frequency
//! [`CONTACT_RESOLUTION`] times over.
//!
//! The limit holds at rest. As a body deforms its stiffness changes (the
//! barrier of `volumetric-barrier` stiffens compressed cells, folding
//! springs stiffen transversally), and a step that was stable can stop being
//! so. [`Explicit`] therefore controls its sub-step. At every check it
//! estimates how much the stiffness has grown ([`Model::stiffness_growth`])
//! and, from the next step on, takes as many sub-steps as keep the sub-step
//! below the limit at rest divided by the square root of that growth, less
//! half the safety margin (at most `2^`[`MAX_GROWTH_HALVINGS`] times those
//! at rest; any count, not a power of two, so that a little growth costs a
//! little), and gives fewer back after [`CALM_CHECKS`] calm checks. And
//! when a step fails its
//! checks (non-finite values, a cell deforming by a quarter of its size in
//! one sub-step, an inverted cell), it goes back to the state at the start
//! of that step and takes it again with the sub-step halved, up to
//! [`MAX_HALVINGS`] times; after [`RELAX_AFTER`] good sub-steps it tries the
//! longer sub-step again. Only when the shortest sub-step fails too is the
//! failure returned: then it is not the step (docs/robustness.md).
//!
//! A step after [`Integrator::check_next_step`] ends with a full check, so
//! a state written as a frame has always passed them; the state kept after a
//! failure is the last one that passed.
//!
//! Steps do not allocate: forces, damping products and the last-good snapshot
//! live in buffers owned by [`Explicit`], and the force pass's scratch is
//! the model's spare ([`Model::internal_forces_shared`], shared with the
//! frame writer). Node updates run in parallel over
//! fixed-size chunks with no reduction other than a logical AND, and the
//! contact updates visit the touching nodes in a fixed order on one thread, so
//! results are bitwise identical for any number of threads (the model's
//! force gather is deterministic too).

use rayon::prelude::*;

mod kick;
use kick::{ChunkKick, all_finite, drift};

use super::{
    Divergence, EXPLICIT_HINT, Integrator, Problem, SolverError, State, StepInfo,
    inverted_divergence,
};
use crate::contact::Contact;
use crate::model::kernel::CORNER_BARRIER_START;
use crate::{BlockCsr, Model, Precision, Vec3};

/// Nodes per parallel task.
const CHUNK: usize = 1024;

/// How much finer than its stability limit the explicit step resolves the
/// contact oscillation of an embedded-surface vertex (see
/// [`explicit_time_step_limit`]).
pub const CONTACT_RESOLUTION: f64 = 2.0;

/// How many times a failing step is retried with its sub-step halved.
pub const MAX_HALVINGS: u32 = 5;

/// How many times, at most, the estimated growth of the stiffness may
/// halve the sub-step (its sub-steps grow to at most `2^this` times those
/// of the limit at rest).
pub const MAX_GROWTH_HALVINGS: u32 = 8;

/// Consecutive checks asking for fewer sub-steps than the growth of the
/// stiffness is given before it is given fewer (halfway down to the last
/// one's wish).
pub const CALM_CHECKS: u32 = 5;

/// The most halvings a failure can put in force: one more than the most
/// the other reasons can.
const MOST_HALVINGS: u32 = 1 + if MAX_HALVINGS > MAX_GROWTH_HALVINGS {
    MAX_HALVINGS
} else {
    MAX_GROWTH_HALVINGS
};

/// `substeps` sub-steps halved `k` times: `substeps << k`, saturated.
fn halved(substeps: u32, k: u32) -> u32 {
    u32::try_from(u64::from(substeps) << k.min(32)).unwrap_or(u32::MAX)
}

/// How an attempt at a step ended.
enum Attempt {
    Done,
    /// The stiffness grew: the step needs this many sub-steps.
    Stiffer(u32),
    Failed(Divergence),
}

/// Good sub-steps after which a halved sub-step is doubled again (this
/// doubles, in turn, each time a retry was needed, so that a body that keeps
/// needing the short step soon keeps it).
pub const RELAX_AFTER: u64 = 1000;

/// Which explicit scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExplicitScheme {
    /// Kick-drift-kick velocity Verlet: second-order, positions and velocities
    /// at the same time, so the energy error is O(dt^2). One force evaluation
    /// per step.
    #[default]
    VelocityVerlet,
    /// Symplectic (semi-implicit) Euler: first order, energy error O(dt).
    SymplecticEuler,
}

/// Options of [`Explicit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplicitOptions {
    /// Time advanced per [`Integrator::step`] (s); `None` for the stable limit.
    pub dt: Option<f64>,
    /// Scheme.
    pub scheme: ExplicitScheme,
    /// Fraction of the theoretical stability limit used (0 < safety <= 1).
    pub safety: f64,
    /// If `dt` is above the limit: sub-step (with a warning) instead of
    /// refusing.
    pub substep: bool,
    /// Accept any `dt` without checking the stability limit (for experiments;
    /// divergence is still detected).
    pub unchecked: bool,
    /// Divergence checks (inverted cells, exploding motion) every this many
    /// sub-steps; non-finite values are checked every sub-step.
    pub check_interval: u32,
    /// Precision of the internal force pass ([`Precision`]).
    pub precision: Precision,
}

impl Default for ExplicitOptions {
    fn default() -> Self {
        Self {
            dt: None,
            scheme: ExplicitScheme::VelocityVerlet,
            safety: 0.9,
            substep: false,
            unchecked: false,
            check_interval: 10,
            precision: Precision::F64,
        }
    }
}

/// The largest stable explicit step (s) for `problem`, times `safety`
/// (see the module docs).
pub fn explicit_time_step_limit(problem: &Problem, safety: f64) -> f64 {
    let (w_model_sq, w_contact_sq) = omega_sq_parts(problem);
    let w = (w_model_sq + w_contact_sq).sqrt();
    let d = problem.damping();
    let c = d.alpha + d.beta * w * w;
    let limit = safety * 4.0 / ((c * c + 4.0 * w * w).sqrt() + c);
    // The implicit node contact keeps any spring stable, but a one-sided
    // spring that the trapezoidal rule crosses in fewer than about three
    // steps per radian gains energy at its kink (an elastic bounce comes
    // back higher): contact far stiffer than the lattice is resolved.
    let w_node = problem.contact().map_or(0.0, |c| c.node_omega_sq().sqrt());
    if w_node * limit > NODE_CONTACT_ANGLE {
        NODE_CONTACT_ANGLE / w_node
    } else {
        limit
    }
}

/// The largest phase `omega dt` of a node's contact oscillation per
/// explicit step (rad). Measured on an undamped bounce (docs/solvers.md): at
/// the default contact stiffness (about 1.5 there) no energy is gained; at
/// 2, with contact up to 100 times stiffer, at most about 15 % of the drop's
/// energy, as explicit contact at its own limit did; beyond 3 the bounce
/// gains more than its drop.
pub const NODE_CONTACT_ANGLE: f64 = 2.0;

/// The lattice's and the contact's parts of the `omega_max^2` bound (1/s^2).
fn omega_sq_parts(problem: &Problem) -> (f64, f64) {
    let model = problem.model();
    let w_model = 2.0 / model.critical_time_step();
    // Contact of the nodes is integrated implicitly (module docs) and does
    // not limit the step. A surface vertex's contact spring is explicit: it
    // adds k / m to omega^2 (Gershgorin), and contact switches on and off
    // within an oscillation, which Verlet integrates without energy drift
    // only when it resolves it: that part counts CONTACT_RESOLUTION^2 times.
    let w_contact_sq = problem.contact().map_or(0.0, |c| {
        c.surface_omega_sq() * CONTACT_RESOLUTION * CONTACT_RESOLUTION
    });
    (w_model * w_model, w_contact_sq)
}

/// Newton iterations, at most, of a node's implicit contact update.
const CONTACT_NEWTON_ITERATIONS: usize = 12;

/// The explicit integrator: velocity Verlet or symplectic Euler with a
/// controlled sub-step, and contact of the lattice's nodes updated
/// implicitly node by node (Newmark's trapezoidal rule in the contact force
/// for Verlet, backward Euler for symplectic Euler), so that contact
/// stiffness does not limit the step; docs/solvers.md explains both.
#[derive(Debug)]
pub struct Explicit {
    opts: ExplicitOptions,
    dt: f64,
    dt_sub: f64,
    substeps: u32,
    /// Sub-steps per step that the stability limit at rest asks for.
    base_substeps: u32,
    /// Stable sub-step at rest (s), with the safety factor.
    limit: f64,
    /// Contact's share of `omega_max^2`: the part that does not grow with
    /// the lattice's stiffness.
    contact_share: f64,
    /// Halvings asked for by failed steps (undone after good sub-steps):
    /// they ask for `base_substeps << fail_halvings` sub-steps.
    fail_halvings: u32,
    /// Sub-steps asked for by the stiffness growth seen at the checks
    /// (`>= base_substeps`; `substeps` is the larger of the two wishes).
    growth_substeps: u32,
    /// Checks in a row that asked for fewer sub-steps than `growth_substeps`.
    calm_checks: u32,
    /// Good sub-steps since the last change of `substeps`.
    good_substeps: u64,
    /// Good sub-steps after which a halving is undone.
    relax_after: u64,
    /// The state at the start of the step being taken (to retry it).
    start: State,
    /// Conservative force (internal + external) at the positions whose
    /// [`positions_key`] is `cache_key`, at `cache_time`.
    f_cons: Vec<Vec3>,
    /// Contact forces of the kicks (empty without obstacles).
    f_contact: Vec<Vec3>,
    /// Nodes whose entry of `f_contact` may be non-zero.
    contact_touched: Vec<u32>,
    /// Per chunk of [`CHUNK`] nodes, whether `contact_touched` has a node
    /// in it ([`Explicit::mark_contact_chunks`]): the kicks read
    /// `f_contact` there only. Contact touches a body's surface, a few
    /// chunks of its nodes; reading the whole array in every kick cost the
    /// two bodies of `bodies_contact` 2 % of their step.
    contact_chunks: Vec<bool>,
    /// Entries of `contact_touched` after the last sub-step: more after a
    /// sub-step means something new touched (an impact), and the step is
    /// checked at once, as an impact can crush cells within a few sub-steps.
    touching: u32,
    /// `touching` at the start of the step being taken (to retry it).
    start_touching: u32,
    /// The largest strain a cell took in one sub-step, at the last check.
    last_strain: f64,
    /// Node points that touch (or were anchored) at the start of the
    /// sub-step under way, then those that touch at its end.
    candidates: Vec<u32>,
    /// Their contact forces at the start of the sub-step.
    g_start: Vec<Vec3>,
    /// The node points inside an obstacle at the end of a sub-step
    /// ([`Contact::node_points_inside`]).
    inside: Vec<u32>,
    /// `mark[i] == stamp` marks the points in `candidates`.
    mark: Vec<u32>,
    stamp: u32,
    /// `kept_force[i]`, where `kept_at[i]` is the stamp of the sub-step
    /// just ended: node point `i`'s contact force at that sub-step's end,
    /// found by its anchors' update with anchors that stayed (it sticks),
    /// which the next sub-step of the same call starts with instead of
    /// evaluating it again ([`Contact::update_anchors_keeping`]).
    kept_force: Vec<Vec3>,
    kept_at: Vec<u32>,
    /// Whether the anchors may not tell which node points touch (a new call
    /// of [`Integrator::step`]: obstacles may have been moved by hand, or
    /// the state changed).
    contact_fresh: bool,
    /// The body contact's pairs at a sub-step's end, for its anchors'
    /// update and, when the next sub-step starts from those positions
    /// (`cache_valid`), its start forces (one search and three keys of the
    /// positions fewer).
    step_pairs: Option<crate::contact::StepPairs>,
    cache_key: u64,
    cache_time: f64,
    cache_valid: bool,
    /// `K0 v` for stiffness-proportional damping.
    kv: Vec<Vec3>,
    /// `h / m` per node for the kicks' `h`: a division per node and kick
    /// was a third of a kick's time, and `h` changes only with the
    /// sub-step.
    kick_scale: Vec<f64>,
    /// The `h` (bits) and masses (address) `kick_scale` was computed for.
    kick_scale_for: (u64, usize),
    good: State,
    good_valid: bool,
    /// Whether the step under way has yet to keep its start's positions
    /// and velocities in `start` (its first kick and drift do).
    start_pending: bool,
    steps: u64,
    since_check: u32,
    /// Sub-steps between checks: `check_interval`, fewer while the
    /// stiffness has grown (see [`Explicit::substeps_for_growth`]).
    check_every: u32,
    /// Whether the step under way ends with a check ([`Integrator::check_next_step`]).
    check_at_end: bool,
    /// `state.time` at the end of the last step (to notice external changes).
    last_time: f64,
}

impl Explicit {
    /// Creates the integrator for `problem`. Refuses a `dt` above the stability
    /// limit unless `substep` or `unchecked` is set.
    pub fn new(problem: &Problem, opts: ExplicitOptions) -> Result<Self, SolverError> {
        if !(opts.safety > 0.0 && opts.safety <= 1.0) {
            return Err(SolverError::BadOption(format!(
                "explicit safety factor {} must be in (0, 1]",
                opts.safety
            )));
        }
        if opts.check_interval == 0 {
            return Err(SolverError::BadOption(
                "check_interval must be at least 1".into(),
            ));
        }
        let limit = explicit_time_step_limit(problem, opts.safety);
        let (w_model_sq, w_contact_sq) = omega_sq_parts(problem);
        let contact_share = if w_model_sq + w_contact_sq > 0.0 {
            w_contact_sq / (w_model_sq + w_contact_sq)
        } else {
            0.0
        };
        let dt = opts.dt.unwrap_or(limit);
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SolverError::BadTimeStep(dt));
        }
        let (dt_sub, substeps) = if dt <= limit || opts.unchecked {
            if dt > limit {
                log::warn!(
                    "explicit step {dt:.3e} s is above the stability limit {limit:.3e} s (unchecked mode)"
                );
            }
            (dt, 1)
        } else if opts.substep {
            let n = (dt / limit).ceil();
            if n > u32::MAX as f64 {
                return Err(SolverError::TimeStepTooLarge { dt, limit });
            }
            // Sub-stepping was asked for (an interactive frame): expected,
            // so not a warning.
            log::info!(
                "explicit step {dt:.3e} s is above the stability limit {limit:.3e} s: taking {n} sub-steps of {:.3e} s",
                dt / n
            );
            (dt / n, n as u32)
        } else {
            return Err(SolverError::TimeStepTooLarge { dt, limit });
        };
        let n = problem.model().num_nodes();
        let node_points = problem.contact().map_or(0, |c| c.node_points().len());
        let points = problem.contact().map_or(0, Contact::num_points);
        Ok(Self {
            opts,
            dt,
            dt_sub,
            substeps,
            base_substeps: substeps,
            limit,
            contact_share,
            fail_halvings: 0,
            growth_substeps: substeps,
            calm_checks: 0,
            good_substeps: 0,
            relax_after: RELAX_AFTER,
            start: State {
                x: vec![Vec3::zeros(); n],
                v: vec![Vec3::zeros(); n],
                time: 0.0,
                contact: Vec::new(),
            },
            f_cons: vec![Vec3::zeros(); n],
            f_contact: if problem.contact().is_some() {
                vec![Vec3::zeros(); n]
            } else {
                Vec::new()
            },
            // Every node point may touch at once: no growth while stepping.
            contact_touched: Vec::with_capacity(node_points),
            contact_chunks: if problem.contact().is_some() {
                vec![false; n.div_ceil(CHUNK)]
            } else {
                Vec::new()
            },
            touching: 0,
            start_touching: 0,
            last_strain: 0.0,
            candidates: Vec::with_capacity(node_points),
            g_start: Vec::with_capacity(node_points),
            // Every node point may be inside every obstacle at once.
            inside: Vec::with_capacity(
                node_points * problem.contact().map_or(0, |c| c.obstacles().count()),
            ),
            mark: vec![0; points],
            stamp: 0,
            kept_force: vec![Vec3::zeros(); points],
            kept_at: vec![0; points],
            contact_fresh: true,
            step_pairs: None,
            cache_key: 0,
            cache_time: f64::NAN,
            cache_valid: false,
            kv: if problem.damping().beta > 0.0 {
                vec![Vec3::zeros(); n]
            } else {
                Vec::new()
            },
            kick_scale: Vec::new(),
            kick_scale_for: (0, 0),
            good: State {
                x: vec![Vec3::zeros(); n],
                v: vec![Vec3::zeros(); n],
                time: 0.0,
                contact: Vec::new(),
            },
            good_valid: false,
            start_pending: false,
            steps: 0,
            since_check: 0,
            check_every: opts.check_interval,
            check_at_end: false,
            last_time: f64::NAN,
        })
    }

    /// Sub-steps per call to [`Integrator::step`] (more while the step
    /// control has halved the sub-step).
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// Puts in force the larger of the sub-step counts asked for.
    fn update_substep(&mut self) {
        let substeps = self.wished_substeps();
        if substeps != self.substeps {
            self.substeps = substeps;
            self.dt_sub = self.dt / f64::from(self.substeps);
            self.good_substeps = 0;
        }
    }

    fn wished_substeps(&self) -> u32 {
        self.growth_substeps
            .max(halved(self.base_substeps, self.fail_halvings))
    }

    /// The halvings of the base sub-step that the count in force amounts to
    /// (rounded up).
    fn halvings(&self) -> u32 {
        (0..MOST_HALVINGS)
            .find(|&k| halved(self.base_substeps, k) >= self.substeps)
            .unwrap_or(MOST_HALVINGS)
    }

    /// The sub-steps that the stiffness growth at `x` asks for: as many as
    /// needed, not a power of two, so that a little growth costs a little.
    /// Sets how soon the next check comes: a body whose stiffness has grown
    /// g times (g >= 2: compressed cells on the barrier's steep side) can
    /// stiffen much further within `check_interval` sub-steps, so it is
    /// checked g times as often.
    fn substeps_for_growth(&mut self, (stiffness_growth, lowest_corner): (f64, f64)) -> u32 {
        if self.opts.unchecked {
            return self.base_substeps;
        }
        self.check_every = if stiffness_growth >= 2.0 {
            ((f64::from(self.opts.check_interval) / stiffness_growth) as u32).max(1)
        } else {
            self.opts.check_interval
        };
        // The corner barrier's stiffness rises from zero within a few
        // sub-steps of a fast fold: check before the lowest corner can reach
        // it. A corner Jacobian changes per sub-step by about three times the
        // strain a cell takes in one (the last check's).
        if lowest_corner.is_finite() && self.last_strain > 0.0 {
            let room = (lowest_corner - CORNER_BARRIER_START).max(0.0);
            let reach = room / (3.0 * self.last_strain);
            if reach < f64::from(self.check_every) {
                self.check_every = (reach as u32).max(1);
            }
        }
        // Growth may use up half the safety margin (in the step's logarithm)
        // before the sub-step shrinks, so that small vibrations, which
        // change the stiffness by their amplitude, do not shrink it; a step
        // at the limit (safety 1) has no margin to give, beyond round-off.
        // Only the lattice's part of omega^2 grows with its stiffness.
        let growth = self.contact_share + (1.0 - self.contact_share) * stiffness_growth;
        let wanted = self.limit / (growth * self.opts.safety).sqrt() * (1.0 + 1e-9);
        let most = halved(self.base_substeps, MAX_GROWTH_HALVINGS);
        let needed = (self.dt / wanted).ceil();
        if needed.is_finite() && needed < f64::from(most) {
            (needed as u32).max(self.base_substeps)
        } else {
            most
        }
    }

    /// Takes one step of `dt` in `substeps` sub-steps, checking every
    /// `check_interval` sub-steps.
    fn advance(&mut self, problem: &Problem, state: &mut State, t_end: f64) -> Attempt {
        for s in 0..self.substeps {
            let ok = self.substep(problem, state);
            self.since_check += 1;
            if !ok {
                return Attempt::Failed(Divergence::NonFinite);
            }
            let touching = u32::try_from(self.contact_touched.len()).unwrap_or(u32::MAX);
            let new_touch = touching > self.touching;
            self.touching = touching;
            let last = s + 1 == self.substeps;
            if self.since_check >= self.check_every || new_touch || (last && self.check_at_end) {
                let growth = match self.check(problem.model(), state) {
                    Ok(growth) => growth,
                    Err(reason) => return Attempt::Failed(reason),
                };
                let needed = self.substeps_for_growth(growth);
                if needed > self.substeps {
                    return Attempt::Stiffer(needed);
                }
                // Give fewer sub-steps only after several calm checks: the
                // stiffness of a rebounding body swings faster than checks.
                if needed < self.growth_substeps {
                    self.calm_checks += 1;
                    if self.calm_checks >= CALM_CHECKS {
                        self.growth_substeps = (self.growth_substeps + needed).div_ceil(2);
                        self.calm_checks = 0;
                    }
                } else {
                    self.calm_checks = 0;
                }
                self.since_check = 0;
                if last {
                    state.time = t_end;
                }
                self.save_good(state);
            }
        }
        Attempt::Done
    }

    /// Puts the state back at the start of the step being taken.
    fn restart_step(&mut self, state: &mut State, good_before: f64) {
        state.x.copy_from_slice(&self.start.x);
        state.v.copy_from_slice(&self.start.v);
        state.contact.clone_from(&self.start.contact);
        state.time = self.start.time;
        if self.good.time > good_before {
            // A checkpoint inside the abandoned attempt is not good.
            self.save_good(state);
        }
        self.since_check = 0;
        self.touching = self.start_touching;
        self.cache_valid = false;
        self.contact_fresh = true;
    }

    /// The sub-step actually integrated (s).
    pub fn substep_dt(&self) -> f64 {
        self.dt_sub
    }

    /// Internal and external forces at `state` (cached by position and time).
    fn conservative_forces(&mut self, problem: &Problem, state: &State) {
        let model = problem.model();
        let (x, t) = (&state.x, state.time);
        model.internal_forces_shared(self.opts.precision, x, &mut self.f_cons);
        for l in problem.loads() {
            l.add_forces(model, t, x, 1.0, &mut self.f_cons);
        }
    }

    fn damping_product(&mut self, problem: &Problem, v: &[Vec3]) {
        if problem.damping().beta > 0.0 {
            par_mul(problem.rest_stiffness(), v, &mut self.kv);
        }
    }

    /// Makes `kick_scale` `h / m` per node (the same division as a kick
    /// of `h` computed in place, so the same bits).
    fn prepare_kicks(&mut self, problem: &Problem, h: f64) {
        let masses = problem.model().masses();
        let key = (h.to_bits(), masses.as_ptr() as usize);
        if self.kick_scale_for == key && self.kick_scale.len() == masses.len() {
            return;
        }
        self.kick_scale.resize(masses.len(), 0.0);
        self.kick_scale
            .par_chunks_mut(CHUNK)
            .zip(masses.par_chunks(CHUNK))
            .for_each(|(s, m)| {
                for (s, m) in s.iter_mut().zip(m) {
                    *s = h / m;
                }
            });
        self.kick_scale_for = key;
    }

    /// One velocity kick of `h` with the cached conservative force, the
    /// contact forces and damping, on free components only. Returns false
    /// on non-finite values.
    fn kick(&self, problem: &Problem, v: &mut [Vec3], h: f64) -> bool {
        let kick_chunk = self.chunk_kick(problem, h);
        v.par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, vc)| kick_chunk(ci, vc))
            .reduce(|| true, |a, b| a && b)
    }

    /// The kick of `h` of chunk `ci` of the velocities ([`ChunkKick::apply`]
    /// with the terms the problem has); `kick_scale` holds `h / m`
    /// ([`Explicit::prepare_kicks`]).
    fn chunk_kick<'a>(
        &'a self,
        problem: &'a Problem,
        h: f64,
    ) -> impl Fn(usize, &mut [Vec3]) -> bool + Sync + 'a {
        debug_assert_eq!(self.kick_scale_for.0, h.to_bits(), "kicks prepared for h");
        let masses = problem.model().masses();
        let held = problem.constraints().mask_bits();
        let d = problem.damping();
        // The optional terms are decided once per kick, not per node, so
        // that the common loop (no contact, no stiffness damping) is a
        // straight pass over four arrays.
        let extra = match (self.f_contact.is_empty(), self.kv.is_empty()) {
            (true, true) => Extra::None,
            (false, true) => Extra::Contact,
            _ => Extra::All,
        };
        move |ci: usize, vc: &mut [Vec3]| {
            let range = ci * CHUNK..ci * CHUNK + vc.len();
            let kick = ChunkKick {
                f: &self.f_cons[range.clone()],
                masses: &masses[range.clone()],
                scale: &self.kick_scale[range.clone()],
                held: &held[range.clone()],
                alpha: d.alpha,
            };
            // Where no contact force is, adding its zeros is adding nothing.
            let contact_here = self.contact_chunks.get(ci).copied().unwrap_or(false);
            match extra {
                Extra::None => kick.apply_with(vc, None),
                Extra::Contact if !contact_here => kick.apply_with(vc, None),
                Extra::Contact => kick.apply_with(vc, Some(&self.f_contact[range])),
                Extra::All => {
                    let start = range.start;
                    kick.apply(vc, |k, mut force| {
                        let i = start + k;
                        if contact_here {
                            force += self.f_contact[i];
                        }
                        if !self.kv.is_empty() {
                            force -= self.kv[i] * d.beta;
                        }
                        force
                    })
                }
            }
        }
    }

    /// A sub-step's kick of `h` and drift `x += dt v` in one pass over the
    /// nodes (each chunk kicked, then drifted, while it is in cache), then
    /// held components prescribed at `t1`. In a step's first sub-step it
    /// also keeps the state the step started from (the retry's), copying
    /// each chunk before changing it: that saves a pass over the positions
    /// and velocities per step. Returns false on non-finite values.
    fn kick_and_drift(
        &mut self,
        problem: &Problem,
        state: &mut State,
        h: f64,
        dt: f64,
        t1: f64,
    ) -> bool {
        let keep_start = std::mem::take(&mut self.start_pending);
        let (mut start_x, mut start_v) = if keep_start {
            (
                std::mem::take(&mut self.start.x),
                std::mem::take(&mut self.start.v),
            )
        } else {
            (Vec::new(), Vec::new())
        };
        let ok = {
            let kick_chunk = self.chunk_kick(problem, h);
            let kick_and_drift =
                |ci: usize,
                 xc: &mut [Vec3],
                 vc: &mut [Vec3],
                 saved: Option<(&mut [Vec3], &mut [Vec3])>| {
                    if let Some((sx, sv)) = saved {
                        kick::copy_past_caches(sx, xc);
                        kick::copy_past_caches(sv, vc);
                    }
                    let ok = kick_chunk(ci, vc);
                    ok & drift(xc, vc, dt)
                };
            let chunks = state
                .x
                .par_chunks_mut(CHUNK)
                .zip(state.v.par_chunks_mut(CHUNK))
                .enumerate();
            if keep_start {
                chunks
                    .zip(
                        start_x
                            .par_chunks_mut(CHUNK)
                            .zip(start_v.par_chunks_mut(CHUNK)),
                    )
                    .map(|((ci, (xc, vc)), (sx, sv))| kick_and_drift(ci, xc, vc, Some((sx, sv))))
                    .reduce(|| true, |a, b| a && b)
            } else {
                chunks
                    .map(|(ci, (xc, vc))| kick_and_drift(ci, xc, vc, None))
                    .reduce(|| true, |a, b| a && b)
            }
        };
        if keep_start {
            (self.start.x, self.start.v) = (start_x, start_v);
        }
        let rest = problem.model().rest_positions();
        problem
            .constraints()
            .prescribe_all(t1, dt, rest, &mut state.x, &mut state.v);
        ok
    }

    fn substep(&mut self, problem: &Problem, state: &mut State) -> bool {
        let dt = self.dt_sub;
        let t0 = state.time;
        let t1 = t0 + dt;
        // Between the sub-steps of one call nothing else moves the state; at
        // the start of a call `step_here` has checked the positions' key.
        let cached = self.cache_valid && self.cache_time == t0;
        match self.opts.scheme {
            ExplicitScheme::VelocityVerlet => {
                self.prepare_kicks(problem, 0.5 * dt);
                if !cached {
                    self.conservative_forces(problem, state);
                }
                self.contact_start(problem, state, true, cached);
                self.damping_product(problem, &state.v);
                self.mark_contact_chunks();
                let mut ok = self.kick_and_drift(problem, state, 0.5 * dt, dt, t1);
                ok &= self.contact_end(problem, state, dt, t0, true);
                state.time = t1;
                self.conservative_forces(problem, state);
                self.damping_product(problem, &state.v);
                self.mark_contact_chunks();
                ok &= self.kick(problem, &mut state.v, 0.5 * dt);
                self.cache_time = t1;
                self.cache_valid = ok;
                self.update_anchors(problem, state);
                ok
            }
            ExplicitScheme::SymplecticEuler => {
                self.prepare_kicks(problem, dt);
                if !cached {
                    self.conservative_forces(problem, state);
                }
                self.contact_start(problem, state, false, cached);
                self.damping_product(problem, &state.v);
                self.mark_contact_chunks();
                let mut ok = self.kick_and_drift(problem, state, dt, dt, t1);
                ok &= self.contact_end(problem, state, dt, t0, false);
                state.time = t1;
                self.cache_valid = false;
                self.update_anchors(problem, state);
                ok
            }
        }
    }

    /// Notes which chunks of nodes the kicks' contact forces touch (before
    /// each kick: between them the contact adds forces).
    fn mark_contact_chunks(&mut self) {
        self.contact_chunks.fill(false);
        for &n in &self.contact_touched {
            self.contact_chunks[n as usize / CHUNK] = true;
        }
    }

    /// Zeroes the contact forces of the kicks (the entries written since
    /// the last clearing: every contact force notes its nodes).
    fn clear_contact_forces(&mut self) {
        for &n in &self.contact_touched {
            self.f_contact[n as usize] = Vec3::zeros();
        }
        self.contact_touched.clear();
    }

    /// At the start of a sub-step: finds the node points that touch or are
    /// anchored, with their forces (into the first kick's contact forces
    /// when `verlet`: symplectic Euler's node contact is all implicit), and
    /// the surface points' explicit forces. `cached`: the state is the last
    /// sub-step's end, where its body contact's pairs were found.
    fn contact_start(&mut self, problem: &Problem, state: &State, verlet: bool, cached: bool) {
        let Some(contact) = problem.contact() else {
            return;
        };
        self.clear_contact_forces();
        let ended = self.stamp;
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.mark.fill(0);
            self.kept_at.fill(0);
            self.stamp = 1;
        }
        self.candidates.clear();
        self.g_start.clear();
        let known = state.contact.len() == contact.num_anchors();
        // Within a call, a node point is anchored exactly when it was inside
        // an obstacle at the end of the last sub-step (`contact_end` and
        // `update_anchors` see to it), where this one starts: only the
        // anchored can touch.
        let anchors_tell = known && !self.contact_fresh;
        self.contact_fresh = false;
        for &i in contact.node_points() {
            let anchored = known && contact.is_anchored(i, &state.contact);
            if anchors_tell && !anchored {
                continue;
            }
            let n = contact.point_node(i) as usize;
            let g = if anchored && !verlet {
                // Symplectic Euler's node contact is all implicit: the
                // start's force is not used, and an anchored point is a
                // candidate whether it touches or not.
                Vec3::zeros()
            } else if anchors_tell && self.kept_at[i as usize] == ended {
                // The last sub-step's end, the same state, found it.
                self.kept_force[i as usize]
            } else {
                let force = contact.node_point_force(
                    i,
                    state.time,
                    state.x[n],
                    state.v[n],
                    0.0,
                    &state.contact,
                    false,
                );
                if force.is_none() && !anchored {
                    continue;
                }
                force.map_or(Vec3::zeros(), |(g, _)| g)
            };
            self.candidates.push(i);
            self.g_start.push(g);
            self.mark[i as usize] = self.stamp;
            if verlet {
                self.f_contact[n] += g;
                self.contact_touched.push(n as u32);
            }
        }
        if contact.has_explicit_part() {
            let (f, touched) = (&mut self.f_contact, &mut self.contact_touched);
            let found = self.step_pairs.as_ref().filter(|_| cached);
            let (t, x, v) = (state.time, &state.x, &state.v);
            contact.add_explicit_forces_with(found, t, x, v, &state.contact, f, touched);
        }
    }

    /// After the drift of a sub-step from `t0` by `dt`: the implicit contact
    /// update of the node points (module docs) that touched at its start or
    /// touch at its end, then the contact forces of the second kick (when
    /// `verlet`). Returns false on non-finite values.
    fn contact_end(
        &mut self,
        problem: &Problem,
        state: &mut State,
        dt: f64,
        t0: f64,
        verlet: bool,
    ) -> bool {
        let Some(contact) = problem.contact() else {
            return true;
        };
        let t1 = t0 + dt;
        let started = self.candidates.len();
        self.inside.clear();
        contact.node_points_inside(t1, &state.x, &mut self.inside);
        for &i in &self.inside {
            // Marked: a candidate already (from the start, or inside an
            // obstacle listed before).
            if self.mark[i as usize] != self.stamp {
                self.mark[i as usize] = self.stamp;
                self.candidates.push(i);
                self.g_start.push(Vec3::zeros());
            }
        }
        let model = problem.model();
        let masses = model.masses();
        let cons = problem.constraints();
        let tolerance = 1e-12 * model.h();
        if verlet {
            self.clear_contact_forces();
        }
        let mut ok = true;
        for k in 0..self.candidates.len() {
            let i = self.candidates[k];
            let n = contact.point_node(i) as usize;
            let mask = cons.mask(n);
            let free = |v: Vec3| Vec3::from_fn(|c, _| if mask[c] { 0.0 } else { v[c] });
            // Velocity Verlet: x1 = x* + c (g1 - g0), c = dt^2 / 4m (the
            // trapezoidal rule in the contact force); symplectic Euler:
            // x1 = x* + c g1, c = dt^2 / m (backward Euler in it).
            let c = if verlet { 0.25 } else { 1.0 } * dt * dt / masses[n];
            let g0 = if verlet && k < started {
                self.g_start[k]
            } else {
                Vec3::zeros()
            };
            let x_star = state.x[n];
            let x_prev = x_star - state.v[n] * dt;
            contact.anchor_at_step_start(i, t0, x_prev, &mut state.contact);
            let target = x_star - free(g0) * c;
            let mut x = target;
            let mut g;
            // The first iterate is rarely the answer (it is where the node
            // would be without its new contact force): its Jacobian is
            // taken at once; later ones are checked before it is taken.
            let mut with_jacobian = true;
            let mut iterations = 0;
            loop {
                let v_chord = (x - x_prev) / dt;
                // One call site, so that it is inlined: its result came back
                // through memory, and reading it stalled the store forwarding.
                let (gx, jac) = contact
                    .node_point_force(i, t1, x, v_chord, 1.0 / dt, &state.contact, with_jacobian)
                    .unwrap_or((Vec3::zeros(), crate::Mat3::zeros()));
                let r = free(x - target - gx * c);
                if r.norm() <= tolerance {
                    g = gx;
                    break;
                }
                if !with_jacobian {
                    // The same iterate again, with its Jacobian.
                    with_jacobian = true;
                    continue;
                }
                g = gx;
                with_jacobian = false;
                let mut a = crate::Mat3::identity() - jac * c;
                for d in 0..3 {
                    if mask[d] {
                        for e in 0..3 {
                            a[(d, e)] = if d == e { 1.0 } else { 0.0 };
                            a[(e, d)] = if d == e { 1.0 } else { 0.0 };
                        }
                    }
                }
                let Some(inverse) = a.try_inverse() else {
                    break;
                };
                x -= free(inverse * r);
                iterations += 1;
                if iterations == CONTACT_NEWTON_ITERATIONS {
                    break;
                }
            }
            ok &= all_finite(&x);
            state.x[n] = x;
            if verlet {
                self.f_contact[n] += g;
                self.contact_touched.push(n as u32);
            } else {
                state.v[n] += free(g) * (dt / masses[n]);
            }
        }
        if contact.has_explicit_part() {
            let forces = verlet.then_some((&mut self.f_contact[..], &mut self.contact_touched));
            self.step_pairs = contact.anchor_explicit_and_add_forces(
                t1,
                &state.x,
                &state.v,
                dt,
                &mut state.contact,
                forces,
            );
        }
        ok
    }

    /// After a sub-step: the friction anchors of the points that touched.
    fn update_anchors(&mut self, problem: &Problem, state: &mut State) {
        let Some(contact) = problem.contact() else {
            return;
        };
        let (t, x, v) = (state.time, &state.x, &state.v);
        let (kept_force, kept_at, stamp) = (&mut self.kept_force, &mut self.kept_at, self.stamp);
        contact.update_anchors_keeping(
            &self.candidates,
            t,
            x,
            v,
            &mut state.contact,
            |i, force| {
                kept_force[i as usize] = force;
                kept_at[i as usize] = stamp;
            },
        );
        contact.update_anchors_of(contact.surface_points(), t, x, v, &mut state.contact);
        match self.step_pairs.as_ref() {
            Some(found) => contact.update_body_anchors_with(found, x, v, &mut state.contact),
            None => contact.update_body_anchors(x, v, &mut state.contact),
        }
    }

    /// The divergence checks of a sub-step; when they pass, the stiffness
    /// growth and lowest corner Jacobian the step control needs, from the
    /// same pass over the cells as the inverted ones.
    fn check(&mut self, model: &Model, state: &State) -> Result<(f64, f64), Divergence> {
        let (cell, strain) = max_cell_velocity_change(model, &state.v, self.dt_sub);
        self.last_strain = strain;
        if strain.is_nan() || strain > 0.25 {
            return Err(Divergence::Explosion {
                cell,
                strain_per_step: strain,
            });
        }
        let checks = model.cell_checks(&state.x, !self.opts.unchecked);
        if !checks.inverted.is_empty() {
            return Err(inverted_divergence(checks.inverted));
        }
        Ok((checks.stiffness_growth, checks.lowest_corner))
    }

    /// The stiffness growth and lowest corner Jacobian at `x` (not measured
    /// when the step is unchecked).
    fn growth_at(&self, model: &Model, x: &[Vec3]) -> (f64, f64) {
        if self.opts.unchecked {
            (1.0, f64::INFINITY)
        } else {
            model.stiffness_growth_and_lowest_corner(x)
        }
    }

    fn save_good(&mut self, state: &State) {
        self.good.x.copy_from_slice(&state.x);
        self.good.v.copy_from_slice(&state.v);
        self.good.contact.clone_from(&state.contact);
        self.good.time = state.time;
        self.good_valid = true;
    }
}

/// A key of the positions' bits, to notice a state changed from outside
/// between two steps: a wrapping sum of every coordinate's bits times an odd
/// number that depends on its index, so that any change of one coordinate
/// changes it; wrapping addition is associative, so it is the same for any
/// split among threads.
fn positions_key(x: &[Vec3]) -> u64 {
    x.par_chunks(CHUNK)
        .enumerate()
        .map(|(ci, c)| {
            let mut h = 0u64;
            for (k, p) in c.iter().enumerate() {
                let i = (ci * CHUNK + k) as u64;
                let m = i.wrapping_mul(0x9e37_79b9_7f4a_7c16) | 1;
                h = h.wrapping_add(
                    p.x.to_bits()
                        .wrapping_add(p.y.to_bits().rotate_left(21))
                        .wrapping_add(p.z.to_bits().rotate_left(42))
                        .wrapping_mul(m),
                );
            }
            h
        })
        .reduce(|| 0, u64::wrapping_add)
}

/// Layout of [`Explicit`]'s [`IntegratorMemory`](super::IntegratorMemory)
/// (changed whenever its counters change).
const EXPLICIT_MEMORY_VERSION: u64 = 4;

impl Integrator for Explicit {
    fn name(&self) -> &'static str {
        match self.opts.scheme {
            ExplicitScheme::VelocityVerlet => "verlet",
            ExplicitScheme::SymplecticEuler => "symplectic-euler",
        }
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    /// The positions a step keeps to be retried from: each step's first
    /// drift copies them again before anything reads them.
    fn lend_scratch(&mut self) -> Option<&mut [Vec3]> {
        Some(&mut self.start.x)
    }

    fn check_next_step(&mut self) {
        self.check_at_end = true;
    }

    fn memory(&self) -> super::IntegratorMemory {
        let mut values = Vec::new();
        if self.cache_valid {
            values.reserve(3 * self.f_cons.len());
            values.extend(self.f_cons.iter().flat_map(|f| [f.x, f.y, f.z]));
        }
        super::IntegratorMemory {
            counters: vec![
                EXPLICIT_MEMORY_VERSION,
                self.steps,
                u64::from(self.substeps),
                u64::from(self.fail_halvings),
                u64::from(self.growth_substeps),
                u64::from(self.calm_checks),
                self.good_substeps,
                self.relax_after,
                u64::from(self.since_check),
                u64::from(self.check_every),
                u64::from(self.good_valid),
                u64::from(self.cache_valid),
                self.last_time.to_bits(),
                self.cache_time.to_bits(),
                self.cache_key,
                u64::from(self.touching),
            ],
            values,
            states: vec![self.good.clone()],
        }
    }

    fn restore(&mut self, memory: &super::IntegratorMemory) -> Result<(), SolverError> {
        let bad = |why: &str| {
            SolverError::BadOption(format!(
                "the checkpoint's integrator memory does not fit this explicit integrator: {why}"
            ))
        };
        let &[
            version,
            steps,
            substeps,
            fail_halvings,
            growth_substeps,
            calm_checks,
            good_substeps,
            relax_after,
            since_check,
            check_every,
            good_valid,
            cache_valid,
            last_time,
            cache_time,
            cache_key,
            touching,
        ] = memory.counters.as_slice()
        else {
            return Err(bad("wrong number of counters"));
        };
        if version != EXPLICIT_MEMORY_VERSION {
            return Err(bad("written by another version"));
        }
        let n = self.f_cons.len();
        let small = |v: u64, max: u32| u32::try_from(v).ok().filter(|&v| v <= max);
        let base = self.base_substeps;
        let (Some(fail_halvings), Some(growth_substeps)) = (
            small(fail_halvings, MOST_HALVINGS),
            u32::try_from(growth_substeps)
                .ok()
                .filter(|g| (base..=halved(base, MAX_GROWTH_HALVINGS)).contains(g)),
        ) else {
            return Err(bad("sub-step counts out of range"));
        };
        if substeps != u64::from(growth_substeps.max(halved(base, fail_halvings))) {
            return Err(bad("inconsistent sub-step counts"));
        }
        let cache_valid = cache_valid != 0;
        let expected_values = if cache_valid { 3 * n } else { 0 };
        if memory.values.len() != expected_values {
            return Err(bad("wrong number of cached values"));
        }
        let [good] = memory.states.as_slice() else {
            return Err(bad("no fallback state"));
        };
        if good.x.len() != n || good.v.len() != n {
            return Err(bad("a fallback state of another size"));
        }
        self.steps = steps;
        self.fail_halvings = fail_halvings;
        self.growth_substeps = growth_substeps;
        self.calm_checks = u32::try_from(calm_checks).map_err(|_| bad("calm checks"))?;
        self.good_substeps = good_substeps;
        self.relax_after = relax_after;
        self.since_check = u32::try_from(since_check).map_err(|_| bad("checks"))?;
        self.check_every = u32::try_from(check_every)
            .ok()
            .filter(|c| (1..=self.opts.check_interval).contains(c))
            .ok_or_else(|| bad("check interval"))?;
        self.good_valid = good_valid != 0;
        self.cache_valid = cache_valid;
        // The pairs belong to this integrator's last sub-step, not to the
        // restored one's.
        self.step_pairs = None;
        self.last_time = f64::from_bits(last_time);
        self.cache_time = f64::from_bits(cache_time);
        self.cache_key = cache_key;
        self.touching = u32::try_from(touching).map_err(|_| bad("touching count"))?;
        self.substeps = self.wished_substeps();
        self.dt_sub = self.dt / f64::from(self.substeps);
        self.good.clone_from(good);
        if cache_valid {
            for (dst, c) in self.f_cons.iter_mut().zip(memory.values.chunks_exact(3)) {
                *dst = Vec3::new(c[0], c[1], c[2]);
            }
        }
        self.check_at_end = false;
        Ok(())
    }

    fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        crate::on_worker(|| self.step_here(problem, state))
    }
}

impl Explicit {
    /// [`Integrator::step`], on the thread it is called on.
    fn step_here(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        state.check_size(problem.model())?;
        if self.cache_valid
            && (self.cache_time != state.time || self.cache_key != positions_key(&state.x))
        {
            // The state was changed from outside since the forces were cached.
            self.cache_valid = false;
            self.step_pairs = None;
        }
        if !self.good_valid || self.last_time != state.time {
            // A new or externally changed state: it is the reference to fall
            // back on, and it may already be far from rest.
            self.save_good(state);
            self.since_check = 0;
            self.last_strain = 0.0;
            let growth = self.growth_at(problem.model(), &state.x);
            self.growth_substeps = self.substeps_for_growth(growth);
            self.update_substep();
        }
        self.steps += 1;
        self.contact_fresh = true;
        let t_end = state.time + self.dt;
        // The first sub-step's kick and drift fill `start.v` and `start.x`.
        self.start_pending = true;
        self.start.contact.clone_from(&state.contact);
        self.start.time = state.time;
        self.start_touching = self.touching;
        let good_before = self.good.time;
        loop {
            let reason = match self.advance(problem, state, t_end) {
                Attempt::Done => break,
                Attempt::Stiffer(needed) => {
                    // The body stiffened within the step: take it again with
                    // the sub-step its stiffness asks for.
                    log::debug!(
                        "explicit: step {} taken again in {} sub-steps (stiffness grew)",
                        self.steps,
                        needed
                    );
                    self.restart_step(state, good_before);
                    self.growth_substeps = needed;
                    self.calm_checks = 0;
                    self.update_substep();
                    continue;
                }
                Attempt::Failed(reason) => reason,
            };
            self.cache_valid = false;
            if self.fail_halvings < MAX_HALVINGS {
                // Take the step again from its start with half the sub-step.
                log::info!(
                    "explicit: step {} ({reason}) retried with the sub-step halved to {:.3e} s",
                    self.steps,
                    0.5 * self.dt_sub
                );
                self.restart_step(state, good_before);
                self.relax_after = self.relax_after.saturating_mul(2);
                self.fail_halvings = self.halvings() + 1;
                self.update_substep();
                continue;
            }
            self.check_at_end = false;
            let time = state.time;
            state.x.copy_from_slice(&self.good.x);
            state.v.copy_from_slice(&self.good.v);
            state.contact.clone_from(&self.good.contact);
            state.time = self.good.time;
            return Err(SolverError::Diverged {
                solver: "explicit",
                step: self.steps,
                time,
                reason,
                kept_time: self.good.time,
                hint: EXPLICIT_HINT,
            });
        }
        self.check_at_end = false;
        let substeps = self.substeps;
        self.good_substeps += u64::from(substeps);
        if self.fail_halvings > 0 && self.good_substeps >= self.relax_after {
            self.fail_halvings -= 1;
            self.good_substeps = 0;
        }
        self.update_substep();
        // Sub-step times accumulate round-off: land exactly on the step's end.
        state.time = t_end;
        self.last_time = t_end;
        if self.cache_valid {
            self.cache_time = t_end;
            self.cache_key = positions_key(&state.x);
        }
        Ok(StepInfo {
            time: state.time,
            dt: self.dt,
            substeps,
            newton_iterations: 0,
        })
    }
}

/// The terms a kick adds beyond the conservative force and mass damping.
#[derive(Clone, Copy)]
enum Extra {
    None,
    Contact,
    /// Contact (when there is any) and stiffness damping.
    All,
}

/// `out = a v`, rows in parallel (each row summed in a fixed order).
fn par_mul(a: &BlockCsr, v: &[Vec3], out: &mut [Vec3]) {
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, oc)| {
        for (k, o) in oc.iter_mut().enumerate() {
            let i = ci * CHUNK + k;
            let mut acc = Vec3::zeros();
            for j in a.row_offsets[i] as usize..a.row_offsets[i + 1] as usize {
                acc += a.blocks[j] * v[a.col_indices[j] as usize];
            }
            *o = acc;
        }
    });
}

/// Largest `dt * max_a |v_a - mean(v)| / h` over cells: how much of its size a
/// cell deforms in one step. With the cell: the first of the largest, or
/// the last cell whose value is NaN, whatever the thread count (the
/// reduction merges neighbouring ranges in order).
fn max_cell_velocity_change(model: &Model, v: &[Vec3], dt: f64) -> (u32, f64) {
    let cells = model.cells();
    let of_cell = |c: usize| {
        let cell = &cells[c];
        let mut mean = Vec3::zeros();
        for &k in cell {
            mean += v[k as usize];
        }
        mean /= 8.0;
        // The largest squared norm, then one root: the root is monotonic,
        // so the same value as the largest root.
        let mut m2 = 0.0f64;
        for &k in cell {
            m2 = m2.max((v[k as usize] - mean).norm_squared());
        }
        (c as u32, m2.sqrt() * dt / model.h())
    };
    // `later` follows `earlier` in cell order: a NaN wins (the later one),
    // else the larger value (the earlier one on a tie).
    let merge = |earlier: (u32, f64), later: (u32, f64)| {
        if later.1.is_nan() || (!earlier.1.is_nan() && later.1 > earlier.1) {
            later
        } else {
            earlier
        }
    };
    (0..cells.len())
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(of_cell)
        .reduce(|| (0u32, 0.0f64), merge)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel divergence measure names the cell the serial scan
    /// would (the first of the largest), with the same value, on any pool.
    #[test]
    fn cell_velocity_change_is_the_serial_scans_on_any_pool() {
        let lattice = hexmesh::Lattice::block([20, 12, 10], 0.1, [0.0; 3]).unwrap();
        let material = crate::Material::new(1e4, 0.3, 1000.0).unwrap();
        let model = Model::new(&lattice, material, &crate::model::SpringsOnly).unwrap();
        let serial = |v: &[Vec3]| {
            let mut worst = (0u32, 0.0f64);
            for c in 0..model.num_cells() {
                let cell = &model.cells()[c];
                let mean = cell.iter().map(|&k| v[k as usize]).sum::<Vec3>() / 8.0;
                let m = cell
                    .iter()
                    .map(|&k| (v[k as usize] - mean).norm())
                    .fold(0.0, f64::max);
                let s = m * 0.01 / model.h();
                if s.is_nan() || s > worst.1 {
                    worst = (c as u32, s);
                }
            }
            worst
        };
        let n = model.num_nodes();
        // Two equal peaks (the first wins); then NaN velocities in two
        // places, which the kicks catch (here the measure must only agree).
        let mut v = vec![Vec3::zeros(); n];
        for (i, vi) in v.iter_mut().enumerate() {
            vi.x = ((i * 37) % 11) as f64 * 1e-3;
        }
        v[300] = Vec3::new(5.0, 0.0, 0.0);
        v[1800] = Vec3::new(5.0, 0.0, 0.0);
        let mut with_nan = v.clone();
        with_nan[100].y = f64::NAN;
        with_nan[2500].z = f64::NAN;
        for v in [&v, &with_nan] {
            let expected = serial(v);
            for threads in [1, 2, 3] {
                let got = crate::on_threads(threads, || max_cell_velocity_change(&model, v, 0.01));
                assert_eq!(got.0, expected.0, "{threads} threads");
                assert_eq!(got.1.to_bits(), expected.1.to_bits(), "{threads} threads");
            }
        }
    }
}
