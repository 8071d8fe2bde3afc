//! The cost of contact between bodies, measured in one run: two blocks of
//! about 10,000 cells each, the upper one resting on the lower one (their
//! faces 0.1 mm into each other), stepped explicitly, against the same two
//! blocks without contact between them and against one block alone.
//!
//!     cargo run --release -p mss-core --example bodies_contact [CELLS_PER_SIDE] [STEPS]
//!
//! Prints the CPU time per step (one thread, the least of five timings of
//! STEPS steps, the cases timed in turns) and the ratios: two bodies in contact over two without
//! (the contact's cost; target <= 1.3), and over twice one body.

use hexmesh::Lattice;
use mss_core::contact::{BodyContact, Contact, ContactSettings};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model};

/// CPU time of the process so far (s).
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

fn block(n: u32, h: f64, z0: f64) -> Model {
    let lattice = Lattice::block([n, n, n], h, [0.0, 0.0, z0]).expect("lattice");
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("param");
    Model::new(
        &lattice,
        Material::new(1e5, 0.3, 1000.0).expect("material"),
        &param,
    )
    .expect("model")
}

fn problem(model: Model, contact: Option<Contact>) -> Problem {
    let gravity = LoadSpec::Gravity {
        g: [0.0, 0.0, -9.81],
    };
    let p = Problem::from_specs(model, &[], &[gravity], Damping::NONE).expect("problem");
    match contact {
        Some(c) => p.with_contact(c),
        None => p,
    }
}

/// One case's integrator and state, stepped in turns with the others.
struct Run<'a> {
    problem: &'a Problem,
    integrator: Explicit,
    state: State,
    best: f64,
}

impl<'a> Run<'a> {
    fn new(problem: &'a Problem) -> Self {
        let opts = ExplicitOptions {
            dt: Some(1e-5),
            ..ExplicitOptions::default()
        };
        let mut integrator = Explicit::new(problem, opts).expect("integrator");
        let mut state = State::at_rest(problem.model());
        integrator.step(problem, &mut state).expect("step");
        Self {
            problem,
            integrator,
            state,
            best: f64::INFINITY,
        }
    }

    /// Times `steps` more steps; keeps the least CPU seconds per step.
    fn time(&mut self, steps: usize) {
        let t0 = cpu_seconds();
        for _ in 0..steps {
            self.integrator
                .step(self.problem, &mut self.state)
                .expect("step");
        }
        self.best = self.best.min((cpu_seconds() - t0) / steps as f64);
    }
}

/// Timings of each case, taken in turns.
const ROUNDS: usize = 5;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: u32 = args
        .next()
        .map_or(22, |a| a.parse().expect("cells per side"));
    let steps: usize = args.next().map_or(40, |a| a.parse().expect("steps"));
    let h = 0.005;
    let side = f64::from(n) * h;
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .expect("one thread");
    let lower = || block(n, h, 0.0);
    let upper = || block(n, h, side - 1e-4);
    let one = problem(lower(), None);
    let union = || Model::union(&[lower(), upper()]).expect("union");
    let apart = problem(union(), None);
    let model = union();
    let settings = ContactSettings::for_bodies(&model);
    let bodies = BodyContact::new(&model, settings, &[false, false]).expect("contact");
    let contact = Contact::new(&model, Vec::new()).with_bodies(bodies);
    let touching = problem(model, Some(contact));
    let pairs = touching
        .contact()
        .expect("contact")
        .bodies()
        .expect("bodies");
    let depth = pairs.max_depth(touching.model().rest_positions());
    // The contact search alone, at positions that change every time.
    let mut x = touching.model().rest_positions().to_vec();
    let t0 = cpu_seconds();
    for k in 0..steps {
        x[0].x += 1e-12 * k as f64;
        std::hint::black_box(pairs.max_depth(&x));
    }
    let search = (cpu_seconds() - t0) / steps as f64;
    // The three cases in turns, so that a slow spell of the machine
    // touches them alike; the least time of each.
    let mut runs = [Run::new(&one), Run::new(&apart), Run::new(&touching)];
    for _ in 0..ROUNDS {
        for run in &mut runs {
            run.time(steps);
        }
    }
    let [t1, t2, tc] = runs.map(|r| r.best);
    println!(
        "{} cells per body, {} boundary points, {} surface triangles, contact depth {:.1e} m",
        one.model().num_cells(),
        pairs.num_points(),
        pairs.num_triangles(),
        depth
    );
    println!("| case | CPU per step | ratio |");
    println!("|---|---|---|");
    println!("| one body | {:.3} ms | |", 1e3 * t1);
    println!(
        "| the contact search alone (two bodies) | {:.3} ms | |",
        1e3 * search
    );
    println!(
        "| two bodies, no contact between them | {:.3} ms | {:.2} of twice one body |",
        1e3 * t2,
        t2 / (2.0 * t1)
    );
    println!(
        "| two bodies in contact | {:.3} ms | {:.2} of two without contact, {:.2} of twice one body |",
        1e3 * tc,
        tc / t2,
        tc / (2.0 * t1)
    );
}
