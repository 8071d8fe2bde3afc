//! Explicit, implicit and static solvers: conservation, invariance, agreement,
//! stability limits, divergence and mechanism detection.

use hexmesh::Lattice;
use mss_core::constraints::{ConstraintSpec, Constraints, Face, NodeSelector};
use mss_core::loads::{Damping, Gravity, Load, LoadSpec};
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric};
use mss_core::solver::{
    Divergence, Explicit, ExplicitOptions, Implicit, ImplicitOptions, Integrator,
    IntegratorSettings, Integrators, Problem, SolverError, State, StaticOptions,
    explicit_time_step_limit, solve_static,
};
use mss_core::{Mat3, Material, Model, Parameterization, Precision, Vec3};

fn free_block(param: &dyn Parameterization) -> Model {
    let lattice = Lattice::block([4, 4, 4], 0.25, [0.0; 3]).unwrap();
    Model::new(&lattice, Material::new(1000.0, 0.3, 1.0).unwrap(), param).unwrap()
}

/// A smooth initial state: deformation `a * u(X)`, uniform velocity `b * w`.
/// The velocity is a translation: a velocity field with rotation or hourglass
/// components makes those zero-stiffness motions grow without bound, and over
/// 10^4 steps they dwarf the elastic vibration being measured.
fn smooth_state(model: &Model, a: f64, b: f64) -> State {
    let mut s = State::at_rest(model);
    for (i, p) in model.rest_positions().iter().enumerate() {
        let u = Vec3::new(p.x * p.y, (p.y * p.z).sin(), p.z * p.x - 0.3 * p.x);
        s.x[i] += u * a;
        s.v[i] = Vec3::new(1.0, -0.5, 0.25) * b;
    }
    s
}

fn quadratic_energy(k0: &mss_core::BlockCsr, model: &Model, x: &[Vec3]) -> f64 {
    let u: Vec<Vec3> = x
        .iter()
        .zip(model.rest_positions())
        .map(|(x, r)| x - r)
        .collect();
    let mut ku = vec![Vec3::zeros(); u.len()];
    k0.mul_vec(&u, &mut ku);
    0.5 * u.iter().zip(&ku).map(|(a, b)| a.dot(b)).sum::<f64>()
}

/// Energy figures of an undamped explicit run at the default (stable) step.
struct EnergyRun {
    /// Largest relative deviation of the physical energy `KE + U`.
    physical: f64,
    /// Relative change of the mean physical energy between the first and the
    /// last tenth of the run (drift).
    drift: f64,
    /// Largest relative deviation of the Verlet ("shadow") energy
    /// `sum m v_{n-1/2} . v_{n+1/2} / 2 + U = KE - dt^2/8 sum m |a|^2 + U`,
    /// which velocity Verlet conserves exactly for a linear system.
    shadow: f64,
    /// Largest relative deviation of the linear momentum.
    momentum: f64,
}

fn energy_run(
    model: Model,
    a: f64,
    b: f64,
    steps: usize,
    potential: &dyn Fn(&Model, &[Vec3]) -> f64,
) -> EnergyRun {
    let state0 = smooth_state(&model, a, b);
    let problem = Problem::new(model);
    let model = problem.model();
    let mut it = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
    let dt = it.dt();
    let mut f = vec![Vec3::zeros(); model.num_nodes()];
    let mut energies = |s: &State| {
        model.internal_forces(&s.x, &mut f);
        let acc2: f64 = f
            .iter()
            .zip(model.masses())
            .map(|(f, m)| f.norm_squared() / m)
            .sum();
        // Kinetic energy relative to the centre of mass: the translation's
        // share is constant and would only dilute the relative deviations.
        let ke = s.kinetic_energy(model.masses())
            - s.momentum(model.masses()).norm_squared() / (2.0 * model.total_mass());
        let e = ke + potential(model, &s.x);
        (e, e - dt * dt / 8.0 * acc2)
    };
    let mut s = state0.clone();
    let (e0, h0) = energies(&s);
    let p0 = s.momentum(model.masses());
    let pscale = p0.norm();
    let mut r = EnergyRun {
        physical: 0.0,
        drift: 0.0,
        shadow: 0.0,
        momentum: 0.0,
    };
    let (mut first, mut last, mut count) = (0.0, 0.0, 0usize);
    for k in 0..steps {
        it.step(&problem, &mut s).unwrap();
        let (e, hh) = energies(&s);
        r.physical = r.physical.max((e - e0).abs() / e0);
        r.shadow = r.shadow.max((hh - h0).abs() / h0);
        r.momentum = r
            .momentum
            .max((s.momentum(model.masses()) - p0).norm() / pscale);
        if k < steps / 10 {
            first += e;
            count += 1;
        } else if k >= steps - steps / 10 {
            last += e;
        }
    }
    r.drift = ((last - first) / count as f64).abs() / e0;
    println!(
        "dt {dt:.3e}: physical energy deviation {:.3e}, drift of its mean {:.3e}, Verlet energy deviation {:.3e}, momentum {:.3e}",
        r.physical, r.drift, r.shadow, r.momentum
    );
    r
}

#[test]
fn explicit_conserves_energy_and_momentum_springs_only() {
    let r = energy_run(free_block(&SpringsOnly), 1e-3, 0.05, 10_000, &|m, x| {
        m.energy(x)
    });
    assert!(r.shadow < 0.01 && r.drift < 0.01, "energy not conserved");
    // Bounded O(dt^2) oscillation of Verlet at the stable step, not a drift
    // (0.16 at the Gershgorin step, 0.24 at the Lanczos one: 0.86 of the
    // true limit, where the top modes' share dt^2 |a|^2 / 8 is larger).
    assert!(r.physical < 0.3, "{}", r.physical);
    assert!(r.momentum < 1e-12, "momentum deviation {}", r.momentum);
}

#[test]
fn explicit_conserves_quadratic_energy_with_corrections_at_small_amplitude() {
    // With hourglass control too (strong, alpha = 1, on the volumetric
    // variant): its energy is conservative and the stable step accounts for
    // the stiffness it adds.
    let volumetric_hg = HourglassControl::new(Box::new(Volumetric), 1.0).unwrap();
    for param in [&PaperModel as &dyn Parameterization, &volumetric_hg] {
        let model = free_block(param);
        let k0 = model.rest_stiffness();
        let r = energy_run(model, 1e-7, 1e-6, 10_000, &|m, x| {
            quadratic_energy(&k0, m, x)
        });
        assert!(
            r.shadow < 0.01 && r.drift < 0.01,
            "{}: energy not conserved",
            param.name()
        );
        assert!(r.physical < 0.3, "{}: {}", param.name(), r.physical);
        assert!(r.momentum < 1e-12, "momentum deviation {}", r.momentum);
    }
}

/// Observation (reported, not a conservation claim): the correction forces are
/// not conservative at large strain. Starting from a 10% smooth deformation,
/// the quadratic energy is no longer an invariant, and the run at the stable
/// step eventually explodes (detected as exploding motion, with the state kept
/// finite). Observed steps before detection: paper 2090, paper+hg 380,
/// springs+hg 9570, volumetric 130, volumetric+hg 1040 (hourglass factor 1).
/// Even the conservative springs+hg fails, late: compressed springs have a
/// negative transverse stiffness, so the free lattice can buckle locally at
/// this strain; the corrections make it much earlier. Momentum is conserved
/// until then (the corrections of each cell sum to zero).
#[test]
fn explicit_with_corrections_at_large_strain_observed() {
    let paper_hg = HourglassControl::new(Box::new(PaperModel), 1.0).unwrap();
    let springs_hg = HourglassControl::new(Box::new(SpringsOnly), 1.0).unwrap();
    let volumetric_hg = HourglassControl::new(Box::new(Volumetric), 1.0).unwrap();
    for param in [
        &PaperModel as &dyn Parameterization,
        &paper_hg,
        &springs_hg,
        &Volumetric,
        &volumetric_hg,
    ] {
        let model = free_block(param);
        let state0 = smooth_state(&model, 0.1, 0.01);
        let problem = Problem::new(model);
        let m = problem.model();
        let k0 = m.rest_stiffness();
        let mut it = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
        let mut s = state0.clone();
        let p0 = s.momentum(m.masses());
        let e = |s: &State| s.kinetic_energy(m.masses()) + quadratic_energy(&k0, m, &s.x);
        let e0 = e(&s);
        let mut peak = 0.0f64;
        let mut outcome = String::from("no divergence in 10000 steps");
        for _ in 0..10_000 {
            if let Err(err) = it.step(&problem, &mut s) {
                outcome = err.to_string();
                break;
            }
            peak = peak.max(e(&s) / e0);
            let dp = (s.momentum(m.masses()) - p0).norm() / p0.norm();
            assert!(dp < 1e-9, "momentum deviation {dp}");
        }
        println!(
            "large strain, {}: peak energy ratio {peak:.3e}; {outcome}",
            param.name()
        );
        assert!(
            s.x.iter()
                .chain(&s.v)
                .all(|v| v.iter().all(|c| c.is_finite()))
        );
    }
}

fn rotation() -> Mat3 {
    let axis = nalgebra::Unit::new_normalize(Vec3::new(1.0, 2.0, 3.0));
    *nalgebra::Rotation3::from_axis_angle(&axis, std::f64::consts::FRAC_PI_2).matrix()
}

fn cantilever(n: [u32; 3], material: Material) -> Model {
    cantilever_with(n, material, &PaperModel)
}

fn cantilever_with(n: [u32; 3], material: Material, param: &dyn Parameterization) -> Model {
    let lattice = Lattice::block(n, 0.4 / n[0] as f64, [0.0; 3]).unwrap();
    Model::new(&lattice, material, param).unwrap()
}

#[test]
fn static_solution_rotates_with_the_lattice_and_loads() {
    // Large deflection: total mass 0.0125 kg (docs/model.md), tip deflection ~0.1 m.
    let mat = Material::new(1000.0, 0.3, 3.125).unwrap();
    let fixed = [ConstraintSpec::fixed(NodeSelector::face(Face::XMin))];
    let g = Vec3::new(0.0, 0.0, -9.81);
    let opts = StaticOptions {
        rtol: 1e-12,
        ..StaticOptions::default()
    };
    let p = Problem::from_specs(
        cantilever([8, 2, 2], mat),
        &fixed,
        &[LoadSpec::Gravity { g: g.into() }],
        Damping::NONE,
    )
    .unwrap();
    let mut reference = State::at_rest(p.model());
    let info = solve_static(&p, &mut reference, &opts).unwrap();
    let u = reference.displacements(p.model());
    let umax = u.iter().map(|v| v.norm()).fold(0.0, f64::max);
    println!("reference: {info:?}, max displacement {umax}");
    assert!(umax > 0.05, "not a large deflection: {umax}");

    let r = rotation();
    let rg = r * g;
    let rp = Problem::from_specs(
        cantilever([8, 2, 2], mat),
        &fixed,
        &[LoadSpec::Gravity { g: rg.into() }],
        Damping::NONE,
    )
    .unwrap();
    let mut rotated = State::at_rest(rp.model());
    for x in &mut rotated.x {
        *x = r * *x;
    }
    solve_static(&rp, &mut rotated, &opts).unwrap();
    let err = rotated
        .x
        .iter()
        .zip(&reference.x)
        .map(|(a, b)| (a - r * b).norm())
        .fold(0.0, f64::max);
    println!("rotation error {:.3e} (relative)", err / umax);
    assert!(err / umax < 1e-8, "relative error {}", err / umax);
}

fn damped_cantilever(alpha: f64) -> Problem {
    damped_cantilever_with(alpha, &PaperModel)
}

fn damped_cantilever_with(alpha: f64, param: &dyn Parameterization) -> Problem {
    let mat = Material::new(1000.0, 0.3, 0.01).unwrap();
    Problem::from_specs(
        cantilever_with([8, 2, 2], mat, param),
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping { alpha, beta: 0.0 },
    )
    .unwrap()
}

fn rel_diff(model: &Model, a: &State, b: &State) -> f64 {
    let ub = b.displacements(model);
    let umax = ub.iter().map(|v| v.norm()).fold(0.0, f64::max);
    a.x.iter()
        .zip(&b.x)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
        / umax
}

#[test]
fn explicit_implicit_and_static_reach_the_same_equilibrium() {
    // Every parameterization works with all three solvers.
    let volumetric_hg = HourglassControl::new(Box::new(Volumetric), 1.0).unwrap();
    for param in [
        &PaperModel as &dyn Parameterization,
        &Volumetric,
        &volumetric_hg,
    ] {
        let p = damped_cantilever_with(300.0, param);
        let mut st = State::at_rest(p.model());
        solve_static(&p, &mut st, &StaticOptions::default()).unwrap();
        let t_end = 0.3;

        let mut ex = Integrators::default()
            .build(
                "explicit",
                &p,
                &IntegratorSettings {
                    dt: None,
                    ..Default::default()
                },
            )
            .unwrap();
        let mut se = State::at_rest(p.model());
        while se.time < t_end {
            ex.step(&p, &mut se).unwrap();
        }
        let mut im = Integrators::default()
            .build(
                "implicit",
                &p,
                &IntegratorSettings {
                    dt: Some(2e-3),
                    ..Default::default()
                },
            )
            .unwrap();
        let mut si = State::at_rest(p.model());
        while si.time < t_end {
            im.step(&p, &mut si).unwrap();
        }
        let (de, di) = (rel_diff(p.model(), &se, &st), rel_diff(p.model(), &si, &st));
        println!(
            "{}: explicit vs static {de:.3e}, implicit vs static {di:.3e}",
            param.name()
        );
        assert!(de < 1e-4 && di < 1e-4, "{}", param.name());
    }
}

#[test]
fn implicit_is_stable_far_above_the_explicit_limit_and_explicit_refuses() {
    let p = damped_cantilever(0.0);
    let limit = explicit_time_step_limit(&p, 0.9);
    let mut st = State::at_rest(p.model());
    solve_static(&p, &mut st, &StaticOptions::default()).unwrap();
    let ustatic = st
        .displacements(p.model())
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max);
    for factor in [10.0, 100.0] {
        let mut im = Implicit::new(
            &p,
            ImplicitOptions {
                dt: factor * limit,
                ..ImplicitOptions::default()
            },
        )
        .unwrap();
        let mut s = State::at_rest(p.model());
        for _ in 0..60 {
            im.step(&p, &mut s).unwrap();
        }
        let umax = s
            .displacements(p.model())
            .iter()
            .map(|v| v.norm())
            .fold(0.0, f64::max);
        println!(
            "implicit dt = {factor} x limit: max displacement {umax:.3e} (static {ustatic:.3e})"
        );
        assert!(umax.is_finite() && umax < 2.5 * ustatic);
        assert!(p.model().inverted_cells(&s.x).is_empty());
    }
    let err = Explicit::new(
        &p,
        ExplicitOptions {
            dt: Some(2.0 * limit),
            ..ExplicitOptions::default()
        },
    )
    .unwrap_err();
    let msg = err.to_string();
    println!("{msg}");
    assert!(matches!(err, SolverError::TimeStepTooLarge { .. }));
    assert!(
        msg.contains("stability limit") && msg.contains("implicit"),
        "{msg}"
    );
    // Sub-stepping when asked for.
    let ex = Explicit::new(
        &p,
        ExplicitOptions {
            dt: Some(2.5 * limit),
            substep: true,
            ..ExplicitOptions::default()
        },
    )
    .unwrap();
    assert_eq!(ex.substeps(), 3);
}

/// What the explicit integrator lends between steps is not read again
/// before it is refilled: NaN written into it after every step leaves the
/// steps bitwise unchanged, through stable steps, retried ones (the
/// sub-step halved) and the final fallback of a diverging run.
#[test]
fn scratch_lent_by_the_explicit_integrator_does_not_change_its_steps() {
    let p = damped_cantilever(0.0);
    let limit = explicit_time_step_limit(&p, 1.0);
    for (dt, unchecked) in [(0.5 * limit, false), (1.5 * limit, true)] {
        let opts = ExplicitOptions {
            dt: Some(dt),
            unchecked,
            ..ExplicitOptions::default()
        };
        let run = |scribble: bool| {
            let mut ex = Explicit::new(&p, opts).unwrap();
            let mut s = State::at_rest(p.model());
            let mut outcome = String::new();
            for _ in 0..400 {
                if let Err(e) = ex.step(&p, &mut s) {
                    outcome = e.to_string();
                    break;
                }
                if scribble {
                    let lent = ex
                        .lend_scratch()
                        .expect("explicit lends its retry positions");
                    assert_eq!(lent.len(), p.model().num_nodes());
                    lent.fill(Vec3::repeat(f64::NAN));
                }
            }
            (s, outcome)
        };
        let (plain, plain_outcome) = run(false);
        let (scribbled, scribbled_outcome) = run(true);
        assert_eq!(plain_outcome, scribbled_outcome);
        assert_eq!(plain.time.to_bits(), scribbled.time.to_bits());
        assert!(
            plain
                .x
                .iter()
                .zip(&scribbled.x)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
        );
        assert!(
            plain
                .v
                .iter()
                .zip(&scribbled.v)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
        );
        // The second case diverges (and retries on the way).
        assert_eq!(plain_outcome.is_empty(), !unchecked, "{plain_outcome}");
    }
}

#[test]
fn explicit_divergence_is_detected_and_last_good_state_kept() {
    let p = damped_cantilever(0.0);
    let limit = explicit_time_step_limit(&p, 1.0);
    let mut ex = Explicit::new(
        &p,
        ExplicitOptions {
            dt: Some(1.5 * limit),
            unchecked: true,
            ..ExplicitOptions::default()
        },
    )
    .unwrap();
    let mut s = State::at_rest(p.model());
    let mut err = None;
    for _ in 0..5000 {
        if let Err(e) = ex.step(&p, &mut s) {
            err = Some(e);
            break;
        }
    }
    let err = err.expect("explicit above the limit must diverge");
    println!("{err}");
    let SolverError::Diverged {
        step, kept_time, ..
    } = err
    else {
        panic!("wrong error {err:?}")
    };
    assert!(err.to_string().contains(&format!("step {step}")));
    assert_eq!(s.time, kept_time);
    assert!(
        s.x.iter()
            .chain(&s.v)
            .all(|v| v.iter().all(|c| c.is_finite()))
    );
    assert!(p.model().inverted_cells(&s.x).is_empty());
}

/// A load that turns NaN after a given time.
#[derive(Debug)]
struct NanAfter(f64);

impl Load for NanAfter {
    fn name(&self) -> String {
        "nan".into()
    }
    fn add_forces(&self, _m: &Model, t: f64, _x: &[Vec3], _s: f64, f: &mut [Vec3]) {
        if t >= self.0 {
            f[3].x = f64::NAN;
        }
    }
}

#[test]
fn nan_load_is_detected_by_every_solver() {
    let base = damped_cantilever(10.0);
    let dt = explicit_time_step_limit(&base, 0.9);
    let t_bad = 25.5 * dt;
    let p = damped_cantilever(10.0).with_load(Box::new(NanAfter(t_bad)));
    for name in ["verlet", "symplectic-euler", "implicit"] {
        let mut it = Integrators::default()
            .build(
                name,
                &p,
                &IntegratorSettings {
                    dt: Some(dt),
                    ..Default::default()
                },
            )
            .unwrap();
        let mut s = State::at_rest(p.model());
        let mut failed = false;
        for k in 0..100 {
            match it.step(&p, &mut s) {
                Ok(_) => {}
                Err(e) => {
                    println!("{name}: {e}");
                    let SolverError::Diverged { step, reason, .. } = &e else {
                        panic!("{e:?}")
                    };
                    assert!(*step as usize == k + 1);
                    assert!(matches!(
                        reason,
                        Divergence::NonFinite | Divergence::NewtonFailed { .. }
                    ));
                    assert!(s.time <= t_bad + 1.5 * dt);
                    failed = true;
                    break;
                }
            }
        }
        assert!(failed, "{name} did not notice the NaN");
        assert!(
            s.x.iter()
                .chain(&s.v)
                .all(|v| v.iter().all(|c| c.is_finite()))
        );
    }
}

#[test]
fn static_mechanisms_are_reported() {
    let mat = Material::new(1000.0, 0.3, 1.0).unwrap();
    let gravity = || {
        Box::new(Gravity {
            g: Vec3::new(0.0, 0.0, -9.81),
        })
    };
    // No fixed node at all.
    let p = Problem::new(cantilever([4, 1, 1], mat)).with_load(gravity());
    let mut s = State::at_rest(p.model());
    let err = solve_static(&p, &mut s, &StaticOptions::default()).unwrap_err();
    println!("{err}");
    assert!(matches!(err, SolverError::Mechanism { .. }));
    assert!(err.to_string().contains("no node is fixed"));
    assert_eq!(s, State::at_rest(p.model()));
    // Two fixed nodes: rotation about the line through them is free.
    let model = cantilever([4, 1, 1], mat);
    let mut c = Constraints::none(model.num_nodes());
    c.fix(&[0, 1]).unwrap();
    let p = Problem::new(model)
        .with_constraints(c)
        .unwrap()
        .with_load(gravity());
    let err = solve_static(&p, &mut s, &StaticOptions::default()).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, SolverError::Mechanism { .. }) && err.to_string().contains("7 zero-energy"),
        "{err:?}"
    );
}

#[test]
fn a_bar_one_cell_thick_is_refused_as_a_mechanism_for_every_model_ratio_and_load() {
    // Clamped at its x- face, a 4 x 1 x 1 bar keeps 4 hourglass mechanisms
    // of the lattice: its static problem has no unique solution, whatever
    // the model, the Poisson ratio and the load (the LU factored the
    // singular matrix with round-off pivots and answered, for most of them).
    // With hourglass control it has none and is solved.
    let fixed = [ConstraintSpec::fixed(NodeSelector::face(Face::XMin))];
    let hg = |p: Box<dyn Parameterization>| -> Box<dyn Parameterization> {
        Box::new(HourglassControl::new(p, 1.0).unwrap())
    };
    let params: [(&str, Box<dyn Parameterization>, bool); 4] = [
        ("paper", Box::new(PaperModel), true),
        ("springs", Box::new(SpringsOnly), true),
        ("volumetric", Box::new(Volumetric), true),
        ("volumetric+hg", hg(Box::new(Volumetric)), false),
    ];
    for (name, param, mechanisms) in &params {
        for nu in [0.0, 0.25, 0.3, 0.45] {
            for g in [1e-3, 1.0, 9.81] {
                let mat = Material::new(1000.0, nu, 1.0).unwrap();
                let model = cantilever_with([4, 1, 1], mat, param.as_ref());
                let gravity = LoadSpec::Gravity { g: [0.0, 0.0, -g] };
                let p = Problem::from_specs(model, &fixed, &[gravity], Damping::NONE).unwrap();
                let mut s = State::at_rest(p.model());
                let result = solve_static(&p, &mut s, &StaticOptions::default());
                let what = format!("{name}, nu {nu}, g {g}");
                if *mechanisms {
                    let err = result.unwrap_err();
                    assert!(
                        matches!(err, SolverError::Mechanism { .. })
                            && err.to_string().contains("4 zero-energy"),
                        "{what}: {err}"
                    );
                } else {
                    assert!(result.is_ok(), "{what}: {result:?}");
                }
            }
        }
    }
}

#[test]
fn empty_selection_is_a_typed_error() {
    let mat = Material::new(1000.0, 0.3, 1.0).unwrap();
    let err = Problem::from_specs(
        cantilever([4, 1, 1], mat),
        &[ConstraintSpec::fixed(NodeSelector::boxed(
            [5.0; 3], [6.0; 3],
        ))],
        &[],
        Damping::NONE,
    )
    .unwrap_err();
    assert!(err.to_string().contains("selects no node"), "{err}");
}

#[test]
fn large_deflection_static_solve_takes_few_newton_iterations() {
    // The large-deflection cantilever (total mass 0.0125 kg, tip ~0.11 m) at
    // 16x4x4: the slope line search takes (nearly) full Newton steps, so the
    // whole load goes in one increment in about 10 iterations (backtracking
    // on the residual norm needed 190 iterations and 4 increments).
    let mat = Material::new(1000.0, 0.3, 3.125).unwrap();
    let p = Problem::from_specs(
        cantilever([16, 4, 4], mat),
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81],
        }],
        Damping::NONE,
    )
    .unwrap();
    let mut s = State::at_rest(p.model());
    // The paper's model has no hourglass control, and this equilibrium fails
    // the stability test (docs/robustness.md); the iteration count is what
    // is tested here.
    let opts = StaticOptions {
        rtol: 1e-10,
        accept_unstable: true,
        ..StaticOptions::default()
    };
    let info = solve_static(&p, &mut s, &opts).unwrap();
    println!("{info:?}");
    assert!(
        info.newton_iterations <= 15 && info.rejected_iterations == 0,
        "{info:?}"
    );
    assert!(info.relative_residual < 1e-10);
    let tip = -s
        .displacements(p.model())
        .iter()
        .map(|v| v.z)
        .fold(0.0, f64::min);
    // Measured 0.10811 m (also with the former line search).
    assert!((tip - 0.10811).abs() < 1e-4, "tip {tip}");
}

/// A damped explicit run with the single-precision force pass settles where
/// the `f64` one does (the cantilever sags to its static deflection in
/// both), and the Newton solvers refuse `f32` by name.
#[test]
fn single_precision_explicit_run_matches_double() {
    let p = damped_cantilever(20.0);
    let run = |precision: Precision| {
        let mut ex = Explicit::new(
            &p,
            ExplicitOptions {
                precision,
                ..ExplicitOptions::default()
            },
        )
        .unwrap();
        let mut s = State::at_rest(p.model());
        while s.time < 1.5 {
            ex.step(&p, &mut s).unwrap();
        }
        s
    };
    let (double, single) = (run(Precision::F64), run(Precision::F32));
    let diff = rel_diff(p.model(), &single, &double);
    // The error of f32 forces is about 1e-7 / strain relative (positions
    // rounded at 6e-8 of a cell against strains of 1e-4 here).
    let umax = double
        .displacements(p.model())
        .iter()
        .map(|u| u.norm())
        .fold(0.0, f64::max);
    // The bar is 0.4 m long: its bending strain is of the order of umax / L.
    let strain = umax / 0.4;
    println!("f32 against f64: {diff:.2e} of the largest displacement (strain ~ {strain:.1e})");
    assert!(diff > 0.0 && diff < 20.0 * 6e-8 / strain, "{diff:e}");
    let settings = IntegratorSettings {
        precision: Precision::F32,
        ..IntegratorSettings::default()
    };
    let err = Integrators::default()
        .build("implicit", &p, &settings)
        .err()
        .expect("implicit refuses f32");
    assert!(err.to_string().contains("f32"), "{err}");
    assert!(
        Integrators::default()
            .build("explicit", &p, &settings)
            .is_ok()
    );
}

/// The matrix-free tangent action (the kernel on dual numbers) is the
/// assembled tangent's product to round-off, for every kind of term
/// (corrections at large strain, the volumetric law with its corner
/// barrier, hourglass control), and the same bits for any thread count.
#[test]
fn matrix_free_tangent_action_is_the_assembled_product() {
    let lattice = Lattice::block([6, 5, 4], 0.02, [0.0; 3]).unwrap();
    let material = Material::new(1e4, 0.45, 1000.0).unwrap();
    let default = mss_core::Parameterizations::default()
        .get("volumetric-barrier+hg")
        .unwrap();
    let params: Vec<Box<dyn Parameterization>> = vec![
        Box::new(PaperModel),
        Box::new(SpringsOnly),
        Box::new(HourglassControl::new(Box::new(Volumetric), 0.05).unwrap()),
        default,
    ];
    for param in &params {
        let model = Model::new(&lattice, material, param.as_ref()).unwrap();
        // A large, non-affine deformation: squeezed to 60 % in z, sheared,
        // and rippled, so that every term is far from its rest value.
        let x: Vec<Vec3> = model
            .rest_positions()
            .iter()
            .map(|p| {
                Vec3::new(
                    p.x + 0.3 * p.z + 0.004 * (90.0 * p.y).sin(),
                    p.y + 0.003 * (70.0 * p.x).cos(),
                    0.6 * p.z + 0.002 * (50.0 * (p.x + p.y)).sin(),
                )
            })
            .collect();
        let v: Vec<Vec3> = (0..model.num_nodes())
            .map(|i| {
                let t = i as f64;
                Vec3::new((0.7 * t).sin(), (1.3 * t).cos(), (0.4 * t).sin() - 0.2)
            })
            .collect();
        let tangent = model.tangent(&x);
        let mut assembled = vec![Vec3::zeros(); v.len()];
        tangent.mul_vec(&v, &mut assembled);
        let free = |threads| {
            crate::on_threads(threads, || {
                let mut out = vec![Vec3::zeros(); v.len()];
                model.tangent_mul(&x, &v, &mut out);
                out
            })
        };
        let one = free(1);
        let scale = assembled.iter().map(|f| f.amax()).fold(0.0, f64::max);
        assert!(scale > 0.0);
        let largest = one
            .iter()
            .zip(&assembled)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0, f64::max);
        assert!(
            largest <= 1e-11 * scale,
            "{}: {largest:e} of {scale:e}",
            param.name()
        );
        let two = free(2);
        assert!(
            one.iter()
                .zip(&two)
                .all(|(a, b)| (0..3).all(|d| a[d].to_bits() == b[d].to_bits())),
            "{}: the action depends on the thread count",
            param.name()
        );
    }
}

/// A soft cantilever swinging down from rest in steps of 0.1 s (each step
/// turns its tip by tens of degrees): Newton's full steps raise `|R|` while
/// they lower the step's energy, and the implicit solver's line search on
/// the energy's slope takes them where backtracking on `|R|` cut them
/// (measured: 52 and 42 Newton iterations over the ten steps with the slope,
/// 77 and 60 with `|R|` backtracking).
#[test]
fn a_swinging_cantilever_takes_full_newton_steps() {
    let mat = Material::new(1000.0, 0.3, 3.125).unwrap();
    let hg = mss_core::HourglassControl::new(Box::new(mss_core::Volumetric), 0.05).unwrap();
    for (param, most) in [(&PaperModel as &dyn Parameterization, 60), (&hg, 50)] {
        let p = Problem::from_specs(
            cantilever_with([16, 4, 4], mat, param),
            &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
            &[LoadSpec::Gravity {
                g: [0.0, 0.0, -9.81],
            }],
            Damping::NONE,
        )
        .unwrap();
        let mut im = Implicit::new(
            &p,
            ImplicitOptions {
                dt: 0.1,
                ..ImplicitOptions::default()
            },
        )
        .unwrap();
        let mut s = State::at_rest(p.model());
        let (mut newton, mut substeps) = (0, 0);
        for _ in 0..10 {
            let info = im.step(&p, &mut s).unwrap();
            newton += info.newton_iterations;
            substeps += info.substeps;
        }
        let tip = s
            .displacements(p.model())
            .iter()
            .map(|u| u.norm())
            .fold(0.0, f64::max);
        println!(
            "{}: {newton} Newton iterations, {substeps} steps, tip moved {tip:.3} m",
            param.name()
        );
        assert!(tip > 0.05, "{}: not a large swing ({tip} m)", param.name());
        assert_eq!(substeps, 10, "{}: steps were halved", param.name());
        assert!(
            newton <= most,
            "{}: {newton} Newton iterations",
            param.name()
        );
    }
}

#[test]
fn an_implicit_run_without_matrices_restored_from_its_memory_continues_bitwise() {
    // Solves that keep no matrix precondition the next steps' tangents with
    // the hierarchy of an earlier one: the memory carries where its
    // stiffness was taken, and a restored integrator builds it again.
    let model = free_block(&PaperModel);
    let p = Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -2.0],
        }],
        Damping::NONE,
    )
    .unwrap();
    let opts = ImplicitOptions {
        dt: 0.05,
        linear_solver: mss_core::solver::LinearSolverKind::Iterative,
        matrix_free_above: 0,
        ..ImplicitOptions::default()
    };
    let memory = crate::assert_restored_implicit_continues_bitwise(&p, opts, 5, 5);
    assert_eq!(
        memory.counters[1], 2,
        "a hierarchy is kept: {:?}",
        memory.counters
    );
}
