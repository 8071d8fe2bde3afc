//! Internal-force evaluation speed (cell-steps per second).
//!
//! `cargo bench -p mss-core --bench step`; throughput is reported in cells
//! ("elements") per second.

#[path = "../examples/common/baseline.rs"]
mod baseline;
use baseline::{merged_springs, perturbed, spring_loop};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use hexmesh::Lattice;
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric};
use mss_core::{Material, Model, Parameterization, Vec3};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("internal_forces");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(300));
    group.measurement_time(std::time::Duration::from_secs(2));
    let material = Material::new(1000.0, 0.3, 1.0).unwrap();
    let alpha = HourglassControl::DEFAULT_ALPHA;
    let paper_hg = HourglassControl::new(Box::new(PaperModel), alpha).unwrap();
    let volumetric_hg = HourglassControl::new(Box::new(Volumetric), alpha).unwrap();
    for n in [32u32, 64] {
        let lattice = Lattice::block([n; 3], 1.0 / n as f64, [0.0; 3]).unwrap();
        for param in [
            &PaperModel as &dyn Parameterization,
            &SpringsOnly,
            &Volumetric,
            &paper_hg,
            &volumetric_hg,
        ] {
            let model = Model::new(&lattice, material, param).unwrap();
            let x = perturbed(&model);
            let mut ws = model.workspace();
            let mut out = vec![Vec3::zeros(); model.num_nodes()];
            eprintln!(
                "{} {n}^3: model {:.0} B/cell, workspace {:.0} B/cell",
                param.name(),
                model.memory_bytes() as f64 / model.num_cells() as f64,
                ws.memory_bytes() as f64 / model.num_cells() as f64
            );
            group.throughput(Throughput::Elements(model.num_cells() as u64));
            for threads in [1usize, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let id = BenchmarkId::new(format!("{}/{threads}t", param.name()), format!("{n}^3"));
                group.bench_function(id, |b| {
                    pool.install(|| b.iter(|| model.internal_forces_with(&x, &mut ws, &mut out)))
                });
            }
            if param.name() != "springs" {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(1)
                    .build()
                    .unwrap();
                let id = BenchmarkId::new(format!("{}/scalar-1t", param.name()), format!("{n}^3"));
                group.bench_function(id, |b| {
                    pool.install(|| {
                        b.iter(|| model.internal_forces_scalar_with(&x, &mut ws, &mut out))
                    })
                });
            } else {
                let springs = merged_springs(&lattice, &model);
                let id = BenchmarkId::new("spring-loop/1t", format!("{n}^3"));
                group.bench_function(id, |b| b.iter(|| spring_loop(&springs, &x, &mut out)));
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
