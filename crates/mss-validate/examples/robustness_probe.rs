//! Diagnoses a scene that fails: steps it as `mss run` would, tracing the
//! worst cell (centre Jacobian, deviation from affine), and solves the same
//! lattice, supports and loads statically with the large-strain Q1 FEM
//! (neo-Hookean), the referee of docs/robustness.md.
//!
//! `cargo run --release -p mss-validate --example robustness_probe -- SCENE [--fem] [--model NAME]`

use mss_core::Vec3;
use mss_scene::{Job, Registry, SceneInput, no_progress};
use mss_validate::fem::{Fem, FemConstraints, FemLaw, NewtonOptions};

fn centre_jacobians(model: &mss_core::Model, x: &[Vec3]) -> Vec<f64> {
    model
        .cell_diagnostics(x)
        .iter()
        .map(|d| 1.0 + d.volumetric_strain)
        .collect()
}

/// Per cell, the smallest corner Jacobian: the determinant of the cell's
/// three edge vectors at each corner over h^3 (computed here from the
/// positions, so that any build of the model can be measured the same way).
fn corner_jacobians(model: &mss_core::Model, x: &[Vec3]) -> Vec<f64> {
    let h3 = model.h().powi(3);
    // The corners of a cell (VTK order) and their neighbours along +-x, +-y, +-z,
    // listed so that the three edge vectors point along +x, +y, +z.
    const AT: [[(usize, usize); 3]; 8] = [
        [(0, 1), (0, 3), (0, 4)],
        [(0, 1), (1, 2), (1, 5)],
        [(3, 2), (1, 2), (2, 6)],
        [(3, 2), (0, 3), (3, 7)],
        [(4, 5), (4, 7), (0, 4)],
        [(4, 5), (5, 6), (1, 5)],
        [(7, 6), (5, 6), (2, 6)],
        [(7, 6), (4, 7), (3, 7)],
    ];
    model
        .cells()
        .iter()
        .map(|cell| {
            AT.iter()
                .map(|edges| {
                    let e = edges.map(|(a, b)| x[cell[b] as usize] - x[cell[a] as usize]);
                    e[0].dot(&e[1].cross(&e[2])) / h3
                })
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// "N folded cells (corner J <= 0), lowest corner J v".
fn folded(model: &mss_core::Model, x: &[Vec3]) -> String {
    let cj = corner_jacobians(model, x);
    let n = cj.iter().filter(|&&j| j <= 0.0).count();
    let lowest = cj.iter().cloned().fold(f64::INFINITY, f64::min);
    format!("{n} folded cells (corner J <= 0), lowest corner J {lowest:.3}")
}

struct Stderr;
impl log::Log for Stderr {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, r: &log::Record) {
        if r.level() <= log::max_level() {
            eprintln!("[{}] {}", r.level(), r.args());
        }
    }
    fn flush(&self) {}
}

/// The largest norm of a node vector field.
fn largest(u: &[Vec3]) -> f64 {
    u.iter().map(|v| v.norm()).fold(0.0, f64::max)
}

fn main() {
    let _ = log::set_logger(&Stderr);
    log::set_max_level(if std::env::var_os("PROBE_DEBUG").is_some() {
        log::LevelFilter::Debug
    } else {
        log::LevelFilter::Warn
    });
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = std::path::PathBuf::from(&args[0]);
    let fem = args.iter().any(|a| a == "--fem");
    let mut input = SceneInput::load(Some(&path)).expect("scene");
    if let Some(i) = args.iter().position(|a| a == "--model") {
        input.scene.model.parameterization = args[i + 1].clone();
    }
    if let Some(i) = args.iter().position(|a| a == "--solver") {
        input.scene.solver.kind = args[i + 1].clone();
    }
    let job = Job::prepare(input, Registry::default(), &no_progress).expect("prepare");
    let problem = &job.problem;
    let model = problem.model();
    let h = model.h();
    println!(
        "{} cells, {} nodes, h = {h:.4e} m, model {}, dt {:.3e} s x {} steps",
        model.num_cells(),
        model.num_nodes(),
        model.parameterization_name(),
        job.plan.dt,
        job.plan.steps
    );
    let lat = &job.lattice();
    let neighbours = |c: usize| {
        let [i, j, k] = lat.cell_coords()[c];
        let mut n = 0;
        for (di, dj, dk) in [
            (1i64, 0i64, 0i64),
            (-1, 0, 0),
            (0, 1, 0),
            (0, -1, 0),
            (0, 0, 1),
            (0, 0, -1),
        ] {
            let q = [i as i64 + di, j as i64 + dj, k as i64 + dk];
            if q.iter().all(|&v| v >= 0)
                && lat
                    .cell_at([q[0] as u32, q[1] as u32, q[2] as u32])
                    .is_some()
            {
                n += 1;
            }
        }
        n
    };
    let mut state = mss_core::State::at_rest(model);
    problem.apply_constraints(&mut state);
    let integ = job
        .input
        .integrator(&job.registry, problem, &job.plan)
        .expect("integrator");
    if let Some(mut integ) = integ {
        let every = (job.plan.steps / 40).max(1);
        for k in 1..=job.plan.steps {
            let r = integ.step(problem, &mut state);
            if k % every == 0 || r.is_err() {
                let jac = centre_jacobians(model, &state.x);
                let dev = model.affine_deviation(&state.x);
                let (cj, minj) = jac
                    .iter()
                    .enumerate()
                    .fold((0, f64::MAX), |a, (i, &v)| if v < a.1 { (i, v) } else { a });
                let (cd, maxd) = dev
                    .iter()
                    .enumerate()
                    .fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
                let ke = state.kinetic_energy(model.masses());
                let umax = largest(&state.displacements(model));
                println!(
                    "t {:.4} minJ {minj:.3} (cell {cj} at {:?}, {} nbrs) maxdev {:.2}%h (cell {cd} at {:?}, {} nbrs) KE {ke:.3e} umax {umax:.3e}",
                    state.time,
                    lat.cell_coords()[cj],
                    neighbours(cj),
                    100.0 * maxd,
                    lat.cell_coords()[cd],
                    neighbours(cd)
                );
            }
            if let Err(e) = r {
                println!("FAILED: {e}");
                break;
            }
        }
        println!("end t {:.4}: {}", state.time, folded(model, &state.x));
    } else {
        let r = mss_core::solve_static(problem, &mut state, &Default::default());
        let jac = centre_jacobians(model, &state.x);
        let minj = jac.iter().cloned().fold(f64::MAX, f64::min);
        let dev = model.affine_deviation(&state.x);
        let maxd = dev.iter().cloned().fold(0.0, f64::max);
        let umax = largest(&state.displacements(model));
        println!(
            "static: {:?}; minJ {minj:.3} maxdev {:.2}%h umax {umax:.4e}",
            r.map(|i| i.newton_iterations),
            100.0 * maxd
        );
    }
    if let Some(i) = args.iter().position(|a| a == "--fem-r") {
        let r: u32 = args[i + 1].parse().unwrap();
        let f = Fem::new(lat, r, *model.materials().first().unwrap()).expect("fem");
        let fl = f.lattice();
        let zmin = fl.nodes().iter().map(|p| p[2]).fold(f64::MAX, f64::min);
        let bc = f.clamp_where(|p| p[2] <= zmin + 1e-9 * h);
        let load = f.gravity_load(Vec3::new(0.0, 0.0, -9.81));
        match f.solve(FemLaw::NeoHookean, &bc, &load, &NewtonOptions::default()) {
            Ok(s) => {
                let x: Vec<Vec3> = fl
                    .nodes()
                    .iter()
                    .zip(&s.displacement)
                    .map(|(r, u)| Vec3::from(*r) + u)
                    .collect();
                // A model on the refined lattice measures its cells the same way.
                let fine = mss_core::Model::new(
                    fl,
                    *model.materials().first().unwrap(),
                    &mss_core::SpringsOnly,
                )
                .expect("model of the refined lattice");
                let minj = centre_jacobians(&fine, &x)
                    .into_iter()
                    .fold(f64::MAX, f64::min);
                let umax = largest(&s.displacement);
                println!(
                    "FEM r={r} NeoHookean: {} load steps, minJ {minj:.3} umax {umax:.4e}",
                    s.load_steps
                );
            }
            Err(e) => println!("FEM r={r} failed: {e}"),
        }
    }
    if fem {
        let f = Fem::new(lat, 1, *model.materials().first().unwrap()).expect("fem");
        let mut bc = FemConstraints::new(model.num_nodes());
        for n in 0..model.num_nodes() {
            for d in 0..3 {
                if problem.constraints().is_held(n, d) {
                    bc.fix(n as u32, d, 0.0).unwrap();
                }
            }
        }
        let rest = model.rest_positions().to_vec();
        let mut load = vec![Vec3::zeros(); model.num_nodes()];
        problem.external_forces(job.plan.dt * job.plan.steps as f64, &rest, 1.0, &mut load);
        for law in [FemLaw::NeoHookean, FemLaw::StVenantKirchhoff] {
            match f.solve(law, &bc, &load, &NewtonOptions::default()) {
                Ok(s) => {
                    let x: Vec<Vec3> = rest
                        .iter()
                        .zip(&s.displacement)
                        .map(|(r, u)| r + u)
                        .collect();
                    let jac = centre_jacobians(model, &x);
                    let minj = jac.iter().cloned().fold(f64::MAX, f64::min);
                    let dev = model.affine_deviation(&x);
                    let maxd = dev.iter().cloned().fold(0.0, f64::max);
                    let umax = s.displacement.iter().map(|u| u.norm()).fold(0.0, f64::max);
                    let mss_u = state.displacements(model);
                    let diff = largest(
                        &mss_u
                            .iter()
                            .zip(&s.displacement)
                            .map(|(a, b)| a - b)
                            .collect::<Vec<_>>(),
                    );
                    println!(
                        "FEM {law:?}: {} load steps, minJ {minj:.3} maxdev {:.2}%h umax {umax:.4e}; {}; \
                         largest |u_mss - u_fem| {diff:.4e} ({:.1} % of the FEM's max)",
                        s.load_steps,
                        100.0 * maxd,
                        folded(model, &x),
                        100.0 * diff / umax
                    );
                }
                Err(e) => println!("FEM {law:?} failed: {e}"),
            }
        }
    }
}
