//! Explicit time stepping: velocity Verlet (default) and symplectic Euler.
//!
//! Both are conditionally stable: `dt < 2 / omega_max` without damping. The
//! limit used here is `safety * 4 / (sqrt(c^2 + 4 w^2) + c)` with
//! `w = 2 / Model::critical_time_step()` (an upper bound of omega_max at rest)
//! and `c = alpha + beta w^2` the damping rate of the highest mode: the exact
//! stability bound of symplectic Euler for a damped oscillator, which reduces
//! to `safety * 2 / w` without damping.
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
    let w = 2.0 / problem.model().critical_time_step();
    let d = problem.damping();
    let c = d.alpha + d.beta * w * w;
    safety * 4.0 / ((c * c + 4.0 * w * w).sqrt() + c)
}

/// The explicit integrator.
#[derive(Debug)]
pub struct Explicit {
    opts: ExplicitOptions,
    dt: f64,
    dt_sub: f64,
    substeps: u32,
    ws: ForceWorkspace,
    /// Conservative force (internal + external) at `cache_x`, `cache_time`.
    f_cons: Vec<Vec3>,
    cache_x: Vec<Vec3>,
    cache_time: f64,
    cache_valid: bool,
    /// `K0 v` for stiffness-proportional damping.
    kv: Vec<Vec3>,
    good: State,
    good_valid: bool,
    steps: u64,
    since_check: u32,
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
            ws: problem.model().workspace(),
            f_cons: vec![Vec3::zeros(); n],
            cache_x: vec![Vec3::zeros(); n],
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
            },
            good_valid: false,
            steps: 0,
            since_check: 0,
            last_time: f64::NAN,
        })
    }

    /// Sub-steps per call to [`Integrator::step`].
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// The sub-step actually integrated (s).
    pub fn substep_dt(&self) -> f64 {
        self.dt_sub
    }

    fn conservative_forces(&mut self, problem: &Problem, x: &[Vec3], t: f64) {
        let model = problem.model();
        model.internal_forces_with(x, &mut self.ws, &mut self.f_cons);
        for l in problem.loads() {
            l.add_forces(model, t, x, 1.0, &mut self.f_cons);
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
        let kv = &self.kv;
        v.par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(ci, vc)| {
                let mut ok = true;
                for (k, vi) in vc.iter_mut().enumerate() {
                    let i = ci * CHUNK + k;
                    let mut force = f[i] - *vi * (d.alpha * masses[i]);
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
        let cached = self.cache_valid && self.cache_time == t0 && self.cache_x == state.x;
        match self.opts.scheme {
            ExplicitScheme::VelocityVerlet => {
                if !cached {
                    self.conservative_forces(problem, &state.x, t0);
                }
                self.damping_product(problem, &state.v);
                let mut ok = self.kick(problem, &mut state.v, 0.5 * dt);
                ok &= Self::drift(problem, state, dt, t1);
                self.conservative_forces(problem, &state.x, t1);
                self.damping_product(problem, &state.v);
                ok &= self.kick(problem, &mut state.v, 0.5 * dt);
                state.time = t1;
                self.cache_x.copy_from_slice(&state.x);
                self.cache_time = t1;
                self.cache_valid = ok;
                ok
            }
            ExplicitScheme::SymplecticEuler => {
                if !cached {
                    self.conservative_forces(problem, &state.x, t0);
                }
                self.damping_product(problem, &state.v);
                let mut ok = self.kick(problem, &mut state.v, dt);
                ok &= Self::drift(problem, state, dt, t1);
                state.time = t1;
                self.cache_valid = false;
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
        self.good.time = state.time;
        self.good_valid = true;
    }
}

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

    fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        state.check_size(problem.model())?;
        if !self.good_valid || self.last_time != state.time {
            // A new or externally changed state: it is the reference to fall back on.
            self.save_good(state);
            self.since_check = 0;
        }
        self.steps += 1;
        let t_end = state.time + self.dt;
        for s in 0..self.substeps {
            let ok = self.substep(problem, state);
            self.since_check += 1;
            let last = s + 1 == self.substeps;
            let failure = if !ok {
                Some(Divergence::NonFinite)
            } else if self.since_check >= self.opts.check_interval {
                self.check(problem.model(), state)
            } else {
                None
            };
            if let Some(reason) = failure {
                let time = state.time;
                state.x.copy_from_slice(&self.good.x);
                state.v.copy_from_slice(&self.good.v);
                state.time = self.good.time;
                self.cache_valid = false;
                return Err(SolverError::Diverged {
                    solver: "explicit",
                    step: self.steps,
                    time,
                    reason,
                    kept_time: self.good.time,
                    hint: EXPLICIT_HINT,
                });
            }
            if self.since_check >= self.opts.check_interval {
                self.since_check = 0;
                if last {
                    state.time = t_end;
                }
                self.save_good(state);
            }
        }
        // Sub-step times accumulate round-off: land exactly on the step's end.
        state.time = t_end;
        self.last_time = t_end;
        if self.cache_valid {
            self.cache_time = t_end;
        }
        Ok(StepInfo {
            time: state.time,
            dt: self.dt,
            substeps: self.substeps,
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
