//! The interactive benchmark of the contact issue: a body of about 10,000
//! cells on the ground, dragged by a picked node at 60 frames per second;
//! prints the frame time (with its explicit sub-steps) on the threads rayon
//! is given (`RAYON_NUM_THREADS=1` for one).
//!
//!     cargo run --release -p mss-core --example interactive [CELLS_PER_SIDE] [YOUNG] [f64|f32]

use std::time::Instant;

mod common;
use common::cpu_seconds;

use mss_core::contact::{Contact, ContactSettings, Plane};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::simulation::Simulation;
use mss_core::solver::Problem;
use mss_core::{Material, Model, Precision, Vec3};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u32 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(22);
    let young: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2.0e4);
    let precision = args
        .get(3)
        .map(|a| Precision::from_name(a).expect("precision: f64 or f32"))
        .unwrap_or_default();
    let side = 0.2;
    let h = side / n as f64;
    let lattice = hexmesh::Lattice::block([n, n, n], h, [0.0; 3]).expect("block");
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("hg");
    let model = Model::new(
        &lattice,
        Material::new(young, 0.3, 1000.0).expect("material"),
        &param,
    )
    .expect("model");
    let cells = model.num_cells();
    let settings = ContactSettings::for_model(&model);
    let ground = Plane::new(Vec3::zeros(), Vec3::z()).expect("plane");
    let contact = Contact::new(&model, vec![(Box::new(ground), settings)]);
    let problem = Problem::from_specs(
        model,
        &[],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping {
            alpha: 5.0,
            beta: 0.0,
        },
    )
    .expect("problem")
    .with_contact(contact);
    let limit = mss_core::solver::explicit_time_step_limit(&problem, 0.9);
    let model_limit = 0.9 * problem.model().critical_time_step();
    println!("stable step {limit:.3e} s (the lattice alone: {model_limit:.3e} s)");
    let mut sim = Simulation::new(problem).expect("simulation");
    sim.set_precision(precision);
    let corner = sim.nearest_node(Vec3::new(side, side / 2.0, side));
    sim.pick(&[corner], 5.0).expect("pick");
    let start = sim.positions()[corner as usize];
    let frame = 1.0 / 60.0;
    let mut times = Vec::new();
    let mut substeps = 0;
    let frames = 120;
    let cpu_start = cpu_seconds();
    for k in 0..frames {
        let phase = k as f64 * frame * std::f64::consts::TAU * 0.5;
        sim.drag_to(start + Vec3::new(0.03 * phase.sin(), 0.0, 0.02));
        let t = Instant::now();
        let info = sim.step(frame).expect("step");
        times.push(t.elapsed().as_secs_f64() * 1e3);
        if std::env::var_os("FRAMES").is_some() {
            eprintln!(
                "frame {k}: {:.1} ms, {} sub-steps",
                times[k as usize], info.substeps
            );
        }
        substeps = info.substeps;
    }
    let cpu_per_frame = (cpu_seconds() - cpu_start) / f64::from(frames) * 1e3;
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!(
        "{cells} cells, E = {young} Pa, {} threads, {}: frame of 1/60 s in {substeps} sub-steps; \
         frame time mean {mean:.1} ms, median {:.1} ms, max {:.1} ms; CPU {cpu_per_frame:.1} ms per frame (target 16 ms)",
        rayon::current_num_threads(),
        precision.name(),
        times[times.len() / 2],
        times[times.len() - 1]
    );
}
