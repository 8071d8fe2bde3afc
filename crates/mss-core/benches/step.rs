//! Internal-force evaluation speed (cell-steps per second).
//!
//! `cargo bench -p mss-core --bench step`; throughput is reported in cells
//! ("elements") per second.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use hexmesh::Lattice;
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric};
use mss_core::{Material, Model, Parameterization, Vec3};

fn perturbed(model: &Model) -> Vec<Vec3> {
    let h = model.h();
    model
        .rest_positions()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let s = ((i as f64) * 0.618).fract() - 0.5;
            Vec3::new(
                1.01 * p.x + 0.05 * s * h,
                p.y - 0.03 * s * h,
                p.z + 0.02 * p.x,
            )
        })
        .collect()
}

/// Merged springs `(a, b, k, rest)` of the springs-only model: the
/// straightforward spring-loop baseline.
fn merged_springs(lattice: &Lattice, model: &Model) -> Vec<(u32, u32, f64, f64)> {
    let co = model.cell_coefficients(0);
    let h = model.h();
    let mut edges: Vec<(u32, u32)> = Vec::new();
    let mut springs = Vec::new();
    for cell in lattice.cells() {
        for &(a, b, _) in &hexmesh::CELL_EDGES {
            edges.push((cell[a], cell[b]));
        }
        for &(a, b) in &hexmesh::CELL_DIAGONALS {
            springs.push((cell[a], cell[b], co.k_diag, 3f64.sqrt() * h));
        }
    }
    edges.sort_unstable();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i;
        while j < edges.len() && edges[j] == edges[i] {
            j += 1;
        }
        springs.push((edges[i].0, edges[i].1, (j - i) as f64 * co.k_edge, h));
        i = j;
    }
    springs.sort_unstable_by_key(|s| (s.0, s.1));
    springs
}

fn spring_loop(springs: &[(u32, u32, f64, f64)], x: &[Vec3], out: &mut [Vec3]) {
    out.fill(Vec3::zeros());
    for &(a, b, k, rest) in springs {
        let d = x[b as usize] - x[a as usize];
        let l = d.norm();
        let f = d * (k * (1.0 - rest / l));
        out[a as usize] += f;
        out[b as usize] -= f;
    }
}

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
