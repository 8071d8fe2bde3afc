//! `mss check`: validates a scene and prints its size and cost estimates,
//! without simulating or writing anything.

use std::path::PathBuf;

use clap::Args;
use mss_io::scene::SolverKind;

use crate::commands::run::prepare;
use crate::output::{FrameCounts, frame_size_estimate};
use crate::progress::human_bytes;
use crate::{GlobalArgs, setup};

/// Arguments of `mss check`.
#[derive(Debug, Clone, Args)]
pub struct CheckArgs {
    /// Scene file (TOML); without it, the bundled default scene.
    #[arg(value_name = "SCENE")]
    pub scene: Option<PathBuf>,
}

/// Estimated memory of a run (bytes): the model, the state and the solver's
/// work arrays; implicit and static solves add a sparse 3x3-block matrix
/// (27 blocks per node row) and its solver's copies.
pub fn memory_estimate(model_bytes: usize, nodes: usize, kind: SolverKind) -> u64 {
    let vec3 = 24;
    let explicit = nodes * vec3 * 8;
    let matrix = nodes * 27 * (72 + 4);
    let extra = match kind {
        SolverKind::Explicit => 0,
        SolverKind::Implicit | SolverKind::Static => 3 * matrix + nodes * vec3 * 8,
    };
    (model_bytes + explicit + extra) as u64
}

/// Runs `mss check`.
pub fn run(args: &CheckArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    let input = setup::load_scene(args.scene.as_deref())?;
    let name = input.name();
    let p = prepare(input, global.chatty())?;
    let scene = &p.input.scene;
    let model = p.problem.model();
    let plan = p.plan;
    let skin = hexmesh::boundary_skin(&p.lattice);
    let frame = frame_size_estimate(
        &scene.output,
        &FrameCounts {
            nodes: model.num_nodes(),
            cells: model.num_cells(),
            springs: model.num_springs(),
            skin_vertices: skin.vertex_nodes.len(),
            skin_triangles: skin.triangles.len(),
            surface_vertices: p.mesh.vertices.len(),
            surface_triangles: p.mesh.triangles.len(),
        },
    );
    let frames = plan.num_frames();
    let held: usize = (0..model.num_nodes())
        .filter(|&n| p.problem.constraints().mask(n).iter().any(|&h| h))
        .count();
    let memory = memory_estimate(model.memory_bytes(), model.num_nodes(), plan.kind);
    let out_dir = setup::output_folder(scene, global.out.as_deref());
    let mechanism = mechanism_warning(&p);
    if !global.chatty() {
        if let Some(w) = &mechanism {
            log::warn!("{w}");
        }
        return Ok(());
    }
    println!("scene            {name}: OK");
    println!(
        "mesh             {}: {} vertices, {} triangles",
        p.mesh_name,
        p.mesh.vertices.len(),
        p.mesh.triangles.len()
    );
    println!(
        "lattice          {} cells, {} nodes, {} springs, cell size {:.4} m",
        model.num_cells(),
        model.num_nodes(),
        model.num_springs(),
        model.h()
    );
    let m = &scene.material;
    let hourglass = model.cell_coefficients(0).hourglass;
    println!(
        "material         E = {} Pa, nu = {}, density = {} kg/m^3, model \"{}\"{}",
        m.young,
        m.poisson,
        m.density,
        model.parameterization_name(),
        if hourglass > 0.0 {
            format!(" (hourglass stiffness {hourglass:.4e} N/m per cell)")
        } else {
            String::new()
        }
    );
    println!("mass             {:.4} kg", model.total_mass());
    println!("held nodes       {held}");
    println!(
        "stable time step {:.3e} s (critical {:.3e} s, safety {}, damping included)",
        plan.stable_dt,
        model.critical_time_step(),
        scene.solver.safety
    );
    println!(
        "time stepping    {:?}, dt = {:.3e} s, {} steps for {} s",
        plan.kind, plan.dt, plan.steps, scene.solver.duration
    );
    println!("memory estimate  {}", human_bytes(memory));
    println!(
        "output estimate  {} frames x {} = {} in {}",
        frames,
        human_bytes(frame),
        human_bytes(frame.saturating_mul(frames)),
        out_dir.display()
    );
    match &mechanism {
        Some(w) => println!("warning          {w}"),
        None => println!("mechanisms       none expected"),
    }
    Ok(())
}

/// Largest model (nodes) on which `mss run` counts zero-energy modes before
/// starting; `mss check` always counts them.
pub const RUN_MODE_CHECK_MAX_NODES: usize = 20_000;

/// A warning if the boundary conditions leave zero-energy motions (rigid
/// motions or hourglass mechanisms) that the loads can excite: counted on the
/// rest stiffness restricted to the free dofs (mss_core::modes).
pub fn mechanism_warning(p: &crate::commands::run::Prepared) -> Option<String> {
    let c = p.problem.constraints();
    let model = p.problem.model();
    let restrained = !p.input.scene.loads.drags.is_empty();
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
