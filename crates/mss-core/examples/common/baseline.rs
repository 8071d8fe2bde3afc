//! The naive springs-only baseline of the explicit-speed measurements
//! (`examples/explicit_speed.rs`, `benches/step.rs`): every lattice edge and
//! body diagonal once, in one scatter loop.

use hexmesh::Lattice;
use mss_core::{Model, Vec3};

/// Merged springs `(a, b, k, rest)`: every lattice edge once (its stiffness
/// summed over the cells around it) and every body diagonal.
pub fn merged_springs(lattice: &Lattice, model: &Model) -> Vec<(u32, u32, f64, f64)> {
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

/// The naive baseline: one pass over the springs, scattering into the nodes.
pub fn spring_loop(springs: &[(u32, u32, f64, f64)], x: &[Vec3], out: &mut [Vec3]) {
    out.fill(Vec3::zeros());
    for &(a, b, k, rest) in springs {
        let d = x[b as usize] - x[a as usize];
        let l = d.norm();
        let f = d * (k * (1.0 - rest / l));
        out[a as usize] += f;
        out[b as usize] -= f;
    }
}

/// Rest positions stretched, sheared and jittered: a deformed state where
/// every force term is at work.
pub fn perturbed(model: &Model) -> Vec<Vec3> {
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
