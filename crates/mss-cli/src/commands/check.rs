//! `mss check`: validates a scene and prints its size and cost estimates,
//! without simulating or writing anything.

use std::path::PathBuf;

use clap::Args;
use mss_scene::check::CheckReport;

use crate::GlobalArgs;
use crate::progress::{JobBars, human_bytes};

/// Arguments of `mss check`.
#[derive(Debug, Clone, Args)]
pub struct CheckArgs {
    /// Scene file (TOML); without it, the bundled default scene.
    #[arg(value_name = "SCENE")]
    pub scene: Option<PathBuf>,
}

/// Runs `mss check`.
pub fn run(args: &CheckArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let label = args
        .scene
        .as_ref()
        .map_or("the bundled critter".to_owned(), |p| {
            p.display().to_string()
        });
    let bars = JobBars::new(&label, global.chatty());
    // The same preparation as `mss run`: whatever it refuses, check refuses.
    let input = super::run::load_input(args.scene.as_deref(), None)?;
    if input.scene.is_plane() {
        return check_plane(input, global);
    }
    let job = super::run::prepare_input(input, global.limits(), &bars)?;
    let cancel = mss_scene::Cancel::new();
    super::run::interrupt_on_signals(&cancel)?;
    let report = CheckReport::new_cancellable(&job, &cancel.flag());
    if cancel.is_cancelled() {
        anyhow::bail!(
            "{}: mss check interrupted before its checks finished (nothing was written)",
            job.input.name()
        );
    }
    let scene = &job.input.scene;
    let model = job.problem.model();
    let plan = job.plan;
    let out_dir = mss_scene::build::output_folder(scene, global.out.as_deref());
    if !global.chatty() {
        if let Some(w) = &report.mechanism_warning {
            log::warn!("{w}");
        }
        if let Some(w) = report.load_check.warning() {
            log::warn!("{w}");
        }
        return Ok(());
    }
    crate::outln!("scene            {}: OK", job.input.name());
    let views = scene.bodies();
    let several = job.bodies.len() > 1;
    for ((body, view), span) in job.bodies.iter().zip(&views).zip(model.bodies()) {
        if several {
            crate::outln!(
                "body             {}: {} cells, {} nodes, {:.4} kg",
                body.name,
                span.cells.len(),
                span.nodes.len(),
                model.masses()[span.nodes.clone()].iter().sum::<f64>()
            );
        }
        print_body(body, view, span, &report)?;
    }
    if several {
        crate::outln!(
            "lattices         {} cells, {} nodes, {} springs in all",
            model.num_cells(),
            model.num_nodes(),
            model.num_springs()
        );
    }
    crate::outln!("mass             {:.4} kg", model.total_mass());
    crate::outln!("held nodes       {}", report.held_nodes);
    crate::outln!(
        "stable time step {:.3e} s (critical {:.3e} s, safety {}, damping included)",
        plan.stable_dt,
        model.critical_time_step(),
        scene.solver.safety
    );
    crate::outln!(
        "time stepping    {}, dt = {:.3e} s, {} steps for {} s",
        scene.solver.kind,
        plan.dt,
        plan.steps,
        scene.solver.duration
    );
    crate::outln!(
        "memory estimate  {} (limit {})",
        human_bytes(report.memory_bytes),
        human_bytes(job.limits.memory_bytes)
    );
    match &report.time_estimate {
        Some(t) if t.probe_steps > 0 => {
            let mut parts = vec![format!(
                "{:.3e} s per step, timed on {} steps",
                t.seconds_per_step, t.probe_steps
            )];
            if let Some(p) = &t.pilot {
                parts.push(format!(
                    "{}{:.1} times that per step in a pilot run{}",
                    if report.body_folds() {
                        "the body folds: "
                    } else {
                        ""
                    },
                    p.time_ratio,
                    if p.simulated_fraction < 1.0 {
                        format!(
                            " of the first {:.0} %, the rest projected",
                            100.0 * p.simulated_fraction
                        )
                    } else {
                        String::new()
                    }
                ));
            }
            if t.load_check_seconds > 0.0 {
                parts.push(format!(
                    "its load check {}",
                    human_seconds(t.load_check_seconds)
                ));
            }
            parts.push(format!("writing {}", human_seconds(t.writing_seconds)));
            crate::outln!(
                "time estimate    {}{} ({}){}",
                if report.time_is_lower_bound() {
                    "at least "
                } else {
                    ""
                },
                human_seconds(t.seconds),
                parts.join("; "),
                if report.time_is_lower_bound() {
                    "; the body does not carry its load statically, and a run's steps shrink \
                     as it folds: it may take several times longer"
                } else {
                    ""
                }
            )
        }
        Some(t) => crate::outln!(
            "time estimate    {} (the static solve took {}; writing {})",
            human_seconds(t.seconds),
            human_seconds(t.seconds_per_step),
            human_seconds(t.writing_seconds)
        ),
        None => crate::outln!("time estimate    not estimated (a probe step would cost too much)"),
    }
    let (free, disk_warning) = report.disk(&out_dir);
    crate::outln!(
        "output estimate  {} frames x {} = {} in {}{}",
        report.frames,
        human_bytes(report.frame_bytes),
        human_bytes(report.frame_bytes.saturating_mul(report.frames)),
        out_dir.display(),
        free.map_or_else(String::new, |f| format!(" ({} free)", human_bytes(f)))
    );
    if let Some(w) = &disk_warning {
        crate::outln!("warning          {w}");
    }
    match &report.mechanism_warning {
        Some(w) => crate::outln!("warning          {w}"),
        None => crate::outln!("mechanisms       none expected"),
    }
    crate::outln!("under load       {}", report.load_check.describe());
    if let Some(w) = report.load_check.warning() {
        crate::outln!("warning          {w}");
    }
    Ok(())
}

/// Seconds as "0.42 s", "12 s", "3.5 min" or "2.1 h".
fn human_seconds(s: f64) -> String {
    if s < 10.0 {
        format!("{s:.2} s")
    } else if s < 120.0 {
        format!("{s:.0} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

/// `mss check` of a 2D scene: what the run would build and its step.
fn check_plane(input: mss_scene::SceneInput, global: &GlobalArgs) -> anyhow::Result<()> {
    let job = mss_scene::plane_job::PlaneJob::prepare(input)?;
    if !global.chatty() {
        return Ok(());
    }
    let p = &job.problem;
    let [lx, ly] = job.lattice.cell_size();
    crate::outln!(
        "scene            {}: OK (2D, plane stress)",
        job.input.name()
    );
    crate::outln!(
        "outline          {}: {} polygons, area {:.4e} m^2",
        job.outline_name,
        job.outline.polygons().len(),
        job.outline.area()
    );
    crate::outln!(
        "lattice          {} cells of {} x {}, {} nodes, area {:.4e} m^2",
        job.lattice.num_cells(),
        crate::progress::human_length(lx),
        crate::progress::human_length(ly),
        job.lattice.num_nodes(),
        job.lattice.area()
    );
    let c = p.model.coefficients();
    crate::outln!(
        "model            {:?}, springs k_l {:.4e}, k_h {:.4e}, k_d {:.4e} N/m{}",
        p.model.parameterization(),
        c.k_l,
        c.k_h,
        c.k_d,
        if c.k_l < 0.0 || c.k_h < 0.0 {
            " (a negative edge spring: the cells are elongated; hourglass control keeps bending stable)"
        } else {
            ""
        }
    );
    crate::outln!(
        "mass             {:.4e} kg, {} held nodes",
        p.model.total_mass(),
        p.held.iter().filter(|h| h[0] || h[1]).count()
    );
    if job.input.scene.solver.is_static() {
        crate::outln!("time stepping    static");
    } else {
        crate::outln!(
            "time stepping    {}, dt = {:.3e} s, {} steps",
            job.input.scene.solver.kind,
            job.dt,
            job.steps
        );
    }
    Ok(())
}

/// The mesh, lattice, material and regions lines of one body.
fn print_body(
    body: &mss_scene::job::JobBody,
    view: &mss_scene::scene::BodyView<'_>,
    span: &mss_scene::mss_core::BodySpan,
    report: &CheckReport,
) -> anyhow::Result<()> {
    let [ex, ey, ez] = body.mesh.bounding_box().map_or([0.0; 3], |b| b.extent());
    match &body.cell_labels {
        None => crate::outln!(
            "mesh             {}: {} vertices, {} triangles, {ex:.4} x {ey:.4} x {ez:.4} m \
             (placement: {})",
            body.mesh_name,
            body.mesh.vertices.len(),
            body.mesh.triangles.len(),
            body.placement
        ),
        Some(labels) => {
            let mut per_label = std::collections::BTreeMap::new();
            for &l in labels {
                *per_label.entry(l).or_insert(0usize) += 1;
            }
            crate::outln!(
                "image            {}: labels' surface {ex:.4} x {ey:.4} x {ez:.4} m, volume \
                 {:.4e} m^3; cells per label {:?} (placement: {})",
                body.mesh_name,
                body.vox_stats.mesh_volume,
                per_label.into_iter().collect::<Vec<_>>(),
                body.placement
            )
        }
    }
    crate::outln!(
        "lattice          {} cells, {} nodes, cell size {}",
        span.cells.len(),
        span.nodes.len(),
        crate::progress::human_length(span.h)
    );
    let m = &view.material;
    crate::outln!(
        "material         E = {} Pa, nu = {}, density = {} kg/m^3, model \"{}\"{}",
        m.young,
        m.poisson,
        m.density,
        span.parameterization,
        if report.hourglass_stiffness > 0.0 {
            format!(
                " (hourglass stiffness {:.4e} N/m per cell)",
                report.hourglass_stiffness
            )
        } else {
            String::new()
        }
    );
    if let Some(a) = &body.regions {
        let cells = a.cells_per_material();
        for (k, m) in a.materials.iter().enumerate().skip(1) {
            crate::outln!(
                "region #{k:<8} E = {} Pa, nu = {}, density = {} kg/m^3: {} cells ({} selected)",
                m.young,
                m.poisson,
                m.density,
                cells[k],
                a.selected[k - 1]
            );
        }
        crate::outln!("[material]       {} cells", cells[0]);
    }
    Ok(())
}
