//! Running a 2D scene (`[model] dimension = 2`): the outline of `[mesh]` (an
//! SVG drawing or a planar mesh) rasterized into rectangles, the paper's
//! 2D element on them (`mss_core::plane`), held nodes, in-plane gravity and
//! forces, fixed obstacles, the explicit, implicit or static solver, and
//! frames written as VTK
//! quads (`lattice_NNNN.vtu`, `lattice.pvd`) with the outline carried by the
//! lattice as SVG and OBJ (`outline_NNNN.svg`, `outline_NNNN.obj`).
//!
//! ```
//! use mss_scene::SceneInput;
//! use mss_scene::plane_job::PlaneJob;
//!
//! let dir = tempfile::tempdir().unwrap();
//! std::fs::write(dir.path().join("bar.svg"),
//!     r#"<svg><rect x="0" y="-0.02" width="0.2" height="0.02"/></svg>"#).unwrap();
//! let scene = format!(r#"
//!     [mesh]
//!     path = "{}"
//!     [voxelize]
//!     cell_size = [0.02, 0.01]
//!     [model]
//!     dimension = 2
//!     thickness = 0.01
//!     [material]
//!     young = 1.0e6
//!     poisson = 0.3
//!     density = 1000.0
//!     [[fixed]]
//!     kind = "face"
//!     face = "x-"
//!     [loads]
//!     gravity = [0.0, -9.81, 0.0]
//!     [solver]
//!     kind = "static"
//!     "#, dir.path().join("bar.svg").display());
//! let input = SceneInput::from_toml(&scene, "bar.toml").unwrap();
//! let job = PlaneJob::prepare(input).unwrap();
//! assert_eq!(job.lattice.num_cells(), 20);
//! let summary = job.run(&dir.path().join("out"), &mss_scene::Cancel::new()).unwrap();
//! assert!(summary.max_displacement > 1e-4);
//! assert!(dir.path().join("out/lattice_0001.vtu").exists());
//! assert!(dir.path().join("out/outline_0001.svg").exists());
//! ```

use std::path::Path;
use std::time::Instant;

use hexmesh::outline::{OutlineEmbedding, load_outline};
use hexmesh::plane::{Outline, RectLattice, rasterize};
use mss_core::Vec3;
use mss_core::constraints::NodeSelector;
use mss_core::plane::{PlaneModel, PlaneMotion, PlaneProblem};
use mss_io::vtk::{Field, PvdWriter, VtuEncoding, write_quads_vtu};
use serde::Serialize;

use crate::build::{SceneInput, prepare_output_folder};
use crate::error::JobError;
use crate::job::Cancel;
use crate::scene::{MeshSource, Scene, TimeStep};

/// A prepared 2D scene.
#[derive(Debug, Clone)]
pub struct PlaneJob {
    /// The scene.
    pub input: SceneInput,
    /// The outline's file.
    pub outline_name: String,
    /// The outline, placed (m).
    pub outline: Outline,
    /// The rectangles.
    pub lattice: RectLattice,
    /// For a body made from a label image, the label covering most of each
    /// cell (frames carry it as the cell field `label`).
    pub cell_labels: Option<Vec<i32>>,
    /// Model, held nodes and loads.
    pub problem: PlaneProblem,
    /// The outline carried by the lattice.
    pub embedding: OutlineEmbedding,
    /// Time step (s), 0 for a static solve.
    pub dt: f64,
    /// Steps to the scene's duration (0 for a static solve).
    pub steps: usize,
    /// Steps between frames (`usize::MAX`: only the first and last).
    pub frame_every: usize,
}

/// What a 2D run did (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct PlaneSummary {
    /// The scene.
    pub scene: String,
    /// Always 2.
    pub dimension: u32,
    /// The outline's file.
    pub mesh: String,
    /// Cells and nodes.
    pub cells: usize,
    /// Nodes.
    pub nodes: usize,
    /// Cell sides `[lx, ly]` (m).
    pub cell_size: [f64; 2],
    /// Thickness (m).
    pub thickness: f64,
    /// Total mass (kg).
    pub mass: f64,
    /// The 2D variant (`paper`, `springs`, `areal`) and its hourglass factor.
    pub parameterization: String,
    /// `explicit`, `implicit` or `static`.
    pub solver: String,
    /// Time step (s; 0 for static).
    pub dt: f64,
    /// Steps taken (Newton iterations for static).
    pub steps: usize,
    /// Simulated time (s).
    pub time: f64,
    /// Largest node displacement at the end (m).
    pub max_displacement: f64,
    /// Largest node displacement over the run (m) and when (s).
    pub peak_displacement: f64,
    /// When the peak happened (s).
    pub peak_time: f64,
    /// Frames written.
    pub frames: usize,
    /// Wall-clock seconds.
    pub wall_seconds: f64,
}

impl PlaneJob {
    /// Reads the outline, rasterizes it and builds the problem, with the
    /// built-in load kinds.
    pub fn prepare(input: SceneInput) -> Result<Self, JobError> {
        Self::prepare_with(input, &crate::scene::LoadKinds::default())
    }

    /// [`PlaneJob::prepare`], resolving `[[loads.custom]]` against
    /// `load_kinds` (their 2D forms: [`crate::scene::LoadKinds::register_plane`]).
    pub fn prepare_with(
        input: SceneInput,
        load_kinds: &crate::scene::LoadKinds,
    ) -> Result<Self, JobError> {
        let scene = &input.scene;
        let name = input.name();
        let setting = |key: &str, message: String| JobError::Setting {
            scene: name.clone(),
            key: key.to_owned(),
            message,
        };
        let vox = &scene.voxelize;
        // The body's outline, and for an image the slice to resample.
        let (outline_name, outline, slice, placement) = match (&scene.mesh, &scene.image) {
            (Some(mesh), _) => {
                let (name, outline) = mesh_outline(&input, mesh, &setting)?;
                (name, outline, None, mesh.placement())
            }
            (None, Some(image)) => {
                let (name, outline, slice) = image_outline(&input, image, &setting)?;
                (name, outline, Some(slice), image.placement())
            }
            (None, None) => {
                return Err(setting(
                    "[mesh]",
                    "a 2D body needs its outline: [mesh] path = \"shape.svg\", or a label image of one slice: [image] path = \"slice.nrrd\"".into(),
                ));
            }
        };
        let (lo, hi) = outline.bounds();
        let longest = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell = match (vox.cell_sides, vox.cell_size, vox.cells_per_axis, vox.cells) {
            (Some(s), ..) => s,
            (None, Some(h), ..) => [h, h],
            (None, None, Some([nx, ny]), _) => [
                (hi[0] - lo[0]) / f64::from(nx),
                (hi[1] - lo[1]) / f64::from(ny),
            ],
            (None, None, None, n) => {
                let h = longest / n.unwrap_or(crate::scene::DEFAULT_CELLS) as f64;
                [h, h]
            }
        };
        let grid = ((hi[0] - lo[0]) / cell[0] + 3.0) * ((hi[1] - lo[1]) / cell[1] + 3.0);
        if grid > vox.max_cells as f64 * 16.0 {
            return Err(setting(
                "[voxelize]",
                format!(
                    "cells of {cell:?} m on an outline of {:.3} x {:.3} m make a grid of {grid:.3e} cells; use larger cells",
                    hi[0] - lo[0],
                    hi[1] - lo[1]
                ),
            ));
        }
        let (lattice, cell_labels) = match &slice {
            None => (
                rasterize(&outline, cell).map_err(|e| setting("[voxelize]", e.to_string()))?,
                None,
            ),
            Some(slice) => {
                let section = scene.image.as_ref().expect("a slice comes from [image]");
                let (lattice, labels) = hexmesh::image::plane::resample_plane(
                    &slice.image,
                    section.labels.as_deref(),
                    &slice.map,
                    &outline,
                    cell,
                    section.threshold,
                    vox.components,
                )
                .map_err(|e| setting("[image]", e.to_string()))?;
                (lattice, Some(labels))
            }
        };
        if lattice.num_cells() as u64 > vox.max_cells {
            return Err(setting(
                "[voxelize] max_cells",
                format!(
                    "the lattice would have {} cells, more than {}",
                    lattice.num_cells(),
                    vox.max_cells
                ),
            ));
        }
        let (variant, hourglass) = scene
            .model
            .plane_variant()
            .map_err(|e| setting("[model] parameterization", e.message))?;
        let material = scene
            .material
            .ok_or_else(|| setting("[material]", "missing".into()))?;
        let thickness = scene.model.thickness.unwrap_or_default();
        let mut model = PlaneModel::new(&lattice, material, thickness, variant, hourglass)
            .map_err(|e| setting("[model]", e.to_string()))?;
        if !scene.regions.is_empty() {
            // A material per region, chosen by each cell's centre (z = 0),
            // as a 3D body's regions are.
            let nodes = lattice.nodes();
            let centres: Vec<[f64; 3]> = lattice
                .cells()
                .iter()
                .map(|c| {
                    let (x, y) = c.iter().fold((0.0, 0.0), |(x, y), &a| {
                        (
                            x + 0.25 * nodes[a as usize][0],
                            y + 0.25 * nodes[a as usize][1],
                        )
                    });
                    [x, y, 0.0]
                })
                .collect();
            let loaders = crate::Registry::default().loaders;
            let mesh_of = |path: &str| input.load_placed_mesh_with(path, &placement, &loaders);
            let context = crate::regions::RegionContext {
                bounds: hexmesh::Aabb::of_points(nodes.iter().map(|p| [p[0], p[1], 0.0]))
                    .ok_or_else(|| setting("[voxelize]", "the lattice has no node".into()))?,
                h: cell[0].min(cell[1]),
                mesh_of: &mesh_of,
                cell_labels: cell_labels
                    .as_deref()
                    .map(|l| std::sync::Arc::new(crate::regions::CellLabels::plane(&lattice, l))),
            };
            let regions = crate::regions::assign_regions_at(
                &centres,
                &context,
                &material,
                &scene.regions,
                &crate::regions::RegionSelectors::default(),
            )
            .map_err(|e| setting(&format!("[[regions]] #{}", e.region + 1), e.message))?;
            model = model
                .with_regions(hourglass, &regions.materials[1..], regions.cell_material)
                .map_err(|e| setting("[[regions]]", e.to_string()))?;
        }
        if model.unstable_in_bending() {
            // Without hourglass control such a lattice has bending modes of
            // negative stiffness: no stable equilibrium, a run that explodes.
            return Err(setting(
                "[model] parameterization",
                format!(
                    "= {:?} on cells of {:?} m: a cell longer than sqrt(2 + 3 nu) = {:.2} times its \
                     height gives negative edge springs, and the lattice is unstable in bending; \
                     use \"{}+hg\" (hourglass control) or squarer cells",
                    scene.model.parameterization,
                    cell,
                    (2.0 + 3.0 * material.poisson).sqrt(),
                    variant.name()
                ),
            ));
        }
        let mut problem = PlaneProblem::new(model);
        let rest = problem.model.rest_positions().to_vec();
        let select = |s: &NodeSelector, key: &str| -> Result<Vec<u32>, JobError> {
            problem
                .model
                .select_nodes(s)
                .map_err(|e| setting(key, e.to_string()))
        };
        for (i, s) in scene.fixed.iter().enumerate() {
            for n in select(s, &format!("[[fixed]] #{}", i + 1))? {
                problem.held[n as usize] = [true, true];
            }
        }
        for (i, m) in scene.motions.iter().enumerate() {
            let nodes = select(&m.select, &format!("[[motions]] #{}", i + 1))?;
            for &n in &nodes {
                problem.held[n as usize] = [true, true];
            }
            problem.motions.push(PlaneMotion {
                nodes,
                displacement: [m.displacement[0], m.displacement[1]],
                ramp: m.ramp.unwrap_or(scene.solver.duration),
            });
        }
        let mut dead = Vec::new();
        for (i, t) in scene.loads.tractions.iter().enumerate() {
            let key = format!("[[loads.tractions]] #{}", i + 1);
            let forces = crate::scene::plane_traction(t, &problem.model)
                .map_err(|e| setting(&key, e.to_string()))?;
            dead.extend(forces);
        }
        for (i, f) in scene.loads.forces.iter().enumerate() {
            let key = format!("[[loads.forces]] #{}", i + 1);
            let forces = crate::scene::plane_force(f, &problem.model)
                .map_err(|e| setting(&key, e.to_string()))?;
            dead.extend(forces);
        }
        for (n, f) in dead {
            problem.forces[n as usize][0] += f[0];
            problem.forces[n as usize][1] += f[1];
        }
        for (i, d) in scene.loads.drags.iter().enumerate() {
            let key = format!("[[loads.drags]] #{}", i + 1);
            let drag = crate::scene::plane_drag(d, &problem.model)
                .map_err(|e| setting(&key, e.to_string()))?;
            problem.loads.push(std::sync::Arc::new(drag));
        }
        for (i, table) in scene.loads.custom.iter().enumerate() {
            let key = format!("[[loads.custom]] #{}", i + 1);
            let load = load_kinds
                .build_plane(table, &problem.model)
                .map_err(|e| setting(&key, e.to_string()))?;
            problem.loads.push(std::sync::Arc::from(load));
        }
        if let Some(g) = scene.loads.gravity {
            problem.gravity = [g[0], g[1]];
        }
        problem.damping = scene.solver.damping;
        problem.precision = scene.solver.precision;
        if !scene.obstacles.is_empty() {
            let low = rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
            let mut obstacles = Vec::new();
            let mut paths = Vec::new();
            let mut settings = Vec::new();
            // The body's stiffest node sets the default penalty (N/m per
            // node); friction 0.5 and damping ratio 0.2 as in 3D.
            let default_stiffness = problem.model.max_node_stiffness();
            for (i, o) in scene.obstacles.iter().enumerate() {
                let key = format!("[[obstacles]] #{} shape", i + 1);
                let shape: crate::obstacles::BuiltinShape = o
                    .shape
                    .tagged_as()
                    .map_err(|e| setting(&key, e.to_string()))?;
                obstacles.push(plane_obstacle(shape, low).map_err(|m| setting(&key, m))?);
                let motion_key = format!("[[obstacles]] #{} motion", i + 1);
                if let Some(k) = o.motion.iter().find(|k| k[3] != 0.0) {
                    return Err(setting(
                        &motion_key,
                        format!(
                            "has the keyframe {k:?}; a 2D obstacle moves in the x-y plane (dz = 0)"
                        ),
                    ));
                }
                paths.push(o.path().map_err(|e| setting(&motion_key, e.message))?);
                let friction = o.friction.or(scene.contact.friction).unwrap_or(0.5);
                let s = mss_core::plane::PlaneContactSettings {
                    stiffness: o
                        .stiffness
                        .or(scene.contact.stiffness)
                        .unwrap_or(default_stiffness),
                    friction_static: friction,
                    friction_kinetic: o
                        .friction_kinetic
                        .or(scene.contact.friction_kinetic)
                        .unwrap_or(friction),
                    damping_ratio: o
                        .damping_ratio
                        .or(scene.contact.damping_ratio)
                        .unwrap_or(0.2),
                };
                s.validate()
                    .map_err(|e| setting(&format!("[[obstacles]] #{}", i + 1), e.0))?;
                settings.push(s);
            }
            problem.contact = Some(
                mss_core::plane::PlaneContact::new(obstacles, paths, settings)
                    .map_err(|e| setting("[[obstacles]]", e.0))?,
            );
        }
        let (dt, steps, frame_every) = if scene.solver.is_static() {
            (0.0, 0, usize::MAX)
        } else {
            let stable = problem.stable_time_step(1.0);
            let implicit = scene.solver.kind == "implicit";
            let dt = match scene.solver.dt {
                TimeStep::Auto if implicit => {
                    scene.solver.duration / crate::scene::IMPLICIT_AUTO_STEPS as f64
                }
                TimeStep::Auto => stable * scene.solver.safety,
                TimeStep::Seconds(dt) if dt > stable && !implicit => {
                    return Err(setting(
                        "[solver] dt",
                        format!(
                            "= {dt} s is above the stable step of this lattice, {stable:.3e} s: use dt = \"auto\" or a smaller step"
                        ),
                    ));
                }
                TimeStep::Seconds(dt) => dt,
            };
            let steps = (scene.solver.duration / dt).ceil().max(1.0) as usize;
            let dt = scene.solver.duration / steps as f64;
            let out = &scene.output;
            let every = if out.last_only {
                usize::MAX
            } else if let Some(n) = out.every_steps {
                n.max(1) as usize
            } else if let Some(t) = out.every_time {
                ((t / dt).round() as usize).max(1)
            } else {
                (steps / crate::build::DEFAULT_FRAMES as usize).max(1)
            };
            (dt, steps, every)
        };
        let embedding = OutlineEmbedding::new(&lattice, &outline);
        Ok(Self {
            input,
            outline_name,
            outline,
            lattice,
            cell_labels,
            problem,
            embedding,
            dt,
            steps,
            frame_every,
        })
    }

    /// Runs the scene, writing frames and `summary.json` into `out_dir`.
    pub fn run(&self, out_dir: &Path, cancel: &Cancel) -> Result<PlaneSummary, JobError> {
        let start = Instant::now();
        prepare_output_folder(out_dir)?;
        let p = &self.problem;
        let rest = p.model.rest_positions().to_vec();
        let mut x = rest.clone();
        let mut v = vec![Vec3::zeros(); x.len()];
        let mut writer = FrameWriter::new(self, out_dir);
        let displacement = |x: &[Vec3]| {
            x.iter()
                .zip(&rest)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max)
        };
        writer.write(0.0, &x, &v)?;
        let (mut peak, mut peak_time) = (0.0, 0.0);
        let solver_error = |e: mss_core::plane::PlaneSolveError| JobError::Setting {
            scene: self.input.name(),
            key: "[solver]".into(),
            message: e.to_string(),
        };
        let (steps, time) = if self.input.scene.solver.is_static() {
            let iterations = p
                .solve_static(self.input.scene.solver.duration, &mut x)
                .map_err(solver_error)?;
            peak = displacement(&x);
            writer.write(0.0, &x, &v)?;
            (iterations as usize, 0.0)
        } else {
            let mut done = 0;
            while done < self.steps {
                if cancel.is_cancelled() {
                    break;
                }
                let chunk = self.frame_every.min(self.steps - done);
                let t0 = done as f64 * self.dt;
                if self.input.scene.solver.kind == "implicit" {
                    p.step_implicit(t0, &mut x, &mut v, self.dt, chunk)
                        .map_err(solver_error)?;
                } else {
                    p.step_explicit(t0, &mut x, &mut v, self.dt, chunk)
                        .map_err(solver_error)?;
                }
                done += chunk;
                let t = done as f64 * self.dt;
                let d = displacement(&x);
                if d > peak {
                    (peak, peak_time) = (d, t);
                }
                if done % self.frame_every == 0 || done == self.steps {
                    writer.write(t, &x, &v)?;
                }
            }
            (done, done as f64 * self.dt)
        };
        writer.finish()?;
        let (variant, hourglass) = self
            .input
            .scene
            .model
            .plane_variant()
            .expect("checked when the job was prepared");
        let summary = PlaneSummary {
            scene: self.input.name(),
            dimension: 2,
            mesh: self.outline_name.clone(),
            cells: self.lattice.num_cells(),
            nodes: self.lattice.num_nodes(),
            cell_size: self.lattice.cell_size(),
            thickness: p.model.thickness(),
            mass: p.model.total_mass(),
            parameterization: match hourglass {
                Some(a) => format!("{}+hg ({a})", variant.name()),
                None => variant.name().to_owned(),
            },
            solver: self.input.scene.solver.kind.clone(),
            dt: self.dt,
            steps,
            time,
            max_displacement: displacement(&x),
            peak_displacement: peak,
            peak_time,
            frames: writer.frames,
            wall_seconds: start.elapsed().as_secs_f64(),
        };
        let json = serde_json::to_string_pretty(&summary).expect("a summary encodes");
        mss_io::atomic::write_atomic(&out_dir.join("summary.json"), |w| {
            w.write_all(json.as_bytes())?;
            w.write_all(b"\n")
        })?;
        Ok(summary)
    }
}

/// A scene's obstacle shape in the plane z = 0 (`lowest`: the lattice's
/// lowest y, for `ground`).
fn plane_obstacle(
    shape: crate::obstacles::BuiltinShape,
    lowest: f64,
) -> Result<mss_core::plane::PlaneObstacle, String> {
    use crate::obstacles::BuiltinShape;
    use mss_core::plane::PlaneObstacle;
    let in_plane = |what: &str, v: [f64; 3]| {
        if v[2] == 0.0 {
            Ok([v[0], v[1]])
        } else {
            Err(format!(
                "{what} = {v:?}: a 2D body's obstacles lie in the x-y plane (z = 0)"
            ))
        }
    };
    match shape {
        BuiltinShape::Ground { gap } => Ok(PlaneObstacle::HalfPlane {
            point: [0.0, lowest - gap],
            normal: [0.0, 1.0],
        }),
        BuiltinShape::Plane { point, normal } => {
            let n = in_plane("normal", normal)?;
            let len = n[0].hypot(n[1]);
            if !(len.is_finite() && len > 0.0) {
                return Err(format!("normal = {normal:?} must be a non-zero direction"));
            }
            Ok(PlaneObstacle::HalfPlane {
                point: in_plane("point", point)?,
                normal: [n[0] / len, n[1] / len],
            })
        }
        BuiltinShape::Sphere { centre, radius } if radius.is_finite() && radius > 0.0 => {
            Ok(PlaneObstacle::Disc {
                centre: in_plane("centre", centre)?,
                radius,
            })
        }
        // A box's section by the plane z = 0.
        BuiltinShape::Box { min, max }
            if (0..2).all(|k| min[k] < max[k]) && min[2] <= 0.0 && max[2] >= 0.0 =>
        {
            Ok(PlaneObstacle::Rect {
                min: [min[0], min[1]],
                max: [max[0], max[1]],
            })
        }

        BuiltinShape::Sphere { radius, .. } => {
            Err(format!("radius = {radius} must be a positive length"))
        }
        BuiltinShape::Box { min, max } => Err(format!(
            "min = {min:?}, max = {max:?}: a 2D body's box needs min below max in x and y, and to cross z = 0"
        )),
        BuiltinShape::Mesh { .. } | BuiltinShape::Capsule { .. } => Err(
            "a 2D body's obstacles are ground, plane, sphere (a disc) and box (a rectangle)".into(),
        ),
    }
}

/// The frames of a 2D run.
struct FrameWriter<'a> {
    job: &'a PlaneJob,
    dir: &'a Path,
    pvd: Option<PvdWriter>,
    frames: usize,
}

impl<'a> FrameWriter<'a> {
    fn new(job: &'a PlaneJob, dir: &'a Path) -> Self {
        let pvd = job
            .input
            .scene
            .output
            .pvd
            .then(|| PvdWriter::new(dir.join("lattice.pvd")));
        Self {
            job,
            dir,
            pvd,
            frames: 0,
        }
    }

    fn write(&mut self, time: f64, x: &[Vec3], v: &[Vec3]) -> Result<(), JobError> {
        let out = &self.job.input.scene.output;
        let p = &self.job.problem;
        let index = self.frames;
        let points: Vec<[f64; 3]> = x.iter().map(|p| [p.x, p.y, 0.0]).collect();
        if out.vtu {
            let rest = p.model.rest_positions();
            let displacement: Vec<[f64; 3]> = x
                .iter()
                .zip(rest)
                .map(|(a, b)| [a.x - b.x, a.y - b.y, 0.0])
                .collect();
            let velocity: Vec<[f64; 3]> = v.iter().map(|v| [v.x, v.y, 0.0]).collect();
            let mut f = vec![Vec3::zeros(); x.len()];
            p.model.internal_forces(x, &mut f);
            let force: Vec<[f64; 3]> = f.iter().map(|f| [f.x, f.y, 0.0]).collect();
            let fixed: Vec<bool> = p.held.iter().map(|h| h[0] || h[1]).collect();
            let file = format!("lattice_{index:04}.vtu");
            write_quads_vtu(
                &self.dir.join(&file),
                &points,
                p.model.cells(),
                &[
                    Field::vectors("displacement", &displacement),
                    Field::vectors("velocity", &velocity),
                    Field::vectors("internal_force", &force),
                    Field::flags("fixed", &fixed),
                ],
                &{
                    let mut cells = Vec::new();
                    if !p.model.cell_materials().is_empty() {
                        // As a 3D frame's: 0 the scene's material, k the k-th region.
                        cells.push(Field::ids("material", p.model.cell_materials()));
                    }
                    if let Some(labels) = &self.job.cell_labels {
                        cells.push(Field::labels("label", labels));
                    }
                    cells
                },
                VtuEncoding::Base64Zlib,
            )?;
            if let Some(pvd) = &mut self.pvd {
                pvd.add_frame(time, &file)?;
            }
        }
        if out.embedded || out.skin_obj {
            let nodes: Vec<[f64; 2]> = x.iter().map(|p| [p.x, p.y]).collect();
            let loops = self.job.embedding.deform(&nodes);
            mss_io::outline::write_outline_svg(
                &self.dir.join(format!("outline_{index:04}.svg")),
                &loops,
            )?;
            mss_io::outline::write_outline_obj(
                &self.dir.join(format!("outline_{index:04}.obj")),
                &loops,
            )?;
        }
        self.frames += 1;
        Ok(())
    }

    fn finish(&mut self) -> Result<(), JobError> {
        if let Some(pvd) = &self.pvd {
            pvd.write()?;
        }
        Ok(())
    }
}

/// A one-slice label image, and its map from pixel indices to the plane.
struct Slice {
    image: hexmesh::image::LabelImage,
    map: [[f64; 3]; 2],
}

/// The file `path` names (relative to the scene's folder), or the error
/// under `key` saying `why` a built-in does not serve.
fn file_of(
    input: &SceneInput,
    path: &str,
    key: &str,
    why: &str,
    setting: &dyn Fn(&str, String) -> JobError,
) -> Result<std::path::PathBuf, JobError> {
    match Scene::source_of(path, &input.origin) {
        MeshSource::File(p) => Ok(p),
        MeshSource::Builtin(b) => Err(setting(key, format!("= \"builtin:{b}\"; {why}"))),
    }
}

/// The outline of a 2D body's `[mesh]` (an SVG drawing or a planar mesh),
/// placed in the x-y plane, and the file's name.
fn mesh_outline(
    input: &SceneInput,
    mesh: &crate::scene::MeshSection,
    setting: &dyn Fn(&str, String) -> JobError,
) -> Result<(String, Outline), JobError> {
    let path = file_of(
        input,
        &mesh.path,
        "[mesh] path",
        "a 2D body needs an outline: an SVG drawing or a planar mesh file",
        setting,
    )?;
    let raw = load_outline(&path).map_err(|e| setting("[mesh] path", e.to_string()))?;
    // The placement's units, scale, rotation and translation, kept in the
    // x-y plane.
    let placement = mesh.placement();
    let mut polygons = Vec::new();
    for poly in raw.polygons() {
        let mut placed = Vec::with_capacity(poly.len());
        for p in poly {
            let q = placement.apply_point([p[0], p[1], 0.0]);
            if q[2].abs() > 1e-9 * (1.0 + q[0].abs() + q[1].abs()) {
                return Err(setting(
                    "[mesh]",
                    "the placement turns the outline out of the x-y plane: a 2D body's up and rotate keep z".into(),
                ));
            }
            placed.push([q[0], q[1]]);
        }
        polygons.push(placed);
    }
    let outline = Outline::new(polygons).map_err(|e| setting("[mesh] path", e.to_string()))?;
    Ok((path.display().to_string(), outline))
}

/// A 2D body's `[image]`: the slice read (within the default memory
/// limit), in the frame and unit asked, placed; the chosen pixels' boundary
/// as its outline; and the file's name.
fn image_outline(
    input: &SceneInput,
    section: &crate::scene::ImageSection,
    setting: &dyn Fn(&str, String) -> JobError,
) -> Result<(String, Outline, Slice), JobError> {
    let path = file_of(
        input,
        &section.path,
        "[image] path",
        "built-in meshes are not images: give a label image file",
        setting,
    )?;
    let limits = hexmesh::image::ImageLimits {
        max_bytes: crate::limits::Limits::default().memory_bytes,
    };
    let mut image = hexmesh::image::load_image(&path, &limits)
        .map_err(|e| setting("[image] path", e.to_string()))?;
    if let Some(target) = section.space.target() {
        image = image.in_space(&target);
    }
    let unit = section
        .units
        .map(|u| u.factor())
        .unwrap_or_else(|| image.unit_metres_or_default());
    let to_metres = image.to_metres(unit, &section.placement());
    let map = hexmesh::image::plane::slice_to_plane(&image, &to_metres)
        .map_err(|e| setting("[image]", e.to_string()))?;
    let body = hexmesh::image::plane::pixel_outline(&image, section.labels.as_deref(), &map)
        .map_err(|e| setting("[image] labels", e.to_string()))?;
    log::info!(
        "{}: {:?} pixels; labels and pixels in the body {:?}",
        path.display(),
        image.dims,
        body.pixels_per_label
    );
    Ok((
        path.display().to_string(),
        body.outline,
        Slice { image, map },
    ))
}
