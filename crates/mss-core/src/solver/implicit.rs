//! Implicit backward Euler.
//!
//! Unknown: the positions `x` at `t + dt`; velocities `v = (x - x_n) / dt`.
//! Newton solves, on the free dofs,
//! `R(x) = f_int(x) + f_ext(t + dt, x) - alpha M v - beta K0 v - M (v - v_n) / dt = 0`
//! with the exact tangent of the internal forces (non-symmetric at large strain
//! with correction forces), the loads' Jacobians and the damping terms, a
//! sparse LU solve (or multigrid Krylov) and a line search on the slope of
//! the step's incremental energy (`|R|` rises along Newton steps that turn
//! the body while the energy falls; backtracking on `|R|` is the fallback
//! where the slope does not descend). If Newton fails or
//! cells invert, the step is retried as two half steps (recursively, up to
//! `max_halvings` times) before giving up.
//!
//! Backward Euler is unconditionally stable and dissipative: it damps high
//! frequencies, so use it for large steps and settling, not for energy studies.
#![allow(clippy::needless_range_loop)] // loops over several per-node arrays at once

use super::linear::{KeptHierarchy, LinearSolver, StiffnessOrigin};
use super::{
    Divergence, IMPLICIT_HINT, Integrator, NewtonFailure, NewtonOptions, NonlinearSystem, Problem,
    SolverError, State, StepInfo, check_inverted, newton,
};
use crate::{BlockCsr, Mat3, Vec3};

/// Options of [`Implicit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImplicitOptions {
    /// Time step (s).
    pub dt: f64,
    /// Newton iterations per step before the step is halved.
    pub max_newton: u32,
    /// Newton tolerance: residual over free dofs relative to the largest
    /// force term (inertia, internal or external).
    pub rtol: f64,
    /// How many times a failing step may be halved.
    pub max_halvings: u32,
    /// The linear solver of the Newton steps (default: chosen by size).
    pub linear_solver: super::LinearSolverKind,
    /// Free dofs above which the iterative Newton solves keep no matrix:
    /// the Krylov products use the tangent's action (`Model::tangent_mul`
    /// and the mass term), the multigrid hierarchy is built from the
    /// symmetric part held once per pair of blocks, and a tangent's
    /// hierarchy preconditions the later tangents, of this step and the
    /// next ones, while it serves them (`NewtonOptions::keep_hierarchy`); for problems
    /// whose Jacobian is the model's tangent and the mass term alone (no
    /// contact, loads that do not depend on positions, no stiffness
    /// damping). Default [`IMPLICIT_MATRIX_FREE_ABOVE`].
    pub matrix_free_above: usize,
}

/// Default of [`ImplicitOptions::matrix_free_above`]: where the iterative
/// solver takes over from the direct one. A static solve keeps the matrix up
/// to where a stalled iterative solve may fall back to a direct one
/// ([`super::MATRIX_FREE_ABOVE`]); an implicit step's system has the mass
/// term on its diagonal, and a step whose solve fails is halved instead.
/// docs/solvers.md ("Matrix-free or assembled") has the measurements.
pub const IMPLICIT_MATRIX_FREE_ABOVE: usize = super::linear::DIRECT_MAX_FREE_DOFS;

impl Default for ImplicitOptions {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            max_newton: super::DEFAULT_MAX_NEWTON,
            rtol: super::DEFAULT_NEWTON_RTOL,
            max_halvings: 4,
            linear_solver: super::LinearSolverKind::Auto,
            matrix_free_above: IMPLICIT_MATRIX_FREE_ABOVE,
        }
    }
}

/// The backward Euler integrator.
#[derive(Debug)]
pub struct Implicit {
    opts: ImplicitOptions,
    free: Vec<bool>,
    steps: u64,
    /// The linear solver (symbolic LU analysis or multigrid structure),
    /// reused over steps; made at the first step.
    linear: std::cell::RefCell<Option<super::linear::LinearSolver>>,
    /// What a checkpoint gave of the linear solver's kept state, put back
    /// at the next step (the hierarchy needs the model to be built).
    restored: std::cell::RefCell<KeptSolver>,
}

/// The linear solver's state that its next solves depend on beyond the
/// step's state: the direct solver's kept factors (as their pattern's key and
/// their matrix), or a matrix-free hierarchy (as what built it).
#[derive(Debug, Clone, Default, PartialEq)]
struct KeptSolver {
    factors: Option<(u64, Vec<f64>)>,
    hierarchy: Option<KeptHierarchy>,
}

/// Tags of [`KeptSolver`]'s records in an [`IntegratorMemory`](super::IntegratorMemory)'s counters.
const FACTORS_RECORD: u64 = 1;
const HIERARCHY_RECORD: u64 = 2;

impl KeptSolver {
    /// Appends the records to a memory's counters and values.
    fn write(&self, counters: &mut Vec<u64>, values: &mut Vec<f64>) {
        if let Some((key, matrix)) = &self.factors {
            counters.extend([FACTORS_RECORD, *key, matrix.len() as u64]);
            values.extend_from_slice(matrix);
        }
        if let Some(h) = &self.hierarchy {
            counters.extend([
                HIERARCHY_RECORD,
                h.origin.shift.to_bits(),
                h.fresh_rate.to_bits(),
                h.newton_scale.to_bits(),
                u64::from(h.symmetric),
                h.origin.x.len() as u64,
            ]);
            values.extend(h.origin.x.iter().flat_map(|p| [p.x, p.y, p.z]));
        }
    }

    /// Reads what [`KeptSolver::write`] wrote; `None` if it is not that.
    fn read(mut counters: &[u64], values: &[f64]) -> Option<Self> {
        let mut kept = Self::default();
        let mut used = 0usize;
        let mut take = |len: u64| -> Option<&[f64]> {
            let len = usize::try_from(len).ok()?;
            let end = used.checked_add(len)?;
            let part = values.get(used..end)?;
            used = end;
            Some(part)
        };
        while let Some((&tag, rest)) = counters.split_first() {
            match (tag, rest) {
                (FACTORS_RECORD, [key, len, rest @ ..]) if kept.factors.is_none() => {
                    kept.factors = Some((*key, take(*len)?.to_vec()));
                    counters = rest;
                }
                (HIERARCHY_RECORD, [shift, rate, scale, symmetric @ (0 | 1), nodes, rest @ ..])
                    if kept.hierarchy.is_none() =>
                {
                    let x = take(nodes.checked_mul(3)?)?
                        .chunks_exact(3)
                        .map(|c| Vec3::new(c[0], c[1], c[2]))
                        .collect();
                    kept.hierarchy = Some(KeptHierarchy {
                        origin: StiffnessOrigin {
                            x,
                            shift: f64::from_bits(*shift),
                        },
                        fresh_rate: f64::from_bits(*rate),
                        symmetric: *symmetric == 1,
                        newton_scale: f64::from_bits(*scale),
                    });
                    counters = rest;
                }
                _ => return None,
            }
        }
        (used == values.len()).then_some(kept)
    }
}

impl Implicit {
    /// Creates the integrator.
    pub fn new(problem: &Problem, opts: ImplicitOptions) -> Result<Self, SolverError> {
        if !(opts.dt.is_finite() && opts.dt > 0.0) {
            return Err(SolverError::BadTimeStep(opts.dt));
        }
        if !(opts.rtol > 0.0 && opts.max_newton > 0) {
            return Err(SolverError::BadOption(format!(
                "implicit: rtol {} must be > 0 and max_newton {} >= 1",
                opts.rtol, opts.max_newton
            )));
        }
        Ok(Self {
            opts,
            free: problem.free_mask(),
            steps: 0,
            linear: std::cell::RefCell::new(None),
            restored: std::cell::RefCell::new(KeptSolver::default()),
        })
    }

    /// What the Newton iterations' linear solver did over the steps so far
    /// (solves, Krylov iterations, hierarchies built).
    pub fn linear_stats(&self) -> super::LinearStats {
        self.linear
            .borrow()
            .as_ref()
            .map_or_else(super::LinearStats::default, |l| l.stats())
    }

    /// One backward Euler step of `dt` from `state` (not modified on failure).
    fn try_step(
        &self,
        problem: &Problem,
        state: &State,
        dt: f64,
    ) -> Result<(State, u32), Divergence> {
        let model = problem.model();
        let rest = model.rest_positions();
        let t1 = state.time + dt;
        let mut x: Vec<Vec3> = state
            .x
            .iter()
            .zip(&state.v)
            .map(|(x, v)| x + v * dt)
            .collect();
        let mut v1 = state.v.clone();
        for n in 0..model.num_nodes() {
            let mut xn = state.x[n];
            problem
                .constraints()
                .prescribe(n, t1, dt, &rest[n], &mut xn, &mut v1[n]);
            let mask = problem.constraints().mask(n);
            for d in 0..3 {
                if mask[d] {
                    x[n][d] = xn[d];
                }
            }
        }
        let anchors = match problem.contact() {
            Some(c) => c.step_anchors(state.time, &state.x, &state.contact),
            None => Vec::new(),
        };
        let mut sys = BackwardEuler {
            problem,
            x0: &state.x,
            v0: &state.v,
            anchors: &anchors,
            t1,
            dt,
            scratch: vec![Vec3::zeros(); model.num_nodes()],
            kv: vec![Vec3::zeros(); model.num_nodes()],
            v1: vec![Vec3::zeros(); model.num_nodes()],
        };
        let its = newton(
            &mut sys,
            &mut x,
            &self.free,
            problem.size(),
            model.h(),
            NewtonOptions {
                max_iterations: self.opts.max_newton,
                rtol: self.opts.rtol,
                slope_line_search: true,
                keep_hierarchy: true,
            },
            self.linear.borrow_mut().get_or_insert_with(|| {
                let mut linear = LinearSolver::new(model, self.opts.linear_solver);
                linear.set_matrix_free_above(self.opts.matrix_free_above);
                let restored = self.restored.take();
                if let Some((key, values)) = restored.factors {
                    linear.restore_kept_factors(key, values);
                }
                // (A memory for another lattice or with non-finite values
                // is not used: a checkpoint's checksum does not vouch for
                // the program that wrote it.)
                if let Some(kept) = restored.hierarchy.filter(|k| {
                    k.origin.x.len() == model.num_nodes()
                        && k.origin.x.iter().all(|p| p.iter().all(|c| c.is_finite()))
                        && k.origin.shift.is_finite()
                }) {
                    let k = shifted_symmetric_stiffness(model, &kept.origin.x, kept.origin.shift);
                    // A hierarchy that cannot be built again is not kept:
                    // the step builds its own.
                    if let Err(e) = linear.restore_kept_hierarchy(k, &self.free, kept) {
                        log::warn!(
                            "the checkpoint's multigrid hierarchy was not built again: {e:?}"
                        );
                    }
                }
                linear
            }),
        )
        .map_err(|e| match e {
            NewtonFailure::Diverged(d) => d,
            // A singular Jacobian with mass on the diagonal means garbage values.
            NewtonFailure::Singular(_) | NewtonFailure::Linear(_) | NewtonFailure::Cancelled => {
                Divergence::NonFinite
            }
        })?;
        if let Some(d) = check_inverted(model, &x) {
            return Err(d);
        }
        for n in 0..model.num_nodes() {
            let mask = problem.constraints().mask(n);
            for d in 0..3 {
                if !mask[d] {
                    v1[n][d] = (x[n][d] - state.x[n][d]) / dt;
                }
            }
        }
        let mut next = State {
            x,
            v: v1,
            time: t1,
            contact: anchors,
        };
        problem.update_contact(&mut next);
        Ok((next, its))
    }

    /// Advances by `dt`, halving on failure; returns the new state, Newton
    /// iterations and sub-steps.
    fn advance(
        &self,
        problem: &Problem,
        state: &State,
        dt: f64,
        depth: u32,
    ) -> Result<(State, u32, u32), Divergence> {
        match self.try_step(problem, state, dt) {
            Ok((s, its)) => Ok((s, its, 1)),
            Err(e) if depth >= self.opts.max_halvings => Err(e),
            Err(e) => {
                log::warn!(
                    "implicit step of {dt:.3e} s at t = {:.3e} s failed ({e}); retrying as two half steps",
                    state.time
                );
                let (s1, i1, n1) = self.advance(problem, state, 0.5 * dt, depth + 1)?;
                let (s2, i2, n2) = self.advance(problem, &s1, 0.5 * dt, depth + 1)?;
                Ok((s2, i1 + i2, n1 + n2))
            }
        }
    }
}

impl Integrator for Implicit {
    fn name(&self) -> &'static str {
        "implicit"
    }

    fn dt(&self) -> f64 {
        self.opts.dt
    }

    fn memory(&self) -> super::IntegratorMemory {
        // The step count (in messages), and what the linear solver keeps
        // from one step to the next: the next solves are preconditioned by
        // it, and their results differ from a fresh solver's in the last
        // bits.
        let kept = match self.linear.borrow().as_ref() {
            Some(linear) => KeptSolver {
                factors: linear
                    .kept_factors()
                    .map(|(key, values)| (key, values.to_vec())),
                hierarchy: linear.kept_hierarchy(),
            },
            None => self.restored.borrow().clone(),
        };
        let mut memory = super::IntegratorMemory {
            counters: vec![self.steps],
            ..Default::default()
        };
        kept.write(&mut memory.counters, &mut memory.values);
        memory
    }

    fn restore(&mut self, memory: &super::IntegratorMemory) -> Result<(), SolverError> {
        let kept = match memory.counters.split_first() {
            Some((steps, records)) if memory.states.is_empty() => {
                KeptSolver::read(records, &memory.values).map(|kept| (*steps, kept))
            }
            _ => None,
        };
        let Some((steps, kept)) = kept else {
            return Err(SolverError::BadOption(
                "the checkpoint's integrator memory is not the implicit integrator's".into(),
            ));
        };
        self.steps = steps;
        // The next step makes its linear solver with what was kept.
        *self.linear.get_mut() = None;
        *self.restored.get_mut() = kept;
        Ok(())
    }

    fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        crate::on_worker(|| self.step_here(problem, state))
    }
}

impl Implicit {
    /// [`Integrator::step`], on the thread it is called on.
    fn step_here(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        state.check_size(problem.model())?;
        self.steps += 1;
        let t_end = state.time + self.opts.dt;
        match self.advance(problem, state, self.opts.dt, 0) {
            Ok((mut s, its, n)) => {
                s.time = t_end;
                *state = s;
                Ok(StepInfo {
                    time: t_end,
                    dt: self.opts.dt,
                    substeps: n,
                    newton_iterations: its,
                })
            }
            Err(reason) => Err(SolverError::Diverged {
                solver: "implicit",
                step: self.steps,
                time: t_end,
                reason,
                kept_time: state.time,
                hint: IMPLICIT_HINT,
            }),
        }
    }
}

impl BackwardEuler<'_> {
    /// `(1 + alpha dt) / dt^2`: the inertia and mass damping's part of the
    /// Jacobian per unit mass (on the diagonal, with a minus sign).
    fn inertia_factor(&self) -> f64 {
        let dt = self.dt;
        (1.0 + self.problem.damping().alpha * dt) / (dt * dt)
    }
}

/// The model's symmetric stiffness at `x` with `shift` times the masses on
/// its diagonal.
fn shifted_symmetric_stiffness(
    model: &crate::Model,
    x: &[Vec3],
    shift: f64,
) -> crate::sparse::SymmetricUpper {
    let mut k = model.symmetric_stiffness_upper(x);
    for (i, m) in model.masses().iter().enumerate() {
        let d = k.upper.find(i, i).expect("diagonal in the lattice pattern");
        k.upper.blocks[d] += Mat3::identity() * (m * shift);
    }
    k
}

struct BackwardEuler<'a> {
    problem: &'a Problem,
    x0: &'a [Vec3],
    v0: &'a [Vec3],
    /// Friction anchors at the start of the step (held during it).
    anchors: &'a [Option<Vec3>],
    t1: f64,
    dt: f64,
    scratch: Vec<Vec3>,
    kv: Vec<Vec3>,
    /// Velocities `(x - x0) / dt` of the iterate.
    v1: Vec<Vec3>,
}

impl NonlinearSystem for BackwardEuler<'_> {
    fn residual(&mut self, x: &[Vec3], r: &mut [Vec3]) -> f64 {
        let p = self.problem;
        let model = p.model();
        let masses = model.masses();
        let d = p.damping();
        let dt = self.dt;
        model.internal_forces(x, r);
        p.external_forces(self.t1, x, 1.0, &mut self.scratch);
        if let Some(c) = p.contact() {
            for i in 0..x.len() {
                self.v1[i] = (x[i] - self.x0[i]) / dt;
            }
            c.add_forces(self.t1, x, &self.v1, self.anchors, &mut self.scratch);
        }
        let (mut s_int, mut s_ext, mut s_in) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..x.len() {
            s_int += r[i].norm_squared();
            s_ext += self.scratch[i].norm_squared();
            r[i] += self.scratch[i];
        }
        // Damping with v = (x - x0) / dt.
        if d.beta > 0.0 {
            for i in 0..x.len() {
                self.scratch[i] = (x[i] - self.x0[i]) / dt;
            }
            p.rest_stiffness().mul_vec(&self.scratch, &mut self.kv);
        }
        for i in 0..x.len() {
            let v = (x[i] - self.x0[i]) / dt;
            let inertia = (v - self.v0[i]) * (masses[i] / dt);
            s_in += inertia.norm_squared();
            r[i] -= inertia + v * (d.alpha * masses[i]);
            if d.beta > 0.0 {
                r[i] -= self.kv[i] * d.beta;
            }
        }
        s_int.sqrt().max(s_ext.sqrt()).max(s_in.sqrt())
    }

    fn has_jacobian_mul(&self) -> bool {
        // The Jacobian is the model's tangent and the mass term alone: no
        // contact, loads that do not depend on positions, no stiffness
        // damping (its rest stiffness would be one more product).
        let p = self.problem;
        p.contact().is_none()
            && p.damping().beta == 0.0
            && p.loads().iter().all(|l| l.independent_of_positions())
    }

    fn jacobian_mul(&self, x: &[Vec3], v: &[Vec3], out: &mut [Vec3]) {
        let p = self.problem;
        p.model().tangent_mul(x, v, out);
        let inertia = self.inertia_factor();
        for ((o, vi), m) in out.iter_mut().zip(v).zip(p.model().masses()) {
            *o -= vi * (m * inertia);
        }
    }

    fn symmetric_stiffness(&mut self, x: &[Vec3]) -> Option<crate::sparse::SymmetricUpper> {
        if !self.has_jacobian_mul() {
            return None;
        }
        Some(shifted_symmetric_stiffness(
            self.problem.model(),
            x,
            self.inertia_factor(),
        ))
    }

    fn stiffness_shift(&self) -> f64 {
        self.inertia_factor()
    }

    fn jacobian(&mut self, x: &[Vec3]) -> BlockCsr {
        let p = self.problem;
        let model = p.model();
        let dt = self.dt;
        let d = p.damping();
        let mut j = model.tangent(x);
        for l in p.loads() {
            l.add_jacobian(model, self.t1, x, 1.0, &mut j);
        }
        let inertia = self.inertia_factor();
        for (i, &m) in model.masses().iter().enumerate() {
            let k = j.find(i, i).expect("diagonal in the lattice pattern");
            j.blocks[k] -= Mat3::identity() * (m * inertia);
        }
        if d.beta > 0.0 {
            let k0 = p.rest_stiffness();
            debug_assert_eq!(k0.col_indices, j.col_indices);
            for (b, k) in j.blocks.iter_mut().zip(&k0.blocks) {
                *b -= k * (d.beta / dt);
            }
        }
        // Last: contact between bodies may grow the pattern.
        if let Some(c) = p.contact() {
            for i in 0..x.len() {
                self.v1[i] = (x[i] - self.x0[i]) / dt;
            }
            c.add_jacobian(self.t1, x, &self.v1, self.anchors, 1.0 / dt, &mut j);
        }
        j
    }
}
