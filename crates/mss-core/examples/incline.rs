//! A block on an incline with friction and no material damping, against
//! the rigid answer, stepped explicitly and implicitly: on the ground (an
//! obstacle) or, with `--slab`, on a held slab (contact between bodies).
//!
//!     cargo run --release -p mss-core --example incline [-- [--slab] [--settled] [E] [SAFETY] [IMPLICIT_DT]]
//!
//! The 4 x 4 x 2 block (0.1 x 0.1 x 0.05 m, nu 0.3, 1000 kg/m^3, default
//! E = 1e5 Pa) starts at rest on the surface, gravity turned by the slope,
//! mu = 0.5. Per slope and solver it prints: above the friction angle, the
//! acceleration along the slope from 0.1 s to 0.4 s over g (sin - mu cos);
//! below it, how far the block moved in 0.6 s (it should stick); the
//! normal force's range over the weight, its mean, and the mean friction
//! over mu times the mean normal force. With `--settled`, a block that
//! should stick is first settled under its weight (`solver::settle`) and
//! its motion measured from there.

use hexmesh::Lattice;
use mss_core::contact::{BodyContact, Contact, ContactSettings, Plane};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{
    Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator, Problem, SettleOptions,
    State, settle,
};
use mss_core::{ConstraintSpec, Material, Model, NodeSelector, Vec3};

const G: f64 = 9.81;
const MU: f64 = 0.5;

fn gravity(tan: f64) -> LoadSpec {
    let a = tan.atan();
    LoadSpec::Gravity {
        g: [0.0, G * a.sin(), -G * a.cos()],
    }
}

fn model(lattice: &Lattice, e: f64) -> Model {
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).expect("param");
    Model::new(
        lattice,
        Material::new(e, 0.3, 1000.0).expect("material"),
        &param,
    )
    .expect("model")
}

fn block(e: f64) -> Model {
    model(
        &Lattice::block([4, 4, 2], 0.025, [0.0; 3]).expect("lattice"),
        e,
    )
}

fn with_friction(mut s: ContactSettings) -> ContactSettings {
    s.friction_static = MU;
    s.friction_kinetic = MU;
    s
}

fn on_ground(e: f64, tan: f64) -> Problem {
    let model = block(e);
    let s = with_friction(ContactSettings::for_model(&model));
    let ground = Plane::new(Vec3::zeros(), Vec3::z()).expect("plane");
    let contact = Contact::new(&model, vec![(Box::new(ground), s)]);
    Problem::from_specs(model, &[], &[gravity(tan)], Damping::NONE)
        .expect("problem")
        .with_contact(contact)
}

/// The block on a held slab long enough for 0.4 s of sliding.
fn on_slab(e: f64, tan: f64) -> Problem {
    let slab = Lattice::block([8, 24, 1], 0.025, [-0.05, -0.05, -0.025]).expect("lattice");
    let held = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0; 3],
        max: [1.0; 3],
        relative: false,
    });
    let slab = Problem::from_specs(model(&slab, e), &[held], &[], Damping::NONE).expect("slab");
    let block = Problem::from_specs(block(e), &[], &[gravity(tan)], Damping::NONE).expect("block");
    let u = Problem::union(vec![slab, block]).expect("union");
    let s = with_friction(ContactSettings::for_bodies(u.model()));
    let bodies = BodyContact::new(u.model(), s, &[false, false]).expect("bodies");
    let contact = Contact::new(u.model(), vec![]).with_bodies(bodies);
    u.with_contact(contact)
}

/// What a run measured.
struct Measured {
    /// Acceleration over the rigid one (sliding), or distance moved (m).
    value: f64,
    n_min: f64,
    n_max: f64,
    n_mean: f64,
    friction_ratio: f64,
}

fn measure(p: &Problem, it: &mut dyn Integrator, tan: f64, settled: bool) -> Measured {
    let free: Vec<usize> = (0..p.model().num_nodes())
        .filter(|&i| !p.constraints().mask(i)[2])
        .collect();
    let masses = p.model().masses();
    let mass: f64 = free.iter().map(|&i| masses[i]).sum();
    let a = tan.atan();
    let weight = mass * G * a.cos();
    let expected = G * (a.sin() - MU * a.cos());
    let mean_y = |s: &State| free.iter().map(|&i| s.x[i].y).sum::<f64>() / free.len() as f64;
    let speed = |s: &State| free.iter().map(|&i| masses[i] * s.v[i].y).sum::<f64>() / mass;
    let mut s = State::at_rest(p.model());
    if settled && expected <= 0.0 {
        let info = settle(p, it, &mut s, &SettleOptions::default()).expect("settle");
        println!(
            "     settled in {} steps ({:.3} s, residual {:.1e})",
            info.steps, info.settle_time, info.relative_residual
        );
    }
    let y0 = mean_y(&s);
    let (mut n_min, mut n_max, mut n_sum, mut t_sum, mut count) =
        (f64::INFINITY, 0.0f64, 0.0, 0.0, 0usize);
    let mut v1 = 0.0;
    let end = if expected > 0.0 { 0.4 } else { 0.6 };
    while s.time < end - 1e-12 {
        it.step(p, &mut s).expect("step");
        if (s.time - 0.1).abs() < 0.5 * it.dt() {
            v1 = speed(&s);
        }
        if s.time > 0.1 {
            let f = p.contact_forces(&s);
            let n: f64 = free.iter().map(|&i| f[i].z).sum();
            n_min = n_min.min(n / weight);
            n_max = n_max.max(n / weight);
            n_sum += n;
            t_sum -= free.iter().map(|&i| f[i].y).sum::<f64>();
            count += 1;
        }
    }
    let value = if expected > 0.0 {
        (speed(&s) - v1) / (s.time - 0.1) / expected
    } else {
        mean_y(&s) - y0
    };
    Measured {
        value,
        n_min,
        n_max,
        n_mean: n_sum / count as f64 / weight,
        friction_ratio: t_sum / (MU * n_sum),
    }
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut flag = |name: &str| {
        let found = args.iter().position(|a| a == name);
        found.map(|k| args.remove(k)).is_some()
    };
    let slab = flag("--slab");
    let settled = flag("--settled");
    let number = |k: usize, default: f64| {
        args.get(k)
            .map_or(default, |a| a.parse().expect("a number"))
    };
    let (e, safety, implicit_dt) = (number(0, 1e5), number(1, 0.9), number(2, 1e-3));
    println!(
        "block on {} at E = {e:e} Pa, mu = {MU}, no damping; explicit safety {safety}, implicit dt {implicit_dt} s",
        if slab { "a held slab" } else { "the ground" }
    );
    println!(
        "tan  solver    dt (s)    accel/rigid or moved (m)  N/W min..max  mean  friction/(mu N)"
    );
    for tan in [0.8, 0.7, 0.4, 0.3] {
        let p = if slab {
            on_slab(e, tan)
        } else {
            on_ground(e, tan)
        };
        let opts = ExplicitOptions {
            safety,
            ..ExplicitOptions::default()
        };
        let mut explicit = Explicit::new(&p, opts).expect("explicit");
        let opts = ImplicitOptions {
            dt: implicit_dt,
            ..ImplicitOptions::default()
        };
        let mut implicit = Implicit::new(&p, opts).expect("implicit");
        for (name, it) in [
            ("explicit", &mut explicit as &mut dyn Integrator),
            ("implicit", &mut implicit),
        ] {
            let dt = it.dt();
            let m = measure(&p, it, tan, settled);
            println!(
                "{tan:.1}  {name}  {dt:.2e}  {:>10}                {:.2}..{:.2}    {:.3} {:.4}",
                // Distances moved to the micrometre and below.
                if m.value.abs() < 1e-3 {
                    format!("{:.2e}", m.value)
                } else {
                    format!("{:.4}", m.value)
                },
                m.n_min,
                m.n_max,
                m.n_mean,
                m.friction_ratio
            );
        }
    }
}
