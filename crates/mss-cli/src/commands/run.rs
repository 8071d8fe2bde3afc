//! `mss run`: runs a scene (default: the bundled job) and writes its frames.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;
use mss_scene::check::{mechanism_warning, run_counts_modes};
use mss_scene::{Cancel, Job, Registry, RunSummary, SceneInput, write_summary};

use crate::GlobalArgs;
use crate::progress::{self, JobBars};

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
    /// Continue the interrupted run in FOLDER from its checkpoint (written
    /// at Ctrl-C and every `[output] checkpoint_every` seconds), with the
    /// same scene; its frames end bitwise as an uninterrupted run's.
    #[arg(long, value_name = "FOLDER", conflicts_with = "duration")]
    pub resume: Option<PathBuf>,
}

/// Reads the scene of `mss run`/`mss check` and prepares its job behind
/// progress bars.
pub fn prepare(
    scene: Option<&std::path::Path>,
    duration: Option<f64>,
    limits: mss_scene::limits::Limits,
    bars: &JobBars,
) -> anyhow::Result<Job> {
    prepare_input(load_input(scene, duration)?, limits, bars)
}

/// Reads the scene of `mss run`/`mss check`, with `--duration` applied.
pub fn load_input(
    scene: Option<&std::path::Path>,
    duration: Option<f64>,
) -> anyhow::Result<SceneInput> {
    let mut input = SceneInput::load(scene)?;
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration {d}: give a positive number of seconds");
        }
        input.scene.solver.duration = d;
    }
    Ok(input)
}

/// Prepares the job of a (3D) scene behind progress bars.
pub fn prepare_input(
    input: SceneInput,
    limits: mss_scene::limits::Limits,
    bars: &JobBars,
) -> anyhow::Result<Job> {
    let job = Job::prepare_with_limits(input, Registry::default(), limits, &|p| bars.report(p));
    bars.clear();
    Ok(job?)
}

/// Runs `mss run`.
pub fn run(args: &RunArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let show = global.chatty();
    let label = args
        .scene
        .as_ref()
        .map_or("the bundled critter".to_owned(), |p| {
            p.display().to_string()
        });
    let bars = JobBars::new(&label, show);
    // Everything is checked before the output folder is created, so that bad
    // input leaves no file behind.
    let input = load_input(args.scene.as_deref(), args.duration)?;
    if input.scene.is_plane() {
        if args.resume.is_some() {
            bail!("--resume: a 2D run has no checkpoints; run it again");
        }
        return run_plane(input, global);
    }
    let job = prepare_input(input, global.limits(), &bars)?;
    let out_dir = match (&args.resume, &global.out) {
        (Some(folder), Some(out)) if folder != out => {
            bail!(
                "--resume {} --out {}: a resumed run continues in its own folder; give one of them",
                folder.display(),
                out.display()
            )
        }
        (Some(folder), _) => folder.clone(),
        (None, out) => mss_scene::build::output_folder(&job.input.scene, out.as_deref()),
    };
    // A static solve reports mechanisms itself, as its one-line error; dynamic
    // runs go on, so they get the warning.
    if !job.plan.is_static
        && run_counts_modes(job.problem.model())
        && let Some(warning) = mechanism_warning(&job)
    {
        log::warn!("{warning}");
    }
    let cancel = Cancel::new();
    interrupt_on_signals(&cancel)?;
    let result = match &args.resume {
        None => job.run(&out_dir, &|p| bars.report(p), &cancel),
        Some(_) => job.resume(&out_dir, &|p| bars.report(p), &cancel),
    };
    bars.clear();
    let summary = result?;
    write_summary(&out_dir, &summary)?;
    if show {
        print_summary(&summary)?;
    }
    if summary.interrupted {
        bail!(
            "{}: interrupted at t = {:.3e} s after {} steps; the {} frames written so far, \
             summary.json (\"interrupted\": true) and a checkpoint are in {}; `mss run{} \
             --resume {}` continues",
            summary.scene,
            summary.simulated_time,
            summary.steps,
            summary.frames,
            summary.output_folder,
            args.scene
                .as_ref()
                .map_or(String::new(), |p| format!(" {}", p.display())),
            summary.output_folder
        );
    }
    Ok(())
}

/// `mss run` of a 2D scene (`[model] dimension = 2`).
fn run_plane(input: SceneInput, global: &GlobalArgs) -> anyhow::Result<()> {
    let out_dir = mss_scene::build::output_folder(&input.scene, global.out.as_deref());
    let job = mss_scene::plane_job::PlaneJob::prepare(input)?;
    let cancel = Cancel::new();
    interrupt_on_signals(&cancel)?;
    let spinner = crate::progress::spinner("2D run", global.chatty());
    let summary = job.run(&out_dir, &cancel);
    spinner.finish_and_clear();
    let s = summary?;
    if global.chatty() {
        crate::outln!("scene            {} (2D, plane stress)", s.scene);
        crate::outln!(
            "outline          {}: {} cells of {} x {}, {} nodes, thickness {}",
            s.mesh,
            s.cells,
            crate::progress::human_length(s.cell_size[0]),
            crate::progress::human_length(s.cell_size[1]),
            s.nodes,
            crate::progress::human_length(s.thickness)
        );
        crate::outln!(
            "model            {}, mass {:.4e} kg",
            s.parameterization,
            s.mass
        );
        if s.solver == "static" {
            crate::outln!("solver           static, {} Newton iterations", s.steps);
        } else {
            crate::outln!(
                "solver           {}, time step {:.3e} s, {} steps, {:.4} s simulated",
                s.solver,
                s.dt,
                s.steps,
                s.time
            );
        }
        crate::outln!(
            "max displacement {:.4e} m at the end, {:.4e} m at its peak (t = {:.4} s)",
            s.max_displacement,
            s.peak_displacement,
            s.peak_time
        );
        crate::outln!(
            "output           {}: {} frames (lattice quads .vtu, outline .svg and .obj), {:.2} s",
            out_dir.display(),
            s.frames,
            s.wall_seconds
        );
    }
    if cancel.is_cancelled() {
        bail!(
            "{}: interrupted at t = {:.3e} s; the frames written so far are in {}",
            s.scene,
            s.time,
            out_dir.display()
        );
    }
    Ok(())
}

/// SIGINT and SIGTERM set `cancel`: the run stops after the step under way,
/// writes the state reached and its summary, and `mss` exits with 1. A second
/// SIGINT or SIGTERM while it winds down ends the process at once (exit 130).
pub(crate) fn interrupt_on_signals(cancel: &Cancel) -> anyhow::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let flag = cancel.flag();
    for signal in [SIGINT, SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 130, std::sync::Arc::clone(&flag))
            .map_err(|e| anyhow::anyhow!("cannot install the signal handler: {e}"))?;
        signal_hook::flag::register(signal, std::sync::Arc::clone(&flag))
            .map_err(|e| anyhow::anyhow!("cannot install the signal handler: {e}"))?;
    }
    Ok(())
}

fn print_summary(s: &RunSummary) -> Result<(), crate::StdoutError> {
    crate::outln!("scene            {}", s.scene);
    let [ex, ey, ez] = s.mesh_extent;
    crate::outln!(
        "mesh             {} ({ex:.4} x {ey:.4} x {ez:.4} m; placement: {})",
        s.mesh,
        s.placement
    );
    crate::outln!(
        "lattice          {} cells, {} nodes, {} springs, cell size {}",
        s.cells,
        s.nodes,
        s.springs,
        crate::progress::human_length(s.cell_size)
    );
    if s.cells_per_material.len() > 1 {
        crate::outln!(
            "materials        cells per material ([material], then each region): {:?}",
            s.cells_per_material
        );
    }
    crate::outln!(
        "mass             {:.4} kg, {} held nodes",
        s.mass,
        s.held_nodes
    );
    crate::outln!(
        "solver           {}, time step {:.3e} s (stable limit {:.3e} s), {} steps, {:.4} s simulated",
        s.solver,
        s.time_step,
        s.stable_time_step,
        s.steps,
        s.simulated_time
    );
    if let Some(verdict) = &s.load_check {
        crate::outln!("under load       {verdict}");
    }
    if let Some(settled) = &s.settled {
        crate::outln!(
            "settled          in {} steps ({:.3e} s simulated), residual {:.1e} of the loads",
            settled.steps,
            settled.settle_time,
            settled.relative_residual
        );
    }
    if s.newton_iterations > 0 {
        crate::outln!(
            "newton           {} iterations, {:.2} per step",
            s.newton_iterations,
            s.newton_iterations_per_step
        );
    }
    if s.bodies.len() > 1 {
        for b in &s.bodies {
            let [fx, fy, fz] = b.contact_force_from_bodies;
            crate::outln!(
                "body             {}: {} cells, {:.4} kg, max displacement {:.4e} m, force from the other bodies [{fx:.4}, {fy:.4}, {fz:.4}] N",
                b.name,
                b.cells,
                b.mass,
                b.max_displacement
            );
        }
    }
    crate::outln!(
        "wall time        {:.2} s (voxelize {:.2} s, simulate and write {:.2} s)",
        s.wall_seconds,
        s.voxelize_seconds,
        s.simulate_seconds
    );
    crate::outln!(
        "peak memory      {}",
        s.peak_memory_bytes
            .map(progress::human_bytes)
            .unwrap_or_else(|| "unknown".into())
    );
    crate::outln!(
        "max displacement {:.4e} m at the end, {:.4e} m at its peak (t = {:.4} s)",
        s.max_displacement,
        s.peak_displacement,
        s.peak_displacement_time
    );
    if s.most_folded_cells.0 > 0 {
        crate::outln!(
            "folded cells     {} at the end, {} at most (t = {:.4} s): cells with a corner \
             Jacobian <= 0 (see the warning above)",
            s.folded_cells,
            s.most_folded_cells.0,
            s.most_folded_cells.1
        );
    }
    // The collections a user opens in ParaView, as the run left them.
    let folder = std::path::Path::new(&s.output_folder);
    let collections: Vec<&str> = ["lattice.pvd", "surface.pvd"]
        .into_iter()
        .filter(|name| folder.join(name).is_file())
        .collect();
    let open = if collections.is_empty() {
        String::new()
    } else {
        format!(" (open {} in ParaView)", collections.join(" and "))
    };
    crate::outln!(
        "output           {}: {} frames, {} files, {}{open}",
        s.output_folder,
        s.frames,
        s.files,
        progress::human_bytes(s.bytes_written)
    );
    Ok(())
}
