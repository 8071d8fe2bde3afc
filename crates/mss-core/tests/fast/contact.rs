//! Contact with obstacles: a block resting on the ground carries its weight,
//! sticks on an incline below the friction angle and slides above it, a
//! sphere pressed in leaves no node deep inside it, an elastic drop does not
//! gain energy; the same in the implicit and static solvers.

use hexmesh::Lattice;
use mss_core::contact::{Contact, ContactSettings, Cuboid, Obstacle, Path, Plane, Sphere};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{
    Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator, Problem, SettleOptions,
    SolverError, State, StaticOptions, settle, solve_static,
};
use mss_core::{ConstraintSpec, Material, Model, NodeSelector, SpringsOnly, Vec3};

const G: f64 = 9.81;

/// A 0.1 x 0.1 x 0.05 m block of 4 x 4 x 2 cells standing at z = `z0`.
fn block(z0: f64) -> Model {
    let lattice = Lattice::block([4, 4, 2], 0.025, [0.0, 0.0, z0]).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    Model::new(&lattice, Material::new(1.0e5, 0.3, 1000.0).unwrap(), &param).unwrap()
}

fn problem(
    model: Model,
    g: Vec3,
    obstacle: Box<dyn Obstacle>,
    settings: impl Fn(ContactSettings) -> ContactSettings,
    damping: Damping,
    fixed: &[ConstraintSpec],
) -> Problem {
    let s = settings(ContactSettings::for_model(&model));
    let contact = Contact::new(&model, vec![(obstacle, s)]);
    Problem::from_specs(model, fixed, &[LoadSpec::Gravity { g: g.into() }], damping)
        .unwrap()
        .with_contact(contact)
}

fn mass_damping(alpha: f64) -> Damping {
    Damping { alpha, beta: 0.0 }
}

fn ground() -> Box<dyn Obstacle> {
    Box::new(Plane::new(Vec3::zeros(), Vec3::z()).unwrap())
}

fn run(p: &Problem, seconds: f64) -> State {
    let mut it = Explicit::new(p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let steps = (seconds / it.dt()).ceil() as usize;
    for _ in 0..steps {
        it.step(p, &mut s).unwrap();
    }
    s
}

/// A block on the ground under gravity, damped to rest.
fn resting_block() -> Problem {
    let down = Vec3::new(0.0, 0.0, -G);
    problem(block(0.0), down, ground(), |s| s, mass_damping(30.0), &[])
}

fn mean_y(s: &State) -> f64 {
    s.x.iter().map(|x| x.y).sum::<f64>() / s.x.len() as f64
}

#[test]
fn a_block_on_the_ground_carries_its_weight_without_sinking() {
    let p = resting_block();
    let s = run(&p, 0.4);
    let k = ContactSettings::for_model(p.model()).stiffness;
    assert_rests_on_the_ground(&p, &s, k, "default");
}

/// The block at `s` carries its weight on the ground within 1 %, sideways
/// forces cancel, no node is deeper than four times the mean load of a
/// bottom node over the contact stiffness `k`, and it is at rest.
fn assert_rests_on_the_ground(p: &Problem, s: &State, k: f64, what: &str) {
    let weight = p.model().total_mass() * G;
    let f = p.contact_forces(s);
    let total: Vec3 = f.iter().sum();
    assert!(
        (total.z - weight).abs() < 0.01 * weight,
        "{what}: {} vs {weight}",
        total.z
    );
    assert!(total.x.abs() + total.y.abs() < 1e-6 * weight, "{what}");
    let touching = f.iter().filter(|v| v.z > 0.0).count();
    let tolerance = 4.0 * weight / touching as f64 / k;
    let deepest = s.x.iter().map(|x| -x.z).fold(f64::MIN, f64::max);
    assert!(
        deepest > 0.0 && deepest < tolerance,
        "{what}: {deepest} vs {tolerance}"
    );
    assert!(s.v.iter().all(|v| v.norm() < 1e-3), "{what}");
}

#[test]
fn a_block_sticks_below_the_friction_angle_and_slides_above() {
    // The incline as gravity turned by the angle (the same to the block).
    let mu = 0.5;
    let incline = |tan: f64| {
        let a = tan.atan();
        Vec3::new(0.0, G * a.sin(), -G * a.cos())
    };
    let friction = |s: ContactSettings| ContactSettings {
        friction_static: mu,
        friction_kinetic: mu,
        ..s
    };
    let p = problem(
        block(0.0),
        incline(0.3),
        ground(),
        friction,
        Damping::NONE,
        &[],
    );
    // It settles onto the slope (slipping a little while the contact forces
    // build up), then stays.
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let mut at = |s: &mut State, t: f64| {
        while s.time < t {
            it.step(&p, s).unwrap();
        }
        mean_y(s)
    };
    let (y1, y2) = (at(&mut s, 0.2), at(&mut s, 0.5));
    assert!((y2 - y1).abs() < 2e-5, "crept by {} m in 0.3 s", y2 - y1);
    // Above it: the acceleration g (sin - mu cos) along the slope within
    // 3 %, with no damping at all, though the block hops as it slides (its
    // normal force swings from 0 to 2.7 times its weight). A contact made
    // within a step has its friction from the step's start: anchored where
    // it touched, each landing lost a step of friction (18 % too fast).
    let p = problem(
        block(0.0),
        incline(0.8),
        ground(),
        friction,
        Damping::NONE,
        &[],
    );
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let masses = p.model().masses();
    let mut speed_at = |s: &mut State, t: f64| {
        while s.time < t {
            it.step(&p, s).unwrap();
        }
        s.momentum(masses).y / p.model().total_mass()
    };
    let (v1, v2) = (speed_at(&mut s, 0.1), speed_at(&mut s, 0.4));
    let a = 0.8f64.atan();
    let expected = G * (a.sin() - mu * a.cos());
    let got = (v2 - v1) / 0.3;
    assert!(
        (got - expected).abs() < 0.03 * expected,
        "{got} vs {expected} m/s^2"
    );
}

/// Below the friction angle with no damping at all (tan 0.4, mu 0.5): the
/// block released unstressed rings (its normal force swings between 0.6
/// and 1.5 times its weight), slips whenever the ringing unloads it, and
/// walks millimetres down the slope, as an undamped elastic body does;
/// settled first (`solver::settle`), it stays, in either solver.
#[test]
fn a_settled_block_sticks_on_a_slope_without_damping() {
    let (tan, mu) = (0.4f64, 0.5);
    let a = tan.atan();
    let incline = Vec3::new(0.0, G * a.sin(), -G * a.cos());
    let friction = |s: ContactSettings| ContactSettings {
        friction_static: mu,
        friction_kinetic: mu,
        ..s
    };
    let p = problem(block(0.0), incline, ground(), friction, Damping::NONE, &[]);
    let explicit = || Box::new(Explicit::new(&p, ExplicitOptions::default()).unwrap());
    let implicit = || {
        let opts = ImplicitOptions {
            dt: 1e-3,
            ..ImplicitOptions::default()
        };
        Box::new(Implicit::new(&p, opts).unwrap())
    };
    let moved = |it: &mut dyn Integrator, settled: bool| {
        let mut s = State::at_rest(p.model());
        if settled {
            let opts = SettleOptions::default();
            let info = settle(&p, it, &mut s, &opts).unwrap();
            assert!(info.relative_residual <= opts.rtol, "{info:?}");
            assert_eq!(s.time, 0.0, "the run starts at its start time");
            assert!(s.v.iter().all(|v| *v == Vec3::zeros()));
            // At rest on the slope: the contact carries the weight.
            let weight = p.model().total_mass() * G * a.cos();
            let normal: f64 = p.contact_forces(&s).iter().map(|f| f.z).sum();
            assert!(
                (normal - weight).abs() < 1e-4 * weight,
                "{normal} vs {weight}"
            );
        }
        let y0 = mean_y(&s);
        while s.time < 0.6 - 1e-9 {
            it.step(&p, &mut s).unwrap();
        }
        (mean_y(&s) - y0).abs()
    };
    let unsettled = moved(explicit().as_mut(), false);
    assert!(
        unsettled > 1e-3,
        "released unstressed it slips: {unsettled} m"
    );
    let settled = moved(explicit().as_mut(), true);
    assert!(settled < 1e-6, "explicit, settled: moved {settled} m");
    let settled = moved(implicit().as_mut(), true);
    assert!(settled < 1e-6, "implicit, settled: moved {settled} m");
    // An interactive simulation settles the same way before its frames.
    let mut sim = mss_core::simulation::Simulation::new(problem(
        block(0.0),
        incline,
        ground(),
        friction,
        Damping::NONE,
        &[],
    ))
    .unwrap();
    sim.settle(&SettleOptions::default()).unwrap();
    let y0 = mean_y(sim.state());
    for _ in 0..36 {
        sim.step(1.0 / 60.0).unwrap();
    }
    let moved = (mean_y(sim.state()) - y0).abs();
    assert!(moved < 1e-6, "simulation, settled: moved {moved} m");
    // Above the friction angle there is no rest to settle into.
    let b = 0.8f64.atan();
    let steep = Vec3::new(0.0, G * b.sin(), -G * b.cos());
    let p = problem(block(0.0), steep, ground(), friction, Damping::NONE, &[]);
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let opts = SettleOptions {
        max_time: 0.3,
        ..SettleOptions::default()
    };
    let r = settle(&p, &mut it, &mut s, &opts);
    assert!(
        matches!(r, Err(SolverError::NotSettled { max_time, .. }) if max_time == 0.3),
        "{r:?}"
    );
}

#[test]
fn a_sphere_pressed_in_leaves_no_node_deep_inside() {
    // Held at its base; a sphere of 3 cm comes down 1 cm into the top
    // centre over 0.2 s, then stays.
    let radius = 0.03;
    let centre = Vec3::new(0.05, 0.05, 0.05 + radius);
    let path = Path::new(vec![
        (0.0, Vec3::zeros()),
        (0.2, Vec3::new(0.0, 0.0, -0.01)),
    ])
    .unwrap();
    let sphere = Sphere::new(centre, radius).unwrap().moving(path);
    let base = [ConstraintSpec::fixed(NodeSelector::LowestLayer)];
    let p = problem(
        block(0.0),
        Vec3::zeros(),
        Box::new(sphere.clone()),
        |s| s,
        mass_damping(30.0),
        &base,
    );
    let s = run(&p, 0.4);
    let depth = |x: &[Vec3], t: f64| {
        x.iter()
            .filter_map(|&xi| sphere.penetration(t, xi).map(|q| q.depth))
            .fold(0.0, f64::max)
    };
    let f = p.contact_forces(&s);
    let total: Vec3 = f.iter().sum();
    assert!(total.z < 0.0, "the sphere pushes down: {total:?}");
    let k = ContactSettings::for_model(p.model()).stiffness;
    let touching = f.iter().filter(|v| v.norm() > 0.0).count().max(1);
    let tolerance = 4.0 * total.norm() / touching as f64 / k;
    let d = depth(&s.x, s.time);
    assert!(d < tolerance && d < 0.1 * 0.025, "{d} vs {tolerance}");
    // The static solve of the pressed state agrees.
    let mut st = State::at_rest(p.model());
    st.time = 0.4;
    let opts = StaticOptions {
        accept_unstable: true,
        ..StaticOptions::default()
    };
    solve_static(&p, &mut st, &opts).unwrap();
    let ds = depth(&st.x, 0.4);
    assert!(ds < tolerance, "{ds} vs {tolerance}");
    let top = |x: &[Vec3]| x.iter().map(|v| v.z).fold(f64::MIN, f64::max);
    assert!(
        (top(&st.x) - top(&s.x)).abs() < 0.1 * 0.01,
        "{} vs {}",
        top(&st.x),
        top(&s.x)
    );
}

#[test]
fn an_elastic_drop_does_not_gain_energy() {
    // The default ground, and one 100 times stiffer (which the explicit
    // step integrates with the same step: node contact is implicit).
    for stiffer in [1.0, 100.0] {
        elastic_drop(stiffer);
    }
}

fn elastic_drop(stiffer: f64) {
    // 1 cm above the ground, no damping, no friction: the energy of the
    // bounce stays what the fall started with.
    let lattice = Lattice::block([4, 4, 2], 0.025, [0.0, 0.0, 0.01]).unwrap();
    // Springs only: the correction forces of the other models do no work
    // that an energy accounts for.
    let model = Model::new(
        &lattice,
        Material::new(1.0e5, 0.3, 1000.0).unwrap(),
        &SpringsOnly,
    )
    .unwrap();
    let elastic = |s: ContactSettings| ContactSettings {
        stiffness: stiffer * s.stiffness,
        friction_static: 0.0,
        friction_kinetic: 0.0,
        damping_ratio: 0.0,
    };
    let p = problem(
        model,
        Vec3::new(0.0, 0.0, -G),
        ground(),
        elastic,
        Damping::NONE,
        &[],
    );
    let m = p.model();
    let contact = p.contact().unwrap();
    let energy = |s: &State| {
        let gravity: f64 = s.x.iter().zip(m.masses()).map(|(x, mi)| mi * G * x.z).sum();
        s.kinetic_energy(m.masses()) + m.energy(&s.x) + contact.energy(s.time, &s.x) + gravity
    };
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(m);
    let e0 = energy(&s);
    let drop = m.total_mass() * G * 0.01;
    let mut bounced = false;
    let mut worst = 0.0f64;
    for _ in 0..(0.3 / it.dt()) as usize {
        it.step(&p, &mut s).unwrap();
        worst = worst.max(energy(&s) - e0);
        bounced |= s.v.iter().map(|v| v.z).sum::<f64>() > 0.0;
    }
    assert!(bounced, "it must have hit the ground");
    assert!(
        worst < 0.05 * drop,
        "ground {stiffer} x stiffer: energy grew by {worst} J of {drop} J"
    );
}

/// Contact of the nodes is implicit in the explicit step: at the default
/// stiffness it does not shorten the step at all; 100 times stiffer, the
/// step resolves it (NODE_CONTACT_ANGLE), still twice as long as explicit
/// contact allows, and a block rests at its equilibrium with either scheme;
/// contact of embedded-surface vertices is explicit and shortens the step.
#[test]
fn node_contact_does_not_limit_the_explicit_step() {
    use mss_core::contact::ContactPoints;
    use mss_core::solver::{ExplicitScheme, NODE_CONTACT_ANGLE, explicit_time_step_limit};
    let down = Vec3::new(0.0, 0.0, -G);
    let gravity = [LoadSpec::Gravity { g: down.into() }];
    let lattice_only = Problem::from_specs(block(0.0), &[], &gravity, mass_damping(30.0)).unwrap();
    let limit = explicit_time_step_limit(&lattice_only, 0.9);
    let p = resting_block();
    assert_eq!(explicit_time_step_limit(&p, 0.9), limit);
    let stiff = |s: ContactSettings| ContactSettings {
        stiffness: 100.0 * s.stiffness,
        ..s
    };
    let p = problem(block(0.0), down, ground(), stiff, mass_damping(30.0), &[]);
    let contact = p.contact().unwrap();
    let stiff_limit = explicit_time_step_limit(&p, 0.9);
    assert_eq!(
        stiff_limit,
        NODE_CONTACT_ANGLE / contact.node_omega_sq().sqrt()
    );
    // Explicit contact: the lattice and contact frequencies together, the
    // contact's twice over (mss_core::solver::CONTACT_RESOLUTION).
    let w_lattice = 2.0 / p.model().critical_time_step();
    let explicit = 0.9 * 2.0 / (w_lattice.powi(2) + 4.0 * contact.omega_sq()).sqrt();
    assert!(stiff_limit > 2.0 * explicit, "{stiff_limit} vs {explicit}");
    let k = stiff(ContactSettings::for_model(p.model())).stiffness;
    for scheme in [
        ExplicitScheme::VelocityVerlet,
        ExplicitScheme::SymplecticEuler,
    ] {
        let opts = ExplicitOptions {
            scheme,
            ..ExplicitOptions::default()
        };
        let mut it = Explicit::new(&p, opts).unwrap();
        assert_eq!(it.dt(), stiff_limit);
        let mut s = State::at_rest(p.model());
        while s.time < 0.4 {
            it.step(&p, &mut s).unwrap();
        }
        assert_rests_on_the_ground(&p, &s, k, &format!("{scheme:?}"));
    }
    // The same block touching with its embedded surface's vertices.
    let model = block(0.0);
    let surface = hexmesh::generate::box_mesh([0.001, 0.001, 0.001], [0.099, 0.099, 0.049]);
    let lattice = Lattice::block([4, 4, 2], 0.025, [0.0; 3]).unwrap();
    let embedding = hexmesh::Embedding::new(&lattice, &surface);
    let settings = ContactSettings::for_model(&model);
    let contact = Contact::with_points(
        &model,
        vec![(ground(), settings)],
        ContactPoints::Surface,
        Some(&embedding),
    );
    let p = Problem::from_specs(model, &[], &gravity, mass_damping(30.0))
        .unwrap()
        .with_contact(contact);
    assert!(explicit_time_step_limit(&p, 0.9) < 0.8 * limit);
}

#[test]
fn implicit_steps_rest_on_the_ground_too() {
    let p = resting_block();
    let mut it = Implicit::new(
        &p,
        ImplicitOptions {
            dt: 0.01,
            ..ImplicitOptions::default()
        },
    )
    .unwrap();
    let mut s = State::at_rest(p.model());
    for _ in 0..40 {
        it.step(&p, &mut s).unwrap();
    }
    let weight = p.model().total_mass() * G;
    let total: Vec3 = p.contact_forces(&s).iter().sum();
    assert!(
        (total.z - weight).abs() < 0.02 * weight,
        "{} vs {weight}",
        total.z
    );
}

#[test]
fn an_implicit_run_restored_from_its_memory_continues_bitwise() {
    // The direct solver keeps its last factors and preconditions the next
    // steps' matrices with them: their solutions differ from fresh factors'
    // in the last bits, so the memory carries the kept factors' matrix and a
    // restored integrator factors it again.
    let down = Vec3::new(0.0, 0.0, -G);
    let friction = |s: ContactSettings| ContactSettings {
        friction_static: 0.5,
        friction_kinetic: 0.5,
        ..s
    };
    let p = problem(block(0.001), down, ground(), friction, Damping::NONE, &[]);
    let opts = ImplicitOptions {
        dt: 0.005,
        ..ImplicitOptions::default()
    };
    let memory = crate::assert_restored_implicit_continues_bitwise(&p, opts, 12, 12);
    assert_eq!(
        memory.counters[1], 1,
        "the factors are kept: {:?}",
        memory.counters
    );
    assert!(!memory.values.is_empty());
}

#[test]
fn an_implicit_landing_takes_contact_without_halving_its_steps() {
    // A 512-cell cube dropped 1 mm onto the ground at dt = 0.01 s, no
    // material damping: Newton meets the contact at once (its friction
    // anchored where each node starts the step, so the tangent is the
    // force's), with a handful of iterations and no step halved.
    let lattice = Lattice::block([8, 8, 8], 0.0125, [0.0, 0.0, 0.001]).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let model = Model::new(&lattice, Material::new(1.0e5, 0.3, 1000.0).unwrap(), &param).unwrap();
    let down = Vec3::new(0.0, 0.0, -G);
    let p = problem(model, down, ground(), |s| s, Damping::NONE, &[]);
    let opts = ImplicitOptions {
        dt: 0.01,
        ..ImplicitOptions::default()
    };
    let mut it = Implicit::new(&p, opts).unwrap();
    let mut s = State::at_rest(p.model());
    let (mut most, mut total) = (0, 0);
    for _ in 0..30 {
        let info = it.step(&p, &mut s).unwrap();
        assert_eq!(info.substeps, 1, "a step halved at t = {}", s.time);
        most = most.max(info.newton_iterations);
        total += info.newton_iterations;
    }
    assert!(most <= 6 && total <= 60, "{most} at most, {total} in all");
    let weight = p.model().total_mass() * G;
    let carried: Vec3 = p.contact_forces(&s).iter().sum();
    assert!(
        carried.z > 0.5 * weight,
        "it stands on the ground: {carried:?}"
    );
}

#[test]
fn bad_obstacles_are_refused() {
    assert!(Plane::new(Vec3::zeros(), Vec3::zeros()).is_err());
    assert!(Sphere::new(Vec3::zeros(), 0.0).is_err());
    assert!(Sphere::new(Vec3::new(f64::NAN, 0.0, 0.0), 1.0).is_err());
    assert!(Path::new(vec![(1.0, Vec3::zeros()), (0.5, Vec3::zeros())]).is_none());
    let s = ContactSettings::for_model(&block(0.0));
    for bad in [
        ContactSettings {
            stiffness: 0.0,
            ..s
        },
        ContactSettings {
            friction_static: -1.0,
            ..s
        },
        ContactSettings {
            friction_kinetic: 0.9,
            friction_static: 0.5,
            ..s
        },
        ContactSettings {
            damping_ratio: f64::NAN,
            ..s
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}

/// The interactive API: a pick drags the block across the ground, a steered
/// sphere pushes it, and the result does not depend on the thread count.
#[test]
fn a_simulation_drags_and_pushes_the_same_for_any_thread_count() {
    use mss_core::contact::Steered;
    use mss_core::simulation::Simulation;
    let run = |threads: usize| {
        crate::on_threads(threads, || {
            let model = block(0.0);
            let settings = ContactSettings::for_model(&model);
            let (ball, handle) = Steered::new(Box::new(
                Sphere::new(Vec3::new(-0.03, 0.05, 0.025), 0.02).unwrap(),
            ));
            let contact = Contact::new(
                &model,
                vec![(ground(), settings), (Box::new(ball), settings)],
            );
            let problem = Problem::from_specs(
                model,
                &[],
                &[LoadSpec::Gravity { g: [0.0, 0.0, -G] }],
                Damping {
                    alpha: 5.0,
                    beta: 0.0,
                },
            )
            .unwrap()
            .with_contact(contact);
            let mut sim = Simulation::new(problem).unwrap();
            let top = sim.nearest_node(Vec3::new(0.1, 0.05, 0.05));
            sim.pick(&[top], 400.0).unwrap();
            let start = sim.positions()[top as usize];
            let frame = 1.0 / 60.0;
            for k in 0..30 {
                sim.drag_to(start + Vec3::new(0.002 * k as f64, 0.0, 0.0));
                // The ball rolls in from -x and pushes the other side.
                handle.move_to(Vec3::new(0.0005 * k as f64, 0.0, 0.0), frame);
                sim.step(frame).unwrap();
            }
            sim.release();
            assert!(sim.pick(&[], 1.0).is_err() && sim.pick(&[top], -1.0).is_err());
            (sim.positions()[top as usize] - start, sim.state().clone())
        })
    };
    let (moved, one) = run(1);
    assert!(moved.x > 0.01, "dragged by {moved:?}");
    let (_, two) = run(2);
    assert_eq!(one, two);
}

/// A closed mesh obstacle answers like the analytic shape it describes, and
/// an open one is refused.
#[test]
fn a_mesh_obstacle_agrees_with_the_box_it_is() {
    use mss_core::contact::{Cuboid, MeshObstacle};
    let (lo, hi) = ([0.0, 0.0, 0.0], [0.2, 0.1, 0.05]);
    let mesh = MeshObstacle::new(&hexmesh::generate::box_mesh(lo, hi)).unwrap();
    let cuboid = Cuboid::new(Vec3::from(lo), Vec3::from(hi)).unwrap();
    let mut seed = 12345u64;
    let mut r = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..200 {
        let p = Vec3::new(0.3 * r() - 0.05, 0.2 * r() - 0.05, 0.1 * r() - 0.025);
        match (mesh.penetration(0.0, p), cuboid.penetration(0.0, p)) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                assert!((a.depth - b.depth).abs() < 1e-12, "{p:?}");
                assert!((a.normal - b.normal).norm() < 1e-9, "{p:?}: {a:?} vs {b:?}");
            }
            (a, b) => panic!("{p:?}: {a:?} vs {b:?}"),
        }
    }
    let mut open = hexmesh::generate::box_mesh(lo, hi);
    open.triangles.pop();
    assert!(MeshObstacle::new(&open).is_err());
}

/// The contact Jacobian is the derivative of the contact forces (finite
/// differences), for nodes and embedded-surface vertices, sticking and
/// sliding, on a tilted plane and a sphere.
#[test]
fn the_contact_jacobian_matches_finite_differences() {
    use mss_core::contact::ContactPoints;
    let lattice = Lattice::block([2, 2, 1], 0.05, [0.0, 0.0, -0.01]).unwrap();
    let model = Model::new(
        &lattice,
        Material::new(1.0e5, 0.3, 1000.0).unwrap(),
        &SpringsOnly,
    )
    .unwrap();
    // A surface a little inside the block, so its vertices are embedded.
    let surface = hexmesh::generate::box_mesh([0.005, 0.005, -0.008], [0.095, 0.095, 0.04]);
    let embedding = hexmesh::Embedding::new(&lattice, &surface);
    for (which, obstacle) in [
        Box::new(Plane::new(Vec3::new(0.0, 0.0, 0.002), Vec3::new(0.1, -0.2, 1.0)).unwrap())
            as Box<dyn Obstacle>,
        Box::new(Sphere::new(Vec3::new(0.05, 0.05, -0.2), 0.203).unwrap()),
    ]
    .into_iter()
    .enumerate()
    {
        let s = ContactSettings::for_model(&model);
        let contact = Contact::with_points(
            &model,
            vec![(obstacle, s)],
            ContactPoints::Both,
            Some(&embedding),
        );
        let x0: Vec<Vec3> = model.rest_positions().to_vec();
        // Moving, damped (velocities following positions as in an implicit
        // step): the damping's derivative, the normal's turning included.
        let v: Vec<Vec3> = (0..x0.len())
            .map(|i| Vec3::new((1.3 * i as f64).sin(), (0.7 * i as f64).cos(), -1.0) * 1e-3)
            .collect();
        let dv_dx = 100.0;
        // Anchors a little away: some points stick, some slide.
        let anchors: Vec<Option<Vec3>> = contact
            .point_positions(&x0)
            .iter()
            .enumerate()
            .map(|(i, p)| {
                // Beyond mu times the depth the point slides.
                let far = if i % 3 == 0 { 0.02 } else { 1e-6 };
                Some(p + Vec3::new(far, -0.5 * far * (i % 2) as f64, 0.0))
            })
            .collect();
        let forces_at = |x: &[Vec3], v: &[Vec3]| {
            let mut f = vec![Vec3::zeros(); x.len()];
            contact.add_forces(0.0, x, v, &anchors, &mut f);
            f
        };
        let forces = |x: &[Vec3]| forces_at(x, &v);
        // Both regimes are exercised.
        let f0 = forces(&x0);
        assert!(f0.iter().any(|f| f.norm() > 0.0));
        let mut jac = mss_core::BlockCsr::lattice_pattern(model.num_nodes(), model.cells());
        contact.add_jacobian(0.0, &x0, &v, &anchors, dv_dx, &mut jac);
        let eps = 1e-9;
        let mut worst = 0.0f64;
        let scale = forces(&x0).iter().map(|f| f.norm()).fold(0.0, f64::max) / 1e-3;
        for b in 0..x0.len() {
            for d in 0..3 {
                let shifted = |sign: f64| {
                    let (mut xs, mut vs) = (x0.clone(), v.clone());
                    xs[b][d] += sign * eps;
                    vs[b][d] += sign * eps * dv_dx;
                    forces_at(&xs, &vs)
                };
                let (fp, fm) = (shifted(1.0), shifted(-1.0));
                for a in 0..x0.len() {
                    let fd = (fp[a] - fm[a]) / (2.0 * eps);
                    let exact = jac
                        .find(a, b)
                        .map_or(Vec3::zeros(), |k| jac.blocks[k].column(d).into());
                    worst = worst.max((fd - exact).norm());
                }
            }
        }
        // (Without the damping's turning term: 5.6e-7 of the scale.)
        assert!(worst < 1e-8 * scale, "obstacle {which}: {worst} vs {scale}");
    }
}

/// A held 8 x 8 x 4 block (1.25 cm cells) that `obstacle`, moving down by
/// `press` over 0.2 s, presses into, mu = 0.5, mass damping for the
/// dynamic runs.
fn deep_press(obstacle: impl Fn(Path) -> Box<dyn Obstacle>, press: f64) -> Problem {
    let lattice = Lattice::block([8, 8, 4], 0.0125, [0.0; 3]).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let model = Model::new(&lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &param).unwrap();
    let path = Path::new(vec![
        (0.0, Vec3::zeros()),
        (0.2, Vec3::new(0.0, 0.0, -press)),
    ])
    .unwrap();
    let base = [ConstraintSpec::fixed(NodeSelector::LowestLayer)];
    problem(
        model,
        Vec3::zeros(),
        obstacle(path),
        |s| s,
        mass_damping(60.0),
        &base,
    )
}

/// An obstacle of [`deep_press`] given its path.
type DeepObstacle = Box<dyn Fn(Path) -> Box<dyn Obstacle>>;

/// A box pressed 1.2 cells and a sphere 2 cells into [`deep_press`]'s block,
/// with the depth of each press.
fn deep_obstacles() -> [(&'static str, DeepObstacle, f64); 2] {
    [
        (
            "box",
            Box::new(|path| {
                let b = Cuboid::new(Vec3::new(0.03, 0.03, 0.05), Vec3::new(0.07, 0.07, 0.09));
                Box::new(b.unwrap().moving(path))
            }),
            0.015,
        ),
        (
            "sphere",
            Box::new(|path| {
                let s = Sphere::new(Vec3::new(0.05, 0.05, 0.08), 0.03).unwrap();
                Box::new(s.moving(path))
            }),
            0.025,
        ),
    ]
}

#[test]
fn a_static_solve_inserts_an_obstacle_placed_deep_without_a_path() {
    // The box and the sphere of the test below, placed where its presses
    // end, with no path: the static solve inserts each from outside along
    // its shortest way out (up), and gives what following the press gives
    // (which the test below checks against the press in time). Placed at
    // once, the box gave 8.2 N for 57.8 N.
    let cases = deep_obstacles();
    for (name, obstacle, press) in cases {
        let push = |p: &Problem, s: &State| p.contact_forces(s).iter().map(|f| f.z).sum::<f64>();
        let opts = StaticOptions {
            obstacles_from: Some(0.0),
            accept_unstable: true,
            ..StaticOptions::default()
        };
        let followed = deep_press(&obstacle, press);
        let mut reference = State::at_rest(followed.model());
        reference.time = 0.8;
        solve_static(&followed, &mut reference, &opts).unwrap();
        // The same obstacle held where the press ends.
        let at_end = Path::new(vec![(0.0, Vec3::new(0.0, 0.0, -press))]).unwrap();
        let placed = deep_press(|_| obstacle(at_end.clone()), press);
        for obstacles_from in [None, Some(0.0)] {
            let mut st = State::at_rest(placed.model());
            st.time = 0.8;
            let info = solve_static(
                &placed,
                &mut st,
                &StaticOptions {
                    obstacles_from,
                    ..opts
                },
            )
            .unwrap();
            assert!(info.load_steps >= 5, "{name}: inserted in increments");
            let (expected, got) = (push(&followed, &reference), push(&placed, &st));
            assert!(
                (got - expected).abs() < 0.02 * expected.abs(),
                "{name}: inserted {got} N vs followed {expected} N"
            );
            assert!(
                st.contact.iter().any(Option::is_some),
                "{name}: anchors kept"
            );
            // The obstacle is back where its path puts it.
            let (o, _) = placed.contact().unwrap().obstacles().next().unwrap();
            assert_eq!(o.offset(0.8), Vec3::new(0.0, 0.0, -press), "{name}");
        }
    }
}

#[test]
fn a_static_solve_follows_an_obstacle_pressed_deep_and_keeps_its_friction() {
    // A box 1.2 cells and a sphere 2 cells into the block: solved statically
    // at the end of the press, each must give what the slow press gives in
    // time (implicit, at rest), friction included. Placed there at once, the
    // box pushed the nodes near its edges out through its side faces (a fifth
    // of the force), and the state lost its friction anchors (the sphere's
    // force 25 % low).
    let cases = deep_obstacles();
    for (name, obstacle, press) in cases {
        let p = deep_press(obstacle, press);
        let push = |s: &State| p.contact_forces(s).iter().map(|f| f.z).sum::<f64>();
        let opts = ImplicitOptions {
            dt: 0.05,
            ..ImplicitOptions::default()
        };
        let mut it = Implicit::new(&p, opts).unwrap();
        let mut pressed = State::at_rest(p.model());
        while pressed.time < 0.8 - 1e-9 {
            it.step(&p, &mut pressed).unwrap();
        }
        let mut st = State::at_rest(p.model());
        st.time = 0.8;
        let opts = StaticOptions {
            obstacles_from: Some(0.0),
            accept_unstable: true,
            ..StaticOptions::default()
        };
        let info = solve_static(&p, &mut st, &opts).unwrap();
        assert!(info.load_steps >= 5, "{name}: followed in increments");
        let (dynamic, statics) = (push(&pressed), push(&st));
        assert!(
            (statics - dynamic).abs() < 0.02 * dynamic.abs(),
            "{name}: static {statics} N vs pressed in time {dynamic} N"
        );
        // Friction holds the surface: the anchors came with the state.
        assert!(st.contact.iter().any(Option::is_some), "{name}");
    }
}

/// The cheap inside test of the obstacles that override it (the explicit
/// step asks it of every surface node each sub-step) says exactly what
/// their penetration says, on points on both sides and on the surfaces,
/// moving along a path and steered by hand.
#[test]
fn contains_is_exactly_penetration_is_some() {
    use mss_core::contact::Steered;
    let path = Path::new(vec![(0.0, Vec3::zeros()), (1.0, Vec3::new(0.1, -0.2, 0.3))]).unwrap();
    let plane = Plane::new(Vec3::new(0.0, 0.0, 0.1), Vec3::new(0.3, -0.2, 1.0)).unwrap();
    let sphere = Sphere::new(Vec3::new(0.1, 0.2, 0.3), 0.25).unwrap();
    let (steered, hand) = Steered::new(Box::new(sphere.clone().moving(path.clone())));
    hand.move_to(Vec3::new(0.05, 0.0, -0.02), 0.01);
    let obstacles: Vec<Box<dyn Obstacle>> = vec![
        Box::new(plane.clone()),
        Box::new(plane.moving(path.clone())),
        Box::new(sphere.clone()),
        Box::new(sphere.moving(path)),
        Box::new(steered),
    ];
    let mut seed = 17u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let (mut inside, mut outside) = (0, 0);
    for o in &obstacles {
        for k in 0..2000 {
            let t = 1.2 * (next() + 0.5);
            let mut p = Vec3::new(next(), next(), next()) * 1.2;
            if k % 10 == 0 {
                // A point on the surface, where the two tests' `<` and `>=` meet.
                if let Some(pen) = o.penetration(t, p) {
                    p += pen.normal * pen.depth;
                }
            }
            let expect = o.penetration(t, p).is_some();
            assert_eq!(o.contains(t, p), expect, "{} at t = {t}, {p:?}", o.name());
            inside += usize::from(expect);
            outside += usize::from(!expect);
        }
    }
    assert!(inside > 1000 && outside > 1000, "{inside} {outside}");
    assert!(!obstacles[0].contains(0.0, Vec3::new(f64::NAN, 0.0, 0.0)));
    assert!(!obstacles[2].contains(0.0, Vec3::new(f64::NAN, 0.0, 0.0)));
}

/// The anchors' update of node points reports, for the points that stick,
/// the force `node_point_force` gives after it, bit for bit (the explicit
/// step starts its next sub-step with it), updates the anchors as
/// `update_anchors_of` does, and reports no point that slides or leaves:
/// a block sliding on a slope into a sphere, two obstacles at once, some
/// points sticking, some sliding, some touching both.
#[test]
fn the_anchors_update_reports_the_force_of_the_points_that_stick() {
    let mu = 0.5;
    let a = 0.6f64.atan();
    let g = Vec3::new(0.0, G * a.sin(), -G * a.cos());
    let sphere = || Sphere::new(Vec3::new(0.05, 0.12, 0.0), 0.03).unwrap();
    let model = block(0.0);
    let s = ContactSettings::for_model(&model);
    let friction = ContactSettings {
        friction_static: mu,
        friction_kinetic: 0.8 * mu,
        ..s
    };
    let obstacles: Vec<(Box<dyn Obstacle>, ContactSettings)> =
        vec![(ground(), friction), (Box::new(sphere()), friction)];
    let contact = Contact::new(&model, obstacles);
    let p = Problem::from_specs(
        model,
        &[],
        &[LoadSpec::Gravity { g: g.into() }],
        Damping::NONE,
    )
    .unwrap()
    .with_contact(contact);
    let contact = p.contact().unwrap();
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let (mut stuck, mut slid, mut both) = (0, 0, 0);
    while s.time < 0.15 {
        // The anchors of the step's start against its end: some stay,
        // some slide, some are new.
        let anchors = s.contact.clone();
        it.step(&p, &mut s).unwrap();
        let after_step = std::mem::replace(&mut s.contact, anchors);
        let nodes = contact.node_points();
        let mut want = s.contact.clone();
        contact.update_anchors_of(nodes, s.time, &s.x, &s.v, &mut want);
        let mut got = s.contact.clone();
        let mut kept = Vec::new();
        contact.update_anchors_keeping(nodes, s.time, &s.x, &s.v, &mut got, |i, f| {
            kept.push((i, f));
        });
        assert_eq!(got, want, "the same anchors at {}", s.time);
        let mut k = 0;
        for &i in nodes {
            let n = contact.point_node(i) as usize;
            let before =
                contact.node_point_force(i, s.time, s.x[n], s.v[n], 0.0, &s.contact, false);
            let after = contact.node_point_force(i, s.time, s.x[n], s.v[n], 0.0, &got, false);
            if kept.get(k).is_some_and(|&(j, _)| j == i) {
                let f = kept[k].1;
                k += 1;
                let after = after.expect("a kept point touches").0;
                assert_eq!(f.map(f64::to_bits), after.map(f64::to_bits), "point {i}");
                assert_eq!(before.map(|b| b.0), Some(f), "its anchors stayed");
                stuck += 1;
                let x = s.x[n];
                both += usize::from(sphere().contains(s.time, x) && x.z < 0.0);
            } else if after.is_some() && before.map(|b| b.0) != after.map(|a| a.0) {
                slid += 1;
            }
        }
        assert_eq!(k, kept.len(), "reported in the order asked");
        s.contact = after_step;
    }
    assert!(
        stuck > 0 && slid > 0,
        "{stuck} stuck, {slid} slid or touched anew"
    );
    assert!(both > 0, "no point sticks on both obstacles");
}
