//! The frame benchmarks of the speed issue, shared by the `interactive` and
//! `haptic` examples and the one-run table of `explicit_speed`: a body
//! stepped frame by frame through [`Simulation`], as a viewer or a haptic
//! loop drives it.

use std::time::Instant;

use mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_core::contact::{Contact, ContactSettings, Plane, Sphere, Steered};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::simulation::Simulation;
use mss_core::solver::Problem;
use mss_core::{Material, Model, Precision, Vec3};

/// The frame examples' arguments `[CELLS_PER_SIDE] [YOUNG] [f64|f32]`, with
/// their defaults, and the rest of the command line.
pub fn args(cells: u32, young: f64) -> (u32, f64, Precision, Vec<String>) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n = args.first().and_then(|a| a.parse().ok()).unwrap_or(cells);
    let young = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(young);
    let precision = args
        .get(2)
        .map(|a| Precision::from_name(a).expect("precision: f64 or f32"))
        .unwrap_or_default();
    (n, young, precision, args.into_iter().skip(3).collect())
}

/// CPU time of this process (s), to the nanosecond.
fn process_cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

/// What a frame benchmark measured (times in ms).
#[derive(Debug, Clone, Copy)]
pub struct FrameStats {
    /// Cells of the body.
    pub cells: usize,
    /// Most sub-steps a frame took.
    pub substeps: u32,
    /// The first frame's wall time, which builds the integrator (the stable
    /// step's estimate, the contact search's structures).
    pub first: f64,
    /// Mean, median, 99th percentile and worst wall time of the others.
    pub mean: f64,
    pub median: f64,
    pub p99: f64,
    pub worst: f64,
    /// CPU time of the process per frame, the first included.
    pub cpu_per_frame: f64,
    /// CPU time of the process per frame after the first (the rate a
    /// running simulation keeps, without the integrator's set-up).
    pub cpu_per_later_frame: f64,
}

/// Steps `sim` for `frames` frames of `frame` seconds, calling `before`
/// with the frame's index first (to move a drag or a tool); with `FRAMES`
/// set, frames over `slow` ms are listed with their sub-steps.
fn measure(
    sim: &mut Simulation,
    frames: usize,
    frame: f64,
    slow: f64,
    mut before: impl FnMut(&mut Simulation, usize),
) -> FrameStats {
    let mut times = Vec::with_capacity(frames);
    let mut substeps = 0;
    let cpu_start = process_cpu_seconds();
    let mut cpu_after_first = cpu_start;
    for k in 0..frames {
        if k == 1 {
            cpu_after_first = process_cpu_seconds();
        }
        before(sim, k);
        let clock = Instant::now();
        let info = sim.step(frame).expect("step");
        times.push(clock.elapsed().as_secs_f64() * 1e3);
        if std::env::var_os("FRAMES").is_some() && times[k] > slow {
            eprintln!("frame {k}: {:.3} ms, {} sub-steps", times[k], info.substeps);
        }
        substeps = substeps.max(info.substeps);
    }
    let cpu_end = process_cpu_seconds();
    let cpu_per_frame = (cpu_end - cpu_start) / frames as f64 * 1e3;
    let cpu_per_later_frame = (cpu_end - cpu_after_first) / (frames - 1).max(1) as f64 * 1e3;
    let first = times.remove(0);
    times.sort_by(f64::total_cmp);
    let pct = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    FrameStats {
        cells: sim.problem().model().num_cells(),
        substeps,
        first,
        mean: times.iter().sum::<f64>() / times.len() as f64,
        median: pct(0.5),
        p99: pct(0.99),
        worst: times[times.len() - 1],
        cpu_per_frame,
        cpu_per_later_frame,
    }
}

/// A cube of `n`^3 cells and `side` metres with the default model
/// (`volumetric-barrier+hg`), E = `young`, Poisson's ratio `nu`, water's
/// density.
fn default_block(n: u32, side: f64, young: f64, nu: f64) -> Model {
    let lattice = hexmesh::Lattice::block([n, n, n], side / f64::from(n), [0.0; 3]).expect("block");
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("hg");
    let material = Material::new(young, nu, 1000.0).expect("material");
    Model::new(&lattice, material, &param).expect("model")
}

/// The interactive benchmark: a cube of `n`^3 cells (0.2 m, the default
/// model, E = `young`) on the ground, a corner node dragged back and forth
/// at 60 frames per second of simulated time.
pub fn interactive(n: u32, young: f64, precision: Precision, frames: usize) -> FrameStats {
    let side = 0.2;
    let model = default_block(n, side, young, 0.3);
    let settings = ContactSettings::for_model(&model);
    let ground = Plane::new(Vec3::zeros(), Vec3::z()).expect("plane");
    let contact = Contact::new(&model, vec![(Box::new(ground), settings)]);
    let gravity = LoadSpec::Gravity {
        g: [0.0, 0.0, -9.81],
    };
    let damping = Damping {
        alpha: 5.0,
        beta: 0.0,
    };
    let problem = Problem::from_specs(model, &[], &[gravity], damping)
        .expect("problem")
        .with_contact(contact);
    let mut sim = Simulation::new(problem).expect("simulation");
    sim.set_precision(precision);
    let corner = sim.nearest_node(Vec3::new(side, side / 2.0, side));
    sim.pick(&[corner], 5.0).expect("pick");
    let start = sim.positions()[corner as usize];
    let frame = 1.0 / 60.0;
    measure(&mut sim, frames, frame, 2.0 * frame * 1e3, |sim, k| {
        let phase = k as f64 * frame * std::f64::consts::TAU * 0.5;
        sim.drag_to(start + Vec3::new(0.03 * phase.sin(), 0.0, 0.02));
    })
}

/// The haptic benchmark: a 5 cm block of `n`^3 cells (the default model,
/// E = `young`, nu = 0.45) held at its base, pressed 5 mm deep by a 1 cm
/// sphere that a hand circles at 2 Hz, one frame per millisecond.
pub fn haptic(n: u32, young: f64, precision: Precision, frames: usize) -> FrameStats {
    let side = 0.05;
    let model = default_block(n, side, young, 0.45);
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
    measure(&mut sim, frames, frame, 2.0, |_, k| {
        let t = k as f64 * frame;
        let phase = std::f64::consts::TAU * 2.0 * t;
        let depth = 0.005 * (1.0 - (-(t / 0.2)).exp());
        hand.move_to(
            Vec3::new(0.01 * phase.cos(), 0.01 * phase.sin(), -depth),
            frame,
        );
    })
}
