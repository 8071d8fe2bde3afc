//! Explicit runs are bitwise identical for 1, 2 and 4 threads.

use hexmesh::Lattice;
use mss_core::constraints::{ConstraintSpec, NodeSelector};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::model::PaperModel;
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model, Vec3};

fn run(threads: usize) -> State {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
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
