//! The committed default mesh is exactly what the generator produces.

use crate::common;

use std::path::PathBuf;

use common::assert_closed_oriented;
use hexmesh::{MeshFormat, Resolution, VoxelizeOptions, load_mesh, load_mesh_bytes, voxelize};

fn critter_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/meshes/critter.obj")
}

#[test]
fn committed_critter_matches_generator() {
    let text = std::fs::read_to_string(critter_path()).expect("data/meshes/critter.obj must exist");
    assert!(
        text == hexmesh::generate::critter_obj(),
        "data/meshes/critter.obj is stale: run cargo run --release -p hexmesh --example generate_default_mesh"
    );
}

#[test]
fn critter_file_is_closed_outward_and_one_component() {
    let loaded = load_mesh(&critter_path()).unwrap();
    let m = &loaded.mesh;
    assert_eq!(loaded.report.vertices_welded, 0);
    assert_eq!(
        loaded.report.degenerate_repeated + loaded.report.degenerate_zero_area,
        0
    );
    assert_closed_oriented(&m.triangles);
    assert!(m.signed_volume() > 0.0);
    let b = m.bounding_box().unwrap();
    let (lo, hi) = (b.min, b.max);
    assert!(hi[0] - lo[0] > 0.18 && hi[0] - lo[0] < 0.22);
    let v = voxelize(
        m,
        &VoxelizeOptions {
            resolution: Resolution::CellsAlongLongestAxis(24),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(v.stats.components_found, 1, "{:?}", v.stats);
    // The lowest cell layer carries the feet.
    let zmin = v.lattice.cell_coords().iter().map(|c| c[2]).min().unwrap();
    assert!(
        v.lattice
            .cell_coords()
            .iter()
            .filter(|c| c[2] == zmin)
            .count()
            >= 4
    );
    let same = load_mesh_bytes(text_bytes().as_bytes(), MeshFormat::Obj, "critter").unwrap();
    assert_eq!(same.mesh, loaded.mesh);
}

fn text_bytes() -> String {
    hexmesh::generate::critter_obj()
}
