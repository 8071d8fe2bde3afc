//! Explicit time stepping: velocity Verlet (default) and symplectic Euler.
//!
//! Both are conditionally stable: `dt < 2 / omega_max` without damping. The
//! limit used here is `safety * 4 / (sqrt(c^2 + 4 w^2) + c)` with
//! `w = 2 / Model::critical_time_step()` (an upper bound of omega_max at rest)
//! and `c = alpha + beta w^2` the damping rate of the highest mode: the exact
//! stability bound of symplectic Euler for a damped oscillator, which reduces
//! to `safety * 2 / w` without damping.
//!
//! The limit holds at rest. As a body deforms its stiffness changes (the
//! barrier of `volumetric-barrier` stiffens compressed cells, folding
//! springs stiffen transversally), and a step that was stable can stop being
//! so. [`Explicit`] therefore controls its sub-step. At every check it
//! estimates how much the stiffness has grown ([`Model::stiffness_growth`])
//! and, from the next step on, halves the sub-step until it is below the
//! limit at rest divided by the square root of that growth, less half the
//! safety margin (up to
//! [`MAX_GROWTH_HALVINGS`] times). And when a step fails its
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
//! live in buffers owned by [`Explicit`]. Node updates run in parallel over
//! fixed-size chunks with no reduction other than a logical AND, so results are
//! bitwise identical for any number of threads (the model's force gather is
//! deterministic too).

use rayon::prelude::*;

use super::{
    Divergence, EXPLICIT_HINT, Integrator, Problem, SolverError, State, StepInfo, check_inverted,
};
use crate::model::ForceWorkspace;
use crate::{BlockCsr, Model, Vec3};

/// Nodes per parallel task.
const CHUNK: usize = 1024;

/// How much finer than its stability limit the explicit step resolves a
/// contact oscillation (see [`explicit_time_step_limit`]).
pub const CONTACT_RESOLUTION: f64 = 2.0;

/// How many times a failing step is retried with its sub-step halved.
pub const MAX_HALVINGS: u32 = 5;

/// How many times the sub-step is halved, at most, for the estimated growth
/// of the stiffness.
pub const MAX_GROWTH_HALVINGS: u32 = 8;

/// Consecutive checks asking for fewer growth halvings before one is undone.
pub const CALM_CHECKS: u32 = 5;

/// How an attempt at a step ended.
enum Attempt {
    Done,
    /// The stiffness grew: the step needs this many growth halvings.
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
    safety * 4.0 / ((c * c + 4.0 * w * w).sqrt() + c)
}

/// The lattice's and the contact's parts of the `omega_max^2` bound (1/s^2).
fn omega_sq_parts(problem: &Problem) -> (f64, f64) {
    let model = problem.model();
    let w_model = 2.0 / model.critical_time_step();
    // A contact spring on a boundary node adds k / m to omega^2 (Gershgorin:
    // it sits on that node's diagonal). Contact switches on and off within
    // an oscillation, which Verlet integrates without energy drift only when
    // it resolves it: that part counts CONTACT_RESOLUTION^2 times (about 7
    // steps per contact period at safety 0.9).
    let w_contact_sq = problem.contact().map_or(0.0, |c| {
        c.omega_sq() * CONTACT_RESOLUTION * CONTACT_RESOLUTION
    });
    (w_model * w_model, w_contact_sq)
}

/// The explicit integrator.
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
    /// Halvings of the sub-step in force (see the module docs): the larger
    /// of `fail_halvings` and `growth_halvings`.
    halvings: u32,
    /// Halvings asked for by failed steps (undone after good sub-steps).
    fail_halvings: u32,
    /// Halvings asked for by the stiffness growth seen at the checks.
    growth_halvings: u32,
    /// Checks in a row that asked for fewer growth halvings.
    calm_checks: u32,
    /// Good sub-steps since the last change of `halvings`.
    good_substeps: u64,
    /// Good sub-steps after which a halving is undone.
    relax_after: u64,
    /// The state at the start of the step being taken (to retry it).
    start: State,
    ws: ForceWorkspace,
    /// Conservative force (internal + external) at the positions whose
    /// [`positions_key`] is `cache_key`, at `cache_time`.
    f_cons: Vec<Vec3>,
    /// Contact forces (empty without obstacles).
    f_contact: Vec<Vec3>,
    cache_key: u64,
    cache_time: f64,
    cache_valid: bool,
    /// `K0 v` for stiffness-proportional damping.
    kv: Vec<Vec3>,
    good: State,
    good_valid: bool,
    steps: u64,
    since_check: u32,
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
            log::warn!(
                "explicit step {dt:.3e} s is above the stability limit {limit:.3e} s: taking {n} sub-steps of {:.3e} s",
                dt / n
            );
            (dt / n, n as u32)
        } else {
            return Err(SolverError::TimeStepTooLarge { dt, limit });
        };
        let n = problem.model().num_nodes();
        Ok(Self {
            opts,
            dt,
            dt_sub,
            substeps,
            base_substeps: substeps,
            limit,
            contact_share,
            halvings: 0,
            fail_halvings: 0,
            growth_halvings: 0,
            calm_checks: 0,
            good_substeps: 0,
            relax_after: RELAX_AFTER,
            start: State {
                x: vec![Vec3::zeros(); n],
                v: vec![Vec3::zeros(); n],
                time: 0.0,
                contact: Vec::new(),
            },
            ws: problem.model().workspace(),
            f_cons: vec![Vec3::zeros(); n],
            f_contact: if problem.contact().is_some() {
                vec![Vec3::zeros(); n]
            } else {
                Vec::new()
            },
            cache_key: 0,
            cache_time: f64::NAN,
            cache_valid: false,
            kv: if problem.damping().beta > 0.0 {
                vec![Vec3::zeros(); n]
            } else {
                Vec::new()
            },
            good: State {
                x: vec![Vec3::zeros(); n],
                v: vec![Vec3::zeros(); n],
                time: 0.0,
                contact: Vec::new(),
            },
            good_valid: false,
            steps: 0,
            since_check: 0,
            check_at_end: false,
            last_time: f64::NAN,
        })
    }

    /// Sub-steps per call to [`Integrator::step`] (more while the step
    /// control has halved the sub-step).
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// Puts in force the larger of the halvings asked for.
    fn update_substep(&mut self) {
        let halvings = self.fail_halvings.max(self.growth_halvings);
        if halvings != self.halvings {
            self.halvings = halvings;
            self.substeps = self.base_substeps << halvings;
            self.dt_sub = self.dt / f64::from(self.substeps);
            self.good_substeps = 0;
        }
    }

    /// The halvings that the stiffness growth at `x` asks for.
    fn halvings_for_growth(&self, model: &Model, x: &[Vec3]) -> u32 {
        if self.opts.unchecked {
            return 0;
        }
        // Growth may use up half the safety margin (in the step's logarithm)
        // before the sub-step is halved, so that small vibrations, which
        // change the stiffness by their amplitude, do not halve it; a step
        // at the limit (safety 1) has no margin to give, beyond round-off.
        // Only the lattice's part of omega^2 grows with its stiffness.
        let growth = self.contact_share + (1.0 - self.contact_share) * model.stiffness_growth(x);
        let wanted = self.limit / (growth * self.opts.safety).sqrt() * (1.0 + 1e-9);
        let base = self.dt / f64::from(self.base_substeps);
        (0..MAX_GROWTH_HALVINGS)
            .find(|&k| base / f64::from(1u32 << k) <= wanted)
            .unwrap_or(MAX_GROWTH_HALVINGS)
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
            let last = s + 1 == self.substeps;
            if self.since_check >= self.opts.check_interval || (last && self.check_at_end) {
                if let Some(reason) = self.check(problem.model(), state) {
                    return Attempt::Failed(reason);
                }
                let needed = self.halvings_for_growth(problem.model(), &state.x);
                if needed > self.halvings {
                    return Attempt::Stiffer(needed);
                }
                // Undo growth halvings only after several calm checks: the
                // stiffness of a rebounding body swings faster than checks.
                if needed < self.growth_halvings {
                    self.calm_checks += 1;
                    if self.calm_checks >= CALM_CHECKS {
                        self.growth_halvings -= 1;
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
        self.cache_valid = false;
    }

    /// The sub-step actually integrated (s).
    pub fn substep_dt(&self) -> f64 {
        self.dt_sub
    }

    /// Internal and external forces at `state` (cached by position and time).
    fn conservative_forces(&mut self, problem: &Problem, state: &State) {
        let model = problem.model();
        let (x, t) = (&state.x, state.time);
        model.internal_forces_with(x, &mut self.ws, &mut self.f_cons);
        for l in problem.loads() {
            l.add_forces(model, t, x, 1.0, &mut self.f_cons);
        }
    }

    /// Contact forces at `state`, which depend on its velocities and friction
    /// anchors too: evaluated at every kick, apart from the cached forces
    /// (they cost the boundary points only).
    fn contact_forces(&mut self, problem: &Problem, state: &State) {
        if let Some(c) = problem.contact() {
            let f = &mut self.f_contact;
            f.iter_mut().for_each(|v| *v = Vec3::zeros());
            c.add_forces(state.time, &state.x, &state.v, &state.contact, f);
        }
    }

    fn damping_product(&mut self, problem: &Problem, v: &[Vec3]) {
        if problem.damping().beta > 0.0 {
            par_mul(problem.rest_stiffness(), v, &mut self.kv);
        }
    }

    /// One velocity kick of `h` with the cached conservative force plus
    /// damping, on free components only. Returns false on non-finite values.
    fn kick(&self, problem: &Problem, v: &mut [Vec3], h: f64) -> bool {
        let model = problem.model();
        let masses = model.masses();
        let cons = problem.constraints();
        let d = problem.damping();
        let f = &self.f_cons;
        let fc = &self.f_contact;
        let kv = &self.kv;
        v.par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, vc)| {
                let mut ok = true;
                for (k, vi) in vc.iter_mut().enumerate() {
                    let i = ci * CHUNK + k;
                    let mut force = f[i] - *vi * (d.alpha * masses[i]);
                    if !fc.is_empty() {
                        force += fc[i];
                    }
                    if !kv.is_empty() {
                        force -= kv[i] * d.beta;
                    }
                    let dv = force * (h / masses[i]);
                    let mask = cons.mask(i);
                    for c in 0..3 {
                        if !mask[c] {
                            vi[c] += dv[c];
                        }
                    }
                    ok &= vi.iter().all(|a| a.is_finite());
                }
                ok
            })
            .reduce(|| true, |a, b| a && b)
    }

    /// `x += dt v`, then held components prescribed at `t1`.
    fn drift(problem: &Problem, state: &mut State, dt: f64, t1: f64) -> bool {
        let model = problem.model();
        let rest = model.rest_positions();
        let cons = problem.constraints();
        state
            .x
            .par_chunks_mut(CHUNK)
            .zip(state.v.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(ci, (xc, vc))| {
                let mut ok = true;
                for (k, (xi, vi)) in xc.iter_mut().zip(vc.iter_mut()).enumerate() {
                    let i = ci * CHUNK + k;
                    *xi += *vi * dt;
                    cons.prescribe(i, t1, dt, &rest[i], xi, vi);
                    ok &= xi.iter().all(|a| a.is_finite());
                }
                ok
            })
            .reduce(|| true, |a, b| a && b)
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
                if !cached {
                    self.conservative_forces(problem, state);
                }
                self.contact_forces(problem, state);
                self.damping_product(problem, &state.v);
                let mut ok = self.kick(problem, &mut state.v, 0.5 * dt);
                ok &= Self::drift(problem, state, dt, t1);
                state.time = t1;
                self.conservative_forces(problem, state);
                self.contact_forces(problem, state);
                self.damping_product(problem, &state.v);
                ok &= self.kick(problem, &mut state.v, 0.5 * dt);
                self.cache_time = t1;
                self.cache_valid = ok;
                problem.update_contact(state);
                ok
            }
            ExplicitScheme::SymplecticEuler => {
                if !cached {
                    self.conservative_forces(problem, state);
                }
                self.contact_forces(problem, state);
                self.damping_product(problem, &state.v);
                let mut ok = self.kick(problem, &mut state.v, dt);
                ok &= Self::drift(problem, state, dt, t1);
                state.time = t1;
                self.cache_valid = false;
                problem.update_contact(state);
                ok
            }
        }
    }

    fn check(&self, model: &Model, state: &State) -> Option<Divergence> {
        let (cell, strain) = max_cell_velocity_change(model, &state.v, self.dt_sub);
        if strain.is_nan() || strain > 0.25 {
            return Some(Divergence::Explosion {
                cell,
                strain_per_step: strain,
            });
        }
        check_inverted(model, &state.x)
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
const EXPLICIT_MEMORY_VERSION: u64 = 2;

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
                u64::from(self.halvings),
                u64::from(self.fail_halvings),
                u64::from(self.growth_halvings),
                u64::from(self.calm_checks),
                self.good_substeps,
                self.relax_after,
                u64::from(self.since_check),
                u64::from(self.good_valid),
                u64::from(self.cache_valid),
                self.last_time.to_bits(),
                self.cache_time.to_bits(),
                self.cache_key,
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
            halvings,
            fail_halvings,
            growth_halvings,
            calm_checks,
            good_substeps,
            relax_after,
            since_check,
            good_valid,
            cache_valid,
            last_time,
            cache_time,
            cache_key,
        ] = memory.counters.as_slice()
        else {
            return Err(bad("wrong number of counters"));
        };
        if version != EXPLICIT_MEMORY_VERSION {
            return Err(bad("written by another version"));
        }
        let n = self.f_cons.len();
        let small = |v: u64, max: u32| u32::try_from(v).ok().filter(|&v| v <= max);
        let (Some(halvings), Some(fail_halvings), Some(growth_halvings)) = (
            small(halvings, MAX_HALVINGS.max(MAX_GROWTH_HALVINGS)),
            small(fail_halvings, MAX_HALVINGS),
            small(growth_halvings, MAX_GROWTH_HALVINGS),
        ) else {
            return Err(bad("halvings out of range"));
        };
        if halvings != fail_halvings.max(growth_halvings) {
            return Err(bad("inconsistent halvings"));
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
        self.halvings = halvings;
        self.fail_halvings = fail_halvings;
        self.growth_halvings = growth_halvings;
        self.calm_checks = u32::try_from(calm_checks).map_err(|_| bad("calm checks"))?;
        self.good_substeps = good_substeps;
        self.relax_after = relax_after;
        self.since_check = u32::try_from(since_check).map_err(|_| bad("checks"))?;
        self.good_valid = good_valid != 0;
        self.cache_valid = cache_valid;
        self.last_time = f64::from_bits(last_time);
        self.cache_time = f64::from_bits(cache_time);
        self.cache_key = cache_key;
        self.substeps = self.base_substeps << halvings;
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
        }
        if !self.good_valid || self.last_time != state.time {
            // A new or externally changed state: it is the reference to fall
            // back on, and it may already be far from rest.
            self.save_good(state);
            self.since_check = 0;
            self.growth_halvings = self.halvings_for_growth(problem.model(), &state.x);
            self.update_substep();
        }
        self.steps += 1;
        let t_end = state.time + self.dt;
        self.start.x.copy_from_slice(&state.x);
        self.start.v.copy_from_slice(&state.v);
        self.start.contact.clone_from(&state.contact);
        self.start.time = state.time;
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
                        self.base_substeps << needed
                    );
                    self.restart_step(state, good_before);
                    self.growth_halvings = needed;
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
                self.fail_halvings = self.halvings + 1;
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
/// cell deforms in one step.
fn max_cell_velocity_change(model: &Model, v: &[Vec3], dt: f64) -> (u32, f64) {
    let mut worst = (0u32, 0.0f64);
    for (c, cell) in model.cells().iter().enumerate() {
        let mut mean = Vec3::zeros();
        for &k in cell {
            mean += v[k as usize];
        }
        mean /= 8.0;
        let mut m = 0.0f64;
        for &k in cell {
            m = m.max((v[k as usize] - mean).norm());
        }
        let s = m * dt / model.h();
        if s.is_nan() || s > worst.1 {
            worst = (c as u32, s);
        }
    }
    worst
}
