//! Writing speed of lattice frames (issue: explicit step at the bandwidth
//! limit, writing): a frame of an N^3 block with the point and cell fields of
//! a run, as `.vtu` with each encoding, and its skin as OBJ; bytes of the
//! file per second of wall time (best of REPEATS), on the threads rayon has.
//!
//!     cargo run --release -p mss-io --example write_speed [N] [REPEATS]

use std::time::Instant;

use mss_io::vtk::{Field, LatticeFrame, VtuEncoding, write_vtu};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(128);
    let repeats: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(3);
    let m = n + 1;
    let node = |i: usize, j: usize, k: usize| (i + m * (j + m * k)) as u32;
    let h = 1.0 / n as f64;
    let mut points = Vec::with_capacity(m * m * m);
    for k in 0..m {
        for j in 0..m {
            for i in 0..m {
                // A smooth deformation, as a run's frames have.
                let (x, y, z) = (i as f64 * h, j as f64 * h, k as f64 * h);
                points.push([x + 0.01 * (3.0 * z).sin(), y, z - 0.02 * x * x]);
            }
        }
    }
    let mut cells = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                cells.push([
                    node(i, j, k),
                    node(i + 1, j, k),
                    node(i + 1, j + 1, k),
                    node(i, j + 1, k),
                    node(i, j, k + 1),
                    node(i + 1, j, k + 1),
                    node(i + 1, j + 1, k + 1),
                    node(i, j + 1, k + 1),
                ]);
            }
        }
    }
    let disp: Vec<[f64; 3]> = points
        .iter()
        .map(|p| [0.01 * p[2], 0.0, -0.02 * p[0]])
        .collect();
    let vel: Vec<[f64; 3]> = points.iter().map(|p| [0.1 * p[1], 0.0, 0.0]).collect();
    let fixed: Vec<bool> = points.iter().map(|p| p[2] == 0.0).collect();
    let strain: Vec<f64> = cells
        .iter()
        .enumerate()
        .map(|(c, _)| (c as f64 * 1e-6).sin())
        .collect();
    let frame = LatticeFrame::new(&points, &cells)
        .with_point_field(Field::vectors("displacement", &disp))
        .with_point_field(Field::vectors("velocity", &vel))
        .with_point_field(Field::vectors("internal_force", &disp))
        .with_point_field(Field::vectors("external_force", &vel))
        .with_point_field(Field::flags("fixed", &fixed))
        .with_cell_field(Field::scalars("volumetric_strain", &strain))
        .with_cell_field(Field::scalars("shear_strain", &strain))
        .with_cell_field(Field::scalars("correction_force", &strain));
    let dir = tempfile::tempdir().expect("temporary folder");
    println!(
        "{n}^3 block: {} cells, {} nodes, {} threads",
        cells.len(),
        points.len(),
        rayon::current_num_threads()
    );
    for (name, enc) in [
        ("zlib", VtuEncoding::Base64Zlib),
        ("none (base64)", VtuEncoding::Base64),
    ] {
        let path = dir.path().join("f.vtu");
        let mut best = f64::INFINITY;
        for _ in 0..repeats {
            let t = Instant::now();
            write_vtu(&path, &frame, enc).expect("write");
            best = best.min(t.elapsed().as_secs_f64());
        }
        let bytes = std::fs::metadata(&path).expect("written").len() as f64;
        println!(
            "vtu {name:<14} {:>8.1} MB in {:>6.3} s = {:>6.0} MB/s",
            bytes / 1e6,
            best,
            bytes / best / 1e6
        );
    }
}
