//! `[solver]`: the solver kind, the time step, damping and the Newton settings.

use std::fmt;

use mss_core::Precision;
use mss_core::loads::Damping;
use mss_core::solver::{
    DEFAULT_MAX_NEWTON, DEFAULT_NEWTON_RTOL, ExplicitOptions, Integrators, LinearSolverKind,
    SettleOptions,
};
use serde::Deserialize;

use super::key::KeyError;
use serde::de::{self, Deserializer, Visitor};

/// `[solver] kind` of a static solve (equilibrium, no inertia); every other
/// kind names an integrator of the [`Registry`](crate::Registry).
pub const STATIC_KIND: &str = "static";

/// `[solver] kind` of a scene that names none.
pub const DEFAULT_KIND: &str = "explicit";

/// Steps of an implicit (or other non-explicit) run when `dt = "auto"`: the
/// step is `duration / IMPLICIT_AUTO_STEPS`.
pub const IMPLICIT_AUTO_STEPS: u32 = 100;

/// A time step: `"auto"` (from the model's stability limit) or seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TimeStep {
    /// The model's stable step times `safety` (explicit schemes,
    /// [`IntegratorEntry::explicit`](mss_core::solver::IntegratorEntry)), or
    /// `duration / IMPLICIT_AUTO_STEPS` (the others).
    #[default]
    Auto,
    /// A fixed step (s).
    Seconds(f64),
}

impl<'de> Deserialize<'de> for TimeStep {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = TimeStep;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("\"auto\" or a time step in seconds")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<TimeStep, E> {
                if v == "auto" {
                    Ok(TimeStep::Auto)
                } else {
                    Err(E::invalid_value(de::Unexpected::Str(v), &self))
                }
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<TimeStep, E> {
                Ok(TimeStep::Seconds(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<TimeStep, E> {
                Ok(TimeStep::Seconds(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<TimeStep, E> {
                Ok(TimeStep::Seconds(v as f64))
            }
        }
        d.deserialize_any(V)
    }
}

/// `[solver]`: time integration. Defaults are the library's
/// ([`IntegratorSettings`](mss_core::solver::IntegratorSettings) and the
/// Newton constants of [`mss_core::solver`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSection {
    /// `"explicit"` (default, velocity Verlet), `"symplectic-euler"`,
    /// `"implicit"` (backward Euler), `"static"` (equilibrium), or the name of
    /// an integrator registered by the program.
    #[serde(default = "default_kind")]
    pub kind: String,
    /// Time step: `"auto"` (default) or seconds.
    #[serde(default)]
    pub dt: TimeStep,
    /// Fraction of the stable step used when `dt = "auto"` (0 < s <= 1,
    /// default [`ExplicitOptions::default`]'s 0.9).
    #[serde(default = "default_safety")]
    pub safety: f64,
    /// Explicit solver only: if `dt` is above the stability limit, take as many
    /// sub-steps as needed instead of refusing (default false).
    #[serde(default)]
    pub substep: bool,
    /// Mass-proportional damping alpha (1/s): force `-alpha m v` (default 0).
    #[serde(default)]
    pub damping: f64,
    /// Stiffness-proportional damping beta (s): force `-beta K0 v`, K0 the
    /// stiffness at rest (default 0).
    #[serde(default)]
    pub stiffness_damping: f64,
    /// Simulated duration (s), > 0 (default 1.0). Static solves ignore it.
    #[serde(default = "default_duration")]
    pub duration: f64,
    /// Newton tolerance on the residual force, relative to the load (implicit,
    /// static; default [`DEFAULT_NEWTON_RTOL`]).
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Newton iteration limit per step or load increment (implicit, static;
    /// default [`DEFAULT_MAX_NEWTON`]).
    #[serde(default = "default_max_iterations")]
    pub max_iterations: u32,
    /// Linear solver of the Newton steps (implicit, static): `"auto"`
    /// (default: direct for small problems, multigrid-preconditioned Krylov
    /// above [`mss_core::solver::DIRECT_MAX_FREE_DOFS`] free dofs),
    /// `"direct"` or `"iterative"`.
    #[serde(default)]
    pub linear_solver: LinearSolverKind,
    /// Static solves: the load is applied in this many equal first
    /// increments (default 1; the solver halves an increment that fails and
    /// doubles one that succeeds).
    #[serde(default = "default_load_steps")]
    pub load_steps: u32,
    /// Static solves: solve the small-strain (linearized) problem once
    /// instead of the nonlinear one (default false).
    #[serde(default)]
    pub linear: bool,
    /// Static solves: keep an equilibrium that the stability test finds
    /// unstable instead of failing; dynamic runs: run a model (one without
    /// hourglass control or the barrier) that the static solve of the
    /// scene's load says would fold, instead of refusing it up front
    /// (default false).
    #[serde(default)]
    pub accept_unstable: bool,
    /// Explicit solvers: precision of the internal force pass, `"f64"`
    /// (default) or `"f32"` (faster, for interactive use; positions and
    /// velocities stay `f64`; see [`Precision`]). Newton solvers (implicit,
    /// static) refuse `"f32"`.
    #[serde(default)]
    pub precision: Precision,
    /// How the run starts: `"rest"` (default: the bodies at rest in their
    /// rest shape, the loads switched on at once) or `"settled"` (first
    /// brought to rest under the loads at the start time, contact and
    /// friction included: [`mss_core::solver::settle`]). With
    /// `kind = "static"`, `"settled"` makes the settling the solve (it
    /// settles bodies that only contact holds, which Newton cannot start).
    #[serde(default)]
    pub start: Start,
    /// `start = "settled"`: the simulated time the settling may take before
    /// the run fails (s, default [`SettleOptions::default`]'s 10).
    #[serde(default = "default_settle_time")]
    pub settle_time: f64,
    /// `start = "settled"`: settled when the residual force is at most this
    /// fraction of the loads (default [`SettleOptions::default`]'s 1e-4).
    #[serde(default = "default_settle_tolerance")]
    pub settle_tolerance: f64,
}

/// `[solver] start`: where a run begins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Start {
    /// The rest shape, at rest, loads on at once.
    #[default]
    Rest,
    /// At rest under the loads ([`mss_core::solver::settle`]).
    Settled,
}

fn default_settle_time() -> f64 {
    SettleOptions::default().max_time
}
fn default_settle_tolerance() -> f64 {
    SettleOptions::default().rtol
}

fn default_load_steps() -> u32 {
    1
}

fn default_kind() -> String {
    DEFAULT_KIND.to_owned()
}
fn default_safety() -> f64 {
    ExplicitOptions::default().safety
}
fn default_duration() -> f64 {
    1.0
}
fn default_tolerance() -> f64 {
    DEFAULT_NEWTON_RTOL
}
fn default_max_iterations() -> u32 {
    DEFAULT_MAX_NEWTON
}

impl Default for SolverSection {
    fn default() -> Self {
        Self {
            kind: default_kind(),
            dt: TimeStep::Auto,
            substep: false,
            safety: default_safety(),
            damping: 0.0,
            stiffness_damping: 0.0,
            duration: default_duration(),
            tolerance: default_tolerance(),
            max_iterations: default_max_iterations(),
            linear_solver: LinearSolverKind::default(),
            load_steps: default_load_steps(),
            linear: false,
            accept_unstable: false,
            precision: Precision::F64,
            start: Start::Rest,
            settle_time: default_settle_time(),
            settle_tolerance: default_settle_tolerance(),
        }
    }
}

impl SolverSection {
    /// Checks the ranges of the keys (duration, dt, safety, damping,
    /// tolerance, iterations, load steps); whether `kind` names an
    /// integrator is known only against a registry, when the job is built.
    pub fn check(&self) -> Result<(), KeyError> {
        let bad = |key: &str, message: String| Err(KeyError::new(key, message));
        let s = self;
        if !(s.duration.is_finite() && s.duration > 0.0) {
            return bad(
                "duration",
                format!(
                    "= {}; the simulated duration must be a positive number of seconds",
                    s.duration
                ),
            );
        }
        if let TimeStep::Seconds(dt) = s.dt
            && !(dt.is_finite() && dt > 0.0)
        {
            return bad(
                "dt",
                format!("= {dt}; use a positive time step in seconds, or \"auto\""),
            );
        }
        if !(s.safety > 0.0 && s.safety <= 1.0) {
            return bad(
                "safety",
                format!(
                    "= {}; must be in (0, 1] (fraction of the stable time step)",
                    s.safety
                ),
            );
        }
        if !(s.damping.is_finite() && s.damping >= 0.0) {
            return bad("damping", format!("= {}; must be >= 0 (1/s)", s.damping));
        }
        if !(s.stiffness_damping.is_finite() && s.stiffness_damping >= 0.0) {
            return bad(
                "stiffness_damping",
                format!("= {}; must be >= 0 (s)", s.stiffness_damping),
            );
        }
        if !(s.tolerance.is_finite() && s.tolerance > 0.0) {
            return bad("tolerance", format!("= {}; must be positive", s.tolerance));
        }
        if s.max_iterations == 0 {
            return bad("max_iterations", "= 0; must be at least 1".into());
        }
        if s.load_steps == 0 || s.load_steps > 1_000_000 {
            return bad(
                "load_steps",
                format!("= {}; use 1 to 1000000 increments", s.load_steps),
            );
        }
        if !(s.settle_time.is_finite() && s.settle_time > 0.0) {
            return bad(
                "settle_time",
                format!(
                    "= {}; must be a positive number of seconds (simulated)",
                    s.settle_time
                ),
            );
        }
        if !(s.settle_tolerance.is_finite() && s.settle_tolerance > 0.0 && s.settle_tolerance < 1.0)
        {
            return bad(
                "settle_tolerance",
                format!(
                    "= {}; must be in (0, 1) (residual force over the loads)",
                    s.settle_tolerance
                ),
            );
        }
        if s.precision != Precision::F64 && s.is_static() {
            return bad(
                "precision",
                format!(
                    "= \"{}\" with kind = \"static\"; Newton's method needs f64 forces and \
                     tangents: remove the key, or use an explicit solver",
                    s.precision.name()
                ),
            );
        }
        Ok(())
    }

    /// Whether this is a static solve.
    pub fn is_static(&self) -> bool {
        self.kind == STATIC_KIND
    }

    /// Whether this kind is an explicit integrator of `integrators` (then
    /// `dt = "auto"` means the stable step and the run assembles no
    /// matrices); the registry's entries say which are.
    pub fn is_explicit(&self, integrators: &Integrators) -> bool {
        integrators.is_explicit(&self.kind)
    }

    /// The settling of `start = "settled"`: a static solve's, at the end
    /// time, follows the obstacles along their paths from time 0, as a
    /// static Newton solve does.
    pub fn settle_options(&self) -> SettleOptions {
        SettleOptions {
            rtol: self.settle_tolerance,
            max_time: self.settle_time,
            follow_from: self.is_static().then_some(0.0),
        }
    }

    /// The damping of the run.
    pub fn damping(&self) -> Damping {
        Damping {
            alpha: self.damping,
            beta: self.stiffness_damping,
        }
    }
}
