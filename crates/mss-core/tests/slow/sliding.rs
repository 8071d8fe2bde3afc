//! Friction with the implicit solver on a refined lattice.

use hexmesh::Lattice;
use mss_core::contact::{Contact, ContactSettings, Plane};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::{HourglassControl, VolumetricBarrier};
use mss_core::solver::{Implicit, ImplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model, Vec3};

/// An 8 x 8 x 4 block (1.25 cm cells, E = 1e5 Pa) sliding down a slope
/// (tan 0.7, mu = 0.5, no material damping, the default contact damping)
/// takes every implicit step of 1 ms whole, and slides at the rigid rate
/// g (sin - mu cos) within 3 %. Points that landed during a step used to
/// get the contact's damping force at once (`c |v_n|` at zero depth), with
/// friction's share of it: Newton could not descend across that jump, the
/// steps failed from 22 ms on at every halving, and at 0.15 s the solver
/// gave up.
#[test]
fn an_implicit_step_takes_a_refined_block_sliding_on_a_slope_whole() {
    const G: f64 = 9.81;
    let (tan, mu) = (0.7f64, 0.5);
    let lattice = Lattice::block([8, 8, 4], 0.0125, [0.0; 3]).unwrap();
    let param = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let model = Model::new(&lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &param).unwrap();
    let settings = ContactSettings {
        friction_static: mu,
        friction_kinetic: mu,
        ..ContactSettings::for_model(&model)
    };
    let ground = Plane::new(Vec3::zeros(), Vec3::z()).unwrap();
    let contact = Contact::new(&model, vec![(Box::new(ground), settings)]);
    let a = tan.atan();
    let gravity = LoadSpec::Gravity {
        g: [0.0, G * a.sin(), -G * a.cos()],
    };
    let p = Problem::from_specs(model, &[], &[gravity], Damping::NONE)
        .unwrap()
        .with_contact(contact);
    let mut it = Implicit::new(&p, ImplicitOptions::default()).unwrap();
    let mut s = State::at_rest(p.model());
    let masses = p.model().masses();
    let mut speed_at = |s: &mut State, t: f64| {
        while s.time < t - 1e-9 {
            let info = it.step(&p, s).unwrap();
            assert_eq!(info.substeps, 1, "the step to {} s was halved", info.time);
        }
        s.momentum(masses).y / p.model().total_mass()
    };
    let (v1, v2) = (speed_at(&mut s, 0.05), speed_at(&mut s, 0.25));
    let expected = G * (a.sin() - mu * a.cos());
    let got = (v2 - v1) / 0.2;
    assert!(
        (got - expected).abs() < 0.03 * expected,
        "{got} vs {expected} m/s^2"
    );
}
