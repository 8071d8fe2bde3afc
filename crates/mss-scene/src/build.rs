//! Scene values to library parameters: the mesh, the voxelizer's options,
//! material and parameterization, boundary conditions, loads, damping, the
//! integrator and the time plan. Every conversion of a scene value lives here
//! or beside the scene type it converts.

use std::path::{Path, PathBuf};

use hexmesh::load::{LoadedMesh, Loaders, MeshFormat};
use mss_core::solver::{Integrator, IntegratorSettings, Problem, ProblemError};
use mss_core::{Material, Parameterization, ParameterizationError};
use thiserror::Error;

use crate::error::JobError;
use crate::registry::Registry;
use crate::scene::{
    BUILTIN_MESHES, BUNDLED_CRITTER_OBJ, BodyView, DEFAULT_SCENE_TOML, IMPLICIT_AUTO_STEPS,
    MeshSource, Scene, SceneOrigin, TimeStep,
};
use crate::stages::ProblemStageError;

/// A scene and where it came from.
#[derive(Debug, Clone)]
pub struct SceneInput {
    /// The parsed, checked scene.
    pub scene: Scene,
    /// Its file, or the bundled default.
    pub origin: SceneOrigin,
}

impl SceneInput {
    /// Reads a scene file, or the bundled default scene when `path` is `None`.
    pub fn load(path: Option<&Path>) -> Result<Self, JobError> {
        Ok(match path {
            Some(p) => SceneInput {
                scene: Scene::load(p)?,
                origin: SceneOrigin::File(p.to_path_buf()),
            },
            None => Self::bundled_default(),
        })
    }

    /// The bundled default scene (the critter sagging under gravity).
    pub fn bundled_default() -> Self {
        let origin = SceneOrigin::Bundled;
        let scene = Scene::from_toml_str(DEFAULT_SCENE_TOML, &origin.display_name())
            // The bundled scene is checked by the tests; it always parses.
            .unwrap_or_else(|e| panic!("the bundled default scene is invalid: {e}"));
        SceneInput { scene, origin }
    }

    /// A scene given as TOML text; `name` is used in messages and relative
    /// mesh paths are relative to the working directory.
    pub fn from_toml(text: &str, name: &str) -> Result<Self, JobError> {
        Ok(SceneInput {
            scene: Scene::from_toml_str(text, name)?,
            origin: SceneOrigin::Text(name.to_owned()),
        })
    }

    /// The static solver's options from `[solver]` (`load_steps`,
    /// `tolerance`, `max_iterations`, `linear_solver`, `linear`,
    /// `accept_unstable`), obstacles followed along their paths from time 0.
    pub fn static_options(&self) -> mss_core::solver::StaticOptions {
        let s = &self.scene.solver;
        let first = 1.0 / f64::from(s.load_steps);
        mss_core::solver::StaticOptions {
            rtol: s.tolerance,
            max_newton: s.max_iterations,
            initial_load_increment: first,
            min_load_increment: mss_core::solver::StaticOptions::default()
                .min_load_increment
                .min(first),
            linear_solver: s.linear_solver,
            small_strain: s.linear,
            accept_unstable: s.accept_unstable,
            // A scene's static solve starts at rest at time 0: its obstacles
            // come along their paths from there.
            obstacles_from: Some(0.0),
            accept_mechanisms: false,
            ..mss_core::solver::StaticOptions::default()
        }
    }

    /// Name of the scene in messages.
    pub fn name(&self) -> String {
        self.origin.display_name()
    }

    fn setting(&self, key: &str, message: impl std::fmt::Display) -> JobError {
        JobError::Setting {
            scene: self.name(),
            key: key.to_owned(),
            message: message.to_string(),
        }
    }

    /// The material and parameterization of the scene's first body (the
    /// only one without `[[bodies]]`), checked against each other.
    pub fn material(
        &self,
        registry: &Registry,
    ) -> Result<(Material, Box<dyn Parameterization>), JobError> {
        let bodies = self.scene.bodies();
        self.material_of(&bodies[0], registry)
    }

    /// The material and parameterization of `body` (its `[model]` resolved
    /// against `registry`), checked against each other.
    pub fn material_of(
        &self,
        body: &BodyView<'_>,
        registry: &Registry,
    ) -> Result<(Material, Box<dyn Parameterization>), JobError> {
        let m = body.model;
        let param = registry
            .parameterizations
            .build(&m.parameterization, m.hourglass)
            .map_err(|e| match e {
                ParameterizationError::Unknown(u) => {
                    self.setting(&body.key("[model] parameterization"), u)
                }
                ParameterizationError::Hourglass(h) => {
                    self.setting(&body.key("[model] hourglass"), h)
                }
            })?;
        let material = body.material;
        param
            .validate(&material)
            .map_err(|e| self.setting(&body.key("[material]"), e))?;
        Ok((material, param))
    }

    /// The problem of the scene for a built model: constraints, loads, damping.
    pub fn problem(&self, model: mss_core::Model) -> Result<Problem, JobError> {
        self.problem_with(model, &Registry::default(), None)
    }

    /// Loads a second mesh the scene names (a region's, an obstacle's),
    /// resolved like `[mesh] path` and placed like the first body's mesh;
    /// errors as one line naming the file.
    pub fn load_placed_mesh(
        &self,
        path: &str,
        loaders: &Loaders,
    ) -> Result<hexmesh::TriMesh, String> {
        let placement = self.scene.bodies()[0].source.placement();
        self.load_placed_mesh_with(path, &placement, loaders)
    }

    /// [`SceneInput::load_placed_mesh`] placed by `placement`.
    pub fn load_placed_mesh_with(
        &self,
        path: &str,
        placement: &hexmesh::Placement,
        loaders: &Loaders,
    ) -> Result<hexmesh::TriMesh, String> {
        let source = Scene::source_of(path, &self.origin);
        crate::stages::load_placed(&source, placement, loaders)
            .map(|placed| placed.mesh)
            .map_err(|e| e.to_string())
    }

    /// [`SceneInput::problem`] with the loaders of `registry` for the
    /// meshes that `[[obstacles]]` name (placed like `[mesh]`), its shapes
    /// for their kinds, and the embedded `surface` whose vertices touch them
    /// when `[contact] points` asks.
    pub fn problem_with(
        &self,
        model: mss_core::Model,
        registry: &Registry,
        surface: Option<&hexmesh::Embedding>,
    ) -> Result<Problem, JobError> {
        self.problem_with_obstacles(model, registry, surface, Vec::new())
    }

    /// [`SceneInput::problem_with`] with `extra` obstacles after the
    /// scene's `[[obstacles]]` (the tools of an interactive front end),
    /// for the scene's first body (the only one without `[[bodies]]`).
    pub fn problem_with_obstacles(
        &self,
        model: mss_core::Model,
        registry: &Registry,
        surface: Option<&hexmesh::Embedding>,
        extra: crate::build::ExtraObstacles,
    ) -> Result<Problem, JobError> {
        let scene = &self.scene;
        let body = &scene.bodies()[0];
        let constraints = body.constraint_specs(scene.solver.duration);
        let loads = scene.loads.specs();
        let specs = crate::stages::ProblemSpecs {
            constraints: &constraints,
            loads: &loads,
            custom_loads: &scene.loads.custom,
            load_kinds: &registry.loads,
            damping: scene.solver.damping(),
            obstacles: &scene.obstacles,
            points: scene.contact.points,
            shapes: &registry.shapes,
        };
        self.stage_problem(model, &specs, body, registry, surface, extra)
    }

    /// The problem of one of `[[bodies]]` alone: its held nodes, motions
    /// and loads (no obstacles: they are scene-wide).
    pub fn body_problem(
        &self,
        body: &BodyView<'_>,
        model: mss_core::Model,
        registry: &Registry,
    ) -> Result<Problem, JobError> {
        let scene = &self.scene;
        let constraints = body.constraint_specs(scene.solver.duration);
        let (loads, custom) = match body.loads {
            Some(l) => (l.specs(), l.custom.as_slice()),
            None => (Vec::new(), &[][..]),
        };
        let specs = crate::stages::ProblemSpecs {
            constraints: &constraints,
            loads: &loads,
            custom_loads: custom,
            load_kinds: &registry.loads,
            damping: scene.solver.damping(),
            obstacles: &[],
            points: mss_core::contact::ContactPoints::Nodes,
            shapes: &registry.shapes,
        };
        self.stage_problem(model, &specs, body, registry, None, Vec::new())
    }

    /// The scene-wide part of a scene of `[[bodies]]` added to the union
    /// of its bodies' problems: the top-level `[loads]` (on every body) and
    /// the `[[obstacles]]` (touched by every body's boundary nodes, and by
    /// the vertices of `surface`, the bodies' embedded surfaces over the
    /// union's nodes, when `[contact] points` asks).
    pub fn scene_wide_problem(
        &self,
        union: Problem,
        registry: &Registry,
        surface: Option<&hexmesh::Embedding>,
        extra: crate::build::ExtraObstacles,
    ) -> Result<Problem, JobError> {
        let scene = &self.scene;
        let model = union.model();
        let placement = scene.bodies()[0].source.placement();
        let mesh_of = |path: &str| self.load_placed_mesh_with(path, &placement, &registry.loaders);
        let contact = crate::obstacles::build_contact_with(
            model,
            &scene.obstacles,
            &registry.shapes,
            extra,
            &mesh_of,
            scene.contact.points,
            surface,
        )
        .map_err(|(index, source)| {
            self.setting(&format!("[[obstacles]] #{}", index + 1), source)
        })?;
        let mut loads = Vec::new();
        for spec in scene.loads.specs() {
            loads.push(
                spec.resolve(model)
                    .map_err(|e| self.setting("[loads]", e))?,
            );
        }
        for (index, table) in scene.loads.custom.iter().enumerate() {
            loads.push(
                registry
                    .loads
                    .build(table, model)
                    .map_err(|e| self.setting(&format!("[[loads.custom]] #{}", index + 1), e))?,
            );
        }
        let mut problem = loads.into_iter().fold(union, Problem::with_load);
        if let Some(c) = contact {
            problem = problem.with_contact(c);
        }
        Ok(problem)
    }

    /// [`crate::stages::problem`] with its errors named as `body`'s keys.
    fn stage_problem(
        &self,
        model: mss_core::Model,
        specs: &crate::stages::ProblemSpecs<'_>,
        body: &BodyView<'_>,
        registry: &Registry,
        surface: Option<&hexmesh::Embedding>,
        extra: crate::build::ExtraObstacles,
    ) -> Result<Problem, JobError> {
        let n_fixed = body.fixed.len();
        let placement = body.source.placement();
        let mesh_of = |path: &str| self.load_placed_mesh_with(path, &placement, &registry.loaders);
        let loads_key = |list: &str| match body.index {
            None => list.to_owned(),
            Some(_) => body.key(list),
        };
        crate::stages::problem(model, specs, &mesh_of, surface, extra).map_err(|e| match e {
            ProblemStageError::Obstacle { index, source } => {
                self.setting(&format!("[[obstacles]] #{}", index + 1), source)
            }
            ProblemStageError::Problem(ProblemError::Constraint { index, source })
                if index < n_fixed =>
            {
                self.setting(&body.key(&format!("[[fixed]] #{}", index + 1)), source)
            }
            ProblemStageError::Problem(ProblemError::Constraint { index, source }) => self.setting(
                &body.key(&format!("[[motions]] #{}", index - n_fixed + 1)),
                source,
            ),
            ProblemStageError::Problem(ProblemError::Load { source, .. }) => {
                self.setting(&loads_key("[loads]"), source)
            }
            ProblemStageError::CustomLoad { index, source } => self.setting(
                &loads_key(&format!("[[loads.custom]] #{}", index + 1)),
                source,
            ),
            ProblemStageError::Problem(other) => self.setting("[solver]", other),
        })
    }

    /// How time advances for `problem`: explicit schemes step at the stable
    /// limit times `safety` (adjusted down so that whole steps end exactly at
    /// the duration), other integrators at `duration / IMPLICIT_AUTO_STEPS`,
    /// unless `dt` is given; a static solve is one step.
    pub fn time_plan(
        &self,
        problem: &Problem,
        integrators: &mss_core::solver::Integrators,
    ) -> Result<TimePlan, JobError> {
        let s = &self.scene.solver;
        let stable_dt = mss_core::solver::explicit_time_step_limit(problem, s.safety);
        let duration = s.duration;
        let every_time = match (self.scene.output.every_steps, self.scene.output.every_time) {
            (Some(_), _) => None,
            (None, t) => Some(t.unwrap_or(duration / DEFAULT_FRAMES as f64)),
        };
        let (dt, steps) = match s.dt {
            _ if s.is_static() => (duration, 1),
            TimeStep::Auto => {
                let wanted = if s.is_explicit(integrators) {
                    stable_dt
                } else {
                    duration / f64::from(IMPLICIT_AUTO_STEPS)
                };
                // Frames land exactly on multiples of `every_time` when the
                // step divides it; that needs the duration to be a multiple
                // of it too, otherwise the step divides the duration.
                let span = match every_time {
                    Some(every) if is_multiple(duration, every) => every,
                    _ => duration,
                };
                let per_span = self.whole_steps(span, wanted)?;
                let dt = span / per_span as f64;
                (dt, (duration / dt).round().max(1.0) as u64)
            }
            TimeStep::Seconds(dt) => {
                let n = (duration / dt).round().max(1.0);
                if n.is_nan() || n > MAX_STEPS as f64 {
                    return Err(self.setting(
                        "[solver] dt",
                        format!(
                            "{dt:.3e} s: {n:.3e} steps for {duration} s exceeds the limit of \
                             {MAX_STEPS}; use a larger time step or a shorter duration"
                        ),
                    ));
                }
                (dt, n as u64)
            }
        };
        if steps > MAX_STEPS {
            return Err(self.setting(
                "[solver]",
                format!(
                    "{duration} s at a step of {dt:.3e} s needs {steps} steps (limit {MAX_STEPS}); \
                     shorten the duration, use fewer cells or a softer material"
                ),
            ));
        }
        let frames = match (self.scene.output.every_steps, every_time) {
            (Some(n), _) => FrameSchedule::EverySteps(n),
            (None, Some(every)) if is_multiple(every, dt) => {
                FrameSchedule::EverySteps(((every / dt).round() as u64).max(1))
            }
            (None, Some(every)) => FrameSchedule::EveryTime { every, dt },
            (None, None) => FrameSchedule::EverySteps(steps.max(1)),
        };
        Ok(TimePlan {
            is_static: s.is_static(),
            dt,
            steps,
            stable_dt,
            frames,
            last_only: self.scene.output.last_only,
        })
    }

    /// The number of whole steps of at most `wanted` seconds that fill `span`.
    fn whole_steps(&self, span: f64, wanted: f64) -> Result<u64, JobError> {
        let n = (span / wanted).ceil().max(1.0);
        let total = n * (self.scene.solver.duration / span);
        if n.is_nan() || total.is_nan() || total > MAX_STEPS as f64 {
            return Err(self.setting(
                "[solver]",
                format!(
                    "{} s at a stable step of {wanted:.3e} s needs {total:.3e} steps (limit \
                     {MAX_STEPS}); shorten the duration, use fewer cells or a softer material",
                    self.scene.solver.duration
                ),
            ));
        }
        let mut n = n as u64;
        // Rounding may put span / n a hair above the limit.
        while span / n as f64 > wanted {
            n += 1;
        }
        Ok(n)
    }

    /// The time integrator of the scene (`None` for a static solve), built
    /// from the registry. Refuses, among others, an explicit step above the
    /// stability limit (unless `substep`).
    pub fn integrator(
        &self,
        registry: &Registry,
        problem: &Problem,
        plan: &TimePlan,
    ) -> Result<Option<Box<dyn Integrator>>, JobError> {
        let s = &self.scene.solver;
        if s.is_static() {
            return Ok(None);
        }
        let settings = IntegratorSettings {
            dt: Some(plan.dt),
            safety: s.safety,
            substep: s.substep,
            rtol: s.tolerance,
            max_newton: s.max_iterations,
            linear_solver: s.linear_solver,
            precision: s.precision,
        };
        if !registry.integrators.contains(&s.kind) {
            return Err(self.setting(
                "[solver] kind",
                format!(
                    "unknown solver \"{}\"; use one of static, {}",
                    s.kind,
                    registry.integrators.names().join(", ")
                ),
            ));
        }
        registry
            .integrators
            .build(&s.kind, problem, &settings)
            .map(Some)
            .map_err(|e| self.setting("[solver]", e))
    }

    /// The integrator that settles the scene for `start = "settled"`
    /// ([`mss_core::solver::settle`]): an explicit scheme at its stable
    /// step, one sub-step per step, so that each step's increments tell the
    /// frequency being damped; a static solve with backward Euler at
    /// [`STATIC_SETTLE_STEP`]; any other scheme as the run has it.
    pub fn settle_integrator(
        &self,
        registry: &Registry,
        problem: &Problem,
        plan: &TimePlan,
    ) -> Result<Box<dyn Integrator>, JobError> {
        let s = &self.scene.solver;
        if s.is_static() {
            // Backward Euler with the exact contact tangents: the explicit
            // step, its velocities damped each step, chattered at 3.5e-3 of
            // the loads on the bundled squeeze with its plate 2 cm into the
            // ball and never settled; this settles it to 2e-7.
            let settings = IntegratorSettings {
                dt: Some(STATIC_SETTLE_STEP),
                rtol: s.tolerance,
                max_newton: s.max_iterations,
                linear_solver: s.linear_solver,
                ..IntegratorSettings::default()
            };
            return registry
                .integrators
                .build("implicit", problem, &settings)
                .map_err(|e| self.setting("[solver]", e));
        }
        let kind = if s.is_explicit(&registry.integrators) {
            s.kind.as_str()
        } else {
            return self
                .integrator(registry, problem, plan)?
                .ok_or_else(|| self.setting("[solver] kind", "no integrator to settle with"));
        };
        let settings = IntegratorSettings {
            dt: None,
            safety: s.safety,
            precision: s.precision,
            ..IntegratorSettings::default()
        };
        registry
            .integrators
            .build(kind, problem, &settings)
            .map_err(|e| self.setting("[solver]", e))
    }

    /// Where the mesh is: `"builtin:NAME"` names a bundled mesh; a relative
    /// path is relative to the scene file's folder.
    pub fn mesh_source(&self) -> MeshSource {
        self.scene.mesh_source(&self.origin)
    }
}

/// The step (s) of the backward Euler that settles a static scene with
/// `start = "settled"`: a hundredth of a second resolves the bodies' slow
/// motion (a settled 1.2 kg stack: tens of rad/s) and damps the rest.
pub const STATIC_SETTLE_STEP: f64 = 0.01;

/// Why a mesh named by a scene or a command could not be had.
#[derive(Debug, Error)]
pub enum MeshSourceError {
    /// `builtin:NAME` with an unknown name.
    #[error("unknown built-in mesh \"builtin:{name}\"; built-in meshes: {known}")]
    UnknownBuiltin {
        /// The name given.
        name: String,
        /// The bundled meshes, as `builtin:NAME`, comma-separated.
        known: String,
    },
    /// The file does not exist.
    #[error(
        "mesh file {} does not exist (a relative mesh path in a scene is relative to the scene \
         file's folder)",
        path.display()
    )]
    Missing {
        /// The path looked for.
        path: PathBuf,
    },
    /// The loader refused the file.
    #[error(transparent)]
    Load(#[from] hexmesh::LoadError),
}

/// Obstacles a front end adds after a scene's `[[obstacles]]` (a viewer's
/// poking sphere, a haptic tool), with their contact settings.
pub type ExtraObstacles = Vec<(
    Box<dyn mss_core::contact::Obstacle>,
    mss_core::contact::ContactSettings,
)>;

/// Loads (and cleans) the mesh `source` names with `loaders`. Returns a
/// display name and the mesh.
pub fn load_mesh(
    source: &MeshSource,
    loaders: &Loaders,
) -> Result<(String, LoadedMesh), MeshSourceError> {
    match source {
        MeshSource::Builtin(name) if name == "critter" => {
            let label = "builtin:critter".to_owned();
            let m = hexmesh::load::load_mesh_bytes(BUNDLED_CRITTER_OBJ, MeshFormat::Obj, &label)?;
            Ok((label, m))
        }
        MeshSource::Builtin(name) if name == "cube" || name == "sphere" => {
            let label = format!("builtin:{name}");
            let raw = if name == "cube" {
                hexmesh::generate::box_mesh([-0.5; 3], [0.5; 3])
            } else {
                hexmesh::generate::sphere(0.5, 3)
            };
            Ok((label.clone(), hexmesh::load::clean_mesh(raw, 0.0, &label)?))
        }
        MeshSource::Builtin(name) => Err(MeshSourceError::UnknownBuiltin {
            name: name.clone(),
            known: BUILTIN_MESHES
                .iter()
                .map(|n| format!("builtin:{n}"))
                .collect::<Vec<_>>()
                .join(", "),
        }),
        MeshSource::File(path) => {
            if !path.exists() {
                return Err(MeshSourceError::Missing { path: path.clone() });
            }
            let m = loaders.load(path)?;
            Ok((path.display().to_string(), m))
        }
    }
}

/// Whether `a` is a whole multiple of `b` (relative tolerance 1e-9).
fn is_multiple(a: f64, b: f64) -> bool {
    let r = a / b;
    r >= 0.5 && (r - r.round()).abs() <= 1e-9 * r
}

/// Largest number of time steps a run may take: beyond it, something is
/// wrong with the time step or the duration.
pub const MAX_STEPS: u64 = 100_000_000;

/// Frames of a run whose `[output]` gives neither `every_steps` nor
/// `every_time` (besides the initial state).
pub const DEFAULT_FRAMES: u32 = 20;

/// When frames are written.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameSchedule {
    /// After every `n`-th step.
    EverySteps(u64),
    /// At every multiple of `every` seconds of simulated time, reached by
    /// steps of `dt`.
    EveryTime {
        /// Interval (s).
        every: f64,
        /// Time step (s).
        dt: f64,
    },
}

/// How time advances in a run and when frames are written.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimePlan {
    /// Whether the run is a static solve.
    pub is_static: bool,
    /// Time step (s); the duration for static solves.
    pub dt: f64,
    /// Number of steps (1 for static solves).
    pub steps: u64,
    /// Largest stable explicit step with the scene's safety factor (s).
    pub stable_dt: f64,
    /// When frames are written (besides the initial and the last state).
    pub frames: FrameSchedule,
    /// Whether only the final state is written.
    pub last_only: bool,
}

impl TimePlan {
    /// Whether a frame is written after step `k` (1-based): at the schedule,
    /// and always after the last step.
    pub fn frame_after(&self, k: u64) -> bool {
        if k == self.steps {
            return true;
        }
        if self.last_only {
            return false;
        }
        match self.frames {
            FrameSchedule::EverySteps(n) => k.is_multiple_of(n),
            FrameSchedule::EveryTime { every, dt } => {
                // Frame j is due at t = j * every; it is written after the
                // first step whose end reaches it.
                let due = |t: f64| (t / every * (1.0 + 1e-9)).floor();
                due(k as f64 * dt) > due((k - 1) as f64 * dt)
            }
        }
    }

    /// Frames written: the initial state, the scheduled ones, and the last.
    pub fn num_frames(&self) -> u64 {
        if self.last_only {
            return 1;
        }
        match self.frames {
            FrameSchedule::EverySteps(n) => {
                1 + self.steps / n + u64::from(!self.steps.is_multiple_of(n))
            }
            FrameSchedule::EveryTime { every, dt } => {
                let total = self.steps as f64 * dt;
                let scheduled = (total / every * (1.0 + 1e-9)).floor() as u64;
                let last_is_scheduled = self.frame_after_schedule_only(self.steps);
                1 + scheduled + u64::from(!last_is_scheduled)
            }
        }
    }

    fn frame_after_schedule_only(&self, k: u64) -> bool {
        match self.frames {
            FrameSchedule::EverySteps(n) => k.is_multiple_of(n),
            FrameSchedule::EveryTime { every, dt } => {
                let due = |t: f64| (t / every * (1.0 + 1e-9)).floor();
                k > 0 && due(k as f64 * dt) > due((k - 1) as f64 * dt)
            }
        }
    }
}

/// The output folder: `out` if given, else the scene's `[output] folder`.
pub fn output_folder(scene: &Scene, out: Option<&Path>) -> PathBuf {
    out.map(Path::to_path_buf)
        .unwrap_or_else(|| scene.output.folder.clone())
}

/// Creates the output folder and checks that files can be created in it, so
/// that an unwritable folder is reported before any long computation.
pub fn prepare_output_folder(dir: &Path) -> Result<(), JobError> {
    mss_io::atomic::ensure_dir(dir).map_err(|e| match e {
        mss_io::IoError::Io { source, .. } => JobError::OutputFolder {
            path: dir.to_path_buf(),
            problem: "cannot be created",
            source,
        },
        other => JobError::Output(other),
    })?;
    let probe = dir.join(format!(".mss-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|source| JobError::OutputFolder {
        path: dir.to_path_buf(),
        problem: "is not writable",
        source,
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}
