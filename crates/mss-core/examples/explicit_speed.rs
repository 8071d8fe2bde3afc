//! The explicit step's speed against a naive springs-only kernel, measured
//! in one run on the same lattice (issue: explicit step at the memory
//! bandwidth limit).
//!
//!     cargo run --release -p mss-core --example explicit_speed [CELLS_PER_SIDE] [REPEATS]
//!
//! For each model, in f64 and in f32: the force pass alone and a whole explicit step (velocity
//! Verlet at the stable step, one sub-step), on 1 and 2 threads, as the
//! minimum over REPEATS timings (noise only adds time; CPU time on one
//! thread, wall time on two), with the ratio to
//! the baseline timed beside it (each model's timings alternate with the
//! baseline's): a merged-spring scatter loop (each lattice edge and body
//! diagonal once, 7 springs per cell, f64, one thread). The `/arith`
//! column sets the `f64` force pass beside its arithmetic bound: the
//! operations per cell the kernel performs (`Model::force_operations`)
//! over this core's measured rate for them. The `/bandwidth` column
//! sets the step beside the bandwidth bound: the bytes its arrays move, divided
//! by the copy bandwidth measured here.
//!
//! Then, in the same run and on one thread, the interactive and haptic
//! frames (examples `interactive` and `haptic`), and a last table of the
//! figures the speed issue sets targets for.

use std::time::Instant;

#[path = "common/arith_rate.rs"]
mod arith_rate;
#[path = "common/baseline.rs"]
mod baseline;
use baseline::{merged_springs, perturbed, spring_loop};
// The frame examples print every figure of a run; the table here some.
#[allow(dead_code)]
#[path = "common/frames.rs"]
mod frames;

use hexmesh::Lattice;
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric, VolumetricBarrier};
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model, Parameterization, Precision, Vec3};

/// CPU time of the process so far (s): on a shared machine, time the
/// process was not running (other tenants, steal) is not counted.
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

/// One run of `f` (s): the process CPU time when one thread works (time
/// the process did not run, on a shared machine, is not counted), the wall
/// time otherwise (idle pool threads spin, which CPU time would count).
fn time_once(f: &mut dyn FnMut()) -> f64 {
    let wall = Instant::now();
    let cpu = cpu_seconds();
    f();
    if rayon::current_num_threads() == 1 {
        cpu_seconds() - cpu
    } else {
        wall.elapsed().as_secs_f64()
    }
}

/// Minimum over `repeats` runs of `f` (s), timed by [`time_once`], after
/// one run that warms the caches.
fn best(repeats: usize, mut f: impl FnMut()) -> f64 {
    f();
    (0..repeats)
        .map(|_| time_once(&mut f))
        .fold(f64::INFINITY, f64::min)
}

/// [`best`] of `f` and of `g` (the baseline), timed alternately:
/// `f, g, f, g, ...`. On a shared machine whose speed drifts by 10-15 %
/// within a run, a baseline timed minutes before the model it is compared
/// with moved the ratio by as much; timed beside it, both see the same
/// machine. `g` must be serial work (it is timed like `f`: CPU time on one
/// thread, wall time otherwise, which for serial work is its own time).
fn best_beside(repeats: usize, mut f: impl FnMut(), mut g: impl FnMut()) -> (f64, f64) {
    f();
    g();
    let (mut best_f, mut best_g) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..repeats {
        best_f = best_f.min(time_once(&mut f));
        best_g = best_g.min(time_once(&mut g));
    }
    (best_f, best_g)
}

/// [`best`] of single-threaded work (the baseline, the copy).
fn best_serial(repeats: usize, f: impl FnMut() + Send) -> f64 {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool")
        .install(|| best(repeats, f))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u32 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(64);
    let repeats: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(7);
    let lattice = Lattice::block([n; 3], 1.0 / f64::from(n), [0.0; 3]).expect("block");
    let material = Material::new(1.0e4, 0.3, 1000.0).expect("material");
    let cells = lattice.num_cells();
    let nodes = lattice.num_nodes();

    // Copy bandwidth: read + write of a buffer far larger than the caches.
    let len = 32 << 20; // 256 MiB of f64
    let src = vec![1.0f64; len];
    let mut dst = vec![0.0f64; len];
    let copy = best_serial(3, || {
        dst.copy_from_slice(std::hint::black_box(&src));
        std::hint::black_box(&mut dst);
    });
    let bandwidth = 2.0 * 8.0 * len as f64 / copy;
    drop((src, dst));

    let models: Vec<(&str, Box<dyn Parameterization>)> = vec![
        ("paper", Box::new(PaperModel)),
        ("springs", Box::new(SpringsOnly)),
        ("volumetric", Box::new(Volumetric)),
        ("volumetric-barrier", Box::new(VolumetricBarrier)),
        (
            "paper+hg",
            Box::new(HourglassControl::new(Box::new(PaperModel), 1.0).expect("hg")),
        ),
        (
            "volumetric-barrier+hg",
            Box::new(HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("hg")),
        ),
    ];
    // Arrays one explicit step (velocity Verlet, one sub-step) reads and
    // writes, per node and per cell (bytes): the force pass reads the cells
    // (32) and positions (24), zeroes and adds into the forces (24 + 48);
    // two kicks read forces and masses and update velocities (2 x 80); the
    // drift updates positions from velocities and rest positions (96); the
    // force cache copies positions (48).
    let step_bytes = 32.0 * cells as f64 + (24.0 + 72.0 + 160.0 + 96.0 + 48.0) * nodes as f64;
    let bound = step_bytes / bandwidth;
    println!(
        "lattice {n}^3: {cells} cells, {nodes} nodes; copy bandwidth {:.1} GB/s; \
         bandwidth bound of a step {:.2} ms ({:.0} B/cell)",
        bandwidth / 1e9,
        bound * 1e3,
        step_bytes / cells as f64
    );
    // The arithmetic bound of the f64 force pass: its counted operations per
    // cell over this core's rate for them (the adders and multipliers, and
    // the unit that divides and takes roots, whichever is slower).
    let rate = arith_rate::f64_rate();
    if let Some(r) = rate {
        println!(
            "f64 arithmetic rate, one core: {:.1} G additions or multiplications per second, \
             {:.2} G divisions or square roots per second (per lane)",
            r.pipelined / 1e9,
            r.divide / 1e9
        );
    }
    let arith_bound = |model: &Model| {
        let ops = model.force_operations(Precision::F64);
        rate.map(|r| {
            cells as f64
                * (ops.pipelined() as f64 / r.pipelined).max((ops.div + ops.sqrt) as f64 / r.divide)
        })
    };
    for precision in [Precision::F64, Precision::F32] {
        let (isa, lanes) = precision.kernel_vectors();
        println!(
            "force kernel in {}: {isa}, {lanes} cells per vector",
            precision.name()
        );
    }
    // (threads, model, precision) -> step time (s) and the baseline timed
    // beside it (s).
    let mut steps: Vec<(usize, &str, Precision, f64, f64)> = Vec::new();
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let base_model = Model::new(&lattice, material, &SpringsOnly).expect("model");
            let springs = merged_springs(&lattice, &base_model);
            let x_base = perturbed(&base_model);
            let mut f = vec![Vec3::zeros(); nodes];
            let baseline = best_serial(repeats, || spring_loop(&springs, &x_base, &mut f));
            println!(
                "\n{threads} thread(s): baseline (naive merged springs, {} springs, 1 thread) {:.2} ms \
                 = {:.0} Mcell/s; each ratio below is to the baseline timed beside it \
                 (alternately; the last column is the step's)",
                springs.len(),
                baseline * 1e3,
                cells as f64 / baseline / 1e6
            );
            println!(
                "{:<26} {:>10} {:>10} {:>10} {:>10} {:>10} {:>12} {:>12}",
                "model",
                "force ms",
                "/baseline",
                "/arith",
                "step ms",
                "/baseline",
                "/bandwidth",
                "baseline ms"
            );
            let runs = models.iter().flat_map(|(name, param)| {
                [Precision::F64, Precision::F32].map(|precision| (*name, param, precision))
            });
            for (name, param, precision) in runs {
                let model = Model::new(&lattice, material, param.as_ref()).expect("model");
                let x = perturbed(&model);
                let mut ws = model.workspace();
                let mut f = vec![Vec3::zeros(); nodes];
                let mut f_base = vec![Vec3::zeros(); nodes];
                let (force, base_force) = best_beside(
                    repeats,
                    || model.internal_forces_in(precision, &x, &mut ws, &mut f),
                    || spring_loop(&springs, &x_base, &mut f_base),
                );
                let problem = Problem::new(model);
                let options = ExplicitOptions {
                    precision,
                    ..ExplicitOptions::default()
                };
                let mut integ = Explicit::new(&problem, options).expect("explicit");
                let mut state = State::at_rest(problem.model());
                state.x = x.clone();
                let (step, base_step) = best_beside(
                    repeats,
                    || {
                        integ.step(&problem, &mut state).expect("step");
                    },
                    || spring_loop(&springs, &x_base, &mut f_base),
                );
                let step = step / f64::from(integ.substeps());
                steps.push((threads, name, precision, step, base_step));
                // Against the arithmetic bound: f64 only (the rate is
                // measured in f64 lanes).
                let over_arith = match (precision, arith_bound(problem.model())) {
                    (Precision::F64, Some(bound)) => format!("{:.2}", force / bound),
                    _ => "-".to_string(),
                };
                println!(
                    "{:<26} {:>10.2} {:>10.2} {:>10} {:>10.2} {:>10.2} {:>12.2} {:>12.2}",
                    format!("{name} {}", precision.name()),
                    force * 1e3,
                    force / base_force,
                    over_arith,
                    step * 1e3,
                    step / base_step,
                    step / bound,
                    base_step * 1e3
                );
            }
        });
    }

    frame_table(n, cells, &steps);
}

/// The interactive and haptic frames on one thread, and the figures the
/// speed issue sets targets for, all from this run.
fn frame_table(n: u32, cells: usize, steps: &[(usize, &str, Precision, f64, f64)]) {
    let find = |threads: usize, name: &str, precision: Precision| {
        steps
            .iter()
            .find(|s| s.0 == threads && s.1 == name && s.2 == precision)
    };
    let step = |threads: usize, name: &str, precision: Precision| {
        find(threads, name, precision).map_or(f64::NAN, |s| s.3)
    };
    // The one-thread step over the baseline timed beside it.
    let ratio =
        |name: &str, precision: Precision| find(1, name, precision).map_or(f64::NAN, |s| s.3 / s.4);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let (inter, hapt) = one.install(|| {
        let inter =
            [Precision::F64, Precision::F32].map(|p| frames::interactive(22, 2.0e4, p, 120));
        let hapt = [Precision::F64, Precision::F32].map(|p| frames::haptic(10, 1.0e4, p, 10_000));
        (inter, hapt)
    });
    let default = "volumetric-barrier+hg";
    let rate = |s: f64| cells as f64 / s / 1e6;
    println!("\nfigures with targets (one thread unless said; this run):");
    println!("{:<64} {:>16} {:>12}", "measure", "value", "target");
    let rows = [
        (
            format!("{n}^3 step / baseline, paper f64 (f32)"),
            format!(
                "{:.2} ({:.2})",
                ratio("paper", Precision::F64),
                ratio("paper", Precision::F32)
            ),
            "<= 1.0",
        ),
        (
            format!("{n}^3 step / baseline, default model f64 (f32)"),
            format!(
                "{:.2} ({:.2})",
                ratio(default, Precision::F64),
                ratio(default, Precision::F32)
            ),
            "<= 1.3",
        ),
        (
            format!("{n}^3 step, 2 threads against 1, paper f64 (default f64)"),
            format!(
                "{:.2} ({:.2})",
                step(1, "paper", Precision::F64) / step(2, "paper", Precision::F64),
                step(1, default, Precision::F64) / step(2, default, Precision::F64)
            ),
            ">= 1.8",
        ),
        (
            format!(
                "interactive frame CPU, {} cells, {} sub-steps, f64 (f32), ms",
                inter[0].cells, inter[0].substeps
            ),
            format!(
                "{:.1} ({:.1})",
                inter[0].cpu_per_frame, inter[1].cpu_per_frame
            ),
            "<= 8",
        ),
        (
            "  the same, frames after the first (set-up left out), ms".to_owned(),
            format!(
                "{:.1} ({:.1})",
                inter[0].cpu_per_later_frame, inter[1].cpu_per_later_frame
            ),
            "",
        ),
        (
            format!("haptic frame CPU, {} cells, f64 (f32), ms", hapt[0].cells),
            format!(
                "{:.3} ({:.3})",
                hapt[0].cpu_per_frame, hapt[1].cpu_per_frame
            ),
            "<= 1",
        ),
        (
            "haptic worst wall frame of 10,000 after the first, f64 (f32), ms".to_owned(),
            format!("{:.2} ({:.2})", hapt[0].worst, hapt[1].worst),
            "",
        ),
        (
            "million cell-steps per s, paper f32 (default f64)".to_owned(),
            format!(
                "{:.1} ({:.1})",
                rate(step(1, "paper", Precision::F32)),
                rate(step(1, default, Precision::F64))
            ),
            "72 (Warp x 3)",
        ),
    ];
    for (measure, value, target) in rows {
        println!("{measure:<64} {value:>16} {target:>12}");
    }
}
