//! One static solve of the docs/model.md cantilever (0.4 x 0.1 x 0.1 m, 32x8x8
//! cells, paper model, nu = 0.3, gravity, x = 0 fixed), under the small load
//! and under the large-deflection load (total mass 0.0125 kg, 16x4x4).

use criterion::{Criterion, criterion_group, criterion_main};
use hexmesh::Lattice;
use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
use mss_core::loads::{Damping, LoadSpec};
use mss_core::solver::{Problem, State, StaticOptions, solve_static};
use mss_core::{Material, Model, PaperModel};

fn bench(c: &mut Criterion) {
    let lattice = Lattice::block([32, 8, 8], 0.4 / 32.0, [0.0; 3]).unwrap();
    let model = Model::new(
        &lattice,
        Material::new(1000.0, 0.3, 0.01).unwrap(),
        &PaperModel,
    )
    .unwrap();
    let problem = cantilever(model);
    let large = cantilever(
        Model::new(
            &Lattice::block([16, 4, 4], 0.4 / 16.0, [0.0; 3]).unwrap(),
            Material::new(1000.0, 0.3, 3.125).unwrap(),
            &PaperModel,
        )
        .unwrap(),
    );
    let mut group = c.benchmark_group("static_solve");
    group.sample_size(10);
    group.bench_function("cantilever_32x8x8", |b| {
        b.iter(|| {
            let mut s = State::at_rest(problem.model());
            solve_static(&problem, &mut s, &StaticOptions::default()).unwrap()
        })
    });
    group.bench_function("cantilever_large_16x4x4", |b| {
        b.iter(|| {
            let mut s = State::at_rest(large.model());
            solve_static(&large, &mut s, &StaticOptions::default()).unwrap()
        })
    });
    group.finish();
}

fn cantilever(model: Model) -> Problem {
    Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping::NONE,
    )
    .unwrap()
}

criterion_group!(benches, bench);
criterion_main!(benches);
