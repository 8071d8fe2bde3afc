//! Explicit, implicit and static results are bitwise identical for 1, 2 and 4 threads.

use hexmesh::Lattice;
use mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::PaperModel;
use mss_core::solver::{
    Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator, Problem, State,
    StaticOptions, solve_static,
};
use mss_core::{Material, Model, Vec3};

fn run(threads: usize) -> State {
    crate::on_threads(threads, || {
        // 25 x 20 x 20 = 10^4 cells.
        let lattice = Lattice::block([25, 20, 20], 0.01, [0.0; 3]).unwrap();
        let model = Model::new(
            &lattice,
            Material::new(1e4, 0.3, 100.0).unwrap(),
            &PaperModel,
        )
        .unwrap();
        let p = Problem::from_specs(
            model,
            &[ConstraintSpec::fixed(NodeSelector::LowestLayer)],
            &[LoadSpec::Gravity {
                g: [1.0, 0.0, -9.81],
            }],
            Damping {
                alpha: 1.0,
                beta: 1e-5,
            },
        )
        .unwrap();
        let mut s = State::at_rest(p.model());
        for (i, v) in s.v.iter_mut().enumerate() {
            *v = Vec3::new((i as f64 * 0.37).sin(), (i as f64 * 0.11).cos(), 0.0) * 1e-3;
        }
        p.apply_constraints(&mut s);
        let mut it = Explicit::new(&p, ExplicitOptions::default()).unwrap();
        for _ in 0..100 {
            it.step(&p, &mut s).unwrap();
        }
        s
    })
}

#[test]
fn explicit_is_bitwise_identical_for_1_2_4_threads() {
    let one = run(1);
    // The run must actually move (a frozen state would be trivially identical).
    assert!(one.v.iter().any(|v| v.norm() > 1e-4));
    for t in [2, 4] {
        let other = run(t);
        assert!(one.time == other.time);
        let same = one
            .x
            .iter()
            .chain(&one.v)
            .zip(other.x.iter().chain(&other.v))
            .all(|(a, b)| {
                a.iter()
                    .zip(b.iter())
                    .all(|(p, q)| p.to_bits() == q.to_bits())
            });
        assert!(same, "{t} threads differ from 1 thread");
    }
}

fn bits(s: &State) -> Vec<u64> {
    s.x.iter()
        .chain(&s.v)
        .flat_map(|v| v.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
        .collect()
}

/// A 12x3x3 cantilever under a large gravity load: a static solve and 5
/// implicit steps at 20 times the explicit limit, in a pool of `threads`.
fn implicit_and_static(threads: usize) -> (State, State) {
    crate::on_threads(threads, || {
        let lattice = Lattice::block([12, 3, 3], 0.025, [0.0; 3]).unwrap();
        let model = Model::new(
            &lattice,
            Material::new(1000.0, 0.3, 3.0).unwrap(),
            &PaperModel,
        )
        .unwrap();
        let p = Problem::from_specs(
            model,
            &[ConstraintSpec::fixed(NodeSelector::face(
                mss_core::constraints::Face::XMin,
            ))],
            &[LoadSpec::Gravity {
                g: [0.0, 0.0, -9.81],
            }],
            Damping {
                alpha: 2.0,
                beta: 0.0,
            },
        )
        .unwrap();
        let mut statics = State::at_rest(p.model());
        solve_static(&p, &mut statics, &StaticOptions::default()).unwrap();
        let mut dynamic = State::at_rest(p.model());
        let dt = 20.0 * p.model().critical_time_step();
        let mut it = Implicit::new(
            &p,
            ImplicitOptions {
                dt,
                ..ImplicitOptions::default()
            },
        )
        .unwrap();
        for _ in 0..5 {
            it.step(&p, &mut dynamic).unwrap();
        }
        (statics, dynamic)
    })
}

#[test]
fn implicit_and_static_are_bitwise_identical_for_1_2_4_threads() {
    let (s1, d1) = implicit_and_static(1);
    let rest = State::at_rest(
        &Model::new(
            &Lattice::block([12, 3, 3], 0.025, [0.0; 3]).unwrap(),
            Material::new(1000.0, 0.3, 3.0).unwrap(),
            &PaperModel,
        )
        .unwrap(),
    );
    assert_ne!(
        bits(&s1),
        bits(&rest),
        "the static solve must move the beam"
    );
    assert_ne!(
        bits(&d1),
        bits(&rest),
        "the implicit steps must move the beam"
    );
    for t in [2, 4] {
        let (s, d) = implicit_and_static(t);
        assert!(
            bits(&s) == bits(&s1),
            "static: {t} threads differ from 1 thread"
        );
        assert!(
            bits(&d) == bits(&d1),
            "implicit: {t} threads differ from 1 thread"
        );
    }
}
