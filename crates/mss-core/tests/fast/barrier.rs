//! The barrier volumetric law of `volumetric-barrier` (docs/model.md,
//! section 4): the same as `volumetric` at small strain, `lambda h^3 (ln J)^2
//! / 2` beyond, with exact tangents.

use hexmesh::Lattice;
use mss_core::model::{Volumetric, VolumetricBarrier};
use mss_core::{Mat3, Material, Model, Vec3};

fn material() -> Material {
    Material::new(1000.0, 0.3, 1.0).unwrap()
}

fn deformed(model: &Model, f: Mat3) -> Vec<Vec3> {
    model.rest_positions().iter().map(|p| f * p).collect()
}

fn forces(model: &Model, x: &[Vec3]) -> Vec<Vec3> {
    let mut f = vec![Vec3::zeros(); x.len()];
    model.internal_forces(x, &mut f);
    f
}

#[test]
fn same_stiffness_at_rest_as_the_quadratic_law() {
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let a = Model::new(&l, material(), &Volumetric).unwrap();
    let b = Model::new(&l, material(), &VolumetricBarrier).unwrap();
    let (ka, kb) = (a.rest_stiffness(), b.rest_stiffness());
    let scale = ka.max_diagonal();
    for (x, y) in ka.blocks.iter().zip(&kb.blocks) {
        assert!((x - y).abs().max() <= 1e-12 * scale);
    }
    assert_eq!(a.critical_time_step(), b.critical_time_step());
}

#[test]
fn energy_of_a_uniform_compression_is_the_barrier_law() {
    let h = 0.1;
    let l = Lattice::block([1, 1, 1], h, [0.0; 3]).unwrap();
    let m = material();
    let a = Model::new(&l, m, &Volumetric).unwrap();
    let b = Model::new(&l, m, &VolumetricBarrier).unwrap();
    let lambda_h3 = m.lambda() * h * h * h;
    for j in [1.3f64, 0.9, 0.5, 0.2, 0.1] {
        // A uniform compression along z only: J = j, springs identical in both.
        let x = deformed(&a, Mat3::from_diagonal(&Vec3::new(1.0, 1.0, j)));
        // Uniform: every corner Jacobian is j too, and below 0.2 the corner
        // barrier (lambda + 2 mu) h^3 / 8 psi(J_n) adds its share at each of
        // the 8 corners, psi(J) = 2 ((0.2 - J) / 0.2)^3 (docs/model.md).
        let corner = (m.lambda() + 2.0 * m.shear_modulus())
            * h.powi(3)
            * 2.0
            * ((0.2 - j).max(0.0) / 0.2).powi(3);
        let expected = lambda_h3 * (0.5 * j.ln().powi(2) - 0.5 * (j - 1.0).powi(2)) + corner;
        let got = b.energy(&x) - a.energy(&x);
        assert!(
            (got - expected).abs() <= 1e-12 * lambda_h3,
            "J = {j}: {got} vs {expected}"
        );
    }
    // Near collapse the barrier costs many times what the quadratic law does.
    let x = deformed(&a, Mat3::from_diagonal(&Vec3::new(1.0, 1.0, 0.15)));
    let springs = a.energy(&x) - 0.5 * lambda_h3 * 0.85f64.powi(2);
    assert!(b.energy(&x) - springs > 4.0 * (a.energy(&x) - springs));
}

#[test]
fn energy_and_forces_are_continuous_through_the_knee_and_beyond_collapse() {
    let h = 0.1;
    let l = Lattice::block([1, 1, 1], h, [0.0; 3]).unwrap();
    let b = Model::new(&l, material(), &VolumetricBarrier).unwrap();
    let at = |j: f64| {
        let x = deformed(&b, Mat3::from_diagonal(&Vec3::new(1.0, 1.0, j)));
        (b.energy(&x), forces(&b, &x))
    };
    for j0 in [0.1, 0.3] {
        let (e1, f1) = at(j0 - 1e-9);
        let (e2, f2) = at(j0 + 1e-9);
        assert!((e1 - e2).abs() < 1e-6 * e1.abs().max(1e-12));
        for (p, q) in f1.iter().zip(&f2) {
            assert!((p - q).norm() < 1e-6 * p.norm().max(1e-12));
        }
    }
    // Inverted cells are pushed back (finite forces, pointing out).
    let (_, f) = at(-0.05);
    assert!(f.iter().all(|v| v.iter().all(|c| c.is_finite())));
    let top: f64 = f
        .iter()
        .zip(b.rest_positions())
        .filter(|(_, p)| p.z > 0.5 * h)
        .map(|(v, _)| v.z)
        .sum();
    assert!(top > 0.0, "the top face is pushed up: {top}");
}

#[test]
fn the_tangent_is_exact_at_large_compression() {
    let l = Lattice::block([2, 1, 1], 0.1, [0.0; 3]).unwrap();
    let b = Model::new(&l, material(), &VolumetricBarrier).unwrap();
    for jz in [0.6, 0.08] {
        let f = Mat3::new(1.05, 0.1, 0.0, -0.05, 0.97, 0.02, 0.03, 0.0, jz);
        let mut x = deformed(&b, f);
        x[3].x += 0.004;
        let tangent = b.tangent(&x);
        let eps = 1e-7;
        for node in [0usize, 4, 7] {
            for d in 0..3 {
                let mut xp = x.clone();
                let mut xm = x.clone();
                xp[node][d] += eps;
                xm[node][d] -= eps;
                let (fp, fm) = (forces(&b, &xp), forces(&b, &xm));
                for row in 0..x.len() {
                    let fd = (fp[row] - fm[row]) / (2.0 * eps);
                    let exact = tangent
                        .find(row, node)
                        .map(|k| tangent.blocks[k].column(d).into_owned())
                        .unwrap_or_else(Vec3::zeros);
                    let scale = tangent.max_diagonal();
                    assert!(
                        (fd - exact).norm() <= 1e-5 * scale,
                        "J_z {jz}, node {node}, dof {d}, row {row}: {fd:?} vs {exact:?}"
                    );
                }
            }
        }
    }
}

/// Largest eigenvalue of `M^-1/2 K_s M^-1/2`, `K_s` the symmetric part of
/// the stiffness at `x`: omega_max^2 of small vibrations about `x`.
fn omega_sq(model: &Model, x: &[Vec3]) -> f64 {
    let k = model.stiffness(x);
    let n = 3 * model.num_nodes();
    let scale = |dof: usize| 1.0 / model.masses()[dof / 3].sqrt();
    let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
    for row in 0..model.num_nodes() {
        for idx in k.row_offsets[row] as usize..k.row_offsets[row + 1] as usize {
            let col = k.col_indices[idx] as usize;
            for a in 0..3 {
                for b in 0..3 {
                    let (r, c) = (3 * row + a, 3 * col + b);
                    dense[(r, c)] = k.blocks[idx][(a, b)] * scale(r) * scale(c);
                }
            }
        }
    }
    let sym = (&dense + dense.transpose()) * 0.5;
    sym.symmetric_eigenvalues().max()
}

#[test]
fn the_stiffness_growth_bounds_the_highest_frequency() {
    let l = Lattice::block([2, 2, 2], 0.1, [0.0; 3]).unwrap();
    let m = Material::new(1000.0, 0.45, 1.0).unwrap();
    for param in [
        &Volumetric as &dyn mss_core::Parameterization,
        &VolumetricBarrier,
    ] {
        let model = Model::new(&l, m, param).unwrap();
        let rest = model.rest_positions().to_vec();
        // At rest the element bound is the assembled one (a corner node of
        // the block belongs to one cell), up to round-off.
        assert!((model.stiffness_growth(&rest) - 1.0).abs() < 1e-12);
        let bound_at_rest = model.omega_max_bound().powi(2);
        assert!(omega_sq(&model, &rest) <= bound_at_rest);
        let mut previous = 1.0;
        for jz in [0.9, 0.7, 0.5, 0.3, 0.15] {
            let f = Mat3::new(1.02, 0.05, 0.0, 0.0, 0.98, 0.0, 0.0, 0.0, jz);
            let x = deformed(&model, f);
            let growth = model.stiffness_growth(&x);
            let actual = omega_sq(&model, &x);
            assert!(
                growth * bound_at_rest >= actual,
                "{}: J_z {jz}: bound {} < omega^2 {actual}",
                param.name(),
                growth * bound_at_rest
            );
            if param.name() == "volumetric-barrier" && jz < 0.8 {
                assert!(growth > previous, "J_z {jz}: grows with compression");
                previous = growth;
            }
        }
    }
    // Springs do not stiffen along their length: no growth is claimed.
    let springs = Model::new(&l, m, &mss_core::SpringsOnly).unwrap();
    let x = deformed(&springs, Mat3::from_diagonal(&Vec3::new(1.0, 1.0, 0.5)));
    assert_eq!(springs.stiffness_growth(&x), 1.0);
}
