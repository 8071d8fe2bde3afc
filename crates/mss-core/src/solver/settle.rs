//! A settled start: the bodies brought to rest under the loads at the start
//! time before a run begins (what finite element codes call dynamic
//! relaxation), so that a run starts from equilibrium rather than from the
//! rest shape with the loads switched on at once.
//!
//! Why: an elastic body released unstressed under gravity rings, and with
//! no damping it rings forever; a block on a slope whose friction holds it
//! statically then slips a little whenever the ringing unloads its contact,
//! and walks down the slope (the undamped 4 x 4 x 2 block of the `incline`
//! example at tan 0.4, mu 0.5: 4 mm in 0.6 s). Started settled, it stays.
//!
//! How: adaptive dynamic relaxation (Underwood's). The scene's own
//! integrator steps the problem with time held at the start (every step
//! ends at the start time, so loads, prescribed motions and obstacles stay
//! at their start values), and after each step the
//! free velocities are scaled by `exp(-2 omega dt)`: mass-proportional
//! damping, critical for the frequency `omega` of the motion under way,
//! which each step estimates by a Rayleigh quotient of the step's own
//! increments (`omega^2 = -(dx . M da) / (dx . M dx)`, the accelerations
//! read off the velocity changes), so no frequency is asked of the user and
//! any integrator will do. The ringing is damped first; as the slowest
//! motion is what is left, the estimate falls to its frequency and damps it
//! critically. A body in free fall has no stiffness along its motion and is
//! not damped: a ball placed above a block falls onto it and settles there,
//! which a static solve cannot start from (only contact holds the ball, and
//! at rest it touches nothing). Contact and friction act throughout (the
//! anchors are the integrator's, kept in the [`State`]).
//!
//! It stops when the residual force on the free dofs is below `rtol` of
//! the loads (checked every [`CHECK_EVERY`] steps; the residual is the
//! net force of the last step, `M dv/dt`, the integrator's own forces).
//! Tried first and
//! dropped: kinetic damping (velocities zeroed at each peak of the kinetic
//! energy), which on the bundled squeeze reset every third step on the
//! ringing's peaks and left the slow motion crawling (residual 6e-5 of the
//! loads after 1.2 s simulated, against 1e-6 in 0.22 s here). A body that
//! never comes to rest (it slides down a slope steeper than its friction,
//! or falls with nothing below it) stops it at `max_time` with an error.

use std::sync::atomic::{AtomicBool, Ordering};

use super::statics::obstacle_travel;
use super::{Integrator, OBSTACLE_INCREMENT, Problem, SolverError, State, free_norm};
use crate::Vec3;

/// Steps between two checks of the residual force (each check costs a
/// force pass).
pub const CHECK_EVERY: u64 = 16;

/// How [`settle`] ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleOptions {
    /// Settled when the residual force on the free dofs is at most this
    /// fraction of the loads' (external and contact forces, and the held
    /// dofs' reactions).
    pub rtol: f64,
    /// Simulated time (s) after which a settle that has not come to rest
    /// fails.
    pub max_time: f64,
    /// Settle along the obstacles' paths from this time to the state's
    /// time: at successive times, each moving the obstacles by at most
    /// [`OBSTACLE_INCREMENT`] cells, as a slow press would, instead of
    /// placing them where they are at the state's time at once (a plate
    /// that ends deep in a ball would shoot it out). `None`: at the state's
    /// time only.
    pub follow_from: Option<f64>,
}

impl Default for SettleOptions {
    fn default() -> Self {
        // 1e-4: contact keeps a little chatter where points sit on the
        // edges between triangles (the bundled squeeze, settled under its
        // plate, levels off between 1e-6 and 6e-5), and a balance to a
        // ten-thousandth of the loads moves nothing a run can see.
        Self {
            rtol: 1e-4,
            max_time: 10.0,
            follow_from: None,
        }
    }
}

/// What [`settle`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleInfo {
    /// Integrator steps taken.
    pub steps: u64,
    /// The last estimate of the frequency of the motion being damped
    /// (rad/s; 0 if no step gave one).
    pub omega: f64,
    /// Simulated time the settling took (s; the state's time is back at
    /// the start).
    pub settle_time: f64,
    /// Residual force on the free dofs over the loads', at the end.
    pub relative_residual: f64,
    /// Newton iterations, for an implicit integrator.
    pub newton_iterations: u64,
}

/// Brings `state` to rest under the problem's loads at `state.time` (see
/// the module documentation), stepping with `integrator`. On success the
/// state is at equilibrium within `opts.rtol`, with zero velocities, at its
/// start time, and keeps the contacts' friction anchors; the integrator
/// then continues from it. On failure the state is where the settling got
/// to.
pub fn settle(
    problem: &Problem,
    integrator: &mut dyn Integrator,
    state: &mut State,
    opts: &SettleOptions,
) -> Result<SettleInfo, SolverError> {
    settle_cancellable(problem, integrator, state, opts, &AtomicBool::new(false))
}

/// [`settle`] that stops, with [`SolverError::SettleCancelled`] and the
/// state where it got to, once `cancel` is set (checked every step).
pub fn settle_cancellable(
    problem: &Problem,
    integrator: &mut dyn Integrator,
    state: &mut State,
    opts: &SettleOptions,
    cancel: &AtomicBool,
) -> Result<SettleInfo, SolverError> {
    if !(opts.rtol.is_finite() && opts.rtol > 0.0) {
        return Err(SolverError::BadOption(format!(
            "settle tolerance {} must be a positive number",
            opts.rtol
        )));
    }
    if !(opts.max_time.is_finite() && opts.max_time > 0.0) {
        return Err(SolverError::BadOption(format!(
            "settle time {} s must be a positive number",
            opts.max_time
        )));
    }
    let end = state.time;
    let mut total = SettleInfo {
        steps: 0,
        omega: 0.0,
        settle_time: 0.0,
        relative_residual: 0.0,
        newton_iterations: 0,
    };
    let free = problem.free_mask();
    for t in stops(problem, opts.follow_from, end) {
        state.time = t;
        let info = settle_at(
            problem,
            integrator,
            state,
            opts,
            cancel,
            &free,
            total.settle_time,
        )?;
        total.steps += info.steps;
        total.settle_time += info.settle_time;
        total.newton_iterations += info.newton_iterations;
        total.relative_residual = info.relative_residual;
        if info.omega > 0.0 {
            total.omega = info.omega;
        }
    }
    Ok(total)
}

/// The times to settle at, ending at `end`: from `from` on, the obstacles
/// move by at most [`OBSTACLE_INCREMENT`] cells between two.
fn stops(problem: &Problem, from: Option<f64>, end: f64) -> Vec<f64> {
    let (Some(t0), Some(contact)) = (from, problem.contact()) else {
        return vec![end];
    };
    if t0.is_nan() || t0 >= end {
        return vec![end];
    }
    let travel = obstacle_travel(contact, t0, end);
    let increments = (travel / (OBSTACLE_INCREMENT * problem.model().h())).ceil();
    // A bound: a path a thousand increments long is followed in a thousand.
    let k = increments.clamp(1.0, 1000.0) as usize;
    (0..=k)
        .map(|i| {
            if i == k {
                end
            } else {
                t0 + (end - t0) * i as f64 / k as f64
            }
        })
        .collect()
}

/// [`settle_cancellable`] at the state's time, `spent` seconds of the
/// budget already used.
#[allow(clippy::too_many_arguments)]
fn settle_at(
    problem: &Problem,
    integrator: &mut dyn Integrator,
    state: &mut State,
    opts: &SettleOptions,
    cancel: &AtomicBool,
    free: &[bool],
    spent: f64,
) -> Result<SettleInfo, SolverError> {
    let model = problem.model();
    let n = model.num_nodes();
    let start = state.time;
    let mut residual = Residual::new(n);
    let mut info = SettleInfo {
        steps: 0,
        omega: 0.0,
        settle_time: 0.0,
        relative_residual: residual.relative(problem, state, free),
        newton_iterations: 0,
    };
    if info.relative_residual <= opts.rtol {
        return Ok(info);
    }
    let masses = model.masses();
    // The last step's increments, for the Rayleigh quotient.
    let mut x_before = state.x.clone();
    let mut v_before = state.v.clone();
    let mut dx_prev = vec![Vec3::zeros(); n];
    let mut a_prev = vec![Vec3::zeros(); n];
    let mut have_prev = false;
    loop {
        if cancel.load(Ordering::Relaxed) {
            state.time = start;
            return Err(SolverError::SettleCancelled {
                settle_time: spent + info.settle_time,
            });
        }
        x_before.copy_from_slice(&state.x);
        v_before.copy_from_slice(&state.v);
        // Each step ends at the start time, where the residual is measured:
        // the loads, motions and obstacles its end forces see are the
        // start's (a moving obstacle stepped past it would press deeper at
        // every step than the residual knows).
        state.time = start - integrator.dt();
        let step = integrator.step(problem, state)?;
        info.steps += 1;
        info.newton_iterations += u64::from(step.newton_iterations);
        info.settle_time += step.dt;
        state.time = start;
        let dt = step.dt;
        let (mut num, mut den, mut net) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let m = masses[i];
            for d in 0..3 {
                if !free[3 * i + d] {
                    continue;
                }
                let a = (state.v[i][d] - v_before[i][d]) / dt;
                let dx = state.x[i][d] - x_before[i][d];
                let mid = 0.5 * (dx + dx_prev[i][d]);
                num -= m * (a - a_prev[i][d]) * mid;
                net += (m * a).powi(2);
                den += m * mid * mid;
                a_prev[i][d] = a;
                dx_prev[i][d] = dx;
            }
        }
        if have_prev && num > 0.0 && den > 0.0 {
            info.omega = (num / den).sqrt();
        }
        have_prev = true;
        if info.omega > 0.0 {
            scale_free_velocities(state, free, (-2.0 * info.omega * dt).exp());
        }
        // The residual is the net force of the step just taken (`M dv/dt`),
        // the forces the integrator applies: its contact with a moving
        // obstacle (whose velocity its damping sees) is not the force pass
        // of `Contact::forces`, and the run continues with the integrator.
        let net = net.sqrt();
        if info.steps.is_multiple_of(CHECK_EVERY) {
            info.relative_residual = residual.relative_to_loads(net, problem, state, free);
            log::trace!(
                "settle: step {} at {:.4e} s, omega {:.3e}/s, residual {:.3e} of the loads",
                info.steps,
                info.settle_time,
                info.omega,
                info.relative_residual
            );
            if info.relative_residual <= opts.rtol {
                scale_free_velocities(state, free, 0.0);
                return Ok(info);
            }
        }
        if spent + info.settle_time >= opts.max_time {
            info.relative_residual = residual.relative_to_loads(net, problem, state, free);
            return Err(SolverError::NotSettled {
                max_time: opts.max_time,
                relative_residual: info.relative_residual,
                rtol: opts.rtol,
            });
        }
    }
}

/// Multiplies the free velocity components by `factor`.
fn scale_free_velocities(state: &mut State, free: &[bool], factor: f64) {
    for (i, v) in state.v.iter_mut().enumerate() {
        for d in 0..3 {
            if free[3 * i + d] {
                v[d] *= factor;
            }
        }
    }
}

/// Scratch for the residual force at a state at rest.
struct Residual {
    internal: Vec<Vec3>,
    loads: Vec<Vec3>,
}

impl Residual {
    fn new(n: usize) -> Self {
        Self {
            internal: vec![Vec3::zeros(); n],
            loads: vec![Vec3::zeros(); n],
        }
    }

    /// The residual force on the free dofs over the loads' norm (external
    /// and contact forces on the free dofs, reactions on the held ones), as
    /// a static solve measures it; the absolute residual when nothing
    /// loads the bodies.
    fn relative(&mut self, problem: &Problem, state: &State, free: &[bool]) -> f64 {
        let (res, scale) = self.measure(problem, state, free);
        if scale > 0.0 { res / scale } else { res }
    }

    /// `net` (N) over the loads' norm at `state` (`net` itself when nothing
    /// loads the bodies).
    fn relative_to_loads(
        &mut self,
        net: f64,
        problem: &Problem,
        state: &State,
        free: &[bool],
    ) -> f64 {
        let (_, scale) = self.measure(problem, state, free);
        if scale > 0.0 { net / scale } else { net }
    }

    /// The residual force's norm on the free dofs and the loads' norm.
    fn measure(&mut self, problem: &Problem, state: &State, free: &[bool]) -> (f64, f64) {
        problem
            .model()
            .internal_forces(&state.x, &mut self.internal);
        self.loads.fill(Vec3::zeros());
        problem.external_forces(state.time, &state.x, 1.0, &mut self.loads);
        if let Some(c) = problem.contact() {
            c.add_forces(
                state.time,
                &state.x,
                &state.v,
                &state.contact,
                &mut self.loads,
            );
        }
        let mut scale = 0.0;
        for (i, (load, internal)) in self.loads.iter().zip(&self.internal).enumerate() {
            for d in 0..3 {
                scale += if free[3 * i + d] {
                    load[d] * load[d]
                } else {
                    (load[d] + internal[d]).powi(2)
                };
            }
        }
        for (f, load) in self.internal.iter_mut().zip(&self.loads) {
            *f += load;
        }
        (free_norm(&self.internal, free), scale.sqrt())
    }
}
