//! Static equilibrium: `f_int(x) + f_ext(t, x) = 0` on the free dofs.
//!
//! Newton's method with the exact tangent, a sparse LU solve and a
//! backtracking line search, inside adaptive load stepping: the loads and the
//! prescribed displacements are scaled by a load factor that goes from 0 to 1,
//! in one increment if Newton converges, in halved increments if not.
//! Convergence: residual over the free dofs below `rtol` times the norm of the
//! external load (including the reactions of held dofs, so that problems
//! driven by prescribed displacements have a scale too).
//!
//! Mechanisms (rigid motions or the lattice's hourglass modes left free by the
//! boundary conditions) make the tangent singular: they are reported as
//! [`SolverError::Mechanism`].
#![allow(clippy::needless_range_loop)] // loops over several per-node arrays at once

use super::linear::{LinearSolver, LinearSolverKind, LinearStats, Stiffness};
use super::{
    Divergence, NewtonFailure, NewtonOptions, NonlinearSystem, Problem, STATIC_HINT, SolverError,
    State, check_inverted, free_norm, newton,
};
use crate::{BlockCsr, Vec3};
use std::sync::atomic::{AtomicBool, Ordering};

/// The error text of a static problem that is singular at rest.
const MECHANISM_MESSAGE: &str = "the stiffness matrix is singular: the boundary conditions leave a mechanism free (a rigid motion, or one of the 3 hourglass modes of the lattice); fix a whole face, or more nodes spread over the body";

/// The error text of a static problem singular at rest whose free nodes
/// `nodes` show: a body of several that nothing holds but contact, and that
/// touches nothing firmly enough at rest (a ball a little above the block it
/// is to be pressed into), is a different remedy from a body held too little.
fn mechanism_message(problem: &Problem, nodes: &[u32]) -> String {
    let model = problem.model();
    let free_body = (model.bodies().len() > 1 && problem.contact().is_some())
        .then(|| nodes.first().map(|&n| model.body_of_node(n as usize)))
        .flatten()
        .filter(|&b| {
            let held = |n: usize| problem.constraints().mask(n).iter().any(|&h| h);
            !model.bodies()[b].nodes.clone().any(held)
        });
    match free_body {
        Some(b) => format!(
            "body {} (counted from 1) has no fixed node and only contact holds it, but at rest it \
             touches nothing firmly enough to stop its rigid motions: Newton cannot start \
             from there; settle it first (solver::settle, which lets it fall and rest on the \
             others), start it touching, or fix a region of it",
            b + 1
        ),
        None => MECHANISM_MESSAGE.into(),
    }
}

/// Options of [`solve_static`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticOptions {
    /// Relative residual to reach (default [`super::DEFAULT_NEWTON_RTOL`]).
    pub rtol: f64,
    /// Newton iterations per load increment before the increment is halved.
    pub max_newton: u32,
    /// First load increment (fraction of the full load; default 1).
    pub initial_load_increment: f64,
    /// Smallest load increment before giving up (default 1/1024).
    pub min_load_increment: f64,
    /// The linear solver of the Newton steps (default: chosen by size).
    pub linear_solver: LinearSolverKind,
    /// Solve the small-strain (linearized) problem once instead of the
    /// nonlinear one: `K0 u = f` with the rest tangent (default false).
    pub small_strain: bool,
    /// Keep an equilibrium whose stiffness is not positive definite instead
    /// of returning [`SolverError::UnstableEquilibrium`] (default false).
    pub accept_unstable: bool,
    /// The time at which the starting state was in equilibrium with the
    /// obstacles (a body at rest at time 0: `Some(0.0)`): when an obstacle
    /// ends more than [`FOLLOW_DEPTH`] cells inside the starting state, the
    /// solve moves the obstacles along their paths from that time to the
    /// state's, at most [`OBSTACLE_INCREMENT`] of a cell per load increment,
    /// as a slow press would, friction anchors following. `None` (the default),
    /// or a path that moved too little to follow: the obstacles are where they
    /// are at the state's time, and one that starts more than [`FOLLOW_DEPTH`]
    /// cells in is inserted there from outside along its shortest way out
    /// (placed at once, a box 1.2 cells into a block pushed its nodes out
    /// through its side faces and gave a seventh of the force).
    pub obstacles_from: Option<f64>,
    /// Solve even when the held nodes leave zero-energy modes (default
    /// false: [`SolverError::Mechanism`]). The answer is then one of many:
    /// the one the LU's round-off pivots pick, which a load that does not
    /// excite the modes leaves meaningful. For studies of the lattice
    /// itself (the validation experiments' 4 x 1 x 1 beams), not for
    /// scenes.
    pub accept_mechanisms: bool,
    /// Free dofs above which the iterative Newton solves keep no `f64`
    /// tangent: the multigrid hierarchy drops it once it has its
    /// single-precision copy, and the Krylov products use the tangent's
    /// action (`Model::tangent_mul`); for problems whose Jacobian is the
    /// model's tangent alone (no contact, loads that do not depend on
    /// positions). Default [`MATRIX_FREE_ABOVE`].
    pub matrix_free_above: usize,
}

/// Default of [`StaticOptions::matrix_free_above`] (about 10,000 nodes):
/// where a stalled iterative solve can no longer fall back to a direct one
/// (which needs the assembled matrix). Above it the action, evaluated on
/// packs of cells, costs 0.4 to 1.4 times the assembled product (less the
/// larger the lattice, once the matrix has left the cache), and a solve
/// skips assembling the `f64` tangent (20 to 40 products' worth each time)
/// and holding it (2 GB at a million nodes): docs/solvers.md, "Matrix-free
/// or assembled".
pub const MATRIX_FREE_ABOVE: usize = super::linear::FALLBACK_MAX_FREE_DOFS;

/// How far an obstacle moves along its path per load increment of a static
/// solve that follows it (in cells of the model).
pub const OBSTACLE_INCREMENT: f64 = 0.25;

/// How deep (in cells) an obstacle must end inside the starting state for a
/// static solve to follow it along its path.
pub const FOLLOW_DEPTH: f64 = 0.5;

/// The deepest that any point of `contact` at `x` lies inside an obstacle
/// at time `t` (m; 0 when none does).
fn deepest_overlap(contact: &crate::contact::Contact, t: f64, x: &[Vec3]) -> f64 {
    let points = contact.point_positions(x);
    contact
        .obstacles()
        .flat_map(|(o, _)| points.iter().filter_map(move |&p| o.penetration(t, p)))
        .map(|pen| pen.depth)
        .fold(0.0, f64::max)
}

/// Where each obstacle of `contact` (at time `t`) leaves the body `x` with
/// the least travel: the shortest translation along the three axes (either
/// way) and against the mean push on the points inside it that leaves no
/// point of `x` inside it (to a thousandth of `h`); zero for an obstacle at
/// most [`FOLLOW_DEPTH`] cells in, or one that no such translation frees
/// (a ground under the whole body frees along its normal).
fn exit_shifts(contact: &crate::contact::Contact, t: f64, x: &[Vec3], h: f64) -> Vec<Vec3> {
    use rayon::prelude::*;
    let points = contact.point_positions(x);
    let size = {
        let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
        for p in &points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (hi - lo).norm()
    };
    contact
        .obstacles()
        .map(|(o, _)| {
            // The deepest point inside the obstacle moved by `shift` (order-free
            // maximum: the same for any thread count).
            let depth = |shift: Vec3| {
                points
                    .par_iter()
                    .filter_map(|&p| o.penetration(t, p - shift))
                    .map(|pen| pen.depth)
                    .reduce(|| 0.0, f64::max)
            };
            let deepest = depth(Vec3::zeros());
            if deepest <= FOLLOW_DEPTH * h {
                return Vec3::zeros();
            }
            // The points are pushed out along the normals: the obstacle
            // leaves the other way.
            let push: Vec3 = points
                .iter()
                .filter_map(|&p| o.penetration(t, p))
                .map(|pen| pen.normal * pen.depth)
                .sum();
            let mut directions: Vec<Vec3> = (0..3)
                .flat_map(|k| {
                    let e = Vec3::from_fn(|d, _| if d == k { 1.0 } else { 0.0 });
                    [e, -e]
                })
                .collect();
            if push.norm() > 0.0 {
                directions.push(-push.normalize());
            }
            directions
                .into_iter()
                .filter_map(|u| {
                    // Double until free (within a few body sizes), then halve
                    // the bracket.
                    let mut hi = deepest;
                    while depth(u * hi) > 0.0 {
                        hi *= 2.0;
                        if hi > 4.0 * size + 4.0 * deepest {
                            return None;
                        }
                    }
                    let mut lo = 0.0;
                    while hi - lo > 1e-3 * h {
                        let mid = 0.5 * (lo + hi);
                        if depth(u * mid) > 0.0 {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    Some(u * hi)
                })
                .min_by(|a, b| a.norm().total_cmp(&b.norm()))
                .unwrap_or_else(Vec3::zeros)
        })
        .collect()
}

/// Puts the obstacles of a contact back where their paths put them when
/// dropped: a static solve that inserted them leaves no shift behind,
/// however it ends.
struct ObstaclesPutBack<'a>(Option<&'a crate::contact::Contact>);

impl Drop for ObstaclesPutBack<'_> {
    fn drop(&mut self) {
        if let Some(c) = self.0 {
            c.shift_obstacles(None);
        }
    }
}

/// The length of the longest obstacle path of `contact` from `t0` to `t1`
/// (m), sampled at 256 times.
pub(super) fn obstacle_travel(contact: &crate::contact::Contact, t0: f64, t1: f64) -> f64 {
    const SAMPLES: usize = 256;
    contact
        .obstacles()
        .map(|(o, _)| {
            let at = |k: usize| o.offset(t0 + (t1 - t0) * k as f64 / SAMPLES as f64);
            (1..=SAMPLES)
                .map(|k| (at(k) - at(k - 1)).norm())
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
}

impl Default for StaticOptions {
    fn default() -> Self {
        Self {
            rtol: super::DEFAULT_NEWTON_RTOL,
            max_newton: super::DEFAULT_MAX_NEWTON,
            initial_load_increment: 1.0,
            min_load_increment: 1.0 / 1024.0,
            linear_solver: LinearSolverKind::Auto,
            small_strain: false,
            accept_unstable: false,
            obstacles_from: None,
            accept_mechanisms: false,
            matrix_free_above: MATRIX_FREE_ABOVE,
        }
    }
}

/// Load increments that may fail in one static solve before it stops with
/// the load carried so far ([`SolverError::LoadLimit`]), so that the cost of
/// a path that cannot be followed is bounded by this many times
/// `max_newton` iterations in failed increments. The template's buckling
/// at 83 % of its weight takes 10 (half of them within 1 % of the limit).
pub const MAX_FAILED_INCREMENTS: u32 = 16;

/// What [`solve_static`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticInfo {
    /// Whether the equilibrium found is stable (see [`Stability`]).
    pub stability: Stability,
    /// Newton iterations over all load increments.
    pub newton_iterations: u32,
    /// Load increments that converged.
    pub load_steps: u32,
    /// Newton iterations spent in load increments that failed and were
    /// retried with a smaller increment (not in `newton_iterations`).
    pub rejected_iterations: u32,
    /// Final residual over free dofs relative to the load norm.
    pub relative_residual: f64,
    /// What the linear solver did.
    pub linear: LinearStats,
}

struct StaticSystem<'a> {
    problem: &'a Problem,
    t: f64,
    /// The time the obstacles are at (`t`, or on their way to it).
    t_contact: f64,
    lambda: f64,
    scratch: Vec<Vec3>,
    free: &'a [bool],
    /// Friction anchors: every node sticks where it started (a body placed
    /// at rest, then loaded), until Coulomb's limit lets it slide.
    anchors: Vec<Option<Vec3>>,
    /// Zero velocities (statics has no contact damping).
    still: Vec<Vec3>,
    /// Set by the caller to stop.
    cancel: &'a AtomicBool,
}

impl NonlinearSystem for StaticSystem<'_> {
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    fn residual(&mut self, x: &[Vec3], r: &mut [Vec3]) -> f64 {
        let p = self.problem;
        p.model().internal_forces(x, r);
        p.external_forces(self.t, x, self.lambda, &mut self.scratch);
        if let Some(c) = p.contact() {
            c.add_forces(
                self.t_contact,
                x,
                &self.still,
                &self.anchors,
                &mut self.scratch,
            );
        }
        let mut s = 0.0;
        for i in 0..x.len() {
            for d in 0..3 {
                if self.free[3 * i + d] {
                    s += self.scratch[i][d].powi(2);
                } else {
                    // Reaction of the held dof.
                    s += (r[i][d] + self.scratch[i][d]).powi(2);
                }
            }
            r[i] += self.scratch[i];
        }
        s.sqrt()
    }

    fn has_jacobian_mul(&self) -> bool {
        let p = self.problem;
        p.contact().is_none() && p.loads().iter().all(|l| l.independent_of_positions())
    }

    fn jacobian_mul(&self, x: &[Vec3], v: &[Vec3], out: &mut [Vec3]) {
        self.problem.model().tangent_mul(x, v, out);
    }

    fn symmetric_stiffness(&mut self, x: &[Vec3]) -> Option<crate::sparse::SymmetricUpper> {
        self.has_jacobian_mul()
            .then(|| self.problem.model().symmetric_stiffness_upper(x))
    }

    fn jacobian(&mut self, x: &[Vec3]) -> BlockCsr {
        let p = self.problem;
        let mut j = p.model().tangent(x);
        for l in p.loads() {
            l.add_jacobian(p.model(), self.t, x, self.lambda, &mut j);
        }
        if let Some(c) = p.contact() {
            c.add_jacobian(self.t_contact, x, &self.still, &self.anchors, 0.0, &mut j);
        }
        j
    }
}

/// Solves for static equilibrium at time `state.time` (loads and prescribed
/// motions evaluated then), starting from `state.x`. Held components marked
/// fixed keep their value in `state`. On success `state.x` is the equilibrium
/// and `state.v` zero; on failure `state` is unchanged.
pub fn solve_static(
    problem: &Problem,
    state: &mut State,
    opts: &StaticOptions,
) -> Result<StaticInfo, SolverError> {
    solve_static_cancellable(problem, state, opts, &AtomicBool::new(false))
}

/// [`solve_static`] that stops with [`SolverError::Cancelled`] at the next
/// load increment once `cancel` is set (a Ctrl-C or a front end's stop
/// button: a static solve that cannot follow its load path can take
/// minutes).
pub fn solve_static_cancellable(
    problem: &Problem,
    state: &mut State,
    opts: &StaticOptions,
    cancel: &AtomicBool,
) -> Result<StaticInfo, SolverError> {
    crate::on_worker(|| solve_static_here(problem, state, opts, cancel))
}

/// [`solve_static_cancellable`], on the thread it is called on.
fn solve_static_here(
    problem: &Problem,
    state: &mut State,
    opts: &StaticOptions,
    cancel: &AtomicBool,
) -> Result<StaticInfo, SolverError> {
    let model = problem.model();
    state.check_size(model)?;
    if !(opts.rtol > 0.0
        && opts.max_newton > 0
        && opts.initial_load_increment > 0.0
        && opts.initial_load_increment <= 1.0
        && opts.min_load_increment > 0.0
        && opts.min_load_increment <= opts.initial_load_increment)
    {
        return Err(SolverError::BadOption(format!(
            "static options {opts:?}: need rtol > 0, max_newton >= 1, 0 < min_load_increment <= initial_load_increment <= 1"
        )));
    }
    let held = problem.constraints().num_held_dofs();
    if held < 6 && !problem.has_restraining_load() {
        let message = if held == 0 && problem.contact().is_some() {
            // Penalty contact holds a body only once it touches, and a
            // static solve starts from rest, where it may not: there is no
            // unique equilibrium to start from.
            "no node is fixed and only obstacles hold the body: a static solve cannot settle a free body onto them (at rest it touches them nowhere, or not firmly enough to stop its rigid motions); settle it first (solver::settle, which lets it fall and rest on them), or fix a region".to_string()
        } else if held == 0 {
            "no node is fixed: the static problem has no unique solution (the body can translate and rotate freely under its loads); fix a region, e.g. a face or the lowest layer of nodes".to_string()
        } else {
            format!(
                "only {held} displacement components are held: that cannot stop the 6 rigid motions, so the static problem has no unique solution; fix a region (a face or the lowest layer of nodes)"
            )
        };
        return Err(SolverError::Mechanism {
            message,
            nodes: Vec::new(),
        });
    }
    if cancel.load(Ordering::Relaxed) {
        return Err(SolverError::Cancelled { load_factor: 0.0 });
    }
    if problem.contact().is_none() && !problem.has_restraining_load() && !opts.accept_mechanisms {
        refuse_mechanisms(problem)?;
    }
    let free = problem.free_mask();
    let rest = model.rest_positions();
    let n = model.num_nodes();
    // Start and end values of held components.
    let x_init = state.x.clone();
    let mut x_target = state.x.clone();
    let mut scratch_v = vec![Vec3::zeros(); n];
    for i in 0..n {
        problem.constraints().prescribe(
            i,
            state.time,
            0.0,
            &rest[i],
            &mut x_target[i],
            &mut scratch_v[i],
        );
    }
    // Obstacles that move far enough are followed along their paths.
    let t_end = state.time;
    // Only when they end deep in the body as it starts: an obstacle that
    // ends outside it, or barely in, is where a slow press leaves it too
    // (a press and release ends touching nothing), and following costs an
    // increment per quarter cell of its path.
    let follow_from = match (problem.contact(), opts.obstacles_from) {
        (Some(c), Some(t0))
            if t0 < t_end && deepest_overlap(c, t_end, &state.x) > FOLLOW_DEPTH * model.h() =>
        {
            let travel = obstacle_travel(c, t0, t_end);
            (travel > OBSTACLE_INCREMENT * model.h()).then_some((t0, travel))
        }
        _ => None,
    };
    // Obstacles that end deep in the body with no path to follow there
    // (placed there, or barely moved) are inserted from outside, each along
    // the straight line by which it leaves the body with the least travel,
    // as a slow press from there would: placed at once, they pushed the
    // nodes near their edges out through their side faces.
    let insertion: Option<Vec<Vec3>> = match (problem.contact(), follow_from) {
        (Some(c), None)
            if !opts.small_strain
                && deepest_overlap(c, t_end, &state.x) > FOLLOW_DEPTH * model.h() =>
        {
            let shifts = exit_shifts(c, t_end, &state.x, model.h());
            shifts
                .iter()
                .any(|s| s.norm() > OBSTACLE_INCREMENT * model.h())
                .then_some(shifts)
        }
        _ => None,
    };
    let _put_back = ObstaclesPutBack(insertion.as_ref().and(problem.contact()));
    let insertion_travel = insertion
        .as_ref()
        .map_or(0.0, |s| s.iter().map(|v| v.norm()).fold(0.0, f64::max));
    let insert_to = |lambda: f64| {
        if let (Some(c), Some(shifts)) = (problem.contact(), &insertion) {
            let at: Vec<Vec3> = shifts.iter().map(|s| s * (1.0 - lambda)).collect();
            c.shift_obstacles(Some(&at));
        }
    };
    if let Some(shifts) = &insertion {
        log::info!(
            "static: obstacles start deep in the body; inserted from outside along {shifts:?}"
        );
    }
    insert_to(0.0);
    let contact_time = |lambda: f64| match follow_from {
        Some((t0, _)) if lambda < 1.0 => t0 + lambda * (t_end - t0),
        _ => t_end,
    };
    // The obstacles move at most OBSTACLE_INCREMENT cells per increment
    // (their paths need not be uniform in time: each increment is fitted).
    let step_limit = OBSTACLE_INCREMENT * model.h();
    let fit = |lambda: f64, mut dl: f64| {
        if let (Some(c), Some(_)) = (problem.contact(), follow_from) {
            let end = |dl: f64| (lambda + dl).min(1.0);
            while dl > 1e-9
                && obstacle_travel(c, contact_time(lambda), contact_time(end(dl))) > step_limit
            {
                dl *= 0.5;
            }
        }
        while dl > 1e-9 && insertion_travel * dl > step_limit {
            dl *= 0.5;
        }
        dl
    };
    let travel = follow_from.map_or(insertion_travel, |(_, travel)| travel);
    let min_increment = if travel > 0.0 {
        opts.min_load_increment.min(step_limit / travel / 64.0)
    } else {
        opts.min_load_increment
    };
    let anchors = match problem.contact() {
        Some(c) => c.static_anchors(contact_time(0.0), &state.x),
        None => Vec::new(),
    };
    let mut sys = StaticSystem {
        problem,
        t: state.time,
        t_contact: contact_time(0.0),
        lambda: 0.0,
        scratch: vec![Vec3::zeros(); n],
        free: &free,
        anchors,
        still: vec![Vec3::zeros(); n],
        cancel,
    };
    let newton_opts = NewtonOptions {
        max_iterations: opts.max_newton,
        rtol: opts.rtol,
        slope_line_search: true,
        keep_hierarchy: false,
    };
    let mut linear = LinearSolver::new(model, opts.linear_solver);
    linear.set_matrix_free_above(opts.matrix_free_above);
    if opts.small_strain {
        return solve_small_strain(&mut sys, state, &x_target, &free, &mut linear, opts);
    }
    let mut x = x_init.clone();
    let mut lambda = 0.0;
    let mut dl = opts.initial_load_increment;
    let mut total_its = 0;
    let mut load_steps = 0;
    let mut rejected = 0;
    // The previous converged load factor and positions (for the predictor).
    let mut previous: Option<(f64, Vec<Vec3>)> = None;
    // After an increment to `.0` failed, increments stay below `.1` (half
    // the one that failed) until the load has passed `.0`: near a limit
    // point, doubling after every success would try the failing increment
    // again and again, each time costing max_newton iterations.
    let mut cap: Option<(f64, f64)> = None;
    let mut failed_increments = 0;
    while lambda < 1.0 {
        if cancel.load(Ordering::Relaxed) {
            return Err(SolverError::Cancelled {
                load_factor: lambda,
            });
        }
        dl = fit(lambda, dl);
        let lt = if lambda + dl >= 1.0 - 1e-12 {
            1.0
        } else {
            lambda + dl
        };
        // Predictor: extrapolate the last converged increment linearly in the
        // load factor (secant), which saves Newton iterations in bending.
        let mut trial = x.clone();
        if let Some((lp, xp)) = &previous {
            let ratio = (lt - lambda) / (lambda - lp);
            for i in 0..n {
                trial[i] += (x[i] - xp[i]) * ratio;
            }
        }
        for i in 0..n {
            for d in 0..3 {
                if !free[3 * i + d] {
                    trial[i][d] = x_init[i][d] + lt * (x_target[i][d] - x_init[i][d]);
                }
            }
        }
        sys.lambda = lt;
        sys.t_contact = contact_time(lt);
        insert_to(lt);
        if load_steps == 0 && trial == x_init {
            // The first tangent is the one at the start: its hierarchy is
            // the stability test's preconditioner.
            linear.keep_next_hierarchy();
        }
        let result = newton(
            &mut sys,
            &mut trial,
            &free,
            problem.size(),
            model.h(),
            newton_opts,
            &mut linear,
        )
        .and_then(|its| match check_inverted(model, &trial) {
            Some(d) => Err(NewtonFailure::Diverged(d)),
            None => Ok(its),
        });
        match result {
            Ok(its) => {
                log::debug!("static: load factor {lt}: {its} Newton iterations");
                total_its += its;
                load_steps += 1;
                previous = Some((lambda, std::mem::replace(&mut x, trial)));
                lambda = lt;
                dl = (2.0 * dl).min(1.0);
                if let (Some(c), true) = (
                    problem.contact(),
                    follow_from.is_some() || insertion.is_some(),
                ) {
                    // The contacts made on the way stick where they were
                    // made; sliding ones keep their kinetic offset.
                    c.update_anchors(sys.t_contact, &x, &sys.still, &mut sys.anchors);
                    // Those it makes next stick where they start it.
                    sys.anchors = c.step_anchors(sys.t_contact, &x, &sys.anchors);
                }
                match cap {
                    Some((failed, _)) if lambda >= failed => cap = None,
                    Some((_, most)) => dl = dl.min(most),
                    None => {}
                }
            }
            Err(failure) => {
                let reason = match failure {
                    NewtonFailure::Singular(nodes)
                        if singular_at_rest(&mut sys, &x_init, &free, &mut linear) =>
                    {
                        return Err(SolverError::Mechanism {
                            message: mechanism_message(problem, &nodes),
                            nodes,
                        });
                    }
                    // Singular in a deformed state only: a smaller increment
                    // may pass it (a limit point) or not (collapse); say which.
                    NewtonFailure::Singular(nodes) => Divergence::SingularUnderLoad {
                        load_factor: lambda,
                        nodes,
                    },
                    NewtonFailure::Linear(m) => return Err(SolverError::LinearSolver(m)),
                    NewtonFailure::Cancelled => {
                        return Err(SolverError::Cancelled {
                            load_factor: lambda,
                        });
                    }
                    NewtonFailure::Diverged(reason) => reason,
                };
                if let Divergence::NewtonFailed { iterations, .. } = &reason {
                    rejected += iterations;
                }
                // Halve the increment that was tried: `dl` may reach past the
                // full load, and halving it alone would try the same one again.
                dl = 0.5 * (lt - lambda);
                cap = Some((lt, dl));
                failed_increments += 1;
                if dl < min_increment || failed_increments > MAX_FAILED_INCREMENTS {
                    // Some load carried and no more: a limit point, most likely.
                    if lambda > 0.0 {
                        return Err(SolverError::LoadLimit {
                            load_factor: lambda,
                            reason,
                        });
                    }
                    return Err(SolverError::Diverged {
                        solver: "static",
                        step: load_steps as u64 + 1,
                        time: state.time,
                        reason,
                        kept_time: state.time,
                        hint: STATIC_HINT,
                    });
                }
                log::debug!(
                    "static: load increment to {lt} failed ({reason}); trying {}",
                    lambda + dl
                );
            }
        }
    }
    let mut r = vec![Vec3::zeros(); n];
    sys.lambda = 1.0;
    let stability = equilibrium_stability(&mut sys, &x, &x_init, &free, &mut linear);
    if stability == Stability::Unstable {
        if opts.accept_unstable {
            log::warn!("static: the equilibrium is unstable (kept, as asked)");
        } else {
            state.x = x;
            state.v.iter_mut().for_each(|v| *v = Vec3::zeros());
            return Err(SolverError::UnstableEquilibrium {
                hourglass_control: crate::modes::cells_are_rigid(problem.model()),
            });
        }
    }
    let scale = sys.residual(&x, &mut r);
    let res = free_norm(&r, &free);
    if let Some(c) = problem.contact() {
        // The state keeps the anchors of the contacts that hold it, so that
        // its contact forces (an output's, or a run continued in time) are
        // the equilibrium's, friction included.
        let mut anchors = std::mem::take(&mut sys.anchors);
        c.update_anchors(t_end, &x, &sys.still, &mut anchors);
        state.contact = anchors;
    }
    state.x = x;
    state.v.iter_mut().for_each(|v| *v = Vec3::zeros());
    Ok(StaticInfo {
        newton_iterations: total_its,
        load_steps,
        rejected_iterations: rejected,
        relative_residual: if scale > 0.0 { res / scale } else { res },
        linear: linear.stats(),
        stability,
    })
}

/// Refuses a problem whose held nodes leave zero-energy modes of the rest
/// stiffness ([`crate::modes`], as `mss check` counts them): its equilibrium
/// is not unique, whatever the load. Newton's LU factors such a matrix with
/// round-off pivots and returned an answer, silently, for most models and
/// loads. Obstacles and restraining loads may hold the modes: the caller
/// skips the count then.
///
/// The count must stay cheap beside the solve: with hourglass control it is
/// the rigid-cell count (exact, linear in the cells); without, the dense
/// eigenvalues up to [`crate::modes::DENSE_LIMIT`] free dofs (exact), and
/// beyond that the modes that move every cell rigidly (a lower bound, linear:
/// the subspace count factors the stiffness, which tripled the time and
/// quintupled the memory of a 64 x 16 x 16 `paper` solve), Newton's own
/// singularity checks catching the rest.
fn refuse_mechanisms(problem: &Problem) -> Result<(), SolverError> {
    use crate::modes;
    let model = problem.model();
    let mask: Vec<[bool; 3]> = (0..model.num_nodes())
        .map(|n| problem.constraints().mask(n))
        .collect();
    let rigid = modes::cells_are_rigid(model);
    let free = mask.iter().flatten().filter(|&&held| !held).count();
    let count = if free <= modes::DENSE_LIMIT {
        modes::zero_energy_modes_dense(model, &mask).ok()
    } else {
        // Rigid motions of the cells have no energy in any model.
        modes::zero_energy_modes_rigid_cells(model, &mask)
    };
    match count {
        Some(z) if z.count > 0 => Err(SolverError::Mechanism {
            message: format!(
                "the held nodes leave {}{} zero-energy mode(s) (rigid motions, or hourglass \
                 mechanisms of the lattice): the static problem has no unique solution; hold a \
                 larger region (a whole face){}",
                z.count,
                if z.exact && (rigid || z.method == "dense") {
                    ""
                } else {
                    " or more"
                },
                if rigid {
                    ""
                } else {
                    ", or add hourglass control (parts one cell thick keep hourglass mechanisms however they are held)"
                }
            ),
            nodes: Vec::new(),
        }),
        _ => Ok(()),
    }
}

/// Largest Cholesky factor (bytes) that the stability test of a static
/// equilibrium builds; larger problems are not tested (logged).
pub const STABILITY_TEST_MAX_FACTOR_BYTES: usize = 1 << 30;

/// Whether a static equilibrium is stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stability {
    /// The stiffness is positive definite on the free dofs.
    Stable,
    /// It is not.
    Unstable,
    /// The test was skipped: the factor would exceed
    /// [`STABILITY_TEST_MAX_FACTOR_BYTES`], or the linear algebra failed.
    NotTested,
}

/// The symmetric part of the stiffness `-jac`, in place.
fn symmetric_stiffness(mut jac: BlockCsr) -> BlockCsr {
    for row in 0..jac.num_rows() {
        for idx in jac.row_offsets[row] as usize..jac.row_offsets[row + 1] as usize {
            let col = jac.col_indices[idx] as usize;
            if col < row {
                // Done with the block of (col, row).
                continue;
            }
            let mirror = jac
                .find(col, row)
                .expect("the lattice pattern is symmetric");
            let sym = -(jac.blocks[idx] + jac.blocks[mirror].transpose()) * 0.5;
            jac.blocks[idx] = sym;
            jac.blocks[mirror] = sym.transpose();
        }
    }
    jac
}

/// Tests the stability of the equilibrium `x`: whether the symmetric part
/// of the stiffness `K = -d(residual)/dx` is positive definite on the free
/// dofs. For a conservative model `K` is the energy's Hessian and this is
/// the second-order test of a minimum; with the correction forces `K` is not
/// symmetric, and a positive definite symmetric part is a sufficient
/// condition (`v . K v > 0` for every `v`: no static direction releases
/// energy), so the test errs on the side of refusing.
///
/// Above [`super::linear::DIRECT_MAX_FREE_DOFS`] free dofs it is a Lanczos
/// iteration preconditioned by a multigrid cycle of the stiffness at the
/// start `x0` (`LinearSolver::is_positive_definite`: a negative Rayleigh
/// quotient is a certificate, about the cost of one iterative solve);
/// otherwise, or when that does not decide, a Cholesky factorization.
fn equilibrium_stability(
    sys: &mut StaticSystem<'_>,
    x: &[Vec3],
    x0: &[Vec3],
    free: &[bool],
    linear: &mut LinearSolver,
) -> Stability {
    let free_dofs = free.iter().filter(|f| **f).count();
    if free_dofs > super::linear::DIRECT_MAX_FREE_DOFS {
        // One matrix alive at a time besides the test's own. When the
        // Jacobian is the model's tangent alone, its symmetric part is
        // assembled once per pair of blocks: at a million nodes the full
        // `f64` matrix (2 GB) beside the kept hierarchy was the solve's
        // memory peak.
        let problem = sys.problem;
        let upper = sys
            .has_jacobian_mul()
            .then(|| problem.model().symmetric_stiffness_upper(x));
        let upper_mul = |v: &[Vec3], out: &mut [Vec3]| {
            if let Some(u) = &upper {
                u.mul(v, out);
            }
        };
        let k = match &upper {
            Some(_) => Stiffness::Action(&upper_mul),
            None => Stiffness::Matrix(symmetric_stiffness(sys.jacobian(x))),
        };
        let reference = || symmetric_stiffness(sys.jacobian(x0));
        match linear.is_positive_definite(k, reference, free) {
            Some(true) => return Stability::Stable,
            Some(false) => return Stability::Unstable,
            None => log::debug!("static: Lanczos stability test undecided; factoring"),
        }
    }
    let mut k = symmetric_stiffness(sys.jacobian(x));
    // A relative shift below round-off of the Newton solution, so that a
    // positive definite matrix is not refused for its last digits.
    let shift = 1e-10 * k.max_diagonal();
    k.add_diagonal(-shift);
    let fixed: Vec<[bool; 3]> = free.chunks(3).map(|f| [!f[0], !f[1], !f[2]]).collect();
    match k.cholesky_factor_bytes(&fixed) {
        Ok(bytes) if bytes <= STABILITY_TEST_MAX_FACTOR_BYTES => {}
        Ok(bytes) => {
            log::info!(
                "static: stability of the equilibrium not tested (the factor would take {} MiB)",
                bytes >> 20
            );
            return Stability::NotTested;
        }
        Err(e) => {
            log::info!("static: stability of the equilibrium not tested: {e}");
            return Stability::NotTested;
        }
    }
    match k.factor_cholesky(&fixed) {
        Ok(_) => Stability::Stable,
        Err(crate::LinearSolveError::NotPositiveDefinite { .. }) => Stability::Unstable,
        Err(e) => {
            log::info!("static: stability of the equilibrium not tested: {e}");
            Stability::NotTested
        }
    }
}

/// Whether the tangent at the start configuration `x0` is singular on the
/// free dofs: a mechanism of the boundary conditions, as opposed to a
/// singularity that the load brings about.
fn singular_at_rest(
    sys: &mut StaticSystem<'_>,
    x0: &[Vec3],
    free: &[bool],
    linear: &mut LinearSolver,
) -> bool {
    let jac = sys.jacobian(x0);
    // A right-hand side that excites every free dof.
    let b: Vec<Vec3> = (0..x0.len())
        .map(|i| Vec3::new(1.0, -0.5, 0.25) * (1.0 + (i % 7) as f64))
        .collect();
    matches!(
        linear.solve(jac, &b, free, sys.problem.size(), 1e-8, None),
        Err(super::linear::LinearFailure::Singular { .. })
    )
}

/// One solve of the problem linearized at rest: `K0 (x - X) = f` on the free
/// dofs, with the held dofs at their prescribed values.
fn solve_small_strain(
    sys: &mut StaticSystem<'_>,
    state: &mut State,
    x_target: &[Vec3],
    free: &[bool],
    linear: &mut LinearSolver,
    opts: &StaticOptions,
) -> Result<StaticInfo, SolverError> {
    let problem = sys.problem;
    let model = problem.model();
    let n = model.num_nodes();
    let rest = model.rest_positions();
    // Held dofs at their targets, free dofs at rest: the residual there is
    // the load plus what the prescribed motion pulls.
    let mut x0 = rest.to_vec();
    for i in 0..n {
        for d in 0..3 {
            if !free[3 * i + d] {
                x0[i][d] = x_target[i][d];
            }
        }
    }
    sys.lambda = 1.0;
    let mut r = vec![Vec3::zeros(); n];
    let scale = sys.residual(&x0, &mut r);
    let jac = sys.jacobian(rest);
    let neg_r: Vec<Vec3> = r.iter().map(|v| -v).collect();
    let du = match linear.solve(jac.clone(), &neg_r, free, problem.size(), opts.rtol, None) {
        Ok(d) => d,
        Err(super::linear::LinearFailure::Singular { nodes }) => {
            return Err(SolverError::Mechanism {
                message: mechanism_message(problem, &nodes),
                nodes,
            });
        }
        Err(super::linear::LinearFailure::Other(m)) => return Err(SolverError::LinearSolver(m)),
    };
    for i in 0..n {
        state.x[i] = x0[i] + du[i];
    }
    state.v.iter_mut().for_each(|v| *v = Vec3::zeros());
    // The residual of the linear problem (not of the nonlinear forces).
    let mut kdu = vec![Vec3::zeros(); n];
    jac.mul_vec(&du, &mut kdu);
    let res = free_norm(
        &r.iter().zip(&kdu).map(|(a, b)| a + b).collect::<Vec<_>>(),
        free,
    );
    Ok(StaticInfo {
        newton_iterations: 1,
        load_steps: 1,
        rejected_iterations: 0,
        relative_residual: if scale > 0.0 { res / scale } else { res },
        linear: linear.stats(),
        // The rest stiffness is positive semi-definite, and the solve above
        // refused it singular: small-strain equilibria are stable.
        stability: Stability::Stable,
    })
}
