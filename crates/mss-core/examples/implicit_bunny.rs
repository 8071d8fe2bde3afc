//! One implicit (backward Euler) step of the Stanford bunny sagging under
//! gravity: `cargo run --release -p mss-core --example implicit_bunny -- CELLS [auto|direct|iterative] [MODEL] [STEPS]`.
//!
//! The bunny (`data/meshes/bunny.obj`, about 10 units tall, y up) is scaled
//! to 0.2 m and turned z up, voxelized with CELLS cells along its longest
//! axis; E = 10 kPa, nu = 0.45, rho = 1000 kg/m^3, MODEL (default the
//! volumetric model with hourglass control), the lowest layer held, dt = 0.01 s. Prints the CPU time
//! of the step (this process, user + system), its Newton and Krylov
//! iterations, the largest displacement and the peak memory. With STEPS
//! (default 1), that many steps (the bunny sagging and swinging), and the
//! CPU time per step after the first.

use std::time::Instant;

mod common;
use common::{cpu_seconds, peak_mib};

use mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::solver::{Implicit, ImplicitOptions, Integrator, LinearSolverKind, Problem, State};
use mss_core::{Material, Model, Parameterizations};

fn main() {
    let mut args = std::env::args().skip(1);
    let cells: u32 = args.next().and_then(|s| s.parse().ok()).unwrap_or(32);
    let kind = match args.next().as_deref() {
        Some("direct") => LinearSolverKind::Direct,
        Some("iterative") => LinearSolverKind::Iterative,
        _ => LinearSolverKind::Auto,
    };
    let name = args.next().unwrap_or_else(|| "volumetric+hg".into());
    let steps: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(1);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/meshes/bunny.obj");
    let mut mesh = hexmesh::load_mesh(&path).expect("the bunny").mesh;
    let b = mesh.bounding_box().expect("vertices");
    let scale = 0.2 / b.extent().iter().copied().fold(0.0, f64::max);
    for v in &mut mesh.vertices {
        // y up -> z up, scaled to 0.2 m.
        *v = [v[0] * scale, -v[2] * scale, v[1] * scale];
    }
    let opts = hexmesh::VoxelizeOptions {
        resolution: hexmesh::voxelize::Resolution::CellsAlongLongestAxis(cells),
        ..hexmesh::VoxelizeOptions::default()
    };
    let lattice = hexmesh::voxelize(&mesh, &opts).expect("voxelize").lattice;
    let param = Parameterizations::default()
        .get(&name)
        .expect("a model name");
    let model = Model::new(
        &lattice,
        Material::new(1e4, 0.45, 1000.0).unwrap(),
        param.as_ref(),
    )
    .unwrap();
    let problem = Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::LowestLayer)],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping::NONE,
    )
    .unwrap();
    let nodes = problem.model().num_nodes();
    let mut integrator = Implicit::new(
        &problem,
        ImplicitOptions {
            dt: 0.01,
            linear_solver: kind,
            ..ImplicitOptions::default()
        },
    )
    .unwrap();
    let mut state = State::at_rest(problem.model());
    let (c0, t0) = (cpu_seconds(), Instant::now());
    let info = integrator.step(&problem, &mut state).unwrap();
    let (cpu, wall) = (cpu_seconds() - c0, t0.elapsed().as_secs_f64());
    let (first_newton, first_krylov) = (
        info.newton_iterations,
        integrator.linear_stats().krylov_iterations,
    );
    if steps > 1 {
        let c1 = cpu_seconds();
        for _ in 1..steps {
            integrator.step(&problem, &mut state).unwrap();
        }
        let later = cpu_seconds() - c1;
        let stats = integrator.linear_stats();
        println!(
            "bunny {cells} cells: {} more steps: cpu {:.3} s per step, {:.1} Krylov iterations per step, {} hierarchy set-ups in all",
            steps - 1,
            later / (steps - 1) as f64,
            f64::from(stats.krylov_iterations - first_krylov) / (steps - 1) as f64,
            stats.hierarchy_builds,
        );
    }
    println!(
        "bunny {cells} cells ({} cells, {nodes} nodes, {name}, {kind:?}): one implicit step of 0.01 s: cpu {cpu:.2} s, wall {wall:.2} s, {} Newton iterations, {} Krylov iterations, largest displacement {:.9e} m, peak {:.0} MiB",
        lattice.num_cells(),
        first_newton,
        first_krylov,
        state
            .displacements(problem.model())
            .iter()
            .map(|u| u.norm())
            .fold(0.0, f64::max),
        peak_mib()
    );
}
