//! `mss run`: runs a scene (default: the bundled job) and writes its frames.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use mss_core::Model;
use mss_core::solver::{
    Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator, Problem, State,
    StaticOptions, solve_static,
};
use mss_io::scene::SolverKind;
use serde::Serialize;

use crate::output::FrameWriter;
use crate::setup::{self, SceneInput, TimePlan};
use crate::{GlobalArgs, progress};

/// Arguments of `mss run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Scene file (TOML). Without it, the bundled default scene runs: the
    /// bundled critter mesh sagging under gravity, written to ./out.
    #[arg(value_name = "SCENE")]
    pub scene: Option<PathBuf>,
    /// Simulated duration in seconds, overriding the scene's `[solver] duration`.
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
}

/// Everything built from a scene before time stepping.
pub struct Prepared {
    /// The scene.
    pub input: SceneInput,
    /// Display name of the mesh.
    pub mesh_name: String,
    /// The cleaned input surface.
    pub mesh: hexmesh::TriMesh,
    /// The voxelized lattice.
    pub lattice: hexmesh::Lattice,
    /// Voxelization statistics.
    pub vox_stats: hexmesh::voxelize::VoxelizeStats,
    /// The problem (model, constraints, loads, damping).
    pub problem: Problem,
    /// Time stepping plan.
    pub plan: TimePlan,
    /// Seconds spent loading and voxelizing the mesh.
    pub voxelize_seconds: f64,
}

/// Loads the mesh, voxelizes it and builds the problem and time plan of a scene.
pub fn prepare(input: SceneInput, show: bool) -> anyhow::Result<Prepared> {
    let scene_name = input.name();
    let scene = &input.scene;
    let t0 = Instant::now();
    let source = scene.mesh_source(&input.origin);
    let (mesh_name, loaded) =
        setup::load_mesh(&source).with_context(|| format!("{scene_name}: [mesh] path"))?;
    let opts = setup::scene_voxelize_options(&scene.voxelize)
        .with_context(|| format!("{scene_name}: [voxelize]"))?;
    let vox = progress::voxelize_with_bar(
        &loaded.mesh,
        &opts,
        &format!("voxelizing {mesh_name}"),
        show,
    );
    let vox = vox.with_context(|| format!("{scene_name}: cannot voxelize {mesh_name}"))?;
    let voxelize_seconds = t0.elapsed().as_secs_f64();
    let (material, param) = setup::material(scene).with_context(|| scene_name.clone())?;
    let model = Model::new(&vox.lattice, material, &*param)
        .with_context(|| format!("{scene_name}: cannot build the model"))?;
    let problem = setup::problem(scene, model).with_context(|| scene_name.clone())?;
    let plan = setup::time_plan(scene, &problem).with_context(|| scene_name.clone())?;
    Ok(Prepared {
        mesh_name,
        mesh: loaded.mesh,
        lattice: vox.lattice,
        vox_stats: vox.stats,
        problem,
        plan,
        voxelize_seconds,
        input,
    })
}

/// Figures of a finished run (printed, and written as `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Scene file, or the bundled default.
    pub scene: String,
    /// Mesh name.
    pub mesh: String,
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
}

/// Runs `mss run`.
pub fn run(args: &RunArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut input = setup::load_scene(args.scene.as_deref())?;
    if let Some(d) = args.duration {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration {d}: give a positive number of seconds");
        }
        input.scene.solver.duration = d;
    }
    let out_dir = setup::output_folder(&input.scene, global.out.as_deref());
    let show = global.chatty();
    // Everything is checked before the output folder is created, so that bad
    // input leaves no file behind.
    let prepared = prepare(input, show)?;
    // A static solve reports mechanisms itself, as its one-line error; dynamic
    // runs go on, so they get the warning.
    if prepared.plan.kind != mss_io::scene::SolverKind::Static
        && prepared.problem.model().num_nodes() <= super::check::RUN_MODE_CHECK_MAX_NODES
        && let Some(warning) = super::check::mechanism_warning(&prepared)
    {
        log::warn!("{warning}");
    }
    let summary = simulate(&prepared, &out_dir, show, start)?;
    let json = serde_json::to_string_pretty(&summary).context("cannot encode the summary")?;
    let summary_path = out_dir.join("summary.json");
    mss_io::atomic::write_atomic(&summary_path, |w| {
        w.write_all(json.as_bytes())?;
        w.write_all(b"\n")
    })?;
    if show {
        print_summary(&summary);
    }
    Ok(())
}

/// Time-steps a prepared scene, writing frames into `out_dir`.
pub fn simulate(
    p: &Prepared,
    out_dir: &Path,
    show: bool,
    start: Instant,
) -> anyhow::Result<RunSummary> {
    let scene = &p.input.scene;
    let name = p.input.name();
    let problem = &p.problem;
    let plan = p.plan;
    let s = &scene.solver;
    let t_sim = Instant::now();
    let integrator = integrator(p)?;
    let mut state = State::at_rest(problem.model());
    problem.apply_constraints(&mut state);
    let mut steps_done = 0;
    let mut writer;
    match integrator {
        None => {
            // A static solve is the whole computation: do it before creating
            // any file, so that a failure leaves nothing behind.
            let rest_state = state.clone();
            let opts = StaticOptions {
                rtol: s.tolerance,
                max_newton: s.max_iterations,
                ..StaticOptions::default()
            };
            state.time = s.duration;
            let spinner = progress::spinner("static solve", show);
            let r = solve_static(problem, &mut state, &opts);
            spinner.finish_and_clear();
            let info = r.with_context(|| format!("{name}: static solve failed"))?;
            log::info!(
                "static equilibrium: {} load steps, {} Newton iterations, relative residual {:.2e}",
                info.load_steps,
                info.newton_iterations,
                info.relative_residual
            );
            steps_done = 1;
            setup::prepare_output_folder(out_dir)?;
            writer = FrameWriter::new(out_dir, &scene.output, &p.lattice, &p.mesh)?;
            if !plan.last_only {
                writer.write(problem, &rest_state)?;
            }
            writer.write(problem, &state)?;
        }
        Some(mut integrator) => {
            // Fail on an unwritable folder before the long part.
            setup::prepare_output_folder(out_dir)?;
            writer = FrameWriter::new(out_dir, &scene.output, &p.lattice, &p.mesh)?;
            if !plan.last_only {
                writer.write(problem, &state)?;
            }
            let bar = progress::bar(plan.steps, "steps", show);
            for k in 1..=plan.steps {
                if let Err(e) = integrator.step(problem, &mut state) {
                    bar.abandon();
                    // Keep what was simulated: the last good state is a frame.
                    let _ = writer.write(problem, &state);
                    let _ = writer.finish();
                    return Err(e).with_context(|| format!("{name}: the simulation failed"));
                }
                steps_done = k;
                if plan.frame_after(k) {
                    writer.write(problem, &state)?;
                }
                bar.inc(1);
            }
            bar.finish_and_clear();
        }
    }
    writer.finish()?;
    let model = problem.model();
    let max_displacement = state
        .x
        .iter()
        .zip(model.rest_positions())
        .map(|(x, r)| (x - r).norm())
        .fold(0.0, f64::max);
    let (files, bytes) = writer.files_and_bytes();
    let held_nodes = (0..model.num_nodes())
        .filter(|&n| problem.constraints().mask(n).iter().any(|&h| h))
        .count();
    Ok(RunSummary {
        scene: name,
        mesh: p.mesh_name.clone(),
        cells: model.num_cells(),
        nodes: model.num_nodes(),
        springs: model.num_springs(),
        cell_size: model.h(),
        mass: model.total_mass(),
        held_nodes,
        solver: format!("{:?}", plan.kind).to_lowercase(),
        time_step: plan.dt,
        stable_time_step: plan.stable_dt,
        steps: steps_done,
        simulated_time: state.time,
        frames: writer.frames(),
        files,
        bytes_written: bytes,
        max_displacement,
        voxelize_seconds: p.voxelize_seconds,
        simulate_seconds: t_sim.elapsed().as_secs_f64(),
        wall_seconds: start.elapsed().as_secs_f64(),
        peak_memory_bytes: progress::peak_memory_bytes(),
        output_folder: out_dir.display().to_string(),
    })
}

/// The time integrator of a prepared scene (`None` for a static solve).
/// Refuses, among others, an explicit step above the stability limit.
pub fn integrator(p: &Prepared) -> anyhow::Result<Option<Box<dyn Integrator>>> {
    let s = &p.input.scene.solver;
    let name = p.input.name();
    let problem = &p.problem;
    Ok(match p.plan.kind {
        SolverKind::Static => None,
        SolverKind::Explicit => Some(Box::new(
            Explicit::new(
                problem,
                ExplicitOptions {
                    dt: Some(p.plan.dt),
                    safety: s.safety,
                    substep: s.substep,
                    ..ExplicitOptions::default()
                },
            )
            .with_context(|| format!("{name}: [solver]"))?,
        )),
        SolverKind::Implicit => Some(Box::new(
            Implicit::new(
                problem,
                ImplicitOptions {
                    dt: p.plan.dt,
                    max_newton: s.max_iterations,
                    rtol: s.tolerance,
                    ..ImplicitOptions::default()
                },
            )
            .with_context(|| format!("{name}: [solver]"))?,
        )),
    })
}

fn print_summary(s: &RunSummary) {
    println!("scene            {}", s.scene);
    println!("mesh             {}", s.mesh);
    println!(
        "lattice          {} cells, {} nodes, {} springs, cell size {:.4} m",
        s.cells, s.nodes, s.springs, s.cell_size
    );
    println!(
        "mass             {:.4} kg, {} held nodes",
        s.mass, s.held_nodes
    );
    println!(
        "solver           {}, time step {:.3e} s (stable limit {:.3e} s), {} steps, {:.4} s simulated",
        s.solver, s.time_step, s.stable_time_step, s.steps, s.simulated_time
    );
    println!(
        "wall time        {:.2} s (voxelize {:.2} s, simulate and write {:.2} s)",
        s.wall_seconds, s.voxelize_seconds, s.simulate_seconds
    );
    println!(
        "peak memory      {}",
        s.peak_memory_bytes
            .map(progress::human_bytes)
            .unwrap_or_else(|| "unknown".into())
    );
    println!("max displacement {:.4e} m", s.max_displacement);
    println!(
        "output           {}: {} frames, {} files, {} (open lattice.pvd in ParaView)",
        s.output_folder,
        s.frames,
        s.files,
        progress::human_bytes(s.bytes_written)
    );
}
