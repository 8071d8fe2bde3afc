//! The lattice volume of a sphere converges to 4/3 pi r^3 about linearly in h.

use hexmesh::generate::sphere;
use hexmesh::{OccupancyRule, Resolution, VoxelizeOptions, voxelize};

#[test]
fn sphere_volume_error_falls_like_h() {
    let r = 1.0;
    let mesh = sphere(r, 6);
    // Reference: the polyhedron's own volume (the faceting error is ~1e-4).
    let exact = mesh.signed_volume();
    assert!((exact - 4.0 / 3.0 * std::f64::consts::PI).abs() < 2e-3);
    let mut points = Vec::new();
    for n in [8u32, 16, 32, 64] {
        // Conservative rule: the error is one-sided (always an over-estimate),
        // so it does not cancel by luck and shows the O(h) rate cleanly.
        let v = voxelize(
            &mesh,
            &VoxelizeOptions {
                resolution: Resolution::CellsAlongLongestAxis(n),
                rule: OccupancyRule::AnyOverlap,
                ..Default::default()
            },
        )
        .unwrap();
        let err = (v.stats.lattice_volume - exact) / exact;
        assert!(err > 0.0);
        points.push((v.lattice.h().ln(), err.ln()));
        eprintln!("n = {n}: h = {:.4}, relative error {err:.5}", v.lattice.h());
    }
    // Least-squares slope of log(error) against log(h).
    let m = points.len() as f64;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
    let sxx: f64 = points.iter().map(|p| p.0 * p.0).sum();
    let sxy: f64 = points.iter().map(|p| p.0 * p.1).sum();
    let slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
    eprintln!("fitted rate {slope:.3}");
    assert!((0.8..1.2).contains(&slope), "rate {slope}");
    // Centre rule: error small and shrinking overall.
    let centre = |n| {
        let v = voxelize(
            &mesh,
            &VoxelizeOptions {
                resolution: Resolution::CellsAlongLongestAxis(n),
                ..Default::default()
            },
        )
        .unwrap();
        ((v.stats.lattice_volume - exact) / exact).abs()
    };
    assert!(centre(64) < 0.01 && centre(64) < centre(8));
}
