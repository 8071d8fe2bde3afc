//! `mss experiment`: the paper's experiments (cantilever, L-shape, material
//! tests), or any scene (`mss experiment scene SCENE.toml`), against a
//! converged FEM reference, written as a Markdown report with CSV tables, SVG
//! plots and VTU files.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::Context;
use indicatif::ProgressBar;
use mss_validate::experiments::{self, Regime, SharedParameterization, builtin_models};
use mss_validate::report;
use mss_validate::suite::{Experiment, SceneDescription, SuiteSettings, run_suite, scene_report};

use crate::progress;

/// Which experiment to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Which {
    /// The cantilever under gravity (small load at nu = 0.3 and 0, large deflection).
    Beam,
    /// The L-shaped block under a surface load.
    Lshape,
    /// Virtual material tests (E, nu, G, K).
    Material,
    /// All of the above.
    All,
    /// The paper's 2D element: virtual elongation and shear tests at aspect
    /// ratios 1, 2, 4, and a cantilever convergence study against bilinear
    /// plane-stress FEM and Timoshenko's beam.
    #[value(name = "2d")]
    Plane,
    /// Any scene file (given after it): the MSS static equilibrium under its
    /// fixed regions and loads against a Q1 FEM reference on the refined lattice.
    Scene,
}

/// Regime of `mss experiment scene`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RegimeArg {
    /// Linear if the linear FEM reference's largest displacement is at most 1 % of the body's diagonal, else nonlinear.
    Auto,
    /// Small-strain linear solutions on both sides.
    Linear,
    /// The nonlinear static MSS solver against compressible neo-Hookean FEM.
    Nonlinear,
}

/// Arguments of `mss experiment`.
#[derive(Debug, Clone, clap::Args)]
pub struct ExperimentArgs {
    /// Experiment to run.
    #[arg(value_enum, default_value = "all")]
    pub which: Which,
    /// Scene file (TOML) for `mss experiment scene`.
    #[arg(required_if_eq("which", "scene"))]
    pub scene: Option<PathBuf>,
    /// `scene`: FEM refinement per lattice cell (an even factor also gives a
    /// Richardson extrapolation from half of it).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=8))]
    pub refine: u32,
    /// `scene`: linear, nonlinear, or chosen from the size of the linear response.
    #[arg(long, value_enum, default_value = "auto")]
    pub regime: RegimeArg,
    /// `scene`: compare all three parameterizations (paper, springs,
    /// volumetric) instead of only the scene's.
    #[arg(long)]
    pub all_models: bool,
    /// Small resolutions and coarser references (seconds instead of minutes).
    #[arg(long)]
    pub quick: bool,
    /// Also write the Markdown report to this path, with image links relative
    /// to it (e.g. `--out docs/experiments --report EXPERIMENTS.md`).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Runs `mss experiment`, writing into `out_dir`; `chatty` shows progress
/// and prints a summary.
pub fn run(
    args: &ExperimentArgs,
    out_dir: &Path,
    chatty: bool,
    limits: mss_scene::limits::Limits,
) -> anyhow::Result<()> {
    let which = match args.which {
        Which::Scene => return run_scene(args, out_dir, chatty, limits),
        Which::Plane => return run_plane(args, out_dir, chatty),
        Which::Beam => Experiment::Beam,
        Which::Lshape => Experiment::Lshape,
        Which::Material => Experiment::Material,
        Which::All => Experiment::All,
    };
    if args.scene.is_some() {
        anyhow::bail!(
            "a scene file is only taken by `mss experiment scene SCENE.toml`, not by `{:?}`",
            args.which
        );
    }
    let settings = SuiteSettings {
        which,
        quick: args.quick,
        link_prefix: args
            .report
            .as_deref()
            .map_or_else(String::new, |rep| relative_link(rep, out_dir)),
    };
    let spinner = Mutex::new(None::<ProgressBar>);
    let outcome = run_suite(&settings, out_dir, &|title| {
        let mut s = spinner.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(old) = s.take() {
            old.finish_and_clear();
        }
        *s = Some(progress::spinner(title, chatty));
    });
    if let Some(old) = spinner.lock().unwrap_or_else(|e| e.into_inner()).take() {
        old.finish_and_clear();
    }
    let outcome = outcome?;
    if let Some(rep) = &args.report {
        report::write_text(rep, &outcome.markdown)?;
    }
    if chatty {
        for line in &outcome.headlines {
            crate::outln!("{line}");
        }
        print_report_line(out_dir, args.report.as_deref(), outcome.seconds)?;
    }
    Ok(())
}

/// `mss experiment 2d`: the 2D element's report.
fn run_plane(args: &ExperimentArgs, out_dir: &Path, chatty: bool) -> anyhow::Result<()> {
    if args.scene.is_some() {
        anyhow::bail!(
            "a scene file is only taken by `mss experiment scene SCENE.toml`, not by `2d`"
        );
    }
    let t0 = Instant::now();
    let spinner = progress::spinner("The 2D element against plane-stress FEM", chatty);
    let md = mss_validate::plane::plane_report(args.quick);
    spinner.finish_and_clear();
    let md = md.context("the 2D experiments failed")?;
    mss_scene::mss_io::atomic::ensure_dir(out_dir)?;
    report::write_text(&out_dir.join("report.md"), &md)?;
    if let Some(rep) = &args.report {
        report::write_text(rep, &md)?;
    }
    if chatty {
        print_report_line(out_dir, args.report.as_deref(), t0.elapsed().as_secs_f64())?;
    }
    Ok(())
}

/// The closing line: where the report is and how long it took.
fn print_report_line(
    out_dir: &Path,
    report: Option<&Path>,
    seconds: f64,
) -> Result<(), crate::StdoutError> {
    crate::outln!(
        "report           {}{} ({seconds:.1} s)",
        out_dir.join("report.md").display(),
        report.map_or_else(String::new, |r| format!(" and {}", r.display())),
    );
    Ok(())
}

/// Link prefix from the report's folder to `out_dir` (both relative to the
/// working directory, or absolute).
fn relative_link(report: &Path, out_dir: &Path) -> String {
    let base = report
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let (b, o) = (abs(base), abs(out_dir));
    match o.strip_prefix(&b) {
        Ok(rel) if rel.as_os_str().is_empty() => String::new(),
        Ok(rel) => format!("{}/", rel.display()),
        Err(_) => format!("{}/", o.display()),
    }
}

/// `mss experiment scene SCENE.toml`: the scene's static equilibrium against
/// the FEM reference, written as `report.md`, `scene_errors.csv` and
/// `scene_MODEL.vtu`.
fn run_scene(
    args: &ExperimentArgs,
    out_dir: &Path,
    chatty: bool,
    limits: mss_scene::limits::Limits,
) -> anyhow::Result<()> {
    let t_all = Instant::now();
    let path = args
        .scene
        .as_deref()
        .context("`mss experiment scene` needs a scene file")?;
    let input = mss_scene::SceneInput::load(Some(path))?;
    let name = input.name();
    let registry = mss_scene::Registry::default();
    let bars = progress::JobBars::new(&name, chatty);
    let job =
        mss_scene::Job::prepare_with_limits(input, registry.clone(), limits, &|p| bars.report(p));
    bars.clear();
    let job = job?;
    let scene = &job.input.scene;
    if job.bodies.len() > 1 {
        anyhow::bail!(
            "{name}: mss experiment compares one body with the FEM; this scene has {} ([[bodies]])",
            job.bodies.len()
        );
    }
    let constraints = scene.bodies()[0].constraint_specs(scene.solver.duration);
    let loads = scene.loads.specs();
    let (material, param) = job.input.material(&registry)?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create the output folder {}", out_dir.display()))?;
    let settings = experiments::SceneSettings {
        refine: args.refine,
        regime: match args.regime {
            RegimeArg::Auto => experiments::RegimeChoice::Auto,
            RegimeArg::Linear => experiments::RegimeChoice::Fixed(Regime::Linear),
            RegimeArg::Nonlinear => experiments::RegimeChoice::Fixed(Regime::Large),
        },
        models: if args.all_models {
            builtin_models(&["paper", "springs", "volumetric"])?
        } else {
            vec![SharedParameterization::from(param)]
        },
    };
    let l = job.lattice();
    log::info!(
        "comparing {name} ({} cells) with Q1 FEM refined {} times",
        l.num_cells(),
        args.refine
    );
    let spinner = progress::spinner("FEM reference and MSS solves", chatty);
    let r = experiments::scene(l, material, &constraints, &loads, &settings);
    spinner.finish_and_clear();
    let r = r.map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let description = SceneDescription {
        name: &name,
        lattice: l,
        material,
        num_constraints: constraints.len(),
        num_loads: loads.len(),
        refine: args.refine,
    };
    let mut md = scene_report(&description, &r, out_dir)?;
    let _ = writeln!(md, "Total time: {:.1} s.", t_all.elapsed().as_secs_f64());
    report::write_text(&out_dir.join("report.md"), &md)?;
    if let Some(rep) = &args.report {
        report::write_text(rep, &md)?;
    }
    for run in r.runs.iter().filter(|_| chatty) {
        crate::outln!(
            "{}: M {:.3} %, SD {:.3} %, MAX {:.3} % ({})",
            run.model,
            run.stats.mean,
            run.stats.sd,
            run.stats.max,
            r.regime.label()
        );
    }
    log::info!("report written to {}", out_dir.join("report.md").display());
    Ok(())
}
