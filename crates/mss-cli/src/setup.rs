//! The one place where scene tables and command-line arguments become the
//! libraries' parameter structs: meshes, voxelization options, material and
//! parameterization, boundary conditions, loads, damping and the time plan.

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow, bail};
use hexmesh::load::{LoadedMesh, MeshFormat};
use hexmesh::voxelize::{OccupancyRule, Resolution, VoxelizeOptions};
use mss_core::constraints::{
    Axis as CAxis, ConstraintSpec, Dofs, Face, Keyframe, Motion, NodeSelector, Side as CSide,
};
use mss_core::loads::{Damping, ForceDistribution, LoadSpec};
use mss_core::model::{HourglassControl, PARAMETERIZATION_NAMES, parameterization_by_name};
use mss_core::solver::{Problem, explicit_time_step_limit};
use mss_core::{Material, Parameterization};
use mss_io::scene::{
    Axis, BoxFace, DEFAULT_SCENE_TOML, KeepComponents, MeshSource, Scene, SceneOrigin, Selector,
    Side, SolverKind, TimeStep, VoxelResolution, VoxelizeSection,
};

/// The bundled default mesh (`data/meshes/critter.obj`), so that `mss run`
/// works from any folder.
pub const BUNDLED_CRITTER_OBJ: &[u8] = include_bytes!("../../../data/meshes/critter.obj");

/// Names of the bundled meshes (`"builtin:NAME"` in a scene).
pub const BUILTIN_MESHES: &[&str] = &["critter"];

/// A scene and where it came from.
#[derive(Debug, Clone)]
pub struct SceneInput {
    /// The parsed, checked scene.
    pub scene: Scene,
    /// Its file, or the bundled default.
    pub origin: SceneOrigin,
}

impl SceneInput {
    /// Name of the scene in messages.
    pub fn name(&self) -> String {
        self.origin.display_name()
    }
}

/// Reads a scene file, or the bundled default scene when `path` is `None`.
pub fn load_scene(path: Option<&Path>) -> anyhow::Result<SceneInput> {
    match path {
        Some(p) => Ok(SceneInput {
            scene: Scene::load(p)?,
            origin: SceneOrigin::File(p.to_path_buf()),
        }),
        None => {
            let origin = SceneOrigin::Bundled;
            let scene = Scene::from_toml_str(DEFAULT_SCENE_TOML, &origin.display_name())?;
            Ok(SceneInput { scene, origin })
        }
    }
}

/// Loads (and cleans) the mesh a scene or command names. Returns a display
/// name and the mesh.
pub fn load_mesh(source: &MeshSource) -> anyhow::Result<(String, LoadedMesh)> {
    match source {
        MeshSource::Builtin(name) if name == "critter" => {
            let label = "builtin:critter".to_owned();
            let m = hexmesh::load::load_mesh_bytes(BUNDLED_CRITTER_OBJ, MeshFormat::Obj, &label)?;
            Ok((label, m))
        }
        MeshSource::Builtin(name) => bail!(
            "unknown built-in mesh \"builtin:{name}\"; built-in meshes: {}",
            BUILTIN_MESHES
                .iter()
                .map(|n| format!("builtin:{n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        MeshSource::File(path) => {
            if !path.exists() {
                bail!(
                    "mesh file {} does not exist (a relative mesh path is relative to the scene \
                     file's folder)",
                    path.display()
                );
            }
            let m = hexmesh::load::load_mesh(path)?;
            Ok((path.display().to_string(), m))
        }
    }
}

/// Voxelization options from explicit values (shared by scenes and `mss voxelize`).
pub fn voxelize_options(
    resolution: VoxelResolution,
    rule: &str,
    fraction: f64,
    components: KeepComponents,
    max_cells: u64,
) -> anyhow::Result<VoxelizeOptions> {
    let resolution = match resolution {
        VoxelResolution::Cells(n) => {
            if n == 0 {
                bail!("the number of cells along the longest axis must be at least 1");
            }
            Resolution::CellsAlongLongestAxis(n)
        }
        VoxelResolution::CellSize(h) => {
            if !(h.is_finite() && h > 0.0) {
                bail!("cell size {h} m: give a positive length");
            }
            Resolution::CellSize(h)
        }
    };
    let rule = match rule {
        "fraction" => OccupancyRule::Fraction {
            threshold: fraction,
            samples_per_axis: 4,
        },
        other => other
            .parse::<OccupancyRule>()
            .map_err(|e| anyhow!("occupancy rule \"{other}\": {e}"))?,
    };
    Ok(VoxelizeOptions {
        resolution,
        rule,
        max_cells,
        components: if components == KeepComponents::Largest {
            hexmesh::voxelize::ComponentPolicy::LargestOnly
        } else {
            hexmesh::voxelize::ComponentPolicy::All
        },
        ..VoxelizeOptions::default()
    })
}

/// Voxelization options of a scene's `[voxelize]` table.
pub fn scene_voxelize_options(v: &VoxelizeSection) -> anyhow::Result<VoxelizeOptions> {
    voxelize_options(
        v.resolution(),
        &v.rule,
        v.fraction,
        v.components,
        v.max_cells,
    )
}

/// The material and parameterization of a scene, checked against each other.
pub fn material(scene: &Scene) -> anyhow::Result<(Material, Box<dyn Parameterization>)> {
    let name = scene.model.parameterization.as_str();
    let unknown = || {
        anyhow!(
            "[model] parameterization: unknown name \"{name}\"; use one of {}",
            PARAMETERIZATION_NAMES.join(", ")
        )
    };
    let param = match scene.model.hourglass {
        None => parameterization_by_name(name).ok_or_else(unknown)?,
        Some(alpha) => {
            // An explicit factor replaces the default of a "+hg" name.
            let base = name.strip_suffix("+hg").unwrap_or(name);
            let inner = parameterization_by_name(base).ok_or_else(unknown)?;
            Box::new(
                HourglassControl::new(inner, alpha)
                    .map_err(|e| anyhow!("[model] hourglass: {e}"))?,
            )
        }
    };
    let m = &scene.material;
    let material = Material {
        young: m.young,
        poisson: m.poisson,
        density: m.density,
    };
    param
        .validate(&material)
        .map_err(|e| anyhow!("[material]: {e}"))?;
    Ok((material, param))
}

/// A scene selector as the library's node selector. `bounds` is the rest
/// bounding box of the lattice (for relative boxes).
pub fn node_selector(s: &Selector, bounds: ([f64; 3], [f64; 3])) -> NodeSelector {
    match s {
        Selector::LowestLayer {} => NodeSelector::LowestLayer,
        Selector::Box { min, max, relative } => {
            if *relative {
                let (lo, hi) = bounds;
                let at = |f: &[f64; 3]| std::array::from_fn(|k| lo[k] + f[k] * (hi[k] - lo[k]));
                NodeSelector::Box {
                    min: at(min),
                    max: at(max),
                }
            } else {
                NodeSelector::Box {
                    min: *min,
                    max: *max,
                }
            }
        }
        Selector::Plane { axis, value, side } => NodeSelector::Plane {
            axis: match axis {
                Axis::X => CAxis::X,
                Axis::Y => CAxis::Y,
                Axis::Z => CAxis::Z,
            },
            value: *value,
            side: match side {
                Side::Below => CSide::Below,
                Side::Above => CSide::Above,
            },
        },
        Selector::Face { face } => NodeSelector::BoundingFace(match face {
            BoxFace::XMin => Face::XMin,
            BoxFace::XMax => Face::XMax,
            BoxFace::YMin => Face::YMin,
            BoxFace::YMax => Face::YMax,
            BoxFace::ZMin => Face::ZMin,
            BoxFace::ZMax => Face::ZMax,
        }),
        Selector::Indices { nodes } => NodeSelector::Indices(nodes.clone()),
    }
}

/// Boundary conditions of a scene: `[[fixed]]` sets, then `[[motions]]`.
pub fn constraint_specs(scene: &Scene, bounds: ([f64; 3], [f64; 3])) -> Vec<ConstraintSpec> {
    let mut specs: Vec<ConstraintSpec> = scene
        .fixed
        .iter()
        .map(|s| ConstraintSpec::fixed(node_selector(s, bounds)))
        .collect();
    for m in &scene.motions {
        let ramp = m.ramp.unwrap_or(scene.solver.duration);
        specs.push(ConstraintSpec {
            select: node_selector(&m.select, bounds),
            dofs: Dofs::ALL,
            motion: Motion::Keyframes(vec![
                Keyframe {
                    time: 0.0,
                    displacement: [0.0; 3],
                },
                Keyframe {
                    time: ramp,
                    displacement: m.displacement,
                },
            ]),
        });
    }
    specs
}

/// Loads of a scene.
pub fn load_specs(scene: &Scene, bounds: ([f64; 3], [f64; 3])) -> Vec<LoadSpec> {
    let l = &scene.loads;
    let mut specs = Vec::new();
    if let Some(g) = l.gravity {
        specs.push(LoadSpec::Gravity { g });
    }
    for f in &l.forces {
        specs.push(LoadSpec::Force {
            select: node_selector(&f.select, bounds),
            force: f.force,
            distribution: if f.per_node {
                ForceDistribution::PerNode
            } else {
                ForceDistribution::Total
            },
        });
    }
    for t in &l.tractions {
        specs.push(LoadSpec::Traction {
            min: t.min,
            max: t.max,
            traction: t.traction,
        });
    }
    for d in &l.drags {
        specs.push(LoadSpec::Drag {
            select: node_selector(&d.select, bounds),
            target: d.target,
            stiffness: d.stiffness,
        });
    }
    specs
}

/// Damping of a scene.
pub fn damping(scene: &Scene) -> Damping {
    Damping {
        alpha: scene.solver.damping,
        beta: scene.solver.stiffness_damping,
    }
}

/// Rest bounding box of model nodes.
pub use mss_core::constraints::node_bounds;

/// The problem of a scene for a built model: constraints, loads, damping.
pub fn problem(scene: &Scene, model: mss_core::Model) -> anyhow::Result<Problem> {
    let bounds = node_bounds(model.rest_positions());
    let constraints = constraint_specs(scene, bounds);
    let loads = load_specs(scene, bounds);
    let n_fixed = scene.fixed.len();
    Problem::from_specs(model, &constraints, &loads, damping(scene)).map_err(|e| {
        use mss_core::solver::ProblemError;
        match &e {
            ProblemError::Constraint { index, source } if *index < n_fixed => {
                anyhow!("[[fixed]] #{}: {source}", index + 1)
            }
            ProblemError::Constraint { index, source } => {
                anyhow!("[[motions]] #{}: {source}", index - n_fixed + 1)
            }
            ProblemError::Load { source, .. } => anyhow!("[loads]: {source}"),
            _ => anyhow!("{e}"),
        }
    })
}

/// How time advances in a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimePlan {
    /// Solver kind.
    pub kind: SolverKind,
    /// Time step (s); the duration for static solves.
    pub dt: f64,
    /// Number of steps (1 for static solves).
    pub steps: u64,
    /// Largest stable explicit step with the scene's safety factor (s).
    pub stable_dt: f64,
    /// Steps between frames (frame after step `k` when `k % every == 0`, and
    /// always after the last step).
    pub frame_every: u64,
    /// Whether only the final state is written.
    pub last_only: bool,
}

impl TimePlan {
    /// Frames written: the initial state, every `frame_every` steps, and the last.
    pub fn num_frames(&self) -> u64 {
        if self.last_only {
            1
        } else {
            1 + self.steps / self.frame_every
                + u64::from(!self.steps.is_multiple_of(self.frame_every))
        }
    }

    /// Whether a frame is written after step `k` (1-based).
    pub fn frame_after(&self, k: u64) -> bool {
        k == self.steps || (!self.last_only && k.is_multiple_of(self.frame_every))
    }
}

/// Largest number of time steps a run may take: beyond it, something is
/// wrong with the time step or the duration.
pub const MAX_STEPS: u64 = 100_000_000;

/// The time plan of a scene for a problem: explicit steps at the stable limit
/// (adjusted down so that whole steps end exactly at the duration), or the
/// scene's `dt`.
pub fn time_plan(scene: &Scene, problem: &Problem) -> anyhow::Result<TimePlan> {
    let s = &scene.solver;
    let stable_dt = explicit_time_step_limit(problem, s.safety);
    let duration = s.duration;
    let (dt_wanted, steps) = match (s.kind, s.dt) {
        (SolverKind::Static, _) => (duration, 1),
        (kind, TimeStep::Auto) => {
            let wanted = if kind == SolverKind::Explicit {
                stable_dt
            } else {
                duration / 100.0
            };
            let n = (duration / wanted).ceil().max(1.0);
            if n.is_nan() || n > MAX_STEPS as f64 {
                bail!(
                    "[solver]: {duration} s at a stable step of {wanted:e} s needs {n:e} steps \
                     (limit {MAX_STEPS}); shorten the duration, use fewer cells or a softer material"
                );
            }
            let mut n = n as u64;
            // Rounding may put duration / n a hair above the limit.
            while duration / n as f64 > wanted {
                n += 1;
            }
            (duration / n as f64, n)
        }
        (_, TimeStep::Seconds(dt)) => {
            let n = (duration / dt).round().max(1.0);
            if n.is_nan() || n > MAX_STEPS as f64 {
                bail!(
                    "[solver] dt = {dt:e} s: {n:e} steps for {duration} s exceeds the limit of \
                     {MAX_STEPS}; use a larger time step or a shorter duration"
                );
            }
            (dt, n as u64)
        }
    };
    let o = &scene.output;
    let frame_every = match (o.every_steps, o.every_time) {
        (Some(n), _) => n,
        (None, t) => {
            let t = t.unwrap_or(duration / 20.0);
            ((t / dt_wanted).round() as u64).max(1)
        }
    };
    Ok(TimePlan {
        kind: s.kind,
        dt: dt_wanted,
        steps,
        stable_dt,
        frame_every,
        last_only: o.last_only,
    })
}

/// The output folder: `--out` if given, else the scene's `[output] folder`.
pub fn output_folder(scene: &Scene, out: Option<&Path>) -> PathBuf {
    out.map(Path::to_path_buf)
        .unwrap_or_else(|| scene.output.folder.clone())
}

/// Creates the output folder and checks that files can be created in it, so
/// that an unwritable folder is reported before any long computation.
pub fn prepare_output_folder(dir: &Path) -> anyhow::Result<()> {
    mss_io::atomic::ensure_dir(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    let probe = dir.join(format!(".mss-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("the output folder {} is not writable", dir.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}
