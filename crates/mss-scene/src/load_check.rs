//! Whether the body has a stable equilibrium under its load ([`LoadCheck`]),
//! and the sizes up to which the checks that need a factorization run. Used
//! by [`crate::check`] (what `mss check` reports) and by
//! [`Job::run`](crate::job::Job::run) (which refuses a run that would fold);
//! it depends on neither.

use std::sync::atomic::AtomicBool;

use mss_core::solver::{
    Problem, SolverError, Stability, State, StaticOptions, solve_static_cancellable,
};
use serde::Serialize;

/// Largest model (nodes) on which a run counts zero-energy modes before
/// starting when the count needs a factorization; [`CheckReport::new`](crate::check::CheckReport::new)
/// always counts them, and so does a run whose cells are rigid (hourglass
/// control: the count is linear in the cells).
pub const RUN_MODE_CHECK_MAX_NODES: usize = 20_000;

/// True when a run should count zero-energy modes before starting: the count
/// is cheap for this model (see [`RUN_MODE_CHECK_MAX_NODES`]).
pub fn run_counts_modes(model: &mss_core::Model) -> bool {
    model.num_nodes() <= RUN_MODE_CHECK_MAX_NODES || mss_core::modes::cells_are_rigid(model)
}

/// Largest model (nodes) on which [`CheckReport::new`](crate::check::CheckReport::new) solves the scene's
/// load statically (seconds with the multigrid solver at this size), when
/// the model has hourglass control; without, [`RUN_MODE_CHECK_MAX_NODES`].
pub const LOAD_CHECK_MAX_NODES: usize = 60_000;

/// Smallest load increment of the load check's static solve.
pub const LOAD_CHECK_MIN_INCREMENT: f64 = 1.0 / 32.0;

/// What the static solve of a scene's load at its end time found: whether
/// the body has a stable equilibrium under it, so that mechanisms which only
/// appear under load (a compressed lattice losing stiffness, buckling under
/// the body's own weight) are reported before a dynamic run folds.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum LoadCheck {
    /// An equilibrium was found.
    Equilibrium {
        /// Whether its stiffness is positive definite (`None`: too large to
        /// test, see [`mss_core::solver::STABILITY_TEST_MAX_FACTOR_BYTES`]).
        stable: Option<bool>,
        /// Largest displacement (m).
        max_displacement: f64,
        /// The same relative to the body's largest extent.
        relative_displacement: f64,
        /// Smallest volume ratio `J` at a cell centre at the equilibrium.
        min_jacobian: f64,
        /// Smallest corner Jacobian `J_n` at the equilibrium (`<= 0`: a cell
        /// folded at a corner, `mss_core::Model::folded_cells`).
        min_corner_jacobian: f64,
        /// Worst cell's deviation from the affine map of its corners, as a
        /// fraction of the cell size.
        worst_affine_deviation: f64,
    },
    /// The equilibrium path ends before the full load: the body buckles or
    /// collapses under it.
    LoadLimit {
        /// Fraction of the load carried.
        load_factor: f64,
    },
    /// The held nodes leave zero-energy modes of the lattice (rigid
    /// motions or hourglass mechanisms): there is no unique equilibrium,
    /// and a dynamic run under load folds along them.
    Mechanism {
        /// The solver's message.
        reason: String,
    },
    /// The static solve failed for another reason.
    Failed {
        /// The solver's message.
        reason: String,
    },
    /// Not solved.
    Skipped {
        /// Why not.
        reason: String,
    },
}

impl LoadCheck {
    /// Solves `problem`'s load at `end_time` statically with the scene's
    /// `scene_opts` (tightened for a check), and measures the displacement
    /// against `body_extent` (m); [`Job::load_check`](crate::job::Job::load_check)
    /// passes a job's. Stops at the next load increment once `cancel` is set
    /// (then [`LoadCheck::Skipped`]); `mechanisms_at_rest` skips the solve
    /// (it would fail).
    pub fn solve(
        problem: &Problem,
        scene_opts: StaticOptions,
        end_time: f64,
        body_extent: Option<f64>,
        mechanisms_at_rest: bool,
        cancel: &AtomicBool,
    ) -> Self {
        let model = problem.model();
        let skipped = |reason: &str| LoadCheck::Skipped {
            reason: reason.to_owned(),
        };
        if problem.loads().is_empty() && problem.contact().is_none() {
            return skipped("the scene has no load");
        }
        if mechanisms_at_rest {
            return skipped("the held nodes leave zero-energy modes");
        }
        // Without hourglass control the lattice's near-mechanisms stall the
        // iterative solver (docs/solvers.md): minutes beyond the size that
        // the direct fallback covers.
        let limit = if mss_core::modes::cells_are_rigid(model) {
            LOAD_CHECK_MAX_NODES
        } else {
            RUN_MODE_CHECK_MAX_NODES
        };
        if model.num_nodes() > limit {
            return LoadCheck::Skipped {
                reason: format!("{} nodes, more than {limit}", model.num_nodes()),
            };
        }
        let opts = StaticOptions {
            // Past a limit point Newton fails slowly; within 25 iterations
            // a converging increment has converged (5 on the bundled scenes).
            max_newton: scene_opts.max_newton.min(25),
            // The load limit to about 3 %: enough to tell buckling apart,
            // without the many failing increments a precise limit costs.
            min_load_increment: LOAD_CHECK_MIN_INCREMENT.min(scene_opts.initial_load_increment),
            small_strain: false,
            accept_unstable: true,
            ..scene_opts
        };
        let mut state = State::at_rest(model);
        problem.apply_constraints(&mut state);
        state.time = end_time;
        match solve_static_cancellable(problem, &mut state, &opts, cancel) {
            Ok(info) => {
                let u = state.displacements(model);
                let max_displacement = u.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let extent = body_extent.unwrap_or(model.h());
                let min_jacobian = model
                    .cell_diagnostics(&state.x)
                    .iter()
                    .map(|d| 1.0 + d.volumetric_strain)
                    .fold(f64::INFINITY, f64::min);
                let min_corner_jacobian = model
                    .corner_jacobians(&state.x)
                    .into_iter()
                    .fold(f64::INFINITY, f64::min);
                let worst = model
                    .affine_deviation(&state.x)
                    .into_iter()
                    .fold(0.0, f64::max);
                LoadCheck::Equilibrium {
                    stable: match info.stability {
                        Stability::Stable => Some(true),
                        Stability::Unstable => Some(false),
                        Stability::NotTested => None,
                    },
                    max_displacement,
                    relative_displacement: max_displacement / extent,
                    min_jacobian,
                    min_corner_jacobian,
                    worst_affine_deviation: worst,
                }
            }
            Err(SolverError::LoadLimit { load_factor, .. }) => LoadCheck::LoadLimit { load_factor },
            Err(SolverError::Cancelled { .. }) => skipped("stopped"),
            Err(e @ SolverError::Mechanism { .. }) => LoadCheck::Mechanism {
                reason: e.to_string(),
            },
            Err(e) => LoadCheck::Failed {
                reason: e.to_string(),
            },
        }
    }

    /// A warning when the body has no stable equilibrium under its load.
    pub fn warning(&self) -> Option<String> {
        match self {
            LoadCheck::Equilibrium {
                stable: Some(false),
                ..
            } => Some(
                "under the scene's load the static equilibrium is unstable (its stiffness is \
                 not positive definite): a mechanism appears under load and the body may fold; \
                 use hourglass control (parameterization \"volumetric-barrier+hg\", \
                 hourglass = 1.0), a stiffer material or a larger held region"
                    .to_owned(),
            ),
            LoadCheck::LoadLimit { load_factor } => Some(format!(
                "the body carries only {:.0} % of the scene's load statically: it buckles or \
                 collapses under it, and a dynamic run will fold or sag far; hold a larger \
                 region, stiffen the material or reduce the load",
                100.0 * load_factor
            )),
            LoadCheck::Failed { reason } => Some(format!(
                "the static solve of the scene's load failed: {reason}"
            )),
            LoadCheck::Mechanism { reason } => Some(format!(
                "the static solve of the scene's load is refused: {reason}"
            )),
            _ => None,
        }
    }

    /// One line for `mss check`.
    pub fn describe(&self) -> String {
        match self {
            LoadCheck::Equilibrium {
                stable,
                max_displacement,
                relative_displacement,
                min_jacobian,
                min_corner_jacobian,
                worst_affine_deviation,
            } => format!(
                "{} static equilibrium: largest displacement {max_displacement:.3e} m \
                 ({:.1} % of the body's size), smallest volume ratio {min_jacobian:.3} \
                 ({min_corner_jacobian:.3} at a corner{}), worst cell {:.1} % of h off affine",
                match stable {
                    Some(true) => "stable",
                    Some(false) => "UNSTABLE",
                    None => "untested",
                },
                100.0 * relative_displacement,
                if *min_corner_jacobian <= 0.0 {
                    ": cells folded"
                } else {
                    ""
                },
                100.0 * worst_affine_deviation
            ),
            LoadCheck::LoadLimit { load_factor } => format!(
                "no equilibrium beyond {:.0} % of the load (buckling or collapse)",
                100.0 * load_factor
            ),
            LoadCheck::Failed { reason } => format!("static solve failed: {reason}"),
            LoadCheck::Mechanism { reason } => format!("no unique static equilibrium: {reason}"),
            LoadCheck::Skipped { reason } => format!("not solved: {reason}"),
        }
    }
}
