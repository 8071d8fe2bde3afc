//! The haptic benchmark of the speed issue: a 1,000-cell soft block held at
//! its base, pressed by a sphere that a hand moves every frame, one frame
//! per millisecond of simulated time (a haptic device's 1 kHz loop). Prints
//! the frame time over 10,000 frames: mean, median, 99th percentile and the
//! worst, and the process's CPU time per frame, on the threads rayon is
//! given (`RAYON_NUM_THREADS=1` for one). With `FRAMES` set, frames over
//! 2 ms are listed with their sub-steps.
//!
//!     cargo run --release -p mss-core --example haptic [CELLS_PER_SIDE] [YOUNG] [f64|f32] [FRAMES]

use std::time::Instant;

mod common;
use common::cpu_seconds;

use mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_core::contact::{Contact, ContactSettings, Sphere, Steered};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::simulation::Simulation;
use mss_core::solver::Problem;
use mss_core::{Material, Model, Precision, Vec3};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u32 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10);
    let young: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(1.0e4);
    let precision = args
        .get(3)
        .map(|a| Precision::from_name(a).expect("precision: f64 or f32"))
        .unwrap_or_default();
    let frames: usize = args.get(4).and_then(|a| a.parse().ok()).unwrap_or(10_000);
    // Tissue-like: a 5 cm block of 5 mm cells, E = 10 kPa, nearly incompressible.
    let side = 0.05;
    let h = side / f64::from(n);
    let lattice = hexmesh::Lattice::block([n, n, n], h, [0.0; 3]).expect("block");
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("hg");
    let model = Model::new(
        &lattice,
        Material::new(young, 0.45, 1000.0).expect("material"),
        &param,
    )
    .expect("model");
    let cells = model.num_cells();
    let settings = ContactSettings::for_model(&model);
    let radius = 0.01;
    let start = Vec3::new(side / 2.0, side / 2.0, side + radius);
    let (tool, hand) = Steered::new(Box::new(Sphere::new(start, radius).expect("sphere")));
    let contact = Contact::new(&model, vec![(Box::new(tool), settings)]);
    let problem = Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::LowestLayer)],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping {
            alpha: 10.0,
            beta: 0.0,
        },
    )
    .expect("problem")
    .with_contact(contact);
    let mut sim = Simulation::new(problem).expect("simulation");
    sim.set_precision(precision);
    let frame = 1.0e-3;
    let mut times = Vec::with_capacity(frames);
    let mut substeps = 0;
    let cpu_start = cpu_seconds();
    for k in 0..frames {
        // The hand presses 5 mm in and circles at 2 Hz.
        let t = k as f64 * frame;
        let phase = std::f64::consts::TAU * 2.0 * t;
        let depth = 0.005 * (1.0 - (-(t / 0.2)).exp());
        hand.move_to(
            Vec3::new(0.01 * phase.cos(), 0.01 * phase.sin(), -depth),
            frame,
        );
        let clock = Instant::now();
        let info = sim.step(frame).expect("step");
        times.push(clock.elapsed().as_secs_f64() * 1e3);
        if std::env::var_os("FRAMES").is_some() && times[k] > 2.0 {
            eprintln!("frame {k}: {:.3} ms, {} sub-steps", times[k], info.substeps);
        }
        substeps = substeps.max(info.substeps);
    }
    let cpu_per_frame = (cpu_seconds() - cpu_start) / frames as f64 * 1e3;
    // The first frame builds the integrator (the stable step's estimate,
    // the contact search's structures): reported apart from the loop's.
    let first = times.remove(0);
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    let pct = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    println!(
        "{cells} cells, E = {young} Pa, {} thread(s), {}: {frames} frames of 1 ms (at most {substeps} \
         sub-steps); frame time mean {mean:.3} ms, median {:.3} ms, 99th percentile {:.3} ms, \
         worst {:.3} ms (the first frame, which sets up the integrator: {first:.3} ms); \
         CPU {cpu_per_frame:.3} ms per frame (target 1 ms)",
        rayon::current_num_threads(),
        precision.name(),
        pct(0.5),
        pct(0.99),
        times[times.len() - 1],
    );
}
