//! The 2D element against plane-stress finite elements: Q1 converges to
//! Timoshenko's cantilever, the virtual tests return E, nu and G, and the
//! element with hourglass control beats bilinear elements on coarse beams.

use mss_validate::plane::{cantilever_study, plane_report, timoshenko_tip, virtual_tests};

#[test]
fn the_virtual_tests_return_the_material_at_every_aspect_ratio() {
    let variants = [
        "paper",
        "areal",
        "paper+hg",
        "areal+hg",
        "springs",
        "springs+hg",
    ];
    let aspects = [0.25, 0.5, 1.0, 2.0, 4.0];
    let tests = virtual_tests(&variants, &aspects, &[0.0, 0.25, 0.3, 0.45, 0.49]).unwrap();
    assert_eq!(tests.len(), 6 * 5 * 5);
    for t in &tests {
        // Shear is the diagonals' alone, in every variant; hourglass
        // control changes no homogeneous strain.
        assert!((t.shear - 1.0).abs() < 1e-6, "{t:?}");
        if !t.variant.starts_with("springs") {
            for k in 0..2 {
                assert!((t.young[k] - 1.0).abs() < 1e-6, "{t:?}");
                assert!((t.poisson[k] - t.nu).abs() < 1e-6, "{t:?}");
            }
        }
    }
}

#[test]
fn the_cantilever_study_converges_and_hourglass_control_beats_bilinear_elements() {
    let runs =
        cantilever_study(&["paper+hg", "areal+hg", "paper"], &[1.0, 4.0], &[1, 2], 4).unwrap();
    let get = |model: &str, aspect: f64, through: u32| {
        runs.iter()
            .find(|r| r.model == model && r.aspect == aspect && r.through == through)
            .unwrap()
            .clone()
    };
    for aspect in [1.0, 4.0] {
        let fem = get("Q1 FEM", aspect, 1);
        let hg = get("paper+hg", aspect, 1);
        // Bilinear elements lock in shear one cell thick; the element with
        // hourglass control bends as a beam.
        assert!(fem.tip_over_timoshenko < 0.9, "{fem:?}");
        assert!((hg.tip_over_timoshenko - 1.0).abs() < 0.03, "{hg:?}");
        assert!(hg.mean < fem.mean, "{hg:?} vs {fem:?}");
        // Refinement reduces the error.
        assert!(get("paper+hg", aspect, 2).mean < 1.5 * hg.mean.max(1.0));
        assert!(get("Q1 FEM", aspect, 2).mean < fem.mean);
    }
    assert!(timoshenko_tip() > 0.0);
}

#[test]
fn the_report_has_both_tables() {
    let md = plane_report(true).unwrap();
    assert!(md.contains("### Virtual elongation and shear tests"));
    assert!(md.contains("### Cantilever convergence"));
    assert!(md.matches("| paper+hg |").count() >= 6, "{md}");
    eprintln!("{md}");
}
