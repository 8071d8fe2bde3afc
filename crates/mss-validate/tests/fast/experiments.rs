//! The paper's experiments at small resolutions: errors fall with refinement,
//! the paper's model beats springs only at nu = 0.3 from 16x4x4 on, and the
//! measured error statistics stay below bounds set a little above today's
//! values (so that a regression fails).

use mss_core::Vec3;
use mss_validate::experiments::{
    BeamSettings, LLoad, LShapeSettings, Regime, SharedParameterization, beam, builtin_models,
    error_stats, lshape, material,
};

fn models() -> Vec<SharedParameterization> {
    builtin_models(&["paper", "springs", "volumetric"]).unwrap()
}

fn stats(r: &mss_validate::experiments::BeamResult, model: &str, n: u32) -> (f64, f64, f64) {
    let run = r
        .runs
        .iter()
        .find(|x| x.model == model && x.dims[1] == n)
        .unwrap();
    (run.stats.mean, run.stats.sd, run.stats.max)
}

#[test]
fn error_metric_is_relative_to_the_largest_reference_displacement() {
    let u_ref = vec![Vec3::new(0.0, 0.0, 2.0), Vec3::new(1.0, 0.0, 0.0)];
    let u = vec![Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 0.0)];
    let (e, s) = error_stats(&u, &u_ref);
    assert_eq!(e, vec![50.0, 0.0]);
    assert!((s.mean - 25.0).abs() < 1e-12 && (s.sd - 25.0).abs() < 1e-12 && s.max == 50.0);
}

#[test]
fn small_load_cantilever_errors_fall_and_paper_beats_springs() {
    // Reference: Q1 on 32x8x8 extrapolated with 16x4x4.
    let s = BeamSettings {
        second_half_young: None,
        reference_law: None,
        poisson: 0.3,
        density: 0.01,
        regime: Regime::Linear,
        resolutions: vec![2, 4],
        reference: 8,
        models: models(),
    };
    let r = beam(&s).unwrap();
    for m in ["paper", "springs", "volumetric"] {
        assert!(stats(&r, m, 4).0 < stats(&r, m, 2).0, "{m}");
        assert!(stats(&r, m, 4).2 < stats(&r, m, 2).2, "{m}");
    }
    assert!(stats(&r, "paper", 4).0 < stats(&r, "springs", 4).0);
    assert!(stats(&r, "paper", 4).2 < stats(&r, "springs", 4).2);
    assert!(stats(&r, "volumetric", 4).0 < stats(&r, "paper", 4).0);
    // Measured: paper 8x2x2 12.38/9.59/28.76, 16x4x4 4.20/3.12/9.86;
    // springs 16x4x4 4.95/3.78/11.87; volumetric 16x4x4 0.889/0.563/1.89.
    let bound = |got: (f64, f64, f64), b: (f64, f64, f64)| {
        assert!(
            got.0 < b.0 && got.1 < b.1 && got.2 < b.2,
            "{got:?} above {b:?}"
        );
    };
    bound(stats(&r, "paper", 2), (12.6, 9.8, 29.2));
    bound(stats(&r, "paper", 4), (4.3, 3.2, 10.1));
    bound(stats(&r, "springs", 4), (5.05, 3.9, 12.1));
    bound(stats(&r, "volumetric", 4), (0.92, 0.59, 1.95));
    // Tip deflection approaches the reference; the reference lies near
    // Timoshenko's value.
    let tip = |n| {
        r.runs
            .iter()
            .find(|x| x.model == "paper" && x.dims[1] == n)
            .unwrap()
            .monitor
            .z
    };
    let tref = r.reference.monitor_ref.z;
    assert!((tip(4) - tref).abs() < (tip(2) - tref).abs());
    assert!((-tref - r.timoshenko_tip).abs() < 0.05 * r.timoshenko_tip);
}

#[test]
fn nu_zero_cantilever_matches_model_md_tips() {
    let s = BeamSettings {
        second_half_young: None,
        reference_law: None,
        poisson: 0.0,
        density: 0.01,
        regime: Regime::Linear,
        resolutions: vec![1, 2, 4],
        reference: 8,
        models: builtin_models(&["paper"]).unwrap(),
    };
    let r = beam(&s).unwrap();
    // docs/model.md: 2.6732e-4, 3.5060e-4, 3.8293e-4.
    for (n, want) in [(1, 2.6732e-4), (2, 3.5060e-4), (4, 3.8293e-4)] {
        let run = r.runs.iter().find(|x| x.dims[1] == n).unwrap();
        assert!(
            (-run.monitor.z - want).abs() < 1e-4 * want,
            "{n}: {}",
            run.monitor.z
        );
    }
    assert!((r.euler_bernoulli_tip - 3.7670e-4).abs() < 1e-7);
    assert!((r.timoshenko_tip - 3.9554e-4).abs() < 1e-7);
}

#[test]
fn large_deflection_cantilever_errors_fall() {
    // Neo-Hookean reference on 16x4x4 (extrapolated with 8x2x2): coarse but fast.
    let s = BeamSettings {
        second_half_young: None,
        reference_law: None,
        poisson: 0.3,
        density: 3.125,
        regime: Regime::Large,
        resolutions: vec![1, 2],
        reference: 4,
        models: builtin_models(&["paper", "volumetric"]).unwrap(),
    };
    let r = beam(&s).unwrap();
    let tip = -r.reference.monitor_ref.z;
    assert!((0.10..0.13).contains(&tip), "tip {tip}");
    for m in ["paper", "volumetric"] {
        assert!(stats(&r, m, 2).0 < stats(&r, m, 1).0, "{m}");
    }
    // Measured (this coarse reference): paper 8x2x2 M ~11.9, volumetric ~3.0.
    assert!(stats(&r, "paper", 2).0 < 13.0 && stats(&r, "volumetric", 2).0 < 3.6);
}

#[test]
fn lshape_errors_fall_with_resolution() {
    let s = LShapeSettings {
        load: LLoad::ArmTopDown,
        traction: 1.0,
        resolutions: vec![1, 2],
        reference: 4,
        models: models(),
    };
    let r = lshape(&s).unwrap();
    for m in ["paper", "springs", "volumetric"] {
        let at = |n: u32| {
            r.runs
                .iter()
                .find(|x| x.model == m && x.dims[0] == 2 * n)
                .unwrap()
                .stats
        };
        assert!(at(2).mean < at(1).mean && at(2).max < at(1).max, "{m}");
    }
}

#[test]
fn material_tests_recover_e_and_nu_for_the_paper_model_only() {
    let rows = material(
        &[0.0, 0.3],
        &builtin_models(&["paper", "springs"]).unwrap(),
        1,
    )
    .unwrap();
    for r in &rows {
        let e_ok = (r.measured.young - 1000.0).abs() < 1e-6 * 1000.0;
        let nu_ok = (r.measured.poisson - r.poisson).abs() < 1e-6;
        if r.model == "paper" {
            assert!(e_ok && nu_ok, "{r:?}");
        } else if r.poisson == 0.3 {
            // Springs only: nu' = 1 / (4 nu + 3).
            assert!((r.measured.poisson - 1.0 / 4.2).abs() < 1e-6, "{r:?}");
        }
    }
}

#[test]
fn hourglass_control_fixes_the_one_cell_beam_and_leaves_16x4x4_alone() {
    // The criterion for keeping the option: it must fix 4x1x1 (one cell
    // through the thickness, free mechanisms) without making 16x4x4 worse.
    let s = BeamSettings {
        second_half_young: None,
        reference_law: None,
        poisson: 0.3,
        density: 0.01,
        regime: Regime::Linear,
        resolutions: vec![1, 4],
        reference: 8,
        models: builtin_models(&["paper", "paper+hg", "volumetric", "volumetric+hg"]).unwrap(),
    };
    let r = beam(&s).unwrap();
    // (base, bound on the mean and on the largest error with hg, %), 10 %
    // above what was measured: paper 25.1 / 56.9, volumetric 5.3 / 11.2.
    for (base, bound) in [("paper", (28.0, 63.0)), ("volumetric", (6.0, 12.5))] {
        let hg = format!("{base}+hg");
        // Without control, the one-cell beam keeps mechanisms that the
        // lumped gravity load excites: its tangent is singular and the
        // numbers of its solve are whatever the round-off of the
        // factorization makes of a zero pivot (they changed 4x when the
        // cell Jacobian was rewritten, correct to 1e-16 either way). So the
        // test asks that the mechanisms be there without control, gone with
        // it, and that the controlled beam be accurate.
        let lattice = hexmesh::Lattice::block([4, 1, 1], 0.1, [0.0; 3]).unwrap();
        let clamped: Vec<bool> = lattice.node_coords().iter().map(|c| c[0] == 0).collect();
        let material = mss_core::Material::new(1000.0, 0.3, 0.01).unwrap();
        let params = mss_core::Parameterizations::default();
        let modes = |name: &str| {
            let model =
                mss_core::Model::new(&lattice, material, params.get(name).unwrap().as_ref())
                    .unwrap();
            mss_core::modes::count_zero_energy_modes(&model, &clamped).unwrap()
        };
        assert!(modes(base) > 0, "{base} 4x1x1 has mechanisms");
        assert_eq!(modes(&hg), 0, "{hg} 4x1x1 has none");
        let (plain1, with1) = (stats(&r, base, 1), stats(&r, &hg, 1));
        assert!(
            with1.0 < bound.0 && with1.2 < bound.1,
            "{base} 4x1x1: {plain1:?} -> {with1:?}"
        );
        let (plain4, with4) = (stats(&r, base, 4), stats(&r, &hg, 4));
        println!("{base}: 4x1x1 {plain1:?} -> {with1:?}; 16x4x4 {plain4:?} -> {with4:?}");
        // Measured (alpha 0.05): paper 4.199 / 9.856 -> 4.201 / 9.846,
        // volumetric 0.889 / 1.888 -> 0.892 / 1.864.
        assert!(
            with4.0 < plain4.0 * 1.005 && with4.2 < plain4.2 * 1.005,
            "{base} 16x4x4: {plain4:?} -> {with4:?}"
        );
    }
}

fn scene_box(n: u32) -> hexmesh::Lattice {
    // A 0.2 x 0.05 x 0.05 m bar, 4n x n x n cells.
    hexmesh::Lattice::block([4 * n, n, n], 0.05 / n as f64, [0.0; 3]).unwrap()
}

fn scene_specs() -> (
    Vec<mss_core::ConstraintSpec>,
    Vec<mss_core::LoadSpec>,
    mss_core::Material,
) {
    use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
    use mss_core::loads::{ForceDistribution, LoadSpec};
    let fixed = vec![ConstraintSpec::fixed(NodeSelector::face(Face::XMin))];
    let loads = vec![
        LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        },
        // A downward traction on the free end face and a sideways force on
        // the top of the free end.
        LoadSpec::Traction {
            min: [0.2, 0.0, 0.0],
            max: [0.2, 0.05, 0.05],
            traction: [0.0, 0.0, -1.0],
        },
        LoadSpec::Force {
            select: NodeSelector::boxed([0.2, 0.0, 0.05], [0.2, 0.05, 0.05]),
            force: [0.0, 1e-4, 0.0],
            distribution: ForceDistribution::Total,
        },
    ];
    (
        fixed,
        loads,
        // Stiff enough for a small (linear) response: about 0.2 mm.
        mss_core::Material::new(1.0e5, 0.3, 1.0).unwrap(),
    )
}

#[test]
fn scene_comparison_error_is_bounded_and_falls_with_resolution() {
    use mss_validate::experiments::{RegimeChoice, SceneSettings, scene};
    let (fixed, loads, mat) = scene_specs();
    let settings = SceneSettings {
        refine: 2,
        regime: RegimeChoice::Auto,
        models: models(),
    };
    // (One cell through the thickness, 4x1x1, is too ill-conditioned for the
    // sideways force.)
    let coarse = scene(&scene_box(2), mat, &fixed, &loads, &settings).unwrap();
    let fine = scene(&scene_box(4), mat, &fixed, &loads, &settings).unwrap();
    assert_eq!(coarse.regime, Regime::Linear, "{:?}", coarse.auto_ratio);
    assert!(coarse.reference.richardson);
    for m in ["paper", "springs", "volumetric"] {
        let at = |r: &mss_validate::experiments::SceneResult| {
            r.runs.iter().find(|x| x.model == m).unwrap().stats
        };
        let (c, f) = (at(&coarse), at(&fine));
        println!("{m}: 8x2x2 {c:?}, 16x4x4 {f:?}");
        assert!(f.mean < c.mean && f.max < c.max, "{m}");
        assert!(f.mean < 6.0 && f.max < 14.0, "{m}: {f:?}");
    }
    // The nonlinear regime on request: same order of error at this small load.
    let nl = scene(
        &scene_box(2),
        mat,
        &fixed,
        &loads,
        &SceneSettings {
            regime: RegimeChoice::Fixed(Regime::Large),
            models: builtin_models(&["volumetric"]).unwrap(),
            ..settings
        },
    )
    .unwrap();
    assert_eq!(nl.regime, Regime::Large);
    assert!(nl.runs[0].stats.mean < 25.0, "{:?}", nl.runs[0].stats);
}

#[test]
fn scene_comparison_refuses_drag_springs_and_prescribed_motions() {
    use mss_core::constraints::{ConstraintSpec, Motion, NodeSelector};
    use mss_core::loads::LoadSpec;
    use mss_validate::experiments::{ExperimentError, RegimeChoice, SceneSettings, scene};
    let (mut fixed, mut loads, mat) = scene_specs();
    let settings = SceneSettings {
        refine: 2,
        regime: RegimeChoice::Auto,
        models: builtin_models(&["paper"]).unwrap(),
    };
    loads.push(LoadSpec::Drag {
        select: NodeSelector::indices(vec![3]),
        target: [0.3, 0.0, 0.0],
        stiffness: 1.0,
    });
    let err = scene(&scene_box(1), mat, &fixed, &loads, &settings).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, ExperimentError::UnsupportedLoad { index: 4, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("drag"), "{err}");
    loads.pop();
    fixed.push(ConstraintSpec {
        motion: Motion::Velocity([0.0, 0.0, 0.01]),
        ..ConstraintSpec::fixed(NodeSelector::indices(vec![5]))
    });
    let err = scene(&scene_box(1), mat, &fixed, &loads, &settings).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, ExperimentError::UnsupportedConstraint { index: 2, .. }),
        "{err:?}"
    );
}

#[test]
fn beam_theories_of_a_varying_modulus_reduce_to_the_closed_forms() {
    use mss_validate::experiments::{
        BEAM_LENGTH, BEAM_YOUNG, beam_theories_varying, euler_bernoulli, timoshenko,
    };
    let q = 0.981;
    let xs: Vec<f64> = (0..=8).map(|i| BEAM_LENGTH * i as f64 / 8.0).collect();
    for (x, eb, t) in beam_theories_varying(q, &|_| BEAM_YOUNG, 0.3, &xs) {
        let (e0, t0) = (
            euler_bernoulli(x, q, BEAM_YOUNG),
            timoshenko(x, q, BEAM_YOUNG, 0.3),
        );
        assert!((eb - e0).abs() <= 1e-9 * e0.max(1e-30), "{x}: {eb} vs {e0}");
        assert!((t - t0).abs() <= 1e-9 * t0.max(1e-30), "{x}: {t} vs {t0}");
    }
    // A free half ten times stiffer: less than the soft beam, more than the
    // stiff one, and exactly the soft beam's up to the interface.
    let half = |x: f64| {
        if x > BEAM_LENGTH / 2.0 {
            10.0 * BEAM_YOUNG
        } else {
            BEAM_YOUNG
        }
    };
    let two = beam_theories_varying(q, &half, 0.3, &xs);
    let tip = two[8].1;
    assert!(tip < euler_bernoulli(BEAM_LENGTH, q, BEAM_YOUNG));
    assert!(tip > euler_bernoulli(BEAM_LENGTH, q, 10.0 * BEAM_YOUNG));
    assert!((two[4].1 - euler_bernoulli(BEAM_LENGTH / 2.0, q, BEAM_YOUNG)).abs() < 1e-12);
}

#[test]
fn a_cantilever_of_two_materials_converges_to_its_reference() {
    // Root half E = 1 kPa, free half 10 kPa: every model's error falls with
    // refinement against the two-material FEM, and the FEM follows the
    // stepped-beam theory.
    let s = BeamSettings {
        second_half_young: Some(1.0e4),
        reference_law: None,
        poisson: 0.3,
        density: 0.01,
        regime: Regime::Linear,
        resolutions: vec![2, 4],
        reference: 8,
        models: builtin_models(&["paper", "springs", "volumetric", "volumetric-barrier+hg"])
            .unwrap(),
    };
    let r = beam(&s).unwrap();
    for m in ["paper", "springs", "volumetric", "volumetric-barrier+hg"] {
        assert!(stats(&r, m, 4).0 < stats(&r, m, 2).0, "{m}");
        assert!(stats(&r, m, 4).2 < stats(&r, m, 2).2, "{m}");
    }
    assert!(stats(&r, "volumetric", 4).0 < stats(&r, "springs", 4).0);
    let tref = -r.reference.monitor_ref.z;
    assert!(
        (tref - r.timoshenko_tip).abs() < 0.05 * r.timoshenko_tip,
        "{tref} vs {}",
        r.timoshenko_tip
    );
    // Stiffer than a soft beam, softer than a stiff one.
    let soft = mss_validate::experiments::timoshenko(
        mss_validate::experiments::BEAM_LENGTH,
        0.01 * 9.81 * 0.01,
        1.0e3,
        0.3,
    );
    assert!(tref < soft);
}
