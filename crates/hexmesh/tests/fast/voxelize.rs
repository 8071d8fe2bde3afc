//! Voxelization: exact cells of a box, the bunny (one component, agreement
//! with parry's flood fill), robustness to flipped, holed and STL input.

use crate::common;

use std::collections::BTreeSet;

use common::*;
use hexmesh::TriMesh;
use hexmesh::generate::box_mesh;
use hexmesh::voxelize::{
    ComponentPolicy, Grid, OccupancyRule, Resolution, VoxelizeError, VoxelizeOptions, voxelize,
    voxelize_with,
};
use hexmesh::winding::WindingInside;

fn opts(n: u32) -> VoxelizeOptions {
    VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(n),
        ..Default::default()
    }
}

#[test]
fn box_voxelizes_to_exact_cells() {
    let m = box_mesh([1.0, 2.0, 3.0], [2.0, 2.5, 3.25]);
    for rule in [
        OccupancyRule::Centre,
        OccupancyRule::AnyOverlap,
        "fraction:0.5:3".parse().unwrap(),
    ] {
        let v = voxelize(
            &m,
            &VoxelizeOptions {
                rule: rule.clone(),
                ..opts(8)
            },
        )
        .unwrap();
        let l = &v.lattice;
        assert_eq!(l.h(), 0.125);
        assert_eq!(l.dims(), [10, 6, 4], "{rule:?}");
        let expect: Vec<[u32; 3]> = (1..3)
            .flat_map(|z| (1..5).flat_map(move |y| (1..9).map(move |x| [x, y, z])))
            .collect();
        assert_eq!(l.cell_coords(), &expect[..], "{rule:?}");
        assert!((l.origin()[0] - (1.0 - 0.125)).abs() < 1e-12);
        assert!((v.stats.lattice_volume - 0.125).abs() < 1e-12);
        assert!((v.stats.mesh_volume - 0.125).abs() < 1e-12);
        assert_eq!(v.stats.components_found, 1);
        assert_eq!(v.stats.unique_edges, l.num_unique_edges());
    }
}

#[test]
fn refuses_bad_requests_before_allocating() {
    let m = box_mesh([0.0; 3], [1.0; 3]);
    let err = voxelize(
        &m,
        &VoxelizeOptions {
            resolution: Resolution::CellSize(1e-6),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(err, VoxelizeError::GridTooLarge { .. }), "{err}");
    let limit = VoxelizeOptions::default().max_grid_cells;
    assert!(
        err.to_string()
            .contains(&format!("exceeds the limit of {limit}")),
        "{err}"
    );
    for r in [
        Resolution::CellSize(0.0),
        Resolution::CellSize(-1.0),
        Resolution::CellSize(f64::NAN),
        Resolution::CellsAlongLongestAxis(0),
    ] {
        let e = voxelize(
            &m,
            &VoxelizeOptions {
                resolution: r,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(matches!(e, VoxelizeError::BadResolution(_)), "{r:?}: {e}");
    }
    let e = voxelize(
        &m,
        &VoxelizeOptions {
            rule: "fraction:1.5".parse().unwrap(),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, VoxelizeError::BadRule(_)));
    assert!("bogus".parse::<OccupancyRule>().is_err());
    assert!(matches!(
        "center".parse::<OccupancyRule>(),
        Ok(OccupancyRule::Centre)
    ));
    assert!(matches!(
        "any".parse::<OccupancyRule>(),
        Ok(OccupancyRule::AnyOverlap)
    ));
}

#[test]
fn components_largest_or_all() {
    let mut m = box_mesh([0.0; 3], [1.0; 3]);
    let small = box_mesh([2.0, 0.0, 0.0], [2.5, 0.5, 0.5]);
    let base = m.vertices.len() as u32;
    m.vertices.extend(small.vertices);
    m.triangles
        .extend(small.triangles.iter().map(|t| t.map(|i| i + base)));
    let v = voxelize(&m, &opts(10)).unwrap();
    assert_eq!(
        (
            v.stats.components_found,
            v.stats.components_kept,
            v.stats.cells_dropped
        ),
        (2, 1, 8)
    );
    assert_eq!(v.lattice.num_cells(), 64);
    let all = voxelize(
        &m,
        &VoxelizeOptions {
            components: ComponentPolicy::All,
            ..opts(10)
        },
    )
    .unwrap();
    assert_eq!(all.lattice.num_cells(), 72);
}

fn bunny_opts(n: u32) -> VoxelizeOptions {
    VoxelizeOptions {
        max_cells: 50_000_000,
        ..opts(n)
    }
}

#[test]
fn bunny_is_one_closed_component() {
    let b = bunny();
    let v = voxelize(&b, &bunny_opts(48)).unwrap();
    assert!(v.stats.mesh_closed);
    assert_eq!(v.stats.components_found, 1, "{:?}", v.stats);
    let rel = (v.stats.lattice_volume - v.stats.mesh_volume).abs() / v.stats.mesh_volume;
    assert!(rel < 0.03, "lattice volume off by {rel}");
    assert_eq!(v.stats.unique_edges, v.lattice.num_unique_edges());
    assert_eq!(v.stats.nodes, v.lattice.num_nodes());
    let all = voxelize(
        &b,
        &VoxelizeOptions {
            components: ComponentPolicy::All,
            ..bunny_opts(48)
        },
    )
    .unwrap();
    assert_eq!(all.lattice, v.lattice);
}

/// Our any-overlap cells on parry's grid versus parry's flood fill.
#[test]
fn bunny_agrees_with_parry_flood_fill() {
    use parry3d_f64::math::Vector;
    use parry3d_f64::transformation::voxelization::{FillMode, VoxelSet};
    let b = bunny();
    let res = 48u32;
    let points: Vec<Vector> = b
        .vertices
        .iter()
        .map(|p| Vector::new(p[0], p[1], p[2]))
        .collect();
    let set = VoxelSet::voxelize(
        &points,
        &b.triangles,
        res,
        FillMode::FloodFill {
            detect_cavities: false,
        },
        false,
    );
    let theirs: BTreeSet<[i64; 3]> = set
        .voxels()
        .iter()
        .map(|v| [v.coords.x, v.coords.y, v.coords.z])
        .collect();
    // Same grid: parry's voxel i is centred at min + i * scale.
    let bb = b.bounding_box().unwrap();
    let (lo, hi) = (bb.min, bb.max);
    let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    let s = longest / (res - 1) as f64;
    assert!((set.scale - s).abs() < 1e-12 * s);
    let pad = 2u32;
    let dims: [u32; 3] = std::array::from_fn(|k| ((hi[k] - lo[k]) / s).ceil() as u32 + 1 + 2 * pad);
    let grid = Grid {
        origin: std::array::from_fn(|k| lo[k] - (pad as f64 + 0.5) * s),
        h: s,
        dims,
    };
    let inside = WindingInside::new(&b, s);
    let o = VoxelizeOptions {
        rule: OccupancyRule::AnyOverlap,
        ..Default::default()
    };
    let ours = voxelize_with(inside.oriented_mesh(), &inside, grid, &o).unwrap();
    let ours: BTreeSet<[i64; 3]> = ours
        .lattice
        .cell_coords()
        .iter()
        .map(|c| std::array::from_fn(|k| c[k] as i64 - pad as i64))
        .collect();
    let common = ours.intersection(&theirs).count();
    let union = ours.union(&theirs).count();
    let agree = common as f64 / union as f64;
    eprintln!(
        "ours {} parry {} common {common} agreement {agree:.4}",
        ours.len(),
        theirs.len()
    );
    assert!(agree >= 0.98, "agreement {agree}");
}

fn flipped(m: &TriMesh) -> TriMesh {
    TriMesh {
        vertices: m.vertices.clone(),
        triangles: m.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
    }
}

#[test]
fn flipped_bunny_gives_same_cells() {
    let b = bunny();
    let a = voxelize(&b, &bunny_opts(40)).unwrap();
    let f = voxelize(&flipped(&b), &bunny_opts(40)).unwrap();
    assert_eq!(a.lattice, f.lattice);
    assert_eq!(f.stats.triangles_flipped, b.triangles.len());
    // Half of the triangles flipped (inconsistent orientation) as well.
    let mut half = b.clone();
    for t in half.triangles.iter_mut().step_by(2) {
        t.swap(1, 2);
    }
    let h = voxelize(&half, &bunny_opts(40)).unwrap();
    assert_eq!(a.lattice, h.lattice);
}

#[test]
fn bunny_with_holes_gives_nearly_same_cells() {
    let b = bunny();
    let a = voxelize(&b, &bunny_opts(40)).unwrap();
    let mut holed = b.clone();
    for i in [5usize, 400, 1200, 2500, 3000] {
        holed.triangles.remove(i);
    }
    let h = voxelize(&holed, &bunny_opts(40)).unwrap();
    assert!(!h.stats.mesh_closed);
    assert_eq!(a.lattice.dims(), h.lattice.dims());
    let ka: BTreeSet<_> = a.lattice.cell_coords().iter().copied().collect();
    let kb: BTreeSet<_> = h.lattice.cell_coords().iter().copied().collect();
    let diff = ka.symmetric_difference(&kb).count();
    eprintln!(
        "holed bunny: {} vs {} cells, {diff} differ",
        ka.len(),
        kb.len()
    );
    assert!(diff <= 5, "{diff} cells differ");
}

#[test]
fn bunny_as_binary_stl_with_solid_header_gives_same_cells() {
    let b = bunny();
    let mut bytes = Vec::new();
    let mut header = [b' '; 80];
    header[..20].copy_from_slice(b"solid bunny (binary)");
    bytes.extend_from_slice(&header);
    bytes.extend_from_slice(&(b.triangles.len() as u32).to_le_bytes());
    for t in &b.triangles {
        bytes.extend_from_slice(&[0u8; 12]);
        for &i in t {
            for c in b.vertices[i as usize] {
                bytes.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        bytes.extend_from_slice(&[0, 0]);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bunny.stl");
    std::fs::write(&path, &bytes).unwrap();
    let loaded = hexmesh::load::load_mesh(&path).unwrap();
    assert_eq!(loaded.mesh.triangles.len(), b.triangles.len());
    assert_eq!(
        loaded.mesh.vertices.len(),
        b.vertices.len(),
        "welding must restore shared vertices"
    );
    let a = voxelize(&b, &bunny_opts(40)).unwrap();
    let s = voxelize(&loaded.mesh, &bunny_opts(40)).unwrap();
    assert!(s.stats.mesh_closed);
    // The OBJ has 6 decimals, so its coordinates are exact in f32 to well below a cell.
    assert_eq!(a.lattice.cell_coords(), s.lattice.cell_coords());
}

/// `max_cells` counts occupied cells, not the bounding grid: a thin diagonal
/// shape whose grid is mostly empty fits a limit below its grid size, and a
/// lattice above the limit is refused before it is built.
#[test]
fn max_cells_counts_occupied_cells() {
    let m = hexmesh::generate::sphere(0.5, 3);
    let base = VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(20),
        ..Default::default()
    };
    let v = voxelize(&m, &base).unwrap();
    let occupied = v.lattice.num_cells() as u64;
    let grid: u64 = v.stats.grid_dims.iter().map(|&d| d as u64).product();
    assert!(grid > occupied);
    let just = VoxelizeOptions {
        max_cells: occupied,
        max_grid_cells: grid,
        ..base.clone()
    };
    assert_eq!(
        voxelize(&m, &just).unwrap().lattice.num_cells() as u64,
        occupied
    );
    let under = VoxelizeOptions {
        max_cells: occupied - 1,
        ..base.clone()
    };
    match voxelize(&m, &under).unwrap_err() {
        VoxelizeError::TooManyCells { cells, max_cells } => {
            assert_eq!((cells, max_cells), (occupied, occupied - 1))
        }
        other => panic!("{other}"),
    }
    let small_grid = VoxelizeOptions {
        max_grid_cells: grid - 1,
        ..base
    };
    assert!(matches!(
        voxelize(&m, &small_grid).unwrap_err(),
        VoxelizeError::GridTooLarge { .. }
    ));
}
