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

use super::linear::LinearSolver;
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
    /// Kept factors from a checkpoint, for the linear solver once made.
    restored_factors: std::cell::RefCell<Option<(u64, Vec<f64>)>>,
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
            restored_factors: std::cell::RefCell::new(None),
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
                if let Some((key, values)) = self.restored_factors.take() {
                    linear.restore_kept_factors(key, values);
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
        // The step count (in messages), and the direct solver's kept
        // factors: they precondition the next steps' solves, whose results
        // then differ from fresh factors' in the last bits. (The symbolic
        // analysis is the same for the same pattern.)
        let linear = self.linear.borrow();
        let restored = self.restored_factors.borrow();
        let kept = match linear.as_ref() {
            Some(linear) => linear.kept_factors(),
            None => restored
                .as_ref()
                .map(|(key, values)| (*key, values.as_slice())),
        };
        match kept {
            Some((key, values)) => super::IntegratorMemory {
                counters: vec![self.steps, key],
                values: values.to_vec(),
                ..Default::default()
            },
            None => super::IntegratorMemory {
                counters: vec![self.steps],
                ..Default::default()
            },
        }
    }

    fn restore(&mut self, memory: &super::IntegratorMemory) -> Result<(), SolverError> {
        match memory.counters.as_slice() {
            [steps] if memory.values.is_empty() && memory.states.is_empty() => {
                self.steps = *steps;
                self.restored_factors.replace(None);
                if let Some(linear) = self.linear.get_mut() {
                    linear.drop_kept_factors();
                }
                Ok(())
            }
            [steps, key] if memory.states.is_empty() => {
                self.steps = *steps;
                let factors = (*key, memory.values.clone());
                match self.linear.get_mut() {
                    Some(linear) => linear.restore_kept_factors(factors.0, factors.1),
                    None => {
                        self.restored_factors.replace(Some(factors));
                    }
                }
                Ok(())
            }
            _ => Err(SolverError::BadOption(
                "the checkpoint's integrator memory is not the implicit integrator's".into(),
            )),
        }
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
        let model = self.problem.model();
        let mut k = model.symmetric_stiffness_upper(x);
        let inertia = self.inertia_factor();
        for (i, m) in model.masses().iter().enumerate() {
            let d = k.upper.find(i, i).expect("diagonal in the lattice pattern");
            k.upper.blocks[d] += Mat3::identity() * (m * inertia);
        }
        Some(k)
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
