//! Several bodies in one model: each body's forces are those it has alone,
//! bit for bit; a cube stacked on another carries its weight through their
//! contact (explicit, implicit and static), the contact forces between two
//! bodies are equal and opposite, and nothing sinks into anything.

use hexmesh::Lattice;
use mss_core::contact::{BodyContact, Contact, ContactSettings, Plane};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{
    Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator, Problem, State,
    StaticOptions, solve_static,
};
use mss_core::{ConstraintSpec, Material, Model, NodeSelector, SpringsOnly, Vec3};

const G: f64 = 9.81;

fn cube(n: u32, h: f64, origin: [f64; 3], e: f64) -> Model {
    let lattice = Lattice::block([n, n, n], h, origin).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    Model::new(&lattice, Material::new(e, 0.3, 1000.0).unwrap(), &param).unwrap()
}

#[test]
fn a_union_has_each_bodys_forces_and_energy_bit_for_bit() {
    let a = cube(3, 0.02, [0.0, 0.0, 0.0], 1e5);
    let b = cube(2, 0.035, [0.01, 0.0, 0.07], 4e5);
    let u = Model::union(&[a.clone(), b.clone()]).unwrap();
    assert_eq!(u.num_nodes(), a.num_nodes() + b.num_nodes());
    assert_eq!(u.bodies().len(), 2);
    assert_eq!(u.bodies()[1].nodes, a.num_nodes()..u.num_nodes());
    assert_eq!(u.bodies()[1].h, 0.035);
    assert_eq!(u.h(), 0.02);
    // A deformed state: every node moved differently.
    let deform = |m: &Model, s: f64| -> Vec<Vec3> {
        m.rest_positions()
            .iter()
            .enumerate()
            .map(|(i, p)| p + Vec3::new((i as f64 * s).sin(), (i as f64).cos(), 0.5) * 1e-3)
            .collect()
    };
    let (xa, xb) = (deform(&a, 0.7), deform(&b, 1.3));
    let xu: Vec<Vec3> = xa.iter().chain(&xb).copied().collect();
    let forces = |m: &Model, x: &[Vec3]| {
        let mut f = vec![Vec3::zeros(); m.num_nodes()];
        m.internal_forces(x, &mut f);
        f
    };
    let fu = forces(&u, &xu);
    let expected: Vec<Vec3> = forces(&a, &xa).into_iter().chain(forces(&b, &xb)).collect();
    assert_eq!(fu, expected);
    assert_eq!(u.energy(&xu), a.energy(&xa) + b.energy(&xb));
    assert_eq!(u.masses()[a.num_nodes()..], *b.masses());
    // The tangent's blocks of the second body are its own.
    let (tu, tb) = (u.tangent(&xu), b.tangent(&xb));
    let off = a.num_nodes();
    for i in 0..b.num_nodes() {
        for j in 0..b.num_nodes() {
            if let Some(k) = tb.find(i, j) {
                assert_eq!(tu.blocks[tu.find(i + off, j + off).unwrap()], tb.blocks[k]);
            }
        }
        assert!(tu.find(i + off, 0).is_none(), "no coupling between bodies");
    }
    // The stable step is the stiffer body's.
    let step = u.stable_time_step();
    assert!(step <= a.stable_time_step().min(b.stable_time_step()) * 1.0001);
}

/// Two cubes (the upper one softer and finer) stacked on the ground, the
/// upper one `gap` above the lower, under gravity, damped.
fn stack(gap: f64, damping: f64) -> Problem {
    stack_held(gap, damping, &[])
}

fn stack_held(gap: f64, damping: f64, fixed: &[ConstraintSpec]) -> Problem {
    let lower = cube(4, 0.025, [0.0, 0.0, 0.0], 2e5);
    let upper = cube(5, 0.016, [0.02, 0.01, 0.1 + gap], 1e5);
    let model = Model::union(&[lower, upper]).unwrap();
    let ground = Plane::new(Vec3::zeros(), Vec3::z()).unwrap();
    let bodies =
        BodyContact::new(&model, ContactSettings::for_bodies(&model), &[false, false]).unwrap();
    let contact = Contact::new(
        &model,
        vec![(Box::new(ground), ContactSettings::for_model(&model))],
    )
    .with_bodies(bodies);
    let gravity = LoadSpec::Gravity { g: [0.0, 0.0, -G] };
    Problem::from_specs(
        model,
        fixed,
        &[gravity],
        Damping {
            alpha: damping,
            beta: 0.0,
        },
    )
    .unwrap()
    .with_contact(contact)
}

fn body_mass(p: &Problem, b: usize) -> f64 {
    p.model().masses()[p.model().bodies()[b].nodes.clone()]
        .iter()
        .sum()
}

/// The upper body's weight goes through the contact between the bodies
/// within 1 %, equal and opposite, and the ground carries both; no point is
/// deeper in the other body than `depth`.
fn assert_stacked(p: &Problem, s: &State, what: &str) {
    let contact = p.contact().unwrap();
    let bodies = contact.bodies().unwrap();
    let between = bodies.body_forces(
        &s.x,
        &s.v,
        &s.contact[s.contact.len() - bodies.num_points()..],
    );
    let upper = body_mass(p, 1) * G;
    assert!(
        (between[1].z - upper).abs() < 0.01 * upper,
        "{what}: the upper body gets {} N up for its weight {upper} N",
        between[1].z
    );
    assert!(
        (between[0] + between[1]).norm() < 1e-9 * upper,
        "{what}: action != reaction"
    );
    let total: Vec3 = p.contact_forces(s).iter().sum();
    let weight = p.model().total_mass() * G;
    assert!(
        (total.z - weight).abs() < 0.01 * weight,
        "{what}: ground {} vs {weight}",
        total.z
    );
    let depth = bodies.max_depth(&s.x);
    let h = p.model().h();
    assert!(depth < 0.05 * h, "{what}: {depth} m deep in the other body");
}

#[test]
fn a_stacked_cube_rests_on_the_lower_one_in_the_explicit_solver() {
    let p = stack(0.002, 30.0);
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    while s.time < 0.6 {
        it.step(&p, &mut s).unwrap();
    }
    assert!(s.v.iter().all(|v| v.norm() < 2e-3), "at rest");
    assert_stacked(&p, &s, "explicit");
}

#[test]
fn a_stacked_cube_rests_on_the_lower_one_in_the_implicit_and_static_solvers() {
    let p = stack(0.0005, 30.0);
    let opts = ImplicitOptions {
        dt: 0.01,
        ..ImplicitOptions::default()
    };
    let mut it = Implicit::new(&p, opts).unwrap();
    let mut s = State::at_rest(p.model());
    while s.time < 0.8 {
        it.step(&p, &mut s).unwrap();
    }
    assert_stacked(&p, &s, "implicit");
}

#[test]
fn a_cube_pressed_on_a_held_one_settles_statically_with_equal_and_opposite_forces() {
    // The lower cube held at its base; the upper one starts 0.1 mm into it.
    let base = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0, -1.0, -1.0],
        max: [1.0, 1.0, 1e-6],
        relative: false,
    });
    let p = stack_held(-1e-4, 0.0, &[base]);
    let mut s = State::at_rest(p.model());
    solve_static(&p, &mut s, &StaticOptions::default()).unwrap();
    let bodies = p.contact().unwrap().bodies().unwrap();
    let between = bodies.body_forces(&s.x, &s.v, &s.contact);
    let upper = body_mass(&p, 1) * G;
    assert!(
        (between[1].z - upper).abs() < 0.01 * upper,
        "{between:?} for {upper}"
    );
    assert!((between[0] + between[1]).norm() < 1e-9 * upper);
    assert!(bodies.max_depth(&s.x) < 0.05 * p.model().h());
}

/// A static solve cannot settle a body that only contact holds and that
/// touches nothing at rest (here 5 mm above the held one): the error says
/// which body and what to do, not "fix a whole face".
#[test]
fn a_static_solve_names_the_body_only_contact_would_hold() {
    let base = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0, -1.0, -1.0],
        max: [1.0, 1.0, 1e-6],
        relative: false,
    });
    let p = stack_held(0.005, 0.0, &[base]);
    let mut s = State::at_rest(p.model());
    match solve_static(&p, &mut s, &StaticOptions::default()) {
        Err(mss_core::solver::SolverError::Mechanism { message, nodes }) => {
            assert!(message.contains("body 2 (counted from 1)"), "{message}");
            assert!(message.contains("only contact holds it"), "{message}");
            assert!(
                nodes
                    .iter()
                    .all(|&n| p.model().body_of_node(n as usize) == 1)
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn contact_between_bodies_keeps_momentum_and_does_not_depend_on_threads() {
    // The upper cube starts 1 mm inside the lower one, sideways offset.
    let p = stack(-0.001, 0.0);
    let contact = p.contact().unwrap();
    let s = State::at_rest(p.model());
    let bodies = contact.bodies().unwrap();
    let mut f = vec![Vec3::zeros(); p.model().num_nodes()];
    bodies.add_forces(&s.x, &s.v, &[], &mut f);
    let total: Vec3 = f.iter().sum();
    let largest = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(largest > 0.0, "they overlap: contact forces");
    assert!(total.norm() < 1e-12 * largest * f.len() as f64, "{total:?}");
    let mut f1 = vec![Vec3::zeros(); p.model().num_nodes()];
    crate::on_threads(1, || bodies.add_forces(&s.x, &s.v, &[], &mut f1));
    assert_eq!(f, f1);
}

#[test]
fn the_contact_tangent_between_bodies_matches_finite_differences() {
    // Frictionless, undamped: the force is the gradient of k d^2 / 2, and
    // the tangent its exact derivative, the normal's turning and the
    // projections' sliding included (they are a relative 1e-3 here, depth
    // over cell size: 20 um in 16 mm cells, which the tangent once left out).
    let p = stack(-2e-5, 0.0);
    let model = p.model();
    let settings = ContactSettings {
        friction_static: 0.0,
        friction_kinetic: 0.0,
        damping_ratio: 0.0,
        ..ContactSettings::for_bodies(model)
    };
    let bodies = BodyContact::new(model, settings, &[false, false]).unwrap();
    let x: Vec<Vec3> = model
        .rest_positions()
        .iter()
        .enumerate()
        .map(|(i, r)| r + Vec3::new((i as f64).sin(), (i as f64 * 0.3).cos(), 0.0) * 1e-6)
        .collect();
    let (worst, scale) = tangent_error(&bodies, model, &x, 7);
    assert!(worst < 1e-6 * scale, "worst {worst} of {scale}");
}

/// The largest difference between `bodies`' contact tangent at `x` (at
/// rest) and finite differences of its forces, over the touching nodes
/// (every `stride`-th perturbed), and the tangent's largest block norm.
fn tangent_error(bodies: &BodyContact, model: &Model, x: &[Vec3], stride: usize) -> (f64, f64) {
    let v = vec![Vec3::zeros(); x.len()];
    let mut jac = model.tangent(x);
    jac.blocks
        .iter_mut()
        .for_each(|b| *b = mss_core::Mat3::zeros());
    bodies.add_jacobian(x, &v, &[], 1.0, &mut jac);
    let force = |x: &[Vec3]| {
        let mut f = vec![Vec3::zeros(); x.len()];
        bodies.add_forces(x, &v, &[], &mut f);
        f
    };
    let f0 = force(x);
    let touching: Vec<usize> = (0..x.len()).filter(|&i| f0[i].norm() > 0.0).collect();
    assert!(touching.len() > 10);
    let eps = 1e-9;
    let mut worst = 0.0f64;
    let scale = jac.blocks.iter().map(|b| b.norm()).fold(0.0, f64::max);
    for &j in touching.iter().step_by(stride) {
        for d in 0..3 {
            let mut xp = x.to_vec();
            xp[j][d] += eps;
            let fp = force(&xp);
            for &i in &touching {
                let fd = (fp[i] - f0[i]) / eps;
                let exact = jac
                    .find(i, j)
                    .map_or(Vec3::zeros(), |k| jac.blocks[k].column(d).into());
                worst = worst.max((fd - exact).norm());
            }
        }
    }
    (worst, scale)
}

#[test]
fn a_union_of_problems_keeps_each_bodys_constraints_and_loads() {
    // Two held cubes apart, each pushed sideways by its own force: solved
    // together, each ends where it ends alone.
    let part = |origin: [f64; 3], force: [f64; 3]| {
        let m = cube(3, 0.02, origin, 1e5);
        let base = ConstraintSpec::fixed(NodeSelector::Box {
            min: [-1.0, -1.0, -1.0],
            max: [1.0, 1.0, origin[2] + 1e-6],
            relative: false,
        });
        let push = LoadSpec::Force {
            select: NodeSelector::Box {
                min: [-1.0, -1.0, origin[2] + 0.059],
                max: [1.0, 1.0, 1.0],
                relative: false,
            },
            force,
            distribution: Default::default(),
        };
        Problem::from_specs(m, &[base], &[push], Damping::NONE).unwrap()
    };
    let solve = |p: &Problem| {
        let mut s = State::at_rest(p.model());
        solve_static(p, &mut s, &StaticOptions::default()).unwrap();
        s.x
    };
    let a = part([0.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
    let b = part([0.5, 0.0, 0.2], [0.0, -3.0, 0.0]);
    let (xa, xb) = (solve(&a), solve(&b));
    let u = Problem::union(vec![a, b]).unwrap();
    assert_eq!(u.constraints().num_held_dofs(), 2 * 3 * 16);
    let xu = solve(&u);
    let alone: Vec<Vec3> = xa.into_iter().chain(xb).collect();
    let rest = u.model().rest_positions();
    let scale = alone
        .iter()
        .zip(rest)
        .map(|(x, r)| (x - r).norm())
        .fold(0.0, f64::max);
    let worst = xu
        .iter()
        .zip(&alone)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max);
    assert!(scale > 1e-5 && worst < 1e-6 * scale, "{worst} of {scale}");
}

#[test]
fn a_cube_dropped_on_another_gains_no_energy_without_damping() {
    // The lower cube held at its base, the upper one dropped from 3 mm,
    // no damping anywhere (material or contact), no friction: the energy
    // (kinetic, elastic, gravity, contact) may only be lost, never gained.
    let base = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0, -1.0, -1.0],
        max: [1.0, 1.0, 1e-6],
        relative: false,
    });
    // Springs only: every force has an energy.
    let springs = |n: u32, h: f64, origin: [f64; 3], e: f64| {
        let lattice = Lattice::block([n, n, n], h, origin).unwrap();
        Model::new(
            &lattice,
            Material::new(e, 0.3, 1000.0).unwrap(),
            &SpringsOnly,
        )
        .unwrap()
    };
    let lower = springs(4, 0.025, [0.0, 0.0, 0.0], 2e5);
    // Inside the lower cube's top face: its edges are not the lower's.
    let upper = springs(5, 0.016, [0.01, 0.01, 0.103], 1e5);
    let model = Model::union(&[lower, upper]).unwrap();
    let settings = ContactSettings {
        friction_static: 0.0,
        friction_kinetic: 0.0,
        damping_ratio: 0.0,
        ..ContactSettings::for_bodies(&model)
    };
    let bodies = BodyContact::new(&model, settings, &[false, false]).unwrap();
    let contact = Contact::new(&model, Vec::new()).with_bodies(bodies);
    let gravity = LoadSpec::Gravity { g: [0.0, 0.0, -G] };
    let p = Problem::from_specs(model, &[base], &[gravity], Damping::NONE)
        .unwrap()
        .with_contact(contact);
    let model = p.model();
    let energy = |s: &State| {
        let potential: f64 =
            s.x.iter()
                .zip(model.masses())
                .map(|(x, m)| m * G * x.z)
                .sum();
        s.kinetic_energy(model.masses())
            + model.energy(&s.x)
            + potential
            + p.contact().unwrap().energy(s.time, &s.x)
    };
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(model);
    let e0 = energy(&s);
    let upper_mass: f64 = model.masses()[model.bodies()[1].nodes.clone()].iter().sum();
    let drop = upper_mass * G * 0.003;
    let (mut worst, mut touched) = (f64::MIN, false);
    while s.time < 0.15 {
        it.step(&p, &mut s).unwrap();
        worst = worst.max(energy(&s) - e0);
        touched |= p.contact().unwrap().bodies().unwrap().max_depth(&s.x) > 0.0;
    }
    assert!(touched, "it must have landed");
    assert!(worst < 0.01 * drop, "gained {worst} J of a {drop} J drop");
}

/// A U of 1 cm cells (base 8 x 2 x 2, arms 2 x 2 x 6, a 4 cm slot between
/// them) held at its base, the top of the left arm driven 6 cm to the right
/// in 0.2 s, into the right arm; with or without self-contact.
fn folded_u(self_contact: bool) -> (Problem, State) {
    let h = 0.01;
    let cells =
        (0..8u32).flat_map(|x| (0..2u32).flat_map(move |y| (0..8u32).map(move |z| [x, y, z])));
    let cells = cells.filter(|&[x, _, z]| z < 2 || !(2..6).contains(&x));
    let lattice = Lattice::from_cells([0.0; 3], h, [8, 2, 8], cells).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let model = Model::new(&lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &param).unwrap();
    let base = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0, -1.0, -1.0],
        max: [1.0, 1.0, 1e-6],
        relative: false,
    });
    let drive = ConstraintSpec {
        select: NodeSelector::Box {
            min: [-1.0, -1.0, 0.08 - 1e-6],
            max: [0.02 + 1e-6, 1.0, 1.0],
            relative: false,
        },
        dofs: mss_core::constraints::Dofs::ALL,
        motion: mss_core::constraints::Motion::Velocity([0.3, 0.0, 0.0]),
    };
    let contact = Contact::new(&model, Vec::new()).with_bodies(
        BodyContact::new(&model, ContactSettings::for_bodies(&model), &[self_contact]).unwrap(),
    );
    let p = Problem::from_specs(
        model,
        &[base, drive],
        &[],
        Damping {
            alpha: 20.0,
            beta: 0.0,
        },
    )
    .unwrap()
    .with_contact(contact);
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    while s.time < 0.2 {
        it.step(&p, &mut s).unwrap();
    }
    (p, s)
}

#[test]
fn self_contact_keeps_a_folded_body_from_passing_through_itself() {
    // Without it the driven arm's tip ends 2 cm inside the other arm.
    let (p, s) = folded_u(false);
    let deepest_x =
        s.x.iter()
            .zip(p.model().rest_positions())
            .filter(|(_, r)| r.x < 0.02 + 1e-9 && r.z > 0.07)
            .map(|(x, _)| x.x)
            .fold(f64::MIN, f64::max);
    assert!(
        deepest_x > 0.075,
        "without self-contact the arm passes in: {deepest_x}"
    );
    // With it, nothing is deeper than a fifth of a cell in the other arm,
    // which is pushed aside.
    let (p, s) = folded_u(true);
    let bodies = p.contact().unwrap().bodies().unwrap();
    let depth = bodies.max_depth(&s.x);
    assert!(depth < 0.2 * 0.01, "{depth} m deep");
    let pushed =
        s.x.iter()
            .zip(p.model().rest_positions())
            .filter(|(_, r)| r.x > 0.07 && r.z > 0.07)
            .map(|(x, r)| x.x - r.x)
            .fold(f64::MIN, f64::max);
    assert!(pushed > 0.005, "the other arm is pushed: {pushed}");
}

#[test]
fn bodies_in_contact_step_the_same_bits_on_any_thread_count() {
    let run = |threads: usize| {
        crate::on_threads(threads, || {
            let p = stack(-0.0005, 5.0);
            let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
            let mut s = State::at_rest(p.model());
            for _ in 0..100 {
                it.step(&p, &mut s).unwrap();
            }
            let implicit = Implicit::new(
                &p,
                ImplicitOptions {
                    dt: 0.002,
                    ..ImplicitOptions::default()
                },
            );
            let mut it = implicit.unwrap();
            for _ in 0..3 {
                it.step(&p, &mut s).unwrap();
            }
            s
        })
    };
    let one = run(1);
    assert!(one.contact.iter().any(Option::is_some), "in contact");
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}

#[test]
fn a_cube_thrown_fast_onto_another_bounces_off_it_and_does_not_pass_through() {
    // At 8 m/s the upper cube's base goes more than half a cell into the
    // lower one in one or two steps: the points that touched are pushed
    // back out of the side they came in through. (Before, they were taken
    // for inside the lower cube's far faces: at 8 m/s it passed through.)
    let lower = cube(8, 0.0125, [0.0; 3], 2e5);
    let upper = cube(8, 0.0075, [0.01, 0.01, 0.101], 1e5);
    let model = Model::union(&[lower, upper]).unwrap();
    let bodies =
        BodyContact::new(&model, ContactSettings::for_bodies(&model), &[false, false]).unwrap();
    let contact = Contact::new(&model, Vec::new()).with_bodies(bodies);
    let base = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0; 3],
        max: [1.0, 1.0, 1e-6],
        relative: false,
    });
    let p = Problem::from_specs(model, &[base], &[], Damping::NONE)
        .unwrap()
        .with_contact(contact);
    let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let (lower, upper) = (
        p.model().bodies()[0].nodes.clone(),
        p.model().bodies()[1].nodes.clone(),
    );
    for v in &mut s.v[upper.clone()] {
        v.z = -8.0;
    }
    let bodies = p.contact().unwrap().bodies().unwrap();
    let mut deepest = 0.0f64;
    while s.time < 0.05 {
        it.step(&p, &mut s).unwrap();
        let anchors = &s.contact[s.contact.len() - bodies.num_points()..];
        deepest = deepest.max(bodies.max_depth_with(&s.x, anchors));
    }
    assert!(
        deepest > 0.5 * 0.0125,
        "deeper than the search reaches: {deepest}"
    );
    let low = |r: std::ops::Range<usize>| s.x[r].iter().map(|x| x.z).fold(f64::MAX, f64::min);
    let high = |r: std::ops::Range<usize>| s.x[r].iter().map(|x| x.z).fold(f64::MIN, f64::max);
    assert!(
        low(upper.clone()) > high(lower.clone()) - 0.001,
        "it bounced off the top"
    );
    assert!(
        s.v[upper].iter().map(|v| v.z).sum::<f64>() > 0.0,
        "moving up again"
    );
}

/// A 4 x 4 x 2 block (E = 1e5) on a held slab long enough to slide on for
/// 0.4 s, gravity turned by the slope `tan`, mu = 0.5, no damping.
fn block_on_slab(tan: f64) -> Problem {
    let model = |lattice: &Lattice| {
        let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
        Model::new(lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &param).unwrap()
    };
    let slab = Lattice::block([8, 24, 1], 0.025, [-0.05, -0.05, -0.025]).unwrap();
    let block = Lattice::block([4, 4, 2], 0.025, [0.0; 3]).unwrap();
    let everything = ConstraintSpec::fixed(NodeSelector::Box {
        min: [-1.0; 3],
        max: [1.0; 3],
        relative: false,
    });
    let a = tan.atan();
    let gravity = LoadSpec::Gravity {
        g: [0.0, G * a.sin(), -G * a.cos()],
    };
    let slab = Problem::from_specs(model(&slab), &[everything], &[], Damping::NONE).unwrap();
    let block = Problem::from_specs(model(&block), &[], &[gravity], Damping::NONE).unwrap();
    let u = Problem::union(vec![slab, block]).unwrap();
    let settings = ContactSettings {
        friction_static: 0.5,
        friction_kinetic: 0.5,
        ..ContactSettings::for_bodies(u.model())
    };
    let bodies = BodyContact::new(u.model(), settings, &[false, false]).unwrap();
    let contact = Contact::new(u.model(), vec![]).with_bodies(bodies);
    u.with_contact(contact)
}

#[test]
fn a_block_slides_down_another_body_at_the_rigid_rate_in_both_solvers() {
    // The slab's points that the sliding block's leading edge passes over
    // lie inside the block behind its front face as well as its bottom:
    // pushed out through the front face they held it back (11 % slow), and
    // anchors kept on the triangle first touched, extrapolated ever
    // farther, made the implicit solve run away. Each point now touches
    // the surface that faces it, and its anchor moves with it.
    let tan: f64 = 0.8;
    let p = block_on_slab(tan);
    let rigid = G * (tan.atan().sin() - 0.5 * tan.atan().cos());
    let block = p.model().bodies()[1].nodes.clone();
    let masses = p.model().masses();
    let mass: f64 = masses[block.clone()].iter().sum();
    let speed = |s: &State| block.clone().map(|i| masses[i] * s.v[i].y).sum::<f64>() / mass;
    let explicit = Explicit::new(&p, ExplicitOptions::default()).unwrap();
    let opts = ImplicitOptions {
        dt: 1e-3,
        ..ImplicitOptions::default()
    };
    let implicit = Implicit::new(&p, opts).unwrap();
    for (name, mut it) in [
        ("explicit", Box::new(explicit) as Box<dyn Integrator>),
        ("implicit", Box::new(implicit)),
    ] {
        let mut s = State::at_rest(p.model());
        let (mut v1, mut normal, mut friction) = (0.0, 0.0, 0.0);
        while s.time < 0.4 - 1e-9 {
            it.step(&p, &mut s).unwrap();
            if s.time <= 0.1 {
                v1 = speed(&s);
                continue;
            }
            let f = p.contact_forces(&s);
            normal += block.clone().map(|i| f[i].z).sum::<f64>();
            friction -= block.clone().map(|i| f[i].y).sum::<f64>();
        }
        let got = (speed(&s) - v1) / 0.3;
        assert!(
            (got - rigid).abs() < 0.05 * rigid,
            "{name}: {got} vs {rigid} m/s^2"
        );
        assert!(
            friction < 0.5 * normal * 1.01,
            "{name}: the block is held by more than friction: {friction} vs {normal}"
        );
    }
}

/// Contact through the embedded surfaces ([`BodyContact::on_surface`]): a
/// cube's refined surface slightly pressed into another's. The forces sum
/// to zero (momentum), and the tangent, mapped to the nodes through the
/// trilinear weights, matches finite differences of the forces, also for
/// the vertices just outside a body that touch the rim of a face whose
/// plane they are below (the upper cube stands within the lower one's top).
#[test]
fn surface_contact_between_bodies_keeps_momentum_and_its_tangent_matches_finite_differences() {
    let (lower_lattice, upper_lattice) = (
        Lattice::block([4, 4, 4], 0.025, [0.0, 0.0, 0.0]).unwrap(),
        Lattice::block([5, 5, 5], 0.016, [0.01, 0.01, 0.1 - 2e-5]).unwrap(),
    );
    let model = |l: &Lattice, e: f64| {
        let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
        Model::new(l, Material::new(e, 0.3, 1000.0).unwrap(), &param).unwrap()
    };
    let union = Model::union(&[model(&lower_lattice, 2e5), model(&upper_lattice, 1e5)]).unwrap();
    // The surfaces as the lattices' boxes, refined to a cell (what a scene
    // with `[contact] points = "both"` builds), and turned inward for the
    // upper one: the contact turns it back.
    let lower_mesh = hexmesh::generate::box_mesh([0.0; 3], [0.1; 3]).refined(0.025);
    let mut upper_mesh =
        hexmesh::generate::box_mesh([0.01, 0.01, 0.1 - 2e-5], [0.09, 0.09, 0.18 - 2e-5])
            .refined(0.016);
    upper_mesh.triangles.iter_mut().for_each(|t| t.swap(1, 2));
    let mut surface = hexmesh::Embedding::new(&lower_lattice, &lower_mesh);
    surface.append(
        &hexmesh::Embedding::new(&upper_lattice, &upper_mesh),
        lower_lattice.num_nodes() as u32,
    );
    let settings = ContactSettings {
        friction_static: 0.0,
        friction_kinetic: 0.0,
        damping_ratio: 0.0,
        ..ContactSettings::for_bodies(&union)
    };
    let bodies = BodyContact::on_surface(&union, &surface, settings, &[false, false]).unwrap();
    assert!(bodies.on_embedded_surface());
    assert_eq!(
        bodies.num_points(),
        lower_mesh.vertices.len() + upper_mesh.vertices.len()
    );
    let x: Vec<Vec3> = union
        .rest_positions()
        .iter()
        .enumerate()
        .map(|(i, r)| r + Vec3::new((i as f64).sin(), (i as f64 * 0.3).cos(), 0.0) * 1e-6)
        .collect();
    let v = vec![Vec3::zeros(); x.len()];
    let force = |x: &[Vec3]| {
        let mut f = vec![Vec3::zeros(); x.len()];
        bodies.add_forces(x, &v, &[], &mut f);
        f
    };
    let f0 = force(&x);
    let total: Vec3 = f0.iter().sum();
    let largest = f0.iter().map(|f| f.norm()).fold(0.0, f64::max);
    assert!(largest > 0.0, "the surfaces touch");
    assert!(total.norm() < 1e-12 * largest * x.len() as f64, "{total}");
    // The upper body is pushed up.
    let per_body = bodies.body_forces(&x, &v, &[]);
    assert!(per_body[1].z > 0.0 && (per_body[0] + per_body[1]).norm() < 1e-12);
    let (worst, scale) = tangent_error(&bodies, &union, &x, 5);
    assert!(worst < 1e-6 * scale, "worst {worst} of {scale}");
}
