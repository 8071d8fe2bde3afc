//! What `mss check` reports about a prepared job without running it: sizes,
//! the time plan, memory and output estimates, the mechanisms the held
//! nodes leave free, and whether the body has a stable equilibrium under its
//! load.

use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use mss_core::solver::State;

use crate::job::{Job, LoadCheckBudget};
pub use crate::load_check::{
    LOAD_CHECK_MAX_NODES, LOAD_CHECK_MIN_INCREMENT, LoadCheck, RUN_MODE_CHECK_MAX_NODES,
    run_counts_modes,
};
use std::path::Path;

use crate::limits::run_memory_estimate;

/// The figures of a prepared job that `mss check` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckReport {
    /// Fully or partly held nodes.
    pub held_nodes: usize,
    /// Estimated peak memory of the run (bytes).
    pub memory_bytes: u64,
    /// Frames the run writes.
    pub frames: u64,
    /// Estimated bytes of one frame.
    pub frame_bytes: u64,
    /// Hourglass stiffness per cell (N/m; 0 without hourglass control).
    pub hourglass_stiffness: f64,
    /// A warning about mechanisms the held nodes leave free, if any.
    pub mechanism_warning: Option<String>,
    /// What a static solve of the scene's load found (mechanisms that appear
    /// under load, buckling), or why it was not done.
    pub load_check: LoadCheck,
    /// Estimated wall time of the run's stepping and writing, if estimated.
    pub time_estimate: Option<TimeEstimate>,
}

/// Steps an explicit run's time estimate times (after one untimed step,
/// which builds what later steps reuse).
pub const TIME_PROBE_STEPS: u32 = 6;

/// Seconds a frame costs whatever its size (files created and renamed, the
/// `.pvd` collections rewritten), measured on the bundled drop scene (151
/// frames of the lattice and the embedded surface, compressed).
const FRAME_SECONDS: f64 = 0.003;
/// Estimated frame bytes ([`Job::output_estimate`]) written per second and
/// thread with zlib (compression runs in parallel), and in all without
/// compression; measured on voxelized cubes of 32^3 to 96^3 cells.
const WRITE_RATE_ZLIB_PER_THREAD: f64 = 450e6;
const WRITE_RATE_NONE: f64 = 1.2e9;

/// The wall time a run should take, from its own steps timed on a scratch
/// state (nothing is written): what `mss check` prints as the time estimate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimeEstimate {
    /// Estimated wall time of the run: its load check, stepping and
    /// writing (s).
    pub seconds: f64,
    /// Of which writing the frames (s).
    pub writing_seconds: f64,
    /// Of which the run's own load check before its first step (s; see
    /// [`Job::run_load_check_budget`]).
    pub load_check_seconds: f64,
    /// Steps timed (0: the static solve of [`LoadCheck`] was timed).
    pub probe_steps: u32,
    /// Wall time per step measured (s).
    pub seconds_per_step: f64,
    /// The pilot run whose stepping time is the estimate's ([`Pilot`]);
    /// `None` when it failed at once (the steps timed at rest are used).
    pub pilot: Option<Pilot>,
}

/// A run of the scene with nothing written, made by `mss check` for its
/// time estimate. Steps timed at rest miss what changes a step's cost
/// later: contact, a moving obstacle, a fall, and above all a body that does
/// not carry its load statically. Such a body folds or collapses, its
/// compressed cells stiffen, and the explicit sub-step (or the implicit
/// solver's Newton iterations) follows them, with more frequent checks and
/// steps taken again: the soft bunny held by its lowest layer costs ten
/// times its steps at rest. The pilot runs on the scene's own lattice: one
/// twice as coarse spreads the load of a few held nodes over larger cells
/// and folds less (the soft bunny's saw a sixth of the growth). It stops
/// after [`PILOT_SECONDS`] (a folding body) or [`PILOT_CALM_SECONDS`]; the
/// rest of the run is then projected at the rate of the pilot's last
/// quarter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Pilot {
    /// Its mean wall time per step over the scene's duration (projected
    /// past [`Pilot::simulated_fraction`]) over the time per step at rest.
    pub time_ratio: f64,
    /// Its stepping time over the scene's duration (s; projected past
    /// [`Pilot::simulated_fraction`]).
    pub stepping_seconds: f64,
    /// The fraction of the scene's duration it ran (1: to the end; less
    /// when its time budget ran out or a step failed).
    pub simulated_fraction: f64,
}

/// Wall time a [`Pilot`] run may take when the body folds (s).
pub const PILOT_SECONDS: f64 = 15.0;
/// Wall time a [`Pilot`] run may take when the body carries its load (s):
/// contact, a moving obstacle or a fall still change the step's cost (the
/// squeeze scene's ball pressed flat: 1.7 times the steps timed at rest).
pub const PILOT_CALM_SECONDS: f64 = 3.0;

impl TimeEstimate {
    /// Times `job`'s steps (see [`TimeEstimate`]); `static_seconds` is the
    /// time the load check's static solve took, the estimate of a static
    /// run, and `load_check_seconds` how long it would take in the run (see
    /// [`Job::run_load_check_budget`]); `folds`: the body does not carry
    /// its load statically. `None` for an implicit run on more than
    /// [`LOAD_CHECK_MAX_NODES`] nodes (a probe step would cost too much),
    /// when the first step fails, or when `cancel` is set. One pass steps
    /// the scene: its first steps are the ones timed at rest, all of them
    /// the [`Pilot`] run (longer when `folds`), which measures what the
    /// steps at rest cannot see.
    pub fn new(
        job: &Job,
        static_seconds: Option<f64>,
        load_check_seconds: f64,
        folds: bool,
        cancel: &AtomicBool,
    ) -> Option<Self> {
        let (frame_bytes, frames) = job.output_estimate();
        let rate = match job.input.scene.output.compression {
            crate::scene::CompressionKey::Zlib => {
                WRITE_RATE_ZLIB_PER_THREAD * rayon::current_num_threads() as f64
            }
            crate::scene::CompressionKey::None => WRITE_RATE_NONE,
        };
        let writing_seconds = frames as f64 * (FRAME_SECONDS + frame_bytes as f64 / rate);
        let plan = &job.plan;
        if plan.is_static {
            let solve = static_seconds?;
            return Some(TimeEstimate {
                seconds: solve + writing_seconds,
                writing_seconds,
                load_check_seconds: 0.0,
                probe_steps: 0,
                seconds_per_step: solve,
                pilot: None,
            });
        }
        let explicit = job
            .input
            .scene
            .solver
            .is_explicit(&job.registry.integrators);
        let model = job.problem.model();
        if !explicit && model.num_nodes() > LOAD_CHECK_MAX_NODES {
            return None;
        }
        let mut integrator = job
            .input
            .integrator(&job.registry, &job.problem, plan)
            .ok()??;
        let budget = if folds {
            PILOT_SECONDS
        } else {
            PILOT_CALM_SECONDS
        };
        // One pass: its first steps are the probe at rest, all of them the
        // pilot run.
        let ends = step_ends(job, integrator.as_mut(), budget, cancel)?;
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let probe = if explicit { TIME_PROBE_STEPS } else { 1 };
        let probe = (probe as usize)
            .min(usize::try_from(plan.steps.saturating_sub(1)).unwrap_or(usize::MAX))
            .min(ends.len() - 1);
        let first = ends[0];
        let per_step = if probe > 0 {
            (ends[probe] - ends[0]) / probe as f64
        } else {
            first
        };
        let pilot = Pilot::from_step_ends(&ends, plan.steps, per_step);
        let rest_stepping = first + per_step * plan.steps.saturating_sub(1) as f64;
        let stepping = pilot.as_ref().map_or(rest_stepping, |p| p.stepping_seconds);
        Some(TimeEstimate {
            seconds: load_check_seconds + stepping + writing_seconds,
            writing_seconds,
            load_check_seconds,
            probe_steps: probe as u32 + 1,
            seconds_per_step: per_step,
            pilot,
        })
    }
}

/// Steps `job`'s scene with `integrator` from rest, nothing written, until
/// its end, `budget` seconds or `cancel`; each step's end from the start
/// (s). `None` when the first step fails.
fn step_ends(
    job: &Job,
    integrator: &mut dyn mss_core::solver::Integrator,
    budget: f64,
    cancel: &AtomicBool,
) -> Option<Vec<f64>> {
    let plan = &job.plan;
    let mut state = State::at_rest(job.problem.model());
    job.problem.apply_constraints(&mut state);
    let mut ends = Vec::with_capacity(usize::try_from(plan.steps).unwrap_or(0).min(1 << 20));
    let started = std::time::Instant::now();
    while (ends.len() as u64) < plan.steps
        && !cancel.load(Ordering::Relaxed)
        && started.elapsed().as_secs_f64() < budget
    {
        if let Err(e) = integrator.step(&job.problem, &mut state) {
            log::info!("the pilot run for the time estimate stopped: {e}");
            break;
        }
        ends.push(started.elapsed().as_secs_f64());
    }
    (!ends.is_empty()).then_some(ends)
}

impl Pilot {
    /// The pilot of a run of `steps` steps whose first steps ended at
    /// `ends` (s from its start) and whose steps at rest took
    /// `rest_per_step` seconds; `None` with fewer than two steps.
    pub fn from_step_ends(ends: &[f64], steps: u64, rest_per_step: f64) -> Option<Pilot> {
        let done = ends.len();
        if done < 2 {
            return None;
        }
        let total = steps.max(1) as f64;
        let mut stepping_seconds = ends[done - 1];
        if (done as u64) < steps {
            // The rest at the rate of the last quarter of the steps taken.
            let from = done - done.div_ceil(4);
            let from_time = if from == 0 { 0.0 } else { ends[from - 1] };
            let rate = (ends[done - 1] - from_time) / (done - from) as f64;
            stepping_seconds += rate * (total - done as f64);
        }
        Some(Pilot {
            time_ratio: stepping_seconds / total / rest_per_step.max(f64::MIN_POSITIVE),
            stepping_seconds,
            simulated_fraction: done as f64 / total,
        })
    }
}

impl CheckReport {
    /// Whether the load check says the body does not carry its load
    /// statically (it folds or collapses), or could not tell.
    pub fn body_folds(&self) -> bool {
        load_check_folds(&self.load_check)
    }

    /// Whether the time estimate is only a lower bound: the body cannot
    /// carry its load statically (it buckles or collapses, or the solve
    /// failed), and a run's explicit steps shrink as it folds, which steps
    /// timed at rest cannot see, and no [`Pilot`] run measured that (it
    /// failed at once; the soft bunny hanging by its feet took 10 times the
    /// steps timed at rest).
    /// (A static scene's estimate is the load check's own solve, made only
    /// when it converged.)
    pub fn time_is_lower_bound(&self) -> bool {
        load_check_folds(&self.load_check)
            && self
                .time_estimate
                .as_ref()
                .is_some_and(|t| t.pilot.is_none())
    }

    /// Estimates and checks for `job`: counts zero-energy modes, solves the
    /// scene's load statically ([`LoadCheck`]; seconds on large lattices)
    /// and times a few of the run's steps ([`TimeEstimate`]).
    pub fn new(job: &Job) -> Self {
        Self::new_cancellable(job, &AtomicBool::new(false))
    }

    /// [`CheckReport::new`] that stops its static solve within a Newton
    /// iteration once `cancel` is set (a Ctrl-C), and then times no steps:
    /// the report says "not solved: stopped" and has no time estimate.
    pub fn new_cancellable(job: &Job, cancel: &AtomicBool) -> Self {
        let model = job.problem.model();
        let (frame_bytes, frames) = job.output_estimate();
        let held_nodes = (0..model.num_nodes())
            .filter(|&n| job.problem.constraints().mask(n).iter().any(|&h| h))
            .count();
        let needs_matrix = !job
            .input
            .scene
            .solver
            .is_explicit(&job.registry.integrators);
        let mechanism_warning = mechanism_warning(job);
        let started = std::time::Instant::now();
        // A free body in a dynamic run (held by obstacles, or by nothing)
        // has no static equilibrium to compare the run with.
        let free_dynamic = !job.plan.is_static && crate::job::problem_is_free(&job.problem);
        let run_budget = job.run_load_check_budget();
        let (load_check, peak_at_budget) = if free_dynamic {
            let skipped = LoadCheck::Skipped {
                reason: "no node is held: the body moves freely, or as its obstacles let it"
                    .to_owned(),
            };
            (skipped, None)
        } else if let LoadCheckBudget::AtMost(budget) = run_budget {
            // The run stops its check after `budget` seconds: its memory is
            // this process's peak at that time, not at the end of the check.
            let done = AtomicBool::new(false);
            std::thread::scope(|scope| {
                let sampler = scope.spawn(|| {
                    while !done.load(Ordering::Relaxed) && started.elapsed().as_secs_f64() < budget
                    {
                        std::thread::sleep(std::time::Duration::from_millis(10));
                    }
                    crate::job::peak_memory_bytes()
                });
                let check = job.load_check(mechanism_warning.is_some(), cancel);
                done.store(true, Ordering::Relaxed);
                (check, sampler.join().ok().flatten())
            })
        } else {
            let check = job.load_check(mechanism_warning.is_some(), cancel);
            (check, crate::job::peak_memory_bytes())
        };
        let check_seconds = started.elapsed().as_secs_f64();
        let static_seconds =
            matches!(load_check, LoadCheck::Equilibrium { .. }).then_some(check_seconds);
        // The run solves the same load before its first step, for as long
        // as its budget lets it.
        let run_check_seconds = match run_budget {
            LoadCheckBudget::None => 0.0,
            LoadCheckBudget::ToTheVerdict => check_seconds,
            LoadCheckBudget::AtMost(budget) => check_seconds.min(budget),
        };
        let folds = load_check_folds(&load_check);
        let mut memory_bytes =
            run_memory_estimate(model.num_cells(), model.num_nodes(), needs_matrix)
                + crate::limits::mesh_memory_estimate(
                    job.bodies.iter().map(|b| b.mesh.vertices.len()).sum(),
                );
        // The run solves the same load (or, static, is that solve): what
        // this process needed for it is a measurement, where the sparse
        // factorization's dense kernels keep per-thread buffers sized by the
        // host's caches (57 MiB resident for the default job on a host
        // reporting a 480 MiB L3) that no count of cells predicts.
        let run_solves = job.plan.is_static || run_budget != LoadCheckBudget::None;
        if run_solves && !matches!(load_check, LoadCheck::Skipped { .. }) {
            memory_bytes = memory_bytes.max(peak_at_budget.unwrap_or(0));
        }
        CheckReport {
            held_nodes,
            memory_bytes,
            frames,
            frame_bytes,
            hourglass_stiffness: model.cell_coefficients(0).hourglass,
            time_estimate: if cancel.load(Ordering::Relaxed) {
                None
            } else {
                TimeEstimate::new(job, static_seconds, run_check_seconds, folds, cancel)
            },
            load_check,
            mechanism_warning,
        }
    }

    /// Free bytes on the disk of `out_dir` and a warning when the output
    /// would take more than half of it (the run refuses more than all of it).
    pub fn disk(&self, out_dir: &Path) -> (Option<u64>, Option<String>) {
        let free = crate::limits::free_disk_bytes(out_dir);
        let needed = self.frames.saturating_mul(self.frame_bytes);
        let warning = free.and_then(|f| {
            (needed > f / 2).then(|| {
                format!(
                    "the output (about {}) {} the {} free in {}",
                    crate::error::human(needed),
                    if needed > f {
                        "exceeds"
                    } else {
                        "takes more than half of"
                    },
                    crate::error::human(f),
                    out_dir.display()
                )
            })
        });
        (free, warning)
    }
}

/// Whether the load check says a run folds or collapses (or could not tell).
fn load_check_folds(check: &LoadCheck) -> bool {
    matches!(
        check,
        LoadCheck::LoadLimit { .. } | LoadCheck::Failed { .. } | LoadCheck::Mechanism { .. }
    )
}

/// A warning if the boundary conditions leave zero-energy motions (rigid
/// motions or hourglass mechanisms) that the loads can excite: counted on the
/// rest stiffness restricted to the free dofs (`mss_core::modes`).
pub fn mechanism_warning(job: &Job) -> Option<String> {
    let c = job.problem.constraints();
    let model = job.problem.model();
    let restrained = !job.input.scene.loads.drags.is_empty();
    // With rigid cells (hourglass control) the only zero-energy modes are
    // rigid motions of the body's free parts. Obstacles hold those (a body
    // resting on the ground), and in a dynamic run a body that nothing holds
    // moving as a whole is physics, not a defect. A body held by too few
    // nodes is still warned about: it swings about them.
    let rigid_motions_only = mss_core::modes::cells_are_rigid(model);
    let free_dynamic = !job.plan.is_static && crate::job::problem_is_free(&job.problem);
    if rigid_motions_only && (job.problem.contact().is_some() || free_dynamic) {
        return None;
    }
    let mask: Vec<[bool; 3]> = (0..model.num_nodes()).map(|n| c.mask(n)).collect();
    match mss_core::modes::zero_energy_modes(model, &mask) {
        Ok(z) if z.count == 0 => None,
        Ok(z) => Some(format!(
            "the held nodes leave {}{} zero-energy mode(s) (rigid motions or hourglass \
             mechanisms){}: a static solve will fail and dynamics may drift; hold a larger \
             region (e.g. a whole face){}",
            z.count,
            if z.exact { "" } else { " or more" },
            if restrained {
                "; drag springs restrain some of them"
            } else {
                ""
            },
            if model.cell_coefficients(0).hourglass > 0.0 {
                ""
            } else {
                // Parts one cell thick leave hourglass mechanisms however they are held.
                ", or add hourglass control ([model] parameterization \"...+hg\" or hourglass = 0.05)"
            },
        )),
        Err(e) => {
            log::debug!("zero-energy modes not counted: {e}");
            let held = c.num_held_dofs();
            if held < 6 && !restrained {
                Some(format!(
                    "only {held} displacement components are held: rigid motions remain free"
                ))
            } else {
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Pilot;

    /// A pilot cut short projects the rest at its last quarter's rate; one
    /// that ran to the end is its own time.
    #[test]
    fn a_pilot_projects_the_rest_at_its_last_quarters_rate() {
        // Steps of 1 s, then 2 s: the last quarter (one step) took 2 s.
        let p = Pilot::from_step_ends(&[1.0, 2.0, 3.0, 5.0], 10, 1.0).unwrap();
        assert_eq!(p.stepping_seconds, 5.0 + 6.0 * 2.0);
        assert_eq!(p.simulated_fraction, 0.4);
        assert_eq!(p.time_ratio, 1.7);
        let whole = Pilot::from_step_ends(&[1.0, 2.0, 3.0, 5.0], 4, 1.0).unwrap();
        assert_eq!(whole.stepping_seconds, 5.0);
        assert!(Pilot::from_step_ends(&[1.0], 4, 1.0).is_none());
    }
}
