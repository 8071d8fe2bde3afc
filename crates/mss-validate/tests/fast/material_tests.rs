//! Virtual material tests against docs/model.md: the paper's model reproduces E and
//! nu exactly in uniaxial tension; springs alone give nu' = 1 / (4 nu + 3).

use mss_core::Material;
use mss_core::model::{PaperModel, SpringsOnly};
use mss_validate::material_test::{measure_material, uniaxial_tension};

const NUS: [f64; 6] = [-0.2, 0.0, 0.25, 0.3, 0.45, 0.49];

#[test]
fn paper_model_measures_e_and_nu_exactly() {
    for n in [1, 2, 4, 8] {
        for nu in NUS {
            let m = Material::new(2500.0, nu, 3.0).unwrap();
            let (e, nu_m) = uniaxial_tension(m, &PaperModel, n).unwrap();
            let (re, rn) = (
                (e / m.young - 1.0).abs(),
                (nu_m - nu).abs() / nu.abs().max(1.0),
            );
            assert!(re < 1e-6 && rn < 1e-6, "n={n} nu={nu}: E={e} nu={nu_m}");
        }
    }
}

#[test]
fn springs_only_measure_classic_poisson_ratio() {
    for n in [1, 2, 4] {
        for nu in NUS {
            let m = Material::new(1.0, nu, 1.0).unwrap();
            let (_, nu_m) = uniaxial_tension(m, &SpringsOnly, n).unwrap();
            let expect = 1.0 / (4.0 * nu + 3.0);
            assert!(
                (nu_m - expect).abs() < 1e-6,
                "n={n} nu={nu}: {nu_m} vs {expect}"
            );
        }
    }
}

#[test]
fn paper_model_shear_and_bulk_moduli() {
    for n in [1, 3] {
        for nu in NUS {
            let m = Material::new(1000.0, nu, 1.0).unwrap();
            let r = measure_material(m, &PaperModel, n).unwrap();
            let g = m.shear_modulus();
            let k = m.bulk_modulus();
            assert!(
                (r.shear / g - 1.0).abs() < 1e-6,
                "n={n} nu={nu}: G={} vs {g}",
                r.shear
            );
            assert!(
                (r.bulk / k - 1.0).abs() < 1e-6,
                "n={n} nu={nu}: K={} vs {k}",
                r.bulk
            );
        }
    }
}
