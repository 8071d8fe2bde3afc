//! Running a scene: [`Job::prepare`] loads, voxelizes and builds the problem;
//! [`Job::run`] time-steps (or solves statically) and writes the outputs.
//! Progress goes to a callback, and a [`Cancel`] flag stops a run between
//! steps with everything written so far kept.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use hexmesh::image::ImageLattice;
use mss_core::Model;
use mss_core::solver::{
    Integrator, Problem, SettleInfo, State, settle_cancellable, solve_static_cancellable,
};
use serde::Serialize;

use crate::build::{SceneInput, TimePlan, prepare_output_folder};
use crate::checkpoint::{CHECKPOINT_FILE, Checkpoint};
use crate::error::JobError;
use crate::limits::Limits;
use crate::load_check::LoadCheck;
use crate::output::{FrameWriter, remove_previous_run};
use crate::registry::Registry;
use crate::scene::{BodySource, BodyView, Scene, Start};
use crate::stages::{PlacedMesh, RunNeeds, StageError, lattice_within, load_placed};

/// What a running job reports, through the callback given to
/// [`Job::prepare`] and [`Job::run`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// Voxelizing: grid rows classified out of the total.
    Voxelizing {
        /// Rows done.
        done: u64,
        /// Rows in all.
        total: u64,
    },
    /// A static solve is running (its length is not known in advance).
    Solving,
    /// Time stepping: steps done out of the total.
    Stepping {
        /// Steps done.
        done: u64,
        /// Steps in all.
        total: u64,
    },
    /// The current stage ended (a front end clears its bar).
    StageDone,
}

/// A progress callback; it must be cheap (a progress bar's update).
pub type ProgressFn<'a> = &'a (dyn Fn(Progress) + Sync);

/// A progress callback that ignores everything.
pub fn no_progress(_: Progress) {}

/// A flag that asks a running job to stop after the current step (set it from
/// another thread or a signal handler). The job then finishes the frame being
/// written, writes the last state reached as a frame and returns its summary
/// with [`RunSummary::interrupted`] set.
#[derive(Debug, Clone, Default)]
pub struct Cancel(Arc<AtomicBool>);

impl Cancel {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Asks the job to stop.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }
    /// Whether [`cancel`](Self::cancel) was called.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// The underlying flag, for a signal handler to set (it only stores
    /// `true`, which is async-signal-safe).
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.0)
    }
}

/// Everything built from a scene before time stepping.
pub struct Job {
    /// The scene.
    pub input: SceneInput,
    /// The plug points it was built with.
    pub registry: Registry,
    /// The bodies: each one's surface, lattice and regions, in the model's
    /// node order (one for a scene without `[[bodies]]`).
    pub bodies: Vec<JobBody>,
    /// The problem (model, constraints, loads, damping, contact).
    pub problem: Problem,
    /// The resource limits it was prepared with.
    pub limits: Limits,
    /// Time stepping plan.
    pub plan: TimePlan,
    /// Seconds spent loading and voxelizing the meshes.
    pub voxelize_seconds: f64,
}

/// One body of a [`Job`].
#[derive(Debug, Clone)]
pub struct JobBody {
    /// Its name (`[[bodies]] name`, or `"body"`).
    pub name: String,
    /// Display name of its mesh (or image).
    pub mesh_name: String,
    /// The cleaned input surface, placed (for an image: its labels'
    /// boundary).
    pub mesh: hexmesh::TriMesh,
    /// How the mesh was placed (`[mesh]` units, scale, ...), described.
    pub placement: String,
    /// The voxelized lattice.
    pub lattice: hexmesh::Lattice,
    /// Voxelization statistics.
    pub vox_stats: hexmesh::voxelize::VoxelizeStats,
    /// The materials of its `[[regions]]` and the cells they hold (`None`
    /// without regions).
    pub regions: Option<crate::regions::RegionAssignment>,
    /// The image label of each cell, for a body made from an `[image]`.
    pub cell_labels: Option<Vec<i32>>,
}

impl Job {
    /// The first body's mesh (the only one without `[[bodies]]`).
    pub fn mesh(&self) -> &hexmesh::TriMesh {
        &self.bodies[0].mesh
    }
    /// The first body's lattice.
    pub fn lattice(&self) -> &hexmesh::Lattice {
        &self.bodies[0].lattice
    }
    /// The first body's mesh name.
    pub fn mesh_name(&self) -> &str {
        &self.bodies[0].mesh_name
    }
    /// The first body's voxelization statistics.
    pub fn vox_stats(&self) -> &hexmesh::voxelize::VoxelizeStats {
        &self.bodies[0].vox_stats
    }
    /// The first body's regions.
    pub fn regions(&self) -> Option<&crate::regions::RegionAssignment> {
        self.bodies[0].regions.as_ref()
    }

    /// Each body's lattice and input surface, in the model's node order.
    pub fn parts(&self) -> Vec<(&hexmesh::Lattice, &hexmesh::TriMesh)> {
        parts_of(&self.bodies)
    }

    /// Every body's input surface embedded in its lattice, as one embedding
    /// over the model's nodes (vertices and triangles in body order).
    pub fn embedding(&self) -> hexmesh::Embedding {
        crate::output::joined_embedding(&self.parts())
    }

    /// Every body's lattice skin, as one skin over the model's nodes.
    pub fn skin(&self) -> hexmesh::Skin {
        crate::output::joined_skin(&self.parts())
    }
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("scene", &self.input.name())
            .field(
                "bodies",
                &self.bodies.iter().map(|b| &b.name).collect::<Vec<_>>(),
            )
            .field("cells", &self.problem.model().num_cells())
            .field("plan", &self.plan)
            .finish()
    }
}

/// How a dynamic run checks its load statically before its first step
/// ([`Job::run_load_check_budget`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoadCheckBudget {
    /// It does not check (a static run, `[solver] accept_unstable`, or the
    /// default kind of model on a body nothing holds).
    None,
    /// It waits for the verdict (a model the check may refuse).
    ToTheVerdict,
    /// It waits at most these seconds ([`Limits::load_check_seconds`]: the
    /// default kind of model, hourglass control and the barrier, whose check
    /// only warns).
    AtMost(f64),
}

/// Figures of a finished run (printed by the CLI, written as `summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Scene file, or the bundled default.
    pub scene: String,
    /// Mesh name.
    pub mesh: String,
    /// How the mesh was placed before voxelizing (`[mesh]` units, scale,
    /// up, rotate, translate), or `"none"`.
    pub placement: String,
    /// Size of the placed mesh's bounding box along x, y, z (m).
    pub mesh_extent: [f64; 3],
    /// Cells per material: `[material]`, then each `[[regions]]` table
    /// (one entry without regions).
    pub cells_per_material: Vec<usize>,
    /// Lattice cells.
    pub cells: usize,
    /// Lattice nodes.
    pub nodes: usize,
    /// Springs.
    pub springs: usize,
    /// Cell edge (m).
    pub cell_size: f64,
    /// Total mass (kg).
    pub mass: f64,
    /// Fully or partly held nodes.
    pub held_nodes: usize,
    /// Solver kind.
    pub solver: String,
    /// Time step (s).
    pub time_step: f64,
    /// Stable explicit step with the scene's safety factor (s).
    pub stable_time_step: f64,
    /// Steps taken.
    pub steps: u64,
    /// Simulated time (s).
    pub simulated_time: f64,
    /// Frames written.
    pub frames: usize,
    /// Files written.
    pub files: usize,
    /// Bytes written.
    pub bytes_written: u64,
    /// Largest node displacement at the end (m).
    pub max_displacement: f64,
    /// Largest node displacement over every step of the run (m): a body
    /// that swings or is pressed and released moves most before the end.
    pub peak_displacement: f64,
    /// Simulated time of [`RunSummary::peak_displacement`] (s).
    pub peak_displacement_time: f64,
    /// Wall time of voxelization (s).
    pub voxelize_seconds: f64,
    /// Wall time of time stepping, including output (s).
    pub simulate_seconds: f64,
    /// Total wall time (s).
    pub wall_seconds: f64,
    /// Peak resident memory (bytes), if known.
    pub peak_memory_bytes: Option<u64>,
    /// Output folder.
    pub output_folder: String,
    /// Whether the run was stopped through its [`Cancel`] flag before the
    /// end (the frames written stop at `simulated_time`).
    pub interrupted: bool,
    /// Newton iterations of the implicit or static solves (0 for explicit
    /// runs).
    pub newton_iterations: u64,
    /// Newton iterations per step (per time step; of the whole solve for a
    /// static one).
    pub newton_iterations_per_step: f64,
    /// Each body's figures (one entry without `[[bodies]]`); the fields
    /// above are the totals, or the first body's for its mesh.
    pub bodies: Vec<BodySummary>,
    /// Cells folded at a corner at the end (a corner Jacobian `<= 0` while
    /// the centre may look healthy: `Model::folded_cells`).
    pub folded_cells: usize,
    /// Most cells folded at a corner in one frame (frames written since the
    /// run started or was resumed), and that frame's time (s).
    pub most_folded_cells: (usize, f64),
    /// What the load check before a dynamic run found, in one line (as
    /// `mss check` prints it), or that it was stopped after
    /// [`Limits::load_check_seconds`](crate::limits::Limits::load_check_seconds);
    /// `None` when no check ran (a static run, a resumed or free body, or
    /// `accept_unstable`).
    pub load_check: Option<String>,
    /// What the settling of `[solver] start = "settled"` did (`None`: the
    /// run started at rest, or was resumed).
    pub settled: Option<SettleReport>,
}

/// What the settling of a run's start did ([`mss_core::solver::SettleInfo`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SettleReport {
    /// Steps of the settling integrator.
    pub steps: u64,
    /// The frequency of the last motion damped (rad/s).
    pub omega: f64,
    /// Simulated time the settling took (s; the run then starts at its
    /// start time).
    pub settle_time: f64,
    /// Residual force over the loads' at the end.
    pub relative_residual: f64,
    /// Newton iterations (an implicit settling).
    pub newton_iterations: u64,
}

impl From<SettleInfo> for SettleReport {
    fn from(i: SettleInfo) -> Self {
        Self {
            steps: i.steps,
            omega: i.omega,
            settle_time: i.settle_time,
            relative_residual: i.relative_residual,
            newton_iterations: i.newton_iterations,
        }
    }
}

/// What a run counts as it goes, kept across a resume by its checkpoint.
#[derive(Debug, Clone, Copy, Default)]
struct RunTotals {
    /// Largest node displacement so far (m) and its time (s).
    peak: (f64, f64),
    /// Newton iterations so far.
    newton_iterations: u64,
    /// Most cells folded at a corner in one frame written by this process,
    /// and its time (s).
    most_folded: (usize, f64),
}

impl RunTotals {
    /// Counts the cells folded at a corner at a frame (`Model::folded_cells`)
    /// and warns the first time there are any: the run goes on (the corner
    /// barrier may unfold them), but the user learns where it happened.
    /// Returns the count.
    fn note_folds(&mut self, scene: &str, model: &mss_core::Model, state: &State) -> usize {
        let folded = model.folded_cells(&state.x);
        if folded.is_empty() {
            return 0;
        }
        if self.most_folded.0 == 0 {
            log::warn!(
                "{scene}: {} cells are folded at a corner at t = {:.3e} s (a corner Jacobian \
                 <= 0; cells {:?}...): the body is deformed past what its lattice resolves there. \
                 A finer lattice ([voxelize] cells), the default model (its corner barrier), \
                 more held nodes or more damping avoid it",
                folded.len(),
                state.time,
                &folded[..folded.len().min(8)]
            );
        }
        if folded.len() > self.most_folded.0 {
            self.most_folded = (folded.len(), state.time);
        }
        folded.len()
    }
}

/// One body's figures in a [`RunSummary`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BodySummary {
    /// Its name.
    pub name: String,
    /// Its mesh.
    pub mesh: String,
    /// How its mesh was placed.
    pub placement: String,
    /// Its cells.
    pub cells: usize,
    /// Its nodes.
    pub nodes: usize,
    /// Its cell edge (m).
    pub cell_size: f64,
    /// Its mass (kg).
    pub mass: f64,
    /// Its cells per material (its `[material]`, then its regions).
    pub cells_per_material: Vec<usize>,
    /// Its largest node displacement at the end (m).
    pub max_displacement: f64,
    /// The total force the other bodies (and its own self-contact, which
    /// sums to zero) exert on it at the end (N).
    pub contact_force_from_bodies: [f64; 3],
}

impl Job {
    /// Loads the mesh, voxelizes it and builds the problem and time plan of a
    /// scene, resolving its names against `registry`. Nothing is written.
    pub fn prepare(
        input: SceneInput,
        registry: Registry,
        progress: ProgressFn<'_>,
    ) -> Result<Job, JobError> {
        Self::prepare_with_limits(input, registry, Limits::default(), progress)
    }

    /// [`Job::prepare`] with resource limits: the bounding grid and the run
    /// are estimated before they are allocated and refused above
    /// `limits.memory_bytes` ([`crate::limits`]); the limits are kept for
    /// the disk check of [`Job::run`].
    pub fn prepare_with_limits(
        input: SceneInput,
        registry: Registry,
        limits: Limits,
        progress: ProgressFn<'_>,
    ) -> Result<Job, JobError> {
        let scene = &input.scene;
        if scene.is_plane() {
            return Err(JobError::Setting {
                scene: input.name(),
                key: "[model] dimension".into(),
                message: "= 2: a 2D scene runs with `mss run` (or hexmss.run); `mss view`, \
                          hexmss.prepare and the interactive simulation take 3D scenes"
                    .into(),
            });
        }
        let t0 = Instant::now();
        let mut registry = registry;
        limits.bound_loaders(&mut registry.loaders);
        let mut bodies = Vec::new();
        for view in scene.bodies() {
            bodies.push(prepare_body(&input, &view, &registry, &limits, progress)?);
        }
        let voxelize_seconds = t0.elapsed().as_secs_f64();
        let problem = build_problem(&input, &registry, &bodies, Vec::new())?;
        let plan = input.time_plan(&problem, &registry.integrators)?;
        // Refuse a bad integrator choice (unknown name, a dt above the
        // stability limit) here, before anything is written.
        input.integrator(&registry, &problem, &plan)?;
        // A run keeps the lattices for their positions and cells (shared
        // with the model and the frames); their grid coordinates, 24 bytes
        // per cell, are derived again if anything asks for them.
        for body in &mut bodies {
            body.lattice.release_coordinates();
        }
        Ok(Job {
            bodies,
            limits,
            problem,
            plan,
            voxelize_seconds,
            input,
            registry,
        })
    }

    /// A fresh copy of the job's problem, built as [`Job::prepare`] built it
    /// (a front end that hands the problem to an owner, such as an
    /// interactive [`Simulation`](mss_core::simulation::Simulation), keeps
    /// the job's own for runs).
    pub fn rebuild_problem(&self) -> Result<Problem, JobError> {
        self.interactive_problem(Vec::new())
    }

    /// [`Job::rebuild_problem`] with `extra` obstacles touching the body
    /// after the scene's own (a viewer's poking sphere, a haptic tool),
    /// usually [`Steered`](mss_core::contact::Steered) ones.
    pub fn interactive_problem(
        &self,
        extra: crate::build::ExtraObstacles,
    ) -> Result<Problem, JobError> {
        build_problem(&self.input, &self.registry, &self.bodies, extra)
    }

    /// Time-steps (or statically solves) the job, writing frames into
    /// `out_dir` (created if missing). A set `cancel` flag stops the time loop
    /// between steps: the state reached is written as the last frame and the
    /// summary says `interrupted`. The files of an earlier run in that
    /// folder are removed first (and only those:
    /// [`previous_run_files`](crate::output::previous_run_files)), so a
    /// shorter run does not leave stale frames beside its own. On a solver
    /// failure the last good state is written as the final frame before the
    /// error is returned.
    pub fn run(
        &self,
        out_dir: &Path,
        progress: ProgressFn<'_>,
        cancel: &Cancel,
    ) -> Result<RunSummary, JobError> {
        self.run_from(out_dir, progress, cancel, None)
    }

    /// Continues the run whose checkpoint (`checkpoint.mss`, written at an
    /// interruption and every `[output] checkpoint_every` seconds) is in
    /// `out_dir`: the frames and the summary are then bitwise those of a run
    /// that was never interrupted (timings aside). Refused if the scene has
    /// changed since, or for a static solve.
    pub fn resume(
        &self,
        out_dir: &Path,
        progress: ProgressFn<'_>,
        cancel: &Cancel,
    ) -> Result<RunSummary, JobError> {
        let resume_error = |message: String| JobError::Resume {
            scene: self.input.name(),
            folder: out_dir.to_path_buf(),
            message,
        };
        if self.plan.is_static {
            return Err(resume_error(
                "a static solve is one step: there is nothing to resume; run it again".into(),
            ));
        }
        let fingerprint = crate::checkpoint::fingerprint(&self.input.scene);
        let checkpoint = Checkpoint::read(out_dir, fingerprint, self.problem.model().num_nodes())
            .map_err(|e| {
                resume_error(match &e {
                    crate::checkpoint::CheckpointError::Io { source, .. }
                        if source.kind() == std::io::ErrorKind::NotFound =>
                    {
                        format!(
                            "{e}; a run leaves one when it is interrupted, or every [output] checkpoint_every seconds, and removes it when it completes"
                        )
                    }
                    _ => e.to_string(),
                })
            })?;
        // A checkpoint with a valid checksum can still disagree with the
        // scene's time plan (written by hand, or by another version).
        let expected = checkpoint.step as f64 * self.plan.dt;
        let t = checkpoint.state.time;
        // Steps summed one by one drift from step * dt by rounding only.
        let tolerance = 1e-6 * self.plan.dt * (1.0 + checkpoint.step as f64);
        if !(t.is_finite() && (t - expected).abs() <= tolerance) {
            return Err(resume_error(format!(
                "the checkpoint's time {t} s does not match its step {} at the scene's dt {} s ({expected} s)",
                checkpoint.step, self.plan.dt
            )));
        }
        if let Some(&late) = checkpoint
            .frame_times
            .iter()
            .find(|&&f| f < 0.0 || f > t + 1e-9 * self.plan.dt)
        {
            return Err(resume_error(format!(
                "the checkpoint lists a frame at {late} s, outside the {t} s simulated so far"
            )));
        }
        if checkpoint.step >= self.plan.steps {
            return Err(resume_error(format!(
                "the checkpoint is at step {} of {}: the run is complete",
                checkpoint.step, self.plan.steps
            )));
        }
        self.run_from(out_dir, progress, cancel, Some(checkpoint))
    }

    /// Solves the job's load statically at the scene's end time (see
    /// [`LoadCheck`]); stops at the next load increment once `cancel` is
    /// set. `mechanisms_at_rest` (the held nodes leave zero-energy modes)
    /// skips the solve, which would fail.
    pub fn load_check(
        &self,
        mechanisms_at_rest: bool,
        cancel: &std::sync::atomic::AtomicBool,
    ) -> LoadCheck {
        let extent = self
            .bodies
            .iter()
            .filter_map(|b| b.mesh.bounding_box())
            .map(|b| b.extent().into_iter().fold(0.0, f64::max))
            .reduce(f64::max);
        LoadCheck::solve(
            &self.problem,
            self.input.static_options(),
            self.input.scene.solver.duration,
            extent,
            mechanisms_at_rest,
            cancel,
        )
    }

    /// [`Job::load_check`] stopped by `cancel`, or after `budget` seconds
    /// when one is given; also says whether the budget stopped it.
    fn load_check_within(
        &self,
        mechanisms_at_rest: bool,
        cancel: &Cancel,
        budget: Option<f64>,
    ) -> (LoadCheck, bool) {
        let Some(budget) = budget else {
            return (self.load_check(mechanisms_at_rest, &cancel.0), false);
        };
        if budget <= 0.0 {
            let skipped = LoadCheck::Skipped {
                reason: "no time for it".into(),
            };
            return (skipped, true);
        }
        let stop = AtomicBool::new(false);
        let over_budget = AtomicBool::new(false);
        let done = AtomicBool::new(false);
        let check = std::thread::scope(|scope| {
            // A watchdog rather than a deadline inside the solver: the
            // solver already stops at its cancel flag within an iteration.
            scope.spawn(|| {
                let started = Instant::now();
                while !done.load(Ordering::Relaxed) {
                    if cancel.is_cancelled() {
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                    if started.elapsed().as_secs_f64() >= budget {
                        over_budget.store(true, Ordering::Relaxed);
                        stop.store(true, Ordering::Relaxed);
                        return;
                    }
                    std::thread::sleep(Duration::from_millis(10));
                }
            });
            let check = self.load_check(mechanisms_at_rest, &stop);
            done.store(true, Ordering::Relaxed);
            check
        });
        let stopped_by_budget =
            over_budget.load(Ordering::Relaxed) && matches!(check, LoadCheck::Skipped { .. });
        (check, stopped_by_budget)
    }

    /// Whether a dynamic run of this job solves its load statically before
    /// its first step (see [`Job::run`]), and for how long at most. A
    /// resumed run does not check.
    pub fn run_load_check_budget(&self) -> LoadCheckBudget {
        if self.input.scene.solver.accept_unstable || self.plan.is_static {
            return LoadCheckBudget::None;
        }
        let model = self.problem.model();
        let default_kind = model_has_barrier(model) && mss_core::modes::cells_are_rigid(model);
        // A free body (held by obstacles or by nothing) has no static
        // equilibrium to check: its rigid motions are no defect.
        if default_kind && problem_is_free(&self.problem) {
            return LoadCheckBudget::None;
        }
        if default_kind {
            LoadCheckBudget::AtMost(self.limits.load_check_seconds)
        } else {
            LoadCheckBudget::ToTheVerdict
        }
    }

    /// Before a dynamic run with a model that is not the default's kind
    /// (hourglass control and the barrier volumetric law): solves the
    /// scene's load statically ([`LoadCheck`]) and refuses the run when that
    /// model would fold (an unstable equilibrium: a mechanism appears under
    /// the load) or, without the barrier, collapse (the equilibrium path
    /// ends before the full load). Those runs used to stop part way with
    /// cells turned inside out or end zigzagging (docs/robustness.md);
    /// `[solver] accept_unstable = true` runs them anyway.
    /// A cancelled check decides nothing: the run then stops at its first
    /// step, as interrupted. Returns the check's verdict in a line
    /// ([`LoadCheck::describe`]), if it ran.
    fn refuse_if_it_would_fold(
        &self,
        progress: &ProgressFn<'_>,
        cancel: &Cancel,
    ) -> Result<Option<String>, JobError> {
        let model = self.problem.model();
        let barrier = model_has_barrier(model);
        let budget = match self.run_load_check_budget() {
            LoadCheckBudget::None => return Ok(None),
            LoadCheckBudget::ToTheVerdict => None,
            LoadCheckBudget::AtMost(seconds) => Some(seconds),
        };
        let default_kind = budget.is_some();
        let free_body = problem_is_free(&self.problem);
        progress(Progress::Solving);
        let (check, over_budget) = self.load_check_within(free_body, cancel, budget);
        progress(Progress::StageDone);
        if over_budget {
            log::info!(
                "{}: the load check was stopped after {} s, before its verdict (the run does \
                 not wait for it; `mss check` runs it to the end)",
                self.input.name(),
                self.limits.load_check_seconds
            );
            return Ok(Some(format!(
                "stopped after {} s, before its verdict",
                self.limits.load_check_seconds
            )));
        }
        let verdict = Some(check.describe());
        if default_kind {
            // The default model runs whatever the check says (it resists
            // folding and collapse), but the user learns before the run what
            // `mss check` would have said.
            if let LoadCheck::Equilibrium {
                stable: Some(false),
                ..
            }
            | LoadCheck::LoadLimit { .. } = check
                && let Some(warning) = check.warning()
            {
                log::warn!("{}: {warning}", self.input.name());
            }
            return Ok(verdict);
        }
        let name = model.parameterization_name();
        let reason = match check {
            LoadCheck::Equilibrium {
                stable: Some(false),
                ..
            } => format!(
                "under the scene's load the static equilibrium of model {name:?} is unstable (a \
                 mechanism of the lattice appears under load): a dynamic run leaves it and folds"
            ),
            LoadCheck::Mechanism { .. } => format!(
                "the held nodes leave zero-energy modes of model {name:?} (mechanisms of the \
                 lattice at rest): a dynamic run under load folds along them"
            ),
            LoadCheck::LoadLimit { load_factor } if !barrier => format!(
                "the body carries only {:.0} % of the scene's load statically (it buckles or \
                 collapses), and model {name:?} does not resist collapse (its volumetric law \
                 has no barrier): its cells would be flattened through and turn inside out",
                100.0 * load_factor
            ),
            _ => return Ok(verdict),
        };
        Err(JobError::WouldFold {
            scene: self.input.name(),
            reason,
            remedy: "use parameterization = \"volumetric-barrier+hg\" with hourglass = 1.0 \
                     (the default), a stiffer material or a larger held region \
                     (docs/robustness.md); [solver] accept_unstable = true runs it anyway"
                .to_owned(),
        })
    }

    /// The scene's static solve from `state` (at the scene's end time);
    /// the Newton iterations it took.
    fn solve_static(
        &self,
        state: &mut State,
        progress: ProgressFn<'_>,
        cancel: &Cancel,
    ) -> Result<u64, JobError> {
        let opts = self.input.static_options();
        progress(Progress::Solving);
        let r = solve_static_cancellable(&self.problem, state, &opts, &cancel.0)
            .map_err(|e| self.name_the_body(e));
        progress(Progress::StageDone);
        let info = r.map_err(|source| JobError::Solver {
            scene: self.input.name(),
            stage: match source {
                mss_core::solver::SolverError::UnstableEquilibrium { .. } => {
                    "static solve failed ([solver] accept_unstable = true keeps an \
                     unstable equilibrium)"
                }
                mss_core::solver::SolverError::Mechanism { .. }
                    if self.problem.contact().is_some() =>
                {
                    "static solve failed ([solver] start = \"settled\" settles bodies that \
                     only contact holds)"
                }
                _ => "static solve failed",
            },
            source: Box::new(source),
        })?;
        log::info!(
            "static equilibrium: {} load steps, {} Newton iterations, relative residual {:.2e}",
            info.load_steps,
            info.newton_iterations,
            info.relative_residual
        );
        Ok(u64::from(info.newton_iterations))
    }

    /// `e` with the body a mechanism frees named as the scene names it
    /// (the core counts bodies from 1).
    fn name_the_body(&self, e: mss_core::SolverError) -> mss_core::SolverError {
        match e {
            mss_core::SolverError::Mechanism { message, nodes } => {
                let model = self.problem.model();
                let named = nodes
                    .first()
                    .map(|&n| model.body_of_node(n as usize))
                    .and_then(|b| Some((b, self.bodies.get(b)?)))
                    .map_or(message.clone(), |(b, body)| {
                        message.replace(
                            &format!("body {} (counted from 1)", b + 1),
                            &format!("body \"{}\"", body.name),
                        )
                    });
                mss_core::SolverError::Mechanism {
                    message: named,
                    nodes,
                }
            }
            other => other,
        }
    }

    /// Brings `state` to rest under the loads at its time (`[solver] start
    /// = "settled"`, [`mss_core::solver::settle`]).
    fn settle(
        &self,
        state: &mut State,
        plan: &TimePlan,
        progress: ProgressFn<'_>,
        cancel: &Cancel,
    ) -> Result<SettleInfo, JobError> {
        let mut integrator = self
            .input
            .settle_integrator(&self.registry, &self.problem, plan)?;
        progress(Progress::Solving);
        let r = settle_cancellable(
            &self.problem,
            integrator.as_mut(),
            state,
            &self.input.scene.solver.settle_options(),
            &cancel.0,
        );
        progress(Progress::StageDone);
        let info = r.map_err(|source| JobError::Solver {
            scene: self.input.name(),
            stage: "settling the start ([solver] start = \"settled\") failed",
            source: Box::new(source),
        })?;
        log::info!(
            "settled: {} steps ({:.3e} s simulated, damping last at {:.3e} rad/s), residual {:.2e} of the loads",
            info.steps,
            info.settle_time,
            info.omega,
            info.relative_residual
        );
        Ok(info)
    }

    fn run_from(
        &self,
        out_dir: &Path,
        progress: ProgressFn<'_>,
        cancel: &Cancel,
        resume: Option<Checkpoint>,
    ) -> Result<RunSummary, JobError> {
        let start = Instant::now();
        let name = self.input.name();
        let scene = &self.input.scene;
        let problem = &self.problem;
        let plan = self.plan;
        let s = &scene.solver;
        let integrator = self.input.integrator(&self.registry, problem, &plan)?;
        // A resumed run reports the verdict its first part found.
        let mut load_check = if integrator.is_some() && resume.is_none() {
            self.refuse_if_it_would_fold(&progress, cancel)?
        } else {
            None
        };
        self.check_disk_space(out_dir)?;
        let mut state = State::at_rest(problem.model());
        problem.apply_constraints(&mut state);
        let settle_start = s.start == Start::Settled && resume.is_none();
        let mut settled = None;
        let mut steps_done = 0;
        let mut totals = RunTotals::default();
        let mut interrupted = false;
        let mut writer;
        match integrator {
            None => {
                // A static solve is the whole computation: do it before creating
                // any file, so that a failure leaves nothing behind.
                let rest_state = state.clone();
                state.time = s.duration;
                if settle_start {
                    // The settling is the solve: it settles bodies that
                    // only contact holds, which Newton cannot start from.
                    let info = self.settle(&mut state, &plan, progress, cancel)?;
                    // The settling's Newton iterations are the solve's.
                    totals.newton_iterations = info.newton_iterations;
                    settled = Some(info.into());
                } else {
                    totals.newton_iterations = self.solve_static(&mut state, progress, cancel)?;
                }
                steps_done = 1;
                totals.peak = (largest_displacement(problem.model(), &state.x), state.time);
                prepare_output_folder(out_dir)?;
                remove_previous_run(out_dir, &self.registry.exporters)?;
                writer = self.writer(out_dir)?;
                if !plan.last_only {
                    writer.write(problem, &rest_state)?;
                }
                writer.write(problem, &state)?;
            }
            Some(mut integrator) => {
                // Fail on an unwritable folder before the long part.
                prepare_output_folder(out_dir)?;
                let first_step = match &resume {
                    None => {
                        if settle_start {
                            let info = self.settle(&mut state, &plan, progress, cancel)?;
                            settled = Some(info.into());
                        }
                        remove_previous_run(out_dir, &self.registry.exporters)?;
                        writer = self.writer(out_dir)?;
                        if !plan.last_only {
                            writer.write_with_scratch(
                                problem,
                                &state,
                                integrator.lend_scratch(),
                            )?;
                        }
                        1
                    }
                    Some(c) => {
                        writer = self.writer(out_dir)?;
                        writer.resume(&c.frame_times, c.files, c.bytes)?;
                        integrator
                            .restore(&c.memory)
                            .map_err(|source| JobError::Resume {
                                scene: name.clone(),
                                folder: out_dir.to_path_buf(),
                                message: source.to_string(),
                            })?;
                        state = c.state.clone();
                        totals = RunTotals {
                            peak: (c.peak_displacement, c.peak_time),
                            newton_iterations: c.newton_iterations,
                            most_folded: (0, 0.0),
                        };
                        load_check.clone_from(&c.load_check);
                        steps_done = c.step;
                        log::info!(
                            "{name}: resumed at step {} (t = {:.3e} s) from {}",
                            c.step,
                            state.time,
                            out_dir.join(CHECKPOINT_FILE).display()
                        );
                        c.step + 1
                    }
                };
                let checkpoint_steps = scene
                    .output
                    .checkpoint_every
                    .map(|t| ((t / plan.dt).round() as u64).max(1));
                let fingerprint = crate::checkpoint::fingerprint(scene);
                let checkpoint = |step: u64,
                                  state: &State,
                                  totals: RunTotals,
                                  integrator: &dyn Integrator,
                                  writer: &FrameWriter| {
                    let (files, bytes) = writer.files_and_bytes();
                    Checkpoint {
                        peak_displacement: totals.peak.0,
                        peak_time: totals.peak.1,
                        newton_iterations: totals.newton_iterations,
                        load_check: load_check.clone(),
                        fingerprint,
                        step,
                        state: state.clone(),
                        memory: integrator.memory(),
                        frame_times: writer.frame_times().to_vec(),
                        files,
                        bytes,
                    }
                    .write(out_dir)
                };
                for k in first_step..=plan.steps {
                    if cancel.is_cancelled() {
                        // The state reached can be resumed from, and it is a
                        // frame (written after the checkpoint, which does not
                        // count it: the resumed run writes that frame's index
                        // again when its time comes).
                        checkpoint(steps_done, &state, totals, integrator.as_ref(), &writer)?;
                        if steps_done > 0 && !plan.frame_after(steps_done) {
                            writer.write_with_scratch(
                                problem,
                                &state,
                                integrator.lend_scratch(),
                            )?;
                        }
                        interrupted = true;
                        log::warn!(
                            "{name}: interrupted at t = {:.3e} s after {steps_done} steps",
                            state.time
                        );
                        break;
                    }
                    if plan.frame_after(k) {
                        // A frame is written only of a state that passed
                        // every check.
                        integrator.check_next_step();
                    }
                    match integrator.step(problem, &mut state) {
                        Ok(info) => totals.newton_iterations += u64::from(info.newton_iterations),
                        Err(source) => {
                            progress(Progress::StageDone);
                            // Keep what was simulated: the last good state is a
                            // frame, unless it is the last frame already written
                            // (time never goes back in the series).
                            if writer.last_time().is_none_or(|t| state.time > t) {
                                let _ = writer.write_with_scratch(
                                    problem,
                                    &state,
                                    integrator.lend_scratch(),
                                );
                            }
                            let _ = writer.finish();
                            return Err(JobError::Solver {
                                scene: name,
                                stage: "the simulation failed",
                                source: Box::new(source),
                            });
                        }
                    }
                    steps_done = k;
                    let moved = largest_displacement(problem.model(), &state.x);
                    if moved > totals.peak.0 {
                        totals.peak = (moved, state.time);
                    }
                    if plan.frame_after(k) {
                        writer.write_with_scratch(problem, &state, integrator.lend_scratch())?;
                        let _ = totals.note_folds(&name, problem.model(), &state);
                    }
                    if checkpoint_steps.is_some_and(|n| k % n == 0) && k < plan.steps {
                        checkpoint(k, &state, totals, integrator.as_ref(), &writer)?;
                    }
                    progress(Progress::Stepping {
                        done: k,
                        total: plan.steps,
                    });
                }
                progress(Progress::StageDone);
                if !interrupted {
                    // A complete run has nothing to resume.
                    let path = out_dir.join(CHECKPOINT_FILE);
                    if path.exists() {
                        std::fs::remove_file(&path).map_err(|e| mss_io::IoError::io(&path, e))?;
                    }
                }
            }
        }
        writer.finish()?;
        let model = problem.model();
        let max_displacement = largest_displacement(model, &state.x);
        // The end state of a static solve (or a run ending between frames).
        let folded_cells = totals.note_folds(&name, model, &state);
        let (files, bytes) = writer.files_and_bytes();
        let held_nodes = (0..model.num_nodes())
            .filter(|&n| problem.constraints().mask(n).iter().any(|&h| h))
            .count();
        let body_summaries = self.body_summaries(&state);
        let first = &self.bodies[0];
        Ok(RunSummary {
            scene: name,
            mesh: first.mesh_name.clone(),
            placement: first.placement.clone(),
            mesh_extent: first.mesh.bounding_box().map_or([0.0; 3], |b| b.extent()),
            cells_per_material: body_summaries
                .iter()
                .flat_map(|b| b.cells_per_material.iter().copied())
                .collect(),
            cells: model.num_cells(),
            nodes: model.num_nodes(),
            springs: model.num_springs(),
            cell_size: model.h(),
            mass: model.total_mass(),
            held_nodes,
            solver: s.kind.clone(),
            time_step: plan.dt,
            stable_time_step: plan.stable_dt,
            steps: steps_done,
            simulated_time: state.time,
            frames: writer.frames(),
            files,
            bytes_written: bytes,
            max_displacement,
            peak_displacement: totals.peak.0,
            peak_displacement_time: totals.peak.1,
            voxelize_seconds: self.voxelize_seconds,
            simulate_seconds: start.elapsed().as_secs_f64(),
            wall_seconds: self.voxelize_seconds + start.elapsed().as_secs_f64(),
            peak_memory_bytes: peak_memory_bytes(),
            output_folder: out_dir.display().to_string(),
            interrupted,
            newton_iterations: totals.newton_iterations,
            newton_iterations_per_step: if steps_done > 0 {
                totals.newton_iterations as f64 / steps_done as f64
            } else {
                0.0
            },
            bodies: body_summaries,
            folded_cells,
            most_folded_cells: totals.most_folded,
            load_check,
            settled,
        })
    }

    /// Each body's figures at `state`.
    fn body_summaries(&self, state: &State) -> Vec<BodySummary> {
        let problem = &self.problem;
        let model = problem.model();
        let between = problem.contact().and_then(|c| {
            let b = c.bodies()?;
            let anchors = &state.contact[state.contact.len().saturating_sub(b.num_points())..];
            Some(b.body_forces(&state.x, &state.v, anchors))
        });
        self.bodies
            .iter()
            .zip(model.bodies())
            .enumerate()
            .map(|(b, (body, span))| {
                let nodes = span.nodes.clone();
                let rest = &model.rest_positions()[nodes.clone()];
                let max_displacement = state.x[nodes.clone()]
                    .iter()
                    .zip(rest)
                    .map(|(x, r)| (x - r).norm())
                    .fold(0.0, f64::max);
                BodySummary {
                    name: body.name.clone(),
                    mesh: body.mesh_name.clone(),
                    placement: body.placement.clone(),
                    cells: span.cells.len(),
                    nodes: nodes.len(),
                    cell_size: span.h,
                    mass: model.masses()[nodes].iter().sum(),
                    cells_per_material: body
                        .regions
                        .as_ref()
                        .map_or_else(|| vec![span.cells.len()], |a| a.cells_per_material()),
                    max_displacement,
                    contact_force_from_bodies: between
                        .as_ref()
                        .map_or([0.0; 3], |f| [f[b].x, f[b].y, f[b].z]),
                }
            })
            .collect()
    }

    /// Estimated bytes of one frame and frames written by [`Job::run`].
    pub fn output_estimate(&self) -> (u64, u64) {
        let model = self.problem.model();
        let skin = self.skin();
        let frame_bytes = crate::output::frame_size_estimate(
            &self.input.scene.output,
            &self.registry.exporters,
            &crate::output::FrameCounts {
                nodes: model.num_nodes(),
                cells: model.num_cells(),
                springs: model.num_springs(),
                skin_vertices: skin.vertex_nodes.len(),
                skin_triangles: skin.triangles.len(),
                surface_vertices: self.bodies.iter().map(|b| b.mesh.vertices.len()).sum(),
                surface_triangles: self.bodies.iter().map(|b| b.mesh.triangles.len()).sum(),
            },
        );
        (frame_bytes, self.plan.num_frames())
    }

    /// Refuses a run whose frames would not fit on the output folder's disk.
    fn check_disk_space(&self, out_dir: &Path) -> Result<(), JobError> {
        if !self.limits.check_disk {
            return Ok(());
        }
        let Some(free) = self
            .limits
            .output_bytes
            .or_else(|| crate::limits::free_disk_bytes(out_dir))
        else {
            return Ok(());
        };
        let (frame_bytes, frames) = self.output_estimate();
        let needed = frame_bytes.saturating_mul(frames);
        // The files of an earlier run there are replaced: their space counts.
        let replaced: u64 = crate::output::previous_run_files(out_dir, &self.registry.exporters)
            .iter()
            .filter_map(|f| std::fs::metadata(f).ok())
            .map(|m| m.len())
            .sum();
        if needed > free.saturating_add(replaced) {
            return Err(JobError::DiskSpace {
                scene: self.input.name(),
                folder: out_dir.to_path_buf(),
                frames,
                frame_bytes,
                needed,
                free,
            });
        }
        if needed > free / 2 {
            log::warn!(
                "{}: the run will write about {} bytes, more than half the {free} bytes free in {}",
                self.input.name(),
                needed,
                out_dir.display()
            );
        }
        Ok(())
    }

    fn writer(&self, out_dir: &Path) -> Result<FrameWriter, JobError> {
        Ok(FrameWriter::new(
            out_dir,
            &self.input.scene.output,
            &self.registry.exporters,
            &self
                .bodies
                .iter()
                .map(|b| crate::output::OutputBody {
                    name: &b.name,
                    lattice: &b.lattice,
                    surface: &b.mesh,
                    cell_labels: b.cell_labels.as_deref(),
                })
                .collect::<Vec<_>>(),
        )?
        .with_time_decimals(
            self.frame_interval().and_then(|every| {
                mss_io::vtk::time_decimals(every, self.input.scene.solver.duration)
            }),
        ))
    }

    /// The frame interval the scene gives in seconds (`[output] every_time`,
    /// or its default), when frames are scheduled by time: the round
    /// number their times are multiples of.
    fn frame_interval(&self) -> Option<f64> {
        let out = &self.input.scene.output;
        if out.every_steps.is_some() || self.plan.is_static {
            return None;
        }
        out.every_time.or(Some(
            self.input.scene.solver.duration / crate::build::DEFAULT_FRAMES as f64,
        ))
    }
}

/// Loads, places and voxelizes one body of a scene, and assigns its
/// regions.
fn prepare_body(
    input: &SceneInput,
    view: &BodyView<'_>,
    registry: &Registry,
    limits: &Limits,
    progress: ProgressFn<'_>,
) -> Result<JobBody, JobError> {
    let scene_name = input.name();
    let scene = &input.scene;
    let setting = |key: String, message: String| JobError::Setting {
        scene: scene_name.clone(),
        key,
        message,
    };
    let stage_error = |e: StageError| match e {
        StageError::Source(crate::build::MeshSourceError::Load(source)) => JobError::Mesh {
            scene: scene_name.clone(),
            source,
        },
        StageError::Source(other) => setting(view.key("[mesh] path"), other.to_string()),
        StageError::Image(e) => setting(view.key("[image] path"), e.to_string()),
        e @ StageError::NoLabelledVoxels { .. } => {
            setting(view.key("[image] labels"), e.to_string())
        }
        e @ StageError::Placement { .. } => setting(view.key("[mesh]"), e.to_string()),
        StageError::Memory {
            what,
            needed,
            limit,
            limit_origin,
            hint,
        } => JobError::Memory {
            scene: scene_name.clone(),
            what,
            needed,
            limit,
            limit_origin,
            hint,
        },
        StageError::Voxelize { mesh, source } => JobError::Voxelize {
            scene: scene_name.clone(),
            mesh,
            source,
        },
    };
    // The rule's name is resolved before the mesh is read: a typo costs
    // nothing.
    let voxelize_options = view
        .voxelize
        .options(&registry.occupancy)
        .map_err(|e| setting(view.key(&e.scene_key("[voxelize]")), e.message))?;
    let placement = view.source.placement();
    let needs = RunNeeds {
        solver: &scene.solver.kind,
        needs_matrix: !scene.solver.is_explicit(&registry.integrators),
    };
    let (mesh_name, mesh, lattice, vox_stats, cell_labels) = match view.source {
        BodySource::Mesh(section) => {
            let source = Scene::source_of(&section.path, &input.origin);
            let placed =
                load_placed(&source, &placement, &registry.loaders).map_err(stage_error)?;
            let hook = |done: u64, total: u64| progress(Progress::Voxelizing { done, total });
            let vox = lattice_within(
                &placed.mesh,
                &placed.name,
                &voxelize_options,
                limits,
                needs,
                &hook,
            );
            progress(Progress::StageDone);
            let vox = vox.map_err(stage_error)?;
            if let Some(odd) = crate::stages::implausible_size(&placed.mesh) {
                log::warn!(
                    "{scene_name}: {}{odd} ([mesh] units = \"mm\" or \"cm\", or scale)",
                    view.index
                        .map_or(String::new(), |_| format!("body {}: ", view.name))
                );
            }
            let PlacedMesh { name, mesh, .. } = placed;
            (name, mesh, vox.lattice, vox.stats, None)
        }
        BodySource::Image(section) => {
            let path = match Scene::source_of(&section.path, &input.origin) {
                crate::scene::MeshSource::File(p) => p,
                crate::scene::MeshSource::Builtin(name) => {
                    return Err(setting(
                        view.key("[image] path"),
                        format!(
                            "= \"builtin:{name}\"; built-in meshes are not images: give a label image file"
                        ),
                    ));
                }
            };
            let choice = crate::stages::ImageChoice {
                labels: section.labels.as_deref(),
                threshold: section.threshold,
                unit_metres: section.units.map(|u| u.factor()),
                space: section.space.target(),
                placement,
            };
            let placed = crate::stages::image_lattice_within(
                &path,
                &choice,
                &voxelize_options,
                limits,
                needs,
            );
            progress(Progress::StageDone);
            let placed = placed.map_err(stage_error)?;
            log::info!(
                "{}: {:?} voxels of {:.3?} mm; labels and voxels in the body {:?}",
                placed.name,
                placed.dims,
                placed.spacing.map(|s| s * 1e3),
                placed.lattice.voxels_per_label
            );
            let ImageLattice {
                lattice,
                cell_labels,
                surface,
                stats,
                ..
            } = placed.lattice;
            (placed.name, surface, lattice, stats, Some(cell_labels))
        }
    };
    let (material, param) = input.material_of(view, registry)?;
    let regions = if view.regions.is_empty() {
        None
    } else {
        let mesh_of = |path: &str| input.load_placed_mesh_with(path, &placement, &registry.loaders);
        let a = crate::regions::assign_regions_with_labels(
            &lattice,
            cell_labels.as_deref(),
            &material,
            view.regions,
            &registry.regions,
            &mesh_of,
        )
        .map_err(|e| {
            setting(
                view.key(&format!("[[regions]] #{}", e.region + 1)),
                e.message,
            )
        })?;
        for (r, m) in a.materials.iter().enumerate().skip(1) {
            param
                .validate(m)
                .map_err(|e| setting(view.key(&format!("[[regions]] #{r}")), e.to_string()))?;
        }
        log::info!(
            "{} regions: cells per material {:?}",
            view.regions.len(),
            a.cells_per_material()
        );
        Some(a)
    };
    Ok(JobBody {
        name: view.name.to_owned(),
        mesh_name,
        mesh,
        placement: placement.describe(),
        lattice,
        vox_stats,
        regions,
        cell_labels,
    })
}

fn parts_of(bodies: &[JobBody]) -> Vec<(&hexmesh::Lattice, &hexmesh::TriMesh)> {
    bodies.iter().map(|b| (&b.lattice, &b.mesh)).collect()
}

/// The model of one prepared body.
fn body_model(
    input: &SceneInput,
    view: &BodyView<'_>,
    body: &JobBody,
    registry: &Registry,
) -> Result<Model, JobError> {
    let (material, param) = input.material_of(view, registry)?;
    match &body.regions {
        None => Model::new(&body.lattice, material, &*param),
        Some(a) => {
            Model::with_cell_materials(&body.lattice, &a.materials, &a.cell_material, &*param)
        }
    }
    .map_err(|source| JobError::Model {
        scene: input.name(),
        source,
    })
}

/// The problem of prepared bodies (`extra` obstacles after the scene's):
/// one body as its tables say, several as the union of each one's, with
/// the scene-wide loads and contact (between bodies too) on top.
fn build_problem(
    input: &SceneInput,
    registry: &Registry,
    bodies: &[JobBody],
    extra: crate::build::ExtraObstacles,
) -> Result<Problem, JobError> {
    let scene = &input.scene;
    let views = scene.bodies();
    // With `[contact] points` "surface" or "both", the embedded surfaces
    // touch the obstacles, and the bodies touch each other through them.
    let surface = (scene.contact.points != mss_core::contact::ContactPoints::Nodes)
        .then(|| crate::output::joined_embedding(&parts_of(bodies)));
    let problem = if !scene.has_bodies() {
        let (view, body) = (&views[0], &bodies[0]);
        let model = body_model(input, view, body, registry)?;
        input.problem_with_obstacles(model, registry, surface.as_ref(), extra)?
    } else {
        let mut parts = Vec::with_capacity(bodies.len());
        for (view, body) in views.iter().zip(bodies) {
            let model = body_model(input, view, body, registry)?;
            parts.push(input.body_problem(view, model, registry)?);
        }
        let union = Problem::union(parts).map_err(|e| JobError::Setting {
            scene: input.name(),
            key: "[[bodies]]".into(),
            message: e.to_string(),
        })?;
        input.scene_wide_problem(union, registry, surface.as_ref(), extra)?
    };
    let self_contact: Vec<bool> = views.iter().map(|v| v.self_contact).collect();
    if views.len() < 2 && !self_contact.iter().any(|&s| s) {
        return Ok(problem);
    }
    let model = problem.model();
    let settings = scene
        .contact
        .body_settings(mss_core::contact::ContactSettings::for_bodies(model));
    let contact = match &surface {
        Some(_) => {
            // The surfaces refined to the cells' size: a contact's reaction
            // goes to the corners of the triangle touched, and a face of a
            // coarse mesh (a cube's) would carry a ball's weight at its
            // corners, far from where the ball presses.
            let refined: Vec<hexmesh::TriMesh> = bodies
                .iter()
                .map(|b| b.mesh.refined(b.lattice.h()))
                .collect();
            let parts: Vec<(&hexmesh::Lattice, &hexmesh::TriMesh)> = bodies
                .iter()
                .zip(&refined)
                .map(|(b, mesh)| (&b.lattice, mesh))
                .collect();
            let surface = crate::output::joined_embedding(&parts);
            mss_core::contact::BodyContact::on_surface(model, &surface, settings, &self_contact)
        }
        None => mss_core::contact::BodyContact::new(model, settings, &self_contact),
    }
    .map_err(|e| JobError::Setting {
        scene: input.name(),
        key: "[contact]".into(),
        message: e.to_string(),
    })?;
    Ok(problem.with_body_contact(contact))
}

/// Writes `summary` as `summary.json` in `dir` (atomically).
pub fn write_summary(dir: &Path, summary: &RunSummary) -> Result<(), JobError> {
    let path = dir.join("summary.json");
    let json = serde_json::to_string_pretty(summary)
        .map_err(|e| mss_io::IoError::invalid(&path, e.to_string()))?;
    mss_io::atomic::write_atomic(&path, |w| {
        w.write_all(json.as_bytes())?;
        w.write_all(b"\n")
    })?;
    Ok(())
}

/// The largest distance of a node from its rest position (m).
fn largest_displacement(model: &mss_core::Model, x: &[mss_core::Vec3]) -> f64 {
    x.iter()
        .zip(model.rest_positions())
        .map(|(x, r)| (x - r).norm_squared())
        .fold(0.0, f64::max)
        .sqrt()
}

/// Whether every cell has the volumetric law with the barrier against
/// collapse (and a volumetric stiffness for it to act through).
fn model_has_barrier(model: &mss_core::model::Model) -> bool {
    (0..model.num_cells()).all(|c| {
        let co = model.cell_coefficients(c);
        co.volumetric_barrier && co.volumetric_lambda > 0.0
    })
}

/// Whether `problem` holds no node: its body is free, held (if at all) by
/// obstacles, and has rigid motions that no static solve can fix.
pub(crate) fn problem_is_free(problem: &Problem) -> bool {
    let model = problem.model();
    !(0..model.num_nodes()).any(|n| problem.constraints().mask(n).iter().any(|&h| h))
}

/// Peak resident memory of this process (bytes), from `VmHWM` in
/// `/proc/self/status`; `None` where that file does not exist.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_vm_hwm(&status)
}

fn parse_vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_vm_hwm() {
        let s = "Name:\tmss\nVmPeak:\t  2000 kB\nVmHWM:\t    1234 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(parse_vm_hwm(s), Some(1234 * 1024));
        assert_eq!(parse_vm_hwm("Name: x\n"), None);
        if cfg!(target_os = "linux") {
            assert!(peak_memory_bytes().unwrap() > 0);
        }
    }

    #[test]
    fn cancel_flag_is_shared_by_clones() {
        let c = Cancel::new();
        let d = c.clone();
        assert!(!d.is_cancelled());
        c.cancel();
        assert!(d.is_cancelled());
    }
}
