//! Hourglass control (`HourglassControl`, the `*+hg` parameterizations): it
//! gives the lattice's mechanisms the stiffness it promises and touches nothing
//! else (homogeneous strains, rigid motions).

use hexmesh::{CORNER_OFFSETS, Lattice};
use mss_core::model::{HourglassControl, PaperModel, Volumetric};
use mss_core::modes::zero_energy_modes_dense;
use mss_core::{Mat3, Material, Model, Parameterizations, Vec3};

fn parameterization_by_name(name: &str) -> Option<Box<dyn mss_core::Parameterization>> {
    Parameterizations::default().get(name).ok()
}

fn mat(nu: f64) -> Material {
    Material::new(100.0, nu, 1.0).unwrap()
}

fn forces(model: &Model, x: &[Vec3]) -> Vec<Vec3> {
    let mut f = vec![Vec3::zeros(); x.len()];
    model.internal_forces(x, &mut f);
    f
}

fn sign(v: u32) -> f64 {
    if v == 1 { 1.0 } else { -1.0 }
}

/// Rotation by `angle` about the unit vector `axis` (Rodrigues).
fn rotation(axis: Vec3, angle: f64) -> Mat3 {
    let k = Mat3::new(
        0.0, -axis.z, axis.y, axis.z, 0.0, -axis.x, -axis.y, axis.x, 0.0,
    );
    Mat3::identity() + k * angle.sin() + k * k * (1.0 - angle.cos())
}

#[test]
fn a_mechanism_gets_exactly_the_stated_energy() {
    // One cell, corners displaced along x by A s_y s_z: no spring changes length,
    // the hourglass amplitude is A, so the energy is k A^2 / 2 with
    // k = alpha (8/3) mu h, whatever the amplitude.
    let h = 0.2;
    let l = Lattice::block([1, 1, 1], h, [0.0; 3]).unwrap();
    let m = mat(0.3);
    for alpha in [0.1, 1.0] {
        let p = HourglassControl::new(Box::new(Volumetric), alpha).unwrap();
        let model = Model::new(&l, m, &p).unwrap();
        let plain = Model::new(&l, m, &Volumetric).unwrap();
        let k = alpha * 8.0 / 3.0 * m.shear_modulus() * h;
        for (axis, amplitude) in [(0usize, 0.01 * h), (1, 0.3 * h), (2, 0.05 * h)] {
            let x: Vec<Vec3> = (0..8)
                .map(|n| {
                    let c = CORNER_OFFSETS[n];
                    let mut p = model.rest_positions()[l.cells()[0][n] as usize];
                    p[axis] += amplitude * sign(c[(axis + 1) % 3]) * sign(c[(axis + 2) % 3]);
                    p
                })
                .collect();
            // Nodes of the single cell are in corner order only through the
            // cell table: place them where the cell says.
            let mut xs = vec![Vec3::zeros(); 8];
            for (n, &node) in l.cells()[0].iter().enumerate() {
                xs[node as usize] = x[n];
            }
            let e = model.energy(&xs);
            let expected = 0.5 * k * amplitude * amplitude;
            // The springs see no stretch; at large amplitude the volume changes a
            // little (second order), so compare without the volumetric part.
            let rest = plain.energy(&xs);
            assert!(
                ((e - rest) - expected).abs() < 1e-9 * expected,
                "axis {axis} A {amplitude}: {} vs {expected}",
                e - rest
            );
            // Without hourglass control only the second-order stretch of the 8
            // edges across the mode's axis stores energy (the diagonals and the
            // volume do not change): 8 * k_edge / 2 * (sqrt(h^2 + 4 A^2) - h)^2.
            let k_edge = plain.cell_coefficients(0).k_edge;
            let stretch = (h * h + 4.0 * amplitude * amplitude).sqrt() - h;
            let springs = 4.0 * k_edge * stretch * stretch;
            assert!(
                (rest - springs).abs() < 1e-9 * springs,
                "axis {axis} A {amplitude}: {rest} vs {springs}"
            );
        }
    }
}

#[test]
fn homogeneous_deformations_and_rigid_motions_feel_no_hourglass_force() {
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let m = mat(0.3);
    let hg = HourglassControl::new(Box::new(PaperModel), 1.0).unwrap();
    let with = Model::new(&l, m, &hg).unwrap();
    let without = Model::new(&l, m, &PaperModel).unwrap();
    let f = Mat3::new(1.3, 0.2, -0.1, 0.05, 0.8, 0.3, -0.2, 0.1, 1.1);
    let r = rotation(Vec3::new(1.0, 2.0, -0.5).normalize(), 1.1);
    for map in [f, r, r * f] {
        let x: Vec<Vec3> = with
            .rest_positions()
            .iter()
            .map(|p| map * p + Vec3::new(0.3, -0.2, 0.1))
            .collect();
        let (a, b) = (forces(&with, &x), forces(&without, &x));
        let scale = b.iter().map(|v| v.norm()).fold(1e-12, f64::max);
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).norm() < 1e-10 * scale.max(1.0), "{p} vs {q}");
        }
        assert!((with.energy(&x) - without.energy(&x)).abs() < 1e-12);
    }
}

#[test]
fn hourglass_forces_rotate_with_the_body() {
    let l = Lattice::block([2, 2, 2], 0.1, [0.0; 3]).unwrap();
    let hg = HourglassControl::new(Box::new(Volumetric), 1.0).unwrap();
    let model = Model::new(&l, mat(0.3), &hg).unwrap();
    // A deformed state with hourglass content (checkerboard along each axis).
    let coords = l.node_coords();
    let x: Vec<Vec3> = model
        .rest_positions()
        .iter()
        .zip(coords.iter())
        .map(|(p, c)| {
            let s = |a: u32, b: u32| if (a + b).is_multiple_of(2) { 1.0 } else { -1.0 };
            p + Vec3::new(s(c[1], c[2]), 0.5 * s(c[0], c[2]), -0.7 * s(c[0], c[1])) * 0.01
                + Vec3::new(0.05 * p.z, 0.0, 0.02 * p.x)
        })
        .collect();
    let r = rotation(Vec3::new(0.3, -1.0, 0.4).normalize(), 2.0);
    let xr: Vec<Vec3> = x.iter().map(|p| r * p).collect();
    let (f, fr) = (forces(&model, &x), forces(&model, &xr));
    let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(scale > 0.0);
    for (a, b) in f.iter().zip(&fr) {
        assert!((r * a - b).norm() < 1e-10 * scale);
    }
    assert!((model.energy(&x) - model.energy(&xr)).abs() < 1e-10 * model.energy(&x));
}

#[test]
fn hourglass_control_removes_the_mechanisms() {
    // docs/model.md: the M2 lattice of a block has 9 zero-energy modes (6 rigid,
    // 3 hourglass); a bar one cell thick both ways has 12. With hourglass
    // control only the rigid ones are left, and a single held node (which fixes
    // translations only) leaves the 3 rotations.
    let m = mat(0.3);
    for (dims, plain_modes) in [([1, 1, 1], 9), ([3, 2, 2], 9), ([4, 1, 1], 12)] {
        let l = Lattice::block(dims, 0.1, [0.0; 3]).unwrap();
        for name in ["paper+hg", "volumetric+hg", "springs+hg"] {
            let p = parameterization_by_name(name).unwrap();
            let model = Model::new(&l, m, p.as_ref()).unwrap();
            let none = vec![[false; 3]; l.num_nodes()];
            let mut one = none.clone();
            one[0] = [true; 3];
            assert_eq!(
                zero_energy_modes_dense(&model, &none).unwrap().count,
                6,
                "{name} {dims:?}"
            );
            assert_eq!(
                zero_energy_modes_dense(&model, &one).unwrap().count,
                3,
                "{name} {dims:?}"
            );
            let plain = parameterization_by_name(name.trim_end_matches("+hg")).unwrap();
            let model = Model::new(&l, m, plain.as_ref()).unwrap();
            assert_eq!(
                zero_energy_modes_dense(&model, &none).unwrap().count,
                plain_modes,
                "{name} {dims:?} without control"
            );
        }
    }
}

#[test]
fn names_and_invalid_factors() {
    for name in ["paper+hg", "springs+hg", "volumetric+hg"] {
        let p = parameterization_by_name(name).unwrap();
        assert_eq!(p.name(), name);
        let co = p.coefficients(&mat(0.3), 0.1);
        let expected = HourglassControl::DEFAULT_ALPHA * 8.0 / 3.0 * mat(0.3).shear_modulus() * 0.1;
        assert!((co.hourglass - expected).abs() < 1e-12 * expected);
    }
    assert!(parameterization_by_name("paper+hg+hg").is_none());
    assert!(parameterization_by_name("nope+hg").is_none());
    for bad in [-0.1, f64::NAN, f64::INFINITY] {
        let e = HourglassControl::new(Box::new(PaperModel), bad).unwrap_err();
        assert!(e.to_string().contains("hourglass"), "{e}");
    }
    // The range of nu is the inner parameterization's.
    let p = parameterization_by_name("volumetric+hg").unwrap();
    assert!(
        p.validate(&Material::with_poisson_range(1.0, -0.5, 1.0, -1.0, 0.5).unwrap())
            .is_ok()
    );
    let p = parameterization_by_name("paper+hg").unwrap();
    assert!(
        p.validate(&Material::with_poisson_range(1.0, -0.5, 1.0, -1.0, 0.5).unwrap())
            .is_err()
    );
}
