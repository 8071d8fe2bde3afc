//! Load + voxelize the bunny at 64, 128 and 256 cells along its longest axis,
//! on 1 and 2 threads, and parry's flood-fill voxelizer at the same resolution.
//!
//! ```text
//! cargo bench -p hexmesh --bench voxelize
//! ```

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use hexmesh::{Resolution, VoxelizeOptions, load_mesh, voxelize};

fn bunny_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/meshes/bunny.obj")
}

fn bench(c: &mut Criterion) {
    let path = bunny_path();
    let mut group = c.benchmark_group("bunny");
    group.sample_size(10);
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        for n in [64u32, 128, 256] {
            let opts = VoxelizeOptions {
                resolution: Resolution::CellsAlongLongestAxis(n),
                max_cells: 100_000_000,
                ..Default::default()
            };
            group.bench_with_input(
                BenchmarkId::new(format!("load+voxelize/{threads}t"), n),
                &n,
                |b, _| {
                    b.iter(|| {
                        pool.install(|| {
                            let mesh = load_mesh(&path).expect("bunny").mesh;
                            black_box(
                                voxelize(&mesh, &opts)
                                    .expect("voxelize")
                                    .lattice
                                    .num_cells(),
                            )
                        })
                    })
                },
            );
        }
    }
    let mesh = load_mesh(&path).expect("bunny").mesh;
    let points: Vec<parry3d_f64::math::Vector> = mesh
        .vertices
        .iter()
        .map(|p| parry3d_f64::math::Vector::new(p[0], p[1], p[2]))
        .collect();
    for n in [64u32, 128, 256] {
        group.bench_with_input(BenchmarkId::new("parry-flood-fill", n), &n, |b, &n| {
            use parry3d_f64::transformation::voxelization::{FillMode, VoxelSet};
            b.iter(|| {
                let fill = FillMode::FloodFill {
                    detect_cavities: false,
                };
                black_box(VoxelSet::voxelize(&points, &mesh.triangles, n, fill, false).len())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
