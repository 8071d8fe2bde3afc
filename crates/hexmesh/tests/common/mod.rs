//! Shared helpers for the integration tests.
#![allow(dead_code)]

use std::collections::BTreeSet;
use std::path::PathBuf;

use hexmesh::{Lattice, TriMesh};

/// The Stanford bunny committed as test data (`data/meshes/bunny.obj`).
pub fn bunny_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/meshes/bunny.obj")
}

/// The bunny, loaded and cleaned.
pub fn bunny() -> TriMesh {
    let path = bunny_path();
    hexmesh::load::load_mesh(&path)
        .unwrap_or_else(|e| panic!("the bunny must load from {}: {e}", path.display()))
        .mesh
}

/// Cell centres of a lattice, as integer keys on the lattice's grid shifted by origin/h.
pub fn cell_keys(l: &Lattice) -> BTreeSet<[i64; 3]> {
    let off: [i64; 3] = std::array::from_fn(|k| (l.origin()[k] / l.h()).round() as i64);
    l.cell_coords()
        .iter()
        .map(|c| std::array::from_fn(|k| c[k] as i64 + off[k]))
        .collect()
}

/// Every undirected edge of the triangles is used exactly twice, once in each direction.
pub fn assert_closed_oriented(triangles: &[[u32; 3]]) {
    let mut directed: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .collect();
    directed.sort_unstable();
    for w in directed.windows(2) {
        assert_ne!(
            w[0], w[1],
            "directed edge {:?} used twice (orientation or manifoldness)",
            w[0]
        );
    }
    for &(a, b) in &directed {
        assert!(
            directed.binary_search(&(b, a)).is_ok(),
            "edge ({a}, {b}) is a border edge"
        );
    }
}

/// Signed volume of triangles over positions.
pub fn signed_volume(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    TriMesh {
        vertices: positions.to_vec(),
        triangles: triangles.to_vec(),
    }
    .signed_volume()
}
